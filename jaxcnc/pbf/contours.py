"""Polygon algebra of a layer with Clipper (pyclipper): unions, offsets ("equidistants"), differences, areas.

A region is a list of closed integer paths in Clipper units (``SCALE`` per mm, 10 nm), outer boundaries
counter-clockwise and holes clockwise, as Clipper returns them; it is filled by the non-zero rule.
"""

from __future__ import annotations

import numpy as np
import pyclipper

#: Clipper integer units per mm (10 nm resolution; ±9e13 mm range in int64, far beyond any build plate).
SCALE = 100_000.0
#: Largest distance of a rounded offset's chords from the true arc, mm.
ARC_TOL_MM = 0.001

Region = list  # list of (n, 2) int64 arrays


def to_clipper(loops_mm: list[np.ndarray]) -> Region:
    """Float loops (mm) to Clipper integer paths."""
    return [np.round(np.asarray(p) * SCALE).astype(np.int64) for p in loops_mm if len(p) >= 3]


def to_mm(region: Region) -> list[np.ndarray]:
    """Clipper paths to float64 loops in mm."""
    return [np.asarray(p, dtype=np.float64) / SCALE for p in region if len(p) >= 3]


def _clip(subject: Region, clip: Region, op: int) -> Region:
    if not subject:
        return []
    pc = pyclipper.Pyclipper()
    pc.AddPaths(subject, pyclipper.PT_SUBJECT, True)
    if clip:
        pc.AddPaths(clip, pyclipper.PT_CLIP, True)
    out = pc.Execute(op, pyclipper.PFT_NONZERO, pyclipper.PFT_NONZERO)
    return [np.asarray(p, dtype=np.int64) for p in out]


def union(region: Region, other: Region | None = None) -> Region:
    """Union (non-zero rule) of the paths of ``region`` (and ``other``): overlaps merged, holes cut."""
    if not region and not other:
        return []
    if not region:
        region, other = other, None
    return _clip(region, other or [], pyclipper.CT_UNION)


def difference(a: Region, b: Region) -> Region:
    """``a`` minus ``b``."""
    return _clip(a, b, pyclipper.CT_DIFFERENCE) if b else list(a)


def intersection(a: Region, b: Region) -> Region:
    """``a`` and ``b``."""
    return _clip(a, b, pyclipper.CT_INTERSECTION) if (a and b) else []


def offset(region: Region, delta_mm: float, join: str = "round") -> Region:
    """Offset a region by ``delta_mm`` (negative: inwards). ``join``: ``round`` or ``miter`` (limit 2)."""
    if not region:
        return []
    if delta_mm == 0:
        return list(region)
    jt = pyclipper.JT_ROUND if join == "round" else pyclipper.JT_MITER
    pco = pyclipper.PyclipperOffset(2.0, ARC_TOL_MM * SCALE)
    pco.AddPaths(region, jt, pyclipper.ET_CLOSEDPOLYGON)
    return [np.asarray(p, dtype=np.int64) for p in pco.Execute(delta_mm * SCALE)]


def area_mm2(region: Region) -> float:
    """Area of a region (holes subtract), mm²."""
    total = 0.0
    for p in region:
        x, y = p[:, 0].astype(np.float64), p[:, 1].astype(np.float64)
        total += 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    return total / (SCALE * SCALE)


def layer_region(loops_mm: list[np.ndarray]) -> Region:
    """The filled region of a layer's slice loops (outer CCW, holes CW; overlapping shells united)."""
    return union(to_clipper(loops_mm))


def contour_offsets(region: Region, spot_comp_mm: float, count: int, spacing_mm: float) -> list[Region]:
    """The ``count`` contour offsets: at ``spot_comp_mm`` inside the boundary, then every ``spacing_mm`` further in."""
    return [offset(region, -(spot_comp_mm + i * spacing_mm)) for i in range(count)]
