"""The scanner vector list format (jaxcnc.format.vectors): file and text round trips, fuzzing, the board's
meaning of each command, tick-exact encoding of tables."""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.errors import JaxcncError
from jaxcnc.format.vectors import (
    FLAG_IDLE,
    PULSE_DTYPE,
    VECTOR_DTYPE,
    Op,
    VectorFileError,
    VectorHeader,
    _longest_linear,
    check_records,
    encode_rows,
    execute,
    from_text,
    make,
    parse_vectors,
    read_vectors,
    records,
    to_text,
    write_vectors,
)

H = VectorHeader(100000.0, 0.001, ("x", "y"))


def encode_rows_loop(
    positions: np.ndarray,
    power: np.ndarray,
    pulses: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`~jaxcnc.format.vectors.encode_rows` one Python step per vector: the first implementation, the
    reference the vectorised one is compared with, record for record, on random tables.

    ``positions``: ``(n, k)`` int discretes, ``k <= 3`` (row 0 is where the list starts); ``power``: ``(n,)`` laser
    output per row (0 = off); ``pulses``: records with fields ``tick``, ``kind`` (9 work, 10 idle), ``aux``,
    ``value`` (the table's pulse events) or ``None``. Each vector is as long as the board's interpolation
    (:func:`_lerp`) reproduces the rows exactly; a vector ends where the laser power changes and at every
    pulse. Returns records ending in LIST_END.
    """
    pos = np.zeros((positions.shape[0], 3), np.int64)
    pos[:, : positions.shape[1]] = positions
    power = np.asarray(power, np.float64)
    n = pos.shape[0]
    if n == 0:
        raise ValueError("no rows to encode")
    pulse_ticks = np.zeros(0, np.int64) if pulses is None else np.asarray(pulses["tick"], np.int64)
    change = np.flatnonzero(power[1:] != power[:-1])  # power changes at row c+1: a vector ends at row c
    breaks = np.unique(np.concatenate([[0, n - 1], change, pulse_ticks[(pulse_ticks > 0) & (pulse_ticks < n)]]))
    items = [make(Op.LIST_START, pos[0], value=power[0])]
    cur_power = power[0]
    if cur_power > 0:
        items.append(make(Op.SET_LASER, value=cur_power))
    by_tick: dict[int, list[int]] = {}
    for i, t in enumerate(pulse_ticks.tolist()):
        by_tick.setdefault(t, []).append(i)

    def emit_pulses(t: int) -> None:
        for i in by_tick.get(t, ()):
            e = pulses[i]
            flags = FLAG_IDLE if int(e["kind"]) == 10 else 0
            items.append(make(Op.LASER_PULSE, aux=int(e["aux"]) if flags == 0 else -1, value=e["value"], flags=flags))

    emit_pulses(0)
    for a, b in zip(breaks[:-1].tolist(), breaks[1:].tolist(), strict=True):
        p_next = power[a + 1]
        if p_next != cur_power and p_next > 0:
            items.append(make(Op.SET_LASER, value=p_next))
        cur_power = p_next
        op = Op.TIMED_MARK if p_next > 0 else Op.TIMED_JUMP
        k = a
        while k < b:  # one step per vector
            m = _longest_linear(pos, k, b)
            items.append(make(op, pos[k + m], ticks=m))
            k += m
        emit_pulses(b)
    items.append(make(Op.LIST_END))
    return records(items)


def _square_list(sky: int = 0, delays: tuple = (0, 0, 0, 0, 0)) -> np.ndarray:
    on, off, jd, md, pd = delays
    return records(
        [
            make(Op.LIST_START),
            make(Op.SET_JUMP_SPEED, value=2000.0),
            make(Op.SET_MARK_SPEED, value=500.0),
            make(Op.SET_LASER, value=100.0, value2=20000.0, aux=200),
            make(Op.SET_LASER_DELAYS, ticks=on, aux=off),
            make(Op.SET_SCANNER_DELAYS, ticks=jd, aux=md, pos=(pd, 0, 0)),
            make(Op.SET_SKY_WRITING, aux=sky, ticks=10, pos=(12, 0, 0), value=30.0),
            make(Op.JUMP_ABS, pos=(1000, 0)),
            make(Op.POLYLINE, aux=4),
            make(Op.VERTEX, pos=(2000, 0)),
            make(Op.VERTEX, pos=(2000, 1000)),
            make(Op.VERTEX, pos=(1000, 1000)),
            make(Op.VERTEX, pos=(1000, 0)),
            make(Op.WAIT, ticks=5),
            make(Op.LIST_END),
        ]
    )


def test_file_and_text_round_trip(tmp_path):
    rec = _square_list(sky=2, delays=(3, 4, 5, 6, 7))
    write_vectors(tmp_path / "a.vec", rec, H)
    h, back = read_vectors(tmp_path / "a.vec")
    assert h.tick_hz == H.tick_hz and h.axes == H.axes and np.array_equal(back, rec)
    h2, back2 = from_text(to_text(rec, H))
    assert np.array_equal(back2, rec) and h2.discrete_mm == H.discrete_mm
    assert "vertex x=2.000 y=1.000" in to_text(rec, H)


def test_damaged_files_are_refused_in_one_line(tmp_path):
    rec = _square_list()
    write_vectors(tmp_path / "a.vec", rec, H)
    data = bytearray((tmp_path / "a.vec").read_bytes())
    data[40] ^= 1
    with pytest.raises(VectorFileError, match="checksum"):
        parse_vectors(bytes(data), "a.vec")
    bad = rec.copy()
    bad["op"][3] = 99
    with pytest.raises(VectorFileError, match=r"record 3 .*unknown command"):
        execute(bad, H)
    bad = rec.copy()
    bad["aux"][8] = 9  # the polyline announces more vertices than follow
    with pytest.raises(VectorFileError, match="record"):
        execute(bad, H)
    with pytest.raises(VectorFileError, match=r":4: unknown command 'zap'"):
        from_text(to_text(rec[:2], H) + "zap x=1\n")


def test_square_at_mark_speed():
    ex = execute(_square_list(), H)
    p = ex.positions
    # jump 1 mm at 2000 mm/s: 50 ticks; each 1 mm side at 500 mm/s: 200 ticks; the wait: 5
    assert p.shape[0] == 1 + 50 + 4 * 200 + 5
    assert np.array_equal(p[50, :2], [1000, 0]) and np.array_equal(p[250, :2], [2000, 0])
    assert ex.power[51:851].min() == 100.0 and ex.power[:51].max() == 0 and ex.power[851:].max() == 0
    assert np.abs(np.diff(p[51:851, :2], axis=0)).max() == 5  # 500 mm/s = 5 discretes a tick


def test_delays_polygon_and_laser():
    ex = execute(_square_list(delays=(3, 4, 5, 6, 7)), H)
    lit = np.flatnonzero(ex.power > 0)
    first_mark = 1 + 50 + 5  # after the jump and its delay
    assert lit[0] == first_mark + 3  # laser-on delay
    # 4 sides + 3 polygon delays of 7, the laser off 4 ticks after the last lit row
    assert lit[-1] == first_mark + 4 * 200 + 3 * 7 - 1 + 4
    assert ex.positions.shape[0] == 1 + 50 + 5 + 800 + 21 + 6 + 5


def test_variable_polygon_delay_scales_with_turning_angle():
    rec = _square_list(delays=(0, 0, 0, 0, 100))
    rec = np.insert(rec, 7, np.array([make(Op.SET_POLYGON_MODE, aux=1)], VECTOR_DTYPE))
    ex = execute(rec, H)
    assert ex.positions.shape[0] == 1 + 50 + 800 + 3 * 50 + 5  # 90 degree turns: half the delay


def test_sky_writing_laser_off_while_turning():
    ex = execute(_square_list(sky=2), H)
    lit = ex.power > 0
    # every corner (90 > 30 degrees) is sky-written: four separate lit runs, each a full side
    runs = np.flatnonzero(np.diff(lit.astype(int)) == 1)
    assert runs.size == 4
    assert lit.sum() == 4 * 200
    # while lit, the beam moves at mark speed (5 discretes a tick) along an axis
    step = np.abs(np.diff(ex.positions[:, :2], axis=0))[lit[1:] & lit[:-1]]
    assert np.all(step.max(axis=1) == 5) and np.all(step.min(axis=1) == 0)


def test_arc_mark():
    rec = records(
        [
            make(Op.LIST_START, pos=(1000, 0)),
            make(Op.SET_MARK_SPEED, value=100.0),
            make(Op.SET_LASER, value=1.0),
            make(Op.ARC_ABS, pos=(0, 0), value=90.0),
            make(Op.LIST_END),
        ]
    )
    ex = execute(rec, H)
    r = np.hypot(ex.positions[:, 0], ex.positions[:, 1])
    assert np.abs(r - 1000).max() <= 1 and np.array_equal(ex.positions[-1, :2], [0, 1000])
    assert ex.positions.shape[0] == 1 + int(np.ceil(np.pi / 2 / (100 * 1e-5)))


def test_encode_rows_reproduces_a_table_tick_for_tick():
    t = np.arange(3000)
    pos = np.stack([np.round(5000 * np.sin(t / 300)), np.round(3 * t + 0.002 * t**2)], 1).astype(np.int64)
    pos[1000:1200] = pos[1000]  # a dwell
    power = np.where((t > 100) & (t < 2500), 50.0, 0.0)
    power[1500:1600] = 80.0
    pulses = np.zeros(3, [("tick", "<i8"), ("kind", "<u4"), ("aux", "<u4"), ("value", "<f8")])
    pulses["tick"], pulses["kind"], pulses["aux"] = [0, 777, 2999], [9, 10, 9], [0, 0, 1]
    ex2 = execute(encode_rows(pos, power, pulses), H)
    assert np.array_equal(ex2.positions[:, :2], pos) and np.array_equal(ex2.power, power)
    assert ex2.pulses["tick"].tolist() == [0, 777, 2999] and ex2.pulses["kind"].tolist() == [9, 10, 9]
    assert len(encode_rows(pos, power, pulses)) < 3000  # vectors, not one command a tick


def test_vector_error_is_a_jaxcnc_error():
    assert issubclass(VectorFileError, JaxcncError)


_any_record = st.tuples(
    st.sampled_from(sorted(Op.NAMES)),
    st.integers(0, 1),
    st.integers(-(2**31), 2**31 - 1),
    st.lists(st.integers(-(2**31), 2**31 - 1), min_size=3, max_size=3),
    st.integers(-(2**31), 2**31 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(allow_nan=True, allow_infinity=True),
)


@settings(max_examples=300, deadline=None)
@given(st.lists(_any_record, max_size=12), st.binary(max_size=64), st.integers(0, 600))
def test_fuzz_reader_never_crashes(items, junk, cut):
    """Random records and damaged bytes: the reader accepts a valid list or refuses it with VectorFileError."""
    rec = np.array([(o, f, t, p, a, v, w) for o, f, t, p, a, v, w in items], VECTOR_DTYPE)
    try:
        check_records(rec)
        valid = True
    except VectorFileError:
        valid = False
    js = json.dumps({"tick_hz": 1e5, "discrete_mm": 1e-3, "axes": ["x", "y"], "n_records": len(rec)}).encode()
    body = b"JXVECTOR" + struct.pack("<II", 1, len(js)) + js + rec.tobytes()
    data = body + struct.pack("<I", zlib.crc32(body))
    if valid:
        _, back = parse_vectors(data)
        assert back.tobytes() == rec.tobytes()
        h, again = from_text(to_text(back, H))
        assert np.array_equal(again["op"], back["op"])
    for damaged in (data[:cut], data[:cut] + junk + data[cut:]):
        if damaged == data:
            continue
        with pytest.raises(VectorFileError):
            parse_vectors(damaged)


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=200))
def test_fuzz_text_reader(text):
    try:
        from_text("# jaxcnc vector list v1 tick_hz=100000.0 discrete_mm=0.001 axes=x,y meta={}\n" + text)
    except VectorFileError:
        pass


def _random_table(rng: np.random.Generator, n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Runs of constant speed, constant acceleration and jitter (short and long vectors), power in runs."""
    v = np.zeros((n, k))
    i = 0
    while i < n:
        m = min(int(rng.integers(1, 300)), n - i)
        mode = int(rng.integers(3))
        if mode == 0:
            v[i : i + m] = rng.normal(0, 20, k)
        elif mode == 1:
            v[i : i + m] = np.outer(np.arange(m), rng.normal(0, 0.5, k))
        else:
            v[i : i + m] = rng.normal(0, 3, (m, k))
        i += m
    pos = np.round(np.cumsum(v, axis=0)).astype(np.int64)
    power = np.repeat(rng.choice([0.0, 0.0, 1.5, 100.0], size=n // 50 + 1), 50)[:n]
    return pos, power


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 2500), k=st.integers(1, 3), n_pulses=st.integers(0, 12))
def test_vectorised_encoder_gives_the_loops_list_record_for_record(seed, n, k, n_pulses):
    rng = np.random.default_rng(seed)
    pos, power = _random_table(rng, n, k)
    pulses = np.zeros(n_pulses, PULSE_DTYPE)
    pulses["tick"] = rng.integers(-2, n + 2, n_pulses)  # some outside the table: neither encoder sends them
    pulses["kind"] = rng.choice([9, 10], n_pulses)
    pulses["aux"], pulses["value"] = rng.integers(0, 100, n_pulses), rng.random(n_pulses)
    fast = encode_rows(pos, power, pulses if n_pulses else None)
    assert fast.tobytes() == encode_rows_loop(pos, power, pulses if n_pulses else None).tobytes()
    ex = execute(fast, H)
    assert np.array_equal(ex.positions[:, :k], pos) and np.array_equal(ex.power, power)


def test_vectorised_encoder_long_runs_and_per_tick_power():
    """Long straight runs (the search past the vectorised lengths) and a power that changes at every tick."""
    t = np.arange(40000)
    pos = np.stack([7 * t, np.round(0.00001 * t**2)], 1).astype(np.int64)
    power = np.where(t % 2 == 0, 1.0, 2.0)
    power[20000:] = 0.0
    fast = encode_rows(pos, power)
    assert fast.tobytes() == encode_rows_loop(pos, power).tobytes()
    assert np.array_equal(execute(fast, H).positions[:, :2], pos)
