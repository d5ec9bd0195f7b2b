"""Batched evaluation of rational spans: position and derivatives with respect to ``u``.

For ``[N, w](u) = sum_k c_k u^k`` and ``P = origin + N / w`` the quotient rule gives

    P'   = (N'   - Q w') / w                                   (Q = N / w)
    P''  = (N''  - 2 P' w' - Q w'') / w
    P''' = (N''' - 3 P'' w' - 3 P' w'' - Q w''') / w

All functions are pure and batched over a leading axis of queries, so they ``vmap``/``jit``
cleanly and run unchanged on CPU or GPU.
"""

from __future__ import annotations

import jax.numpy as jnp

import jaxcnc.jaxconfig  # noqa: F401  (float64)


def _power_derivatives(c: jnp.ndarray, u: jnp.ndarray, order: int) -> list[jnp.ndarray]:
    """``[H, H', ..., H^(order)]`` of ``H(u) = sum_k c_k u^k``.

    Args:
        c: ``(m, degree+1, 4)`` coefficients, one span per query.
        u: ``(m,)`` parameters.
    Returns:
        ``order+1`` arrays of shape ``(m, 4)``.
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


def evaluate(coeffs: jnp.ndarray, origin: jnp.ndarray, u: jnp.ndarray, order: int = 0) -> tuple[jnp.ndarray, ...]:
    """Position and derivatives up to ``order`` (≤ 3) of rational spans at ``u``.

    Args:
        coeffs: ``(m, degree+1, 4)`` homogeneous power-basis coefficients gathered per query
            (``spans.coeffs[span_index]``); origin: ``(m, 3)`` (``spans.origin[span_index]``).
        u: ``(m,)`` parameters in [0, 1].
    Returns:
        ``(P, P', ..., P^(order))``, each ``(m, 3)``; ``P`` in mm, derivatives per unit ``u``.
    """
    if not 0 <= order <= 3:
        raise ValueError("order must be 0, 1, 2 or 3")
    h = _power_derivatives(coeffs, u, order)
    w = [x[:, 3:] for x in h]
    q = h[0][:, :3] / w[0]
    d = [q]
    if order >= 1:
        d.append((h[1][:, :3] - q * w[1]) / w[0])
    if order >= 2:
        d.append((h[2][:, :3] - 2.0 * d[1] * w[1] - q * w[2]) / w[0])
    if order >= 3:
        d.append((h[3][:, :3] - 3.0 * d[2] * w[1] - 3.0 * d[1] * w[2] - q * w[3]) / w[0])
    return (origin + q, *d[1:])
