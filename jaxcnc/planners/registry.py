"""Planners by name: the extension point for researchers' own velocity planners.

A planner is a :class:`~jaxcnc.planners.protocol.Planner` registered under a name that the command line
(``--planner``), the machine file (``[machine] planner``) and :func:`~jaxcnc.planners.plan_job` choose.
The built-ins register when :mod:`jaxcnc.planners` is imported; third-party planners come from the
``jaxcnc.planners`` entry-point group (:mod:`jaxcnc.plugins`). See ``docs/planners.md``.
"""

from __future__ import annotations

from typing import Any

from jaxcnc.errors import PlanningError
from jaxcnc.planners.protocol import Planner, PlanRequest, as_planner
from jaxcnc.plugins import Registry

__all__ = [
    "DEFAULT_PLANNER",
    "PLANNERS",
    "PlanRequest",
    "Planner",
    "get_planner",
    "planner_names",
    "register_planner",
    "resolve_planner",
]

#: The planner used unless one is named: time-optimal with exact per-axis coupling.
DEFAULT_PLANNER = "topp"
#: Contour planners by name (entry-point group ``jaxcnc.planners``).
PLANNERS: Registry[Planner] = Registry("planner", "jaxcnc.planners", adapt=as_planner, error=PlanningError)


def register_planner(
    name: str, planner: Any = None, *, handles_jerk: bool | None = None, honours_holds: bool | None = None
):
    """Make a planner available under ``name``; without ``planner``, a decorator.

    ``planner`` (or what the decorator decorates): a :class:`Planner` subclass (instantiated without
    arguments), a :class:`Planner` instance, or a plain function ``(PlanRequest) -> Plan``, which is
    wrapped with the capabilities given here (``handles_jerk``, ``honours_holds``; default ``False``).
    The decorator returns what it decorates unchanged.
    """

    def add(obj: Any) -> Any:
        p = as_planner(obj, name)
        if handles_jerk is not None or honours_holds is not None:
            if p is obj or isinstance(obj, type):
                raise TypeError(f"planner {name!r}: declare the capabilities of a Planner class as class attributes")
            p.handles_jerk = bool(handles_jerk)
            p.honours_holds = bool(honours_holds)
        PLANNERS.register(name, p)
        return obj

    return add if planner is None else add(planner)


def get_planner(name: str) -> Planner:
    """The planner registered (or installed through an entry point) under ``name``."""
    return PLANNERS.get(name)


def resolve_planner(planner: str | Planner) -> tuple[str, Planner]:
    """``(name, planner)`` for a planner's name or a :class:`Planner` instance."""
    if isinstance(planner, str):
        return planner, get_planner(planner)
    p = as_planner(planner)
    return p.name or type(p).__name__, p


def planner_names() -> list[str]:
    return PLANNERS.names()
