"""``bang``'s polish: windows re-timed jointly between pinned knot velocities, single and pair windows."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.bench.pulsed import _check_tables, glass_engraver
from jaxcnc.io import clouds
from jaxcnc.io.points import PointJob
from jaxcnc.planners.pulsed import bang, plan_points, polish
from tests.helpers import bang_sweeps, window_optimum_at_rest

GLASS = glass_engraver()


def _each_gap_in_the_model(D, ticks, v, q, capm, capk, A, f) -> bool:
    """Every gap passes from its knot velocity to the next one's in bang's model (a single entry speed
    projected through the gap: the next velocity within the reachable interval, every gap feasible)."""
    ok, L, U = bang.project(v[:-1], v[:-1], D, (ticks / f)[:, None], A, capm, capk[1:], q[:, None], xp=np)
    tol = 1e-7 * (1 + np.abs(v[1:]))
    return bool(np.all(ok) and np.all(L <= v[1:] + tol) and np.all(U >= v[1:] - tol))


def _two_jumps() -> np.ndarray:
    """30 short-rows points from 2000: two 14 mm jumps either side of a one-point row."""
    return clouds.HARD_CASES["short-rows"]()[2000:2030]


def test_pair_windows_make_the_move_across_two_centres():
    """Two 14 mm jumps either side of a one-point row: single windows cannot shorten both jumps while the
    point between them takes an idle pulse; a pair window can. Never longer than without pairs, every gap in
    bang's model after it, and above the certified bound."""
    from jaxcnc.planners.protocol import machine_limits
    from jaxcnc.planners.pulsed.bound import lower_bound_travel

    pts = _two_jumps()
    args = bang_sweeps(pts)
    D, ticks, _, _, capm, capk, _, A, f, w = args
    single = polish.polish(*args, rounds=1, pairs=False)[0]
    new, v2, q = polish.polish(*args)
    assert new.sum() < single.sum() <= ticks.sum()
    assert np.all(w.admissible(new, w.snap_up(new)[1]))
    assert _each_gap_in_the_model(D, new, v2, q, capm, capk, A, f)
    assert np.all(np.abs(v2[[0, -1]]) == 0.0)  # the ends stay at rest
    V, Am, _ = machine_limits(GLASS)
    bound = lower_bound_travel(pts, w, V, Am, feed_mm_s=GLASS.path.feed, rapid_mm_s=GLASS.path.rapid)
    assert bound.ticks <= new.sum()


@pytest.mark.slow
def test_pair_move_within_half_a_percent_of_the_window_optimum():
    """On the two-jump window ``bang`` (with the polish) is verified at every tick and within 0.5 % of the
    proven optimum at rest of the LP's 4-step model (1.028 × before the pair windows; the lens lies partly
    outside that model, so ``bang`` may also end below it)."""
    bound, ticks, opt = _bang_and_optimum(_two_jumps(), "two-jumps", check=True)
    assert bound <= ticks <= 1.005 * opt


@pytest.mark.parametrize(
    "roles", [("E", "N", "C", "N", "E"), ("F", "O", "P", "P", "O", "F"), ("F", "O", "P", "M", "P", "O", "F")]
)
def test_meet_in_the_middle_equals_every_combination_propagated(roles):
    """The polish's meet in the middle finds the same feasible combinations and the same least total as
    propagating every combination through the whole window and testing the pinned exit velocity."""
    pts = clouds.HARD_CASES["sparse"]()[:400]
    D, ticks, v, cruise, capm, capk, first, A, f, w = bang_sweeps(pts)
    q = np.array(bang.phase_fraction(cruise, np), dtype=np.float64)
    K = len(roles)
    gaps = np.arange(3, len(ticks) - K, K)[:, None] + np.arange(K)[None]
    tk, qk = polish.window_candidates(gaps, roles, ticks, q, first, w)
    capk = np.broadcast_to(capk, (len(pts), 3))
    Dw, cmw, ckw = D[gaps], capm[gaps], capk[np.concatenate([gaps, gaps[:, -1:] + 1], axis=1)]
    v_in, v_out = v[gaps[:, 0]], v[gaps[:, -1] + 1]
    total, _, _ = polish.meet(v_in, v_out, Dw, tk, qk, cmw, ckw, A, f)
    ok, full, los, his = polish._forward(v_in, Dw, tk, qk, cmw, ckw, A, f)
    tol = bang.EPS_MM_S * (1 + np.abs(v_out[:, None]))
    ok &= np.all((los[-1] <= v_out[:, None] + tol) & (his[-1] >= v_out[:, None] - tol), axis=-1)
    big = np.iinfo(np.int64).max
    assert np.array_equal(np.sort(total, axis=1), np.sort(np.where(ok, full, big), axis=1))
    assert np.all(np.min(total, axis=1) <= ticks[gaps].sum(axis=1))  # the plan's own counts are a combination
    assert np.any(np.min(total, axis=1) < ticks[gaps].sum(axis=1))  # and some window gains


