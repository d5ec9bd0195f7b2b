"""One layer from its slice loops to its scan: contours, zones, hatches, the vector list.

:func:`process_chunk` is the unit of work of a build (serial or on Dask): it slices a run of layers (and the
``skin_layers`` around it the skins need) in one vectorised pass and returns each layer's result. A layer's
result depends only on the mesh, the parameters and its index — never on the chunk it was computed in.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from jaxcnc.pbf import contours as cc
from jaxcnc.pbf.hatch import hatch_region
from jaxcnc.pbf.order import vector_list
from jaxcnc.pbf.params import ZONE_ID, BuildParams
from jaxcnc.pbf.slice import slice_mesh
from jaxcnc.pbf.zones import split_zones

#: Zones hatched, in scan order within a layer (thin walls last, before the contours).
HATCH_ZONES = ("downskin", "core", "upskin", "thin_wall")


@dataclass
class LayerScan:
    """A layer's scan: its vector list (:data:`jaxcnc.pbf.order.VECTOR_DTYPE`) and what it is made of."""

    index: int
    z_mm: float
    vectors: np.ndarray
    zone_area_mm2: dict[str, float] = field(default_factory=dict)
    hatch_length_mm: float = 0.0


def hatch_boundary_offset_mm(params: BuildParams) -> float:
    """How far inside the part's boundary the hatched region ends (spot compensation, contours, hatch offset)."""
    comp = params.spot_diameter_mm / 2
    if params.contour_count == 0:
        return comp
    return comp + (params.contour_count - 1) * params.contour_spacing_mm + params.hatch_offset_mm


def scan_layer(
    k: int, z_mm: float, region: cc.Region, below: list | None, above: list | None, params: BuildParams
) -> LayerScan:
    """Contours, zones and hatches of layer ``k`` whose region (Clipper paths) is ``region``.

    ``below``/``above``: the regions of the ``skin_layers`` layers under/over it (``None``: none are considered).
    """
    comp = params.spot_diameter_mm / 2
    contour_paths = cc.contour_offsets(region, comp, params.contour_count, params.contour_spacing_mm)
    boundary = cc.offset(region, -hatch_boundary_offset_mm(params))
    zones = split_zones(region, below, above, params.thin_wall_mm)
    angle = params.layer_angle_deg(k)
    segs, zone_of = [], []
    length = 0.0
    only_core = not (zones["thin_wall"] or zones["downskin"] or zones["upskin"])
    for name in HATCH_ZONES:
        if not zones[name]:
            continue
        if name == "thin_wall":
            area = cc.intersection(zones[name], cc.offset(region, -comp))
            pattern = "meander"
        else:
            area = boundary if only_core else cc.intersection(zones[name], boundary)
            pattern = params.hatch_pattern
        h = hatch_region(
            cc.to_mm(area),
            params.hatch_spacing_mm,
            angle,
            pattern,
            params.stripe_width_mm,
            params.island_size_mm,
            params.min_hatch_mm,
            params.scan_order,
        )
        segs.append(h.segments_mm)
        zone_of.append(np.full(len(h.segments_mm), ZONE_ID[name], dtype=np.int64))
        length += h.length_mm
    loops = [p for r in contour_paths for p in cc.to_mm(r)]
    vectors = vector_list(
        np.concatenate(segs) if segs else np.zeros((0, 2, 2)),
        np.concatenate(zone_of) if zone_of else np.zeros(0, dtype=np.int64),
        loops,
        [ZONE_ID["contour"]] * len(loops),
        params,
    )
    areas = {name: cc.area_mm2(r) for name, r in zones.items()}
    return LayerScan(k, float(z_mm), vectors, areas, length)


def process_chunk(
    vertices: np.ndarray, faces: np.ndarray, z_all_mm: np.ndarray, layers: list[int], params: BuildParams
) -> list[LayerScan]:
    """Slice and scan the layers ``layers`` (indices into ``z_all_mm``, consecutive) of a prepared mesh."""
    if not layers:
        return []
    n = params.skin_layers
    lo = max(layers[0] - n, 0)
    hi = min(layers[-1] + n + 1, len(z_all_mm))
    sl = slice_mesh(vertices, faces, z_all_mm[lo:hi])
    regions = {lo + i: cc.layer_region(sl.layer_loops(i)) for i in range(hi - lo)}
    out = []
    for k in layers:
        if n > 0:
            below = None if k == 0 else [regions.get(j, []) for j in range(k - n, k) if j >= 0]
            above = [regions.get(j, []) if j < len(z_all_mm) else [] for j in range(k + 1, k + n + 1)]
        else:
            below = above = None
        out.append(scan_layer(k, z_all_mm[k], regions[k], below, above, params))
    return out
