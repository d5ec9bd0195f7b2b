"""Forged and degenerate tables never pass: header validation, axes equal to the machine's, start and end.

Issue 14 found tables that passed ``check`` and played although they were wrong: a header with
``discrete_mm = NaN`` (or ``tick_hz = NaN``) and recomputed CRCs hid a 5 m jump (every comparison with NaN
is false), two axis columns swapped and relabelled passed (sinks send columns by position), crafted headers
(short ``axes``, ``n_rows = 0``, huge ``block_rows``, bad ``data_offset``, huge ``n_axes``) crashed ``check``
with a traceback, and a one-row table at X = 10 from a start at 0 (a jump into the first row) was OK.

Each is a test here. The forgeries recompute every CRC (header, blocks, events) so that only the semantic
validation can catch them; :func:`test_fuzzed_headers_are_refused_or_genuinely_valid` mutates every header
field, the metadata, the padding and the events at random (hypothesis) and prints its figures (``pytest -s``).
"""

from __future__ import annotations

import json
import math
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxcnc.cli.main import main
from jaxcnc.errors import JaxcncError, TableFileError
from jaxcnc.format import EVENT_DTYPE, FINE_SCALE, EventKind, TableFile, TableWriter
from jaxcnc.jobs import check_table
from tests.conftest import machine_text, make_machine

