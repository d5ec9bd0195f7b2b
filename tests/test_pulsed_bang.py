"""The ``bang`` planner: two- and three-phase constant-acceleration gaps, knot speeds by interval propagation."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.bench.pulsed import _check_tables, glass_engraver, program_points
from jaxcnc.io import clouds
from jaxcnc.io.points import PointJob
from jaxcnc.machine import parse_machine
from jaxcnc.planners.pulsed import plan_points
from jaxcnc.planners.pulsed.bang import lens_profile, lens_project, polygon_project, project

GLASS = glass_engraver()


def job(pts: np.ndarray, name: str) -> PointJob:
    return PointJob(pts, None, np.arange(1, len(pts) + 1), name)


@pytest.mark.parametrize("name", ["program", "short-rows", "sparse"])
def test_bang_tables_verified_and_above_the_bound(name):
    """Every table written and checked at every tick (limits, windows, hits); the burn above the bound."""
    pts = program_points(8, 3000) if name == "program" else clouds.HARD_CASES[name]()[:1500]
    planned = plan_points(job(pts, name), GLASS, "bang")
    assert planned.plan.planner == "bang"
    assert _check_tables({"bang": planned}, GLASS) == "bang: ok"
    assert planned.lower_bound_travel_s <= planned.plan.burn_time_s


def test_bang_row_changes_beat_the_spline_on_rows():
    """On a raster solid (long rows, a row change every ~100 points) bang is shorter than sync."""
    pts = program_points(8, 3000)
    bang = plan_points(job(pts, "p8"), GLASS, "bang").plan.burn_time_s
    sync = plan_points(job(pts, "p8"), GLASS, "sync").plan.burn_time_s
    assert bang < sync


def test_best_keeps_the_shorter():
    pts = clouds.HARD_CASES["sparse"]()[:300]
    times = {p: plan_points(job(pts, "s"), GLASS, p).plan.burn_time_s for p in ("sync", "bang", "best")}
    assert times["best"] == min(times["sync"], times["bang"])


def test_jerk_limited_machine_falls_back_to_sync():
    from importlib import resources

    text = resources.files("jaxcnc.data").joinpath("glass-engraver.toml").read_text()
    text = text.replace(
        "a_max = 300.0\nmin = 0.0\nmax = 300.0\n\n[axes.y]",
        "a_max = 300.0\nj_max = 1e5\nmin = 0.0\nmax = 300.0\n\n[axes.y]",
    )
    machine = parse_machine(text, "jerk.toml")
    pts = program_points(8, 200)
    assert plan_points(job(pts, "p"), machine, "bang").plan.planner == "sync"


def test_projection_matches_brute_force():
    """The polygon's closed-form interval of reachable exit speeds equals a dense search over entry/exit pairs."""
    rng = np.random.default_rng(5)
    A, cap = np.array([300.0]), np.array([17.0])
    for _ in range(40):
        D, h = rng.uniform(-0.5, 0.5), rng.uniform(0.02, 0.08)
        lo0 = rng.uniform(-10, 5)
        hi0 = lo0 + rng.uniform(0, 8)
        cruise = bool(rng.random() < 0.5)
        ok, L, U = (
            np.asarray(x)[0]
            for x in polygon_project(np.array([lo0]), np.array([hi0]), np.array([D]), h, A, cap, cap, cruise)
        )
        v0 = np.linspace(lo0, hi0, 401)[:, None]
        v1 = np.linspace(-cap[0], cap[0], 4001)[None]
        m = D / h
        if cruise:
            vc = 4 * m / 3 - (v0 + v1) / 6
            good = (np.abs(vc - v0) <= A * h / 4) & (np.abs(v1 - vc) <= A * h / 4) & (np.abs(vc) <= cap)
        else:
            good = (np.abs(4 * m - 3 * v0 - v1) <= A * h) & (np.abs(-4 * m + v0 + 3 * v1) <= A * h)
            good &= np.abs(2 * m - (v0 + v1) / 2) <= cap
        good &= np.abs(v0) <= cap
        reach = v1[0][good.any(axis=0)]
        assert bool(ok) == (reach.size > 0)
        if reach.size:
            step = 2 * cap[0] / 4000 + (hi0 - lo0) / 400 * 7
            assert abs(reach.min() - L) <= step and abs(reach.max() - U) <= step


