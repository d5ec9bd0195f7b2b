"""The laser channel and every event on the sinks (issue 16, Deliver 4): what the drives played equals the table tick
for tick (``sim``, ``tcp://`` with a lost link, ``udp://`` with loss, duplication and reordering); the laser goes dark
before the drives slow on a hold, a stop and an underrun; the stream frames carry the power (fuzzed).
"""

from __future__ import annotations

import json
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.format import EVENT_DTYPE, EventKind
from jaxcnc.hw.drives import DriveClock
from jaxcnc.hw.player import Player, play
from jaxcnc.hw.receiver import spawn
from jaxcnc.hw.sinks.sim import SimSink
from jaxcnc.hw.sinks.stream import Faults, StreamSink
from jaxcnc.hw.stream import DATA, Frame, ProtocolError, decode
from tests.conftest import make_machine
from tests.helpers import table_of

# M4 through corners (the power varies every tick), an S change, a dwell, M3, rapids: every kind of laser tick
PROGRAM = (
    "M4 S80\nG1 X10 F1200\nG1 Y10\nS40\nG1 X0\nG4 P0.01\nM3 S60\nG1 Y0\nM5\nG0 X5 Y5\nM4 S100\nG1 X15 F600\nM5\nM2\n"
)


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    m = make_machine()
    _, table, meas = table_of(PROGRAM, m, tmp_path_factory.mktemp("ls"))
    assert meas.ok
    p = table.power
    assert len(np.unique(p)) > 500 and p.max() == pytest.approx(100.0)  # M4: the power ramps with the speed
    return m, table


def test_sim_plays_the_power_channel_and_events_tick_for_tick(job):
    _, table = job
    sink = SimSink(buffer_rows=3000, keep=True)
    play(table, sink, chunk_rows=1000)
    np.testing.assert_array_equal(sink.recorded, table.positions)
    np.testing.assert_array_equal(sink.laser.played, table.power)  # bit for bit
    np.testing.assert_array_equal(np.concatenate(sink.events), table.events)
    assert sink.laser.n_dark == 0


def test_an_old_style_sink_still_gets_rows_and_events(job):
    _, table = job

    class EventsOnly(SimSink):
        def write(self, first_tick, rows, events):  # no power parameter: the laser is its events
            super().write(first_tick, rows, events)

    sink = EventsOnly(buffer_rows=3000, keep=True)
    play(table, sink)
    np.testing.assert_array_equal(np.concatenate(sink.events), table.events)
    assert not sink.laser.played.any()


@pytest.mark.parametrize("stop", [False, True])
def test_hold_and_stop_switch_the_laser_off_before_the_drives_slow(job, stop):
    m, table = job
    a_max = np.array([m.axis(a).a_max for a in table.axes])
    sink = SimSink(buffer_rows=1000, keep=True)
    player = Player(table, sink, a_max=a_max)

    def progress(done: int) -> None:
        if done > 4000 and player.commanded_rate != 0.0:
            player.request_stop() if stop else player.hold()
        elif not stop and done > 9000 and player.held:
            player.resume()

    result = player.run(progress)
    assert result.stopped == stop
    x = sink.recorded.astype(np.float64)
    speed = np.linalg.norm(np.diff(x, axis=0), axis=1)
    ev = np.concatenate(sink.events)
    laser = ev[ev["kind"] == EventKind.LASER]
    off = int(laser["tick"][np.flatnonzero(laser["value"] == 0)[0]])  # the first off: the hold's
    assert 4000 < off < 6000
    assert np.all(np.abs(speed[off - 50 : off] - speed[off - 51]) < 1.5)  # still cruising when it went dark
    slowed = off + int(np.argmax(speed[off:] < 0.5 * speed[off - 1]))
    assert slowed > off + 5 and not sink.laser.played[off:slowed].any()  # dark while slowing
    if not stop:  # resumed: the job ends where the table does, the laser back on its channel
        np.testing.assert_array_equal(sink.recorded[-1], table.positions[-1])
        assert sink.laser.played[-6000:].max() == pytest.approx(100.0)


