"""Rational Bézier building blocks (NumPy, build time): bases, NURBS decomposition, restriction.

Spans are stored as homogeneous power-basis coefficients *relative to a span origin*:
``[N, w](u) = sum_k c_k u^k`` with ``P(u) = origin + N(u) / w(u)``. Keeping coordinates local
keeps the coefficients the size of the span, not of the machine, so evaluation rounds at the
1e-15 mm level even far from the machine's zero.
"""

from __future__ import annotations

from math import comb

import numpy as np


def bernstein_to_power_matrix(degree: int) -> np.ndarray:
    """``M`` with ``c_k = sum_i M[k, i] b_i`` (Bernstein coefficients ``b`` → power basis ``c``)."""
    p = degree
    m = np.zeros((p + 1, p + 1))
    for k in range(p + 1):
        for i in range(k + 1):
            m[k, i] = comb(p, k) * comb(k, i) * (-1) ** (k - i)
    return m


def homogeneous_power(points: np.ndarray, weights: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Bézier control points → relative homogeneous power-basis coefficients.

    Args:
        points: ``(S, p+1, 3)`` control points (mm), weights ``(S, p+1)``, origin ``(S, 3)``.
    Returns:
        ``(S, p+1, 4)`` coefficients of ``(w·(P - origin), w)``.
    """
    hb = np.concatenate([(points - origin[:, None, :]) * weights[..., None], weights[..., None]], axis=-1)
    return np.einsum("ki,sid->skd", bernstein_to_power_matrix(points.shape[1] - 1), hb)


def power_to_bezier(coeffs: np.ndarray) -> np.ndarray:
    """Relative homogeneous power-basis coefficients ``(S, p+1, 4)`` → Bézier control points ``(S, p+1, 3)``
    (relative to the span origin), the inverse of :func:`homogeneous_power`."""
    m = np.linalg.inv(bernstein_to_power_matrix(coeffs.shape[1] - 1))
    hb = np.einsum("ik,skd->sid", m, coeffs)
    return hb[..., :3] / hb[..., 3:]


def elevate(coeffs: np.ndarray, degree: int) -> np.ndarray:
    """Pad power-basis coefficients ``(S, p+1, 4)`` to ``degree`` (exact: higher terms are zero)."""
    extra = degree + 1 - coeffs.shape[1]
    if extra < 0:
        raise ValueError(f"cannot lower degree {coeffs.shape[1] - 1} to {degree}")
    return np.pad(coeffs, [(0, 0), (0, extra), (0, 0)])


def restrict(coeffs: np.ndarray, origin: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The piece ``u ∈ [a, b]`` of each span, reparametrised to [0, 1], with a new origin at its start.

    ``H(a + (b - a) v) = sum_j c'_j v^j`` with ``c'_j = (b-a)^j sum_k C(k, j) a^(k-j) c_k``.
    Args: coeffs ``(S, p+1, 4)``, origin ``(S, 3)``, a and b ``(S,)``. Returns (coeffs, origin).
    """
    p = coeffs.shape[1] - 1
    k = np.arange(p + 1)
    binom = np.array([[comb(kk, j) for kk in range(p + 1)] for j in range(p + 1)], dtype=np.float64)  # [j, k]
    expo = k[None, :] - k[:, None]  # k - j
    apow = np.where(expo[None] >= 0, a[:, None, None] ** np.maximum(expo, 0)[None], 0.0)
    mat = binom[None] * apow * ((b - a)[:, None, None] ** k[None, :, None])
    out = np.einsum("sjk,skd->sjd", mat, coeffs)
    # move the origin to the piece's start: N' = N + (o_old - o_new) w
    start = out[:, 0, :3] / out[:, 0, 3:]
    out[..., :3] -= start[:, None, :] * out[..., 3:]
    return out, origin + start


def nurbs_to_bezier(
    degree: int, points: np.ndarray, weights: np.ndarray, knots: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Decompose a clamped NURBS into its rational Bézier pieces, all at once.

    The Bézier control point ``j`` of the piece over ``[U_i, U_{i+1}]`` is the blossom
    ``f(U_i^(p-j), U_{i+1}^(j))`` of the homogeneous curve, evaluated by de Boor's recursion with
    those arguments — the same points repeated knot insertion gives, vectorised over pieces and
    control points (``p`` steps of array arithmetic, no loop over knots).

    Args:
        degree: ``p``. points ``(m, 3)``, weights ``(m,)``, knots ``(m + p + 1,)`` clamped.
    Returns:
        ``(bezier_points (S, p+1, 3), bezier_weights (S, p+1), intervals (S, 2))`` for the ``S``
        knot intervals of non-zero length.
    """
    p = degree
    m = points.shape[0]
    pw = np.concatenate([points * weights[:, None], weights[:, None]], axis=1)  # (m, 4)
    span = np.arange(p, m)
    span = span[knots[span + 1] > knots[span]]
    a, b = knots[span], knots[span + 1]
    j = np.arange(p + 1)
    kk = np.arange(p + 1)
    g = span[:, None] - p + kk[None, :]  # (S, K) global control-point index
    d = np.broadcast_to(pw[g][:, None, :, :], (span.size, p + 1, p + 1, 4)).copy()  # (S, J, K, 4)
    for r in range(1, p + 1):
        t = np.where(r <= p - j, 0.0, 1.0)[None, :] * (b - a)[:, None] + a[:, None]  # (S, J)
        lo = knots[g[:, r:]]  # (S, K - r)
        hi = knots[g[:, r:] + p + 1 - r]
        alpha = (t[:, :, None] - lo[:, None, :]) / (hi - lo)[:, None, :]  # (S, J, K - r)
        d[:, :, r:] = (1 - alpha[..., None]) * d[:, :, r - 1 : -1] + alpha[..., None] * d[:, :, r:]
    hb = d[:, :, p]  # (S, J, 4)
    w = hb[..., 3]
    return hb[..., :3] / w[..., None], w, np.stack([a, b], axis=1)
