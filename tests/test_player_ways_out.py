"""Every way out of a play — an error, a signal, a lost link, an underrun — leaves the laser off and
the drives at rest on the path, per sink: ``sim`` (in memory and recording to a file), the stream
receiver, and LinuxCNC's HAL where it is installed."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from jaxcnc.format import EventKind
from jaxcnc.hw.player import Player
from jaxcnc.hw.receiver import spawn
from jaxcnc.hw.sinks.hal import HalStreamerSink, hal_available
from jaxcnc.hw.sinks.sim import SimSink
from jaxcnc.hw.sinks.stream import StreamSink
from tests.conftest import machine_text, make_machine
from tests.helpers import table_of

PROGRAM = "G1 X150 F3000 M3 S800\nM5\nM2\n"  # 3 s at 50 mm/s with the laser on


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    folder = tmp_path_factory.mktemp("out")
    m = make_machine()
    _, table, _ = table_of(PROGRAM, m, folder, "line.ticks")
    (folder / "m.toml").write_text(machine_text())
    return m, table, np.array([m.axis(a).a_max for a in table.axes]), folder / "m.toml"


class Boom(RuntimeError):
    pass


def _fail_at(tick: int):
    def progress(done: int) -> None:
        if done > tick:
            raise Boom("the player failed")

    return progress


def _windowed_accel(x_mm: np.ndarray, f: float, w: int = 100) -> np.ndarray:
    v = (x_mm[w:] - x_mm[:-w]) * f / w
    return np.abs(v[w:] - v[:-w]) * f / w


def _on_the_line_at_rest(pos: np.ndarray, table, m, a_max) -> None:
    """Positions (servo ticks): on the line, never back, |a| within the limit, at rest at the end."""
    assert np.all(pos[:, 1:] == table.positions[0, 1:])
    assert np.all(np.diff(pos[:, 0]) >= 0)
    assert np.all(pos[-1] == pos[-2])
    assert _windowed_accel(pos[:, 0] * m.discrete_mm, m.tick_hz).max() <= a_max[0] * 1.02


def _last_laser(events: list[np.ndarray]) -> float:
    ev = np.concatenate(events)
    laser = ev[ev["kind"] == EventKind.LASER]
    return float(laser[np.argsort(laser["tick"], kind="stable")]["value"][-1])


@pytest.mark.parametrize("to_file", [False, True], ids=["memory", "record"])
def test_sim_error_mid_job_ramps_down_and_switches_the_laser_off(job, tmp_path, to_file):
    m, table, a_max, _ = job
    rec = tmp_path / "rec.npy" if to_file else None
    sink = SimSink(buffer_rows=4000, keep=True, a_max=a_max, trace=True, record=rec)
    with pytest.raises(Boom):
        Player(table, sink, a_max=a_max).run(_fail_at(10_000))
    executed = sink.clock.executed
    assert 10_000 < executed < table.n_rows - 1000  # stopped mid-job, inside the buffer
    rows = np.load(rec) if to_file else sink.recorded
    np.testing.assert_array_equal(rows, table.positions[: executed + 1])  # each row once, in order
    _on_the_line_at_rest(np.vstack(sink.trace), table, m, a_max)
    assert sink.clock.hard_stops == 0
    assert _last_laser(sink.events) == 0.0  # the laser off


def test_sim_sigterm_is_a_controlled_stop_with_the_recording_finished(job, tmp_path):
    m, table, a_max, mfile = job
    rec = tmp_path / "rec.npy"
    cmd = [sys.executable, "-m", "jaxcnc", "play", str(table.path), "--sink", "sim", "--realtime"]
    proc = subprocess.Popen(
        [*cmd, "--record", str(rec), "-m", str(mfile), "-q"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        part = rec.with_name(rec.name + ".part")
        deadline = time.monotonic() + 60
        while not (part.exists() and part.stat().st_size > 3 * 4 * 3000) and time.monotonic() < deadline:
            time.sleep(0.02)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert "controlled stop" in err and "Traceback" not in err
    rows = np.load(rec)
    assert rows.shape[0] < table.n_rows + 5000
    assert np.all(rows[:, 1:] == table.positions[0, 1:]) and np.all(np.diff(rows[:, 0]) >= 0)
    assert np.all(rows[-1] == rows[-2])


def test_sim_without_limits_an_interrupt_stops_the_drives_at_once(job):
    """No machine file: nothing to ramp with; the drives hold the last row executed (a hard stop,
    counted), the buffered rows are dropped, and the laser is switched off."""
    m, table, a_max, _ = job
    sink = SimSink(buffer_rows=4000, keep=True)

    def progress(done: int) -> None:
        if done > 10_000:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        Player(table, sink).run(progress)
    executed = sink.clock.executed
    np.testing.assert_array_equal(sink.recorded, table.positions[: executed + 1])
    assert executed < 10_000 + 4000 and sink.clock.hard_stops == 1
    assert _last_laser(sink.events) == 0.0


def _receiver(m, a_max, rec, *extra):
    a = ",".join(str(x) for x in a_max / m.discrete_mm)
    return spawn("tcp://127.0.0.1:0", "--record", str(rec), "--a-max-disc", a, "--speed", "1", *extra)


def test_stream_player_error_sends_stop_the_receiver_ramps_down_with_the_laser_off(job, tmp_path):
    m, table, a_max, _ = job
    rec = tmp_path / "rec.npy"
    proc, addr = _receiver(m, a_max, rec, "--idle-timeout", "20")
    try:
        with pytest.raises(Boom):
            Player(table, StreamSink(addr), a_max=a_max).run(_fail_at(8_000))
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 1 and "stopped the job" in err.splitlines()[-1], err
    got = json.loads(out.strip().splitlines()[-1])
    assert got["at_rest"] and got["hard_stops"] == 0 and got["laser"] == 0.0 and not got["done"]
    assert got["laser_events"] >= 1  # the laser had been switched on by the table's event
    played = np.load(rec)
    assert 8_000 < played.shape[0] < table.n_rows
    np.testing.assert_array_equal(played, table.positions[: played.shape[0]])


def test_stream_link_loss_the_receiver_ramps_down_with_the_laser_off(job, tmp_path):
    """The player process dies (SIGKILL: nothing of it runs any more): the receiver's buffer runs
    low, its drives ramp down on the path, the laser goes off at rest, and its idle timeout ends it."""
    m, table, a_max, _ = job
    rec = tmp_path / "rec.npy"
    proc, addr = _receiver(m, a_max, rec, "--idle-timeout", "2")
    player = subprocess.Popen(
        [sys.executable, "-m", "jaxcnc", "play", str(table.path), "--sink", addr, "-q"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        part = rec.with_name(rec.name + ".part")
        deadline = time.monotonic() + 60
        while not (part.exists() and part.stat().st_size > 3 * 4 * 6000) and time.monotonic() < deadline:
            time.sleep(0.02)
        player.kill()
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
        player.kill()
    assert proc.returncode == 1 and "no frame from the player" in err.splitlines()[-1], err
    got = json.loads(out.strip().splitlines()[-1])
    assert got["at_rest"] and got["hard_stops"] == 0 and got["underruns"] >= 1 and got["laser"] == 0.0
    played = np.load(rec)
    np.testing.assert_array_equal(played, table.positions[: played.shape[0]])


@pytest.mark.hal
@pytest.mark.skipif(hal_available() is not None, reason=str(hal_available()))
def test_hal_error_mid_job_closes_the_laser_gate_and_holds_the_drives(job):
    m, table, a_max, _ = job
    sink = HalStreamerSink(depth=2048, keep=True)
    with pytest.raises(Boom):
        Player(table, sink, a_max=a_max).run(_fail_at(5_000))
    assert sink.laser_at_end == 0.0  # the gate closed at once
    rec = sink.recorded
    assert 5_000 < rec.shape[0] < table.n_rows
    np.testing.assert_array_equal(rec, table.positions[: rec.shape[0]])  # on the path; then held
    assert sink.laser_power.max() == 800.0  # (it was on while moving)
    # the session ended: the next one starts
    sink2 = HalStreamerSink(depth=2048, keep=True)
    sink2.open(table.header)
    sink2.abort()


pytestmark = pytest.mark.realtime
