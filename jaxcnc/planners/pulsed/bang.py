"""``hermite``: a C¹ plan whose knot speeds are chosen by interval propagation — fast row changes and jumps.

``sync`` passes one C² spline through the points: the smoothest motion (least ``∫a²``), not the one with
the least peak acceleration, so at a row change (the x axis reverses, y steps 125 µm) and across jumps it
needs about three extra periods. Here each gap is a cubic Hermite piece between the point positions and
*free* knot speeds ``v_g`` (per axis): on gap ``g`` of ``h`` seconds and displacement ``D``

    a(0) h = 6 D/h − 4 v_0 − 2 v_1,   a(h) h = −6 D/h + 2 v_0 + 4 v_1,   (acceleration linear in between)

and the speed, a quadratic, stays inside the hull of its Bézier control values ``v_0, 3 D/h − v_0 − v_1,
v_1``. So ``|a| <= A`` and ``|v| <= V`` on the whole gap are *linear* conditions on the pair ``(v_0, v_1)``:
a convex polygon. A forward scan keeps, per axis, the interval of speeds the knot can have given every
duration chosen so far (the polygon's projection, closed form), and gives each gap the shortest
admissible tick count among its candidates for which every axis' interval stays non-empty; the last knot
must allow rest. A backward scan then picks each knot's speed inside its interval (nearest the mean of
its neighbours' mean speeds). Both are ``lax.scan`` s over the gaps; nothing is sampled.

The motion reverses x and steps y within one period at a row change where the spline needed three
(``y`` wiggles along the row between pulses so it arrives at the row's end moving), and enters each jump
at the speed its neighbours allow. The axes' accelerations step at the knots, so a machine with a jerk
limit is planned with ``sync`` instead; the first point is reached from rest (a straight move from the
start) and the last is left at rest. Caps: each axis ``min(v_max, feed / √3)``, so the path speed stays
within the feed.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size
from jaxcnc.planners.pulsed.request import PulsePlan, PulseRequest, register_pulse_planner
from jaxcnc.planners.pulsed.stop_and_go import rest_to_rest
from jaxcnc.planners.pulsed.trajectory import Trajectory, move_pieces, rest_pieces
from jaxcnc.planners.pulsed.windows import PulseWindow, snap_up_ticks

#: Candidate tick counts per gap: fine steps over the first two period ranges, coarse over the next ones,
#: then a few geometric ones for long jumps.
FINE_STEP_TICKS = 2
COARSE_RANGES = 8
COARSE_PER_RANGE = 5
GEOMETRIC = 8


def candidates(lo: np.ndarray, window: PulseWindow) -> np.ndarray:
    """Admissible tick counts ``(g, C)`` at or above ``lo`` ``(g,)``, ascending per row."""
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    first, m0 = snap_up_ticks(np.asarray(lo, np.int64), n_min, n_max, idle)
    cols = []
    if not idle:
        steps = np.arange(0, n_max - n_min + FINE_STEP_TICKS, FINE_STEP_TICKS)
        return np.minimum(first[:, None] + steps[None], np.maximum(n_max, first[:, None]))
    for r in range(2):  # the first two period ranges, every FINE_STEP_TICKS * m ticks
        m = m0 + r
        start = np.maximum(first, m * n_min) if r == 0 else m * n_min
        k = np.arange(0, (n_max - n_min) // FINE_STEP_TICKS + 1)
        cols.append(np.minimum(start[:, None] + FINE_STEP_TICKS * m[:, None] * k[None], (m * n_max)[:, None]))
    for r in range(2, 2 + COARSE_RANGES):
        m = (m0 + r)[:, None]
        frac = np.linspace(0.0, 1.0, COARSE_PER_RANGE)[None]
        cols.append(np.round(m * n_min + frac * m * (n_max - n_min)).astype(np.int64))
    top = cols[-1][:, -1]
    for r in range(1, GEOMETRIC + 1):
        cols.append(snap_up_ticks(np.ceil(top * 1.3**r).astype(np.int64), n_min, n_max, idle)[0][:, None])
    return np.sort(np.concatenate(cols, axis=1), axis=1)


def _rows(D, h, A, cap, cruise):
    """The gap's linear conditions ``l <= α v0 + β v1 <= u``: four rows, last axis ``(..., 4)``.

    Two phases (``cruise`` false; halves at ``a1``, ``a2``): ``a1 h = 4m − 3v0 − v1``, ``a2 h = −4m + v0 + 3v1``,
    mid speed ``2m − (v0 + v1)/2`` (``m = D/h``). Three (quarter at ``a1``, half cruising at ``v_c``, quarter
    at ``a3``): ``v_c = 4m/3 − (v0 + v1)/6``, ``a1 h/4 = v_c − v0``, ``a3 h/4 = v1 − v_c``.
    """
    m = D / h
    Ah = A * h
    one = jnp.ones_like(m)
    p = jnp.where(cruise, 7.0, 3.0) * one
    alpha = jnp.stack([p, one, one, 0.0 * one], axis=-1)
    beta = jnp.stack([one, p, one, one], axis=-1)
    c = jnp.where(cruise, 8.0 * m, 4.0 * m)
    acc = jnp.where(cruise, 1.5 * Ah, Ah)
    vel = jnp.where(cruise, 6.0 * cap, 2.0 * cap)
    lo = jnp.stack([c - acc, c - acc, c - vel, -cap * one], axis=-1)
    hi = jnp.stack([c + acc, c + acc, c + vel, cap * one], axis=-1)
    return alpha, beta, lo, hi


def project(lo0, hi0, D, h, A, cap, cruise):
    """Speeds ``v1`` reachable from ``v0 ∈ [lo0, hi0]`` over a gap: ``(ok, L, U)``, broadcast.

    Upper limits on ``v1`` are ``(u_i − α_i v0)/β_i`` and lower ones ``(l_j − α_j v0)/β_j``, all
    non-increasing in ``v0``; ``v0`` is feasible where every upper one is above every lower one (a linear
    condition per pair). Over the feasible ``v0`` interval ``[a, b]`` the largest ``v1`` is at ``a``, the
    smallest at ``b``.
    """
    alpha, beta, l, u = _rows(D, h, A, cap, cruise)
    s = alpha / beta
    # pair (i upper, j lower): v0 (s_j - s_i) >= l_j/β_j - u_i/β_i
    c = s[..., None, :] - s[..., :, None]  # (..., i, j)
    r = l[..., None, :] / beta[..., None, :] - u[..., :, None] / beta[..., :, None]
    safe = jnp.where(c != 0, c, 1.0)
    lower_v0 = jnp.where(c > 0, r / safe, -jnp.inf)
    upper_v0 = jnp.where(c < 0, r / safe, jnp.inf)
    same_ok = jnp.all(jnp.where(c == 0, r <= 1e-12 * (1 + jnp.abs(r)), True), axis=(-2, -1))
    a = jnp.maximum(lo0, jnp.max(lower_v0, axis=(-2, -1)))
    b = jnp.minimum(hi0, jnp.min(upper_v0, axis=(-2, -1)))
    ok = same_ok & (a <= b + 1e-12 * (1 + jnp.abs(b)))
    b = jnp.maximum(a, b)
    U = jnp.min((u - alpha * a[..., None]) / beta, axis=-1)
    L = jnp.max((l - alpha * b[..., None]) / beta, axis=-1)
    return ok & (L <= U + 1e-12 * (1 + jnp.abs(U))), L, jnp.maximum(L, U)


#: Gaps ahead a duration is checked against: the next gaps at their shortest candidates must still fit.
LOOKAHEAD = 2


@jax.jit
def forward(D, cand, last, cruise, A, cap, tick_hz):
    """Forward scan over gaps: ``D`` ``(g, 3)``, ``cand`` ``(g, C)`` ticks, ``last`` ``(g,)`` bool.

    Each gap takes its shortest candidate after which the next :data:`LOOKAHEAD` gaps still fit at their
    shortest candidates (else its shortest candidate that fits itself; else its longest).
    Returns ``(ticks (g,), lo (g+1, 3), hi (g+1, 3), ok (g,))``: each gap's chosen tick count, the speed
    interval at every knot (knot 0 at rest), and whether a candidate fitted.
    """
    g = D.shape[0]
    ahead_D = jnp.stack([jnp.roll(D, -k, axis=0) for k in range(1, LOOKAHEAD + 1)], axis=1)  # (g, L, 3)
    ahead_c = jnp.stack([jnp.roll(cruise, -k, axis=0) for k in range(1, LOOKAHEAD + 1)], axis=1)
    ahead_h = jnp.stack([jnp.roll(cand[:, 0], -k) for k in range(1, LOOKAHEAD + 1)], axis=1) / tick_hz
    idx = jnp.arange(g)
    ahead_real = jnp.stack([idx + k < g for k in range(1, LOOKAHEAD + 1)], axis=1)
    ahead_real &= jnp.cumsum(jnp.stack([jnp.roll(last, -k) for k in range(0, LOOKAHEAD)], axis=1), axis=1) == 0

    def step(state, x):
        lo0, hi0 = state
        d, c, is_last, cr, ad, ac, ah, areal = x
        h = c.astype(jnp.float64)[:, None] / tick_hz  # (C, 1)
        ok, L, U = project(lo0[None], hi0[None], d[None], h, A[None], cap[None], cr)  # (C, 3)
        ok = ok & (~is_last | ((L <= 0.0) & (U >= 0.0)))
        fit = jnp.all(ok, axis=1)
        good, lk, uk = fit, L, U
        for k in range(LOOKAHEAD):
            okk, lk, uk = project(lk, uk, ad[k][None], ah[k], A[None], cap[None], ac[k])
            good = good & (~areal[k] | jnp.all(okk, axis=1))
        k = jnp.where(jnp.any(good), jnp.argmax(good), jnp.where(jnp.any(fit), jnp.argmax(fit), c.shape[0] - 1))
        L, U = L[k], U[k]
        L = jnp.where(is_last, 0.0, L)
        U = jnp.where(is_last, 0.0, U)
        return (L, U), (c[k], L, U, jnp.any(fit))

    z = jnp.zeros(D.shape[1])
    _, (ticks, L, U, ok) = jax.lax.scan(step, (z, z), (D, cand, last, cruise, ahead_D, ahead_c, ahead_h, ahead_real))
    return ticks, jnp.concatenate([z[None], L]), jnp.concatenate([z[None], U]), ok


@jax.jit
def backward(D, ticks, cruise, lo, hi, A, cap, tick_hz):
    """Backward scan: each knot's speed ``(g+1, 3)`` inside its interval and fitting the gap after it."""
    h = ticks.astype(jnp.float64)[:, None] / tick_hz
    mean = D / h
    pref = jnp.concatenate([jnp.zeros((1, D.shape[1])), 0.5 * (mean[:-1] + mean[1:]), jnp.zeros((1, D.shape[1]))])

    def step(v1, x):
        d, hh, cr, l0, h0, p = x
        alpha, beta, l, u = _rows(d, hh, A, cap, cr)
        lo_v0 = jnp.max((l[:, :3] - beta[:, :3] * v1[:, None]) / alpha[:, :3], axis=1)
        hi_v0 = jnp.min((u[:, :3] - beta[:, :3] * v1[:, None]) / alpha[:, :3], axis=1)
        a, b = jnp.maximum(l0, lo_v0), jnp.minimum(h0, hi_v0)
        v0 = jnp.clip(p, a, jnp.maximum(a, b))
        return v0, v0

    v_end = jnp.clip(pref[-1], lo[-1], hi[-1])
    _, v = jax.lax.scan(step, v_end, (D, h, cruise, lo[:-1], hi[:-1], pref[:-1]), reverse=True)
    return jnp.concatenate([v, v_end[None]])


