"""``topp.grid_excess``: the interior check of a window with blends, compiled, flags what the NumPy check
(:func:`jaxcnc.planners.topp.interior_excess`) flags, and the window monkeypatched to the NumPy check plans the
same."""

from __future__ import annotations

import numpy as np
import pytest

import jaxcnc.planners.topp as topp
from jaxcnc.bench.programs import BENCH_MACHINE, cam_polyline
from jaxcnc.geometry import build_spans
from jaxcnc.geometry.kinds import SpanKind
from jaxcnc.machine import parse_machine
from jaxcnc.planners import PlanRequest, plan_job
from jaxcnc.planners.grid import build_grid, device_spans, interval_counts
from jaxcnc.planners.protocol import coordinate_extent_mm, request_limits
from jaxcnc.planners.topp import BIG
from tests.test_plan_memory import _same_plan

MACHINE = BENCH_MACHINE + "corner_tol_mm = 0.01\n"


def _numpy_check(arrays, grid, out, a_max, axes, first=0, only=None, midpoints=None):
    """What the boxed windows ran before: the NumPy check on every axis (``midpoints``, the compiled check's frames
    made ahead, unused)."""
    acc = np.minimum(np.asarray(a_max), BIG)[None, :] * out["share"][: len(grid), None]
    return topp.interior_excess(arrays, grid, out["x_node"][: len(grid) + 1], acc, first, only)


@pytest.mark.parametrize("only", [None, "arc"])
def test_the_compiled_check_flags_what_the_numpy_check_flags(only):
    """Speeds raised above the plan make some arc intervals exceed their budget inside: both flag the same ones,
    on a window that starts inside the program (its arrays' row 0 a later span)."""
    prog = cam_polyline(1500)
    machine = parse_machine(MACHINE, "<bench>")
    spans = build_spans(prog, 0.01)
    counts = interval_counts(spans)
    first, last = 200, len(spans) - 100
    arrays = device_spans(spans, first, last)
    grid = build_grid(spans, counts, arrays, first, last, pad_to=int(counts[first:last].sum()) + 37)
    assert grid.boxed.any() and (grid.curved & ~grid.boxed).any()
    assert np.all(spans.kind[grid.span[grid.curved & ~grid.boxed]] == SpanKind.ARC)
    n = len(spans)
    v_max, a_max, _ = request_limits(machine, coordinate_extent_mm(spans))
    req = PlanRequest(spans, np.full(n, 100.0), np.zeros(n), np.zeros(n, bool), v_max, a_max, machine)
    facts = topp._ProgramFacts.of(req)
    out = topp._solve_grid(req, facts, grid, 0.0)
    a_max = np.asarray(req.a_max)
    flagged = 0
    for scale in (0.5, 1.0, 1.01, 1.1, 1.5, 3.0):
        scaled = dict(out, x_node=out["x_node"] * scale)
        expected = _numpy_check(arrays, grid, scaled, a_max, facts.axes, first, only)
        got = topp.grid_excess(arrays, grid, scaled, a_max, facts.axes, first, only)
        np.testing.assert_array_equal(got, expected, err_msg=f"scale {scale}")
        flagged += int(expected.sum())
    assert flagged > 50  # the comparison saw intervals flagged, not only clean ones


def test_windows_with_the_numpy_check_plan_the_same(monkeypatch):
    """The CAM contour with blends and arcs, in many windows (some refined): the same plan, bit for bit."""
    prog = cam_polyline(2000)
    machine = parse_machine(MACHINE, "<bench>")
    monkeypatch.setattr(topp, "WINDOW_INTERVALS", 1 << 10)
    compiled = plan_job(prog, machine).plan
    monkeypatch.setattr(topp, "grid_excess", _numpy_check)
    numpy = plan_job(prog, machine).plan
    assert len(compiled) > 5000
    _same_plan(compiled, numpy)
