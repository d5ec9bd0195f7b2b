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


def evaluate(coeffs: jnp.ndarray, origin: jnp.ndarray, u: jnp.ndarray, order: int = 0) -> tuple[jnp.ndarray, ...]:
    """Position and derivatives up to ``order`` (≤ 3) of rational spans at ``u``.

    Args:
        coeffs: ``(m, degree+1, 4)`` homogeneous power-basis coefficients gathered per query
            (``spans.coeffs[span_index]``); origin: ``(m, 3)`` (``spans.origin[span_index]``).
        u: ``(m,)`` parameters in [0, 1].
    Returns:
        ``(P, P', ..., P^(order))``, each ``(m, 3)``; ``P`` in mm, derivatives per unit ``u``.
    """
    rows = jnp.arange(u.shape[0])
    return evaluate_spans(jnp.transpose(coeffs, (1, 2, 0)), jnp.transpose(origin), rows, u, order)


def evaluate_spans(
    coeffs_t: jnp.ndarray, origin_t: jnp.ndarray, seg: jnp.ndarray, u: jnp.ndarray, order: int = 0
) -> tuple[jnp.ndarray, ...]:
    """Position and derivatives of span ``seg[i]`` at ``u[i]``, gathering coefficients column by column.

    Horner's scheme with derivatives: running ``d_r`` (the r-th derivative over r!) are updated
    from the highest coefficient down, ``d_r ← d_r u + d_(r-1)``, ``d_0 ← d_0 u + c_k``; then the
    quotient rule of the module docstring.

    Args:
        coeffs_t: ``(degree+1, 4, n_spans)`` — the span coefficients transposed so that each
            gather reads one contiguous vector (on CPU this is an order of magnitude faster than
            gathering ``(m, degree+1, 4)`` blocks, and it fuses with Horner's loop).
        origin_t: ``(3, n_spans)``; seg: ``(m,)`` int; u: ``(m,)``.
    Returns:
        ``(P, P', ..., P^(order))``, each ``(m, 3)``.
    """
    if not 0 <= order <= 3:
        raise ValueError("order must be 0, 1, 2 or 3")
    deg = coeffs_t.shape[0] - 1
    comps = []  # per homogeneous component: [H, H', ...]
    for c in range(4):
        d = [coeffs_t[deg, c][seg]] + [jnp.zeros_like(u) for _ in range(order)]
        for k in range(deg - 1, -1, -1):
            for r in range(min(order, deg - k), 0, -1):
                d[r] = d[r] * u + d[r - 1]
            d[0] = d[0] * u + coeffs_t[k, c][seg]
        fact = 1.0
        for r in range(2, order + 1):
            fact *= r
            d[r] = fact * d[r]
        comps.append(d)
    w = comps[3]
    out = []
    for i in range(3):
        n = comps[i]
        q = n[0] / w[0]
        di = [q]
        if order >= 1:
            di.append((n[1] - q * w[1]) / w[0])
        if order >= 2:
            di.append((n[2] - 2.0 * di[1] * w[1] - q * w[2]) / w[0])
        if order >= 3:
            di.append((n[3] - 3.0 * di[2] * w[1] - 3.0 * di[1] * w[2] - q * w[3]) / w[0])
        di[0] = origin_t[i][seg] + q
        out.append(di)
    return tuple(jnp.stack([out[i][r] for i in range(3)], axis=1) for r in range(order + 1))
