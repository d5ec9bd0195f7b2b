"""Scanner vector lists (version 1): the commands a galvo board executes, their file, text form and meaning.

A list is a 1-D NumPy array of :data:`VECTOR_DTYPE` records (40 bytes each): ``op`` (:class:`Op`), ``flags``,
``ticks`` (a duration or a delay in board ticks), ``pos`` (x, y, z in discretes), ``aux`` (a second integer),
``value`` and ``value2`` (float64). ``docs/scanner.md`` lists every command and its fields. This module holds:

- :func:`write_vectors` / :func:`read_vectors`: the binary file (``JXVECTOR`` magic, version, JSON header,
  records, CRC-32), the reader checking every record before anything runs;
- :func:`to_text` / :func:`from_text`: one command per line, a form a person reads and writes;
- :func:`encode_rows`: a tick table (positions, laser power, pulses) as *timed* vectors that reproduce it
  tick for tick;
- :func:`execute`: the reference meaning of a list — the commanded beam position, the laser output and the
  pulses of every board tick (speeds, jump/mark/polygon delays, the variable polygon delay, laser on/off
  delays, sky-writing, arcs, timed marks). The board emulator (``jaxcnc.scanner``) and the ``scanner``
  sink run lists through it.

NumPy and the standard library only (the player side imports it).
"""

from __future__ import annotations

import json
import math
import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxcnc.errors import JaxcncError

MAGIC = b"JXVECTOR"
VERSION = 1
#: A header's JSON may not exceed this (a damaged length field must not make the reader allocate gigabytes).
MAX_JSON_BYTES = 1 << 20
#: Delays and timed durations are capped at 2^31 - 1 ticks by their int32 field; this keeps a list's rows finite.
MAX_TICKS = (1 << 31) - 1

#: One command: 40 bytes, little-endian.
VECTOR_DTYPE = np.dtype(
    [
        ("op", "<u2"),
        ("flags", "<u2"),
        ("ticks", "<i4"),
        ("pos", "<i4", (3,)),
        ("aux", "<i4"),
        ("value", "<f8"),
        ("value2", "<f8"),
    ]
)
assert VECTOR_DTYPE.itemsize == 40


class Op:
    """Command codes of ``VECTOR_DTYPE['op']`` (the fields each one uses: ``docs/scanner.md``)."""

    LIST_START = 1  # pos: where the list starts (the first list: the beam's position); value: laser power of row 0
    LIST_END = 2
    JUMP_ABS = 3  # pos; laser off, at the jump speed; then the jump delay
    MARK_ABS = 4  # pos; laser on, at the mark speed
    POLYLINE = 5  # aux = n: the next n records are VERTEX records, marked as one chain
    VERTEX = 6  # pos (only inside a POLYLINE)
    ARC_ABS = 7  # pos = centre, value = swept angle (degrees, + counter-clockwise), pos[2] ignored
    TIMED_MARK = 8  # pos, ticks > 0: a mark of that exact duration (no speed, no polygon delay, no sky-writing)
    TIMED_JUMP = 9  # pos, ticks >= 0: a dark move of that exact duration (no jump delay)
    SET_JUMP_SPEED = 10  # value mm/s
    SET_MARK_SPEED = 11  # value mm/s
    SET_LASER_DELAYS = 12  # ticks = laser-on delay, aux = laser-off delay (signed board ticks)
    SET_SCANNER_DELAYS = 13  # ticks = jump delay, aux = mark delay, pos[0] = polygon delay (ticks, >= 0)
    SET_POLYGON_MODE = 14  # aux = 0 fixed polygon delay, 1 variable: the delay times turning angle / 180 degrees
    SET_SKY_WRITING = 15  # aux = mode (0 off, 1 chain ends, 2 also corners), ticks = run-in, pos[0] = run-out,
    #                       value = limit angle (degrees): corners turning more than it are sky-written
    SET_LASER = 16  # value = power (table units, S), value2 = pulse frequency (Hz, 0 = CW), aux = pulse width (ns)
    WAIT = 17  # ticks >= 0: hold the beam, laser off
    SET_OUTPUT = 18  # aux = port, pos[0] = value (recorded with the tick it is set at)
    LASER_PULSE = 19  # one pulse at the last executed row; aux = point index (-1 none), value = energy,
    #                   flags & 1: idle pulse (shutter closed, burns nothing)

    NAMES = {
        1: "list_start",
        2: "list_end",
        3: "jump_abs",
        4: "mark_abs",
        5: "polyline",
        6: "vertex",
        7: "arc_abs",
        8: "timed_mark",
        9: "timed_jump",
        10: "set_jump_speed",
        11: "set_mark_speed",
        12: "set_laser_delays",
        13: "set_scanner_delays",
        14: "set_polygon_mode",
        15: "set_sky_writing",
        16: "set_laser",
        17: "wait",
        18: "set_output",
        19: "laser_pulse",
    }
    CODES = {v: k for k, v in NAMES.items()}


#: ``flags`` of LASER_PULSE: an idle pump pulse (shutter closed).
FLAG_IDLE = 1
_MARKS = (Op.MARK_ABS, Op.VERTEX, Op.ARC_ABS)


class VectorFileError(JaxcncError):
    """A vector list that is damaged or malformed: names the file (or list) and the record at fault."""


@dataclass(frozen=True)
class VectorHeader:
    """A list's header: the board tick rate, the discrete, the axes the ``pos`` fields carry, free metadata."""

    tick_hz: float
    discrete_mm: float
    axes: tuple[str, ...] = ("x", "y")
    meta: dict = field(default_factory=dict)

    @property
    def dt(self) -> float:
        """The board tick in seconds."""
        return 1.0 / self.tick_hz