def _pad(a: np.ndarray, size: int, fill) -> np.ndarray:
    out = np.empty((size,) + a.shape[1:], a.dtype)
    out[: a.shape[0]] = a
    out[a.shape[0] :] = fill
    return out


@register_pulse_planner("bang")
def plan_bang(req: PulseRequest) -> PulsePlan:
    """Plan with C¹ cubic Hermite pieces and knot speeds from interval propagation (module docstring)."""
    from jaxcnc.planners.pulsed.sync import plan_sync

    w, f = req.window, req.tick_hz
    pts = req.points
    n = len(pts)
    if n < 2 or np.any(np.isfinite(req.j_max)):
        return plan_sync(req)  # acceleration steps at the knots need an unlimited jerk
    A = np.asarray(req.a_max, dtype=np.float64)
    cap = np.minimum(np.asarray(req.v_max, dtype=np.float64), req.feed_mm_s / np.sqrt(3.0))
    D = np.diff(pts, axis=0)
    g = D.shape[0]
    lo_ticks = np.maximum(np.ceil(np.max(np.abs(D) / cap, axis=1) * f), w.n_min)
    cand = candidates(lo_ticks, w)
    # long jumps (a triangle from rest at A would pass the cap) cruise through their middle half
    cruise = np.any(np.abs(D) >= cap * cap / A, axis=1)
    size = bucket_size(g)
    last = np.zeros(size, bool)
    last[g - 1] = True
    # padding gaps: no motion, any candidate fits
    Dp = _pad(D, size, 0.0)
    cp = _pad(cand, size, w.n_min)
    ticks, lo, hi, ok = forward(Dp, cp, last, _pad(cruise, size, False), A, cap, np.float64(f))
    ticks, lo, hi = ticks[:g], lo[: g + 1], hi[: g + 1]
    if not bool(np.all(np.asarray(ok)[:g])):
        return plan_sync(req)
    v = np.asarray(backward(jnp.asarray(D), ticks, jnp.asarray(cruise), lo, hi, A, cap, np.float64(f)))
    ticks = np.asarray(ticks, np.int64)
    # the approach: rest to rest from the start to the first point, the first pulse on the next whole tick
    u, length, vp, a, t = rest_to_rest(req, req.home[None], pts[:1], np.array([req.rapid_mm_s]))
    z = np.zeros(1)
    a_starts, a_coeffs, arrive = move_pieces(z, req.home[None], u, z, vp, z, length, a, f)
    first = int(np.ceil(float(arrive[0]) - 1e-9))
    work = first + np.concatenate([[0], np.cumsum(ticks)])
    h = (ticks / f)[:, None]
    v0, v1 = v[:-1], v[1:]
    # three constant-acceleration phases per gap, ending at fractions q1, q2, 1 of it
    cr = cruise[:, None]
    q1, q2 = np.where(cruise, 0.25, 0.5), np.where(cruise, 0.75, 0.5)
    vc = np.where(cr, 4.0 * D / (3.0 * h) - (v0 + v1) / 6.0, 2.0 * D / h - 0.5 * (v0 + v1))
    a1 = (vc - v0) / (q1[:, None] * h)
    a3 = (v1 - vc) / ((1.0 - q2)[:, None] * h)
    t1, t2 = q1[:, None] * h, (q2 - q1)[:, None] * h
    c = np.zeros((g, 3, 4, 3))
    c[:, 0, 0], c[:, 0, 1], c[:, 0, 2] = pts[:-1], v0, 0.5 * a1
    c[:, 1, 0], c[:, 1, 1] = pts[:-1] + v0 * t1 + 0.5 * a1 * t1 * t1, vc
    c[:, 2, 0], c[:, 2, 1], c[:, 2, 2] = c[:, 1, 0] + vc * t2, vc, 0.5 * a3
    c = c.reshape(3 * g, 4, 3)
    half = np.column_stack([work[:-1], work[:-1] + q1 * ticks, work[:-1] + q2 * ticks]).reshape(-1).astype(np.float64)
    starts = np.concatenate([a_starts, arrive, half, work[-1:].astype(np.float64)])
    coeffs = np.concatenate([a_coeffs, rest_pieces(arrive, pts[:1]), c, rest_pieces(z, pts[-1:])])
    _, m = w.snap_up(ticks)
    idle = w.split(work[:-1], ticks, m if w.idle_pulses else np.ones_like(ticks))
    traj = Trajectory(start_tick=starts, coeffs=coeffs, n_ticks=int(work[-1]), tick_hz=f)
    return PulsePlan(
        trajectory=traj, work_tick=work, idle_tick=idle, planner="bang", stats={"idle_pulses": int(idle.shape[0])}
    )


@register_pulse_planner("best")
def plan_best(req: PulseRequest) -> PulsePlan:
    """Plan with ``sync`` and ``bang`` and keep the shorter burn (twice the planning time)."""
    from jaxcnc.planners.pulsed.sync import plan_sync

    a, b = plan_sync(req), plan_bang(req)
    return a if a.burn_time_s <= b.burn_time_s else b
