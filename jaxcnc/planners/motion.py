"""The constant-acceleration motion formulas, written once: ramps, trapezoids, their inverses and integrals.

A *trapezoid* segment starts at ``v0``, ramps at ``a_acc`` for ``t_acc`` seconds to ``vp``, cruises
``t_cru`` seconds, and ramps down at ``a_dec`` for ``t_dec`` seconds (a dwell is all cruise at zero
speed). Every function works on arrays of segments and takes the array namespace ``xp`` (NumPy, or
``jax.numpy`` inside compiled kernels) where it needs more than arithmetic, so planners (the time law,
the S-curve stage, the pulse planners) and the tick stage (PSO) share the same expressions — and the
same floating-point results.
"""

from __future__ import annotations

import numpy as np


def ramp_distance(v0, a, t):
    """Path covered in ``t`` seconds from speed ``v0`` at constant acceleration ``a``: ``v0 t + a t²/2``."""
    return v0 * t + 0.5 * a * t**2


def trapezoid_position(v0, vp, a_acc, a_dec, t_acc, t_cru, t_dec, tau, xp=np):
    """Path covered ``tau`` seconds after a trapezoid segment's start (constant past its end)."""
    l_acc = ramp_distance(v0, a_acc, t_acc)
    t1 = xp.minimum(tau, t_acc)
    s_acc = ramp_distance(v0, a_acc, t1)
    t2 = xp.clip(tau - t_acc, 0.0, t_cru)
    t3 = xp.clip(tau - t_acc - t_cru, 0.0, t_dec)
    return xp.where(tau < t_acc, s_acc, l_acc + vp * t2 + vp * t3 - 0.5 * a_dec * t3**2)


def trapezoid_speed(v0, vp, a_acc, a_dec, t_acc, t_cru, t_dec, tau, xp=np):
    """Path speed ``tau`` seconds after a trapezoid segment's start (never below 0)."""
    v_acc = v0 + a_acc * xp.minimum(tau, t_acc)
    v_dec = vp - a_dec * xp.clip(tau - t_acc - t_cru, 0.0, t_dec)
    return xp.maximum(xp.where(tau < t_acc, v_acc, v_dec), 0.0)  # (rounding may leave -1e-14 at a rest)


def trapezoid_integral(v0, vp, a_acc, a_dec, t_acc, t_cru, t_dec, length, tau, xp=np):
    """``∫_0^τ s`` (mm·s) of a trapezoid segment ``tau`` seconds after its start (``s = length`` past its end)."""
    l_acc = ramp_distance(v0, a_acc, t_acc)
    l_cru = vp * t_cru
    t1 = xp.clip(tau, 0.0, t_acc)
    t2 = xp.clip(tau - t_acc, 0.0, t_cru)
    t3 = xp.clip(tau - t_acc - t_cru, 0.0, t_dec)
    t4 = xp.maximum(tau - t_acc - t_cru - t_dec, 0.0)
    return (
        v0 * t1**2 / 2 + a_acc * t1**3 / 6
        + l_acc * t2 + vp * t2**2 / 2
        + (l_acc + l_cru) * t3 + vp * t3**2 / 2 - a_dec * t3**3 / 6
        + length * t4
    )  # fmt: skip


def trapezoid_time_at(v0, vp, a_acc, a_dec, t_acc, t_cru, t_dec, s):
    """Seconds from a trapezoid segment's start until it has covered ``s`` mm (NumPy), inverting it exactly:

        ramp up:    s = v0 τ + a τ²/2      →  τ = 2 s / (v0 + sqrt(v0² + 2 a s))
        cruise:     s = l_acc + vp (τ - t_acc)
        ramp down:  s' = vp τ' - a τ'²/2   →  τ' = 2 s' / (vp + sqrt(vp² - 2 a s'))

    (the rationalised roots lose no digits where ``a`` is small).
    """
    l_acc = ramp_distance(v0, a_acc, t_acc)
    l_cru = vp * t_cru
    with np.errstate(divide="ignore", invalid="ignore"):
        up = 2.0 * s / (v0 + np.sqrt(np.maximum(v0 * v0 + 2.0 * a_acc * s, 0.0)))
        cru = t_acc + (s - l_acc) / vp
        s3 = np.clip(s - l_acc - l_cru, 0.0, None)
        down = t_acc + t_cru + 2.0 * s3 / (vp + np.sqrt(np.maximum(vp * vp - 2.0 * a_dec * s3, 0.0)))
    tau = np.where(s <= l_acc, up, np.where(s <= l_acc + l_cru, cru, down))
    return np.clip(np.nan_to_num(tau), 0.0, t_acc + t_cru + t_dec)