# The fixed header as docs/table-format.md documents it (independent of jaxcnc.format's own struct).
HEADER = struct.Struct("<8sHHIIddQQIQIQQ")
FIELDS = (
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
AXES = ["x", "y", "z"]
TICK_HZ = 10000.0
Q_MM = 0.001
CASES: dict[str, int] = {"run": 0, "refused_on_open": 0, "refused_by_check": 0, "accepted_ok": 0, "accepted_failed": 0}


# --- building and forging tables -------------------------------------------------------------------------


def write_rows(path: Path, x_mm: np.ndarray, *, axes=AXES, meta=None, block_rows=256, events=None) -> Path:
    """A table of exact positions ``x_mm`` ``(n, len(axes))`` (mm) with its fine channel, at 10 kHz, 1 µm."""
    u = np.asarray(x_mm, np.float64) / Q_MM
    pos = np.round(u)
    fine = np.round((u - pos) * FINE_SCALE)
    with TableWriter(
        path, axes=list(axes), tick_hz=TICK_HZ, discrete_mm=Q_MM, n_rows=u.shape[0], meta=meta, block_rows=block_rows
    ) as w:
        w.write(pos.astype(np.int32), fine.astype(np.int32))
        if events is not None:
            w.events = events
    return path


def smooth_rows(n: int = 2001, dist_mm=(1.0, 0.5, 0.0)) -> np.ndarray:
    """A rest-to-rest cosine move from the origin (the test machine's home) over ``n`` ticks, ``(n, 3)`` mm."""
    s = 0.5 * (1.0 - np.cos(np.pi * np.arange(n) / (n - 1)))
    return s[:, None] * np.asarray(dist_mm)[None, :]


def base_events(n: int) -> np.ndarray:
    ev = np.zeros(4, EVENT_DTYPE)
    ev["tick"] = [0, 0, n - 1, n - 1]
    ev["kind"] = [EventKind.BLOCK, EventKind.LASER, EventKind.LASER, EventKind.PROGRAM_END]
    ev["aux"] = [1, 3, 0, 0]
    ev["value"] = [0.0, 50.0, 0.0, 0.0]
    return ev


def header_of(blob: bytes) -> tuple[dict, bytes]:
    """The fixed header's fields and the raw metadata bytes."""
    f = dict(zip(FIELDS, HEADER.unpack_from(blob), strict=True))
    return f, blob[128 : 128 + f["json_bytes"]]


def recrc(blob: bytes) -> bytes:
    """Recompute every CRC the (possibly forged) header points at, where it lies inside the file."""
    b = bytearray(blob)
    f, _ = header_of(b)
    n_ch = 2 if f["flags"] & 1 else 1
    block_bytes = f["block_rows"] * f["n_axes"] * 4
    n_blocks, data = f["n_blocks"], f["data_offset"]
    crc_at = data - 4 * n_ch * n_blocks
    if 0 < block_bytes and 128 <= crc_at and data + n_ch * n_blocks * block_bytes <= len(b) and n_blocks < 1 << 20:
        for ch in range(n_ch):
            for k in range(n_blocks):
                at = data + (ch * n_blocks + k) * block_bytes
                struct.pack_into("<I", b, crc_at + 4 * (ch * n_blocks + k), zlib.crc32(b[at : at + block_bytes]))
    ev_at, ev_len = f["events_offset"], 24 * f["n_events"]
    if ev_at <= len(b) and ev_len <= len(b):
        f["events_crc"] = zlib.crc32(b[ev_at : ev_at + ev_len])
        b[:84] = HEADER.pack(*(f[k] for k in FIELDS))
    meta = bytes(b[128 : 128 + f["json_bytes"]])
    struct.pack_into("<I", b, 124, zlib.crc32(bytes(b[:124]) + meta))
    return bytes(b)


def forge(blob: bytes, meta: dict | bytes | None = None, **fields) -> bytes:
    """``blob`` with header fields and/or metadata replaced, every CRC recomputed (the data stays in place)."""
    b = bytearray(blob)
    f, old = header_of(b)
    if meta is not None:
        raw = meta if isinstance(meta, bytes) else json.dumps(meta, sort_keys=True).encode()
        b[128 : 128 + max(len(raw), len(old))] = raw.ljust(len(old), b"\0")
        f["json_bytes"] = len(raw)
    f.update(fields)
    b[:84] = HEADER.pack(*(f[k] for k in FIELDS))
    return recrc(bytes(b))


def meta_of(blob: bytes) -> dict:
    return json.loads(header_of(blob)[1])


@pytest.fixture
def good(tmp_path) -> Path:
    return write_rows(
        tmp_path / "good.ticks", smooth_rows(), meta={"machine": "test-machine"}, events=base_events(2001)
    )


@pytest.fixture
def machine_file(tmp_path) -> Path:
    p = tmp_path / "machine.toml"
    p.write_text(machine_text())
    return p


def _refused(path: Path, field: str) -> str:
    with pytest.raises(TableFileError) as info:
        TableFile(path)
    msg = str(info.value)
    assert str(path) in msg and field in msg and "\n" not in msg, msg
    return msg


# --- the forgeries of issue 14, one by one -----------------------------------------------------------------


def test_the_good_table_passes_check(good):
    table, meas = check_table(good, make_machine())
    assert meas.ok, [str(v) for v in meas.violations]
    assert table.axes == AXES


@pytest.mark.parametrize("field", ["discrete_mm", "tick_hz"])
def test_a_nan_header_hiding_a_5_m_jump_is_refused(tmp_path, field):
    """Issue 14: ``discrete_mm = NaN`` (or ``tick_hz``) with recomputed CRCs hid a 5 m jump: check said OK."""
    x = np.zeros((100, 3))
    x[50:, 0] = 5000.0  # 5 m in one tick
    p = write_rows(tmp_path / "jump.ticks", x)
    assert not check_table(p, make_machine())[1].ok  # honest header: the jump is a violation
    forged = tmp_path / f"nan_{field}.ticks"
    forged.write_bytes(forge(p.read_bytes(), **{field: math.nan}))
    _refused(forged, field)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("discrete_mm", math.inf),
        ("discrete_mm", -0.001),
        ("discrete_mm", 0.0),
        ("discrete_mm", 1e-300),
        ("discrete_mm", 10.0),
        ("tick_hz", math.inf),
        ("tick_hz", -10000.0),
        ("tick_hz", 0.0),
        ("tick_hz", 1e300),
    ],
)
def test_non_finite_or_out_of_range_scales_are_refused(good, tmp_path, field, value):
    p = tmp_path / "forged.ticks"
    p.write_bytes(forge(good.read_bytes(), **{field: value}))
    _refused(p, field)


