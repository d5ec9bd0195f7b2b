"""Common Layer Interface (CLI) files, ASCII and binary: a writer for builds and a strict reader.

The format (CLI version 2.0, the BRITE-EURAM "Common Layer Interface" of 1994 that machine software reads):
a header of ASCII lines between ``$$HEADERSTART`` and ``$$HEADEREND`` — ``$$ASCII`` or ``$$BINARY``,
``$$UNITS/u`` (mm per coordinate unit), ``$$VERSION/200``, ``$$LABEL/id,text`` per part id, ``$$DIMENSION/x1,y1,
z1,x2,y2,z2`` (mm), ``$$LAYERS/n`` — then the geometry:

- ASCII: ``$$GEOMETRYSTART``, per layer ``$$LAYER/z``, then ``$$POLYLINE/id,dir,n,x1,y1,...,xn,yn`` (dir 0
  clockwise, 1 counter-clockwise, 2 open) and ``$$HATCHES/id,n,x1s,y1s,x1e,y1e,...``, then ``$$GEOMETRYEND``;
- binary, right after ``$$HEADEREND`` (no newline), little-endian, the "long" commands: ``uint16 127`` start layer
  + ``float32 z``; ``uint16 130`` polyline + ``int32 id, dir, n`` + ``2n float32``; ``uint16 132`` hatches +
  ``int32 id, n`` + ``4n float32``. The reader also takes the "short" commands (128 layer ``uint16 z``, 129
  polyline and 131 hatches with ``uint16`` fields and coordinates).

Coordinates and layer heights are in units (``value_mm / units``). jaxcnc writes one label per zone (id = zone
index + 1: core, contour, thin_wall, downskin, upskin), contours as closed polylines (first point repeated), and
each run of hatches of a zone as one ``$$HATCHES`` block. No date is written, so equal builds give equal files.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxcnc.pbf import CLIFileError
from jaxcnc.pbf.params import ZONES

CMD_LAYER_LONG, CMD_LAYER_SHORT = 127, 128
CMD_POLY_SHORT, CMD_POLY_LONG = 129, 130
CMD_HATCH_SHORT, CMD_HATCH_LONG = 131, 132
DIR_CW, DIR_CCW, DIR_OPEN = 0, 1, 2


@dataclass
class Polyline:
    """A polyline block: part id, direction (0 CW, 1 CCW, 2 open) and its points (n, 2) in mm."""

    id: int
    dir: int
    points_mm: np.ndarray


@dataclass
class HatchBlock:
    """A hatches block: part id and its vectors (m, 2, 2) in mm."""

    id: int
    segments_mm: np.ndarray


@dataclass
class CLILayer:
    """One layer: its height and blocks in file order."""

    z_mm: float
    blocks: list = field(default_factory=list)


@dataclass
class CLIData:
    """A whole CLI file: header values and layers."""

    units_mm: float = 1.0
    binary: bool = False
    labels: dict[int, str] = field(default_factory=dict)
    dimension_mm: tuple[float, ...] | None = None
    layers: list[CLILayer] = field(default_factory=list)


def layer_blocks(vectors: np.ndarray) -> list:
    """CLI blocks of a vector list (:data:`jaxcnc.pbf.order.VECTOR_DTYPE`), in scan order.

    Contour marks of one path become a closed polyline (direction from its signed area); consecutive hatch marks
    of one zone become one hatches block. Jumps are implied by the gaps.
    """
    mark = vectors["mark"] == 1
    v = vectors[mark]
    if len(v) == 0:
        return []
    path, zone = v["path"].astype(np.int64), v["zone"].astype(np.int64)
    key = np.where(path >= 0, path, -1) * 256 + zone
    brk = np.flatnonzero((key[1:] != key[:-1]) | ((path[1:] < 0) != (path[:-1] < 0))) + 1
    blocks = []
    for a, b in zip(np.concatenate([[0], brk]), np.concatenate([brk, [len(v)]]), strict=True):
        run = v[a:b]
        zid = int(run["zone"][0]) + 1
        if run["path"][0] >= 0:
            pts = np.column_stack([run["x0_mm"], run["y0_mm"]])
            x, y = pts[:, 0], pts[:, 1]
            area = 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
            blocks.append(Polyline(zid, DIR_CCW if area > 0 else DIR_CW, np.vstack([pts, pts[:1]])))
        else:
            seg = np.stack(
                [np.column_stack([run["x0_mm"], run["y0_mm"]]), np.column_stack([run["x1_mm"], run["y1_mm"]])], axis=1
            )
            blocks.append(HatchBlock(zid, seg))
    return blocks


def _fmt(a: np.ndarray) -> str:
    return ",".join(f"{x:.6f}" for x in np.asarray(a, dtype=np.float64).ravel())


def header_text(data: CLIData) -> str:
    """The header lines, ``$$HEADERSTART`` to ``$$HEADEREND`` (no newline after the last)."""
    lines = ["$$HEADERSTART", "$$BINARY" if data.binary else "$$ASCII", f"$$UNITS/{data.units_mm:.6f}", "$$VERSION/200"]
    lines += [f"$$LABEL/{i},{name}" for i, name in sorted(data.labels.items())]
    if data.dimension_mm is not None:
        lines.append("$$DIMENSION/" + ",".join(f"{x:.6f}" for x in data.dimension_mm))
    lines.append(f"$$LAYERS/{len(data.layers):06d}")
    return "\n".join(lines) + "\n$$HEADEREND"


def encode_layer(layer: CLILayer, units_mm: float, binary: bool) -> bytes:
    """The bytes of one layer of a CLI file (its layer command and blocks), ASCII or binary: a CLI file is its
    header and its layers' bytes in order, so layers are encoded where they are computed (:func:`encode_parts`)."""
    u = units_mm
    if binary:
        parts = [struct.pack("<Hf", CMD_LAYER_LONG, layer.z_mm / u)]
        for b in layer.blocks:
            if isinstance(b, Polyline):
                parts.append(struct.pack("<Hiii", CMD_POLY_LONG, b.id, b.dir, len(b.points_mm)))
                parts.append((np.asarray(b.points_mm, dtype=np.float64) / u).astype("<f4").tobytes())
            else:
                parts.append(struct.pack("<Hii", CMD_HATCH_LONG, b.id, len(b.segments_mm)))
                parts.append((np.asarray(b.segments_mm, dtype=np.float64) / u).astype("<f4").tobytes())
        return b"".join(parts)
    out = [f"$$LAYER/{layer.z_mm / u:.6f}\n"]
    for b in layer.blocks:
        if isinstance(b, Polyline):
            out.append(f"$$POLYLINE/{b.id},{b.dir},{len(b.points_mm)},{_fmt(b.points_mm / u)}\n")
        else:
            out.append(f"$$HATCHES/{b.id},{len(b.segments_mm)},{_fmt(b.segments_mm / u)}\n")
    return "".join(out).encode("ascii")


