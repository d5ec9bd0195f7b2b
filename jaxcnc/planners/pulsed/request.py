"""What a pulse planner is asked (:class:`PulseRequest`), what it answers (:class:`PulsePlan`), by name.

A pulse planner is a callable ``(PulseRequest) -> PulsePlan`` registered with
:func:`register_pulse_planner` (or installed through the ``jaxcnc.pulse_planners`` entry-point group,
:mod:`jaxcnc.plugins`); ``jaxcnc plan --planner NAME`` or ``[machine] planner`` on a pulsed machine
chooses it for point jobs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from jaxcnc.errors import PlanningError, SourceError
from jaxcnc.planners.pulsed.trajectory import Trajectory
from jaxcnc.planners.pulsed.windows import PulseWindow
from jaxcnc.plugins import Registry


@dataclass(frozen=True, eq=False)
class PulseRequest:
    """Points to burn in order, from a start position, on a machine's limits.

    Attributes:
        points: ``(n, 3)`` mm, in burn order.
        home: ``(3,)`` where the machine stands at the start (at rest).
        window: the lamp's admissible pulse intervals.
        v_max, a_max, j_max: ``(3,)`` per-axis limits of x, y, z (``inf`` where absent or unset),
            already reduced by the margin (:func:`~jaxcnc.planners.protocol.with_margin`): plan at them.
        feed_mm_s: cap on the path speed between points (the machine's feed, reduced the same way).
        rapid_mm_s: cap on the path speed of the approach from ``home`` (the same).
        line: ``(n,)`` source line of each point, for error messages.
        file: the source.
        smooth: the motion must keep a continuous acceleration (a galvo head's lag compensation, ``[galvo]``,
            takes its second derivative), so planners whose accelerations step (``bang``) defer to ``sync``.
    """

    points: np.ndarray
    home: np.ndarray
    window: PulseWindow
    v_max: np.ndarray
    a_max: np.ndarray
    j_max: np.ndarray
    feed_mm_s: float
    rapid_mm_s: float
    line: np.ndarray
    file: str
    smooth: bool = False

    @property
    def tick_hz(self) -> float:
        return self.window.tick_hz

    def straight(self, d: np.ndarray, cap_mm_s: float | np.ndarray) -> tuple[np.ndarray, ...]:
        """Unit directions, lengths and path limits of straight moves by ``d`` ``(k, 3)``.

        Along a unit direction ``u`` axis ``i`` sees ``v u_i`` and ``a u_i``, so the path
        speed and acceleration may be ``min_i v_max_i/|u_i|`` and ``min_i a_max_i/|u_i|``.
        Returns ``(u (k,3), length (k,), v_path (k,), a_path (k,))``.
        """
        length = np.linalg.norm(d, axis=1)
        u = d / np.where(length > 0, length, 1.0)[:, None]
        au = np.abs(u)
        with np.errstate(divide="ignore"):
            v_path = np.min(np.where(au > 0, self.v_max / au, np.inf), axis=1)
            a_path = np.min(np.where(au > 0, self.a_max / au, np.inf), axis=1)
        v_path = np.minimum(v_path, cap_mm_s)
        a_path = np.where(np.isfinite(a_path), a_path, np.max(self.a_max[np.isfinite(self.a_max)], initial=1.0))
        return u, length, v_path, a_path


def check_repeats(points: np.ndarray, line: np.ndarray, file: str, tol_mm: float) -> None:
    """Refuse a point given twice: two points closer than ``tol_mm`` anywhere in ``points`` ``(n, 3)``.

    Each would be burned by its own pulse: the same spot twice. The pairs are found with a k-d tree
    (:class:`scipy.spatial.cKDTree`, no loop over points), whatever the order, so a job re-ordered by
    ``--reorder`` is refused as the file is. The error names the later line of the first such pair in file
    order and the earlier one; the caller skips this when repeated burns were asked for (``--allow-repeats``).
    ``line``: ``(n,)`` source line of each point.
    """
    from scipy.spatial import cKDTree

    if points.shape[0] < 2:
        return
    pairs = cKDTree(points).query_pairs(tol_mm, output_type="ndarray")
    if pairs.size == 0:
        return
    a, b = line[pairs[:, 0]], line[pairs[:, 1]]
    first, second = np.minimum(a, b), np.maximum(a, b)
    k = int(np.lexsort((first, second))[0])
    i = int(pairs[k, 0] if a[k] == second[k] else pairs[k, 1])
    j = int(pairs[k, 1] if a[k] == second[k] else pairs[k, 0])
    gap_mm = float(np.linalg.norm(points[i] - points[j]))
    raise SourceError(
        file,
        int(second[k]),
        0,
        f"the same point as line {int(first[k])} ({', '.join(f'{c:g}' for c in points[i])}; {gap_mm:.3g} mm apart, "
        f"within a quarter discrete, {tol_mm:g} mm): it would be burned twice; pass --allow-repeats to burn it again",
    )


@dataclass(frozen=True, eq=False)
class PulsePlan:
    """A planned pulsed job: the motion and the pulses.

    Attributes:
        trajectory: the motion, in time.
        work_tick: ``(n,)`` int64, the tick of the pulse that burns point ``i`` (burn order).
        idle_tick: ``(k,)`` int64, ticks of pulses that burn nothing, sorted.
        planner: the planner's name.
        stats: planner-specific figures (iterations, window violations, ...).
    """

    trajectory: Trajectory
    work_tick: np.ndarray
    idle_tick: np.ndarray
    planner: str
    stats: dict

    @property
    def burn_time_s(self) -> float:
        """Time from the first work pulse to the last: what the planners are compared on."""
        return float(self.work_tick[-1] - self.work_tick[0]) / self.trajectory.tick_hz

    @property
    def n_pulses(self) -> int:
        return int(self.work_tick.shape[0] + self.idle_tick.shape[0])


PulsePlanner = Callable[[PulseRequest], PulsePlan]


def _callable(obj):
    if not callable(obj):
        raise TypeError(f"{obj!r} is not a pulse planner (a callable (PulseRequest) -> PulsePlan)")
    return obj


#: Pulse planners by name (entry-point group ``jaxcnc.pulse_planners``).
PULSE_PLANNERS: Registry[PulsePlanner] = Registry(
    "pulse planner", "jaxcnc.pulse_planners", adapt=_callable, error=PlanningError
)


def register_pulse_planner(name: str) -> Callable[[PulsePlanner], PulsePlanner]:
    """Decorator: make a pulse planner available under ``name``."""
    return PULSE_PLANNERS.register(name)


def get_pulse_planner(name: str) -> PulsePlanner:
    return PULSE_PLANNERS.get(name)


def pulse_planner_names() -> list[str]:
    return PULSE_PLANNERS.names()
