"""The inverse of arc length on a span, ``u(s)``: closed form for lines and arcs, certified fit for curves.

A line's parameter is proportional to length: ``u = s / L``.

A circular piece of sweep ``2α`` written as the rational quadratic with middle weight
``cos α`` is, with ``v = 2u - 1``, the point at angle ``ψ`` from the piece's bisector where
``tan(ψ/2) = v · tan(α/2)`` (check: v = ±1 gives ψ = ±α). Its length from the start is
``s = r (ψ + α)``, hence exactly

    u(s) = (1 + tan((s/r - α) / 2) / tan(α/2)) / 2.

A B-spline piece carries a Chebyshev series of ``u(s)`` whose nodes were solved by Newton's
method on the exact ``s(u)`` and which is certified between the nodes to 1e-11 mm of arc length
(:mod:`jaxcnc.geometry.arclength`), so one series evaluation gives ``u``. ``newton_steps`` adds
Newton corrections ``u ← u - (s(u) - s) / |P'(u)|`` with the exact speed at query time.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.geometry.evaluate import evaluate_spans
from jaxcnc.geometry.spans import SpanKind, Spans

_KEYS = ("kind", "length", "radius", "half_angle")


def span_arrays(spans: Spans) -> dict[str, jnp.ndarray]:
    """Device arrays of the span fields the tick kernels need.

    Coefficients, origins and series are stored transposed (one coefficient per row, spans
    along the last axis) so that gathers by span index read contiguous vectors.
    """
    out = {k: jnp.asarray(getattr(spans, k)) for k in _KEYS}
    out["coeffs_t"] = jnp.asarray(np.ascontiguousarray(np.transpose(spans.coeffs, (1, 2, 0))))
    out["origin_t"] = jnp.asarray(np.ascontiguousarray(spans.origin.T))
    out["cheb_s_t"] = jnp.asarray(np.ascontiguousarray(spans.cheb_s.T))
    out["cheb_u_t"] = jnp.asarray(np.ascontiguousarray(spans.cheb_u.T))
    return out


def chebyshev_columns(series_t: jnp.ndarray, seg: jnp.ndarray, x: jnp.ndarray) -> jnp.ndarray:
    """Evaluate series ``seg[i]`` at ``x[i]`` by Clenshaw's recurrence.

    ``series_t`` is ``(N, n_spans)``: one coefficient per row, so each step gathers a contiguous
    vector. The loop is unrolled (N is static) and fuses into one elementwise kernel.
    """
    b1 = jnp.zeros_like(x)
    b2 = jnp.zeros_like(x)
    two_x = 2.0 * x
    for k in range(series_t.shape[0] - 1, 0, -1):
        b1, b2 = two_x * b1 - b2 + series_t[k][seg], b1
    return x * b1 - b2 + series_t[0][seg]


def u_of_s(spans: dict[str, jnp.ndarray], seg: jnp.ndarray, s: jnp.ndarray, newton_steps: int = 0) -> jnp.ndarray:
    """Span parameter at arc length ``s`` ``(m,)`` from the start of span ``seg`` ``(m,)``.

    ``spans`` comes from :func:`span_arrays`. ``s`` is clipped to ``[0, length]``; point spans
    give ``u = 0``.
    """
    kind, length = spans["kind"][seg], spans["length"][seg]
    s = jnp.clip(s, 0.0, length)
    safe_len = jnp.where(length > 0, length, 1.0)
    u_line = s / safe_len
    is_arc = kind == SpanKind.ARC
    alpha = jnp.where(is_arc, spans["half_angle"][seg], 1.0)
    r = jnp.where(is_arc, spans["radius"][seg], 1.0)
    v = jnp.tan((s / r - alpha) / 2.0) / jnp.tan(alpha / 2.0)
    u = jnp.where(is_arc, 0.5 * (1.0 + jnp.clip(v, -1.0, 1.0)), u_line)
    if spans["cheb_u_t"].shape[0]:  # the program has curves
        uc = jnp.clip(chebyshev_columns(spans["cheb_u_t"], seg, 2.0 * s / safe_len - 1.0), 0.0, 1.0)
        for _ in range(newton_steps):
            uc = jax.lax.optimization_barrier(uc)
            _, d1 = evaluate_spans(spans["coeffs_t"], spans["origin_t"], seg, uc, 1)
            # explicit components: a reduction over the size-3 axis makes XLA's CPU fusion
            # recompute the evaluation per component
            speed = jnp.sqrt(d1[:, 0] ** 2 + d1[:, 1] ** 2 + d1[:, 2] ** 2)
            f = chebyshev_columns(spans["cheb_s_t"], seg, 2.0 * uc - 1.0) - s
            uc = jnp.clip(uc - f / jnp.where(speed > 0, speed, jnp.inf), 0.0, 1.0)
        u = jnp.where(kind == SpanKind.CURVE, uc, u)
    return jnp.where(kind == SpanKind.POINT, 0.0, u)
