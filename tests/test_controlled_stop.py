"""Ctrl-C while playing: a controlled stop along the path, within the acceleration limits."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np

from jaxcnc.hw.player import Player, stop_ramp
from jaxcnc.hw.sinks.sim import SimSink
from tests.conftest import machine_text, make_machine
from tests.helpers import table_of

PROGRAM = "G1 X400 F3000\nM2\n"  # 400 mm at 50 mm/s: 8 s of cruise (the sim buffers 1.6 s)


def _windowed_accel(rows: np.ndarray, q: float, f: float, w: int = 100) -> np.ndarray:
    """|a| from velocities averaged over w ticks (quantisation noise ~ q f / w per velocity)."""
    v = (rows[w:] - rows[:-w]) * q * f / w
    return np.abs(v[w:] - v[:-w]) * f / w


def test_stop_ramp_stays_on_the_path_and_within_limits(tmp_path):
    m = make_machine()
    _, table, _ = table_of(PROGRAM, m, tmp_path)
    a_max = np.array([m.axis(a).a_max for a in table.axes])
    sent = table.n_rows // 2
    ramp = stop_ramp(table, a_max, sent)
    rows = np.vstack([table.positions[:sent], ramp])
    assert rows.shape[0] < table.n_rows  # stopped before the end
    assert np.all(rows[:, 1:] == table.positions[0, 1:])  # still on the line (y, z unchanged)
    assert np.all(np.diff(rows[:, 0]) >= 0)  # never backwards
    assert np.all(ramp[-1] == ramp[-2])  # at rest
    assert _windowed_accel(rows[:, 0].astype(float), m.discrete_mm, m.tick_hz).max() <= 1000.0 * 1.02


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


def test_ctrl_c_in_jaxcnc_play_is_a_controlled_stop(tmp_path):
    machine = tmp_path / "m.toml"
    machine.write_text(machine_text())
    m = make_machine()
    _, table, _ = table_of(PROGRAM, m, tmp_path, "long.ticks")
    rec = tmp_path / "rec.npy"
    cmd = [sys.executable, "-m", "jaxcnc.cli.main", "play", str(tmp_path / "long.ticks"), "--sink", "sim"]
    cmd += ["--realtime", "--record", str(rec), "-m", str(machine), "-q"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ))
    time.sleep(2.0)  # start-up, then about a second of motion
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