def test_an_underrun_darkens_the_rows_the_drives_ramp_on():
    rows = np.cumsum(np.full((20_000, 1), 5, np.int32), axis=0)
    clock = DriveClock(1, 10_000, np.array([1e6]), reserve=2000, resume=4000)
    clock.push(rows[:10_000])
    clock.run(12_000, ended=False)  # the player stalls
    assert clock.underruns == 1
    lit = clock.last_lit
    first_dark = int(np.argmin(lit))
    assert lit[:first_dark].all() and not lit[first_dark:].any()  # lit at the planned rate, dark on the ramp
    assert 10_000 - 2000 <= first_dark < 10_000


def _stream(table, scheme: str, faults: Faults, tmp_path) -> tuple[dict, dict, np.ndarray, np.ndarray, np.ndarray]:
    rec = tmp_path / f"rec_{scheme}.npy"
    opts = ("--record", str(rec), "--speed", "20", "--capacity", "4096", "--idle-timeout", "20")
    proc, addr = spawn(f"{scheme}://127.0.0.1:0", *opts)
    try:
        sink = StreamSink(addr, faults=faults)
        result = play(table, sink)
        out, _ = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert result.executed_tick == table.n_rows - 1
    base = str(rec).removesuffix(".npy")
    got = json.loads(out.strip().splitlines()[-1])
    return sink.stats, got, np.load(rec), np.load(base + ".power.npy"), np.load(base + ".events.npy")


@pytest.mark.realtime
@pytest.mark.parametrize(
    ("scheme", "faults"),
    [
        ("tcp", Faults(disconnect_after=40)),
        ("udp", Faults(drop=0.05, duplicate=0.05, reorder=0.05, seed=3)),
    ],
)
def test_stream_receiver_plays_the_power_and_events_tick_for_tick(job, tmp_path, scheme, faults):
    _, table = job
    sent, got, rows, power, events = _stream(table, scheme, faults, tmp_path)
    if scheme == "udp":
        assert sent["dropped"] > 0 and sent["duplicated"] > 0 and sent["reordered"] > 0 and got["gaps"] > 0
    else:
        assert sent["reconnects"] == 1
    np.testing.assert_array_equal(rows, table.positions)
    np.testing.assert_array_equal(events, table.events)
    assert got["events_crc"] == zlib.crc32(table.events.tobytes())
    # tick for tick, except rows the drives took while slowing for want of rows (an underrun): those are dark
    differ = np.flatnonzero(power != table.power)
    assert np.all(power[differ] == 0) and differ.size == got["dark_rows"]
    assert differ.size == 0 or got["underruns"] > 0
    if got["underruns"] == 0:
        assert got["power_crc"] == zlib.crc32(np.ascontiguousarray(table.power, "<f4").tobytes())
    print(f"\n{scheme}: {got['underruns']} underruns, {differ.size} rows dark of {table.n_rows}")
    assert got["laser"] == 0.0


@settings(max_examples=300, deadline=None)
@given(
    count=st.integers(1, 256),
    n_axes=st.integers(1, 4),
    value=st.floats(width=32, allow_nan=True, allow_infinity=True),
    at=st.integers(0, 255),
)
def test_power_frames_round_trip_or_are_refused(count, n_axes, value, at):
    rows = np.arange(count * n_axes, dtype=np.int32).reshape(count, n_axes)
    power = np.full(count, 7.5, np.float32)
    power[at % count] = value
    ev = np.zeros(1, EVENT_DTYPE)
    ev["tick"], ev["kind"], ev["value"] = 10 + count - 1, EventKind.LASER, 3.0
    frame = Frame(DATA, n_axes, session=1, seq=2, tick=10, count=count, rows=rows, power=power, events=ev)
    data = frame.encode()
    if np.isfinite(np.float32(value)) and np.float32(value) >= 0:
        g = decode(data)
        np.testing.assert_array_equal(g.power, power)
        np.testing.assert_array_equal(g.rows, rows)
        np.testing.assert_array_equal(g.events, ev)
    else:
        with pytest.raises(ProtocolError, match="laser power"):
            decode(data)
    # the POWER flag cleared by a forger (CRC recomputed): the lengths no longer match
    bad = bytearray(data)
    bad[4] &= ~4
    body = bytes(bad[:-4])
    with pytest.raises(ProtocolError):
        decode(body + zlib.crc32(body).to_bytes(4, "little"))
