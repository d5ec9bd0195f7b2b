"""The travel-aware lower bound: never above a true optimum (brute force by linear programming), tight on jumps."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

from jaxcnc.bench.pulsed import glass_engraver, program_points
from jaxcnc.io import clouds
from jaxcnc.io.points import PointJob
from jaxcnc.planners.protocol import machine_limits
from jaxcnc.planners.pulsed import plan_points, pulse_window
from jaxcnc.planners.pulsed.bound import lower_bound_travel, tent_time_s
from jaxcnc.planners.pulsed.windows import snap_up_ticks

GLASS = glass_engraver()
WIN = pulse_window(GLASS)
V, A, _ = machine_limits(GLASS)


def feasible_1d(x: np.ndarray, ticks: np.ndarray, v_max: float, a_max: float, sub: int = 8) -> bool:
    """Is there a motion through ``x`` ``(k,)`` at pulse gaps ``ticks`` ``(k-1,)`` with |v| <= V, |a| <= A?

    Piecewise-constant acceleration on ``sub`` steps per gap (a real motion: if the LP is feasible, so
    is the job), any speed at the first point (the approach before it is free). Velocity is linear per
    step, so its bound at the step ends is exact.
    """
    h = np.repeat(ticks / WIN.tick_hz / sub, sub)  # step lengths
    n = h.size
    # unknowns: v0, a_1..a_n ; v_j = v0 + sum_{i<=j} a_i h_i ; x_j = x0 + sum (v_{i-1} h_i + a_i h_i^2/2)
    L = np.tril(np.ones((n, n))) * h[None, :]  # v_j - v0 = L @ a
    vel = np.hstack([np.ones((n, 1)), L])
    # position increment of step j: v_{j-1} h_j + a_j h_j^2/2
    prev = np.vstack([np.zeros((1, n)), L[:-1]])
    inc = np.hstack([h[:, None], prev * h[:, None] + np.diag(h * h / 2)])
    pos = np.cumsum(inc, axis=0)[sub - 1 :: sub]  # at the pulses 1..k-1
    res = linprog(
        np.zeros(n + 1),
        A_ub=np.vstack([vel, -vel]),
        b_ub=np.full(2 * n, v_max),
        A_eq=pos,
        b_eq=x[1:] - x[0],
        bounds=[(-v_max, v_max)] + [(-a_max, a_max)] * n,
        method="highs",
    )
    return res.status == 0


def best_ticks_1d(x: np.ndarray, centre: int, v_max: float, a_max: float) -> int:
    """A feasible burn time (ticks) of ``x`` found by search (an upper bound on the optimum).

    Two searches, the shorter wins: every gap at its velocity bound, the ``centre`` gap raised one
    admissible count (4 ticks) at a time until the LP finds a motion (at most 800 steps); and every gap
    stretched by a common factor (slowing all of them down is feasible in the end).
    """
    pts = line(x)
    own = lower_bound_travel(pts, WIN, V, A).gap_ticks
    best = None
    ticks = own.copy()
    for _ in range(800):
        if feasible_1d(x, ticks, v_max, a_max):
            best = int(ticks.sum())
            break
        ticks[centre] = snap_up_ticks(ticks[centre] + 4, WIN.n_min, WIN.n_max, True)[0]
    scale = 1.0
    while True:
        ticks = snap_up_ticks(np.ceil(own * scale).astype(np.int64), WIN.n_min, WIN.n_max, True)[0]
        if best is not None and ticks.sum() >= best:
            return best
        if feasible_1d(x, ticks, v_max, a_max):
            return int(ticks.sum())
        scale *= 1.03


def line(x: np.ndarray) -> np.ndarray:
    return np.column_stack([50.0 + x, np.full_like(x, 50.0), np.full_like(x, 20.0)])


def test_two_points_the_bound_is_the_exact_optimum():
    """One gap: the axis may cross at full speed (the approach is free), so the optimum is D/V snapped."""
    for dist in (0.12, 1.0, 5.0, 13.0):
        x = np.array([0.0, dist])
        b = lower_bound_travel(line(x), WIN, V, A)
        exact = best_ticks_1d(x, 0, V[0], A[0])
        assert b.ticks == exact, (dist, b.ticks, exact)


@pytest.mark.parametrize("hole_mm", [0.5, 1.5, 3.0, 6.0])
def test_hole_in_a_row_bound_below_a_feasible_motion_and_close(hole_mm):
    """A row, a hole, a row: the bound never exceeds a motion the LP proves feasible, and is within 6 %."""
    x = np.concatenate([[0.0, 0.125, 0.25], 0.25 + hole_mm + np.array([0.0, 0.125, 0.25])])
    b = lower_bound_travel(line(x), WIN, V, A)
    feasible = best_ticks_1d(x, 2, V[0], A[0])
    plain = snap_up_ticks(np.int64(np.ceil(hole_mm / V[0] * WIN.tick_hz)), WIN.n_min, WIN.n_max, True)[0]
    print(f"hole {hole_mm} mm: bound {b.ticks} ticks, feasible {feasible}, velocity-only {4 * WIN.n_min + plain}")
    assert b.ticks <= feasible
    assert b.ticks >= 4 * WIN.n_min + plain  # at least the velocity bound
    assert feasible <= 1.06 * b.ticks


@settings(max_examples=25, deadline=None)
@given(
    steps=st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=3, max_size=5),
    centre_frac=st.floats(0.0, 1.0),
)
def test_bound_never_exceeds_a_feasible_motion(steps, centre_frac):
    """Random short 1-D jobs: the bound is at most the time of a motion the LP finds."""
    x = np.concatenate([[0.0], np.cumsum(steps)])
    centre = min(int(centre_frac * len(steps)), len(steps) - 1)
    b = lower_bound_travel(line(x), WIN, V, A)
    assert b.ticks <= best_ticks_1d(x, centre, V[0], A[0])


def test_tent_time_matches_sampled_speed_envelope():
    """The closed form equals the root of the integral of the speed envelope, integrated numerically."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        d, a, b = rng.uniform(0.001, 20.0), rng.uniform(0, 50.0), rng.uniform(0, 50.0)
        t = float(tent_time_s(d, a, b, 50.0, 300.0))
        tt = np.linspace(0.0, t, 20001)
        env = np.minimum(np.minimum(a + 300.0 * tt, b + 300.0 * (t - tt)), 50.0)
        area = float(np.sum((env[1:] + env[:-1]) / 2 * np.diff(tt)))
        assert area == pytest.approx(d, rel=1e-6, abs=1e-9)


