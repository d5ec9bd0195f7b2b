"""Span kinds: what a row of :class:`~jaxcnc.geometry.spans.Spans` is."""

from __future__ import annotations

from enum import IntEnum


class SpanKind(IntEnum):
    """The kind of a span; the evaluation and the planner's grid treat each in closed form."""

    POINT = 0  # dwell or machine event: zero length
    LINE = 1  # straight move, unit speed
    ARC = 2  # circular arc or helix, exact, unit speed
    CURVE = 3  # a rational Bézier piece of a B-spline / NURBS, with a timing polynomial
    BLEND = 4  # a corner blend: a quintic Bézier with a timing polynomial


#: Kinds evaluated as rational Bézier pieces through a timing polynomial.
POLY_KINDS = (SpanKind.CURVE, SpanKind.BLEND)
#: Kinds with curvature (the planner cuts them into intervals).
CURVED_KINDS = (SpanKind.ARC, SpanKind.CURVE, SpanKind.BLEND)
