"""Geometry: blocks as batched rational Bézier spans, their evaluation, lengths and ``u(s)``."""

from jaxcnc.geometry.spans import DEGREE_BUCKETS, SpanKind, Spans, build_spans

__all__ = ["DEGREE_BUCKETS", "SpanKind", "Spans", "build_spans"]