def test_bound_is_at_least_the_plain_bound_and_below_sync():
    pts = program_points(8, 3000)
    job = PointJob(pts, None, np.arange(1, len(pts) + 1), "p8")
    planned = plan_points(job, GLASS, "sync")
    assert planned.lower_bound_s <= planned.lower_bound_travel_s <= planned.plan.burn_time_s


@pytest.mark.parametrize("name", sorted(clouds.HARD_CASES))
def test_hard_clouds_bound_between_plain_bound_and_sync(name):
    pts = clouds.HARD_CASES[name]()[:4000]
    job = PointJob(pts, None, np.arange(1, len(pts) + 1), name)
    planned = plan_points(job, GLASS, "sync")
    b = lower_bound_travel(pts, WIN, V, A)
    assert planned.lower_bound_s <= b.seconds <= planned.plan.burn_time_s
    assert b.seconds == planned.lower_bound_travel_s


STL = __import__("pathlib").Path(__file__).resolve().parents[1] / ".." / "shared" / "corpus" / "stl" / "nut.stl"


@pytest.mark.skipif(not STL.is_file(), reason="the shared corpus is absent")
def test_mesh_cloud_points_are_inside_the_mesh():
    """Every sampled point is inside the STL by trimesh's own test; the cloud is a serpentine raster."""
    import trimesh

    pts = clouds.mesh_cloud(STL, size_mm=8.0, seed=1)
    mesh = trimesh.load_mesh(str(STL))
    lo, hi = mesh.bounds
    mesh.apply_translation(-(lo + hi) / 2)
    mesh.apply_scale(8.0 / float(np.max(hi - lo)))
    q = pts - np.asarray(clouds.CENTER_MM)
    sel = np.random.default_rng(0).choice(len(q), 500, replace=False)
    assert mesh.contains(q[sel]).all()
    assert len(pts) > 1000 and len(np.unique(pts, axis=0)) == len(pts)


def test_hard_clouds_have_their_difficulty():
    """Holes and text have long jumps inside rows, short rows have few points per row, sparse gaps are long."""
    for name, min_jump_mm in (("holes", 0.45), ("text", 0.3), ("sparse", 0.3)):
        pts = clouds.HARD_CASES[name]()
        step = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        assert np.mean(step > min_jump_mm) > (0.3 if name == "sparse" else 0.002), name
    pts = clouds.HARD_CASES["short-rows"]()
    new_row = np.abs(np.diff(pts[:, 1])) > 0.05
    assert len(pts) / (new_row.sum() + 1) < 20
