"""A trajectory given directly in time: per-axis cubic pieces ``p(τ) = c0 + c1 τ + c2 τ² + c3 τ³``.

Pulse-synchronised plans pass through points at pulse instants rather than along a fixed path
at a planned speed, so they are not an ``s(t)`` over spans: each planner writes its motion as
pieces in time. Piece ``k`` starts at (fractional) tick ``start_tick[k]`` and runs until the next
piece starts; ``τ`` is seconds since its start. Straight moves with trapezoidal speed (the
stop-and-go and seed planners) are quadratic pieces; the synchronised planner's spline is cubic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jaxcnc.planners.motion import ramp_times


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Piecewise-cubic motion of the program axes x, y, z.

    Attributes:
        start_tick: ``(n,)`` float64, non-decreasing, ``start_tick[0] == 0``.
        coeffs: ``(n, 4, 3)`` mm, mm/s, mm/s², mm/s³ — ``c0..c3`` of each piece, per axis.
        n_ticks: the last tick of the table (rows ``0..n_ticks``).
        tick_hz: ticks per second.
    """

    start_tick: np.ndarray
    coeffs: np.ndarray
    n_ticks: int
    tick_hz: float

    def __len__(self) -> int:
        return int(self.start_tick.shape[0])

    @property
    def total_time_s(self) -> float:
        return self.n_ticks / self.tick_hz

    def position(self, ticks: np.ndarray) -> np.ndarray:
        """Positions ``(m, 3)`` mm at integer ``ticks`` (NumPy; the tick stage has a JAX kernel)."""
        t = np.asarray(ticks, dtype=np.float64)
        k = np.clip(np.searchsorted(self.start_tick, t, side="right") - 1, 0, len(self) - 1)
        tau = ((t - self.start_tick[k]) / self.tick_hz)[:, None]
        c = self.coeffs[k]
        return c[:, 0] + tau * (c[:, 1] + tau * (c[:, 2] + tau * c[:, 3]))

    def extents(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact per-axis minimum and maximum position ``(3,)`` over the whole motion.

        Candidates per piece: both ends and the roots of ``p'(τ) = c1 + 2 c2 τ + 3 c3 τ²`` inside.
        """
        end = np.append(self.start_tick[1:], self.n_ticks)
        h = np.maximum(end - self.start_tick, 0.0)[:, None] / self.tick_hz
        c1, c2, c3 = self.coeffs[:, 1], self.coeffs[:, 2], self.coeffs[:, 3]
        qa, qb, qc = 3.0 * c3, 2.0 * c2, c1
        disc = np.maximum(qb * qb - 4.0 * qa * qc, 0.0)
        sq = np.sqrt(disc)
        with np.errstate(divide="ignore", invalid="ignore"):
            lin = np.where(qb != 0, -qc / qb, 0.0)
            r1 = np.where(qa != 0, (-qb - sq) / (2.0 * qa), lin)
            r2 = np.where(qa != 0, (-qb + sq) / (2.0 * qa), lin)
        cands = [np.zeros_like(h), h, np.clip(np.nan_to_num(r1), 0.0, h), np.clip(np.nan_to_num(r2), 0.0, h)]
        vals = [self.coeffs[:, 0] + t * (c1 + t * (c2 + t * c3)) for t in cands]
        stack = np.stack(vals)
        return stack.min(axis=(0, 1)), stack.max(axis=(0, 1))


def line_pieces(start_tick: np.ndarray, p0: np.ndarray, u: np.ndarray, v0: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """Coefficients ``(k, 4, 3)`` of straight pieces ``p0 + u (v0 τ + acc τ²/2)``.

    ``p0`` ``(k, 3)`` the start point, ``u`` ``(k, 3)`` the unit direction, ``v0`` and ``acc``
    ``(k,)`` path speed (mm/s) and acceleration (mm/s²) at the start. ``start_tick`` only fixes
    ``k``; it is kept beside the coefficients by the caller.
    """
    k = np.asarray(start_tick).shape[0]
    c = np.zeros((k, 4, 3))
    c[:, 0] = p0
    c[:, 1] = u * v0[:, None]
    c[:, 2] = u * (0.5 * acc)[:, None]
    return c


def ramp_profile(
    v0: np.ndarray, vp: np.ndarray, v1: np.ndarray, length: np.ndarray, a: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Times of a ramp ``v0 → vp``, a cruise at ``vp``, a ramp ``vp → v1`` (each ramp at ``±a``).

    Returns ``(t1, t2, t3, s1, s2)``: the phase durations (s) and the path length at the end of
    the first ramp and of the cruise (:func:`jaxcnc.planners.motion.ramp_times`). ``vp`` must allow
    both ramps within ``length``.
    """
    return ramp_times(v0, vp, v1, length, a)


def move_pieces(
    start_tick: np.ndarray,
    p0: np.ndarray,
    u: np.ndarray,
    v0: np.ndarray,
    vp: np.ndarray,
    v1: np.ndarray,
    length: np.ndarray,
    a: np.ndarray,
    tick_hz: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pieces of straight moves ``(k,)``: three per move (ramp, cruise, ramp), interleaved.

    Returns ``(start_tick (3k,), coeffs (3k, 4, 3), end_tick (k,))``.
    """
    t1, t2, t3, s1, s2 = ramp_profile(v0, vp, v1, length, a)
    f = tick_hz
    starts = np.stack([start_tick, start_tick + t1 * f, start_tick + (t1 + t2) * f], axis=1)
    acc1 = np.sign(vp - v0) * a
    acc3 = np.sign(v1 - vp) * a
    c = np.stack(
        [
            line_pieces(start_tick, p0, u, v0, acc1),
            line_pieces(start_tick, p0 + u * s1[:, None], u, vp, np.zeros_like(vp)),
            line_pieces(start_tick, p0 + u * s2[:, None], u, vp, acc3),
        ],
        axis=1,
    )
    return starts.reshape(-1), c.reshape(-1, 4, 3), start_tick + (t1 + t2 + t3) * f


def rest_pieces(start_tick: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Coefficients ``(k, 4, 3)`` of standing still at ``point`` ``(k, 3)``."""
    c = np.zeros((np.asarray(start_tick).shape[0], 4, 3))
    c[:, 0] = point
    return c
