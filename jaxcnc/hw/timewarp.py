"""Feed hold, resume and feed override by time warp: re-sampling a table at a variable rate.

The player plays table time ``τ`` (in table ticks) at a rate ``r`` per output tick: ``r = 1`` plays
the table as planned, ``r = 0.5`` at half feed, ``r = 0`` holds. Positions are the table's own,
interpolated between rows at ``τ`` — the path is unchanged, so hold and resume are exact.

Changing the rate costs acceleration. With table velocity ``v`` and acceleration ``a`` (per axis,
table time), the played motion has velocity ``v r`` and acceleration ``a r² + v ṙ``. The rate
therefore ramps at ``|ṙ| ≤ min_i (A_i - |a_i| r²) / |v_i|`` — the acceleration the table leaves free
on each axis — times a safety factor, so the played motion stays within the machine's limits. From
a cruise at speed ``v`` a hold takes ``1/ṙ`` seconds and ``v / (2 ṙ)`` of path: :func:`hold_distance`.

NumPy only (this runs on the controller side).
"""

from __future__ import annotations

import numpy as np

from jaxcnc.format import TableFile

SAFETY = 0.9


def hold_distance(v_axis: np.ndarray, a_max: np.ndarray) -> float:
    """Path length (mm) a hold from a cruise with axis speeds ``v_axis`` (mm/s) needs."""
    moving = np.abs(v_axis) > 0
    r_dot = SAFETY * np.min(a_max[moving] / np.abs(v_axis[moving]))
    return float(np.linalg.norm(v_axis)) / (2.0 * r_dot)


class TimeWarp:
    """Plays ``table`` with a commanded rate; ``a_max`` ``(n_axes,)`` mm/s² are the machine's limits."""

    def __init__(self, table: TableFile, a_max: np.ndarray, window: int = 65536):
        self.table, self.a_max = table, np.asarray(a_max, dtype=np.float64)
        self.f = table.header.tick_hz
        self.n = table.n_rows
        self.q = table.header.discrete_mm
        self.tau = 0.0
        self.rate = 1.0
        self.target = 1.0
        self.window = window
        self._lo = -1
        self._buf = np.zeros((0, table.header.n_axes))

    def command(self, rate: float) -> None:
        """Set the commanded rate: 0 = feed hold, 1 = as planned, in between = override."""
        if not 0.0 <= rate <= 1.0:
            raise ValueError("the rate is between 0 (hold) and 1 (as planned)")
        self.target = rate

    @property
    def done(self) -> bool:
        return self.tau >= self.n - 1

    def _rows(self, j: int) -> np.ndarray:
        """Exact positions of rows j-1 .. j+2 (clamped to the table)."""
        if not (self._lo <= j - 1 and j + 3 <= self._lo + len(self._buf)):
            self._lo = max(0, j - 1)
            self._buf = self.table.exact_mm(self._lo, min(self.n, self._lo + self.window))
        idx = np.clip(np.arange(j - 1, j + 3), 0, self.n - 1) - self._lo
        return self._buf[np.clip(idx, 0, len(self._buf) - 1)]

    def step(self) -> np.ndarray:
        """Advance one output tick; the exact position (mm) there."""
        j = min(int(self.tau), self.n - 2) if self.n > 1 else 0
        p = self._rows(j)
        v = (p[2] - p[1]) * self.f  # table velocity on this row interval (mm/s, table time)
        a = (p[2] - 2 * p[1] + p[0]) * self.f**2
        if self.rate != self.target:
            moving = np.abs(v) > 1e-9
            spare = np.maximum(self.a_max - np.abs(a) * self.rate**2, 0.0)
            r_dot = SAFETY * float(np.min(spare[moving] / np.abs(v[moving]))) if moving.any() else np.inf
            step = r_dot / self.f
            new = self.rate + np.clip(self.target - self.rate, -step, step)
        else:
            new = self.rate
        self.tau = min(self.tau + 0.5 * (self.rate + new), self.n - 1.0)
        self.rate = new
        j = min(int(self.tau), self.n - 2) if self.n > 1 else 0
        p = self._rows(j)
        return p[1] + (self.tau - j) * (p[2] - p[1])

    def positions(self, count: int) -> np.ndarray:
        """The next ``count`` (fewer at the end) exact positions ``(m, n_axes)`` mm.

        While the rate ramps, one tick at a time; at a steady rate, a whole chunk at once.
        """
        out, taus = [], []
        while len(out) < count and not self.done and self.rate != self.target:
            out.append(self.step()[None, :])
            taus.append([self.tau])
        left = count - len(out)
        if left > 0 and not self.done and self.rate > 0:
            tau = np.minimum(self.tau + self.rate * np.arange(1, left + 1), self.n - 1.0)
            tau = tau[: int(np.searchsorted(tau, self.n - 1.0, side="left")) + 1]
            j = np.minimum(tau.astype(np.int64), self.n - 2)
            lo, hi = int(j[0]), int(j[-1]) + 2
            p = self.table.exact_mm(lo, hi)
            out.append(p[j - lo] + (tau - j)[:, None] * (p[j - lo + 1] - p[j - lo]))
            taus.append(tau)
            self.tau = float(tau[-1])
        elif left > 0 and not self.done:  # holding: the position does not change
            out.append(np.repeat(self.step()[None, :], left, axis=0))
            taus.append(np.full(left, self.tau))
        self.last_taus = np.concatenate(taus) if taus else np.zeros(0)  # table time of each row returned
        return np.concatenate(out) if out else np.zeros((0, self.table.header.n_axes))

    def rows(self, count: int) -> np.ndarray:
        """The next ``count`` (fewer at the end) quantised rows, int32 discretes."""
        return np.round(self.positions(count) / self.q).astype(np.int32)