def test_lens_projection_matches_brute_force_and_its_profile_realises_it():
    """The lens' closed-form exit interval equals a dense search over pairs meeting ``Dmin <= D <= Dmax`` (the
    exact set of every motion with ``|a| <= A``, integrated numerically here) and the caps; each pair found is
    realised by :func:`lens_profile`: end speed, distance, ``|a| <= A`` and the speed within the cap."""
    rng = np.random.default_rng(0)
    A = 300.0
    for _ in range(40):
        D, h = rng.uniform(-1.5, 1.5), rng.uniform(0.0238, 0.08)
        W, K = rng.uniform(20, 50), rng.uniform(5, 30)
        lo0 = rng.uniform(-K, K)
        hi0 = min(K, lo0 + rng.uniform(0, 10))
        ok, L, U = (float(x) for x in lens_project(np.array(lo0), np.array(hi0), D, h, A, W, K, xp=np))
        xs, ys = np.linspace(lo0, hi0, 21)[:, None], np.linspace(-K, K, 401)[None]
        t = np.linspace(0.0, h, 401)[:, None, None]
        dmax = np.trapezoid(np.minimum(xs + A * t, ys + A * (h - t)), t, axis=0)
        dmin = np.trapezoid(np.maximum(xs - A * t, ys - A * (h - t)), t, axis=0)
        m = D / h
        good = (dmin <= D + 1e-4) & (D <= dmax + 1e-4) & (np.abs(ys - xs) <= A * h)
        good &= (np.abs(2 * m - xs) <= W) & (np.abs(2 * m - ys) <= W) & (np.abs(xs) <= W) & (np.abs(ys) <= W)
        reach = np.broadcast_to(ys, good.shape)[good]
        step = 2 * K / 400 + (hi0 - lo0) / 20 * 3 + 0.05
        if not reach.size or not ok:  # either both empty, or the other's set is a sliver at the tolerance
            assert (not ok or U - L <= step) and (not reach.size or reach.max() - reach.min() <= step)
            continue
        assert abs(reach.min() - L) <= step and abs(reach.max() - U) <= step
        for x, y in ((lo0, L), (hi0, U), (0.5 * (lo0 + hi0), 0.5 * (L + U))):
            lo_y, hi_y = (float(z) for z in lens_project(np.array(x), np.array(x), D, h, A, W, K, xp=np)[1:])
            if not lo_y <= y <= hi_y:
                continue
            ts, a1, a2 = lens_profile(np.array(x), np.array(y), np.array(D), np.array(h))
            vs = x + a1 * ts
            assert vs + a2 * (h - ts) == pytest.approx(y, abs=1e-9)
            assert x * ts + a1 * ts**2 / 2 + vs * (h - ts) + a2 * (h - ts) ** 2 / 2 == pytest.approx(D, abs=1e-12)
            assert abs(a1) <= A * (1 + 1e-9) and max(abs(x), abs(vs), abs(y)) <= W * (1 + 1e-9)


def test_sweeps_never_lengthen_and_path_speed_within_feed_at_pulses_and_rapid_between():
    """Each sweep's total is at most the previous one's; the path speed is within the feed at every work
    pulse and within the rapid at every tick (the dark moves between pulses)."""
    from jaxcnc.planners.protocol import with_margin

    pts = clouds.HARD_CASES["sparse"]()[:400]
    plan = plan_points(job(pts, "s"), GLASS, "bang").plan
    passes = plan.stats["pass_ticks"]
    assert all(b <= a for a, b in zip(passes, passes[1:], strict=False))
    traj = plan.trajectory
    ticks = np.arange(traj.n_ticks + 1)
    vel = np.diff(traj.position(ticks), axis=0) * traj.tick_hz  # mean over each tick
    speed = np.linalg.norm(vel, axis=1)
    assert speed.max() <= with_margin(GLASS.path.rapid) * (1 + 1e-9)
    assert speed.max() > with_margin(GLASS.path.feed)  # jumps do use the rapid
    at_pulse = np.maximum(speed[plan.work_tick[1:-1] - 1], speed[plan.work_tick[1:-1]])
    assert at_pulse.max() <= with_margin(GLASS.path.feed) * (1 + 1e-3)


def test_recap_boxes_hold_the_velocities_and_keep_the_path_within_the_cap():
    """Each turned knot box contains its planned velocity, its diagonal is the cap (so every velocity in it
    is within the cap), and it gives the direction of travel more than the isotropic ``F/√3``."""
    from jaxcnc.planners.pulsed.bang import recap

    rng = np.random.default_rng(3)
    F, V = 30.0, np.array([50.0, 50.0, 20.0])
    v = rng.uniform(-1, 1, (500, 3)) * F / np.sqrt(3)
    v[:10] = 0.0
    direction = rng.normal(size=(500, 3))
    direction[:5] = 0.0
    box = recap(v, direction, F, V)
    assert np.all(np.abs(v) <= box * (1 + 1e-12))
    assert np.all(np.linalg.norm(np.minimum(box, F), axis=1) <= F * (1 + 1e-12))
    corners = box[:, None, :] * rng.choice([-1.0, 1.0], (500, 8, 3))
    assert np.linalg.norm(corners, axis=2).max() <= F * (1 + 1e-12)
    along = recap(np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]]), F, V)[0]
    assert along[0] == pytest.approx(F) and along[1] == pytest.approx(0.0)