def test_crafted_headers_are_refused_not_tracebacks(good, tmp_path):
    """Issue 14: short axes, ``n_rows = 0``, huge ``block_rows``, bad ``data_offset``, huge ``n_axes`` crashed check."""
    blob = good.read_bytes()
    f, _ = header_of(blob)
    meta = meta_of(blob)
    cases = {
        "axes": forge(blob, meta={**meta, "axes": ["x", "y"]}),
        "n_rows": forge(blob, n_rows=0, n_blocks=0),
        "n_rows ": forge(blob, n_rows=0),
        "block_rows": forge(blob, block_rows=2**31, n_blocks=1),
        "data_offset": forge(blob, data_offset=f["data_offset"] + 4096),
        "data_offset ": forge(blob, data_offset=8),
        "n_axes": forge(blob, n_axes=60000),
        "n_axes ": forge(blob, n_axes=0),
        "n_blocks": forge(blob, n_blocks=f["n_blocks"] + 1),
        "events_offset": forge(blob, events_offset=f["events_offset"] - 24, n_events=f["n_events"] + 1),
        "flags": forge(blob, flags=3),
    }
    for field, data in cases.items():
        p = tmp_path / f"{field.strip()}{len(field)}.ticks"
        p.write_bytes(data)
        _refused(p, field.strip())
        with pytest.raises(JaxcncError):
            check_table(p, make_machine())


@pytest.mark.parametrize(
    ("meta_change", "needle"),
    [
        ({"axes": ["x", "x", "z"]}, "axes"),
        ({"axes": ["x", "y", ""]}, "axes"),
        ({"axes": ["x", "y", "z z"]}, "axes"),
        ({"axes": ["x", "y", 3]}, "axes"),
        ({"axes": "xyz"}, "axes"),
        ({"axes": None}, "axes"),
        ({"start_mm": [0.0, math.nan, 0.0]}, "start_mm"),
        ({"start_mm": [0.0, 0.0]}, "start_mm"),
        ({"start_mm": {"x": 0}}, "start_mm"),
        ({"n_blocks": "many"}, "n_blocks"),
        ({"source": ["a.ngc"]}, "source"),
        ({"total_time_s": math.inf}, "total_time_s"),
    ],
)
def test_malformed_metadata_is_refused(good, tmp_path, meta_change, needle):
    blob = good.read_bytes()
    p = tmp_path / "forged.ticks"
    p.write_bytes(forge(blob, meta={**meta_of(blob), **meta_change}))
    _refused(p, needle)


def test_metadata_that_is_not_an_object_or_holds_nan_is_refused(good, tmp_path):
    blob = good.read_bytes()
    for i, raw in enumerate([b"[1, 2, 3]", b'{"axes": ["x", "y", "z"], "total_time_s": NaN}', b'"axes"']):
        p = tmp_path / f"meta{i}.ticks"
        p.write_bytes(forge(blob, meta=raw))
        _refused(p, "metadata")


def test_padding_and_reserved_bytes_must_be_well_formed(good, tmp_path):
    blob = good.read_bytes()
    f, _ = header_of(blob)
    t = TableFile(good)
    h = t.header
    # the last block's padding rows must repeat the final row (2001 rows in blocks of 256: 47 padding rows)
    bad = bytearray(blob)
    struct.pack_into("<i", bad, h.data_offset + (h.n_rows + 5) * 3 * 4, 123456)
    (tmp_path / "pad.ticks").write_bytes(recrc(bytes(bad)))
    _refused(tmp_path / "pad.ticks", "padding")
    bad = bytearray(blob)
    struct.pack_into("<i", bad, h.fine_offset + (h.n_rows + 40) * 3 * 4 + 4, 99)
    (tmp_path / "padf.ticks").write_bytes(recrc(bytes(bad)))
    _refused(tmp_path / "padf.ticks", "padding")
    # zero padding after the metadata, reserved header bytes
    bad = bytearray(blob)
    bad[128 + f["json_bytes"] + 10] = 1
    (tmp_path / "zpad.ticks").write_bytes(recrc(bytes(bad)))
    _refused(tmp_path / "zpad.ticks", "padding")
    bad = bytearray(blob)
    bad[100] = 7
    (tmp_path / "reserved.ticks").write_bytes(recrc(bytes(bad)))
    _refused(tmp_path / "reserved.ticks", "reserved")