def encode_parts(data: CLIData, layer_parts: list[bytes]) -> bytes:
    """The bytes of a CLI file from its header values (``data``; ``data.layers`` only counted) and each layer's
    :func:`encode_layer` bytes in layer order."""
    head = header_text(data).encode("ascii")
    if data.binary:
        return b"".join([head, *layer_parts])
    return b"".join([head, b"\n$$GEOMETRYSTART\n", *layer_parts, b"$$GEOMETRYEND\n"])


def encode(data: CLIData) -> bytes:
    """The bytes of a CLI file (ASCII or binary per ``data.binary``)."""
    return encode_parts(data, [encode_layer(layer, data.units_mm, data.binary) for layer in data.layers])


def zone_labels() -> dict[int, str]:
    """The labels jaxcnc writes: id = zone index + 1."""
    return {i + 1: name for i, name in enumerate(ZONES)}


def write_cli(path: str | Path, data: CLIData, layer_parts: list[bytes] | None = None) -> None:
    """Write ``data`` to ``path`` (through a temporary name, renamed when complete); ``layer_parts``: the layers'
    bytes already encoded (:func:`encode_layer`), in place of ``data.layers``' blocks."""
    import os

    p = Path(path)
    tmp = p.with_name(f".{p.name}.tmp-{os.getpid()}")
    tmp.write_bytes(encode(data) if layer_parts is None else encode_parts(data, layer_parts))
    os.replace(tmp, p)


def _header(raw: bytes, file: str) -> tuple[CLIData, int]:
    """Parse the header; returns the data so far and the byte offset where the geometry starts."""
    start = raw.find(b"$$HEADERSTART")
    if start < 0:
        raise CLIFileError(f"{file}: not a CLI file (no $$HEADERSTART)")
    end = raw.find(b"$$HEADEREND", start)
    if end < 0:
        raise CLIFileError(f"{file}: the header does not end ($$HEADEREND missing)")
    try:
        text = raw[start:end].decode("ascii")
    except UnicodeDecodeError:
        raise CLIFileError(f"{file}: the header is not ASCII") from None
    data = CLIData()
    fmt = None
    line_no = raw[:start].count(b"\n") + 1
    for i, line in enumerate(text.splitlines()):
        line = re.sub(r"//.*?//", "", line).strip()
        where = f"{file}:{line_no + i}"
        try:
            if line == "$$ASCII":
                fmt = "ascii"
            elif line == "$$BINARY":
                fmt = "binary"
            elif line.startswith("$$UNITS/"):
                data.units_mm = float(line[8:])
                if not (np.isfinite(data.units_mm) and data.units_mm > 0):
                    raise ValueError("units must be positive")
            elif line.startswith("$$LABEL/"):
                ident, _, name = line[8:].partition(",")
                data.labels[int(ident)] = name
            elif line.startswith("$$DIMENSION/"):
                dims = tuple(float(x) for x in line[12:].split(","))
                if len(dims) != 6:
                    raise ValueError("a dimension has 6 numbers")
                data.dimension_mm = dims
        except ValueError as exc:
            raise CLIFileError(f"{where}: bad header line {line[:60]!r}: {exc}") from None
    if fmt is None:
        raise CLIFileError(f"{file}: the header says neither $$ASCII nor $$BINARY")
    data.binary = fmt == "binary"
    return data, end + len(b"$$HEADEREND")