def test_look_ahead_sets_equal_stepping_through_the_gaps():
    """A knot interval meets the depth-k look-ahead set exactly when projecting it through the next k gaps
    (at their given durations, ending within ``[blo, bhi]``) leaves every axis non-empty."""
    from jaxcnc.planners.pulsed.bang import ahead_sets

    rng = np.random.default_rng(11)
    A, cap = np.full(3, 300.0), np.full(3, 17.0)
    for _ in range(60):
        g = 4
        D = rng.uniform(-0.4, 0.4, (g, 3))
        ticks = rng.integers(238, 600, g)
        cruise = rng.random(g) < 0.3
        capm, capk = np.full((g, 3), 40.0), np.tile(cap, (g + 1, 1))
        blo, bhi = np.full((g + 1, 3), -np.inf), np.full((g + 1, 3), np.inf)
        blo[-1] = bhi[-1] = 0.0
        slo, shi = ahead_sets(D, ticks, cruise, capm, capk, blo, bhi, A, 1e4, depth=3)
        lo = rng.uniform(-15, 10, 3)
        hi = lo + rng.uniform(0, 6, 3)
        for k in (1, 2, 3):
            met = bool(np.all(np.maximum(lo, slo[0, k - 1]) <= np.minimum(hi, shi[0, k - 1]) + 1e-9))
            l, u, ok = lo, hi, True
            for j in range(k):
                okj, l, u = (
                    np.asarray(x) for x in project(l, u, D[j], ticks[j] / 1e4, A, capm[j], capk[j + 1], cruise[j])
                )
                l, u = np.maximum(l, blo[j + 1]), np.minimum(u, bhi[j + 1])
                ok = ok and bool(np.all(okj)) and bool(np.all(l <= u + 1e-9))
            assert met == ok


def test_candidates_admissible_ascending_and_near_the_plan():
    """Every candidate is an admissible gap (some period count), the rows ascend, and a later sweep's
    candidates run from the shortest up to the plan's own count, which is among them."""
    from jaxcnc.planners.pulsed.bang import candidates, near_candidates
    from jaxcnc.planners.pulsed.windows import pulse_window

    w = pulse_window(GLASS)
    rng = np.random.default_rng(2)
    lo = rng.integers(1, 8000, 500)
    c = candidates(lo, w)
    assert np.all(np.diff(c, axis=1) >= 0) and np.all(c >= lo[:, None])

    def admissible(n):
        m = np.arange(1, 1000)[None]
        return np.any((n[..., None] >= m * w.n_min) & (n[..., None] <= m * w.n_max), axis=-1)

    assert np.all(admissible(c))
    prev = c[np.arange(500), rng.integers(0, c.shape[1], 500)]
    near = near_candidates(c[:, 0], prev, w)
    assert np.all(np.diff(near, axis=1) >= 0) and np.all(admissible(near))
    assert np.all(near[:, 0] == c[:, 0]) and np.all(near[:, -1] == prev)


def test_bang_is_the_default_and_a_jerk_machine_gets_sync():
    from jaxcnc.planners.pulsed import DEFAULT_PULSE_PLANNER

    pts = program_points(8, 200)
    assert DEFAULT_PULSE_PLANNER == "bang"
    assert plan_points(job(pts, "p"), GLASS).plan.planner == "bang"


def _window(name: str, n: int) -> np.ndarray:
    cloud = clouds.HARD_CASES[name]()
    first = len(cloud) // 3
    return cloud[first : first + n]


