"""Hard-case point clouds for in-glass engraving: what real images look like, not convex solids.

Real engraving clouds (portraits, models, lettering) are not raster solids of convex shapes with long
rows. Each generator here makes one difficulty, in serpentine raster burn order (rows alternate in
direction, every other layer takes its rows backwards, as ``--reorder`` orders a cloud) with the
dithered 100–150 µm spacing of :func:`~jaxcnc.io.raster.superellipsoid_raster`:

- :func:`holes_cloud` — a solid slab with round holes: long jumps between points of one row;
- :func:`short_rows_cloud` — thin shapes (needles, small spheres): rows of a few points, so row
  changes dominate;
- :func:`misaligned_cloud` — rows whose ends do not line up (jagged edges of a photo);
- :func:`sparse_cloud` — a low-density region: points 0.3–2 mm apart, every gap a jump;
- :func:`text_cloud` — 3-D text rendered with Pillow's font, extruded over layers;
- :func:`mesh_cloud` — a real solid: points on the raster grid inside a closed STL mesh (trimesh).

All take a ``seed`` and return ``(n, 3)`` mm; ``center_mm`` places the cloud in the machine's travel.
Shapes are evaluated on the whole grid at once (no loops over points).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

SPACING_MM = (0.100, 0.150)
ROW_MM = 0.125
LAYER_MM = 0.25
CENTER_MM = (50.0, 50.0, 20.0)


def grid_cloud(
    inside: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    box_mm: tuple[float, float, float],
    *,
    row_mm: float = ROW_MM,
    layer_mm: float = LAYER_MM,
    spacing_mm: tuple[float, float] = SPACING_MM,
    center_mm: tuple[float, float, float] = CENTER_MM,
    seed: int = 0,
) -> np.ndarray:
    """Raster points ``(n, 3)`` inside a shape, in serpentine burn order.

    ``inside(x, y, z)`` (arrays, mm, centred at 0) says which grid points belong to the shape;
    ``box_mm`` the half-widths of the box it lives in. Rows lie ``row_mm`` apart in y, layers
    ``layer_mm`` apart in z; along each row the spacing is drawn uniformly from ``spacing_mm``.
    """
    rng = np.random.default_rng(seed)
    a, b, c = box_mm
    zs = np.arange(-c + layer_mm / 2, c, layer_mm) if c > 0 else np.zeros(1)
    ys = np.arange(-b + row_mm / 2, b, row_mm)
    per_row = int(2 * a / spacing_mm[0]) + 2
    n_rows = zs.size * ys.size
    steps = rng.uniform(*spacing_mm, size=(n_rows, per_row))
    x = -a + np.cumsum(steps, axis=1) - steps[:, :1]
    y = np.repeat(np.tile(ys, zs.size), per_row).reshape(n_rows, per_row)
    z = np.repeat(np.repeat(zs, ys.size), per_row).reshape(n_rows, per_row)
    keep = (x <= a) & inside(x, y, z)
    if not keep.any():
        raise ValueError("the shape holds no grid point")
    # serpentine: rows in y order, backwards on odd layers; the k-th non-empty row runs +x when k is even
    layer = np.arange(n_rows) // ys.size
    rank = np.where(layer % 2 == 1, ys.size - 1 - np.arange(n_rows) % ys.size, np.arange(n_rows) % ys.size)
    burn = np.lexsort((rank, layer))  # rows in burn order
    used = keep.any(axis=1)[burn]
    sign = np.empty(n_rows)
    sign[burn] = np.where((np.cumsum(used) - 1) % 2 == 0, 1.0, -1.0)
    row_of = np.broadcast_to(np.argsort(burn)[:, None], x.shape)[keep]
    xs = x[keep]
    order = np.lexsort((sign[np.broadcast_to(np.arange(n_rows)[:, None], x.shape)[keep]] * xs, row_of))
    pts = np.column_stack([xs, y[keep], z[keep]])[order]
    return pts + np.asarray(center_mm)


def holes_cloud(n_holes: int = 12, size_mm: tuple[float, float] = (10.0, 6.0), seed: int = 0, **kw) -> np.ndarray:
    """A slab ``2 size_mm`` wide, two layers, with ``n_holes`` round holes 0.5–3 mm across."""
    rng = np.random.default_rng(seed + 7)
    a, b = size_mm
    cx, cy = rng.uniform(-a, a, n_holes), rng.uniform(-b, b, n_holes)
    r = rng.uniform(0.25, 1.5, n_holes)

    def inside(x, y, z):
        d2 = (x[..., None] - cx) ** 2 + (y[..., None] - cy) ** 2
        return np.all(d2 > r * r, axis=-1)

    return grid_cloud(inside, (a, b, kw.pop("depth_mm", 0.25)), seed=seed, **kw)


def short_rows_cloud(n_shapes: int = 24, seed: int = 0, **kw) -> np.ndarray:
    """Small spheres (0.3–1.2 mm radius) scattered over a 20 × 12 mm field: rows of 2–20 points."""
    rng = np.random.default_rng(seed + 11)
    cx, cy = rng.uniform(-9.0, 9.0, n_shapes), rng.uniform(-5.0, 5.0, n_shapes)
    cz = rng.uniform(-1.0, 1.0, n_shapes)
    r = rng.uniform(0.3, 1.2, n_shapes)

    def inside(x, y, z):
        d2 = (x[..., None] - cx) ** 2 + (y[..., None] - cy) ** 2 + (z[..., None] - cz) ** 2
        return np.any(d2 <= r * r, axis=-1)

    return grid_cloud(inside, (10.5, 6.5, 2.25), seed=seed, **kw)


def misaligned_cloud(size_mm: tuple[float, float] = (8.0, 6.0), jag_mm: float = 2.0, seed: int = 0, **kw):
    """A slab whose rows start and end up to ``jag_mm`` from the edge, at random (a photo's jagged edges)."""
    rng = np.random.default_rng(seed + 13)
    a, b = size_mm
    n_rows = int(2 * b / ROW_MM) + 2
    left, right = rng.uniform(0.0, jag_mm, n_rows), rng.uniform(0.0, jag_mm, n_rows)

    def inside(x, y, z):
        row = np.clip(((y + b) / ROW_MM).astype(np.int64), 0, n_rows - 1)
        return (x >= -a + left[row]) & (x <= a - right[row])

    return grid_cloud(inside, (a, b, kw.pop("depth_mm", 0.25)), seed=seed, **kw)


def sparse_cloud(size_mm: tuple[float, float] = (8.0, 6.0), keep: float = 0.12, seed: int = 0, **kw) -> np.ndarray:
    """A faint region: a slab of which only ``keep`` of the grid points are burned (gaps of 0.1–2 mm)."""
    rng = np.random.default_rng(seed + 17)
    a, b = size_mm

    def inside(x, y, z):
        return rng.random(x.shape) < keep

    return grid_cloud(inside, (a, b, kw.pop("depth_mm", 0.25)), seed=seed, **kw)


def text_cloud(text: str = "jaxcnc", height_mm: float = 6.0, depth_mm: float = 0.5, seed: int = 0, **kw):
    """3-D text: ``text`` rendered with Pillow's built-in font, ``height_mm`` tall, extruded ``2 depth_mm``.

    Rows cross the strokes, so every row is a few short runs with jumps between letters.
    """
    from PIL import Image, ImageDraw, ImageFont

    font = ImageFont.load_default(size=64) if hasattr(ImageFont, "load_default") else None
    left, top, right, bottom = ImageDraw.Draw(Image.new("L", (1, 1))).textbbox((0, 0), text, font=font)
    img = Image.new("L", (right - left + 4, bottom - top + 4), 0)
    ImageDraw.Draw(img).text((2 - left, 2 - top), text, fill=255, font=font)
    mask = np.asarray(img) > 127
    px_mm = height_mm / mask.shape[0]
    a, b = mask.shape[1] * px_mm / 2, mask.shape[0] * px_mm / 2

    def inside(x, y, z):
        col = np.clip(((x + a) / px_mm).astype(np.int64), 0, mask.shape[1] - 1)
        row = np.clip(((b - y) / px_mm).astype(np.int64), 0, mask.shape[0] - 1)
        return mask[row, col]

    return grid_cloud(inside, (a, b, depth_mm), seed=seed, **kw)


def mesh_cloud(path: str | Path, size_mm: float = 20.0, seed: int = 0, max_points: int | None = None, **kw):
    """Points on the raster grid inside a closed mesh (an STL, read with trimesh), scaled to ``size_mm``.

    The mesh is centred and scaled so its largest extent is ``size_mm``. Inside is decided per row: one
    ray along +x through each row (``mesh.ray.intersects_location``), a point is inside when an odd
    number of crossings lies before it (the even-odd rule; a closed mesh gives pairs).
    ``max_points`` keeps the first points in burn order.
    """
    import trimesh

    mesh = trimesh.load_mesh(str(path))
    lo, hi = mesh.bounds
    scale = size_mm / float(np.max(hi - lo))
    mesh.apply_translation(-(lo + hi) / 2)
    mesh.apply_scale(scale)
    half = (hi - lo) * scale / 2

    def inside(x, y, z):
        y0, z0 = y[:, 0], z[:, 0]  # one ray per row, from beyond the left end
        origins = np.column_stack([np.full(y0.shape, -half[0] - 1.0), y0 + 1e-7, z0 + 1.3e-7])
        dirs = np.tile([1.0, 0.0, 0.0], (y0.shape[0], 1))
        hit, ray, _ = mesh.ray.intersects_location(origins, dirs, multiple_hits=True)
        span = 4.0 * half[0] + 10.0  # rows apart on one sorted axis
        key = np.sort(ray * span + hit[:, 0])
        q = np.arange(x.shape[0])[:, None] * span + x
        before = np.searchsorted(key, q) - np.searchsorted(key, np.arange(x.shape[0])[:, None] * span - span / 2)
        return before % 2 == 1

    pts = grid_cloud(inside, tuple(float(h) for h in half), seed=seed, **kw)
    return pts if max_points is None else pts[:max_points]


#: The hard cases the pulsed benchmark runs, by name: ``() -> points``.
HARD_CASES: dict[str, Callable[[], np.ndarray]] = {
    "holes": lambda: holes_cloud(seed=1),
    "short-rows": lambda: short_rows_cloud(seed=2),
    "misaligned": lambda: misaligned_cloud(seed=3),
    "sparse": lambda: sparse_cloud(seed=4),
    "text": lambda: text_cloud(seed=5),
}
