"""``topp``'s windows with boxes (blends): the pieces in five programs (:func:`jaxcnc.planners.topp._box_pieces`)
give what one program of :func:`~jaxcnc.planners.phaseplane.window_pieces` gives, the two-program solve what
:func:`~jaxcnc.planners.phaseplane.solve_window` gives, and the grid's axis-major storage holds its fields."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import jaxcnc.planners.topp as topp
from jaxcnc.bench.programs import BENCH_MACHINE, cam_polyline
from jaxcnc.geometry.kinds import SpanKind
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job
from jaxcnc.planners.grid import ALIGN_BYTES, AXIS_FIELDS, boxes_at, build_grid, device_spans, interval_counts
from jaxcnc.planners.phaseplane import solve_window, window_pieces


@pytest.fixture(scope="module")
def boxed_window():
    """The inputs of :func:`~jaxcnc.planners.topp.plan_grid` for the first window of a blended CAM contour."""
    seen = []
    real = topp.plan_grid

    def spy(g, *args, **kwargs):
        seen.append((g, args, kwargs))
        return real(g, *args, **kwargs)

    topp.plan_grid = spy
    try:
        plan_job(cam_polyline(1500), parse_machine(BENCH_MACHINE + "corner_tol_mm = 0.01\n", "<bench>"))
    finally:
        topp.plan_grid = real
    g, args, kwargs = seen[0]
    assert kwargs["boxed_any"] and g["boxed"].sum() > 1000
    return g, args, kwargs


def _close(a, b) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    assert np.array_equal(np.isinf(a), np.isinf(b))
    fin = np.isfinite(a)
    np.testing.assert_allclose(a[fin], b[fin], rtol=1e-12, atol=1e-300)


def test_box_pieces_are_the_one_program_pieces(boxed_window):
    g, (v_max, a_max, tol, hz, _), kw = boxed_window
    axes, j_max = kw["axes"], kw["j_max"]

    @jax.jit
    def one_program(g):
        c = topp._interval_rows(g, v_max, a_max, tol, hz, axes, j_max)
        laws = topp._law_inputs(c)
        laws["share"] = topp.interval_share(g["at_kink"], topp._margined(g))
        return window_pieces(c["rows"], c["delta"], c["cap_a"], bands=False), laws

    pieces, laws = topp._box_pieces(g, v_max, a_max, tol, hz, axes, j_max)
    ref_pieces, ref_laws = one_program(g)
    for key, ref in ref_pieces.items():
        got = pieces[key]
        if isinstance(ref, list):
            assert len(got) == len(ref) > 0
            for a, b in zip(got, ref, strict=True):
                _close(a, b)
        else:
            _close(got, ref)
    for key, ref in ref_laws.items():
        _close(laws[key], ref)


def test_boxed_plan_grid_solves_as_solve_window(boxed_window):
    """The two-program solve of a boxed window reaches the speeds of the general one-program solve."""
    g, (v_max, a_max, tol, hz, x_start), kw = boxed_window
    out = topp.plan_grid(g, v_max, a_max, tol, hz, x_start, **kw)
    c = topp._interval_rows(g, v_max, a_max, tol, hz, kw["axes"], kw["j_max"])
    x, exact, k0 = solve_window(c["rows"], c["delta"], c["cap_a"], np.zeros(()), True, x_start)
    assert np.max(out["x_node"]) > 100.0  # the contour moves (x = v², mm²/s²)
    _close(out["x_node"], x)
    assert np.array_equal(np.asarray(out["exact"]), np.asarray(exact))
    _close(out["k0"], k0)


def test_grid_fields_are_views_of_the_padded_axis_major_storage():
    spans = plan_job(cam_polyline(300), parse_machine(BENCH_MACHINE + "corner_tol_mm = 0.01\n", "<bench>")).spans
    counts = interval_counts(spans)
    m = int(counts.sum())
    grid = build_grid(spans, counts, pad_to=m + 37)
    box = np.flatnonzero(grid.boxed)
    assert box.size > 100 and np.any(spans.kind == SpanKind.LINE)
    for f in AXIS_FIELDS:
        major = grid.axis_major[f]
        assert major.shape == (3, m + 37) and major.ctypes.data % ALIGN_BYTES == 0
        assert np.shares_memory(getattr(grid, f), major)
        np.testing.assert_array_equal(getattr(grid, f), major[:, :m].T)
        assert not np.any(major[:, m:])  # zero padding, as the compiled programs expect
    boxes = boxes_at(device_spans(spans), grid.span[box], grid.s_start[box], grid.delta[box])
    for f, want in zip((*AXIS_FIELDS, "speed_hi"), boxes, strict=True):
        np.testing.assert_array_equal(getattr(grid, f)[box], want)
    line = np.flatnonzero(spans.kind[grid.span] == SpanKind.LINE)
    np.testing.assert_array_equal(grid.t_a[line], spans.tangent_in[grid.span[line]])
    np.testing.assert_array_equal(grid.t_lo[line], grid.t_a[line])
    assert not np.any(grid.k_a[line])
