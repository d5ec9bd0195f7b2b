"""Interpolating cubic splines in time through points at given instants, and their exact extremes.

Each axis is the C² cubic through ``(t_i, y_i)`` with the machine at rest at both ends. In the
moment form (``M_i`` = acceleration at knot ``i``, ``h_i = t_{i+1} - t_i``, ``Δ_i = (y_{i+1}-y_i)/h_i``):

    interior:  h_{i-1} M_{i-1} + 2 (h_{i-1} + h_i) M_i + h_i M_{i+1} = 6 (Δ_i - Δ_{i-1})
    at rest:   2 h_0 M_0 + h_0 M_1 = 6 Δ_0            h_{n-1} M_{n-1} + 2 h_{n-1} M_n = -6 Δ_{n-1}

a strictly diagonally dominant tridiagonal system (one ``tridiagonal_solve``, O(n), every axis at
once). Among all C² interpolants it has the least ``∫ a² dt``. Acceleration is linear on each
interval, so its extremes are the knot values ``M_i``; jerk is the constant ``(M_{i+1}-M_i)/h_i``;
velocity is quadratic, with its extreme at an end or at the vertex — all exact, no sampling.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

import jaxcnc.jaxconfig  # noqa: F401  (float64)


def spline_moments(t_s: jnp.ndarray, y: jnp.ndarray, n_knots: jnp.ndarray) -> jnp.ndarray:
    """Knot accelerations ``M`` ``(m, d)`` of the rest-to-rest spline through ``y`` ``(m, d)`` at ``t_s`` ``(m,)``.

    Only knots ``0..n_knots-1`` are used; rows beyond (padding to a bucket) get ``M = 0`` and do
    not couple to the rest.
    """
    m = t_s.shape[0]
    idx = jnp.arange(m)
    last = n_knots - 1
    h = jnp.diff(t_s)
    h = jnp.where(idx[:-1] < last, h, 1.0)  # padding: any positive value
    dy = jnp.diff(y, axis=0) / h[:, None]
    h_prev = jnp.concatenate([jnp.zeros(1), h])  # h_{i-1}, 0 at i = 0
    h_next = jnp.concatenate([h, jnp.zeros(1)])  # h_i
    h_next = jnp.where(idx < last, h_next, 0.0)
    h_prev = jnp.where(idx <= last, h_prev, 0.0)
    d_prev = jnp.concatenate([jnp.zeros((1, y.shape[1])), dy])
    d_next = jnp.concatenate([dy, jnp.zeros((1, y.shape[1]))])
    d_next = jnp.where((idx < last)[:, None], d_next, 0.0)
    d_prev = jnp.where((idx <= last)[:, None], d_prev, 0.0)
    pad = idx > last
    diag = jnp.where(pad, 1.0, 2.0 * (h_prev + h_next))
    rhs = jnp.where(pad[:, None], 0.0, 6.0 * (d_next - d_prev))
    dl = jnp.where(pad, 0.0, h_prev)
    du = jnp.where(pad, 0.0, h_next)
    return jax.lax.linalg.tridiagonal_solve(dl, diag, du, rhs)


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