def make(op: int, pos=(0, 0, 0), ticks: int = 0, aux: int = 0, value: float = 0.0, value2: float = 0.0, flags=0):
    """One record (a tuple for ``np.array(..., VECTOR_DTYPE)``)."""
    p = tuple(int(v) for v in pos) + (0,) * (3 - len(pos))
    return (op, flags, int(ticks), p[:3], int(aux), float(value), float(value2))


def records(items: list) -> np.ndarray:
    """A list of :func:`make` tuples as a record array."""
    return np.array(items, dtype=VECTOR_DTYPE) if items else np.zeros(0, VECTOR_DTYPE)


# ---------------------------------------------------------------------------------------------- checking


def check_records(rec: np.ndarray, where: str = "<list>") -> None:
    """Refuse a malformed list (:class:`VectorFileError` naming ``where`` and the record index and cause).

    Checks: every op known, flags only where defined, values finite, speeds > 0, durations and delays in range,
    POLYLINE followed by exactly ``aux`` VERTEX records, VERTEX only there, LIST_START first.
    """
    if rec.dtype != VECTOR_DTYPE:
        raise VectorFileError(f"{where}: records have dtype {rec.dtype}, not the vector record")
    n = rec.shape[0]
    if n == 0:
        return

    def bad(mask: np.ndarray, why: str) -> None:
        idx = np.flatnonzero(mask)
        if idx.size:
            i = int(idx[0])
            raise VectorFileError(f"{where}: record {i} ({Op.NAMES.get(int(rec['op'][i]), '?')}): {why}")

    op = rec["op"].astype(np.int64)
    bad(~np.isin(op, list(Op.NAMES)), "unknown command code")
    bad((rec["flags"] != 0) & (op != Op.LASER_PULSE), "flags are defined only for laser_pulse")
    bad((rec["flags"].astype(np.int64) & ~FLAG_IDLE) != 0, "unknown flag bits")
    bad(~(np.isfinite(rec["value"]) & np.isfinite(rec["value2"])), "value is not a finite number")
    bad(np.isin(op, (Op.SET_JUMP_SPEED, Op.SET_MARK_SPEED)) & ~(rec["value"] > 0), "a speed must be > 0 mm/s")
    bad(np.isin(op, (Op.SET_JUMP_SPEED, Op.SET_MARK_SPEED)) & (rec["value"] > 1e6), "a speed beyond 1 km/s")
    bad((op == Op.TIMED_MARK) & (rec["ticks"] <= 0), "a timed mark needs ticks > 0")
    bad(np.isin(op, (Op.TIMED_JUMP, Op.WAIT)) & (rec["ticks"] < 0), "a duration needs ticks >= 0")
    bad((op == Op.SET_SCANNER_DELAYS) & ((rec["ticks"] < 0) | (rec["aux"] < 0) | (rec["pos"][:, 0] < 0)),
        "scanner delays must be >= 0 ticks")  # fmt: skip
    bad((op == Op.SET_POLYGON_MODE) & ~np.isin(rec["aux"], (0, 1)), "polygon mode is 0 (fixed) or 1 (variable)")
    sky = op == Op.SET_SKY_WRITING
    bad(sky & ~np.isin(rec["aux"], (0, 1, 2)), "sky-writing mode is 0, 1 or 2")
    bad(sky & ((rec["ticks"] < 0) | (rec["pos"][:, 0] < 0)), "run-in and run-out must be >= 0 ticks")
    bad(sky & ~((rec["value"] >= 0) & (rec["value"] <= 180)), "limit angle must be within 0-180 degrees")
    bad((op == Op.SET_LASER) & ~((rec["value"] >= 0) & (rec["value2"] >= 0) & (rec["aux"] >= 0)),
        "laser power, frequency and pulse width must be >= 0")  # fmt: skip
    bad((op == Op.ARC_ABS) & ~(np.abs(rec["value"]) <= 36000), "an arc sweeps at most 100 turns")
    bad((op == Op.LASER_PULSE) & ~(rec["value"] >= 0), "pulse energy must be >= 0")
    bad((op == Op.POLYLINE) & (rec["aux"] < 1), "a polyline needs aux >= 1 vertices")
    # VERTEX exactly where a POLYLINE announces them
    expect = np.zeros(n, bool)
    for i in np.flatnonzero(op == Op.POLYLINE):  # one step per polyline, not per tick
        k = int(rec["aux"][i])
        if i + k >= n:
            bad(np.arange(n) == i, f"announces {k} vertices, the list ends first")
        expect[i + 1 : i + 1 + k] = True
    bad(expect & (op != Op.VERTEX), "a polyline's vertex expected here")
    bad(~expect & (op == Op.VERTEX), "a vertex outside a polyline")
    bad((np.arange(n) == 0) & (op != Op.LIST_START), "a list begins with list_start")


# ---------------------------------------------------------------------------------------------- file


def vector_bytes(rec: np.ndarray, header: VectorHeader, where: str = "<list>") -> bytes:
    """A list as the bytes of a list file (what a host sends a board): magic, version (u4), JSON length (u4),
    JSON header, records, CRC-32 of all before. The records are checked first (:func:`check_records`)."""
    check_records(rec, where)
    meta = dict(header.meta)
    meta.update(tick_hz=header.tick_hz, discrete_mm=header.discrete_mm, axes=list(header.axes), n_records=len(rec))
    js = json.dumps(meta, sort_keys=True, allow_nan=False).encode("utf-8")
    body = MAGIC + struct.pack("<II", VERSION, len(js)) + js + np.ascontiguousarray(rec, VECTOR_DTYPE).tobytes()
    return body + struct.pack("<I", zlib.crc32(body))


def write_vectors(path: str | Path, rec: np.ndarray, header: VectorHeader) -> None:
    """Write a list file (:func:`vector_bytes`), atomically."""
    data = vector_bytes(rec, header, str(path))
    tmp = Path(str(path) + ".part")
    tmp.write_bytes(data)
    tmp.replace(path)


