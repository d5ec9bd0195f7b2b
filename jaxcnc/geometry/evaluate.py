"""Batched evaluation of rational spans: position and derivatives with respect to ``u``.

For ``[N, w](u) = sum_k c_k u^k`` and ``P = N / w`` the quotient rule gives

    P'  = (N'  - P w') / w
    P'' = (N'' - 2 P' w' - P w'') / w

All functions are pure and shape-polymorphic in the leading batch axis, so they ``vmap``/``jit``
cleanly and run unchanged on CPU or GPU.
"""

from __future__ import annotations

import jax.numpy as jnp

import jaxcnc.jaxconfig  # noqa: F401  (float64)


def _power_derivatives(c: jnp.ndarray, u: jnp.ndarray, order: int) -> list[jnp.ndarray]:
    """``[H, H', ..., H^(order)]`` of ``H(u) = sum_k c_k u^k``.

    Args:
        c: ``(m, degree+1, ndim+1)`` coefficients, one span per query.
        u: ``(m,)`` parameters.
    Returns:
        ``order+1`` arrays of shape ``(m, ndim+1)``.
    """
    deg = c.shape[-2] - 1
    k = jnp.arange(deg + 1, dtype=c.dtype)
    out = []
    coef = jnp.ones_like(k)
    for r in range(order + 1):
        # d^r/du^r u^k = k (k-1) ... (k-r+1) u^(k-r)
        powers = jnp.where(k >= r, u[:, None] ** jnp.maximum(k - r, 0.0), 0.0)
        out.append(jnp.einsum("mk,mkd->md", coef[None, :] * powers, c))
        coef = coef * (k - r)
    return out


def evaluate(coeffs: jnp.ndarray, u: jnp.ndarray, order: int = 0) -> tuple[jnp.ndarray, ...]:
    """Position (and derivatives up to ``order`` ≤ 2) of rational spans.

    Args:
        coeffs: ``(m, degree+1, ndim+1)`` homogeneous power-basis coefficients, gathered
            per query (``spans.coeffs[span_index]``).
        u: ``(m,)`` parameters in [0, 1].
        order: 0 → ``(P,)``; 1 → ``(P, P')``; 2 → ``(P, P', P'')``. Each ``(m, ndim)``.
    """
    if not 0 <= order <= 2:
        raise ValueError("order must be 0, 1 or 2")
    h = _power_derivatives(coeffs, u, order)
    w = h[0][:, -1:]
    p = h[0][:, :-1] / w
    out = [p]
    if order >= 1:
        w1 = h[1][:, -1:]
        p1 = (h[1][:, :-1] - p * w1) / w
        out.append(p1)
    if order >= 2:
        w2 = h[2][:, -1:]
        out.append((h[2][:, :-1] - 2.0 * p1 * w1 - p * w2) / w)
    return tuple(out)
