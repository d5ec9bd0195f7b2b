"""Raster point clouds for in-glass engraving, ordered the way a raster CAM emits them.

A solid (here a superellipsoid ``|x/A|^p + |y/B|^p + |z/C|^p <= 1``) is cut into layers ``layer_mm``
apart; each layer into rows ``row_mm`` apart; each row's chord gets points whose spacing is drawn
uniformly from ``spacing_mm`` (the dither engraving images use against moiré). Rows run
serpentine (alternating direction) and every other layer runs its rows backwards, so each row and
each layer starts near where the previous one ended. Used by the pulsed benchmark (the documents'
14-program table) and the tests; ``jaxcnc`` reads real point clouds from ``.xyz`` files.
"""

from __future__ import annotations

import numpy as np


def superellipsoid_raster(
    semi_axes_mm: tuple[float, float, float],
    *,
    power: float = 4.0,
    row_mm: float = 0.125,
    layer_mm: float = 0.125,
    spacing_mm: tuple[float, float] = (0.100, 0.150),
    center_mm: tuple[float, float, float] = (0.0, 0.0, 0.0),
    seed: int = 0,
    max_points: int | None = None,
) -> np.ndarray:
    """Points ``(n, 3)`` mm of a raster-engraved superellipsoid, in serpentine burn order."""
    rng = np.random.default_rng(seed)
    a, b, c = semi_axes_mm
    zs = np.arange(-c + layer_mm / 2, c, layer_mm)
    rows: list[np.ndarray] = []
    count = 0
    for li, z in enumerate(zs):
        ys = np.arange(-b + row_mm / 2, b, row_mm)
        if li % 2:
            ys = ys[::-1]
        for y in ys:
            rest = 1.0 - abs(y / b) ** power - abs(z / c) ** power
            if rest <= 0:
                continue
            half = a * rest ** (1.0 / power)
            step = rng.uniform(*spacing_mm, size=int(2 * half / spacing_mm[0]) + 2)
            x = -half + np.concatenate([[0.0], np.cumsum(step)])
            x = x[x <= half]
            if x.size == 0:
                continue
            if len(rows) % 2:
                x = x[::-1]
            row = np.column_stack([x, np.full_like(x, y), np.full_like(x, z)])
            rows.append(row)
            count += row.shape[0]
            if max_points is not None and count >= max_points:
                break
        if max_points is not None and count >= max_points:
            break
    pts = np.vstack(rows) + np.asarray(center_mm)
    return pts if max_points is None else pts[:max_points]


def write_xyz(path, points: np.ndarray, energy: np.ndarray | None = None) -> None:
    """Write a ``.xyz`` point file (``x y z [energy]``, µm-exact decimals)."""
    cols = points if energy is None else np.column_stack([points, energy])
    np.savetxt(path, cols, fmt="%.6f", header="x y z" + (" energy" if energy is not None else ""), comments="# ")
