"""The time-optimal planner ``topp``, the reference planners and corner blends."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxcnc.format import TableFile
from jaxcnc.gcode import parse_gcode
from jaxcnc.geometry import SpanKind, build_spans
from jaxcnc.io.curves import curves_program
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job, register_planner
from jaxcnc.ticks.table import write_table
from jaxcnc.ticks.verify import measure_table
from tests.conftest import make_machine
from tests.helpers import at_s, random_cubic_nurbs, table_of
from tests.test_curves import table_of_program


def _curve_program(feed: float = 100.0):
    curve = random_cubic_nurbs(12, seed=3)
    return curves_program([curve], feed, start=curve[1][0])


def test_topp_within_one_percent_of_casadi_and_inside_the_limits(tmp_path):
    pytest.importorskip("casadi")
    from jaxcnc.planners.casadi_ref import casadi_planner

    m = make_machine(v=100, a=1000)
    prog = _curve_program()
    job, _, meas = table_of_program(prog, m, tmp_path)
    assert meas.ok, meas.violations[:3]
    assert max(meas.max_abs_a["x"], meas.max_abs_a["y"]) > 0.98 * 1000  # the limit is used
    register_planner("test-casadi")(casadi_planner(3000))
    ref = plan_job(prog, m, "test-casadi").plan.total_time_s
    assert job.plan.total_time_s == pytest.approx(ref, rel=0.01)
    assert job.plan.total_time_s < plan_job(prog, m, "lookahead").plan.total_time_s


def test_toppra_agrees_on_a_fine_grid_and_overshoots_on_a_coarse_one(tmp_path):
    pytest.importorskip("toppra")
    from jaxcnc.planners.toppra_ref import toppra_planner

    m = make_machine(v=100, a=1000)
    prog = _curve_program()
    topp = plan_job(prog, m).plan.total_time_s
    register_planner("test-toppra")(toppra_planner(4000, "interpolation"))
    assert plan_job(prog, m, "test-toppra").plan.total_time_s == pytest.approx(topp, rel=0.01)
    register_planner("test-toppra-coarse")(toppra_planner(40, "collocation"))
    job = plan_job(prog, m, "test-toppra-coarse")
    meas = measure_table(TableFile(write_table(job, tmp_path / "c.ticks", progress=False)), m)
    assert not meas.ok  # limits imposed at grid points only: exceeded in between


def test_lines_sequential_scan_equals_associative_scan():
    import jax.numpy as jnp

    from jaxcnc.planners.phaseplane import constraint_rows, solve

    rng = np.random.default_rng(0)
    m = 200
    t = rng.normal(size=(m, 3))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    delta = rng.uniform(0.01, 2.0, m)
    acc = np.tile([1000.0, 800.0, 500.0], (m, 1))
    cap = rng.uniform(0.0, 1e4, m + 1)
    cap[0] = cap[-1] = 0.0  # at rest at both ends, as every plan is
    rows = constraint_rows(*(jnp.asarray(a) for a in (delta, t, 0 * t, t, 0 * t, acc, cap[1:])))
    args = (rows, jnp.asarray(delta), jnp.asarray(np.minimum(cap[:-1], 1e4)), jnp.zeros(()))
    np.testing.assert_allclose(np.asarray(solve(*args, True)), np.asarray(solve(*args, False)), rtol=1e-9, atol=1e-6)


@pytest.mark.parametrize("seed", range(4))
def test_band_forms_equal_the_row_pair_forms_bit_for_bit(seed):
    """Without boxes the passes use the band forms: the same static cap and steps bit for bit, the same plan."""
    import jax
    import jax.numpy as jnp

    from jaxcnc.planners import phaseplane as pp

    rng = np.random.default_rng(seed)
    m = 300
    t_a, t_b = rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    k_a, k_b = rng.normal(size=(m, 3)) * 0.5, rng.normal(size=(m, 3)) * 0.5
    for arr in (t_a, t_b, k_a, k_b):  # axes that do not move, tiny tangents, straight pieces
        arr[rng.random((m, 3)) < 0.15] = 0.0
    t_a[rng.random((m, 3)) < 0.05] = 1e-13
    delta = rng.uniform(0.001, 1.0, m)
    delta[rng.random(m) < 0.05] = 0.0  # points
    acc = np.tile([1000.0, 800.0, np.inf], (m, 1))
    acc[:, 2] = 500.0
    cap = rng.uniform(0.0, 1e4, m + 1)
    cap[0] = cap[-1] = 0.0
    rows = pp.constraint_rows(*(jnp.asarray(a) for a in (delta, t_a, k_a, t_b, k_b, acc, cap[1:])))
    d, cap_a = jnp.asarray(delta), jnp.asarray(cap[:-1])
    np.testing.assert_array_equal(pp.static_cap(*rows, cap_a), pp.static_cap_bands(*rows, cap_a))
    for k_b in (0.0, 1.0, 37.5, 1e4):  # the steps as maps of K_b and x_a
        back = [
            jnp.min(jnp.stack([a * k_b + b for a, b in zip(*f(*rows, d), strict=True)]), 0)
            for f in (pp.backward_pieces, pp.backward_pieces_bands)
        ]
        fwd = [
            jnp.min(jnp.stack([a * k_b + b for a, b in zip(*f(*rows, d), strict=True)]), 0)
            for f in (pp.forward_pieces, pp.forward_pieces_bands)
        ]
        np.testing.assert_array_equal(*back)
        np.testing.assert_array_equal(*fwd)
    # compiled, the two programs may contract a multiply-add differently: the last bit may differ
    solve = jax.jit(pp.solve_window, static_argnames=("curved", "bands"))
    plain = solve(rows, d, cap_a, jnp.zeros(()), True)
    banded = solve(rows, d, cap_a, jnp.zeros(()), True, bands=True)
    np.testing.assert_allclose(banded[0], plain[0], rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(banded[1], plain[1])
    assert float(jnp.max(plain[0])) > 0  # the job moves


def _polyline_distance(p: np.ndarray, pts: np.ndarray) -> np.ndarray:
    d = np.full(len(p), np.inf)
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        ab = b - a
        s = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
        d = np.minimum(d, np.linalg.norm(p - (a + s[:, None] * ab), axis=1))
    return d


@pytest.mark.parametrize("tol", [0.002, 0.02])
def test_corner_blends_stay_within_tolerance_and_limits(tmp_path, tol):
    m = make_machine()
    pts = np.array([[0, 0], [10, 0], [10, 10], [20, 12], [30, 12.5], [0, 0]], float)
    moves = "\n".join(f"X{x:g} Y{y:g}" for x, y in pts[1:])
    text = f"G21 G90 G64 P{tol}\nG1 F3000 " + moves + "\n"
    job, table, meas = table_of(text, m, tmp_path)
    assert meas.ok, meas.violations[:3]
    assert np.any(job.spans.kind == SpanKind.BLEND)  # blended
    dev = _polyline_distance(table.exact_mm()[:, :2], pts)
    assert dev.max() <= tol * (1 + 1e-9)
    assert dev.max() > 0.5 * tol  # the tolerance is used
    exact, _, _ = table_of(text.replace(f"G64 P{tol}", "G61"), m, tmp_path, "exact.ticks")
    assert job.plan.total_time_s < exact.plan.total_time_s
    assert not np.any(exact.spans.kind == SpanKind.BLEND)


def test_blends_are_g2_continuous():
    sp = build_spans(parse_gcode("G64 P0.05\nG1 X10 F600\nX10 Y10\n", "b.ngc"))
    np.testing.assert_allclose(sp.start[1:], sp.end[:-1], atol=1e-12)
    np.testing.assert_allclose(sp.tangent_in[1:], sp.tangent_out[:-1], atol=1e-9)
    blend = np.flatnonzero(sp.kind == SpanKind.BLEND)
    # zero curvature where the blend meets a line: q'' = 0 in the path parameter at both ends
    _, _, d2_in = at_s(sp, blend[:1], np.zeros(1), order=2)
    _, _, d2_out = at_s(sp, blend[-1:], sp.length[blend[-1:]], order=2)
    assert np.abs(d2_in).max() < 1e-9 and np.abs(d2_out).max() < 1e-9


def test_laser_switch_and_exact_stop_keep_the_corner():
    # the power changes at the first corner; the move into the second is programmed under G61 (which says how it ends)
    text = "G64 P0.05\nM3 S100\nG1 X10 F600\nS50\nG61\nX10 Y10\nS50\nX20 Y10\n"
    sp = build_spans(parse_gcode(text, "b.ngc"))
    assert not np.any(sp.kind == SpanKind.BLEND)


def test_near_tangent_chain_keeps_speed_where_acceleration_allows(tmp_path):
    # a 20 mm circle as 600 lines; exact path: each kink is a velocity step within a tick
    r, n = 20.0, 600
    ang = np.linspace(0, 2 * np.pi, n + 1)
    pts = np.c_[r * np.cos(ang), r * np.sin(ang)]
    moves = "\n".join(f"G1 X{x:.6f} Y{y:.6f}" for x, y in pts[1:])
    m = make_machine(v=200, a=1000)
    head = f"G0 X{r} Y0\nF{60 * 200}\n"
    exact, _, meas = table_of(head + "G61\n" + moves + "\n", m, tmp_path, "e.ticks")
    assert meas.ok, meas.violations[:3]
    blended, _, meas_b = table_of(head + "G64 P0.001\n" + moves + "\n", m, tmp_path, "b.ticks")
    assert meas_b.ok, meas_b.violations[:3]
    v_circle = math.sqrt(1000 * r)  # centripetal limit on the true circle
    v_mid = blended.plan.vp[len(blended.plan) // 2]
    assert v_mid > 0.8 * v_circle
    assert blended.plan.total_time_s < exact.plan.total_time_s


@pytest.mark.parametrize("corner_tol", [0.0, 0.01])
def test_windows_plan_the_whole_program(monkeypatch, tmp_path, corner_tol):
    """A program planned in windows of a few hundred intervals is planned as in one piece, and its table holds."""
    import jaxcnc.planners.topp as topp
    from jaxcnc.bench.programs import BENCH_MACHINE, cam_polyline

    prog = cam_polyline(1500)
    m = parse_machine(BENCH_MACHINE + f"corner_tol_mm = {corner_tol}\n", "<bench>")
    whole = plan_job(prog, m).plan
    monkeypatch.setattr(topp, "WINDOW_INTERVALS", 300)
    job = plan_job(prog, m)
    windowed = job.plan
    assert len(windowed) == len(whole) > 3 * 300  # several windows
    assert windowed.n_ticks == whole.n_ticks
    np.testing.assert_allclose(windowed.v0, whole.v0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(windowed.vp, whole.vp, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(windowed.first_tick, whole.first_tick)
    meas = measure_table(TableFile(write_table(job, tmp_path / "w.ticks", progress=False)), m)
    assert meas.ok, meas.violations[:3]
