"""Special zones of a layer: thin walls, down-skin, up-skin, and the core that is left.

- thin walls: the parts of the region narrower than ``thin_wall_mm``: the region minus its opening (offset in by
  half the width, then out again, mitred joins: a wall wider than the threshold comes back whole, a narrower one
  does not come back at all);
- down-skin: material with no material under it in one of the ``skin_layers`` layers below (the plate counts as
  material: the first layer has none);
- up-skin: material with no material over it in one of the ``skin_layers`` layers above (the last layer is all
  up-skin);
- core: the rest.

The zones partition the region, in this order of precedence: thin wall, down-skin, up-skin, core.
"""

from __future__ import annotations

from jaxcnc.pbf import contours as cc


def thin_walls(region: cc.Region, width_mm: float) -> cc.Region:
    """The parts of ``region`` narrower than ``width_mm`` (empty when ``width_mm`` is 0)."""
    if width_mm <= 0 or not region:
        return []
    opened = cc.offset(cc.offset(region, -width_mm / 2, join="miter"), width_mm / 2, join="miter")
    return cc.difference(region, opened)


def _common(regions: list[cc.Region]) -> cc.Region:
    out = regions[0]
    for r in regions[1:]:
        out = cc.intersection(out, r)
    return out


def split_zones(
    region: cc.Region,
    below: list[cc.Region] | None,
    above: list[cc.Region] | None,
    thin_wall_mm: float,
) -> dict[str, cc.Region]:
    """Partition ``region`` into zones.

    Args:
        region: the layer's region. below / above: the regions of the ``skin_layers`` layers under / over it
            (``None``: the plate is under it, or skins are off; an empty list entry: no material there).
        thin_wall_mm: the thin-wall threshold (0: none).
    Returns:
        ``{"thin_wall", "downskin", "upskin", "core"}`` -> region.
    """
    thin = thin_walls(region, thin_wall_mm)
    rest = cc.difference(region, thin) if thin else region
    down = cc.difference(rest, _common(below)) if below else []
    rest = cc.difference(rest, down) if down else rest
    up = cc.difference(rest, _common(above)) if above else []
    core = cc.difference(rest, up) if up else rest
    return {"thin_wall": thin, "downskin": down, "upskin": up, "core": core}