def _safe_div(num, den, xp=np):
    ok = den > 0
    return xp.where(ok, num / xp.where(ok, den, 1.0), 0.0)


def trapezoids(x_node, x_cap, a, length, dwell_s, xp=None) -> dict:
    """Per-span trapezoid from node ``v²`` ``(n+1,)`` and span caps/accel/length/dwell ``(n,)``.

    Span ``k`` accelerates from ``v0`` at ``a``, may cruise at ``vp`` and decelerates to ``v1``; the peak
    comes from meeting the two parabolas, ``vp² = min(cap, (v0² + v1²)/2 + a L)``; the phase lengths are
    ``L_acc = (vp² - v0²)/(2a)``, ``L_dec = (vp² - v1²)/(2a)``, ``L_cru = L - L_acc - L_dec`` and the
    times ``2 L / (v_begin + v_end)`` per ramp, ``L_cru / vp`` for the cruise. The ramp accelerations
    are recomputed from the realised times, so that ``s(t)`` ends exactly at ``L``. ``xp``: ``jax.numpy``
    unless given.
    """
    if xp is None:
        import jax.numpy as xp
    x0, x1 = x_node[:-1], x_node[1:]
    a_fin = xp.where(xp.isfinite(a), a, 0.0)
    xp_ = xp.minimum(x_cap, 0.5 * (x0 + x1) + a_fin * length)
    xp_ = xp.maximum(xp_, xp.maximum(x0, x1))  # rounding of the passes
    l_acc = _safe_div(xp_ - x0, 2.0 * a_fin, xp)
    l_dec = _safe_div(xp_ - x1, 2.0 * a_fin, xp)
    over = l_acc + l_dec
    shrink = xp.where(over > length, _safe_div(length, over, xp), 1.0)
    l_acc, l_dec = l_acc * shrink, l_dec * shrink
    l_cru = xp.maximum(length - l_acc - l_dec, 0.0)
    v0, vp, v1 = xp.sqrt(x0), xp.sqrt(xp_), xp.sqrt(x1)
    t_acc = _safe_div(2.0 * l_acc, v0 + vp, xp)
    t_dec = _safe_div(2.0 * l_dec, vp + v1, xp)
    t_cru = _safe_div(l_cru, vp, xp) + dwell_s
    return dict(
        v0=v0,
        vp=vp,
        v1=v1,
        t_acc=t_acc,
        t_cru=t_cru,
        t_dec=t_dec,
        a_acc=_safe_div(vp - v0, t_acc, xp),
        a_dec=_safe_div(vp - v1, t_dec, xp),
    )


def ramp_times(v0, vp, v1, length, a, xp=np):
    """A ramp ``v0 → vp``, a cruise at ``vp``, a ramp ``vp → v1``, both ramps at ``±a``, over ``length``.

    Returns ``(t1, t2, t3, s1, s2)``: the phase durations (s) and the path length at the end of the first
    ramp and of the cruise. ``t2`` is ``inf`` where ``vp = 0`` leaves path to cover (no such motion).
    """
    t1 = xp.abs(vp - v0) / a
    t3 = xp.abs(vp - v1) / a
    s1 = 0.5 * (v0 + vp) * t1
    s3 = 0.5 * (vp + v1) * t3
    cruise = xp.maximum(length - s1 - s3, 0.0)
    moving = vp > 0
    t2 = xp.where(moving, cruise / xp.where(moving, vp, 1.0), xp.where(cruise > 0, xp.inf, 0.0))
    return t1, t2, t3, s1, s1 + cruise


def rest_to_rest(v_cap, length, a):
    """Peak speed and time of a straight move from rest to rest (NumPy): a trapezoid, or a triangle.

    ``vp = min(v_cap, sqrt(a L))`` (the triangle's apex where the ramps meet); time
    ``2 vp/a + (L - vp²/a)/vp``, 0 for ``L = 0``.
    """
    vp = np.minimum(v_cap, np.sqrt(a * length))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(length > 0, 2.0 * vp / a + (length - vp * vp / a) / np.where(vp > 0, vp, 1.0), 0.0)
    return vp, t
