"""Underruns: when the player is late the drives ramp down along the path, wait, and resume exactly."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from jaxcnc.hw.drives import DriveClock
from jaxcnc.hw.player import play
from jaxcnc.hw.receiver import spawn
from jaxcnc.hw.sinks.sim import SimSink
from jaxcnc.hw.sinks.stream import StreamSink
from tests.conftest import make_machine
from tests.helpers import table_of

PROGRAM = "G1 X400 F3000\nM2\n"  # 8 s of cruise at 50 mm/s on x


@pytest.fixture(scope="module")
def line(tmp_path_factory):
    m = make_machine()
    _, table, _ = table_of(PROGRAM, m, tmp_path_factory.mktemp("u"))
    a_max = np.array([m.axis(a).a_max for a in table.axes])
    return m, table, a_max


def _windowed_accel(x_mm: np.ndarray, f: float, w: int = 100) -> np.ndarray:
    """|a| (mm/s²) from velocities averaged over w ticks (the quantisation noise averages out)."""
    v = (x_mm[w:] - x_mm[:-w]) * f / w
    return np.abs(v[w:] - v[:-w]) * f / w


def _check_ramp(pos: np.ndarray, table, a_max: np.ndarray, q: float, f: float) -> None:
    """The drives stayed on the line, never went back, and kept within the x acceleration limit."""
    assert np.all(pos[:, 1:] == table.positions[0, 1:])  # y, z: still on the line
    assert np.all(np.diff(pos[:, 0]) >= 0)  # never backwards
    assert _windowed_accel(pos[:, 0] * q, f).max() <= a_max[0] * 1.02


def test_drive_clock_ramps_down_on_underrun_and_resumes_exactly(line):
    m, table, a_max = line
    q, f, rows = m.discrete_mm, m.tick_hz, table.positions
    clock = DriveClock(rows.shape[1], f, a_max / q, reserve=4000, resume=8000)
    half = rows.shape[0] // 2
    clock.push(rows[:half])
    t1, p1 = clock.run(half + 5000, ended=False)  # the player stalls: 5000 ticks more than it sent
    assert clock.underruns == 1 and clock.hard_stops == 0 and clock.rate == 0.0
    assert clock.held_ticks > 0 and np.all(p1[-1] == p1[-2])  # at rest
    assert half - 4000 < len(t1) < half  # stopped inside the reserve, not at its end
    clock.push(rows[half:])
    t2, p2 = clock.run(10**7, ended=True)
    np.testing.assert_array_equal(np.vstack([t1, t2]), rows)  # every row taken once, in order
    pos = np.vstack([p1, p2])
    np.testing.assert_array_equal(pos[-1], rows[-1])  # same final position
    _check_ramp(pos, table, a_max, q, f)


def test_without_limits_the_drives_can_only_hold(line):
    _, table, _ = line
    rows = table.positions
    clock = DriveClock(rows.shape[1], 10_000.0, None)
    clock.push(rows[:1000])
    taken, pos = clock.run(1500, ended=False)
    assert len(taken) == 1000 and clock.hard_stops == 1 and clock.underruns == 1
    assert np.all(pos[1000:] == rows[999])


class _StallsOnce:
    """Mixed into a sink: the player stalls once, at tick ``stall_at``, for ``stall_s`` seconds."""

    stall_at, stall_s = 10_000, 0.5

    def write(self, first_tick, rows, events):
        if first_tick >= self.stall_at and not getattr(self, "_stalled", False):
            self._stalled = True
            time.sleep(self.stall_s)
        super().write(first_tick, rows, events)


class _LatePlayerSink(_StallsOnce, SimSink):
    """A real-time sim whose player stalls once, 1 s into the job, for 0.5 s."""


@pytest.mark.realtime
def test_sim_sink_reports_an_underrun_and_ramps_down(line):
    m, table, a_max = line
    sink = _LatePlayerSink(buffer_rows=4000, realtime=True, keep=True, a_max=a_max, trace=True)
    result = play(table, sink, chunk_rows=1000)
    assert sink.underruns >= 1 and sink.clock.hard_stops == 0 and sink.clock.held_ticks > 0
    assert result.executed_tick == table.n_rows - 1
    np.testing.assert_array_equal(sink.recorded, table.positions)
    pos = np.vstack(sink.trace)
    assert pos.shape[0] > table.n_rows  # the wait took extra ticks
    np.testing.assert_array_equal(pos[-1], table.positions[-1])
    _check_ramp(pos, table, a_max, m.discrete_mm, m.tick_hz)


class _LateStreamSink(_StallsOnce, StreamSink):
    stall_at, stall_s = 20_000, 1.0


@pytest.mark.realtime
def test_receiver_ramps_down_when_the_player_is_late_and_the_player_reports_it(line, tmp_path):
    m, table, a_max = line
    rec = tmp_path / "rec.npy"
    a = ",".join(str(x) for x in a_max / m.discrete_mm)
    opts = ("--record", str(rec), "--speed", "4", "--capacity", "8192", "--a-max-disc", a, "--idle-timeout", "20")
    proc, addr = spawn("tcp://127.0.0.1:0", *opts)
    try:
        sink = _LateStreamSink(addr)
        result = play(table, sink)
        out, _ = proc.communicate(timeout=60)
    finally:
        proc.kill()
    got = json.loads(out.strip().splitlines()[-1])
    assert got["underruns"] >= 1 and got["hard_stops"] == 0 and got["held_ticks"] > 0
    assert sink.underruns == got["underruns"]  # the player learnt of them from the acknowledgements
    assert result.executed_tick == table.n_rows - 1
    np.testing.assert_array_equal(np.load(rec), table.positions)
