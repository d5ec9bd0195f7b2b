"""Self-intersections of a mesh, where slicing shows them: loops of one layer that cross themselves or each other.

A closed, consistently wound mesh cut at a height gives simple loops that are nested or apart. A mesh that
passes through itself — two shells overlapping, a fold of one shell — gives loops that cross there. Each loop of
every height checked becomes a shapely polygon (all at once: ``shapely.linearrings`` with ragged indices); a
polygon that is not valid crosses itself (``shapely.is_valid_reason``: ``Self-intersection[x y]``), and two
polygons of one layer that **overlap** (their insides meet, neither holds the other; an ``STRtree`` query over all
layers, pairs of one layer kept) cross each other. Loops that only touch are not counted. Found only at the heights
checked (a crossing between two of them is not seen), and only where it changes a cut.
"""

from __future__ import annotations

import re

import numpy as np

from jaxcnc.pbf.slice import slice_mesh


def check_heights_mm(z_lo_mm: float, z_hi_mm: float, thickness_mm: float, max_levels: int = 64) -> np.ndarray:
    """The heights checked: the build's mid-layer heights over ``[z_lo, z_hi]`` at ``thickness_mm``, at most
    ``max_levels`` of them spread evenly over the height."""
    n = max(int(np.ceil((z_hi_mm - z_lo_mm) / thickness_mm - 0.5 - 1e-9)), 0)
    k = np.unique(np.linspace(0, n - 1, min(n, max_levels)).round().astype(np.int64)) if n else np.zeros(0, int)
    return z_lo_mm + (k + 0.5) * thickness_mm


def self_intersections(
    vertices: np.ndarray, faces: np.ndarray, z_mm: np.ndarray
) -> tuple[int, tuple[float, float, float] | None]:
    """Count the heights of ``z_mm`` (sorted) at which the mesh's cut has crossing loops, and where the first is.

    Args:
        vertices: (V, 3) mm. faces: (F, 3). z_mm: (L,) heights, increasing.
    Returns:
        (number of heights with crossings, (x, y, z) mm of a crossing at the lowest such height, or ``None``).
    """
    import shapely

    sl = slice_mesh(vertices, faces, np.asarray(z_mm, np.float64))
    n_loops = len(sl.loop_layer)
    if n_loops == 0:
        return 0, None
    sizes = np.diff(sl.loop_start)
    ok = sizes >= 3
    idx = np.repeat(np.arange(n_loops), sizes)
    keep = ok[idx]
    pts, ring_of = sl.points_mm[keep], idx[keep]
    loops = np.flatnonzero(ok)
    # each layer's loops moved apart along x, so that the tree pairs loops of one layer only (no layer's
    # predicate tests against the same footprint in every other layer); the shift is undone for the report
    span = float(np.ptp(sl.points_mm[:, 0])) + 1.0
    shift = sl.loop_layer[ring_of] * span
    pts = pts + np.column_stack([shift, np.zeros_like(shift)])
    # close each ring: shapely closes rings given with indices
    rings = shapely.linearrings(pts, indices=np.searchsorted(loops, ring_of))
    polys = shapely.polygons(rings)
    layer = sl.loop_layer[loops]
    bad_layer: dict[int, tuple[float, float]] = {}
    invalid = np.flatnonzero(~shapely.is_valid(polys))
    for i in invalid.tolist():  # one step per invalid loop (few: a defect)
        m = re.search(r"\[([-0-9.eE+]+) ([-0-9.eE+]+)\]", shapely.is_valid_reason(polys[i]))
        at = (float(m.group(1)), float(m.group(2))) if m else tuple(np.asarray(polys[i].exterior.coords[0]))
        bad_layer.setdefault(int(layer[i]), (at[0] - float(layer[i]) * span, at[1]))
    a, b = shapely.STRtree(polys).query(polys, predicate="overlaps")
    same = (layer[a] == layer[b]) & (a < b)  # (the shift keeps other layers' loops apart; this is a guard)
    for i, j in zip(a[same].tolist(), b[same].tolist(), strict=True):  # one step per crossing pair (a defect)
        if int(layer[i]) in bad_layer:
            continue
        cross = shapely.intersection(polys[i].exterior, polys[j].exterior)
        p = shapely.get_coordinates(cross)
        x0 = float(layer[i]) * span
        bad_layer[int(layer[i])] = (float(p[0, 0]) - x0, float(p[0, 1])) if len(p) else (np.nan, np.nan)
    if not bad_layer:
        return 0, None
    first = min(bad_layer)
    x, y = bad_layer[first]
    return len(bad_layer), (float(x), float(y), float(sl.z_mm[first]))
