"""A Program's path: its spans in path order with every junction the program allows blended.

:func:`build_spans` is the geometry stage's entry point: the rows as spans
(:func:`jaxcnc.geometry.spans.program_spans`), then the blends within the program's G64 P tolerance
(``corner_tol_mm`` where G64 has no P; :mod:`jaxcnc.geometry.blend`).
"""

from __future__ import annotations

from jaxcnc.geometry.blend import blend_path
from jaxcnc.geometry.spans import Spans, program_spans
from jaxcnc.program import Program


def build_spans(program: Program, corner_tol_mm: float = 0.0) -> Spans:
    """The spans of ``program`` in path order, junctions blended within the tolerance (0: exact corners)."""
    return blend_path(program, program_spans(program), corner_tol_mm)


__all__ = ["build_spans"]
