"""The inverse of arc length on a span, ``u(s)``: closed form for lines and arcs, fit + Newton for curves.

A line's parameter is proportional to length: ``u = s / L``.

A circular piece of sweep ``2α`` written as the rational quadratic with middle weight
``cos α`` is, with ``v = 2u - 1``, the point at angle ``ψ`` from the piece's bisector where
``tan(ψ/2) = v · tan(α/2)`` (check: v = ±1 gives ψ = ±α). Its length from the start is
``s = r (ψ + α)``, hence exactly

    u(s) = (1 + tan((s/r - α) / 2) / tan(α/2)) / 2.

A B-spline piece carries Chebyshev series of ``u(s)`` (the initial guess) and ``s(u)``; Newton
steps ``u ← u - (s(u) - s) / |P'(u)|`` with the exact speed polish the guess to rounding level
(each step squares the error of the fit's ~1e-7 relative).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.geometry.evaluate import evaluate
from jaxcnc.geometry.spans import SpanKind

NEWTON_STEPS = 2


def chebyshev_rows(series: jnp.ndarray, x: jnp.ndarray) -> jnp.ndarray:
    """Evaluate row ``i`` of ``series`` ``(m, N)`` at ``x[i]`` ``(m,)`` by Clenshaw's recurrence."""

    def step(carry, c):
        b1, b2 = carry
        return (2.0 * x * b1 - b2 + c, b1), None

    zero = jnp.zeros_like(x)
    (b1, b2), _ = jax.lax.scan(step, (zero, zero), series[:, :0:-1].T)
    return x * b1 - b2 + series[:, 0]


def u_of_s(spans: dict[str, jnp.ndarray], seg: jnp.ndarray, s: jnp.ndarray) -> jnp.ndarray:
    """Span parameter at arc length ``s`` ``(m,)`` from the start of span ``seg`` ``(m,)``.

    ``spans`` holds JAX arrays of :class:`~jaxcnc.geometry.spans.Spans` fields (``kind``, ``length``,
    ``radius``, ``half_angle``, ``cheb_s``, ``cheb_u``, ``coeffs``, ``origin``). ``s`` is clipped to
    ``[0, length]``; point spans give ``u = 0``.
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
    if spans["cheb_u"].shape[1]:  # the program has curves: fit + Newton on those spans
        is_curve = kind == SpanKind.CURVE
        cs, cu = spans["cheb_s"][seg], spans["cheb_u"][seg]
        coeffs, origin = spans["coeffs"][seg], spans["origin"][seg]
        uc = jnp.clip(chebyshev_rows(cu, 2.0 * s / safe_len - 1.0), 0.0, 1.0)
        for _ in range(NEWTON_STEPS):
            _, d1 = evaluate(coeffs, origin, uc, 1)
            speed = jnp.linalg.norm(d1, axis=1)
            f = chebyshev_rows(cs, 2.0 * uc - 1.0) - s
            uc = jnp.clip(uc - f / jnp.where(speed > 0, speed, jnp.inf), 0.0, 1.0)
        u = jnp.where(is_curve, uc, u)
    return jnp.where(kind == SpanKind.POINT, 0.0, u)