def with_events(blob: bytes, change) -> bytes:
    """``blob`` with its event records changed in place by ``change(records)``, every CRC recomputed."""
    f, _ = header_of(blob)
    b = bytearray(blob)
    at, n = f["events_offset"], f["n_events"]
    ev = np.frombuffer(bytes(b[at : at + 24 * n]), EVENT_DTYPE).copy()
    change(ev)
    b[at : at + 24 * n] = ev.tobytes()
    return recrc(bytes(b))


@pytest.mark.parametrize(
    ("column", "value", "needle"),
    [
        ("tick", -1, "tick"),
        ("tick", 2001, "tick"),
        ("tick", 2**62, "tick"),
        ("kind", 0, "kind"),
        ("kind", 99, "kind"),
        ("value", math.nan, "value"),
        ("value", -math.inf, "value"),
    ],
)
def test_malformed_events_are_refused(good, tmp_path, column, value, needle):
    p = tmp_path / "ev.ticks"
    p.write_bytes(with_events(good.read_bytes(), lambda ev: ev[column].__setitem__(1, value)))
    _refused(p, needle)
    with pytest.raises(ValueError, match=needle):  # the writer never writes them either
        ev = base_events(2001)
        ev[column][1] = value
        write_rows(tmp_path / "w.ticks", smooth_rows(), events=ev)


def test_unsorted_events_and_bad_laser_records_are_refused(good, tmp_path):
    p = tmp_path / "unsorted.ticks"
    p.write_bytes(with_events(good.read_bytes(), lambda ev: ev.__setitem__(slice(None), ev[[0, 2, 1, 3]])))
    _refused(p, "sorted")
    for i, (aux, value) in enumerate([(7, 50.0), (3, -5.0)]):

        def change(ev, aux=aux, value=value):
            ev["aux"][1], ev["value"][1] = aux, value

        p = tmp_path / f"laser{i}.ticks"
        p.write_bytes(with_events(good.read_bytes(), change))
        _refused(p, "laser")


# --- axes equal to the machine's, in order -----------------------------------------------------------------


