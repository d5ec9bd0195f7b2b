"""The inverse of arc length on a span: ``u(s)``, in closed form for lines and arcs.

A line's parameter is proportional to length: ``u = s / L``.

A circular piece of sweep ``2α`` written as the rational quadratic with middle weight
``cos α`` is, with ``v = 2u - 1``, the point at angle ``ψ`` from the piece's bisector where
``tan(ψ/2) = v · tan(α/2)`` (check: v = ±1 gives ψ = ±α). Its length from the start is
``s = r (ψ + α)``, hence exactly

    u(s) = (1 + tan((s/r - α) / 2) / tan(α/2)) / 2.

The geometry issue adds a fitted inverse with Newton correction for general NURBS spans.
"""

from __future__ import annotations

import jax.numpy as jnp

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.geometry.spans import SpanKind


def u_of_s(
    kind: jnp.ndarray, length: jnp.ndarray, radius: jnp.ndarray, half_angle: jnp.ndarray, s: jnp.ndarray
) -> jnp.ndarray:
    """Span parameter at arc length ``s`` from the span start (all arrays ``(m,)``).

    ``s`` is clipped to ``[0, length]``; point spans give ``u = 0``.
    """
    s = jnp.clip(s, 0.0, length)
    safe_len = jnp.where(length > 0, length, 1.0)
    u_line = s / safe_len
    is_arc = kind == SpanKind.ARC
    alpha = jnp.where(is_arc, half_angle, 1.0)
    r = jnp.where(is_arc, radius, 1.0)
    v = jnp.tan((s / r - alpha) / 2.0) / jnp.tan(alpha / 2.0)
    u_arc = 0.5 * (1.0 + jnp.clip(v, -1.0, 1.0))
    u = jnp.where(is_arc, u_arc, u_line)
    return jnp.where(kind == SpanKind.POINT, 0.0, u)
