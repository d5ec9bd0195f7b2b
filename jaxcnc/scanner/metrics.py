"""Figures of merit of a burn: how far the lit beam strays from the programmed path, and the dose along it.

The dose is energy per mm of programmed path: every lit tick deposits ``power · dt`` at the arc length of the
nearest point of its polyline (shapely), smeared along the path by the spot (a Gaussian of ``spot_mm``); its
ratio to the straight-run dose ``power / speed`` is 1 on a run marked at constant speed, above 1 where the beam
lingers (a corner it waits at, a start it accelerates from) and towards 0.5 at a run's very ends.
"""

from __future__ import annotations

import math

import numpy as np
import shapely


def burn_figures(
    paths: list[np.ndarray], speeds_mm_s: list[float], actual_mm: np.ndarray, power: np.ndarray, dt_s: float,
    spot_mm: float = 0.025, corner_deg: float = 20.0,
) -> dict:  # fmt: skip
    """Deviation while lit and dose ratios at corners (turning more than ``corner_deg``), run ends and straights.

    ``paths``: the programmed lit polylines (mm); ``actual_mm`` ``(n, 2)`` the beam per tick; ``power`` ``(n,)``.
    Returns ``max_deviation_mm``, ``p99_deviation_mm``, ``corner_dose_max``, ``end_dose_max``,
    ``straight_dose_median``, ``straight_dose_max``, ``straight_dose_min`` (ratios to ``power / speed``).
    """
    lit = power > 0
    lines = [shapely.LineString(p) for p in paths]
    pts = shapely.points(actual_mm[lit])
    tree = shapely.STRtree(lines)
    owner, dist = tree.query_nearest(pts, return_distance=True, all_matches=False)
    pt_idx, line_idx = owner
    dev = np.zeros(pts.shape[0])
    np.maximum.at(dev, pt_idx, dist)
    s = shapely.line_locate_point(np.asarray(lines, dtype=object)[line_idx], pts[pt_idx])
    energy = power[lit][pt_idx] * dt_s
    out = {"max_deviation_mm": float(dev.max()) if dev.size else 0.0,
           "p99_deviation_mm": float(np.percentile(dev, 99)) if dev.size else 0.0}  # fmt: skip
    bin_mm = spot_mm / 5
    ker_x = np.arange(-4 * spot_mm, 4 * spot_mm + bin_mm / 2, bin_mm)
    ker = np.exp(-0.5 * (ker_x / spot_mm) ** 2)
    ker /= ker.sum() * bin_mm
    corner, end, straight = [], [], []
    for k, (line, path) in enumerate(zip(lines, paths, strict=True)):  # one step per programmed run
        length = line.length
        nb = max(1, math.ceil(length / bin_mm))
        sel = line_idx == k
        hist = np.bincount(np.minimum((s[sel] / bin_mm).astype(np.int64), nb - 1), energy[sel], minlength=nb)
        dose = np.convolve(hist, ker, mode="same") * bin_mm / bin_mm  # energy per mm
        nominal = float(np.max(power[lit])) / speeds_mm_s[k] if lit.any() else 1.0
        ratio = dose / nominal
        centre = (np.arange(nb) + 0.5) * bin_mm
        seg = np.diff(path, axis=0)
        cum = np.concatenate([[0], np.cumsum(np.hypot(*seg.T))])
        cross = seg[:-1, 0] * seg[1:, 1] - seg[:-1, 1] * seg[1:, 0]
        ang = np.degrees(np.abs(np.arctan2(cross, np.einsum("ij,ij->i", seg[:-1], seg[1:]))))
        sharp = cum[1:-1][ang > corner_deg]
        w = 3 * spot_mm
        near_corner = np.zeros(nb, bool)
        if sharp.size:
            near_corner = np.min(np.abs(centre[:, None] - sharp[None, :]), axis=1) <= w
        near_end = (centre <= w) | (centre >= length - w)
        corner.append(ratio[near_corner & ~near_end])
        end.append(ratio[near_end])
        straight.append(ratio[~near_corner & ~near_end])
    cat = [np.concatenate(x) if x else np.zeros(0) for x in (corner, end, straight)]
    out["corner_dose_max"] = float(cat[0].max()) if cat[0].size else float("nan")
    out["end_dose_max"] = float(cat[1].max()) if cat[1].size else float("nan")
    out["straight_dose_median"] = float(np.median(cat[2])) if cat[2].size else float("nan")
    out["straight_dose_max"] = float(cat[2].max()) if cat[2].size else float("nan")
    out["straight_dose_min"] = float(cat[2].min()) if cat[2].size else float("nan")
    return out
