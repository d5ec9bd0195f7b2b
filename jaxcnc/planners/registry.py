"""Planners by name: the extension point for researchers' own velocity planners.

A planner is a callable ``(PlanRequest) -> Plan`` registered under a name that the command line
(``--planner``) and :func:`~jaxcnc.planners.plan_job` choose. See ``docs/planners.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from jaxcnc.errors import PlanningError
from jaxcnc.geometry.spans import Spans
from jaxcnc.machine import MachineConfig
from jaxcnc.planners.timelaw import Plan


@dataclass(frozen=True, eq=False)
class PlanRequest:
    """What a planner is asked to plan.

    Attributes:
        spans: the path.
        feed_mm_s: ``(n,)`` programmed speed of each span (feed, or the rapid cap for G0).
        dwell_s: ``(n,)`` dwell time of each (point) span.
        stop_before: ``(n,)`` bool, the motion must be at rest where the span starts.
        v_max, a_max: ``(3,)`` limits of the x, y, z axes (``inf`` where the machine lacks one).
        machine: the machine (tick rate, tolerances, ...).
        j_max: optional ``(3,)`` jerk limits of the x, y, z axes (``inf`` where unset or absent).
        hold_caps: optional ``(k, 3)`` rows ``(s_lo, s_hi, v)``: the speed stays ≤ ``v`` mm/s
            between path lengths ``s_lo`` and ``s_hi`` mm from the program start (the jerk stage asks
            for flat speed minima this way; planners that cannot honour it ignore it).
    """

    spans: Spans
    feed_mm_s: np.ndarray
    dwell_s: np.ndarray
    stop_before: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray
    machine: MachineConfig
    j_max: np.ndarray | None = None
    hold_caps: np.ndarray | None = None


Planner = Callable[[PlanRequest], Plan]
#: The planner used unless one is named: time-optimal with exact per-axis coupling.
DEFAULT_PLANNER = "topp"
_PLANNERS: dict[str, Planner] = {}


def register_planner(name: str) -> Callable[[Planner], Planner]:
    """Decorator: make a planner available under ``name``."""

    def deco(fn: Planner) -> Planner:
        _PLANNERS[name] = fn
        return fn

    return deco


def get_planner(name: str) -> Planner:
    try:
        return _PLANNERS[name]
    except KeyError:
        raise PlanningError(f"unknown planner {name!r}; known: {', '.join(sorted(_PLANNERS))}") from None


def planner_names() -> list[str]:
    return sorted(_PLANNERS)
