"""A Program's path: its spans in path order with every junction the program allows blended.

:func:`build_spans` is the geometry stage's entry point: the rows as spans
(:func:`jaxcnc.geometry.spans.program_spans`), then the blends within the program's G64 P tolerance
(``corner_tol_mm`` where G64 has no P; :mod:`jaxcnc.geometry.blend`).
"""

from __future__ import annotations

import numpy as np

from jaxcnc.geometry.blend import blend_path
from jaxcnc.geometry.spans import Spans, program_spans
from jaxcnc.program import Program


def build_spans(
    program: Program, corner_tol_mm: float = 0.0, exact_before: np.ndarray | None = None, g2: bool = False
) -> Spans:
    """The spans of ``program`` in path order, junctions blended within the tolerance (0: exact corners).

    ``exact_before``: ``(rows,)`` bool, junctions into these rows kept exact too (where a planner asks). ``g2``:
    tangent junctions where the curvature steps are blended too (for jerk limits; :func:`~.blend.blend_path`)."""
    return blend_path(program, program_spans(program), corner_tol_mm, exact_before, g2)


__all__ = ["build_spans"]
