"""Pulse-synchronised planning for point-by-point pulsed lasers (in-glass engraving).

Every point is burned by exactly one laser pulse, at whose tick the beam is on the point; every
interval between consecutive pulses lies in the lamp's window (:mod:`.windows`); idle pulses keep
the lamp in its window where the motion needs longer. The planners share one interface
(:class:`~.request.PulseRequest` → :class:`~.request.PulsePlan`):

- ``stop-and-go`` — the old scheme: rest at every point, wait for the free-running pulse;
- ``seed`` — the source documents' per-block look-ahead adjusted to pulse windows;
- ``sync`` — the whole job at once: one spline through the points at pulse instants;
- ``bang`` (default) — constant-acceleration pieces between pulses, durations by greedy sweeps (shorter than
  ``sync`` on every measured job; a machine with ``j_max`` or a galvo head is planned with ``sync``); ``best``
  plans both.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from jaxcnc.errors import SourceError
from jaxcnc.jaxconfig import planning_scope
from jaxcnc.machine import MachineConfig
from jaxcnc.planners.job import outside_travel
from jaxcnc.planners.protocol import machine_limits, request_limits, with_margin
from jaxcnc.planners.pulsed import bang, seed, stop_and_go, sync  # noqa: F401  (register the planners)
from jaxcnc.planners.pulsed.bound import lower_bound_travel
from jaxcnc.planners.pulsed.request import (
    PulsePlan,
    PulseRequest,
    check_repeats,
    get_pulse_planner,
    pulse_planner_names,
    register_pulse_planner,
)
from jaxcnc.planners.pulsed.windows import PulseWindow, pulse_window
from jaxcnc.program import PROGRAM_AXES, PointJob, program_start

DEFAULT_PULSE_PLANNER = "bang"

__all__ = [
    "DEFAULT_PULSE_PLANNER",
    "PlannedPoints",
    "PulsePlan",
    "PulseRequest",
    "PulseWindow",
    "get_pulse_planner",
    "plan_points",
    "pulse_planner_names",
    "pulse_request",
    "pulse_window",
    "register_pulse_planner",
]


@dataclass(frozen=True, eq=False)
class PlannedPoints:
    """A planned point job: the points (burn order), the plan, the machine, what it cost."""

    job: PointJob
    plan: PulsePlan
    machine: MachineConfig
    window: PulseWindow
    plan_wall_s: float

    @property
    def lower_bound_s(self) -> float:
        """Intervals between work pulses × the shortest period the lamp allows."""
        return (len(self.job) - 1) * self.window.shortest_period_s

    @cached_property
    def lower_bound_travel_s(self) -> float:
        """A certified bound that also counts travel across gaps (:mod:`.bound`), at the machine's limits:
        the axes' ``v_max``/``a_max`` and the path limits the planners honour (feed at pulses, rapid).
        Computed once (seconds on clouds with long jump chains)."""
        v_max, a_max, _ = machine_limits(self.machine)
        path = self.machine.path
        return lower_bound_travel(
            self.job.points, self.window, v_max, a_max, feed_mm_s=path.feed, rapid_mm_s=path.rapid
        ).seconds


def pulse_request(job: PointJob, machine: MachineConfig) -> PulseRequest:
    """Check ``job`` against ``machine`` (axes, travel) and build the planners' request."""
    pts = job.points
    names = machine.axis_names
    home = program_start(machine)
    for col, axis in enumerate(PROGRAM_AXES):
        if axis in names:
            continue
        moved = np.flatnonzero(pts[:, col] != home[col])
        if moved.size:
            k = int(moved[0])
            raise SourceError(
                job.file, int(job.line[k]), 0, f"the point needs axis {axis.upper()}, which {machine.name!r} lacks"
            )
    if not job.allow_repeats:  # a point given twice is burned twice: only when asked for
        check_repeats(pts, job.line, job.file, machine.discrete_mm / 4)
    out = outside_travel(pts, pts, machine, tol_mm=0.0)
    if out is not None:
        k, axis, value, ax = out
        raise SourceError(
            job.file,
            int(job.line[k]),
            0,
            f"{axis.upper()} {value:g} mm is outside the travel of machine {machine.name!r} [{ax.min:g}, {ax.max:g}]",
        )
    v_max, a_max, j_max = request_limits(machine)  # the machine's limits less the margin, applied here once
    return PulseRequest(
        points=pts,
        home=home,
        window=pulse_window(machine),
        v_max=v_max,
        a_max=a_max,
        j_max=j_max,
        feed_mm_s=with_margin(machine.path.feed),
        rapid_mm_s=with_margin(machine.path.rapid),
        line=job.line,
        file=job.file,
        smooth=machine.galvo is not None,
    )


def plan_points(job: PointJob, machine: MachineConfig, planner: str = DEFAULT_PULSE_PLANNER) -> PlannedPoints:
    """Plan a point job on a pulsed machine with the named pulse planner."""
    t0 = time.perf_counter()
    req = pulse_request(job, machine)
    with planning_scope():  # sequential sweeps: on the host CPU (see jaxconfig)
        plan = get_pulse_planner(planner)(req)
    _check_travel(plan, machine, job)
    return PlannedPoints(job=job, plan=plan, machine=machine, window=req.window, plan_wall_s=time.perf_counter() - t0)


def _check_travel(plan: PulsePlan, machine: MachineConfig, job: PointJob) -> None:
    lo, hi = plan.trajectory.extents()
    out = outside_travel(lo[None], hi[None], machine)
    if out is not None:
        _, axis, value, ax = out
        raise SourceError(
            job.file,
            0,
            0,
            f"passing through the points, {axis.upper()} swings to {value:.6g} mm, outside the travel "
            f"[{ax.min:g}, {ax.max:g}] of machine {machine.name!r}; move the job away from the edge",
        )
