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
