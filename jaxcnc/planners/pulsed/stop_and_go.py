"""``stop-and-go``: the old scheme the source documents measured, as they describe it.

The lamp free-runs at its nominal period ``T``. The machine moves to a point from rest to rest
along a straight line (a trapezoid, or a triangle when the point is closer than the distance to
reach the feed), raises the strobe, and the next free-running pulse burns the point; only then
does the next move start. Starting on pulse ``k``, a move of ``t`` seconds is burned on pulse
``k + ceil(t/T)``: with points 100–150 µm apart at 300 mm/s² a triangle takes ~41 ms, so every
point costs two periods (the documents: 51–55 ms per point at 40 Hz). Fully vectorised: the
pulse numbers are a cumulative sum.
"""

from __future__ import annotations

import numpy as np

from jaxcnc.planners.motion import rest_to_rest as rest_to_rest_move
from jaxcnc.planners.pulsed.request import PulsePlan, PulseRequest, register_pulse_planner
from jaxcnc.planners.pulsed.trajectory import Trajectory, move_pieces, rest_pieces


def rest_to_rest(req: PulseRequest, start: np.ndarray, end: np.ndarray, cap_mm_s) -> tuple[np.ndarray, ...]:
    """Straight rest-to-rest moves ``start → end`` ``(k, 3)``: ``(u, length, vp, a, t_s)``.

    Peak speed and time from :func:`jaxcnc.planners.motion.rest_to_rest`.
    """
    u, length, v_path, a_path = req.straight(end - start, cap_mm_s)
    vp, t = rest_to_rest_move(v_path, length, a_path)
    return u, length, vp, a_path, t


@register_pulse_planner("stop-and-go")
def plan_stop_and_go(req: PulseRequest) -> PulsePlan:
    """Rest at every point and wait for the next free-running pulse (see the module docstring)."""
    w, f = req.window, req.tick_hz
    start = np.vstack([req.home[None], req.points[:-1]])
    caps = np.full(len(req.points), req.feed_mm_s)
    caps[0] = req.rapid_mm_s
    u, length, vp, a, t = rest_to_rest(req, start, req.points, caps)
    nominal = w.nominal_ticks
    # Periods from one burn to the next. With a nominal period of whole ticks the pulses are
    # exactly k*nominal; otherwise each is rounded to a tick, which may shift it by half a tick.
    slack = 0.0 if float(nominal).is_integer() else 1.0
    periods = np.ceil((t * f + slack) / nominal - 1e-9).astype(np.int64)
    periods = np.maximum(periods, 1)
    k = np.cumsum(periods)  # lamp pulse number that burns point i (pulse 0 fires at tick 0)
    pulse_tick = np.round(k * nominal).astype(np.int64)
    move_start = np.concatenate([[0], pulse_tick[:-1]]).astype(np.float64)
    starts, coeffs, arrive = move_pieces(move_start, start, u, np.zeros_like(vp), vp, np.zeros_like(vp), length, a, f)
    rest = rest_pieces(arrive, req.points)
    n = len(req.points)
    all_starts = np.concatenate([starts.reshape(n, 3), arrive[:, None]], axis=1).reshape(-1)
    all_coeffs = np.concatenate([coeffs.reshape(n, 3, 4, 3), rest[:, None]], axis=1).reshape(-1, 4, 3)
    lamp = np.round(np.arange(k[0], k[-1] + 1) * nominal).astype(np.int64)
    idle = np.setdiff1d(lamp, pulse_tick)
    traj = Trajectory(start_tick=all_starts, coeffs=all_coeffs, n_ticks=int(pulse_tick[-1]), tick_hz=f)
    return PulsePlan(
        trajectory=traj,
        work_tick=pulse_tick,
        idle_tick=idle,
        planner="stop-and-go",
        stats={"periods_per_point": float(np.mean(periods[1:])) if n > 1 else 1.0},
    )