def test_swapped_and_relabelled_columns_are_refused_by_check_and_play(tmp_path, machine_file, capsys):
    """Issue 14: x and y swapped and relabelled passed check; sinks send columns by position."""
    x = smooth_rows(dist_mm=(1.0, 0.5, 0.0))
    p = write_rows(tmp_path / "swapped.ticks", x[:, [1, 0, 2]], axes=["y", "x", "z"])
    TableFile(p)  # a well-formed file: only the machine can tell
    with pytest.raises(TableFileError) as info:
        check_table(p, make_machine())
    msg = str(info.value)
    assert "['y', 'x', 'z']" in msg and "['x', 'y', 'z']" in msg and str(p) in msg
    assert main(["check", str(p), "-m", str(machine_file)]) == 2
    assert main(["play", str(p), "--sink", "sim", "-m", str(machine_file), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("['y', 'x', 'z']" in ln for ln in err), err


@pytest.mark.parametrize("axes", [["x", "y"], ["x", "y", "z", "u"], ["x", "y", "u"]])
def test_other_axis_sets_are_refused(tmp_path, axes):
    x = np.zeros((10, len(axes)))
    p = write_rows(tmp_path / "other.ticks", x, axes=axes)
    with pytest.raises(TableFileError, match="axes"):
        check_table(p, make_machine())


# --- start and end at rest, the first row at the start -----------------------------------------------------


def test_a_jump_into_the_first_row_is_a_violation(tmp_path, machine_file, capsys):
    """Issue 14: ``G1 X10 F0.0000001`` once planned a one-row table X = 10 from a start at 0; check said OK."""
    p = write_rows(tmp_path / "teleport.ticks", np.array([[10.0, 0.0, 0.0]]))
    _, meas = check_table(p, make_machine())
    assert not meas.ok
    first = [v for v in meas.violations if v.first_tick == 0 and v.axis == "x"]
    assert first, [str(v) for v in meas.violations]
    assert any(v.quantity == "start" for v in first)
    assert main(["check", str(p), "-m", str(machine_file)]) == 1
    out = capsys.readouterr()
    assert "tick 0" in out.out and "start" in out.out and "FAILED" in out.err


def test_a_small_offset_of_the_first_row_is_a_violation(tmp_path):
    """Half a millimetre off the start, then a smooth move: the jump in is listed like any other violation."""
    x = smooth_rows() + np.array([0.5, 0.0, 0.0])
    _, meas = check_table(write_rows(tmp_path / "off.ticks", x), make_machine())
    kinds = {(v.first_tick, v.axis, v.quantity) for v in meas.violations}
    assert (0, "x", "start") in kinds and (0, "x", "v") in kinds, kinds


def test_the_declared_start_is_the_reference(tmp_path):
    """A table whose header records where the job starts (``start_mm``) is compared with that start."""
    x = smooth_rows() + np.array([10.0, 0.0, 0.0])
    ok = write_rows(tmp_path / "declared.ticks", x, meta={"start_mm": [10.0, 0.0, 0.0]})
    assert check_table(ok, make_machine())[1].ok
    bad = write_rows(tmp_path / "wrong.ticks", x, meta={"start_mm": [0.0, 0.0, 0.0]})
    _, meas = check_table(bad, make_machine())
    assert any(v.quantity == "start" and v.axis == "x" for v in meas.violations)
    bad = write_rows(tmp_path / "home.ticks", x)  # nothing declared: the machine's home (0)
    _, meas = check_table(bad, make_machine())
    assert any(v.quantity == "start" and v.axis == "x" for v in meas.violations)


def test_a_table_that_starts_or_ends_moving_fails(tmp_path):
    x = smooth_rows()
    _, meas = check_table(write_rows(tmp_path / "ends.ticks", x[:1000]), make_machine())  # stops mid-move
    assert any(v.first_tick >= 999 - 3 and v.quantity in ("a", "j", "v") for v in meas.violations)
    moving = np.zeros((200, 3))
    moving[:, 0] = np.arange(200) * 0.005  # 50 mm/s from the first tick
    _, meas = check_table(write_rows(tmp_path / "starts.ticks", moving), make_machine())
    assert any(v.first_tick <= 2 and v.quantity == "a" for v in meas.violations)


# --- the command line on forged files ----------------------------------------------------------------------


def test_check_on_forged_files_exits_2_with_one_line(good, tmp_path, machine_file):
    blob = good.read_bytes()
    f, _ = header_of(blob)
    forged = {
        "nan_discrete": forge(blob, discrete_mm=math.nan),
        "nan_tick": forge(blob, tick_hz=math.nan),
        "no_rows": forge(blob, n_rows=0, n_blocks=0),
        "short_axes": forge(blob, meta={**meta_of(blob), "axes": ["x"]}),
        "huge_axes": forge(blob, n_axes=65535),
        "bad_offset": forge(blob, data_offset=f["data_offset"] * 3),
    }
    for name, data in forged.items():
        p = tmp_path / f"{name}.ticks"
        p.write_bytes(data)
        r = subprocess.run(
            [sys.executable, "-m", "jaxcnc.cli.main", "check", str(p), "-m", str(machine_file)],
            capture_output=True,
            text=True,
        )
        assert r.returncode == 2, (name, r.stdout, r.stderr)
        assert r.stdout == "", (name, r.stdout)
        lines = r.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("jaxcnc: error: ") and str(p) in lines[0], (name, r.stderr)


# --- the fuzzer: every header field, the metadata, the padding, the events, with valid CRCs -----------------

_INT_FIELDS = {
    "version": 2**16 - 1,
    "n_axes": 2**16 - 1,
    "block_rows": 2**32 - 1,
    "flags": 2**32 - 1,
    "n_rows": 2**64 - 1,
    "n_blocks": 2**64 - 1,
    "json_bytes": 2**32 - 1,
    "n_events": 2**64 - 1,
    "data_offset": 2**64 - 1,
    "events_offset": 2**64 - 1,
}
_FLOATS = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 5e-324, 1e-300, 1e300, 2.0**64, -TICK_HZ]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.5, 2.0, 1.0 + 1e-12, 1.0 - 1e-12, 10.0, 0.1]),  # times the true value
)
_JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=6,
)
_AXES_VALUES = st.one_of(
    st.permutations(AXES),
    st.lists(st.sampled_from(["x", "y", "z", "u", "X", "", "x y", "é", "a" * 40, "1x"]), max_size=5),
    _JSON,
)
_META_KEYS = [
    "axes",
    "start_mm",
    "n_blocks",
    "n_points",
    "source",
    "source_sha256",
    "total_time_s",
    "pulse_hz",
    "extra",
]


