"""Laser power per tick: M3 constant, M4 scaled with the tool's speed (``docs/laser.md``). NumPy only.

The table's ``laser`` events say when the beam is commanded on (mode 3 or 4, the S value) and off; its
``feed`` events say the programmed feed. The power channel holds, for every tick ``k``, the output during
``[k, k+1)`` (a zero-order hold, as a PWM or DAC output is):

- M3: ``S``;
- M4: ``S · max(floor, curve(v_k / F))`` with ``v_k = |p_{k+1} - p_k| · tick_hz`` the tool's mean speed over that
  tick, ``F`` the programmed feed and ``curve`` the machine's ``[laser] m4_curve_*`` (the identity by default),
  ``v_k / F`` clipped to [0, 1];
- dark otherwise (0).

An M4 tick without a ``feed`` event before it (a table written by a tool that records none) plays as M3.

With the identity curve and no floor the energy a tick deposits, ``S · v_k / F / tick_hz``, is exactly ``S / F``
per millimetre of the distance it covers: M4 burns evenly through corners and accelerations, where constant
power over-burns by ``F / v``. :func:`power_of_rows` is what the writer stores; ``check`` recomputes it from the
table alone (:mod:`jaxcnc.ticks.verify_laser`).
"""

from __future__ import annotations

import numpy as np

from jaxcnc.format import EventKind
from jaxcnc.machine import LaserConfig


def held(events: np.ndarray, kind: int, first: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``aux`` and ``value`` of the latest ``kind`` event at or before each tick ``first .. first+count-1``
    (``(count,)`` each; 0 before the first such event). ``events``: sorted ``EVENT_DTYPE`` records."""
    ev = events[events["kind"] == kind]
    i = np.searchsorted(ev["tick"], np.arange(first, first + count, dtype=np.int64), side="right") - 1
    aux = np.concatenate([[0], ev["aux"].astype(np.int64)])[i + 1]
    value = np.concatenate([[0.0], ev["value"]])[i + 1]
    return aux, value


def m4_fraction(speed_ratio: np.ndarray, laser: LaserConfig) -> np.ndarray:
    """The M4 power fraction at ``speed_ratio = v / F`` (any shape, clipped to [0, 1]): the machine's curve
    (linear between its points; the identity without one), never below ``m4_floor``."""
    r = np.clip(speed_ratio, 0.0, 1.0)
    if laser.m4_curve_speed is not None and laser.m4_curve_power is not None:
        r = np.interp(r, laser.m4_curve_speed, laser.m4_curve_power)
    return np.maximum(r, laser.m4_floor)


def tick_speed_mm_s(p_mm: np.ndarray, tick_hz: float) -> np.ndarray:
    """Mean tool speed over each tick: ``p_mm`` ``(m+1, n_axes)`` positions of ticks ``k .. k+m`` → ``(m,)`` mm/s."""
    return np.linalg.norm(np.diff(p_mm, axis=0), axis=1) * tick_hz


def power_of_rows(p_mm: np.ndarray, events: np.ndarray, first: int, tick_hz: float, laser: LaserConfig) -> np.ndarray:
    """Laser output of ticks ``first .. first+m-1`` from exact positions ``p_mm`` ``(m+1, n_axes)`` of ticks
    ``first .. first+m`` (the last row: the tick after, for the speed over the last tick) and the table's
    events; ``(m,)`` float32 in the S scale."""
    m = p_mm.shape[0] - 1
    mode, s = held(events, EventKind.LASER, first, m)
    _, feed = held(events, EventKind.FEED, first, m)
    v = tick_speed_mm_s(p_mm, tick_hz)
    ratio = np.divide(v, feed, out=np.zeros_like(v), where=feed > 0)
    scale = np.where((mode == 4) & (feed > 0), m4_fraction(ratio, laser), 1.0)
    return np.where(mode != 0, s * scale, 0.0).astype(np.float32)
