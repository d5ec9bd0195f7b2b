"""``sync``: the whole job planned at once, every point burned in motion on a pulse.

Unknowns: the number of ticks ``d_i`` between the pulses that burn points ``i`` and ``i+1``.
Given them, the motion is the C² spline through the points at their pulse instants
(:mod:`~jaxcnc.planners.pulsed.spline`, one tridiagonal solve for the whole job) — the beam is on
each point exactly at its pulse and never stops there. Each ``d_i`` must be admissible
(``m n_min <= d_i <= m n_max`` for ``m - 1`` idle pulses, :mod:`~jaxcnc.planners.pulsed.windows`).

The iteration starts from the shortest admissible times (one period per point, the time the feed
needs, or a jump's time under the axes' speed envelope, :func:`_jump_ticks`) and stretches only
where a limit is exceeded. Slowing an interval by a factor ``λ`` divides its velocities by ``λ``,
accelerations by ``λ²``, jerks by ``λ³``; so each interval takes

    λ_i = max( |v|/v_max, sqrt(|a|/a_max), cbrt(|j|/j_max), |v_path|/feed )   (exact maxima)

and, where ``λ_i > 1``, ``d_i ← snap_up(ceil(λ_i d_i))``. Lengthening never shortens another
interval, so the durations only grow and the loop ends when every limit holds: a fixed point
reached in a handful of whole-job passes (``lax.while_loop``, one compiled program per size
bucket). Around the approach from the start position and the stop after the last point the
times are free (no pulses there).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size
from jaxcnc.errors import PlanningError, SourceError
from jaxcnc.planners.pulsed.bound import tent_time_s
from jaxcnc.planners.pulsed.request import PulsePlan, PulseRequest, register_pulse_planner
from jaxcnc.planners.pulsed.spline import cubic_coefficients, interval_extremes, spline_moments
from jaxcnc.planners.pulsed.trajectory import Trajectory
from jaxcnc.planners.pulsed.windows import snap_up_ticks

#: Stretch a little beyond the measured factor so the loop does not creep up one tick at a time.
OVERSHOOT = 1.002
MAX_ITERATIONS = 200


def _stretch_factor(t_s, y, n_knots, caps, v_max, a_max, j_max):
    M, y = spline_moments(t_s, y, n_knots)
    c = cubic_coefficients(t_s, y, M)
    ext = interval_extremes(t_s, c, M)
    lam_v = jnp.max(ext["v"] / v_max, axis=1)
    lam_a = jnp.sqrt(jnp.max(ext["a"] / a_max, axis=1))
    lam_j = jnp.cbrt(jnp.max(ext["j"] / j_max, axis=1))
    lam_p = jnp.linalg.norm(ext["v"], axis=1) / caps  # bounds the path speed from above
    return jnp.maximum(jnp.maximum(lam_v, lam_a), jnp.maximum(lam_j, lam_p)), c


@partial(jax.jit, static_argnames=("max_iter",))
def solve_durations(
    d0, y, n_knots, gap, caps, v_max, a_max, j_max, n_min, n_max, idle, tick_hz, max_iter=MAX_ITERATIONS
):
    """Stretch the interval lengths ``d0`` ``(m-1,)`` ticks until the spline keeps every limit.

    ``gap`` ``(m-1,)`` marks intervals between two work pulses (snapped to the pulse windows);
    the others (approach, stop, padding) take any whole number of ticks. Returns
    ``(d, periods, coeffs, iterations, worst λ)``; ``periods`` is 1 outside the gaps.
    """
    real = jnp.arange(d0.shape[0]) < n_knots - 1

    def times(d):
        return jnp.concatenate([jnp.zeros(1), jnp.cumsum(d)]).astype(jnp.float64) / tick_hz

    def body(state):
        d, it, _ = state
        lam, _ = _stretch_factor(times(d), y, n_knots, caps, v_max, a_max, j_max)
        lam = jnp.where(real, lam, 0.0)
        want = jnp.ceil(d * lam * OVERSHOOT).astype(jnp.int64)
        snapped, _ = snap_up_ticks(want, n_min, n_max, idle, jnp)
        d_new = jnp.where(lam > 1.0, jnp.where(gap, snapped, want), d)
        return d_new, it + 1, jnp.max(lam)

    def cond(state):
        _, it, worst = state
        return (worst > 1.0) & (it < max_iter)

    d, it, _ = jax.lax.while_loop(cond, body, (d0, jnp.int64(0), jnp.float64(jnp.inf)))
    m = jnp.where(gap, snap_up_ticks(d, n_min, n_max, idle, jnp)[1], 1)
    lam, c = _stretch_factor(times(d), y, n_knots, caps, v_max, a_max, j_max)
    return d, m, c, it, jnp.max(jnp.where(real, lam, 0.0))


def _jump_ticks(y: np.ndarray, req: PulseRequest) -> np.ndarray:
    """A first guess of each interval's ticks ``(m-1,)`` from the axes' speed envelope (:mod:`.bound`).

    Each axis enters and leaves the move at its neighbours' mean speeds over one shortest period and
    covers the move under ``min(a + A t, b + A (h - t), V)``. Starting a jump at about the time it needs
    keeps the stretching from spreading over its neighbours (it only lengthens intervals), which
    otherwise end with idle pulses on both sides of every hole: −3 to −25 % on the hard-case clouds.
    """
    D = np.abs(np.diff(y, axis=0))
    speed = D / (req.window.n_min / req.tick_hz)
    before = np.minimum(np.vstack([speed[:1], speed[:-1]]), req.v_max)
    after = np.minimum(np.vstack([speed[1:], speed[-1:]]), req.v_max)
    t = np.max(tent_time_s(D, before, after, req.v_max, req.a_max), axis=1)
    return np.ceil(t * req.tick_hz).astype(np.int64)


@register_pulse_planner("sync")
def plan_sync(req: PulseRequest) -> PulsePlan:
    """Plan the whole job as one spline through the points on admissible pulse instants."""
    w, f = req.window, req.tick_hz
    pts = req.points
    n = len(pts)
    # knots: start, a free knot, the points, a free knot, the stop (the last point, at rest)
    y = np.vstack([req.home[None], req.home[None], pts, pts[-1:], pts[-1:]])
    k = y.shape[0]
    size = bucket_size(k)
    y_pad = np.vstack([y, np.repeat(y[-1:], size - k, axis=0)])
    dist = np.linalg.norm(np.diff(y_pad, axis=0), axis=1)
    gap = np.zeros(size - 1, bool)
    gap[2 : n + 1] = True  # interval i (knot i -> i+1) lies between work pulses for i = 2..n
    caps = np.where(np.arange(size - 1) < 2, req.rapid_mm_s, req.feed_mm_s)
    # start from what the speed cap allows, one period at least between pulses; the approach
    # (two intervals) from a rest-to-rest cubic's time sqrt(6 D / a)
    a_min = float(np.min(req.a_max))
    d0 = np.ceil(dist / caps * f).astype(np.int64)
    approach = float(np.linalg.norm(pts[0] - req.home))
    d0[:2] = int(np.ceil(max(np.sqrt(6.0 * approach / a_min), 1.5 * approach / req.rapid_mm_s) * f / 2))
    d0 = np.where(gap, np.maximum(d0, _jump_ticks(y_pad, req)), d0)
    d0 = np.where(gap, w.snap_up(d0)[0], np.maximum(d0, w.n_min))
    d, m, coeffs, iters, worst = solve_durations(
        np.asarray(d0),
        np.asarray(y_pad),
        np.int64(k),
        np.asarray(gap),
        np.asarray(caps),
        np.asarray(req.v_max),
        np.asarray(req.a_max),
        np.asarray(req.j_max),
        np.int64(w.n_min),
        np.int64(w.n_max),
        jnp.bool_(w.idle_pulses),
        np.float64(f),
    )
    d, m, coeffs = (np.asarray(a) for a in jax.device_get((d, m, coeffs)))
    if float(worst) > 1.0:
        raise PlanningError(
            f"{req.file}: the pulse-synchronised plan did not settle in {int(iters)} passes (worst limit factor "
            f"{float(worst):.4f}); please report this job"
        )
    d, m, coeffs = d[: k - 1], m[: k - 1], coeffs[: k - 1]
    too_long = gap[: k - 1] & (d > m * w.n_max)
    if np.any(too_long):
        i = int(np.argmax(np.where(too_long, d, 0)))  # the longest: interval from point i-2 to point i-1
        raise SourceError(
            req.file,
            int(req.line[i - 1]),
            0,
            f"the axes need {d[i] / f * 1e3:.2f} ms to reach this point from the previous one, but without idle "
            f"pulses the lamp allows at most {w.n_max / f * 1e3:.2f} ms between pulses "
            f"({w.pulse_hz:g} Hz, tolerance {w.tolerance:g}); set idle_pulses = true or lower pulse_hz",
        )
    knot = np.concatenate([[0], np.cumsum(d)])
    work = knot[2 : n + 2]
    idle = w.split(work[:-1], np.diff(work), m[2 : n + 1])
    traj = Trajectory(start_tick=knot[:-1].astype(np.float64), coeffs=coeffs, n_ticks=int(knot[-1]), tick_hz=f)
    return PulsePlan(
        trajectory=traj,
        work_tick=work,
        idle_tick=idle,
        planner="sync",
        stats={"iterations": int(iters), "idle_pulses": int(idle.shape[0])},
    )
