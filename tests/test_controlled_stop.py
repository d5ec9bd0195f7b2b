"""Ctrl-C while playing: a controlled stop along the path, within the acceleration limits."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from jaxcnc.format import EventKind
from jaxcnc.hw.player import Player
from jaxcnc.hw.sinks.sim import SimSink
from tests.conftest import machine_text, make_machine
from tests.helpers import table_of

PROGRAM = "G1 X400 F3000\nM2\n"  # 400 mm at 50 mm/s: 8 s of cruise (the sim buffers 1.6 s)


def _windowed_accel(rows: np.ndarray, q: float, f: float, w: int = 100) -> np.ndarray:
    """|a| from velocities averaged over w ticks (quantisation noise ~ q f / w per velocity)."""
    v = (rows[w:] - rows[:-w]) * q * f / w
    return np.abs(v[w:] - v[:-w]) * f / w


def test_player_hold_resume_and_override_on_the_path_within_limits(tmp_path):
    """Feed hold at full speed while playing, a wait, resume at half override: the drives stay on
    the line, within the acceleration limit, and finish at the table's end; the laser is off at rest."""
    m = make_machine()
    _, table, _ = table_of("G1 X400 F3000 M3 S800\nM5\nM2\n", m, tmp_path)
    a_max = np.array([m.axis(a).a_max for a in table.axes])
    sink = SimSink(buffer_rows=2000, keep=True)
    player = Player(table, sink, a_max=a_max)
    held_at = []

    def progress(done: int) -> None:
        if done > 20_000 and not held_at:
            player.hold()
            held_at.append(done)
        elif held_at and done > held_at[0] + 15_000 and player.commanded_rate == 0.0:
            player.set_override(0.5)
            player.resume()

    result = player.run(progress)
    assert not result.stopped and player.holds == 1
    rows = sink.recorded
    assert rows.shape[0] == result.executed_tick + 1 > table.n_rows  # the hold and the half feed took longer
    np.testing.assert_array_equal(rows[-1], table.positions[-1])  # the same final position
    assert np.all(rows[:, 1:] == table.positions[0, 1:])  # on the line (y, z unchanged)
    x = rows[:, 0]
    assert np.all(np.diff(x) >= 0)  # never backwards
    assert _windowed_accel(x.astype(float), m.discrete_mm, m.tick_hz).max() <= 1000.0 * 1.02
    still = np.flatnonzero(np.diff(x) == 0)
    assert still.size > 10_000  # a real wait at rest
    ev = np.concatenate(sink.events)
    laser = ev[ev["kind"] == EventKind.LASER]
    # on at the start, off at rest in the hold, on again before moving, off at M5
    assert list(laser["value"] > 0) == [True, False, True, False]
    off, on = int(laser["tick"][1]), int(laser["tick"][2])
    step = np.diff(x)
    cruise = step[off - 100 : off - 1]
    assert np.all(cruise == cruise[0]) and step[off - 1] == cruise[0]  # off before the drives slowed (issue 16)
    assert np.all(step[on - 10 : on] == 0)  # back on where the drives leave the rest
    played = sink.laser.played
    assert np.all(played[off:on] == 0) and np.all(played[5:off] == 800.0)  # the power channel as played
    v_half = np.diff(x[-30_000:-20_000]).mean() * m.discrete_mm * m.tick_hz
    assert abs(v_half - 25.0) < 0.5  # the 50 mm/s cruise at 50 % override


def test_player_request_stop_from_another_thread(tmp_path):
    m = make_machine()
    _, table, _ = table_of(PROGRAM, m, tmp_path)
    sink = SimSink(buffer_rows=2000, keep=True)
    player = Player(table, sink, a_max=np.array([m.axis(a).a_max for a in table.axes]))
    player.request_stop()
    result = player.run()
    assert result.stopped and result.executed_tick < 2000 + 1000  # the buffer, then the hold
    rec = sink.recorded[: result.executed_tick + 1]
    assert np.all(rec[-1] == rec[-2])


def _start_play(tmp_path, *extra: str, stdin=None):
    """A real ``jaxcnc play -m`` process on the long line in real time; ``(process, table, recording path)``."""
    machine = tmp_path / "m.toml"
    machine.write_text(machine_text())
    _, table, _ = table_of(PROGRAM, make_machine(), tmp_path, "long.ticks")
    rec = tmp_path / "rec.npy"
    cmd = [sys.executable, "-m", "jaxcnc.cli.main", "play", str(tmp_path / "long.ticks"), "--sink", "sim"]
    cmd += ["--realtime", "--record", str(rec), "-m", str(machine), *extra]
    proc = subprocess.Popen(cmd, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return proc, table, rec


def _rows_recorded(rec) -> int:
    """Rows the drives have executed so far (the recording's raw ``.part`` file grows as they run)."""
    try:
        return rec.with_name(rec.name + ".part").stat().st_size // 12
    except FileNotFoundError:
        return 0


def _wait_rows(rec, n: int, timeout: float = 120.0) -> int:
    """Wait (on the recording, not the clock: a loaded machine starts slowly) until ``n`` rows ran."""
    deadline = time.monotonic() + timeout
    while (got := _rows_recorded(rec)) < n:
        assert time.monotonic() < deadline, f"only {got} rows executed"
        time.sleep(0.02)
    return got


@pytest.mark.realtime
def test_ctrl_c_in_jaxcnc_play_is_a_controlled_stop(tmp_path):
    m = make_machine()
    proc, table, rec = _start_play(tmp_path, "-q")
    _wait_rows(rec, 10_000)  # about a second of motion
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "controlled stop" in err and "Traceback" not in err
    executed = int(err.rsplit("tick", 1)[1].split()[0])
    rows = np.load(rec)[: executed + 1]
    assert executed < table.n_rows - 1000  # stopped well before the end
    assert np.all(rows[:, 1:] == table.positions[0, 1:])
    assert np.all(rows[-1] == rows[-2]) and np.all(np.diff(rows[:, 0]) >= 0)
    assert _windowed_accel(rows[:, 0].astype(float), m.discrete_mm, m.tick_hz).max() <= 1000.0 * 1.02


@pytest.mark.realtime
def test_jaxcnc_play_takes_hold_resume_and_override_from_a_pipe(tmp_path):
    """Operator controls on the command line: hold at full speed, resume at 50 %, to the end."""
    m = make_machine()
    proc, table, rec = _start_play(tmp_path, stdin=subprocess.PIPE)
    _wait_rows(rec, 15_000)  # about a second and a half of motion
    proc.stdin.write("hold\n")
    proc.stdin.flush()
    _wait_rows(rec, _rows_recorded(rec) + 25_000)  # the buffer (16,384 rows), the ramp, then a wait at rest
    proc.stdin.write("override 0.5\nbogus\nresume\n")
    proc.stdin.flush()
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "feed holds: 1" in out and "unknown control 'bogus'" in err
    rows = np.load(rec)
    assert rows.shape[0] > table.n_rows + 10_000  # waited, then went on at half feed
    np.testing.assert_array_equal(rows[-1], table.positions[-1])
    assert np.all(rows[:, 1:] == table.positions[0, 1:]) and np.all(np.diff(rows[:, 0]) >= 0)
    assert _windowed_accel(rows[:, 0].astype(float), m.discrete_mm, m.tick_hz).max() <= 1000.0 * 1.02
    assert np.sum(np.diff(rows[:, 0]) == 0) > 5_000  # at rest in the hold
