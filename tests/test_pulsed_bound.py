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


def feasible_1d(
    x: np.ndarray, ticks: np.ndarray, v_max: float, a_max: float, sub: int = 8, knot_max: float | None = None
) -> bool:
    """Is there a motion through ``x`` ``(k,)`` at pulse gaps ``ticks`` ``(k-1,)`` with |v| <= V, |a| <= A?

    Piecewise-constant acceleration on ``sub`` steps per gap (a real motion: if the LP is feasible, so
    is the job), any speed at the first point (the approach before it is free). Velocity is linear per
    step, so its bound at the step ends is exact. ``knot_max``: also ``|v| <= knot_max`` at every pulse.
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
    cap = np.full(n, v_max)
    if knot_max is not None:
        cap[sub - 1 :: sub] = min(v_max, knot_max)
    v0 = v_max if knot_max is None else min(v_max, knot_max)
    res = linprog(
        np.zeros(n + 1),
        A_ub=np.vstack([vel, -vel]),
        b_ub=np.concatenate([cap, cap]),
        A_eq=pos,
        b_eq=x[1:] - x[0],
        bounds=[(-v0, v0)] + [(-a_max, a_max)] * n,
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
    b = lower_bound_travel(pts, WIN, V, A, feed_mm_s=GLASS.path.feed, rapid_mm_s=GLASS.path.rapid)
    assert planned.lower_bound_s <= b.seconds <= planned.plan.burn_time_s
    assert b.seconds == planned.lower_bound_travel_s  # the report's bound is the path-limited one


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


# --- with the path limits: the path speed at most the feed at every pulse, at most the rapid everywhere ---

FEED, RAPID = GLASS.path.feed, GLASS.path.rapid
#: An octagon inside the circle of radius 1: a motion whose velocity stays in ``r`` × it keeps ``‖v‖ <= r``.
OCTAGON = np.array([[np.cos(t), np.sin(t)] for t in np.arange(8) * np.pi / 4]), np.cos(np.pi / 8)


def path_bound(pts: np.ndarray, **kw):
    return lower_bound_travel(pts, WIN, V, A, feed_mm_s=FEED, rapid_mm_s=RAPID, **kw)


def feasible_2d(xy: np.ndarray, ticks: np.ndarray, sub: int = 6) -> bool:
    """A motion through ``xy`` ``(k, 2)`` at gaps ``ticks`` within the axes' limits and the path limits?

    Piecewise-constant acceleration on ``sub`` steps per gap (both axes), each axis ``|v| <= V``,
    ``|a| <= A``; the velocity in an octagon inside the circle of the feed at every pulse and of the rapid at
    every step end (velocity is linear per step and the octagon convex, so it holds everywhere). A feasible
    answer is a real motion within the limits: an upper bound on the optimum.
    """
    h = np.repeat(ticks / WIN.tick_hz / sub, sub)
    n = h.size
    L = np.tril(np.ones((n, n))) * h[None, :]
    vel = np.hstack([np.ones((n, 1)), L])  # v_j = v0 + L a, j = 1..n
    prev = np.vstack([np.zeros((1, n)), L[:-1]])
    inc = np.hstack([h[:, None], prev * h[:, None] + np.diag(h * h / 2)])
    pos = np.cumsum(inc, axis=0)[sub - 1 :: sub]
    Z = np.zeros_like(vel)
    vx, vy = np.hstack([vel, Z]), np.hstack([Z, vel])  # unknowns: (v0x, ax..., v0y, ay...)
    e0x, e0y = np.zeros(2 * (n + 1)), np.zeros(2 * (n + 1))
    e0x[0], e0y[n + 1] = 1.0, 1.0
    cap = np.full(n, RAPID)
    cap[sub - 1 :: sub] = FEED
    dirs, inner = OCTAGON
    rows, rhs = [], []
    for c, s in dirs:
        rows += [c * vx + s * vy, c * e0x[None] + s * e0y[None]]
        rhs += [cap * inner, [FEED * inner]]
    res = linprog(
        np.zeros(2 * (n + 1)),
        A_ub=np.vstack(rows),
        b_ub=np.concatenate(rhs),
        A_eq=np.vstack([np.hstack([pos, np.zeros_like(pos)]), np.hstack([np.zeros_like(pos), pos])]),
        b_eq=np.concatenate([xy[1:, 0] - xy[0, 0], xy[1:, 1] - xy[0, 1]]),
        bounds=([(-V[0], V[0])] + [(-A[0], A[0])] * n + [(-V[1], V[1])] + [(-A[1], A[1])] * n),
        method="highs",
    )
    return res.status == 0


def stretched_until_feasible(start: np.ndarray, feasible) -> int:
    """Ticks of the first feasible plan found raising ``start`` by a common factor (1 % steps), snapped."""
    scale = 1.0
    while True:
        ticks = snap_up_ticks(np.ceil(start * scale).astype(np.int64), WIN.n_min, WIN.n_max, True)[0]
        if feasible(ticks):
            return int(ticks.sum())
        scale *= 1.01


def best_path_ticks_1d(x: np.ndarray) -> int:
    """A feasible burn time (ticks) of ``x`` along X at the path limits, found by search: an upper bound."""
    start = path_bound(line(x)).gap_ticks
    return stretched_until_feasible(start, lambda t: feasible_1d(x, t, min(V[0], RAPID), A[0], knot_max=FEED))


def test_axis_only_bound_unchanged_and_path_bound_at_least_it():
    """Without the path limits the bound is the axis-only one; with them never lower (they only remove motions)."""
    for name in ("sparse", "text", "short-rows"):
        pts = clouds.HARD_CASES[name]()[:1500]
        axis_only = lower_bound_travel(pts, WIN, V, A)
        assert axis_only.chain_ticks == 0
        assert path_bound(pts).ticks >= axis_only.ticks


@pytest.mark.parametrize("dist", [0.3, 1.0, 2.0, 5.0])
def test_two_points_with_path_limits_the_bound_is_attained(dist):
    """One gap, from at most the feed to at most the feed through at most the rapid: the bound's tent is the
    optimum, and the LP (8 steps of constant acceleration) finds a motion within one admissible block of it."""
    x = np.array([0.0, dist])
    b = path_bound(line(x))
    feasible = best_path_ticks_1d(x)
    axis_only = lower_bound_travel(line(x), WIN, V, A).ticks
    print(f"{dist} mm: axis-only {axis_only}, path limits {b.ticks}, feasible {feasible}")
    assert axis_only <= b.ticks <= feasible <= b.ticks + 4
    if dist >= 1.0:  # the feed at the pulses costs time the axis-only bound cannot see
        assert b.ticks > axis_only


@settings(max_examples=25, deadline=None)
@given(steps=st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=3, max_size=6))
def test_path_bound_never_exceeds_a_feasible_motion_1d(steps):
    """Random 1-D jobs (jump chains included): the path-limited bound (windows and chain) is at most a motion
    the LP finds with the same caps (speed <= feed at every pulse, <= rapid and v_max everywhere)."""
    x = np.concatenate([[0.0], np.cumsum(steps)])
    assert path_bound(line(x)).ticks <= best_path_ticks_1d(x)


@settings(max_examples=15, deadline=None)
@given(steps=st.lists(st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0)), min_size=2, max_size=4))
def test_path_bound_never_exceeds_a_feasible_motion_2d(steps):
    """Random 2-D jobs: the bound (the gaps' own directions, the axes) is at most a motion the LP finds with
    the Euclidean path limits (an octagon inside the feed at pulses and inside the rapid everywhere)."""
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(np.array(steps), axis=0)])
    pts = np.column_stack([50.0 + xy[:, 0], 50.0 + xy[:, 1], np.full(len(xy), 20.0)])
    b = path_bound(pts)
    assert b.ticks <= stretched_until_feasible(b.gap_ticks, lambda t: feasible_2d(xy, t))


def lowered_until_stuck(ticks: np.ndarray, floor: np.ndarray, feasible) -> np.ndarray:
    """Local search from a feasible plan: lower one gap to a shorter admissible count while still feasible."""
    admissible = np.array([n for n in range(WIN.n_min, int(ticks.max()) + 1) if WIN.snap_up(np.int64(n))[0] == n])
    improved = True
    while improved:
        improved = False
        for i in range(ticks.shape[0]):
            for cand in admissible[(admissible < ticks[i]) & (admissible >= floor[i])]:
                trial = ticks.copy()
                trial[i] = cand
                if feasible(trial):
                    ticks, improved = trial, True
                    break
    return ticks


def test_chain_of_jumps_bound_below_a_feasible_motion():
    """A chain of uneven jumps (a sparse row): the bound stays below a motion at the path limits found by
    stretching then lowering gaps one by one (LP); the figures are printed (the bound is 1.23x below here:
    on jump chains it is loose, or the local search is)."""
    x = np.cumsum([0.0, 0.125, 1.5, 0.25, 2.0, 0.125, 0.125, 1.0, 0.5, 1.75, 0.125])
    b = path_bound(line(x))

    def feasible(t):
        return feasible_1d(x, t, min(V[0], RAPID), A[0], knot_max=FEED)

    start = stretched_until_feasible(b.gap_ticks, feasible)
    scale = start / b.gap_ticks.sum()
    ticks = snap_up_ticks(np.ceil(b.gap_ticks * scale * 1.0).astype(np.int64), WIN.n_min, WIN.n_max, True)[0]
    while not feasible(ticks):  # the same plan stretched_until_feasible found
        scale *= 1.01
        ticks = snap_up_ticks(np.ceil(b.gap_ticks * scale).astype(np.int64), WIN.n_min, WIN.n_max, True)[0]
    local = lowered_until_stuck(ticks, b.gap_ticks, feasible)
    print(f"chain: windows {b.window_sum_ticks}, chain {b.chain_ticks}, stretched {start}, lowered {local.sum()}")
    assert b.ticks <= local.sum() <= start


def test_chain_bound_gains_on_the_sparse_cloud():
    """On a sparse cloud's jump chains the chain bound is above the windows' sum (and is the bound)."""
    pts = clouds.HARD_CASES["sparse"]()[:400]
    b = path_bound(pts)
    print(f"sparse[:400]: windows {b.window_sum_ticks}, chain {b.chain_ticks}")
    assert b.chain_ticks > b.window_sum_ticks and b.ticks == b.chain_ticks


@settings(max_examples=200, deadline=None)
@given(
    v0=st.floats(-30.0, 30.0),
    v1=st.floats(-30.0, 30.0),
    h_hi=st.floats(0.02, 0.2),
    frac=st.floats(0.0, 1.0),
    width=st.floats(0.0, 0.004),
)
def test_a_block_tested_at_its_end_covers_every_count_in_it(v0, v1, h_hi, frac, width):
    """The chain tests a block of counts once, at its longest ``h_hi``: for any ``h`` in the block, ``Dmax(h)``
    is at most ``Dmax(h_hi)`` plus the block's width times ``max(0, -max(v0, v1))`` and ``Dmin(h)`` at least
    ``Dmin(h_hi)`` less the width times ``max(0, min(v0, v1))`` (``dDmax/dh >= max(v0, v1)``)."""
    from jaxcnc.planners.pulsed.chain import dmax

    a_max, v_cap = A[0], min(V[0], RAPID)
    h = max(h_hi - frac * width, 1e-6)
    if abs(v1 - v0) > a_max * h:
        return  # not a motion at h
    top = dmax(v0, v1, h_hi, v_cap, a_max) + (h_hi - h) * max(0.0, -max(v0, v1))
    bot = -dmax(-v0, -v1, h_hi, v_cap, a_max) - (h_hi - h) * max(0.0, min(v0, v1))
    assert dmax(v0, v1, h, v_cap, a_max) <= top + 1e-12
    assert -dmax(-v0, -v1, h, v_cap, a_max) >= bot - 1e-12


def test_finer_chain_intervals_never_lower_the_bound():
    """The intervals of 16, 32 and 64 nest, so each stretch's chain only rises with them (sparse, 400 points)."""
    from jaxcnc.planners.pulsed.bound import CHAIN_BLOCK_TICKS, N_CHAIN, _candidates
    from jaxcnc.planners.pulsed.chain import chain_ticks

    pts = clouds.HARD_CASES["sparse"]()[:400]
    gap = path_bound(pts, chain_bins=0).gap_ticks
    d = np.diff(pts[:, 0])
    lo, hi = _candidates(WIN, gap, N_CHAIN, CHAIN_BLOCK_TICKS)
    start = np.zeros(gap.shape, bool)
    start[[0, 150, 151, 300]] = True  # four chains
    runs = [chain_ticks(d, lo, hi, start, WIN.tick_hz, FEED, min(V[0], RAPID), A[0], b) for b in (16, 32, 64)]
    assert all(r.shape == (4,) for r in runs)
    assert np.all(runs[0] <= runs[1]) and np.all(runs[0] <= runs[2])
    assert runs[2].sum() > runs[0].sum()
    for r in runs:  # every chain at least its gaps' own bounds
        assert np.all(r >= np.add.reduceat(gap, [0, 150, 151, 300]))


@settings(max_examples=10, deadline=None)
@given(steps=st.lists(st.floats(0.05, 3.0) | st.floats(-3.0, -0.05), min_size=3, max_size=4))
def test_path_bound_never_above_the_proven_optimum(steps):
    """Random jump chains on one axis at 2 kHz ticks (so that the search proves the optimum): the bound (windows
    and chains at their finest) is at most the least time of any motion of the optimum's model."""
    from jaxcnc.planners.protocol import request_limits
    from jaxcnc.planners.pulsed.optimum import optimum_window
    from jaxcnc.planners.pulsed.windows import PulseWindow

    coarse = PulseWindow(tick_hz=2000.0, pulse_hz=40.0, tolerance=0.05, n_min=48, n_max=52, idle_pulses=True)
    v_req, a_req, _ = request_limits(GLASS)
    pts = line(np.concatenate([[0.0], np.cumsum(steps)]))
    b = lower_bound_travel(pts, coarse, V, A, feed_mm_s=FEED, rapid_mm_s=RAPID)
    opt = optimum_window(pts, coarse, v_req, a_req, b.gap_ticks, feed_mm_s=FEED, rapid_mm_s=RAPID, max_seconds=60)
    assert opt.proven
    assert b.ticks <= opt.ticks.sum()
