"""``--reorder``: burn the points in serpentine raster order (fewer reversals and long jumps).

Points are grouped into layers (z values closer than ``tol_mm`` belong together), each layer into
rows (y likewise), and rows are burned alternately left-to-right and right-to-left, every other
layer taking its rows in reverse, so each row starts next to where the previous one ended. The
order is one ``lexsort``; no loops over points. A cloud that is already a serpentine raster keeps
its order; a shuffled, one-directional or column-wise cloud gets the raster one.
"""

from __future__ import annotations

import numpy as np

#: Coordinates closer than this (mm) are on the same layer / row. Engraving points are 100 µm
#: or more apart, so half of that separates rows without merging neighbours.
DEFAULT_TOL_MM = 0.05


def _groups(values: np.ndarray, tol: float) -> np.ndarray:
    """Group ids ``(n,)`` (ascending with ``values``): a new group where sorted values jump > tol."""
    order = np.argsort(values, kind="stable")
    jump = np.concatenate([[0], (np.diff(values[order]) > tol).astype(np.int64)])
    ids = np.empty_like(order)
    ids[order] = np.cumsum(jump)
    return ids


def serpentine_order(points: np.ndarray, tol_mm: float = DEFAULT_TOL_MM) -> np.ndarray:
    """Indices ``(n,)`` that put ``points`` ``(n, 3)`` in serpentine raster order."""
    layer = _groups(points[:, 2], tol_mm)
    # rows: y groups within each layer (sort by layer, then y)
    by_layer_y = np.lexsort((points[:, 1], layer))
    ys = points[by_layer_y, 1]
    new_row = np.concatenate([[True], (np.diff(layer[by_layer_y]) != 0) | (np.diff(ys) > tol_mm)])
    row = np.empty_like(layer)
    row[by_layer_y] = np.cumsum(new_row) - 1
    # rank of each row inside its layer; odd layers take their rows in reverse
    first_row = np.full(layer.max() + 1, np.iinfo(np.int64).max)
    np.minimum.at(first_row, layer, row)
    last_row = np.full(layer.max() + 1, -1)
    np.maximum.at(last_row, layer, row)
    rank = row - first_row[layer]
    rank = np.where(layer % 2 == 1, last_row[layer] - row, rank)
    # serpentine: the k-th row burned overall runs +x when k is even
    n_rows_before = np.concatenate([[0], np.cumsum(last_row - first_row + 1)[:-1]])
    k = n_rows_before[layer] + rank
    direction = np.where(k % 2 == 0, 1.0, -1.0)
    return np.lexsort((direction * points[:, 0], rank, layer))
