"""The tick table file, version 1 — read and written with NumPy and the standard library only.

This module is shared by the planning side (:mod:`jaxcnc.ticks` writes tables) and the player side
(:mod:`jaxcnc.hw` reads them on a controller that may have no JAX). ``docs/table-format.md`` specifies
the bytes precisely enough for firmware; the event records are in :mod:`jaxcnc.format.events`.

Layout (all little-endian)::

    [fixed header, 128 bytes][JSON metadata][pad to 4096]
    [CRC table: u32 per position block, then u32 per fine block]
    [position blocks: n_blocks × block_rows × n_axes int32]
    [fine blocks:     n_blocks × block_rows × n_axes int32]   (only if FLAG_FINE)
    [event records: n_events × 24 bytes]

Rows are ticks ``0 .. n_rows-1``; the last block is padded by repeating the final row.
Positions are integer discretes (``round(p / discrete_mm)``). The optional *fine* channel holds
the rounding residual ``p / discrete_mm - position`` in units of 2^-32 discrete, which lets a
checker measure speed and acceleration at the tick rate from the unquantised path.
"""

from __future__ import annotations

import hashlib
import json
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxcnc.errors import TableFileError
from jaxcnc.format.events import EVENT_DTYPE

MAGIC = b"JXCNCTBL"
VERSION = 1
HEADER_SIZE = 128
DATA_ALIGN = 4096
DEFAULT_BLOCK_ROWS = 4096
FLAG_FINE = 1
FINE_SCALE = 2.0**32  # fine units per discrete

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

    @property
    def axes(self) -> list[str]:
        return list(self.meta.get("axes", []))

    @property
    def has_fine(self) -> bool:
        return bool(self.flags & FLAG_FINE)

    @property
    def block_bytes(self) -> int:
        return self.block_rows * self.n_axes * 4

    @property
    def crc_offset(self) -> int:
        return self.data_offset - 4 * self.n_blocks * (2 if self.has_fine else 1)

    @property
    def fine_offset(self) -> int:
        return self.data_offset + self.n_blocks * self.block_bytes


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
    meta = json.dumps(h.meta, sort_keys=True).encode("utf-8")
    fixed = _HEADER.pack(
        MAGIC,
        VERSION,
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


class TableWriter:
    """Streams rows into a new table file; the row count is known up front.

    Use as a context manager; ``write(pos, fine)`` any number of rows at a time (``(m, n_axes)``
    int32 arrays), then ``events`` is set and ``close()`` finalises CRCs and the header.
    A file is written to ``path + '.part'`` and renamed only when complete, so a crash never
    leaves a table that looks valid.
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
        block_rows: int = DEFAULT_BLOCK_ROWS,
    ):
        if n_rows < 1:
            raise ValueError("a table has at least one row")
        self.path = Path(path)
        self.tmp = self.path.with_name(self.path.name + ".part")
        n_axes = len(axes)
        n_blocks = -(-n_rows // block_rows)
        meta = dict(meta or {})
        meta["axes"] = list(axes)
        flags = FLAG_FINE if fine else 0
        head_len = HEADER_SIZE + len(json.dumps(meta, sort_keys=True).encode("utf-8"))
        crc_len = 4 * n_blocks * (2 if fine else 1)
        data_offset = _align(head_len + crc_len)
        events_offset = data_offset + n_blocks * block_rows * n_axes * 4 * (2 if fine else 1)
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
        self._fill = 0
        self._block = 0
        self._crc = np.zeros((2 if fine else 1, n_blocks), np.uint32)
        self.events = np.zeros(0, EVENT_DTYPE)

    def __enter__(self) -> TableWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def write(self, pos: np.ndarray, fine: np.ndarray | None = None) -> None:
        """Append rows: ``pos`` and ``fine`` of shape ``(m, n_axes)`` int32."""
        h = self.header
        pos = np.asarray(pos, np.int32)
        if self._rows + pos.shape[0] > h.n_rows:
            raise ValueError("more rows written than announced")
        if h.has_fine and fine is None:
            raise ValueError("this table has a fine channel: pass fine")
        i = 0
        while i < pos.shape[0]:
            take = min(h.block_rows - self._fill, pos.shape[0] - i)
            self._buf_pos[self._fill : self._fill + take] = pos[i : i + take]
            if h.has_fine:
                self._buf_fine[self._fill : self._fill + take] = fine[i : i + take]
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
        for ch, (buf, base) in enumerate(((self._buf_pos, h.data_offset), (self._buf_fine, h.fine_offset))):
            if ch == 1 and not h.has_fine:
                break
            data = buf.astype("<i4", copy=False).tobytes()
            self._f.seek(base + self._block * h.block_bytes)
            self._f.write(data)
            self._crc[ch, self._block] = zlib.crc32(data)
        self._block += 1
        self._fill = 0

    def close(self) -> None:
        h = self.header
        if self._rows != h.n_rows:
            self.abort()
            raise ValueError(f"table announced {h.n_rows} rows but {self._rows} were written")
        if self._fill:
            self._flush_block()
        ev = np.ascontiguousarray(self.events, dtype=EVENT_DTYPE)
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
    """A table file opened for reading: memory-mapped, verified before use.

    ``TableFile(path)`` checks the header, the sizes and (unless ``verify=False``) every block's
    CRC and the events' CRC, raising :class:`~jaxcnc.errors.TableFileError` naming the file and
    the damaged part — before anything moves.
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
                if vals[1] != VERSION:
                    raise self._err(f"table format version {vals[1]} is not supported (this reader: {VERSION})")
                json_bytes = vals[9]
                if HEADER_SIZE + json_bytes > size:
                    raise self._err("truncated header")
                meta_raw = f.read(json_bytes)
        except OSError as exc:
            raise self._err(f"cannot read: {exc}") from None
        (crc_stored,) = struct.unpack_from("<I", fixed, 124)
        if zlib.crc32(fixed[:124] + meta_raw) != crc_stored:
            raise self._err("header checksum mismatch (damaged header)")
        try:
            meta = json.loads(meta_raw.decode("utf-8"))
        except ValueError:
            raise self._err("header metadata is not valid JSON") from None
        f = dict(zip(_FIELDS, vals, strict=True))
        self.header = h = TableHeader(**{k: f[k] for k in _HEADER_KEYS}, meta=meta)
        n_axes, n_blocks, n_events, events_offset = h.n_axes, h.n_blocks, h.n_events, h.events_offset
        if (
            n_axes < 1
            or h.block_rows < 1
            or n_blocks != -(-h.n_rows // h.block_rows)
            or min(h.tick_hz, h.discrete_mm) <= 0
        ):
            raise self._err("inconsistent header fields")
        expected = events_offset + n_events * EVENT_DTYPE.itemsize
        if size != expected:
            raise self._err(f"file is {size} bytes, header says {expected} (truncated or extended)")
        rows = n_blocks * h.block_rows
        self._pos = np.memmap(self.path, dtype="<i4", mode="r", offset=h.data_offset, shape=(rows, n_axes))
        self._fine = (
            np.memmap(self.path, dtype="<i4", mode="r", offset=h.fine_offset, shape=(rows, n_axes))
            if h.has_fine
            else None
        )
        n_ch = 2 if h.has_fine else 1
        self._crc = np.fromfile(self.path, dtype="<u4", count=n_ch * n_blocks, offset=h.crc_offset).reshape(
            n_ch, n_blocks
        )
        self.events = np.fromfile(self.path, dtype=EVENT_DTYPE, count=n_events, offset=events_offset)
        if verify:
            self.verify()

    def _err(self, reason: str) -> TableFileError:
        return TableFileError(f"{self.path}: {reason}")

    def verify(self) -> None:
        """Check every block's CRC and the events' CRC; raise on the first damage found.

        Blocks are read with ``pread`` (not through the memory map), so verifying a table of any
        size keeps only one block in memory.
        """
        h = self.header
        with open(self.path, "rb") as f:
            fd = f.fileno()
            for ch, base in enumerate((h.data_offset, h.fine_offset)):
                if ch == 1 and not h.has_fine:
                    break
                for b in range(h.n_blocks):
                    data = os.pread(fd, h.block_bytes, base + b * h.block_bytes)
                    if zlib.crc32(data) == self._crc[ch, b]:
                        continue
                    first = b * h.block_rows
                    last = min(first + h.block_rows, h.n_rows) - 1
                    what = "position" if ch == 0 else "fine"
                    raise self._err(f"{what} block {b} (ticks {first}-{last}) fails its checksum (damaged data)")
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
        p = self.positions[start:stop].astype(np.float64)
        if self._fine is not None:
            p = p + self.fine[start:stop].astype(np.float64) / FINE_SCALE
        return p * self.header.discrete_mm
