"""``seed``: the source documents' per-block method, for comparison.

The points are joined by straight blocks. A look-ahead (the same parallel scans as the contour
planner, exact stops at corners) gives each block's largest final speed. Then, block by block in
program order as a controller would (with the documents' braking check: a block ends no faster than the
next block can stop from): compute the block's trapezoid from the speed it starts with,
count its ticks ``N``; if ``N`` is not admissible for a whole number of pulse periods (the
documents' condition ``N >= n_nom k + n_max_syn``, here: ``k n_min <= N <= k n_max`` with ``k-1``
idle pulses, see :mod:`~jaxcnc.planners.pulsed.windows`), lower the block's final and maximum speed
by a common factor until its time is the next admissible one (bisection), and go on with the
lowered final speed. The approach from the start position has no window. A ``lax.scan``: the
method is sequential by nature, one block's start speed is the previous block's end speed.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.errors import SourceError
from jaxcnc.planners.lookahead import lookahead
from jaxcnc.planners.motion import ramp_times
from jaxcnc.planners.pulsed.request import PulsePlan, PulseRequest, register_pulse_planner
from jaxcnc.planners.pulsed.trajectory import Trajectory, move_pieces
from jaxcnc.planners.pulsed.windows import snap_up_ticks

#: Two block directions closer than this (unit vectors) are collinear: passed without stopping.
COLLINEAR = 1e-9
BISECTION_STEPS = 64


def _block_time(lam, v0, v1_max, v_cap, length, a):
    """Time and speeds of a block whose final and peak speed are ``lam`` times their maxima."""
    reach = 2.0 * a * length  # v1² within v0² ± 2 a L
    v1 = jnp.clip(lam * v1_max, jnp.sqrt(jnp.maximum(v0 * v0 - reach, 0.0)), jnp.sqrt(v0 * v0 + reach))
    mid = 0.5 * (v0 * v0 + v1 * v1)
    lo = jnp.sqrt(jnp.maximum(mid - a * length, 0.0))  # slowest peak that still covers L
    hi = jnp.maximum(jnp.minimum(v_cap, jnp.sqrt(mid + a * length)), lo)
    vp = jnp.clip(lam * v_cap, lo, hi)
    t1, t2, t3, _, _ = ramp_times(v0, vp, v1, length, a, xp=jnp)
    return t1 + t2 + t3, vp, v1


@jax.jit
def _seed_scan(length, a, v_cap, v1_max, free, n_min, n_max, idle, tick_hz):
    def step(v0, blk):
        L, acc, cap, v1m, is_free = blk
        t_fast, _, _ = _block_time(1.0, v0, v1m, cap, L, acc)
        n_fast = jnp.maximum(jnp.ceil(t_fast * tick_hz - 1e-9).astype(jnp.int64), 1)
        n_win, m = snap_up_ticks(n_fast, n_min, n_max, idle, jnp)
        n = jnp.where(is_free, n_fast, n_win)
        target = n.astype(jnp.float64) / tick_hz

        def bisect(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            t_mid, _, _ = _block_time(mid, v0, v1m, cap, L, acc)
            return jnp.where(t_mid > target, mid, lo), jnp.where(t_mid > target, hi, mid)

        lam_lo, lam_hi = jax.lax.fori_loop(0, BISECTION_STEPS, bisect, (jnp.float64(0.0), jnp.float64(1.0)))
        t_res, vp, v1 = _block_time(lam_hi, v0, v1m, cap, L, acc)
        missed = jnp.abs(t_res - target) * tick_hz > 1e-6  # no speed reaches the window
        return v1, (vp, v1, n, jnp.where(is_free, 1, m), missed)

    _, out = jax.lax.scan(step, jnp.float64(0.0), (length, a, v_cap, v1_max, free))
    return out


@register_pulse_planner("seed")
def plan_seed(req: PulseRequest) -> PulsePlan:
    """The documents' per-block pulse-window adjustment (see the module docstring)."""
    w, f = req.window, req.tick_hz
    n = len(req.points)
    start = np.vstack([req.home[None], req.points[:-1]])
    caps = np.full(n, req.feed_mm_s)
    caps[0] = req.rapid_mm_s
    u, length, v_cap, a = req.straight(req.points - start, caps)
    # look-ahead: pass a point moving only where the blocks on both sides are collinear
    collinear = np.max(np.abs(u[1:] - u[:-1]), axis=1) < COLLINEAR
    node_cap = np.concatenate([[0.0], np.where(collinear, np.minimum(v_cap[1:], v_cap[:-1]) ** 2, 0.0), [0.0]])
    x = np.asarray(jax.jit(lookahead)(np.asarray(node_cap), np.asarray(2.0 * a * length)))
    v1_max = np.sqrt(np.minimum(x[1:], v_cap**2))
    # The documents' braking check (S_brake <= S_(i+1)): end no faster than the next block can
    # stop from, so that whatever window the next block needs, slowing down can reach it.
    v1_max[:-1] = np.minimum(v1_max[:-1], np.sqrt(2.0 * a[1:] * length[1:]))
    free = np.zeros(n, bool)
    free[0] = True
    vp, v1, ticks, m, missed = (
        np.asarray(r)
        for r in _seed_scan(
            np.asarray(length),
            np.asarray(a),
            np.asarray(v_cap),
            np.asarray(v1_max),
            np.asarray(free),
            np.int64(w.n_min),
            np.int64(w.n_max),
            jnp.bool_(w.idle_pulses),
            jnp.float64(f),
        )
    )
    if np.any(missed):
        k = int(np.flatnonzero(missed)[0])
        raise SourceError(
            req.file,
            int(req.line[k]),
            0,
            "seed method: no speed lets this block end in a pulse window (it arrives too fast to slow down); "
            "the whole-job planner 'sync' plans such jobs",
        )
    if not w.idle_pulses and np.any(ticks[1:] > w.n_max):
        k = 1 + int(np.flatnonzero(ticks[1:] > w.n_max)[0])
        raise SourceError(
            req.file,
            int(req.line[k]),
            0,
            f"seed method: this block needs {ticks[k] / f * 1e3:.2f} ms but without idle pulses the lamp allows at "
            f"most {w.n_max / f * 1e3:.2f} ms",
        )
    knot = np.concatenate([[0], np.cumsum(ticks)])
    v0 = np.concatenate([[0.0], v1[:-1]])
    starts, coeffs, _ = move_pieces(knot[:-1].astype(np.float64), start, u, v0, vp, v1, length, a, f)
    work = knot[1:]
    idle = w.split(work[:-1], np.diff(work), m[1:])
    traj = Trajectory(start_tick=starts, coeffs=coeffs, n_ticks=int(knot[-1]), tick_hz=f)
    return PulsePlan(
        trajectory=traj,
        work_tick=work,
        idle_tick=idle,
        planner="seed",
        stats={"idle_pulses": int(idle.shape[0]), "stops": int(np.sum(v1[:-1] == 0.0))},
    )
