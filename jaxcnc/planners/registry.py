"""Planners by name: the extension point for researchers' own velocity planners.

A planner is a callable ``(spans, feeds) -> Plan`` given the machine, registered under a name
that machine files and the command line can choose. See ``docs/planners.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from jaxcnc.geometry.spans import Spans
from jaxcnc.machine import MachineConfig
from jaxcnc.planners.timelaw import Plan


class Planner(Protocol):
    def __call__(
        self,
        spans: Spans,
        span_feed_mm_s: np.ndarray,
        span_dwell_s: np.ndarray,
        span_stop_before: np.ndarray,
        axis_v_max: np.ndarray,
        axis_a_max: np.ndarray,
        machine: MachineConfig,
    ) -> Plan:
        """Plan the time law of ``spans`` (per-span programmed speed, dwell and forced stops;
        axis limits of shape ``(3,)`` for x, y, z, ``inf`` where the machine lacks the axis)."""
        ...


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
        raise KeyError(f"unknown planner {name!r}; known: {', '.join(sorted(_PLANNERS))}") from None


def planner_names() -> list[str]:
    return sorted(_PLANNERS)
