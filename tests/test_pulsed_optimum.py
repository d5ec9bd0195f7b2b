"""The window optimum by branch and bound: equal to brute force on small windows, between the bound and bang."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from jaxcnc.bench.pulsed import glass_engraver
from jaxcnc.io import clouds
from jaxcnc.io.points import PointJob
from jaxcnc.planners.protocol import machine_limits, request_limits, with_margin
from jaxcnc.planners.pulsed import plan_points, pulse_window
from jaxcnc.planners.pulsed.bound import lower_bound_travel
from jaxcnc.planners.pulsed.exact import feasible_ticks
from jaxcnc.planners.pulsed.optimum import _Model, optimum_window
from jaxcnc.planners.pulsed.windows import PulseWindow

GLASS = glass_engraver()
WIN = pulse_window(GLASS)
V, A, _ = machine_limits(GLASS)
V_REQ, A_REQ, _ = request_limits(GLASS)
FEED, RAPID = with_margin(GLASS.path.feed), with_margin(GLASS.path.rapid)
CAPS = {"feed_mm_s": FEED, "rapid_mm_s": RAPID}


#: The same lamp at a 2 kHz tick rate: 48..52 ticks a period, few enough counts to try every vector.
COARSE = PulseWindow(tick_hz=2000.0, pulse_hz=40.0, tolerance=0.05, n_min=48, n_max=52, idle_pulses=True)


def path_bound(pts: np.ndarray, win: PulseWindow = WIN):
    return lower_bound_travel(pts, win, V, A, feed_mm_s=GLASS.path.feed, rapid_mm_s=GLASS.path.rapid)


def feasible(pts: np.ndarray, ticks, win: PulseWindow = WIN) -> bool:
    return feasible_ticks(pts - pts[0], np.asarray(ticks, np.int64), win.tick_hz, V_REQ, A_REQ, **CAPS)


def admissible_counts(lo: int, hi: int, win: PulseWindow) -> list[int]:
    """Every admissible tick count in ``[lo, hi]`` (any number of periods)."""
    return [n for n in range(lo, hi + 1) if any(win.admissible(n, m) for m in range(1, n // win.n_min + 1))]


def brute_force(pts: np.ndarray, upper: int, win: PulseWindow) -> int | None:
    """The least total of an admissible tick vector at which the verifying LP finds a motion, by enumeration.

    Every admissible vector with each gap at least its own certified bound and a total of at most ``upper``
    is tried in order of its total (no pruning but the certified per-gap bounds). None: none up to ``upper``.
    """
    lo = path_bound(pts, win).gap_ticks
    spare = upper - int(lo.sum())
    choices = [admissible_counts(int(v), int(v) + spare, win) for v in lo]
    vectors = sorted((sum(c), c) for c in itertools.product(*choices) if sum(c) <= upper)
    for total, ticks in vectors:
        if feasible(pts, ticks, win):
            return total
    return None


def line(*xs: float, y: tuple[float, ...] | None = None) -> np.ndarray:
    x = np.asarray(xs, dtype=np.float64)
    yy = np.zeros_like(x) if y is None else np.asarray(y, dtype=np.float64)
    return np.column_stack([x, yy, np.zeros_like(x)]) + 10.0


def test_feasibility_is_not_monotone_in_a_gaps_ticks():
    """Between two jumps at speed a short gap cannot be lengthened at will: 250 ticks pass, 254 do not, so a
    search upward from a lower corner is not exact (why the optimum splits boxes instead)."""
    pts = line(0.0, 1.5, 2.0, 3.5)
    assert feasible(pts, [524, 250, 524])
    assert not feasible(pts, [524, 254, 524])


def test_the_relaxation_at_one_tick_vector_is_the_verifying_lp():
    """With every gap's box a single count, the optimum's relaxation (chord = tangents = the curve) answers as
    feasible_ticks does, in 1-D, 2-D and 3-D, feasible and infeasible vectors alike."""
    rng = np.random.default_rng(3)
    cases = [line(0.0, 1.5, 2.0, 3.5), line(0.0, 0.125, 1.0, 1.1, y=(0.0, 0.0, 0.6, 0.7))]
    cases.append(np.array([[0, 0, 0], [0.125, 0, 0], [0.6, 0.4, 0.25], [0.7, 0.4, 0.25]]) + 10.0)
    seen = set()
    for pts in cases:
        p0 = pts - pts[0]
        model = _Model(p0, WIN.tick_hz, V_REQ, A_REQ, 4, FEED, RAPID)
        for _ in range(12):
            ticks = WIN.snap_up(rng.integers(WIN.n_min, 3 * WIN.n_max, size=len(pts) - 1))[0]
            ok = model.solve(ticks, ticks)[0]
            assert ok == feasible(pts, ticks)
            seen.add(ok)
    assert seen == {True, False}


@pytest.mark.parametrize(
    "pts",
    [
        line(0.0, 1.5, 2.0, 3.5),  # jump, short gap, jump: the non-monotone case
        line(0.0, 0.6, 0.1, y=(0.0, 0.125, 0.25)),  # a row change with a reversal
        line(0.0, 2.0, y=(0.0, 1.5)),  # one diagonal jump
        clouds.HARD_CASES["sparse"]()[40:44],
    ],
    ids=["jump-short-jump", "reversal", "diagonal", "sparse-4"],
)
def test_optimum_equals_brute_force(pts):
    """On 2-4 points the branch and bound's optimum is the least total found by trying every admissible
    vector in order, and at least the certified bound (at 2 kHz ticks, so that every vector can be tried;
    the 10 kHz diagonal jump too)."""
    for win in (COARSE, WIN) if len(pts) == 2 else (COARSE,):
        opt = optimum_window(pts, win, V_REQ, A_REQ, path_bound(pts, win).gap_ticks, **CAPS)
        assert opt.proven
        assert feasible(pts, opt.ticks, win) and np.all(win.admissible(opt.ticks, opt.periods))
        assert brute_force(pts, int(opt.ticks.sum()), win) == opt.ticks.sum()
        assert path_bound(pts, win).ticks <= opt.ticks.sum()


@pytest.mark.slow
@pytest.mark.parametrize(("name", "start", "n"), [("sparse", 40, 16), ("short-rows", 0, 16), ("text", 1974, 16)])
def test_optimum_between_the_bound_and_bang(name, start, n):
    """On hard-case windows: certified bound <= optimum (free ends) <= optimum at rest, and bang's plan of the
    window (from rest to rest; its ticks are the first incumbent where the LP finds them feasible) above the bound
    and within 2 % of the optimum at rest — or below it: bang's two-phase gaps use the whole lens of reachable end
    speeds, which lies partly outside the optimum's 4-step model (the sparse window: 7600 against 7630 ticks;
    short rows 4290 / 4286, text 6118 / 6045: the text window's last two gaps, 786 + 714 against 952 + 476)."""
    pts = clouds.HARD_CASES[name]()[start : start + n]
    planned = plan_points(PointJob(pts, None, np.arange(1, n + 1), name), GLASS, "bang")
    bang_ticks = np.diff(planned.plan.work_tick)
    bound = path_bound(pts)
    opt = optimum_window(pts, WIN, V_REQ, A_REQ, bound.gap_ticks, start_ticks=bang_ticks, **CAPS)
    rest = optimum_window(pts, WIN, V_REQ, A_REQ, bound.gap_ticks, start_ticks=bang_ticks, rest_ends=True, **CAPS)
    print(f"{name}: bang {bang_ticks.sum()} at rest {rest.ticks.sum()} free {opt.ticks.sum()} bound {bound.ticks}")
    assert opt.proven and rest.proven
    assert bound.ticks <= opt.ticks.sum() <= rest.ticks.sum()
    assert bound.ticks <= bang_ticks.sum() <= 1.02 * rest.ticks.sum()
    assert feasible(pts, opt.ticks)
    assert feasible_ticks(pts - pts[0], rest.ticks, WIN.tick_hz, V_REQ, A_REQ, rest_ends=True, **CAPS)
    assert np.all(WIN.admissible(opt.ticks, opt.periods)) and np.all(WIN.admissible(rest.ticks, rest.periods))


def test_window_bench_rows_are_ordered():
    """The bench's window rows (jaxcnc bench pulsed-windows) on a short window: bound <= optimum with free ends
    <= optimum at rest <= bang, each optimum proven."""
    from jaxcnc.bench.pulsed_windows import window_rows

    (row,) = window_rows(8, names=("short-rows",), exact=False)
    assert row["optimum_free_proven"] and row["optimum_rest_proven"]
    assert row["bound_s"] <= row["optimum_free_s"] <= row["optimum_rest_s"] <= row["bang_s"] + 1e-12
