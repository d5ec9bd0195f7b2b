"""Geometry: blocks as spans (lines, exact arcs and helices, NURBS pieces, corner blends), their evaluation."""

from jaxcnc.geometry.kinds import SpanKind
from jaxcnc.geometry.path import build_spans
from jaxcnc.geometry.spans import DEGREE_BUCKETS, Spans

__all__ = ["DEGREE_BUCKETS", "SpanKind", "Spans", "build_spans"]