@st.composite
def mutations(draw) -> list[tuple]:
    out = []
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(
            st.sampled_from(["float", "int", "int", "meta", "meta_raw", "swap", "pad", "event", "resize", "data"])
        )
        if kind == "float":
            field = draw(st.sampled_from(["tick_hz", "discrete_mm"]))
            out.append((kind, field, draw(_FLOATS), draw(st.booleans())))
        elif kind == "int":
            field = draw(st.sampled_from(sorted(_INT_FIELDS)))
            hi = _INT_FIELDS[field]
            special = st.sampled_from(
                sorted({min(v, hi) for v in (0, 1, 2, 3, 32, 33, 4096, hi - 1, 2**31, 2**32, 2**20 + 1)})
            )
            delta = st.integers(-5000, 5000).map(lambda d: ("delta", d))
            value = draw(st.one_of(special, st.integers(0, hi), delta))
            out.append((kind, field, value, draw(st.booleans())))
        elif kind == "meta":
            key = draw(st.sampled_from(_META_KEYS))
            if key == "axes":
                value = draw(_AXES_VALUES)
            elif key == "start_mm":
                value = draw(st.one_of(st.lists(st.floats(-600, 600), min_size=3, max_size=3), _JSON))
            else:
                value = draw(_JSON)
            out.append((kind, key, value, draw(st.booleans())))  # the flag: delete the key instead
        elif kind == "meta_raw":
            out.append((kind, draw(st.one_of(st.binary(max_size=40), _JSON.map(lambda v: json.dumps(v).encode())))))
        elif kind == "swap":
            i, j = draw(st.permutations(range(3)))[:2]
            out.append((kind, i, j, draw(st.booleans())))  # the flag: relabel the axes too
        elif kind == "pad":
            out.append((kind, draw(st.integers(0, 1)), draw(st.integers(0, 46)), draw(st.integers(0, 2))))
        elif kind == "event":
            column = draw(st.sampled_from(["tick", "kind", "aux", "value", "order"]))
            value = {
                "tick": st.sampled_from([-1, 0, 1999, 2000, 2001, 2**62, -(2**63)]) | st.integers(-(2**63), 2**63 - 1),
                "kind": st.integers(0, 2**32 - 1) | st.integers(0, 14),
                "aux": st.integers(0, 2**32 - 1) | st.integers(0, 10),
                "value": _FLOATS,
                "order": st.permutations(range(4)).map(list),
            }[column]
            out.append((kind, draw(st.integers(0, 3)), column, draw(value)))
        elif kind == "resize":
            out.append((kind, draw(st.integers(-6000, 100))))
        else:  # a data row changed (a jump, a spike): a valid file, a motion check must judge
            out.append(
                (kind, draw(st.integers(0, 2000)), draw(st.integers(0, 2)), draw(st.integers(-(2**31), 2**31 - 1)))
            )
    return out