@pytest.mark.parametrize("name", ["short-rows", "text"])
def test_polish_shorter_verified_and_within_a_percent_of_the_window_optimum(name, monkeypatch):
    """The polish (windows re-timed between pinned knot velocities) never lengthens the plan, its table is
    verified at every tick, it stays above the certified bound and within 1 % of the window optimum at rest
    (the LP's 4-step model; the lens lies partly outside it, so ``bang`` may also end below it)."""
    from jaxcnc.planners.pulsed import bang
    from tests.helpers import window_optimum_at_rest

    pts = _window(name, 40)
    planned = plan_points(job(pts, name), GLASS, "bang")
    monkeypatch.setattr(bang, "POLISH_ROUNDS", 0)
    before = plan_points(job(pts, name), GLASS, "bang").plan
    ticks = np.diff(planned.plan.work_tick)
    assert ticks.sum() <= np.diff(before.work_tick).sum()
    assert _check_tables({"bang": planned}, GLASS) == "bang: ok"
    bound, opt = window_optimum_at_rest(pts, ticks, max_seconds=60)
    assert bound <= ticks.sum() <= 1.01 * opt.ticks.sum()
    assert ticks.sum() < np.diff(before.work_tick).sum()  # the polish gains on both windows


def test_polish_windows_keep_every_gap_in_the_model():
    """After :func:`~jaxcnc.planners.pulsed.polish.polish` every gap passes from its knot velocity to the next
    one's in bang's model (a degenerate interval projected through the gap contains the next velocity)."""
    from jaxcnc.planners.pulsed import bang
    from jaxcnc.planners.pulsed.bang import phase_fraction
    from jaxcnc.planners.pulsed.polish import polish
    from tests.helpers import bang_sweeps

    pts = clouds.HARD_CASES["short-rows"]()[:600]
    D, ticks, v, cruise, capm, capk, shortest, A, f, w = bang_sweeps(pts)
    new, v2, q = polish(D, ticks, v, cruise, capm, capk, shortest, A, f, w)
    assert new.sum() < ticks.sum()  # it gains here (jumps between the small spheres)
    assert np.any(q != phase_fraction(cruise, np))
    assert np.all(w.admissible(new, w.snap_up(new)[1]))
    # the motion the table gets: every piece within |a| <= A and each axis' cap, through every point
    work = np.concatenate([[0], np.cumsum(new)])
    starts, c = bang.gap_pieces(pts, D, new, v2, q, work, f)
    ends = np.append(starts[1:], work[-1])
    tau = ((ends - starts) / f)[:, None]
    assert np.all(tau >= -1e-12)
    end_pos = c[:, 0] + c[:, 1] * tau + c[:, 2] * tau**2
    end_vel = c[:, 1] + 2 * c[:, 2] * tau
    last = np.isin(ends, work[1:])  # each gap's last piece ends on the next pulse
    assert last.sum() == len(new) and np.allclose(end_pos[last], pts[1:], atol=1e-9)
    assert np.allclose(end_pos[:-1], c[1:, 0], atol=1e-9) and np.allclose(end_vel[:-1], c[1:, 1], atol=1e-7)
    assert np.all(np.abs(2 * c[:, 2]) <= A * (1 + 1e-7))
    cap = capm[np.searchsorted(work, starts, side="right") - 1]
    assert np.all(np.abs(c[:, 1]) <= cap + 1e-7) and np.all(np.abs(end_vel) <= cap + 1e-7)
    assert np.all(np.abs(v2) <= capk + 1e-7)


@pytest.mark.parametrize("eps", [0.0, 1e-13, 1e-10, -1e-10, 1e-6])
def test_lens_pieces_continuous_when_axes_switch_together(eps):
    """A lens gap whose axes switch at (nearly) the same instant — slivers between the switches dropped — still
    runs through its end point with its end velocity (the sparse cloud once had x's acceleration held past it)."""
    from jaxcnc.planners.pulsed import bang

    f, ticks = 1e4, np.array([254])
    v = np.array([[29.9997, 0.0, 0.0], [29.9997 + eps, 0.0, 0.0]])  # x switches at h/2 (+ a sliver), y and z at h/2
    D = np.array([[0.7, 0.0, 0.0]])
    pts = np.array([[48.3549, 55.1875, 20.125]])
    pts = np.vstack([pts, pts + D])
    work = np.array([1000, 1000 + ticks[0]])
    starts, c = bang.gap_pieces(pts, D, ticks, v, np.array([bang.LENS_Q]), work, f)
    ends = np.append(starts[1:], work[-1])
    tau = ((ends - starts) / f)[:, None]
    end_pos, end_vel = c[:, 0] + c[:, 1] * tau + c[:, 2] * tau**2, c[:, 1] + 2 * c[:, 2] * tau
    assert np.allclose(end_pos[-1], pts[1], atol=1e-9) and np.allclose(end_vel[-1], v[1], atol=1e-6)
    assert np.allclose(end_pos[:-1], c[1:, 0], atol=1e-9) and np.allclose(end_vel[:-1], c[1:, 1], atol=1e-6)
