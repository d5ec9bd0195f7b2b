"""The exact window reference: a verified motion between the certified bound and the planner's answer."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.bench.pulsed import glass_engraver, program_points
from jaxcnc.io import clouds
from jaxcnc.io.points import PointJob
from jaxcnc.planners.protocol import machine_limits, request_limits, with_margin
from jaxcnc.planners.pulsed import plan_points, pulse_window
from jaxcnc.planners.pulsed.bound import lower_bound_travel
from jaxcnc.planners.pulsed.exact import exact_window, feasible_ticks

pytest.importorskip("casadi")

GLASS = glass_engraver()
WIN = pulse_window(GLASS)
V, A, _ = machine_limits(GLASS)
V_REQ, A_REQ, _ = request_limits(GLASS)
V_REQ = np.minimum(V_REQ, with_margin(GLASS.path.feed))


def window(name: str, start: int, n: int) -> np.ndarray:
    if name == "program":
        return program_points(8, 3000)[start : start + n]
    return clouds.HARD_CASES[name]()[start : start + n]


@pytest.mark.parametrize(
    ("name", "start", "n"), [("short-rows", 0, 24), ("holes", 100, 30), ("sparse", 40, 16), ("program", 60, 30)]
)
def test_sync_at_least_exact_at_least_bound(name, start, n):
    """sync (a plan) >= exact (a verified motion, free end speeds) >= the certified bound; ticks admissible."""
    pts = window(name, start, n)
    planned = plan_points(PointJob(pts, None, np.arange(1, n + 1), name), GLASS, "sync")
    sync_ticks = np.diff(planned.plan.work_tick)
    ex = exact_window(pts, WIN, V_REQ, A_REQ, guess_ticks=sync_ticks)
    bound = lower_bound_travel(pts, WIN, V, A)
    print(
        f"{name}: sync {sync_ticks.sum()} exact {ex.ticks.sum()} relaxed {ex.relaxed_s * 1e4:.0f} bound {bound.ticks}"
    )
    assert bound.ticks <= ex.ticks.sum() <= sync_ticks.sum()
    assert ex.relaxed_s <= ex.seconds * (1 + 1e-6)
    assert np.all(WIN.admissible(ex.ticks, ex.periods))
    assert feasible_ticks(pts - pts[0], ex.ticks, WIN.tick_hz, V_REQ, A_REQ)


def test_two_points_exact_is_the_velocity_bound():
    """One gap with free end speeds: cross at the speed limit, so the optimum is D / V snapped up."""
    pts = np.array([[10.0, 10.0, 10.0], [13.0, 10.0, 10.0]])
    ex = exact_window(pts, WIN, V_REQ, A_REQ)
    want = WIN.snap_up(np.int64(np.ceil(3.0 / V_REQ[0] * WIN.tick_hz)))[0]
    assert ex.ticks.sum() == want


def test_infeasible_durations_are_refused():
    """The verifying linear program says no below the certified bound (the jump needs ~0.15 s) and yes above."""
    pts = np.array([[0.0, 0, 0], [0.125, 0, 0], [3.125, 0, 0], [3.25, 0, 0]])
    assert lower_bound_travel(pts, WIN, V, A).ticks > 238 + 1400 + 238
    assert not feasible_ticks(pts, np.array([238, 1400, 238]), WIN.tick_hz, V_REQ, A_REQ)
    assert feasible_ticks(pts, np.array([238, 2500, 238]), WIN.tick_hz, V_REQ, A_REQ)


# --- at bang's caps: the path speed within the feed at every pulse, within the rapid everywhere ---

V_AXES, _, _ = request_limits(GLASS)
FEED, RAPID = with_margin(GLASS.path.feed), with_margin(GLASS.path.rapid)


def test_path_caps_refused_below_the_path_bound_and_found_at_it():
    """A 2 mm jump between two pulses: the axes alone cross it in two periods, within the feed at both pulses
    it takes three (the path bound's tent); the verifying LP agrees on both sides, in 1-D and diagonally."""
    for direction in (np.array([1.0, 0, 0]), np.array([0.6, 0.8, 0])):
        pts = np.array([[0.0, 0, 0], 2.0 * direction])
        at = lower_bound_travel(pts + 10, WIN, V, A, feed_mm_s=GLASS.path.feed, rapid_mm_s=GLASS.path.rapid).ticks
        assert at == 3 * WIN.n_min and lower_bound_travel(pts + 10, WIN, V, A).ticks == 2 * WIN.n_min
        below = np.array([2 * WIN.n_max])
        assert feasible_ticks(pts, below, WIN.tick_hz, V_AXES, A_REQ)
        assert not feasible_ticks(pts, below, WIN.tick_hz, V_AXES, A_REQ, feed_mm_s=FEED, rapid_mm_s=RAPID)
        assert feasible_ticks(pts, np.array([at + 4]), WIN.tick_hz, V_AXES, A_REQ, feed_mm_s=FEED, rapid_mm_s=RAPID)


@pytest.mark.parametrize(("name", "start", "n"), [("sparse", 40, 16), ("short-rows", 0, 24)])
def test_exact_at_bangs_caps_above_the_path_bound(name, start, n):
    """The reference at bang's caps (descending over period counts) is a verified motion within those caps,
    never below the certified path-limited bound; bang's plan on the window is printed beside it."""
    pts = window(name, start, n)
    planned = plan_points(PointJob(pts, None, np.arange(1, n + 1), name), GLASS, "bang")
    bang_ticks = np.diff(planned.plan.work_tick)
    ex = exact_window(pts, WIN, V_AXES, A_REQ, guess_ticks=bang_ticks, feed_mm_s=FEED, rapid_mm_s=RAPID, descend=True)
    bound = lower_bound_travel(pts, WIN, V, A, feed_mm_s=GLASS.path.feed, rapid_mm_s=GLASS.path.rapid)
    print(f"{name}: bang {bang_ticks.sum()} exact {ex.ticks.sum()} bound {bound.ticks}")
    assert bound.ticks <= ex.ticks.sum()
    assert np.all(WIN.admissible(ex.ticks, ex.periods))
    assert feasible_ticks(pts - pts[0], ex.ticks, WIN.tick_hz, V_AXES, A_REQ, feed_mm_s=FEED, rapid_mm_s=RAPID)