def _apply(blob: bytes, muts: list[tuple]) -> bytes:
    good_f, _ = header_of(blob)
    for m in muts:
        f, raw = header_of(blob)
        if m[0] in ("float", "int"):
            _, field, value, scaled = m
            if m[0] == "float" and scaled and math.isfinite(value):
                value = value * good_f[field]
            if isinstance(value, tuple):
                value = min(max(good_f[field] + value[1], 0), _INT_FIELDS[field])
            blob = forge(blob, **{field: value})
        elif m[0] == "meta":
            _, key, value, delete = m
            try:
                meta = json.loads(raw)
            except ValueError:
                continue
            if not isinstance(meta, dict):
                continue
            if delete:
                meta.pop(key, None)
            else:
                meta[key] = value
            blob = forge(blob, meta=json.dumps(meta).encode()[:3000])
        elif m[0] == "meta_raw":
            blob = forge(blob, meta=m[1])
        elif m[0] in ("swap", "pad", "data"):
            b = bytearray(blob)
            n_axes, br, nb, d0 = f["n_axes"], f["block_rows"], f["n_blocks"], f["data_offset"]
            if n_axes != 3 or d0 + 2 * nb * br * 12 > len(b) or not 1 <= nb * br <= 1 << 20:
                continue
            arr = np.frombuffer(bytes(b[d0 : d0 + 2 * nb * br * 12]), "<i4").reshape(2, nb * br, 3).copy()
            if m[0] == "swap":
                _, i, j, relabel = m
                arr[:, :, [i, j]] = arr[:, :, [j, i]]
            elif m[0] == "pad":
                _, ch, row, col = m
                if f["n_rows"] + row < nb * br:
                    arr[ch, f["n_rows"] + row, col] += 1
            else:
                _, row, col, value = m
                arr[0, row % max(1, min(f["n_rows"], nb * br)), col] = value
            b[d0 : d0 + arr.nbytes] = arr.tobytes()
            blob = recrc(bytes(b))
            if m[0] == "swap" and relabel:
                try:
                    meta = json.loads(header_of(blob)[1])
                    meta["axes"][i], meta["axes"][j] = meta["axes"][j], meta["axes"][i]
                    blob = forge(blob, meta=json.dumps(meta).encode())
                except (ValueError, TypeError, KeyError, IndexError):
                    pass
        elif m[0] == "event":
            _, idx, column, value = m
            if f["n_events"] != 4 or f["events_offset"] + 96 > len(blob):
                continue

            def change(ev, idx=idx, column=column, value=value):
                if column == "order":
                    ev[:] = ev[value]
                else:
                    ev[column][idx] = value

            blob = with_events(blob, change)
        elif m[0] == "resize":
            blob = blob[: len(blob) + m[1]] if m[1] < 0 else blob + bytes(m[1])
            blob = recrc(blob) if len(blob) >= 128 else blob
    return blob


