"""The tick stage window by window (a long job's law and spans on the device a window at a time): the same
positions and spans, bit for bit, as with the whole law on the device."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.bench.plan import bench_machine
from jaxcnc.bench.programs import cam_polyline, synthetic_program
from jaxcnc.geometry.evaluate import span_arrays, window_span_arrays
from jaxcnc.geometry.spans import pad_spans, pad_tables, slice_spans
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job
from jaxcnc.ticks.sample import TickSampler


@pytest.fixture(scope="module")
def blended():
    """Lines, arcs and blends (poly spans): every family of the evaluation."""
    return plan_job(cam_polyline(1500), parse_machine(bench_machine(0.01), "<bench>"))


@pytest.fixture(scope="module")
def lines():
    """Exact corners: lines alone, no arc or poly table."""
    return plan_job(synthetic_program(3000), parse_machine(bench_machine(0.0), "<bench>"))


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint8), b.view(np.uint8))


@pytest.mark.parametrize("name", ["blended", "lines"])
def test_windowed_sampling_matches_the_whole_law_bit_for_bit(name, request):
    job = request.getfixturevalue(name)
    whole = TickSampler(job, chunk=2048)
    windowed = TickSampler(job, chunk=2048, window_segments=256)
    assert not whole._windowed and windowed._windowed
    assert len(job.plan) > 8 * 256  # many windows, and chunks that cross from one to the next
    got = list(windowed)
    want = list(whole)
    assert [f for f, _ in got] == [f for f, _ in want]
    for (_, a), (_, b) in zip(got, want, strict=True):
        assert _same(np.asarray(a), np.asarray(b))
    # any start (backwards too, as the shaped sampler asks), and rows past the last tick (the end position)
    n = job.plan.n_ticks
    for first in (n // 2, 5, n // 3 + 17, n - 100, n):
        p_w, s_w = windowed.program_positions(first, 2048)
        p, s = whole.program_positions(first, 2048)
        assert _same(p_w, p) and np.array_equal(s_w, s)


def test_window_span_arrays_are_the_padded_slice(blended):
    spans = blended.spans
    first, last, rows = 101, 601, 1024
    sub = slice_spans(spans, first, last)
    want = span_arrays(pad_spans(pad_tables(sub, rows, rows), rows), xp=np)
    got = window_span_arrays(spans, first, last, rows, rows)
    assert len(sub.arcs) and len(sub.polys)
    assert set(got) == set(want)
    for k, v in want.items():
        assert _same(np.asarray(got[k]), v), k


def test_a_window_holds_the_ticks_it_reports(blended):
    plan = blended.plan
    tick = plan.n_ticks // 3
    win = plan.device_window(tick, 300)
    k0 = int(np.searchsorted(plan.first_tick, tick, side="right") - 1)
    assert win.span_first == plan.span[k0] and win.span_last == plan.span[k0 + 299] + 1
    assert win.tick_end == plan.first_tick[k0 + 300] > tick
    arrays = win.law.arrays
    assert np.asarray(arrays["first_tick"]).shape == (300,)
    np.testing.assert_array_equal(np.asarray(arrays["span"]), plan.span[k0 : k0 + 300] - win.span_first)
