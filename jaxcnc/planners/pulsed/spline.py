"""Interpolating cubic splines in time through points at given instants, and their exact extremes.

Each axis is the C² cubic through ``(t_i, y_i)``. In the moment form (``M_i`` = acceleration at
knot ``i``, ``h_i = t_{i+1} - t_i``, ``Δ_i = (y_{i+1}-y_i)/h_i``) the interior knots satisfy

    h_{i-1} M_{i-1} + 2 (h_{i-1} + h_i) M_i + h_i M_{i+1} = 6 (Δ_i - Δ_{i-1}).

The motion starts and ends at rest *with zero acceleration* (no acceleration step, so a jerk limit
can hold at the first and last tick): four end conditions where a cubic spline has two. As in
Biagiotti & Melchiorri (Trajectory Planning for Automatic Machines and Robots, §4.4), two extra
knots with free positions carry them: knot 1 between the start ``y_0`` and the first point, knot
``L-1`` between the last point and the stop ``y_L``. ``M_0 = 0`` and ``v(t_0) = 0`` give
``y_1 = y_0 + h_0² M_1 / 6``; substituting keeps the system tridiagonal:

    row 1:    (2(h_0+h_1) + h_0²/h_1 + h_0) M_1 + h_1 M_2 = 6 (y_2 - y_0)/h_1
    row 2:    (h_1 - h_0²/h_1) M_1 + 2(h_1+h_2) M_2 + h_2 M_3 = 6 (Δ_2 - (y_2 - y_0)/h_1)

(and the mirror image at the end) — the usual rows with ``y_1`` read as ``y_0``, plus those
corrections. One ``tridiagonal_solve`` for the whole job, every axis at once. Acceleration is
linear on each interval, so its extremes are the knot values ``M_i``; jerk is the constant
``(M_{i+1}-M_i)/h_i``; velocity is quadratic, with its extreme at an end or at the vertex — all
exact, no sampling.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

import jaxcnc.jaxconfig  # noqa: F401  (float64)


def spline_moments(t_s: jnp.ndarray, y: jnp.ndarray, n_knots: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Moments and knot positions of the rest-to-rest spline with free knots 1 and ``L-1``.

    Args:
        t_s: ``(m,)`` knot times, increasing over the first ``n_knots``.
        y: ``(m, d)`` knot positions; rows 1 and ``L = n_knots - 1`` minus 1 are placeholders.
        n_knots: knots in use (at least 5); rows beyond are padding (``M = 0``, uncoupled).
    Returns:
        ``(M, y)``: accelerations ``(m, d)`` at the knots and the positions with the two free
        knots filled in.
    """
    m = t_s.shape[0]
    idx = jnp.arange(m)
    last = n_knots - 1
    h = jnp.diff(t_s)
    h = jnp.where(idx[:-1] < last, h, 1.0)  # padding: any positive value
    # the usual rows, with the free knots read as the rest positions beside them
    y_eff = jnp.where((idx == 1)[:, None], y[0], y)
    y_eff = jnp.where((idx == last - 1)[:, None], y[last], y_eff)
    dy = jnp.diff(y_eff, axis=0) / h[:, None]
    zero_row = jnp.zeros((1, y.shape[1]))
    h_prev = jnp.concatenate([jnp.zeros(1), h])
    h_next = jnp.concatenate([h, jnp.zeros(1)])
    rhs = 6.0 * (jnp.concatenate([dy, zero_row]) - jnp.concatenate([zero_row, dy]))
    diag = 2.0 * (h_prev + h_next)
    dl, du = h_prev, h_next
    # start: M_0 = 0 and the free knot 1
    h0, h1 = h[0], h[1]
    diag = diag + jnp.where(idx == 1, h0 * h0 / h1 + h0, 0.0)
    dl = jnp.where(idx == 1, 0.0, dl) - jnp.where(idx == 2, h0 * h0 / h1, 0.0)
    # end: M_L = 0 and the free knot L-1
    ha, hb = h[last - 1], h[last - 2]
    diag = diag + jnp.where(idx == last - 1, ha * ha / hb + ha, 0.0)
    du = jnp.where(idx == last - 1, 0.0, du) - jnp.where(idx == last - 2, ha * ha / hb, 0.0)
    fixed = (idx == 0) | (idx >= last)  # M = 0: the two rest ends and the padding
    diag = jnp.where(fixed, 1.0, diag)
    dl = jnp.where(fixed, 0.0, dl)
    du = jnp.where(fixed, 0.0, du)
    rhs = jnp.where(fixed[:, None], 0.0, rhs)
    M = jax.lax.linalg.tridiagonal_solve(dl, diag, du, rhs)
    y1 = y[0] + h0 * h0 * M[1] / 6.0
    y_end = y[last] + ha * ha * M[last - 1] / 6.0
    y_full = jnp.where((idx == 1)[:, None], y1, y)
    y_full = jnp.where((idx == last - 1)[:, None], y_end, y_full)
    return M, y_full


def cubic_coefficients(t_s: jnp.ndarray, y: jnp.ndarray, M: jnp.ndarray) -> jnp.ndarray:
    """Per-interval coefficients ``(m-1, 4, d)`` of ``y_i + c1 τ + c2 τ² + c3 τ³`` from the moments."""
    h = jnp.diff(t_s)[:, None]
    h = jnp.where(h > 0, h, 1.0)
    Mi, Mj = M[:-1], M[1:]
    c1 = (y[1:] - y[:-1]) / h - h * (2.0 * Mi + Mj) / 6.0
    return jnp.stack([y[:-1], c1, 0.5 * Mi, (Mj - Mi) / (6.0 * h)], axis=1)


def interval_extremes(t_s: jnp.ndarray, coeffs: jnp.ndarray, M: jnp.ndarray) -> dict[str, jnp.ndarray]:
    """Exact per-interval, per-axis maxima ``(m-1, d)`` of ``|v|``, ``|a|`` and ``|j|``."""
    h = jnp.diff(t_s)[:, None]
    c1, c2, c3 = coeffs[:, 1], coeffs[:, 2], coeffs[:, 3]
    v_end = c1 + 2.0 * c2 * h + 3.0 * c3 * h * h
    # v' = 2 c2 + 6 c3 τ = 0 at the vertex τ* = -c2 / (3 c3)
    safe = jnp.where(c3 != 0, c3, 1.0)
    tau = jnp.where(c3 != 0, -c2 / (3.0 * safe), 0.0)
    inside = (tau > 0) & (tau < h)
    v_mid = jnp.where(inside, c1 + 2.0 * c2 * tau + 3.0 * c3 * tau * tau, 0.0)
    v = jnp.maximum(jnp.maximum(jnp.abs(c1), jnp.abs(v_end)), jnp.abs(v_mid))
    a = jnp.maximum(jnp.abs(M[:-1]), jnp.abs(M[1:]))
    j = 6.0 * jnp.abs(c3)
    return {"v": v, "a": a, "j": j}