def _ascii_geometry(text: str, data: CLIData, file: str, first_line: int) -> None:
    u = data.units_mm
    layer = None
    for i, line in enumerate(text.splitlines()):
        line = re.sub(r"//.*?//", "", line).strip()
        where = f"{file}:{first_line + i}"
        if not line or line in ("$$GEOMETRYSTART", "$$GEOMETRYEND"):
            continue
        cmd, _, args = line.partition("/")
        try:
            if cmd == "$$LAYER":
                layer = CLILayer(float(args) * u)
                data.layers.append(layer)
                continue
            if cmd not in ("$$POLYLINE", "$$HATCHES"):
                raise ValueError(f"unknown command {cmd!r}")
            if layer is None:
                raise ValueError(f"{cmd} before any $$LAYER")
            vals = args.split(",")
            if cmd == "$$POLYLINE":
                ident, d, n = int(vals[0]), int(vals[1]), int(vals[2])
                xy = np.array([float(x) for x in vals[3:]])
                if len(xy) != 2 * n or d not in (0, 1, 2):
                    raise ValueError(f"polyline of {n} points has {len(xy)} numbers, dir {d}")
                layer.blocks.append(Polyline(ident, d, xy.reshape(-1, 2) * u))
            else:
                ident, n = int(vals[0]), int(vals[1])
                xy = np.array([float(x) for x in vals[2:]])
                if len(xy) != 4 * n:
                    raise ValueError(f"{n} hatches have {len(xy)} numbers")
                layer.blocks.append(HatchBlock(ident, xy.reshape(-1, 2, 2) * u))
        except (ValueError, IndexError) as exc:
            raise CLIFileError(f"{where}: {exc}") from None


def _binary_geometry(raw: bytes, pos: int, data: CLIData, file: str) -> None:
    u = data.units_mm
    layer = None
    n_bytes = len(raw)

    def take(fmt: str) -> tuple:
        nonlocal pos
        size = struct.calcsize(fmt)
        if pos + size > n_bytes:
            raise CLIFileError(f"{file}: byte {pos}: truncated (needs {size} more bytes)")
        vals = struct.unpack_from(fmt, raw, pos)
        pos += size
        return vals

    def coords(count: int, dtype: str) -> np.ndarray:
        nonlocal pos
        size = count * np.dtype(dtype).itemsize
        if count < 0 or pos + size > n_bytes:
            raise CLIFileError(f"{file}: byte {pos}: truncated ({count} coordinates announced)")
        a = np.frombuffer(raw, dtype=dtype, count=count, offset=pos).astype(np.float64)
        pos += size
        return a * u

    while pos < n_bytes:
        at = pos
        (cmd,) = take("<H")
        if cmd in (CMD_LAYER_LONG, CMD_LAYER_SHORT):
            (z,) = take("<f" if cmd == CMD_LAYER_LONG else "<H")
            layer = CLILayer(float(z) * u)
            data.layers.append(layer)
            continue
        if cmd not in (CMD_POLY_SHORT, CMD_POLY_LONG, CMD_HATCH_SHORT, CMD_HATCH_LONG):
            raise CLIFileError(f"{file}: byte {at}: unknown command {cmd}")
        if layer is None:
            raise CLIFileError(f"{file}: byte {at}: geometry before any layer")
        long_ = cmd in (CMD_POLY_LONG, CMD_HATCH_LONG)
        if cmd in (CMD_POLY_SHORT, CMD_POLY_LONG):
            ident, d, n = take("<iii" if long_ else "<HHH")
            if d not in (0, 1, 2):
                raise CLIFileError(f"{file}: byte {at}: polyline direction {d}")
            layer.blocks.append(Polyline(ident, d, coords(2 * n, "<f4" if long_ else "<u2").reshape(-1, 2)))
        else:
            ident, n = take("<ii" if long_ else "<HH")
            layer.blocks.append(HatchBlock(ident, coords(4 * n, "<f4" if long_ else "<u2").reshape(-1, 2, 2)))


def decode(raw: bytes, file: str = "<cli>") -> CLIData:
    """Parse the bytes of a CLI file; raises :class:`CLIFileError` naming the file, line or byte, and cause."""
    data, pos = _header(raw, file)
    if data.binary:
        _binary_geometry(raw, pos, data, file)
    else:
        try:
            text = raw[pos:].decode("ascii")
        except UnicodeDecodeError as exc:
            raise CLIFileError(f"{file}: byte {pos + exc.start}: not ASCII") from None
        _ascii_geometry(text, data, file, raw[:pos].count(b"\n") + 1)
    return data


def read_cli(path: str | Path) -> CLIData:
    """Read a CLI file (ASCII or binary)."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise CLIFileError(f"{p}: cannot read: {exc.strerror or exc}") from None
    return decode(raw, str(p))
