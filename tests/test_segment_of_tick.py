"""The tick stage's segment search (:func:`jaxcnc.planners.timelaw.segment_of_tick`): runs of consecutive ticks are
counted, anything else searched; both are NumPy's ``searchsorted`` on the sorted first ticks, index for index."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.planners.timelaw import segment_of_tick

BIG = np.iinfo(np.int64).max
_find = jax.jit(segment_of_tick)


def _reference(first_tick: np.ndarray, tick: np.ndarray) -> np.ndarray:
    return np.clip(np.searchsorted(first_tick, tick, side="right") - 1, 0, first_tick.size - 1)


@settings(max_examples=150, deadline=None)
@given(
    starts=st.lists(st.integers(-60, 400), min_size=1, max_size=120),
    padding=st.integers(0, 8),
    t0=st.integers(-100, 450),
    m=st.integers(1, 90),
    clamp=st.one_of(st.none(), st.integers(0, 89)),
)
def test_counted_and_searched_segments_are_searchsorted(starts, padding, t0, m, clamp) -> None:
    first_tick = np.array(sorted(starts) + [BIG] * padding, np.int64)  # ties (short segments) and padding rows
    tick = np.arange(t0, t0 + m, dtype=np.int64)
    if clamp is not None:  # a last chunk: the ticks past the job's end read its last tick (not a run: searched)
        tick = np.minimum(tick, t0 + clamp)
    got = np.asarray(_find(jnp.asarray(first_tick), jnp.asarray(tick)))
    np.testing.assert_array_equal(got, _reference(first_tick, tick))


def test_a_run_is_counted() -> None:
    """The run takes the counting branch: with the search's result replaced it still finds the segments."""
    first_tick = np.array([0, 3, 3, 7, 20, BIG], np.int64)
    tick = np.arange(2, 12, dtype=np.int64)
    orig = jnp.searchsorted

    def broken(*args, **kwargs):
        return orig(*args, **kwargs) * 0 - 99  # what the search would give is wrong

    try:
        jnp.searchsorted = broken
        got = np.asarray(segment_of_tick(jnp.asarray(first_tick), jnp.asarray(tick)))
    finally:
        jnp.searchsorted = orig
    np.testing.assert_array_equal(got, _reference(first_tick, tick))
