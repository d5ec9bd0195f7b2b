"""``protocol.range_min`` (the caps the holds put on spans and nodes) against the minimum over every (range, index)
pair, and the S-curve stage's measurement helpers (per-span maxima over sorted runs, ``spans.row_norm``) against
NumPy's own."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.geometry.spans import row_norm
from jaxcnc.planners.protocol import range_min
from jaxcnc.planners.smoothing import _max_into, _runs


def pairs_min(size: int, lo: np.ndarray, count: np.ndarray, value: np.ndarray) -> np.ndarray:
    """The reference: every index each range reaches, listed, and ``np.minimum.at`` over them."""
    count = np.maximum(count, 0)
    which = np.repeat(np.arange(lo.size), count)
    index = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count) + lo[which]
    out = np.full(size, np.inf)
    np.minimum.at(out, index, value[which])
    return out


@st.composite
def ranges(draw):
    size = draw(st.integers(1, 300))
    k = draw(st.integers(0, 60))
    lo = np.array(draw(st.lists(st.integers(0, size - 1), min_size=k, max_size=k)), dtype=np.int64)
    count = np.array([draw(st.integers(-2, size - a)) for a in lo], dtype=np.int64)
    # few distinct values (ties), zeros of both signs, and infinities, as caps and widths have
    value = np.array(
        draw(st.lists(st.sampled_from([0.0, -0.0, 1.5, 2.0, 7.25, 1e-9, np.inf]), min_size=k, max_size=k)), float
    )
    return size, lo, count, value


@settings(max_examples=300, deadline=None)
@given(ranges())
def test_range_min_is_the_minimum_over_every_index_a_range_reaches(case):
    size, lo, count, value = case
    got, want = range_min(size, lo, count, value), pairs_min(size, lo, count, value)
    assert np.array_equal(got, want)  # (which of tied 0.0 and -0.0 is kept may differ: caps are never negative)
    nonzero = want != 0
    assert np.array_equal(got[nonzero].view(np.int64), want[nonzero].view(np.int64))


def test_range_min_over_long_overlapping_ranges():
    rng = np.random.default_rng(7)
    size = 50_000
    lo = rng.integers(0, size, 5_000)
    count = rng.integers(0, 20_000, lo.size).clip(max=size - lo)
    value = rng.uniform(1.0, 100.0, lo.size)
    assert np.array_equal(range_min(size, lo, count, value), pairs_min(size, lo, count, value))
    assert np.all(np.isinf(range_min(size, lo[:0], count[:0], value[:0])))


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.integers(0, 9), min_size=1, max_size=80),
    st.lists(st.sampled_from([0.0, 0.5, 3.0, np.nan, np.inf]), min_size=80, max_size=80),
    st.booleans(),
)
def test_the_maxima_over_runs_are_those_of_maximum_at(keys, values, ordered):
    at = np.array(sorted(keys) if ordered else keys, dtype=np.int64)
    value = np.array(values[: at.size])
    start = np.linspace(0.0, 2.0, 10)
    want, got = start.copy(), start.copy()
    runs = _runs(at)
    assert (runs is not None) == bool(np.all(np.diff(at) >= 0))
    with np.errstate(invalid="ignore"):  # (NaN: propagated by both)
        np.maximum.at(want, at, value)
        _max_into(got, at, value, runs)
    assert np.array_equal(got, want, equal_nan=True)


def test_the_measured_speeds_row_norms_are_those_of_numpy():
    rng = np.random.default_rng(3)
    d = rng.standard_normal((20_000, 3)) * rng.choice([1e-9, 1e-3, 1.0, 1e4], (20_000, 3))
    want = np.linalg.norm(d, axis=1)
    # the same sum order as NumPy 2.4's (bit for bit there); within an ulp under any order of the three terms
    assert np.allclose(row_norm(d), want, rtol=4e-16, atol=0)
    assert np.array_equal(row_norm(d[:0]), want[:0])
