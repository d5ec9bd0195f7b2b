"""Raster jobs at the tick stage: each tick's power read from the image by position, and the check that the laser
fires only where and as strongly as the image says (``docs/laser.md``). NumPy only.

Tick ``k``'s power is held over ``[k, k+1)``; it is ``S · level`` of the pixel under the tick's midpoint
``(p_k + p_{k+1}) / 2`` (:meth:`jaxcnc.io.image.RasterMap.level_at`, reverse lines shifted by the bidirectional
offset), on the ticks the program's burn rows light. A pixel therefore receives ``S · level / tick_hz`` per tick
whose midpoint lies in it: at the feed F, ``S · level · pixel_mm / F`` within one tick's energy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jaxcnc.io.image import RasterMap


def axes_xy(axis_names: list[str] | tuple[str, ...]) -> tuple[int, int]:
    """Columns of the machine axes x and y in a table's positions."""
    names = list(axis_names)
    return names.index("x"), names.index("y")


def raster_levels(image: RasterMap, p_mm: np.ndarray, xy: tuple[int, int]) -> np.ndarray:
    """Level of ticks ``k .. k+m-1`` from positions ``p_mm`` ``(m+1, n_axes)`` of ticks ``k .. k+m``: ``(m,)``
    float64 in [0, 1], the pixel under each tick's midpoint."""
    q = p_mm[:, list(xy)]
    return image.level_at((q[:-1] + q[1:]) / 2, np.diff(q, axis=0))


def pixel_of(image: RasterMap, p_mm: np.ndarray, xy: tuple[int, int]) -> np.ndarray:
    """Flat pixel index ``r · W + c`` under each tick's midpoint (``(m,)``; -1 outside the image)."""
    q = p_mm[:, list(xy)]
    mid, travel = (q[:-1] + q[1:]) / 2, np.diff(q, axis=0)
    d = image.direction
    back = (travel @ d) < 0
    rel = mid - image.origin_mm - np.where(back, image.bidir_offset_mm, 0.0)[:, None] * d
    h, w = image.levels.shape
    c = np.floor(rel[:, 0] / image.pixel_mm).astype(np.int64)
    r = h - 1 - np.floor(rel[:, 1] / image.pixel_mm).astype(np.int64)
    inside = (c >= 0) & (c < w) & (r >= 0) & (r < h)
    return np.where(inside, r * w + c, -1)


@dataclass
class PixelEnergy:
    """Energy per pixel against the image: ``S · level · pixel_mm / F`` each (axis-aligned scans).

    Attributes:
        n_pixels: lit pixels of the image.
        max_error_ticks: the largest difference, in ticks' energy at the pixel's power (allowed: 1 + the speed
            tolerance).
        bad: flat indices of pixels beyond it (at most 10 kept), and ``n_bad`` their count.
    """

    n_pixels: int
    max_error_ticks: float
    bad: list[int]
    n_bad: int


def pixel_energy(image: RasterMap, energy: np.ndarray, tick_hz: float, speed_tol: float) -> PixelEnergy | None:
    """Compare the energy each pixel received (``energy``: ``(H·W,)`` power·s, from the lit ticks) with the image;
    ``None`` when the scan lines are not axis-aligned (a slanted line's chord through a pixel varies)."""
    if abs(image.angle_deg / 90 - round(image.angle_deg / 90)) > 1e-9:
        return None
    lv = image.levels.reshape(-1).astype(np.float64) * image.power
    want = lv * image.pixel_mm / image.feed_mm_s
    tick = np.where(lv > 0, lv / tick_hz, 1.0)
    err = np.abs(energy - want) / tick
    allowed = 1.0 + speed_tol * image.pixel_mm / image.feed_mm_s * tick_hz + 1e-6
    bad = np.flatnonzero(err > allowed)
    return PixelEnergy(int((lv > 0).sum()), float(err.max(initial=0.0)), bad[:10].tolist(), int(bad.size))


def raster_of_table(table, machine) -> tuple[RasterMap | None, str]:
    """The image map a raster table was planned from, or ``(None, why not)``: its source read again with the
    recorded options (looked for from the working directory, then the table's folder; it must be unchanged),
    its placement checked against the header's ``raster`` record."""
    from pathlib import Path

    from jaxcnc.errors import JaxcncError
    from jaxcnc.format import file_sha256
    from jaxcnc.front_ends import ImageFrontEnd

    meta = table.header.meta
    rec = meta.get("raster")
    src = Path(str(meta.get("source", "")))
    if not src.is_file() and not src.is_absolute() and (table.path.parent / src).is_file():
        src = table.path.parent / src
    if not src.is_file():
        return None, f"its source image {str(src)!r} is not here: pixel powers not checked"
    if meta.get("source_sha256") and file_sha256(src) != meta["source_sha256"]:
        return None, f"{src} changed since the table was planned: pixel powers not checked"
    options = meta.get("source_options", {})
    if not isinstance(options, dict):
        raise JaxcncError(f"{table.path}: header source_options = {options!r}: must be a table of named options")
    image = ImageFrontEnd().raster(src, machine, **options).image
    if not isinstance(rec, dict) or rec != image.record():
        raise JaxcncError(
            f"{table.path}: header raster = {rec!r} differs from its source read again ({image.record()})"
        )
    return image, ""