def parse_vectors(data: bytes, where: str = "<bytes>") -> tuple[VectorHeader, np.ndarray]:
    """The header and records of a list file's bytes; :class:`VectorFileError` for anything malformed."""
    if len(data) < 20 or data[:8] != MAGIC:
        raise VectorFileError(f"{where}: not a jaxcnc vector list (bad magic)")
    version, n_js = struct.unpack_from("<II", data, 8)
    if version != VERSION:
        raise VectorFileError(f"{where}: vector list version {version} is not supported (this reader: {VERSION})")
    if n_js > MAX_JSON_BYTES or 16 + n_js + 4 > len(data):
        raise VectorFileError(f"{where}: truncated header")
    (crc,) = struct.unpack_from("<I", data, len(data) - 4)
    if zlib.crc32(data[:-4]) != crc:
        raise VectorFileError(f"{where}: checksum mismatch (damaged or truncated file)")
    try:
        meta = json.loads(data[16 : 16 + n_js].decode("utf-8"), parse_constant=_no_constant)
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise VectorFileError(f"{where}: header is not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise VectorFileError(f"{where}: header is not a JSON object")
    try:
        tick_hz, discrete_mm = float(meta.pop("tick_hz")), float(meta.pop("discrete_mm"))
        axes, n = meta.pop("axes"), meta.pop("n_records")
    except (KeyError, TypeError, ValueError) as exc:
        raise VectorFileError(f"{where}: header lacks or garbles {exc}") from None
    if not (10 <= tick_hz <= 1e7 and 1e-7 <= discrete_mm <= 1):
        raise VectorFileError(f"{where}: header tick_hz {tick_hz:g} or discrete_mm {discrete_mm:g} out of range")
    if not (isinstance(axes, list) and 1 <= len(axes) <= 3 and all(isinstance(a, str) and a for a in axes)):
        raise VectorFileError(f"{where}: header axes must be 1-3 names")
    if len(set(axes)) != len(axes):
        raise VectorFileError(f"{where}: header axes repeat a name")
    body = len(data) - 4 - 16 - n_js
    if not isinstance(n, int) or isinstance(n, bool) or n < 0 or n * VECTOR_DTYPE.itemsize != body:
        raise VectorFileError(f"{where}: header says {n!r} records, the file holds {body} bytes of them")
    rec = np.frombuffer(data, VECTOR_DTYPE, count=n, offset=16 + n_js).copy()
    check_records(rec, where)
    return VectorHeader(tick_hz, discrete_mm, tuple(axes), meta), rec


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number a list may carry")


def read_vectors(path: str | Path) -> tuple[VectorHeader, np.ndarray]:
    """Read and check a list file (:func:`write_vectors`)."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise VectorFileError(f"{path}: cannot read: {exc.strerror or exc}") from None
    return parse_vectors(data, str(path))


# ---------------------------------------------------------------------------------------------- text

# per op: the fields the text form shows, in order (name, record field, index or None, kind)
_TEXT_FIELDS: dict[int, tuple[tuple[str, str, int | None, str], ...]] = {
    Op.LIST_START: (("x", "pos", 0, "mm"), ("y", "pos", 1, "mm"), ("z", "pos", 2, "mm"), ("power", "value", None, "f")),
    Op.LIST_END: (),
    Op.JUMP_ABS: (("x", "pos", 0, "mm"), ("y", "pos", 1, "mm"), ("z", "pos", 2, "mm")),
    Op.MARK_ABS: (("x", "pos", 0, "mm"), ("y", "pos", 1, "mm"), ("z", "pos", 2, "mm")),
    Op.POLYLINE: (("n", "aux", None, "i"),),
    Op.VERTEX: (("x", "pos", 0, "mm"), ("y", "pos", 1, "mm"), ("z", "pos", 2, "mm")),
    Op.ARC_ABS: (("cx", "pos", 0, "mm"), ("cy", "pos", 1, "mm"), ("angle_deg", "value", None, "f")),
    Op.TIMED_MARK: (("x", "pos", 0, "mm"), ("y", "pos", 1, "mm"), ("z", "pos", 2, "mm"), ("ticks", "ticks", None, "i")),
    Op.TIMED_JUMP: (("x", "pos", 0, "mm"), ("y", "pos", 1, "mm"), ("z", "pos", 2, "mm"), ("ticks", "ticks", None, "i")),
    Op.SET_JUMP_SPEED: (("mm_s", "value", None, "f"),),
    Op.SET_MARK_SPEED: (("mm_s", "value", None, "f"),),
    Op.SET_LASER_DELAYS: (("on", "ticks", None, "i"), ("off", "aux", None, "i")),
    Op.SET_SCANNER_DELAYS: (("jump", "ticks", None, "i"), ("mark", "aux", None, "i"), ("polygon", "pos", 0, "i")),
    Op.SET_POLYGON_MODE: (("variable", "aux", None, "i"),),
    Op.SET_SKY_WRITING: (
        ("mode", "aux", None, "i"),
        ("run_in", "ticks", None, "i"),
        ("run_out", "pos", 0, "i"),
        ("limit_deg", "value", None, "f"),
    ),
    Op.SET_LASER: (("power", "value", None, "f"), ("hz", "value2", None, "f"), ("width_ns", "aux", None, "i")),
    Op.WAIT: (("ticks", "ticks", None, "i"),),
    Op.SET_OUTPUT: (("port", "aux", None, "i"), ("value", "pos", 0, "i")),
    Op.LASER_PULSE: (("point", "aux", None, "i"), ("energy", "value", None, "f"), ("idle", "flags", None, "i")),
}


def to_text(rec: np.ndarray, header: VectorHeader) -> str:
    """The list as text: a header line, then one command per line (``mark_abs x=1.250 y=-3.000 z=0``).

    Positions print in mm with as many decimals as the discrete needs (they read back exactly), delays in
    board ticks, speeds in mm/s; ``# ...`` starts a comment. :func:`from_text` reads it back.
    """
    dec = max(0, math.ceil(-math.log10(header.discrete_mm) - 1e-9))
    meta = json.dumps(header.meta, sort_keys=True, allow_nan=False)
    out = [f"# jaxcnc vector list v{VERSION} tick_hz={header.tick_hz!r} discrete_mm={header.discrete_mm!r} "
           f"axes={','.join(header.axes)} meta={meta}"]  # fmt: skip
    for i in range(rec.shape[0]):  # a text export: one line per command
        r = rec[i]
        op = int(r["op"])
        parts = [Op.NAMES[op]]
        for name, fld, idx, kind in _TEXT_FIELDS[op]:
            v = r[fld][idx] if idx is not None else r[fld]
            if kind == "mm":
                parts.append(f"{name}={int(v) * header.discrete_mm:.{dec}f}")
            elif kind == "i":
                parts.append(f"{name}={int(v)}")
            else:
                parts.append(f"{name}={float(v)!r}")
        out.append(" ".join(parts))
    return "\n".join(out) + "\n"


_HEAD = re.compile(r"#\s*jaxcnc vector list v(\d+) tick_hz=(\S+) discrete_mm=(\S+) axes=(\S+) meta=(.*)$")


def from_text(text: str, where: str = "<text>") -> tuple[VectorHeader, np.ndarray]:
    """Read :func:`to_text` output (or a list written by hand in that form); errors name ``where:line``."""
    lines = text.splitlines()
    m = _HEAD.match(lines[0].strip()) if lines else None
    if not m:
        raise VectorFileError(f"{where}:1: the first line must be the '# jaxcnc vector list v1 ...' header")
    if int(m.group(1)) != VERSION:
        raise VectorFileError(f"{where}:1: vector list version {m.group(1)} is not supported")
    try:
        meta = json.loads(m.group(5), parse_constant=_no_constant)
        header = VectorHeader(float(m.group(2)), float(m.group(3)), tuple(m.group(4).split(",")), meta)
    except (ValueError, RecursionError) as exc:
        raise VectorFileError(f"{where}:1: bad header ({exc})") from None
    if not (10 <= header.tick_hz <= 1e7 and 1e-7 <= header.discrete_mm <= 1 and isinstance(meta, dict)):
        raise VectorFileError(f"{where}:1: header tick_hz, discrete_mm or meta out of range")
    items = []
    for ln, raw in enumerate(lines[1:], 2):
        s = raw.split("#", 1)[0].split()
        if not s:
            continue
        op = Op.CODES.get(s[0])
        if op is None:
            raise VectorFileError(f"{where}:{ln}: unknown command {s[0]!r}")
        spec = {name: (fld, idx, kind) for name, fld, idx, kind in _TEXT_FIELDS[op]}
        vals = {"pos": [0, 0, 0], "ticks": 0, "aux": 0, "value": 0.0, "value2": 0.0, "flags": 0}
        for word in s[1:]:
            name, eq, txt = word.partition("=")
            if not eq or name not in spec:
                raise VectorFileError(f"{where}:{ln}: {s[0]} takes {', '.join(spec) or 'no fields'}, not {word!r}")
            fld, idx, kind = spec[name]
            try:
                if kind == "mm":
                    v = float(txt) / header.discrete_mm
                    if not (math.isfinite(v) and abs(v) < 2**31):
                        raise ValueError("outside int32 discretes")
                    vals[fld][idx] = round(v)
                elif kind == "i":
                    v = int(txt)
                    if not -(2**31) <= v < 2**31 or (fld == "flags" and not 0 <= v < 2**16):
                        raise ValueError("out of range")
                    if idx is None:
                        vals[fld] = v
                    else:
                        vals[fld][idx] = v
                else:
                    vals[fld] = float(txt)
            except ValueError as exc:
                raise VectorFileError(f"{where}:{ln}: {name}={txt!r}: {exc}") from None
        items.append(make(op, vals["pos"], vals["ticks"], vals["aux"], vals["value"], vals["value2"], vals["flags"]))
    rec = records(items)
    check_records(rec, where)
    return header, rec


# ---------------------------------------------------------------------------------------------- encoding


def _lerp(a: np.ndarray, b: np.ndarray, j: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The board's interpolation: ``a + round_half_up((b - a) * j / n)`` in exact integers.

    ``a``, ``b``: ``(m, 3)`` int64; ``j``, ``n``: ``(m,)`` int64 with ``1 <= j <= n``. Returns ``(m, 3)``.
    """
    num = 2 * (b - a) * j[:, None] + n[:, None]
    return a + np.floor_divide(num, 2 * n[:, None])


def _longest_linear(p: np.ndarray, k: int, stop: int) -> int:
    """The longest ``m <= stop - k`` such that one vector from row k to row k+m reproduces rows k..k+m."""

    def fits(m: int) -> bool:
        j = np.arange(1, m + 1, dtype=np.int64)
        a = np.broadcast_to(p[k], (m, 3))
        b = np.broadcast_to(p[k + m], (m, 3))
        return bool(np.array_equal(_lerp(a, b, j, np.full(m, m, np.int64)), p[k + 1 : k + m + 1]))

    hi_cap = stop - k
    good, m = 1, 2
    while m <= hi_cap and fits(m):  # doubling, then bisection (lengths tried, not ticks walked)
        good, m = m, 2 * m
    lo, hi = good, min(m, hi_cap + 1)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if fits(mid):
            lo = mid
        else:
            hi = mid
    return lo


#: Vector lengths the vectorised search tries for every row at once; a row whose doubling reaches beyond this
#: (a long straight run) is searched on its own by :func:`_longest_linear` (the same probes).
_SHORT = 32
#: Rows whose search runs at once (bounds the probes' memory: rows x _SHORT x 3 int64).
_BLOCK = 1 << 14


def _fits_many(pos: np.ndarray, ks: np.ndarray, ms: np.ndarray) -> np.ndarray:
    """For each ``(k, m)``: one vector from row k to row k+m reproduces rows k..k+m. ``ks``, ``ms`` ``(q,)``
    int64, ``ms >= 2`` (row k+m itself is always hit). Returns ``(q,)`` bool; no Python step per row."""
    cnt = ms - 1
    owner = np.repeat(np.arange(ks.size), cnt)
    j = np.arange(owner.size, dtype=np.int64) - np.repeat(np.cumsum(cnt) - cnt, cnt) + 1
    k = ks[owner]
    got = _lerp(pos[k], pos[k + ms[owner]], j, ms[owner])
    bad = np.any(got != pos[k + j], axis=1)
    return np.bincount(owner[bad], minlength=ks.size) == 0


def _vector_lengths(pos: np.ndarray, ks: np.ndarray, cap: np.ndarray) -> np.ndarray:
    """:func:`_longest_linear` for many start rows at once (doubling, then bisection, with the same probes):
    ``(q,)`` lengths, -1 where the doubling goes beyond :data:`_SHORT` (left to :func:`_longest_linear`)."""
    good = np.ones(ks.size, np.int64)
    m = np.full(ks.size, 2, np.int64)
    live = m <= cap
    long = np.zeros(ks.size, bool)
    while live.any():  # doubling: one pass per power of two, every row at once
        i = np.flatnonzero(live)
        big = m[i] > _SHORT
        long[i[big]] = True
        i = i[~big]
        ok = _fits_many(pos, ks[i], m[i]) if i.size else np.zeros(0, bool)
        good[i[ok]] = m[i[ok]]
        m[i[ok]] *= 2
        live[:] = False
        live[i[ok]] = m[i[ok]] <= cap[i[ok]]
    lo, hi = good, np.minimum(m, cap + 1)
    todo = (hi - lo > 1) & ~long
    while todo.any():  # bisection, every row at once
        i = np.flatnonzero(todo)
        mid = (lo[i] + hi[i]) // 2
        ok = _fits_many(pos, ks[i], mid)
        lo[i[ok]] = mid[ok]
        hi[i[~ok]] = mid[~ok]
        todo[i] = hi[i] - lo[i] > 1
    return np.where(long, -1, lo)


def encode_rows(
    positions: np.ndarray,
    power: np.ndarray,
    pulses: np.ndarray | None = None,
) -> np.ndarray:
    """Timed vectors that reproduce a table tick for tick: LIST_START, TIMED_MARK/TIMED_JUMP, SET_LASER, pulses.

    ``positions``: ``(n, k)`` int discretes, ``k <= 3`` (row 0 is where the list starts); ``power``: ``(n,)`` laser
    output per row (0 = off); ``pulses``: records with fields ``tick``, ``kind`` (9 work, 10 idle), ``aux``,
    ``value`` (the table's pulse events) or ``None``. Each vector is as long as the board's interpolation
    (:func:`_lerp`) reproduces the rows exactly (found by doubling, then bisection); a vector ends where the laser
    power changes and at every pulse. Returns records ending in LIST_END.

    Vectorised: the vector length from every row is searched for all rows of a block at once
    (:func:`_vector_lengths`); the list follows them from row 0 (one integer step per vector) and is assembled
    with NumPy. The same records, record for record, as the one-step-per-vector reference in
    ``tests/test_scanner_vectors.py`` (compared on random tables).
    """
    pos = np.zeros((positions.shape[0], 3), np.int64)
    pos[:, : positions.shape[1]] = positions
    power = np.asarray(power, np.float64)
    n = pos.shape[0]
    if n == 0:
        raise ValueError("no rows to encode")
    pulse_ticks = np.zeros(0, np.int64) if pulses is None else np.asarray(pulses["tick"], np.int64)
    change = np.flatnonzero(power[1:] != power[:-1])
    breaks = np.unique(np.concatenate([[0, n - 1], change, pulse_ticks[(pulse_ticks > 0) & (pulse_ticks < n)]]))
    # the length of the vector that would start at each row (up to the next break)
    lengths = np.zeros(n, np.int64)
    for first in range(0, n - 1, _BLOCK):  # blocks of rows: bounded memory
        ks = np.arange(first, min(first + _BLOCK, n - 1), dtype=np.int64)
        cap = breaks[np.searchsorted(breaks, ks, side="right")] - ks
        lengths[ks] = _vector_lengths(pos, ks, cap)
    # the list: vectors from row 0 on (each ends where the next starts; breaks are reached exactly)
    starts: list[int] = []
    lens = lengths.tolist()
    nxt = breaks[1:].tolist()
    b_i, k = 0, 0
    while k < n - 1:  # one integer step per vector
        while nxt[b_i] <= k:
            b_i += 1
        m = lens[k]
        if m < 0:
            m = _longest_linear(pos, k, nxt[b_i])
        starts.append(k)
        k += m
    ks = np.asarray(starts, np.int64)
    ends = np.concatenate([ks[1:], [n - 1]]) if ks.size else ks
    vec = np.zeros(ks.size, VECTOR_DTYPE)
    vec["op"] = np.where(power[ks + 1] > 0, Op.TIMED_MARK, Op.TIMED_JUMP) if ks.size else 0
    vec["ticks"] = ends - ks
    vec["pos"] = pos[ends]
    # laser power where an interval's power differs from the one before and is on
    a = breaks[:-1]
    a = a[(power[a + 1] != power[a]) & (power[a + 1] > 0)]
    las = np.zeros(a.size, VECTOR_DTYPE)
    las["op"], las["value"] = Op.SET_LASER, power[a + 1]
    # pulses at row 0 and at the breaks (each after the vector that reaches its row), in the table's order
    if pulses is not None and len(pulses):
        sel = np.flatnonzero((pulse_ticks == 0) | np.isin(pulse_ticks, breaks[1:]))
        e = pulses[sel]
        idle = np.asarray(e["kind"]) == 10
        pul = np.zeros(sel.size, VECTOR_DTYPE)
        pul["op"], pul["flags"] = Op.LASER_PULSE, np.where(idle, FLAG_IDLE, 0)
        pul["aux"] = np.where(idle, -1, np.asarray(e["aux"], np.int64))
        pul["value"] = np.asarray(e["value"], np.float64)
        p_tick = pulse_ticks[sel]
    else:
        pul, p_tick, sel = np.zeros(0, VECTOR_DTYPE), np.zeros(0, np.int64), np.zeros(0, np.int64)
    head = [make(Op.LIST_START, pos[0], value=power[0])]
    if power[0] > 0:
        head.append(make(Op.SET_LASER, value=power[0]))
    # order: pulses at a row, then the laser power of the interval starting there, then its vector
    body = np.concatenate([pul, las, vec])
    key_row = np.concatenate([p_tick, a, ks])
    key_sub = np.concatenate([np.zeros(pul.size, np.int64), np.ones(las.size, np.int64), np.full(ks.size, 2)])
    key_seq = np.concatenate([sel, np.zeros(las.size + ks.size, np.int64)])
    body = body[np.lexsort((key_seq, key_sub, key_row))]
    return np.concatenate([records(head), body, records([make(Op.LIST_END)])])


# ---------------------------------------------------------------------------------------------- execution


@dataclass
class Execution:
    """What a board does with a list, per tick: ``positions`` ``(n, 3)`` int64 commanded discretes, ``power``
    ``(n,)`` laser output, ``lit_cmd`` ``(n,)`` the laser as commanded before its on/off delays, ``pulses``
    ``(m,)`` records (``tick``, ``kind`` 9/10, ``aux``, ``value``), ``outputs`` ``(k, 3)`` (tick, port, value),
    ``list_rows`` the first row of each list, ``vectors`` the number of motion commands executed."""

    positions: np.ndarray
    power: np.ndarray
    lit_cmd: np.ndarray
    pulses: np.ndarray
    outputs: np.ndarray
    list_rows: np.ndarray
    vectors: int


PULSE_DTYPE = np.dtype([("tick", "<i8"), ("kind", "<u4"), ("aux", "<i4"), ("value", "<f8")])


class _Lowering:
    """Commands → segments (a Python step per command; the rows come later, vectorised)."""

    def __init__(self, header: VectorHeader):
        self.h = header
        self.seg: list[tuple] = []  # (x0,y0,z0, x1,y1,z1, n, lit, arc, cx, cy, sweep_rad, chain)
        self.row = 0
        self.chain = -1
        self.chains: list[tuple[int, int, float]] = []  # (laser on delay, off delay, power) per chain
        self.pulses: list[tuple] = []
        self.outputs: list[tuple] = []
        self.list_rows: list[int] = []

    def add(self, a, b, n: int, lit: bool, arc=None) -> None:
        if n <= 0:
            return
        cx, cy, sw = arc if arc is not None else (0.0, 0.0, 0.0)
        self.seg.append((*a, *b, n, lit, arc is not None, cx, cy, sw, self.chain if lit else -1))
        self.row += n


def _ticks_for(length_disc: float, speed_mm_s: float, h: VectorHeader) -> int:
    return max(1, math.ceil(length_disc * h.discrete_mm / (speed_mm_s * h.dt) - 1e-9))


def _unit(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = (b - a).astype(np.float64)
    n = float(np.hypot(d[0], d[1]))
    return d[:2] / n if n > 0 else np.zeros(2)


def _turn_deg(u: np.ndarray, w: np.ndarray) -> float:
    if not (u.any() and w.any()):
        return 0.0
    return math.degrees(math.acos(max(-1.0, min(1.0, float(u @ w)))))


def _arc_geometry(start: np.ndarray, r) -> tuple:
    """(end position, radius in discretes, start angle, sweep in radians, start and end unit tangents)."""
    c = np.array([r["pos"][0], r["pos"][1]], np.float64)
    sweep = math.radians(float(r["value"]))
    rad = float(np.hypot(*(start[:2] - c)))
    a0 = math.atan2(start[1] - c[1], start[0] - c[0])
    end = start.copy()
    end[0] = round(c[0] + rad * math.cos(a0 + sweep))
    end[1] = round(c[1] + rad * math.sin(a0 + sweep))
    sgn = 1.0 if sweep >= 0 else -1.0
    t0 = sgn * np.array([-math.sin(a0), math.cos(a0)])
    t1 = sgn * np.array([-math.sin(a0 + sweep), math.cos(a0 + sweep)])
    return end, rad, a0, sweep, t0, t1


def execute(rec: np.ndarray, header: VectorHeader, where: str = "<list>") -> Execution:
    """The board's execution of a list (one or more LIST_START … LIST_END), tick by tick (``docs/scanner.md``).

    Returns an :class:`Execution`; row 0 is the first list's start. Motion: a JUMP_ABS moves dark at the jump
    speed, then waits the jump delay; marks (MARK_ABS, polyline vertices, ARC_ABS) move lit at the mark speed
    and form a *chain* while they follow each other; between two marks of a chain the beam waits the polygon
    delay (lit; variable mode: times the turning angle / 180°); after a chain, the mark delay (dark). The laser
    switches on ``laser-on delay`` ticks after a chain starts and off ``laser-off delay`` ticks after it ends.
    Sky-writing mode 1: a chain starts with a dark run-in (the beam is jumped back along the first mark's
    direction by run-in ticks of mark speed and accelerates through the start) and ends with a dark run-out;
    mode 2: also every corner turning more than the limit angle is left by a run-out, a dark turn at mark speed
    and a run-in (the chain is split there). Timed marks/jumps take exactly their ticks.
    """
    check_records(rec, where)
    h = header
    low = _Lowering(h)
    pos = np.zeros(3, np.int64)
    jump_v = mark_v = None
    on_d = off_d = jump_d = mark_d = poly_d = 0
    var_poly = False
    sky_mode, run_in, run_out, sky_limit = 0, 0, 0, 90.0
    power = 0.0
    in_chain = False
    last_dir = np.zeros(2)
    started = False
    vectors = 0
    ops = rec["op"]
    n = rec.shape[0]

    def next_mark_dir(i: int, at: np.ndarray) -> np.ndarray | None:
        """Direction of the chain that starts at record i (None: record i is no mark)."""
        j = i
        while j < n and ops[j] == Op.POLYLINE:
            j += 1
        if j >= n or ops[j] not in _MARKS:
            return None
        if ops[j] == Op.ARC_ABS:
            return _arc_geometry(at, rec[j])[4]
        return _unit(at, rec["pos"][j].astype(np.int64))

    def end_chain() -> None:
        nonlocal in_chain, pos
        if not in_chain:
            return
        in_chain = False
        if sky_mode >= 1 and run_out > 0 and last_dir.any():
            step = last_dir * run_out * mark_v * h.dt / h.discrete_mm
            to = pos.copy()
            to[:2] += np.round(step).astype(np.int64)
            low.add(pos, to, run_out, False)
            pos = to
        low.add(pos, pos, mark_d, False)

    def start_chain(direction: np.ndarray, at: np.ndarray) -> None:
        """A chain starts at ``at``; with sky-writing the beam turns (dark, at mark speed) to a run-in point
        behind ``at`` and accelerates through it."""
        nonlocal in_chain, pos
        if sky_mode >= 1 and run_in > 0 and direction.any():
            back = at.copy()
            back[:2] -= np.round(direction * run_in * mark_v * h.dt / h.discrete_mm).astype(np.int64)
            if not np.array_equal(back, pos):
                low.add(pos, back, _ticks_for(float(np.hypot(*(back - pos)[:2])), mark_v, h), False)
            low.add(back, at, run_in, False)
            pos = at.copy()
        low.chain += 1
        low.chains.append((on_d, off_d, power))
        in_chain = True

    pending = None  # the start of a chain a jump went behind (sky-writing's run-in point)
    i = 0
    while i < n:  # one step per command
        r = rec[i]
        op = int(r["op"])
        tgt = r["pos"].astype(np.int64)
        if pending is not None and op not in (*_MARKS, Op.POLYLINE):  # no chain came: run in to the jump's target
            low.add(pos, pending, run_in, False)
            pos, pending = pending, None
        if op == Op.LIST_START:
            end_chain()
            if not started:
                pos = tgt.copy()
                low.power0 = float(r["value"])
                started = True
            elif not np.array_equal(tgt, pos):
                raise VectorFileError(f"{where}: record {i} (list_start): the list starts at {tgt.tolist()}, "
                                      f"the beam is at {pos.tolist()}")  # fmt: skip
            low.list_rows.append(low.row + 1 if low.list_rows else 0)  # the first row the list produces
        elif op == Op.LIST_END:
            end_chain()
        elif op in (Op.JUMP_ABS, Op.TIMED_JUMP):
            end_chain()
            vectors += 1
            if op == Op.TIMED_JUMP:
                low.add(pos, tgt, int(r["ticks"]), False)
                if r["ticks"] == 0:
                    tgt = pos.copy()
                pos = tgt
            else:
                if jump_v is None:
                    raise VectorFileError(f"{where}: record {i} (jump_abs): no jump speed set before it")
                d = next_mark_dir(i + 1, tgt) if sky_mode >= 1 else None
                end = tgt.copy()
                if d is not None and run_in > 0 and mark_v is not None:
                    end[:2] -= np.round(d * run_in * mark_v * h.dt / h.discrete_mm).astype(np.int64)
                if not np.array_equal(end, pos):
                    low.add(pos, end, _ticks_for(float(np.linalg.norm((end - pos).astype(float))), jump_v, h), False)
                low.add(end, end, jump_d, False)
                pos = end  # at the run-in point when sky-writing: the chain's start runs in from here
                pending = tgt if not np.array_equal(end, tgt) else None
                last_dir = np.zeros(2)
        elif op in _MARKS or op == Op.TIMED_MARK:
            vectors += 1
            if op == Op.TIMED_MARK:
                if not in_chain:
                    low.chain += 1
                    low.chains.append((on_d, off_d, power))
                    in_chain = True
                low.add(pos, tgt, int(r["ticks"]), True)
                last_dir = _unit(pos, tgt) if not np.array_equal(pos, tgt) else last_dir
                pos = tgt
            else:
                if mark_v is None:
                    raise VectorFileError(f"{where}: record {i} ({Op.NAMES[op]}): no mark speed set before it")
                vertex = pos.copy() if pending is None else pending
                if op == Op.ARC_ABS:
                    end, rad, a0, sweep, d0, d1 = _arc_geometry(vertex, r)
                    length = abs(sweep) * rad
                else:
                    end = tgt
                    d0 = d1 = _unit(vertex, tgt)
                    length = float(np.linalg.norm((tgt - vertex).astype(float)))
                if length == 0 and op != Op.ARC_ABS:
                    i += 1
                    continue  # a zero-length mark does nothing (a pending run-in waits for the next mark)
                pending = None
                if not in_chain:
                    start_chain(d0, vertex)
                else:
                    turn = _turn_deg(last_dir, d0)
                    if sky_mode == 2 and turn > sky_limit:
                        saved = last_dir
                        end_chain()
                        last_dir = saved
                        start_chain(d0, vertex)
                    else:
                        hold = round(poly_d * turn / 180.0) if var_poly else poly_d
                        low.add(pos, pos, hold, True)
                nt = _ticks_for(length, mark_v, h)
                arc = (float(r["pos"][0]), float(r["pos"][1]), sweep) if op == Op.ARC_ABS else None
                low.add(pos, end, nt, True, arc)
                last_dir = d1
                pos = end
        elif op == Op.POLYLINE:
            pass  # its vertices follow as marks of one chain
        elif op == Op.SET_OUTPUT:
            low.outputs.append((low.row, int(r["aux"]), int(r["pos"][0])))
        elif op == Op.LASER_PULSE:  # the pulse fires on_delay ticks after the last row (the laser's own delay)
            kind = 10 if int(r["flags"]) & FLAG_IDLE else 9
            low.pulses.append((low.row + on_d, kind, int(r["aux"]), float(r["value"])))
        else:
            end_chain()
            if op == Op.SET_JUMP_SPEED:
                jump_v = float(r["value"])
            elif op == Op.SET_MARK_SPEED:
                mark_v = float(r["value"])
            elif op == Op.SET_LASER_DELAYS:
                on_d, off_d = int(r["ticks"]), int(r["aux"])
            elif op == Op.SET_SCANNER_DELAYS:
                jump_d, mark_d, poly_d = int(r["ticks"]), int(r["aux"]), int(r["pos"][0])
            elif op == Op.SET_POLYGON_MODE:
                var_poly = bool(r["aux"])
            elif op == Op.SET_SKY_WRITING:
                sky_mode, run_in, run_out, sky_limit = (
                    int(r["aux"]),
                    int(r["ticks"]),
                    int(r["pos"][0]),
                    float(r["value"]),
                )
            elif op == Op.SET_LASER:
                power = float(r["value"])
            elif op == Op.WAIT:
                low.add(pos, pos, int(r["ticks"]), False)
        i += 1
    end_chain()
    return _render(low, pos, vectors)


def _render(low: _Lowering, final: np.ndarray, vectors: int) -> Execution:
    """Segments → rows, vectorised (no step per tick)."""
    power0 = getattr(low, "power0", 0.0)
    seg = np.array(low.seg, dtype=np.float64) if low.seg else np.zeros((0, 13))
    counts = seg[:, 6].astype(np.int64)
    total = 1 + int(counts.sum())
    starts = 1 + (np.cumsum(counts) - counts).astype(np.int64)  # (no segments: a list of one row)
    idx = np.repeat(np.arange(counts.size), counts)
    j = np.arange(1, total, dtype=np.int64) - np.repeat(starts, counts) + 1
    nn = counts[idx]
    rows = _lerp(seg[idx, 0:3].astype(np.int64), seg[idx, 3:6].astype(np.int64), j, nn)
    arc = seg[idx, 8] > 0
    if arc.any():
        s = seg[idx[arc]]
        cx, cy, sw = s[:, 9], s[:, 10], s[:, 11]
        a0 = np.arctan2(s[:, 1] - cy, s[:, 0] - cx)
        rad = np.hypot(s[:, 0] - cx, s[:, 1] - cy)
        ang = a0 + sw * j[arc] / nn[arc]
        xy = np.stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)], 1)
        last = j[arc] == nn[arc]
        xy[last] = s[last][:, 3:5]  # the arc ends exactly on its end point
        rows[np.flatnonzero(arc), :2] = np.rint(xy).astype(np.int64)
    first = seg[0, 0:3].astype(np.int64) if counts.size else np.asarray(final, np.int64)
    positions = np.concatenate([first[None, :], rows])
    lit_cmd = np.zeros(total, bool)
    lit_cmd[1:] = seg[idx, 7] > 0
    lit_cmd[0] = power0 > 0
    chain_of_row = np.full(total, -1, np.int64)
    chain_of_row[1:] = seg[idx, 12].astype(np.int64)
    # the laser: each chain's lit rows, switched on on_delay ticks after its first row, off off_delay after its last
    edge = np.zeros(total + 1, np.int64)
    pw = np.zeros(total, np.float64)
    if low.chains:
        n_ch = len(low.chains)
        lit_rows = np.flatnonzero(chain_of_row >= 0)
        ch = chain_of_row[lit_rows]
        first_row = np.full(n_ch, total, np.int64)
        last_row = np.full(n_ch, -1, np.int64)
        np.minimum.at(first_row, ch, lit_rows)
        np.maximum.at(last_row, ch, lit_rows)
        params = np.array(low.chains, np.float64)
        used = first_row < total
        on0 = np.clip(first_row[used] + params[used, 0].astype(np.int64), 0, total)
        off1 = np.clip(last_row[used] + 1 + params[used, 1].astype(np.int64), 0, total)
        keep = off1 > on0
        on0, off1, p_ch = on0[keep], off1[keep], params[used][keep, 2]
        np.add.at(edge, on0, 1)
        np.add.at(edge, off1, -1)
        order = np.argsort(on0, kind="stable")
        k = np.searchsorted(on0[order], np.arange(total), side="right") - 1  # the latest chain switched on
        pw[k >= 0] = p_ch[order][k[k >= 0]]
    on = np.cumsum(edge[:-1]) > 0
    power = np.where(on, pw, 0.0)
    power[0] = power0 if power0 > 0 else power[0]
    pulses = np.array(low.pulses, dtype=PULSE_DTYPE) if low.pulses else np.zeros(0, PULSE_DTYPE)
    if pulses.size:
        pulses["tick"] = np.clip(pulses["tick"], 0, total - 1)
    outputs = np.array(low.outputs, np.int64).reshape(-1, 3)
    return Execution(positions, power, lit_cmd, pulses, outputs, np.array(low.list_rows or [0], np.int64), vectors)
