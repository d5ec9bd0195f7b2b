"""Playing a table through a real LinuxCNC HAL: halstreamer → streamer → sampler → halsampler.

Skipped where LinuxCNC (``linuxcnc-uspace``) is not installed; ``.ci/run`` installs it.
"""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.format import EventKind
from jaxcnc.hw.player import play
from jaxcnc.hw.sinks import open_sink
from jaxcnc.hw.sinks.hal import HalStreamerSink, hal_available
from tests.conftest import make_machine
from tests.helpers import table_of

pytestmark = [pytest.mark.hal, pytest.mark.skipif(hal_available() is not None, reason=str(hal_available()))]

# a square with the laser on, then a rapid back: ~2.3 s of motion at 10 kHz (23k ticks)
PROGRAM = "G1 X10 F1200 M3 S500\nY10\nX0\nY0\nM5\nG0 X5 Y5\nM2\n"


def test_table_played_through_linuxcnc_comes_back_tick_for_tick(tmp_path):
    m = make_machine()
    _, table, _ = table_of(PROGRAM, m, tmp_path)
    assert table.n_rows > 10_000
    sink = HalStreamerSink(depth=4096, keep=True)
    result = play(table, sink)
    assert result.executed_tick == table.n_rows - 1
    np.testing.assert_array_equal(sink.recorded, table.positions)  # every tick, exactly
    # the laser column follows the table's LASER events
    laser = table.events[table.events["kind"] == EventKind.LASER]
    on, off = int(laser["tick"][0]), int(laser["tick"][-1])
    assert laser["value"][0] > 0 and laser["value"][-1] == 0
    assert np.all(sink.laser_power[on:off] == laser["value"][0]) and np.all(sink.laser_power[off:] == 0)
    assert np.all(sink.laser_power[:on] == 0)


def test_hal_sink_by_name_and_a_second_session_is_refused(tmp_path):
    m = make_machine()
    _, table, _ = table_of("G1 X1 F600\nM2\n", m, tmp_path)
    first = open_sink("halstreamer", keep=True)
    first.open(table.header)
    try:
        with pytest.raises(Exception, match="already running"):
            HalStreamerSink().open(table.header)
    finally:
        first.close()
    # the session ended cleanly: a new one starts and plays
    sink = open_sink("hal", keep=True)
    play(table, sink)
    np.testing.assert_array_equal(sink.recorded, table.positions)


def test_feed_hold_and_resume_through_linuxcnc(tmp_path):
    """A hold at full speed and a resume, played through the HAL: on the line, never back, same end."""
    from jaxcnc.hw.player import Player

    m = make_machine()
    _, table, _ = table_of("G1 X40 F3000 M3 S500\nM5\nM2\n", m, tmp_path)
    sink = HalStreamerSink(depth=2048, keep=True)
    player = Player(table, sink, a_max=np.array([m.axis(a).a_max for a in table.axes]))
    held = []

    def progress(done: int) -> None:
        if done > 3000 and not held:
            player.hold()
            held.append(done)
        elif held and done > held[0] + 8000 and player.held:
            player.resume()

    result = player.run(progress)
    rec = sink.recorded
    assert player.holds == 1 and rec.shape[0] == result.executed_tick + 1 > table.n_rows + 5000
    np.testing.assert_array_equal(rec[-1], table.positions[-1])
    assert np.all(rec[:, 1:] == table.positions[0, 1:]) and np.all(np.diff(rec[:, 0]) >= 0)


def test_two_sinks_opened_at_the_same_instant_one_is_refused(tmp_path):
    """The guard is race-free: two players opening together can never both start a session."""
    import threading

    m = make_machine()
    _, table, _ = table_of("G1 X1 F600\nM2\n", m, tmp_path)
    sinks = [HalStreamerSink(keep=True) for _ in range(2)]
    barrier = threading.Barrier(2)
    outcome: list = [None, None]

    def open_one(i: int) -> None:
        barrier.wait()
        try:
            sinks[i].open(table.header)
            outcome[i] = "opened"
        except Exception as exc:  # noqa: BLE001 - the refusal is the point
            outcome[i] = str(exc)

    threads = [threading.Thread(target=open_one, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    try:
        assert sorted(o == "opened" for o in outcome) == [False, True], outcome
        assert any("already running" in o for o in outcome if o != "opened"), outcome
    finally:
        for s, o in zip(sinks, outcome, strict=True):
            if o == "opened":
                s.close()


def test_laser_power_enable_and_pulse_bits_through_linuxcnc(tmp_path):
    """Issue 16: M4 power per tick, the enable bit and PSO pulses one tick wide, as the table has them."""
    from jaxcnc.machine import parse_machine
    from tests.conftest import machine_text

    m = parse_machine(machine_text() + '[laser]\nmode = "pso"\npso_mm = 0.5\n', "pso.toml")
    _, table, meas = table_of("M4 S80\nG1 X10 F1200\nG1 Y10\nM5\nG0 X0 Y0\nM2\n", m, tmp_path)
    assert meas.ok
    sink = HalStreamerSink(depth=4096, keep=True)
    play(table, sink)
    np.testing.assert_array_equal(sink.recorded, table.positions)
    np.testing.assert_allclose(sink.laser_power, table.power, rtol=1e-6, atol=1e-6)  # the sampler prints decimals
    np.testing.assert_array_equal(sink.laser_on, table.power > 0)
    pso = table.events[table.events["kind"] == EventKind.PSO_PULSE]["tick"]
    assert pso.size > 30
    np.testing.assert_array_equal(np.flatnonzero(sink.laser_pulse), pso)  # one tick each, on its tick
