"""Raster images (PNG, BMP, TIFF through Pillow) engraved line by line at constant speed (``docs/laser.md``).

An image becomes a few rows per scan line, never one per pixel: an unlit **overscan** line from where the tool
starts at rest up to the line's first lit pixel (long enough to reach the feed), the **burn** line at the feed
(laser on, M3 at S = ``power``), an unlit overscan line after the last lit pixel to brake, and a link to the next
scan line. Blank lines are skipped, and each line only spans its lit pixels (blank margins skipped). The tick
writer reads each tick's power from the image by position (:mod:`jaxcnc.ticks.raster`): ``S · level`` of the
pixel under the tick's midpoint, ``level`` in [0, 1].

Geometry (mm, program x/y): the image's lower-left corner is at ``origin_mm``; pixel ``(r, c)`` (row 0 at the top)
covers ``x ∈ [c·p, (c+1)·p)``, ``y ∈ [(H-1-r)·p, (H-r)·p)`` from it, ``p = pixel_mm``. Scan lines run along
``u = (cos θ, sin θ)`` (θ = ``angle_deg``), ``p`` apart, the first half a pitch inside the image; at θ = 0 each
line runs through one pixel row's centres. The job's bounding box (overscan included) starts at the machine's
home, where every job starts.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from jaxcnc.errors import JaxcncError
from jaxcnc.program import Kind, LaserMode, Program, program_from_columns, program_start

if TYPE_CHECKING:
    from jaxcnc.machine import MachineConfig

#: Image suffixes read through Pillow.
IMAGE_SUFFIXES = (".png", ".bmp", ".tif", ".tiff")
#: Samples per pixel pitch along a scan line when finding its first and last lit pixel.
SAMPLES_PER_PIXEL = 4
#: Overscan beyond the distance the axes need to reach the feed (the planner's margin, jerk rounding).
OVERSCAN_MARGIN = 1.25
#: Largest image accepted, pixels (a 2 m × 2 m plate at 0.05 mm).
MAX_PIXELS = 40000 * 40000
DITHERS = ("none", "threshold", "floyd-steinberg")


@dataclass(frozen=True)
class RasterOptions:
    """How an image is engraved (the ``plan`` options of a raster image; ``None``: the default).

    Attributes:
        pixel_mm: pixel size and scan-line pitch (or ``dpi``; default: the file's DPI, else 0.1 mm; with only
            ``width_mm``: ``width_mm`` / the image's width).
        dpi: resolution in dots per inch (``pixel_mm = 25.4 / dpi``).
        width_mm: the engraved width; with a resolution the image is resampled (Lanczos) to it.
        feed_mm_s: the scan speed (default: the machine's ``[path] feed``); the laser fires only at it.
        power: S at black (the S scale of the table; default 1).
        power_min: the fraction of ``power`` at the lightest grey that is not white (greyscale map).
        dither: ``none`` (greyscale → power), ``threshold`` (black/white at ``threshold``), ``floyd-steinberg``.
        threshold: grey level 1..255 below which a pixel is black (``threshold`` dithering).
        unidirectional: every line in the same direction (default: serpentine).
        angle_deg: the scan lines' angle to x.
        overscan_mm: the unlit run before and after each line (default: what the axes need to reach the feed,
            × 1.25).
        bidir_offset_mm: reverse lines (serpentine) fire each pixel this far early along their travel,
            compensating a mark that lands that far late.
    """

    pixel_mm: float | None = None
    dpi: float | None = None
    width_mm: float | None = None
    feed_mm_s: float | None = None
    power: float = 1.0
    power_min: float = 0.0
    dither: str = "none"
    threshold: int = 128
    unidirectional: bool = False
    angle_deg: float = 0.0
    overscan_mm: float | None = None
    bidir_offset_mm: float = 0.0

    def __post_init__(self) -> None:
        def positive(name: str) -> None:
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} = {v!r}: must be a positive number")

        for name in ("pixel_mm", "dpi", "width_mm", "feed_mm_s", "power"):
            positive(name)
        if self.pixel_mm is not None and self.dpi is not None:
            raise ValueError("give pixel_mm or dpi, not both")
        if not 0.0 <= self.power_min < 1.0:
            raise ValueError(f"power_min = {self.power_min!r}: must be in [0, 1)")
        if self.dither not in DITHERS:
            raise ValueError(f"dither = {self.dither!r}: must be one of {', '.join(DITHERS)}")
        if not (isinstance(self.threshold, int) and 1 <= self.threshold <= 255):
            raise ValueError(f"threshold = {self.threshold!r}: must be a whole grey level in 1..255")
        if not math.isfinite(self.angle_deg):
            raise ValueError(f"angle_deg = {self.angle_deg!r}: must be finite")
        if self.overscan_mm is not None and not (math.isfinite(self.overscan_mm) and self.overscan_mm >= 0):
            raise ValueError(f"overscan_mm = {self.overscan_mm!r}: must be >= 0")
        if not math.isfinite(self.bidir_offset_mm):
            raise ValueError(f"bidir_offset_mm = {self.bidir_offset_mm!r}: must be finite")


@dataclass(frozen=True, eq=False)
class RasterMap:
    """An image as the tick writer and the check read it: power levels on a grid placed in the plane.

    Attributes:
        levels: ``(H, W)`` float32 in [0, 1], row 0 at the top (fraction of ``power``).
        origin_mm: ``(2,)`` program x, y of the image's lower-left corner.
        pixel_mm: pixel size (and scan-line pitch).
        angle_deg: scan-line angle.
        power: S at level 1.
        feed_mm_s: the scan speed.
        bidir_offset_mm: the reverse lines' firing offset (see :class:`RasterOptions`).
    """

    levels: np.ndarray
    origin_mm: np.ndarray
    pixel_mm: float
    angle_deg: float
    power: float
    feed_mm_s: float
    bidir_offset_mm: float = 0.0

    @property
    def direction(self) -> np.ndarray:
        """``(2,)`` unit scan direction u."""
        a = math.radians(self.angle_deg)
        return np.array([math.cos(a), math.sin(a)])

    def record(self) -> dict:
        """The transform as the table header records it (``raster``); the levels come from the source."""
        return {
            "shape": [int(s) for s in self.levels.shape],
            "origin_mm": [float(v) for v in self.origin_mm],
            "pixel_mm": float(self.pixel_mm),
            "angle_deg": float(self.angle_deg),
            "power": float(self.power),
            "feed_mm_s": float(self.feed_mm_s),
            "bidir_offset_mm": float(self.bidir_offset_mm),
        }

    def level_at(self, xy_mm: np.ndarray, travel: np.ndarray | None = None) -> np.ndarray:
        """Level of the pixel under each point ``xy_mm`` ``(n, 2)`` (0 outside the image); ``travel`` ``(n, 2)``:
        the motion over the tick, whose direction picks reverse lines for the bidirectional offset."""
        xy = np.asarray(xy_mm, np.float64) - self.origin_mm
        if travel is not None and self.bidir_offset_mm != 0.0:
            back = (np.asarray(travel) @ self.direction) < 0
            xy = xy - np.where(back, self.bidir_offset_mm, 0.0)[:, None] * self.direction
        h, w = self.levels.shape
        c = np.floor(xy[:, 0] / self.pixel_mm).astype(np.int64)
        r = h - 1 - np.floor(xy[:, 1] / self.pixel_mm).astype(np.int64)
        inside = (c >= 0) & (c < w) & (r >= 0) & (r < h)
        return np.where(inside, self.levels[np.clip(r, 0, h - 1), np.clip(c, 0, w - 1)], 0.0)


@dataclass(frozen=True, eq=False)
class RasterProgram(Program):
    """A raster job's Program carrying its image map (``raster``): the tick writer reads each tick's power from
    it (:func:`jaxcnc.ticks.table.write_table`)."""

    raster: RasterMap | None = None


@dataclass(frozen=True, eq=False)
class Raster:
    """A raster job: its Program (a few rows per scan line), the image map and the options it was read with."""

    program: Program
    image: RasterMap
    options: RasterOptions
    n_lines: int

    def source_options(self) -> dict:
        """The options as given (``None`` left out)."""
        return {k: v for k, v in asdict(self.options).items() if v is not None}


def read_levels(path: Path, options: RasterOptions) -> tuple[np.ndarray, float]:
    """The image's power levels ``(H, W)`` float32 in [0, 1] (row 0 on top) and its pixel size in mm.

    Transparency is composited over white; greyscale maps black → 1 and the lightest grey → ``power_min``, white
    → 0; dithering (Pillow's Floyd–Steinberg ``convert("1")``, or a threshold) gives 0 or 1. A file Pillow cannot
    decode is a one-line :class:`~jaxcnc.errors.JaxcncError` naming it."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            if im.width * im.height > MAX_PIXELS:
                raise JaxcncError(f"{path}: {im.width} x {im.height} pixels is beyond {MAX_PIXELS} pixels")
            dpi = im.info.get("dpi")
            if im.mode in ("RGBA", "LA", "PA") or (im.mode == "P" and "transparency" in im.info):
                rgba = im.convert("RGBA")
                white = Image.new("RGBA", rgba.size, (255, 255, 255, 255))
                grey = Image.alpha_composite(white, rgba).convert("L")
            else:
                grey = im.convert("L")
            grey.load()
    except JaxcncError:
        raise
    except FileNotFoundError:
        raise JaxcncError(f"{path}: no such image file") from None
    except Exception as exc:  # Pillow's decoders raise many kinds (OSError, SyntaxError, ValueError, ...)
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise JaxcncError(f"{path}: not a readable image ({why})") from None
    try:
        file_px = 25.4 / float(dpi[0]) if dpi and float(dpi[0]) > 1 else None
    except (TypeError, ValueError, IndexError):
        file_px = None
    if options.pixel_mm is not None:
        px = options.pixel_mm
    elif options.dpi is not None:
        px = 25.4 / options.dpi
    elif options.width_mm is not None:
        px = options.width_mm / grey.width
    else:
        px = file_px or 0.1
    if options.width_mm is not None and (options.pixel_mm is not None or options.dpi is not None):
        w = max(1, round(options.width_mm / px))
        h = max(1, round(grey.height * w / grey.width))
        if w * h > MAX_PIXELS:
            raise JaxcncError(f"{path}: resampled to {w} x {h} pixels, beyond {MAX_PIXELS} pixels")
        grey = grey.resize((w, h), Image.Resampling.LANCZOS)
    if options.dither == "floyd-steinberg":
        lit = np.asarray(grey.convert("1"), dtype=bool) == 0
        return lit.astype(np.float32), px
    g = np.asarray(grey, dtype=np.float32)
    if options.dither == "threshold":
        return (g < options.threshold).astype(np.float32), px
    level = options.power_min + (1.0 - options.power_min) * (255.0 - g) / 255.0
    return np.where(g < 255, level, 0.0).astype(np.float32), px


def overscan_mm(machine: MachineConfig, direction: np.ndarray, feed_mm_s: float) -> float:
    """The run the axes need to reach ``feed_mm_s`` from rest along ``direction`` (unit, x/y), × 1.25: each axis'
    acceleration (and jerk, when the machine gives one) shared along the direction."""
    a = j = math.inf
    for name, d in zip(("x", "y"), direction, strict=True):
        if abs(d) > 1e-12 and name in machine.axis_names:
            ax = machine.axis(name)
            a = min(a, ax.a_max / abs(d))
            if ax.j_max is not None:
                j = min(j, ax.j_max / abs(d))
    v = feed_mm_s
    if math.isinf(j):
        d_mm = v * v / (2 * a)
    elif v >= a * a / j:
        d_mm = v * v / (2 * a) + v * a / (2 * j)
    else:
        d_mm = v * math.sqrt(v / j)
    return OVERSCAN_MARGIN * d_mm


def _check_feed(path: Path, machine: MachineConfig, u: np.ndarray, feed: float) -> None:
    for name, d in zip(("x", "y"), u, strict=True):
        if abs(d) > 1e-12:
            if name not in machine.axis_names:
                raise JaxcncError(f"{path}: scan lines move axis {name.upper()}, which machine {machine.name!r} lacks")
            cap = machine.axis(name).v_max / abs(d)
            if feed > cap * (1 - 1e-4):
                raise JaxcncError(
                    f"{path}: feed {feed:g} mm/s along the scan lines needs axis {name.upper()} faster than its "
                    f"v_max {machine.axis(name).v_max:g} mm/s allows (at most {cap * (1 - 1e-4):.6g} mm/s)"
                )


def scan_lines(image: RasterMap, unidirectional: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lit extent of every scan line: ``(t, s0, s1)`` each ``(n_lines,)`` — the line at ``t`` along
    ``w = (-sin θ, cos θ)`` from the image's lower-left corner, lit from ``s0`` to ``s1`` along u (mm, in the
    image's frame), in burn order; blank lines left out. ``s0 > s1`` on lines burned backwards (serpentine)."""
    h, w = image.levels.shape
    px = image.pixel_mm
    u = image.direction
    wv = np.array([-u[1], u[0]])
    corners = np.array([[0, 0], [w, 0], [0, h], [w, h]], np.float64) * px
    t_lo, t_hi = (corners @ wv).min(), (corners @ wv).max()
    s_lo, s_hi = (corners @ u).min(), (corners @ u).max()
    n_t = max(1, round((t_hi - t_lo) / px - 1e-9))
    t = t_lo + (np.arange(n_t) + 0.5) * px
    ds = px / SAMPLES_PER_PIXEL
    n_s = max(1, math.ceil((s_hi - s_lo) / ds - 1e-9))
    s = s_lo + (np.arange(n_s) + 0.5) * ds
    if image.angle_deg % 360 == 0:  # lines along the pixel rows, bottom row first: read the grid directly
        lit = image.levels[::-1] > 0
        any_lit = lit.any(axis=1)
        first = np.argmax(lit, axis=1)
        last = w - 1 - np.argmax(lit[:, ::-1], axis=1)
        t, s0, s1 = t[any_lit], first[any_lit] * px, (last[any_lit] + 1) * px
    else:
        lit = np.zeros((n_t, n_s), bool)
        step = max(1, (1 << 22) // n_s)  # bounded memory: lines in batches
        for a in range(0, n_t, step):  # batches of lines, each batch vectorised
            tt = t[a : a + step]
            xy = tt[:, None, None] * wv + s[None, :, None] * u + image.origin_mm
            lit[a : a + step] = image.level_at(xy.reshape(-1, 2)).reshape(tt.size, n_s) > 0
        any_lit = lit.any(axis=1)
        first = np.argmax(lit, axis=1)
        last = n_s - 1 - np.argmax(lit[:, ::-1], axis=1)
        t, s0, s1 = t[any_lit], s[first[any_lit]] - ds / 2, s[last[any_lit]] + ds / 2
    if not unidirectional:
        back = np.arange(t.size) % 2 == 1
        s0, s1 = np.where(back, s1, s0), np.where(back, s0, s1)
    return t, s0, s1


def raster_job(path: str | Path, machine: MachineConfig, options: RasterOptions) -> Raster:
    """Read the image at ``path`` and plan its scan lines as a :class:`Raster` (Program + image map)."""
    path = Path(path)
    levels, px = read_levels(path, options)
    feed = options.feed_mm_s if options.feed_mm_s is not None else machine.path.feed
    angle = options.angle_deg
    u = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    _check_feed(path, machine, u, feed)
    over = options.overscan_mm if options.overscan_mm is not None else overscan_mm(machine, u, feed)
    off = options.bidir_offset_mm if not options.unidirectional else 0.0
    image = RasterMap(levels, np.zeros(2), px, angle, options.power, feed, off)
    t, s0, s1 = scan_lines(image, options.unidirectional)
    if t.size == 0:
        raise JaxcncError(f"{path}: the image is blank (no pixel to burn)")
    sign = np.sign(s1 - s0)
    shift = np.where(sign < 0, off, 0.0)  # reverse lines fire early: their burn runs `off` further along u
    b0, b1 = s0 + shift, s1 + shift
    o0, o1 = b0 - sign * over, b1 + sign * over
    wv = np.array([-u[1], u[0]])
    # points per line: overscan start, burn start, burn end, overscan end (image frame)
    pts = (t[:, None, None] * wv + np.stack([o0, b0, b1, o1], axis=1)[:, :, None] * u).reshape(-1, 2)
    start = program_start(machine)
    origin = start[:2] - pts.min(axis=0)  # the job's bounding box starts at the home
    image = RasterMap(levels, origin, px, angle, options.power, feed, off)
    pts = pts + origin
    n = t.size
    # rows: link to the overscan start (G0 for the first line, G1 unlit after), overscan, burn, overscan
    ends = pts.reshape(n, 4, 2)
    end2 = ends.reshape(-1, 2)
    starts = np.concatenate([start[None, :2], end2[:-1]])
    z = np.full((4 * n, 1), start[2])
    kind = np.full(4 * n, Kind.LINE, np.int8)
    role = np.tile(np.arange(4), n)
    burn = role == 2
    rapid = role == 0
    laser = np.where(burn, LaserMode.CONSTANT, LaserMode.OFF)
    program = program_from_columns(
        file=str(path),
        kind=kind,
        start=np.hstack([starts, z]),
        end=np.hstack([end2, z]),
        feed=np.where(rapid, np.nan, feed),
        rapid=rapid,
        laser=laser,
        power=np.where(burn, options.power, 0.0),
        line=np.repeat(np.arange(1, n + 1), 4),  # "line": the scan line's number
        stop_before=rapid,  # at rest before each link; through overscan → burn → overscan at the feed
    )
    keep = np.linalg.norm(end2 - starts, axis=1) > 0  # a zero overscan (overscan_mm = 0) adds no row
    cols = {f.name: getattr(program, f.name)[keep] for f in fields(Program) if f.name not in ("file", "curves")}
    return Raster(RasterProgram(file=program.file, raster=image, **cols), image, options, n)


def raster_options(path: Path, options: dict) -> RasterOptions:
    """:class:`RasterOptions` from keyword options (``None`` left out); a bad value is a one-line error."""
    try:
        return RasterOptions(**{k: v for k, v in options.items() if v is not None})
    except (TypeError, ValueError) as exc:
        raise JaxcncError(f"{path}: {exc}") from None


def gcode_per_pixel(raster: Raster, tick_hz: float | None = None) -> str:
    """The same job as per-pixel G-code, as common raster tools emit it: per scan line the overscan moves at
    ``S0``, then one ``G1 X… Y… S…`` per pixel (M3, the pixel's power), then the braking overscan.

    Used by ``jaxcnc bench raster`` as the G-code peer of the native raster job; the path is the same."""
    img, prog = raster.image, raster.program
    px = img.pixel_mm
    out = ["G21 G90", f"G0 X{prog.start[0, 0]:.4f} Y{prog.start[0, 1]:.4f}", "M3 S0", f"G1 F{60 * img.feed_mm_s:.6g}"]
    lines = []
    for r in np.flatnonzero(prog.laser == LaserMode.CONSTANT):  # burn rows (a few thousand: a loop per line)
        a, b = prog.start[r, :2], prog.end[r, :2]
        length = float(np.linalg.norm(b - a))
        n = max(1, round(length / px))
        f = (np.arange(n) + 1) / n
        ends = a + f[:, None] * (b - a)
        mids = a + ((np.arange(n) + 0.5) / n)[:, None] * (b - a)
        travel = np.broadcast_to(b - a, mids.shape)
        s = img.power * img.level_at(mids, travel)
        lines.append((r, ends, s))
    body = {r: "\n".join(f"G1 X{x:.4f} Y{y:.4f} S{v:.4g}" for (x, y), v in zip(e, s, strict=True)) for r, e, s in lines}
    for r in range(len(prog)):
        if r in body:
            out.append(body[r])
        elif prog.rapid[r]:
            out.append(f"G0 X{prog.end[r, 0]:.4f} Y{prog.end[r, 1]:.4f}")
        else:
            out.append(f"G1 X{prog.end[r, 0]:.4f} Y{prog.end[r, 1]:.4f} S0")
    out.append("M5\nM2\n")
    return "\n".join(out)