def _genuinely_valid(blob: bytes, machine) -> list[str]:
    """What is wrong with a table, judged from its bytes by the documented layout alone (empty: nothing)."""
    f, raw = header_of(blob)
    wrong = []
    meta = json.loads(raw)
    q, hz = f["discrete_mm"], f["tick_hz"]
    # the tolerances of a rate or step "equal to the machine's" (jaxcnc.ticks.verify)
    if not (abs(hz - machine.tick_hz) <= 1e-9 * machine.tick_hz and abs(q - machine.discrete_mm) <= 1e-12):
        return [f"scales {hz} Hz, {q} mm"]
    if meta.get("axes") != list(machine.axis_names) or f["n_axes"] != len(machine.axis_names) or not f["flags"] & 1:
        return [f"axes {meta.get('axes')} flags {f['flags']}"]
    n, br, nb, d0 = f["n_rows"], f["block_rows"], f["n_blocks"], f["data_offset"]
    if n < 1 or nb != -(-n // br) or len(blob) != f["events_offset"] + 24 * f["n_events"]:
        return [f"layout n_rows {n} block_rows {br} n_blocks {nb}"]
    rows = np.frombuffer(blob, "<i4", 2 * nb * br * 3, d0).reshape(2, nb * br, 3).astype(np.float64)
    if np.any(rows[:, n:] != rows[:, n - 1 : n]):
        wrong.append("padding")
    x = (rows[0, :n] + rows[1, :n] / FINE_SCALE) * q
    start = np.asarray(meta.get("start_mm") or [machine.axis(a).home for a in machine.axis_names], np.float64)
    if np.any(np.abs(x[0] - start) > q / 2):
        wrong.append("start")
    padded = np.vstack([np.repeat(start[None], 3, 0), x, np.repeat(x[-1:], 3, 0)])
    v, a = np.diff(padded, axis=0) * hz, np.diff(padded, n=2, axis=0) * hz**2
    for i, name in enumerate(machine.axis_names):
        ax = machine.axis(name)
        if np.abs(v[:, i]).max() > ax.v_max * (1 + 1e-6) + 1e-6 or np.abs(a[:, i]).max() > ax.a_max * (1 + 1e-6) + 0.1:
            wrong.append(f"limits {name}")
        if rows[0, :n, i].min() * q < ax.min - q / 2 or rows[0, :n, i].max() * q > ax.max + q / 2:
            wrong.append(f"travel {name}")
    ev = np.frombuffer(blob, EVENT_DTYPE, f["n_events"], f["events_offset"])
    if ev.size and (
        ev["tick"].min() < 0
        or ev["tick"].max() >= n
        or np.any(np.diff(ev["tick"]) < 0)
        or not np.isfinite(ev["value"]).all()
    ):
        wrong.append("events")
    if not set(ev["kind"].tolist()) <= set(EventKind.NAMES):
        wrong.append("event kinds")
    return wrong


_BASE: dict[str, object] = {}


def _fuzz_base() -> tuple[bytes, Path]:
    """The valid table every fuzz case mutates, written once (not a fixture: hypothesis would print its bytes)."""
    if not _BASE:
        import tempfile

        folder = Path(tempfile.mkdtemp(prefix="jaxcnc-table-fuzz-"))
        p = write_rows(folder / "base.ticks", smooth_rows(), meta={"machine": "test-machine"}, events=base_events(2001))
        _BASE.update(blob=p.read_bytes(), folder=folder)
    return _BASE["blob"], _BASE["folder"]


@settings(max_examples=2000, deadline=None, suppress_health_check=list(HealthCheck))
@given(muts=mutations())
def test_fuzzed_headers_are_refused_or_genuinely_valid(muts):
    """Any mutation of a valid table, with every CRC recomputed, is refused in one line naming the file (on
    open or by check), or accepted with finite figures — and check says OK only for a table that is genuinely
    valid, judged from its bytes independently of jaxcnc.format."""
    base, folder = _fuzz_base()
    machine = make_machine()
    blob = _apply(base, muts)
    p = folder / "fuzzed.ticks"
    p.write_bytes(blob)
    CASES["run"] += 1
    try:
        TableFile(p)
    except TableFileError as exc:
        msg = str(exc)
        assert "\n" not in msg and msg.startswith(f"{p}: "), msg
        CASES["refused_on_open"] += 1
        return
    try:
        _, meas = check_table(p, machine)
    except JaxcncError as exc:
        msg = str(exc)
        assert "\n" not in msg and str(p) in msg, msg
        CASES["refused_by_check"] += 1
        return
    figures = [meas.max_abs_v, meas.max_abs_a, meas.max_abs_j, meas.min_pos, meas.max_pos]
    assert all(math.isfinite(v) for d in figures for v in d.values()), figures
    assert all(math.isfinite(v.value) and math.isfinite(v.limit) for v in meas.violations)
    if meas.ok:
        assert _genuinely_valid(blob, machine) == [], muts
        CASES["accepted_ok"] += 1
    else:
        CASES["accepted_failed"] += 1


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    print(f"\ntable header fuzz cases: {json.dumps(CASES)}")
    if _BASE:
        import shutil

        shutil.rmtree(_BASE["folder"], ignore_errors=True)
