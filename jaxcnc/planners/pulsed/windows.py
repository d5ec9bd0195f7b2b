"""Pulse windows: which intervals between two laser pulses the lamp accepts, in whole ticks.

A pulsed laser (10–100 Hz lamp-pumped, in-glass engraving) needs its pump pulses at its nominal
period ``T = 1/pulse_hz`` within a tolerance: every interval between two consecutive pulses lies
in ``[T(1-tol), T(1+tol)]``. Pulses are tick events, so an interval is a whole number of ticks
``n`` with ``n_min = ceil(f T (1-tol)) <= n <= n_max = floor(f T (1+tol))``.

Between two points burned one after the other the controller may fire ``m - 1`` idle pulses
(shutter closed), so the time between the two work pulses may be any ``N`` that splits into ``m``
admissible intervals: ``m n_min <= N <= m n_max``. For small ``m`` these ranges leave gaps
(``m n_max < (m+1) n_min``); :func:`snap_up` gives the shortest admissible time at or above a
wanted one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from jaxcnc.errors import MachineFileError
from jaxcnc.machine import MachineConfig


@dataclass(frozen=True)
class PulseWindow:
    """The admissible pulse intervals of a machine, in ticks.

    Attributes:
        tick_hz: the table's tick rate.
        pulse_hz: the lamp's nominal pulse rate.
        tolerance: allowed relative deviation of an interval from the nominal period.
        n_min, n_max: the shortest and longest admissible interval (whole ticks).
        idle_pulses: whether pulses that burn nothing may be fired.
    """

    tick_hz: float
    pulse_hz: float
    tolerance: float
    n_min: int
    n_max: int
    idle_pulses: bool

    @property
    def nominal_ticks(self) -> float:
        return self.tick_hz / self.pulse_hz

    @property
    def shortest_period_s(self) -> float:
        """The shortest interval the lamp accepts, ``T (1 - tol)`` (not rounded to ticks)."""
        return (1.0 - self.tolerance) / self.pulse_hz

    def snap_up(self, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Shortest admissible time ``>= n`` ticks between two work pulses, and its period count.

        See :func:`snap_up_ticks`; without idle pulses times above ``n_max`` stay as they are
        (the caller reports them).
        """
        return snap_up_ticks(np.asarray(n, dtype=np.int64), self.n_min, self.n_max, self.idle_pulses)

    def admissible(self, n: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Whether ``n`` ticks split into ``m`` admissible intervals."""
        return (n >= m * self.n_min) & (n <= m * self.n_max) & (m >= 1)

    def split(self, start: np.ndarray, n: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Ticks of the idle pulses inside each gap: ``m - 1`` of them, intervals within one tick.

        ``start`` ``(g,)`` is the tick of the work pulse opening each gap, ``n`` its length in
        ticks and ``m`` its number of intervals. Returns the sorted idle-pulse ticks.
        """
        start, n, m = (np.asarray(a, dtype=np.int64) for a in (start, n, m))
        idle = m - 1
        total = int(idle.sum())
        if total == 0:
            return np.zeros(0, np.int64)
        gap = np.repeat(np.arange(len(m)), idle)
        j = np.arange(total) - np.repeat(np.cumsum(idle) - idle, idle) + 1  # 1..m-1 within its gap
        # j-th pulse after floor(j n / m) ticks: consecutive intervals differ by at most one tick
        return start[gap] + (j * n[gap]) // m[gap]


def snap_up_ticks(n, n_min, n_max, idle, xp=np):
    """``(ticks, periods)``: the shortest admissible time ``>= n`` and its number of periods.

    ``m = ceil(n / n_max)`` is the fewest periods that can last ``n`` ticks; with ``m`` periods
    the time is at least ``m n_min``. Nothing shorter is admissible, and for an admissible ``n``
    the result is ``n`` itself with an admissible ``m``. Without idle pulses ``m`` is 1.
    ``xp`` is the array module (``numpy``, or ``jax.numpy`` inside a compiled loop).
    """
    n = xp.maximum(n, 1)
    m = xp.where(idle, -(-n // n_max), xp.ones_like(n))
    return xp.maximum(n, m * n_min), m


def pulse_window(machine: MachineConfig) -> PulseWindow:
    """The pulse window of a machine with ``[laser] mode = "pulsed"``."""
    laser = machine.laser
    if laser.pulse_hz is None:
        raise MachineFileError(machine.source, "laser", "pulsed planning needs pulse_hz")
    nominal = machine.tick_hz / laser.pulse_hz
    # 1e-9 keeps an exact product (250 ticks * 0.95 = 237.5) from rounding across an integer
    n_min = max(1, math.ceil(nominal * (1.0 - laser.tolerance) - 1e-9))
    n_max = math.floor(nominal * (1.0 + laser.tolerance) + 1e-9)
    if n_max < n_min:
        raise MachineFileError(
            machine.source,
            "laser.pulse_hz",
            f"no whole number of ticks at tick_hz {machine.tick_hz:g} lies in the pulse window "
            f"[{nominal * (1 - laser.tolerance):.4g}, {nominal * (1 + laser.tolerance):.4g}] ticks; "
            "raise tick_hz or the tolerance",
        )
    return PulseWindow(
        tick_hz=machine.tick_hz,
        pulse_hz=laser.pulse_hz,
        tolerance=laser.tolerance,
        n_min=n_min,
        n_max=n_max,
        idle_pulses=laser.idle_pulses,
    )
