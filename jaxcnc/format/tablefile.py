"""The tick table file, version 2 (and version 1, read) — NumPy and the standard library only.

This module is shared by the planning side (:mod:`jaxcnc.ticks` writes tables) and the player side
(:mod:`jaxcnc.hw` reads them on a controller that may have no JAX). ``docs/table-format.md`` specifies
the bytes precisely enough for firmware; the event records are in :mod:`jaxcnc.format.events`.

Layout (all little-endian)::

    [fixed header, 128 bytes][JSON metadata][pad to 4096]
    [CRC table: u32 per position block, then u32 per fine block]
    [position blocks: n_blocks × block_rows × n_axes int32]
    [fine blocks:     n_blocks × block_rows × n_axes int32]   (only if FLAG_FINE)
    [power blocks:    n_blocks × block_rows float32]          (only if FLAG_POWER, version 2)
    [event records: n_events × 24 bytes]

Rows are ticks ``0 .. n_rows-1``; the last block is padded by repeating the final row.
Positions are integer discretes (``round(p / discrete_mm)``). The optional *fine* channel holds
the rounding residual ``p / discrete_mm - position`` in units of 2^-32 discrete, which lets a
checker measure speed and acceleration at the tick rate from the unquantised path. The optional
*power* channel (version 2) holds the laser output of every tick (the S scale; M4 scaled with speed).
Version 1 files are read unchanged: their power is the held value of their ``laser`` events
(:meth:`TableFile.read_power`).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxcnc.errors import TableFileError
from jaxcnc.format.events import EVENT_DTYPE, EventKind

MAGIC = b"JXCNCTBL"
VERSION = 2
#: Versions this reader accepts (version 1: no power channel, no ``feed`` events).
READ_VERSIONS = (1, 2)
HEADER_SIZE = 128
DATA_ALIGN = 4096
DEFAULT_BLOCK_ROWS = 4096
FLAG_FINE = 1
FLAG_POWER = 2
FINE_SCALE = 2.0**32  # fine units per discrete

# Bounds a header must respect (docs/table-format.md, "Validation"): a reader refuses anything outside them.
MAX_AXES = 32
MAX_BLOCK_ROWS = 1 << 20
MAX_JSON_BYTES = 1 << 20
TICK_HZ_RANGE = (1.0, 1e6)
DISCRETE_MM_RANGE = (1e-9, 0.1)
#: An axis name: an ASCII letter, then up to 31 letters, digits or underscores.
AXIS_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,31}", re.ASCII)
# Metadata keys jaxcnc reads or writes, with the values they may hold (other keys are ignored).
_META_TEXT = ("machine", "machine_file", "machine_sha256", "source", "source_sha256", "generator", "planner")
_META_COUNT = ("n_blocks", "n_points")
_META_NONNEG = ("total_time_s", "pulse_tolerance")
_META_POSITIVE = ("pulse_hz",)

# magic, version, n_axes, block_rows, flags, tick_hz, discrete_mm, n_rows, n_blocks, json_bytes,
# n_events, events_crc, data_offset, events_offset; then the header CRC at byte 124.
_HEADER = struct.Struct("<8sHHIIddQQIQIQQ")
_FIELDS = (
    "magic",
    "version",
    "n_axes",
    "block_rows",
    "flags",
    "tick_hz",
    "discrete_mm",
    "n_rows",
    "n_blocks",
    "json_bytes",
    "n_events",
    "events_crc",
    "data_offset",
    "events_offset",
)
# the TableHeader fields that come from the fixed header (json_bytes only sizes the metadata)
_HEADER_KEYS = tuple(f for f in _FIELDS if f not in ("magic", "version", "json_bytes"))
assert _HEADER.size <= 124


@dataclass(frozen=True)
class TableHeader:
    """The self-description of a table file."""

    n_axes: int
    block_rows: int
    flags: int
    tick_hz: float
    discrete_mm: float
    n_rows: int
    n_blocks: int
    n_events: int
    events_crc: int
    data_offset: int
    events_offset: int
    meta: dict
    version: int = VERSION

    @property
    def axes(self) -> list[str]:
        return list(self.meta.get("axes", []))

    @property
    def has_fine(self) -> bool:
        return bool(self.flags & FLAG_FINE)

    @property
    def has_power(self) -> bool:
        return bool(self.flags & FLAG_POWER)

    @property
    def n_channels(self) -> int:
        """Blocks of CRCs per block index: positions, then fine, then power (those present)."""
        return 1 + self.has_fine + self.has_power

    @property
    def block_bytes(self) -> int:
        return self.block_rows * self.n_axes * 4

    @property
    def power_block_bytes(self) -> int:
        return self.block_rows * 4

    @property
    def crc_offset(self) -> int:
        return self.data_offset - 4 * self.n_blocks * self.n_channels

    @property
    def fine_offset(self) -> int:
        return self.data_offset + self.n_blocks * self.block_bytes

    @property
    def power_offset(self) -> int:
        return self.data_offset + self.n_blocks * self.block_bytes * (2 if self.has_fine else 1)


def fixed_to_mm(pos: np.ndarray, fine: np.ndarray | None, discrete_mm: float) -> np.ndarray:
    """Unquantised positions in mm of rows held as whole discretes ``pos`` and 2^-32 residuals ``fine`` (``None``:
    a table without the fine channel), ``(m, n_axes)`` float64.

    The one arithmetic every reader of a table uses (:meth:`TableFile.exact_mm`, the check's streamed rows) and
    the writer derives the laser from: a tick whose midpoint falls on a raster pixel's edge lands in the same pixel
    for both, to the last bit.
    """
    p = np.asarray(pos).astype(np.float64)
    if fine is not None:
        p = p + np.asarray(fine).astype(np.float64) / FINE_SCALE
    return p * discrete_mm


def file_sha256(path: str | Path) -> str | None:
    """SHA-256 (hex) of a file's bytes, as the header's ``source_sha256``/``machine_sha256`` record it;
    ``None`` when it cannot be read."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def _align(n: int) -> int:
    return (n + DATA_ALIGN - 1) // DATA_ALIGN * DATA_ALIGN


def _pack_header(h: TableHeader) -> bytes:
    meta = json.dumps(h.meta, sort_keys=True, allow_nan=False).encode("utf-8")
    fixed = _HEADER.pack(
        MAGIC,
        h.version,
        h.n_axes,
        h.block_rows,
        h.flags,
        h.tick_hz,
        h.discrete_mm,
        h.n_rows,
        h.n_blocks,
        len(meta),
        h.n_events,
        h.events_crc,
        h.data_offset,
        h.events_offset,
    )
    fixed = fixed.ljust(124, b"\0")
    crc = zlib.crc32(fixed + meta)
    return fixed + struct.pack("<I", crc) + meta


class _Bad(Exception):
    """A header problem: the field and the reason (turned into a TableFileError naming the file)."""

    def __init__(self, field: str, reason: str):
        super().__init__(f"{field} {reason}")
        self.field, self.reason = field, reason


def _is_number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_scalars(
    n_axes: int,
    block_rows: int,
    flags: int,
    tick_hz: float,
    discrete_mm: float,
    n_rows: int,
    n_blocks: int,
    version: int = VERSION,
) -> None:
    """Raise :class:`_Bad` for the first fixed-header field outside its bounds or inconsistent."""
    if not 1 <= n_axes <= MAX_AXES:
        raise _Bad("n_axes", f"= {n_axes}: a table has 1 to {MAX_AXES} axes")
    if version == 1 and flags & ~FLAG_FINE:
        raise _Bad("flags", f"= {flags:#x}: unknown flag bits (version 1 defines only bit 0, the fine channel)")
    if flags & ~(FLAG_FINE | FLAG_POWER):
        raise _Bad("flags", f"= {flags:#x}: unknown flag bits (only bit 0, fine, and bit 1, power, are defined)")
    if not 1 <= block_rows <= MAX_BLOCK_ROWS:
        raise _Bad("block_rows", f"= {block_rows}: must be 1 to {MAX_BLOCK_ROWS}")
    lo, hi = TICK_HZ_RANGE
    if not (math.isfinite(tick_hz) and lo <= tick_hz <= hi):
        raise _Bad("tick_hz", f"= {tick_hz!r}: must be a finite tick rate from {lo:g} to {hi:g} Hz")
    lo, hi = DISCRETE_MM_RANGE
    if not (math.isfinite(discrete_mm) and lo <= discrete_mm <= hi):
        raise _Bad("discrete_mm", f"= {discrete_mm!r}: must be a finite step from {lo:g} to {hi:g} mm")
    if n_rows < 1:
        raise _Bad("n_rows", f"= {n_rows}: a table has at least one row")
    if n_blocks != -(-n_rows // block_rows):
        raise _Bad("n_blocks", f"= {n_blocks}: must be ceil(n_rows / block_rows) = {-(-n_rows // block_rows)}")


def _check_meta(meta: object, n_axes: int) -> None:
    """Raise :class:`_Bad` for metadata that is not an object, axes that are not ``n_axes`` well-formed,
    unique names, or a known key holding a value of the wrong kind."""
    if not isinstance(meta, dict):
        raise _Bad("metadata", f"must be a JSON object, not {type(meta).__name__}")
    axes = meta.get("axes")
    if not isinstance(axes, list) or not all(isinstance(a, str) for a in axes):
        raise _Bad("axes", f"= {axes!r}: must be a list of axis names")
    if len(axes) != n_axes:
        raise _Bad("axes", f"= {axes!r}: {len(axes)} names for n_axes = {n_axes} columns")
    bad = [a for a in axes if not AXIS_NAME.fullmatch(a)]
    if bad:
        raise _Bad("axes", f"= {axes!r}: {bad[0]!r} is not an axis name (a letter, then letters, digits or _)")
    if len(set(axes)) != len(axes):
        raise _Bad("axes", f"= {axes!r}: names repeat")
    start = meta.get("start_mm")
    if start is not None and not (
        isinstance(start, list) and len(start) == n_axes and all(_is_number(v) and math.isfinite(v) for v in start)
    ):
        raise _Bad("start_mm", f"= {start!r}: must be a list of {n_axes} finite positions (mm), one per axis")
    for key in _META_TEXT:
        if not isinstance(meta.get(key), (str, type(None))):
            raise _Bad(key, f"= {meta[key]!r}: must be a string")
    for key in _META_COUNT:
        v = meta.get(key)
        if v is not None and not (isinstance(v, int) and not isinstance(v, bool) and v >= 0):
            raise _Bad(key, f"= {v!r}: must be a count (an integer >= 0)")
    for key in (*_META_NONNEG, *_META_POSITIVE):
        v = meta.get(key)
        floor_ok = key in _META_NONNEG and v == 0
        if v is not None and not (_is_number(v) and math.isfinite(v) and (v > 0 or floor_ok)):
            sign = "positive" if key in _META_POSITIVE else "non-negative"
            raise _Bad(key, f"= {v!r}: must be a finite {sign} number")


def _parse_meta(raw: bytes) -> tuple[object, bool]:
    """The metadata JSON and whether it holds NaN, Infinity or a number that overflows to them."""
    seen: list[str] = []

    def constant(name: str) -> float:
        seen.append(name)
        return float(name)

    def number(text: str) -> float:
        v = float(text)
        if not math.isfinite(v):
            seen.append(text)
        return v

    return json.loads(raw.decode("utf-8"), parse_constant=constant, parse_float=number), bool(seen)


def check_events(events: np.ndarray, n_rows: int, version: int = VERSION) -> str | None:
    """Why the event records are malformed, or ``None``: ticks within ``0 .. n_rows-1`` and sorted, kinds
    known (to ``version``: ``feed`` is new in version 2), values finite; laser records with a mode of 0, 3 or 4
    and a power >= 0, shutter records 0 or 1, coolant records 7, 8 or 9, dwells and block rows >= 0, feeds > 0.
    ``events``: ``(n,)`` of ``EVENT_DTYPE``."""
    if events.size == 0:
        return None
    tick, kind, aux, value = events["tick"], events["kind"], events["aux"], events["value"]

    def first(mask: np.ndarray, why: str) -> str | None:
        if not mask.any():
            return None
        i = int(np.argmax(mask))
        name = EventKind.NAMES.get(int(kind[i]), str(int(kind[i])))
        return f"event {i} ({name} at tick {int(tick[i])}): {why.format(aux=int(aux[i]), value=float(value[i]))}"

    kinds = [k for k in EventKind.NAMES if version >= 2 or k < EventKind.FEED]
    known = np.isin(kind, np.array(kinds, np.uint32))
    laser, shutter, coolant = kind == EventKind.LASER, kind == EventKind.SHUTTER, kind == EventKind.COOLANT
    checks = [
        ((tick < 0) | (tick >= n_rows), f"tick outside the table's rows 0-{n_rows - 1}"),
        (np.r_[False, tick[1:] < tick[:-1]], "event records are not sorted by tick"),
        (~known, "unknown kind"),
        (~np.isfinite(value), "value {value!r} is not finite"),
        (laser & ~np.isin(aux, (0, 3, 4)), "laser mode {aux} (expected 0, 3 or 4)"),
        (laser & ~(value >= 0), "laser power {value!r} < 0"),
        (shutter & (aux > 1), "shutter state {aux} (expected 0 or 1)"),
        (coolant & ~np.isin(aux, (7, 8, 9)), "coolant code {aux} (expected 7, 8 or 9)"),
        (np.isin(kind, (EventKind.DWELL, EventKind.BLOCK)) & ~(value >= 0), "value {value!r} < 0"),
        ((kind == EventKind.FEED) & ~(value > 0), "feed {value!r} mm/s is not positive"),
    ]
    for mask, why in checks:
        if (msg := first(mask, why)) is not None:
            return msg
    return None


def power_from_events(events: np.ndarray, start: int, stop: int) -> np.ndarray:
    """Laser output of ticks ``start:stop`` held from the ``laser`` events (the version 1 reading), ``(m,)``
    float32: each tick carries the value of the latest laser event at or before it (0 before the first)."""
    las = events[events["kind"] == EventKind.LASER]
    ticks = np.arange(start, stop, dtype=np.int64)
    i = np.searchsorted(las["tick"], ticks, side="right") - 1
    vals = np.concatenate([[0.0], las["value"]])
    return vals[i + 1].astype(np.float32)


class TableWriter:
    """Streams rows into a new table file (version 2); the row count is known up front.

    Use as a context manager; ``write(pos, fine, power)`` any number of rows at a time (``(m, n_axes)``
    int32 arrays; ``power`` ``(m,)`` finite >= 0, required when ``power=True``), then ``events`` is set and
    ``close()`` finalises CRCs and the header. A file is written to ``path + '.part'`` and renamed only when
    complete, so a crash never leaves a table that looks valid.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        axes: list[str],
        tick_hz: float,
        discrete_mm: float,
        n_rows: int,
        meta: dict | None = None,
        fine: bool = True,
        power: bool = False,
        block_rows: int = DEFAULT_BLOCK_ROWS,
    ):
        n_axes = len(axes)
        n_blocks = -(-n_rows // block_rows) if block_rows > 0 else 0
        meta = dict(meta or {})
        meta["axes"] = list(axes)
        flags = (FLAG_FINE if fine else 0) | (FLAG_POWER if power else 0)
        try:  # never write a header that a reader refuses
            _check_scalars(n_axes, block_rows, flags, float(tick_hz), float(discrete_mm), n_rows, n_blocks)
            _check_meta(meta, n_axes)
        except _Bad as bad:
            raise ValueError(f"table header field {bad}") from None
        self.path = Path(path)
        self.tmp = self.path.with_name(self.path.name + ".part")
        head_len = HEADER_SIZE + len(json.dumps(meta, sort_keys=True, allow_nan=False).encode("utf-8"))
        n_ch = 1 + bool(fine) + bool(power)
        data_offset = _align(head_len + 4 * n_blocks * n_ch)
        events_offset = data_offset + n_blocks * block_rows * (n_axes * 4 * (2 if fine else 1) + (4 if power else 0))
        self.header = TableHeader(
            n_axes,
            block_rows,
            flags,
            float(tick_hz),
            float(discrete_mm),
            n_rows,
            n_blocks,
            0,
            0,
            data_offset,
            events_offset,
            meta,
        )
        self._f = open(self.tmp, "wb+")  # noqa: SIM115 - closed in close()
        self._f.truncate(events_offset)
        self._rows = 0
        self._buf_pos = np.empty((block_rows, n_axes), np.int32)
        self._buf_fine = np.empty((block_rows, n_axes), np.int32)
        self._buf_power = np.empty((block_rows, 1), np.float32)
        self._fill = 0
        self._block = 0
        self._crc = np.zeros((n_ch, n_blocks), np.uint32)
        self.events = np.zeros(0, EVENT_DTYPE)

    def __enter__(self) -> TableWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def write(self, pos: np.ndarray, fine: np.ndarray | None = None, power: np.ndarray | None = None) -> None:
        """Append rows: ``pos`` and ``fine`` of shape ``(m, n_axes)`` int32, ``power`` ``(m,)`` (float32, >= 0)."""
        h = self.header
        pos = np.asarray(pos, np.int32)
        if self._rows + pos.shape[0] > h.n_rows:
            raise ValueError("more rows written than announced")
        if h.has_fine and fine is None:
            raise ValueError("this table has a fine channel: pass fine")
        if h.has_power:
            if power is None:
                raise ValueError("this table has a power channel: pass power")
            power = np.asarray(power, np.float32).reshape(-1)
            if power.shape[0] != pos.shape[0] or not np.all(np.isfinite(power) & (power >= 0)):
                raise ValueError("power must be one finite value >= 0 per row")
        i = 0
        while i < pos.shape[0]:
            take = min(h.block_rows - self._fill, pos.shape[0] - i)
            self._buf_pos[self._fill : self._fill + take] = pos[i : i + take]
            if h.has_fine:
                self._buf_fine[self._fill : self._fill + take] = fine[i : i + take]
            if h.has_power:
                self._buf_power[self._fill : self._fill + take, 0] = power[i : i + take]
            self._fill += take
            i += take
            self._rows += take
            if self._fill == h.block_rows:
                self._flush_block()

    def _flush_block(self) -> None:
        h = self.header
        if self._fill < h.block_rows:  # last block: repeat the final row (the machine is at rest)
            self._buf_pos[self._fill :] = self._buf_pos[self._fill - 1]
            self._buf_fine[self._fill :] = self._buf_fine[self._fill - 1]
            self._buf_power[self._fill :] = self._buf_power[self._fill - 1]
        channels = [(self._buf_pos, "<i4", h.data_offset, h.block_bytes)]
        if h.has_fine:
            channels.append((self._buf_fine, "<i4", h.fine_offset, h.block_bytes))
        if h.has_power:
            channels.append((self._buf_power, "<f4", h.power_offset, h.power_block_bytes))
        for ch, (buf, dtype, base, size) in enumerate(channels):
            data = buf.astype(dtype, copy=False).tobytes()
            self._f.seek(base + self._block * size)
            self._f.write(data)
            self._crc[ch, self._block] = zlib.crc32(data)
        self._block += 1
        self._fill = 0

    def close(self) -> None:
        h = self.header
        if self._rows != h.n_rows:
            self.abort()
            raise ValueError(f"table announced {h.n_rows} rows but {self._rows} were written")
        ev = np.ascontiguousarray(self.events, dtype=EVENT_DTYPE)
        if (why := check_events(ev, h.n_rows)) is not None:
            self.abort()
            raise ValueError(f"malformed events: {why}")
        if self._fill:
            self._flush_block()
        ev_bytes = ev.tobytes()
        self.header = h = TableHeader(**{**h.__dict__, "n_events": int(ev.size), "events_crc": zlib.crc32(ev_bytes)})
        self._f.seek(h.events_offset)
        self._f.write(ev_bytes)
        self._f.seek(h.crc_offset)
        self._f.write(self._crc.astype("<u4").tobytes())
        self._f.seek(0)
        self._f.write(_pack_header(h))
        self._f.flush()
        os.fsync(self._f.fileno())
        self._f.close()
        os.replace(self.tmp, self.path)

    def abort(self) -> None:
        if not self._f.closed:
            self._f.close()
        self.tmp.unlink(missing_ok=True)


class TableFile:
    """A table file opened for reading: memory-mapped, validated and verified before use.

    ``TableFile(path)`` checks the header — magic, version, CRC, every field finite, consistent and within
    its bounds, the metadata (``axes``: ``n_axes`` well-formed unique names), the layout against the file's
    size, the zero padding — and the event records (ticks in range and sorted, kinds known, values finite);
    unless ``verify=False`` also every block's CRC, the events' CRC and the last block's padding rows. It
    raises :class:`~jaxcnc.errors.TableFileError` naming the file and the field or part at fault — before
    anything moves. ``docs/table-format.md`` lists every rule.
    """

    def __init__(self, path: str | Path, verify: bool = True):
        self.path = Path(path)
        self._fd: int | None = None
        try:
            size = self.path.stat().st_size
            with open(self.path, "rb") as f:
                fixed = f.read(HEADER_SIZE)
                if len(fixed) < HEADER_SIZE or fixed[:8] != MAGIC:
                    raise self._err("not a jaxcnc table file (bad magic)")
                vals = _HEADER.unpack_from(fixed)
                if vals[1] not in READ_VERSIONS:
                    raise self._err(
                        f"table format version {vals[1]} is not supported (this reader: "
                        f"{', '.join(map(str, READ_VERSIONS))})"
                    )
                json_bytes = vals[9]
                if json_bytes > MAX_JSON_BYTES:
                    raise self._err(f"header field json_bytes = {json_bytes}: more than {MAX_JSON_BYTES} bytes")
                if HEADER_SIZE + json_bytes > size:
                    raise self._err("truncated header")
                meta_raw = f.read(json_bytes)
        except OSError as exc:
            raise self._err(f"cannot read: {exc}") from None
        (crc_stored,) = struct.unpack_from("<I", fixed, 124)
        if zlib.crc32(fixed[:124] + meta_raw) != crc_stored:
            raise self._err("header checksum mismatch (damaged header)")
        if fixed[_HEADER.size : 124].strip(b"\0"):
            raise self._err(f"reserved header bytes {_HEADER.size}-123 are not zero")
        try:
            meta, non_finite = _parse_meta(meta_raw)
        except (ValueError, RecursionError) as exc:
            raise self._err(f"header metadata is not valid JSON ({exc})") from None
        f = dict(zip(_FIELDS, vals, strict=True))
        try:
            _check_scalars(*(f[k] for k in ("n_axes", "block_rows", "flags", "tick_hz", "discrete_mm", "n_rows")),
                           f["n_blocks"], f["version"])  # fmt: skip
            _check_meta(meta, f["n_axes"])
        except _Bad as bad:
            field = bad.field if bad.field == "metadata" else f"field {bad.field}"
            raise self._err(f"header {field} {bad.reason}") from None
        if non_finite:
            raise self._err("header metadata holds NaN or Infinity (not a number a table may carry)")
        self.header = h = TableHeader(**{k: f[k] for k in _HEADER_KEYS}, meta=meta, version=f["version"])
        n_axes, n_blocks, n_events, events_offset = h.n_axes, h.n_blocks, h.n_events, h.events_offset
        n_ch = h.n_channels
        want_data = _align(HEADER_SIZE + json_bytes + 4 * n_ch * n_blocks)
        if h.data_offset != want_data:
            raise self._err(
                f"header field data_offset = {h.data_offset}: the layout puts the data at {want_data} "
                "(the first multiple of 4096 after the header, the metadata and the CRC table)"
            )
        want_events = h.power_offset + (n_blocks * h.power_block_bytes if h.has_power else 0)
        if events_offset != want_events:
            raise self._err(f"header field events_offset = {events_offset}: the data ends at {want_events}")
        expected = events_offset + n_events * EVENT_DTYPE.itemsize
        if size != expected:
            raise self._err(f"file is {size} bytes, header says {expected} (truncated or extended)")
        with open(self.path, "rb") as fh:
            pad = os.pread(fh.fileno(), h.crc_offset - HEADER_SIZE - json_bytes, HEADER_SIZE + json_bytes)
        if pad.strip(b"\0"):
            raise self._err("the padding between the metadata and the CRC table is not zero (malformed padding)")
        rows = n_blocks * h.block_rows
        self._pos = np.memmap(self.path, dtype="<i4", mode="r", offset=h.data_offset, shape=(rows, n_axes))
        self._fine = (
            np.memmap(self.path, dtype="<i4", mode="r", offset=h.fine_offset, shape=(rows, n_axes))
            if h.has_fine
            else None
        )
        self._power = (
            np.memmap(self.path, dtype="<f4", mode="r", offset=h.power_offset, shape=(rows,)) if h.has_power else None
        )
        self._crc = np.fromfile(self.path, dtype="<u4", count=n_ch * n_blocks, offset=h.crc_offset).reshape(
            n_ch, n_blocks
        )
        self.events = np.fromfile(self.path, dtype=EVENT_DTYPE, count=n_events, offset=events_offset)
        if verify:
            self.verify()
        if (why := check_events(self.events, h.n_rows, h.version)) is not None:
            raise self._err(f"malformed events: {why}")

    def _err(self, reason: str) -> TableFileError:
        return TableFileError(f"{self.path}: {reason}")

    def require_axes(self, axes: list[str] | tuple[str, ...], owner: str) -> None:
        """Refuse (:class:`~jaxcnc.errors.TableFileError`, naming both lists) unless the table's axes are
        ``axes``, in order. ``owner`` says whose axes they are (e.g. ``"machine 'laser'"``).

        Sinks send a table's columns by position, so a table with two columns swapped and relabelled would
        drive one axis with another's motion even though each column, measured by its name, holds its limits.
        """
        if self.header.axes != list(axes):
            raise self._err(
                f"the table's axes {self.header.axes} differ from {owner} axes {list(axes)} "
                "(columns are sent to the drives by position)"
            )

    def verify(self) -> None:
        """Check every block's CRC, the last block's padding rows, the power values (finite, >= 0) and the
        events' CRC; raise on the first damage found.

        Blocks are read with ``pread`` (not through the memory map), so verifying a table of any
        size keeps only one block in memory.
        """
        h = self.header
        channels = [("position", h.data_offset, h.block_bytes, "<i4", h.n_axes)]
        if h.has_fine:
            channels.append(("fine", h.fine_offset, h.block_bytes, "<i4", h.n_axes))
        if h.has_power:
            channels.append(("power", h.power_offset, h.power_block_bytes, "<f4", 1))
        with open(self.path, "rb") as f:
            fd = f.fileno()
            for ch, (what, base, size, dtype, width) in enumerate(channels):
                for b in range(h.n_blocks):
                    data = os.pread(fd, size, base + b * size)
                    first = b * h.block_rows
                    last = min(first + h.block_rows, h.n_rows) - 1
                    if zlib.crc32(data) != self._crc[ch, b]:
                        raise self._err(f"{what} block {b} (ticks {first}-{last}) fails its checksum (damaged data)")
                    if what == "power":
                        p = np.frombuffer(data, dtype="<f4")
                        if not np.all(np.isfinite(p) & (p >= 0)):
                            i = int(np.argmax(~(np.isfinite(p) & (p >= 0))))
                            raise self._err(f"power at tick {first + i} is {float(p[i])!r}: must be finite and >= 0")
                # the last block is padded by repeating the final row: the machine stands still after it
                tail = h.n_rows - (h.n_blocks - 1) * h.block_rows
                last = np.frombuffer(data, dtype=dtype).reshape(h.block_rows, width)
                if np.any(last[tail:] != last[tail - 1]):
                    raise self._err(
                        f"{what} block {h.n_blocks - 1}: the padding rows after tick {h.n_rows - 1} do not repeat "
                        "the final row (malformed padding)"
                    )
        if zlib.crc32(self.events.tobytes()) != h.events_crc:
            raise self._err("event records fail their checksum (damaged events)")

    def close(self) -> None:
        """Release the file descriptor :meth:`read_positions` uses (the memory maps stay valid)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __del__(self) -> None:
        self.close()

    def read_positions(self, start: int, stop: int) -> np.ndarray:
        """Rows ``start:stop`` of the positions, read with ``pread`` into a fresh array.

        The player streams with this: unlike slices of the memory map it leaves no file pages
        mapped into the process, so a table of any length plays in bounded memory.
        """
        h = self.header
        start, stop = max(0, start), min(stop, h.n_rows)
        if stop <= start:
            return np.zeros((0, h.n_axes), np.int32)
        row = h.n_axes * 4
        if self._fd is None:
            self._fd = os.open(self.path, os.O_RDONLY)
        data = os.pread(self._fd, (stop - start) * row, h.data_offset + start * row)
        return np.frombuffer(data, dtype="<i4").reshape(stop - start, h.n_axes).astype(np.int32)

    def read_power(self, start: int, stop: int) -> np.ndarray:
        """The laser output of rows ``start:stop``, ``(m,)`` float32 (the S scale; 0 = dark), read with ``pread``.

        From the power channel when the table has one; otherwise (version 1, or a table written without it)
        the value of the latest ``laser`` event at or before each tick — what a version 1 player drove.
        """
        h = self.header
        start, stop = max(0, start), min(stop, h.n_rows)
        if stop <= start:
            return np.zeros(0, np.float32)
        if h.has_power:
            if self._fd is None:
                self._fd = os.open(self.path, os.O_RDONLY)
            data = os.pread(self._fd, (stop - start) * 4, h.power_offset + start * 4)
            return np.frombuffer(data, dtype="<f4").astype(np.float32)
        return power_from_events(self.events, start, stop)

    @property
    def power(self) -> np.ndarray:
        """``(n_rows,)`` float32 laser output per tick (memory-mapped channel, or from the events)."""
        if self._power is not None:
            return self._power[: self.header.n_rows]
        return power_from_events(self.events, 0, self.header.n_rows)

    @property
    def n_rows(self) -> int:
        return self.header.n_rows

    @property
    def axes(self) -> list[str]:
        return self.header.axes

    @property
    def positions(self) -> np.ndarray:
        """``(n_rows, n_axes)`` int32 discretes, memory-mapped (read-only)."""
        return self._pos[: self.header.n_rows]

    @property
    def fine(self) -> np.ndarray | None:
        """``(n_rows, n_axes)`` int32 residuals in 2^-32 discretes, or ``None``."""
        return None if self._fine is None else self._fine[: self.header.n_rows]

    def positions_mm(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Quantised positions of rows ``start:stop`` in mm, ``(m, n_axes)`` float64."""
        return self.positions[start:stop].astype(np.float64) * self.header.discrete_mm

    def exact_mm(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Unquantised positions (position + fine residual) of rows ``start:stop`` in mm."""
        fine = self.fine[start:stop] if self._fine is not None else None
        return fixed_to_mm(self.positions[start:stop], fine, self.header.discrete_mm)