@pytest.mark.parametrize(("name", "n"), [("sparse", 500), ("short-rows", 600), ("text", 500)])
def test_polish_never_longer_every_gap_in_the_model_and_the_motion_within_limits(name, n):
    """After the polish (both rounds and the pair windows) every gap passes from its knot velocity to the next
    one's in bang's model; the total is never above the sweeps' nor above the polish without pair windows
    and second round; the table's pieces run through every point within ``|a| <= A`` and each axis' cap."""
    pts = clouds.HARD_CASES[name]()[:n]
    args = bang_sweeps(pts)
    D, ticks, _, _, capm, capk, _, A, f, w = args
    single = polish.polish(*args, rounds=1, pairs=False)[0]
    new, v2, q = polish.polish(*args)
    assert new.sum() <= single.sum() <= ticks.sum()
    assert np.all(w.admissible(new, w.snap_up(new)[1]))
    assert _each_gap_in_the_model(D, new, v2, q, capm, capk, A, f)
    work = np.concatenate([[0], np.cumsum(new)])
    starts, c = bang.gap_pieces(pts, D, new, v2, q, work, f)
    ends = np.append(starts[1:], work[-1])
    tau = ((ends - starts) / f)[:, None]
    end_pos = c[:, 0] + c[:, 1] * tau + c[:, 2] * tau**2
    end_vel = c[:, 1] + 2 * c[:, 2] * tau
    last = np.isin(ends, work[1:])
    assert last.sum() == len(new) and np.allclose(end_pos[last], pts[1:], atol=1e-9)
    assert np.allclose(end_pos[:-1], c[1:, 0], atol=1e-9) and np.allclose(end_vel[:-1], c[1:, 1], atol=1e-7)
    assert np.all(np.abs(2 * c[:, 2]) <= A * (1 + 1e-7))
    cap = capm[np.searchsorted(work, starts, side="right") - 1]
    assert np.all(np.abs(c[:, 1]) <= cap + 1e-7) and np.all(np.abs(end_vel) <= cap + 1e-7)


def _window_from_40() -> np.ndarray:
    """16 points of the sparse cloud from point 40: the optimum at rest trades periods among the last gaps."""
    return clouds.HARD_CASES["sparse"]()[40:56]


def _planned_with_polish_args(pts: np.ndarray, monkeypatch):
    """``bang``'s plan of ``pts`` and the arguments (and keywords) it gave the polish."""
    got = {}
    orig = polish.polish

    def spy(*a, **k):
        got["args"], got["kw"] = a, k
        return orig(*a, **k)

    monkeypatch.setattr(polish, "polish", spy)
    planned = plan_points(PointJob(pts, None, np.arange(1, len(pts) + 1), "sparse-40"), GLASS, "bang")
    return planned, got["args"], got["kw"]


def test_end_windows_trade_periods_among_the_last_gaps(monkeypatch):
    """On the sparse window from 40 the end windows shorten the plan (the last two row gaps a period fewer,
    the final gap a period more): never longer than the polish without them, every gap in bang's model, the
    ends at rest, and the table verified at every tick (limits, windows, hits)."""
    pts = _window_from_40()
    planned, args, kw = _planned_with_polish_args(pts, monkeypatch)
    D, ticks, _, _, capm, capk, _, A, f, w = args
    before = polish.polish(*args, **kw, ends=False)[0]
    new, v2, q = polish.polish(*args, **kw)
    assert new.sum() < before.sum() <= ticks.sum()
    assert np.all(w.admissible(new, w.snap_up(new)[1]))
    capk = np.broadcast_to(capk, (len(pts), 3))
    assert _each_gap_in_the_model(D, new, v2, q, capm, capk, A, f)
    assert np.all(np.abs(v2[[0, -1]]) == 0.0)
    assert np.array_equal(np.diff(planned.plan.work_tick), new)
    assert _check_tables({"bang": planned}, GLASS) == "bang: ok"


@pytest.mark.slow
def test_end_windows_within_one_percent_of_the_window_optimum():
    """The sparse window from 40: ``bang`` within 1 % of the proven optimum at rest (1.015 × before the end
    windows; the lens lies partly outside the LP's model, so ``bang`` may also end below it)."""
    bound, ticks, opt = _bang_and_optimum(_window_from_40(), "sparse-40")
    assert bound <= ticks <= 1.01 * opt


def _bang_and_optimum(pts: np.ndarray, name: str, check: bool = False) -> tuple[int, int, int]:
    """``bang`` on ``pts`` alone (its table verified when ``check``) and the proven optimum at rest of the window:
    ``(the gaps' own bounds, bang's ticks, the optimum's ticks)``."""
    planned = plan_points(PointJob(pts, None, np.arange(1, len(pts) + 1), name), GLASS, "bang")
    if check:
        assert _check_tables({"bang": planned}, GLASS) == "bang: ok"
    ticks = np.diff(planned.plan.work_tick)
    bound, opt = window_optimum_at_rest(pts, ticks)
    assert opt.proven
    return bound, int(ticks.sum()), int(opt.ticks.sum())
