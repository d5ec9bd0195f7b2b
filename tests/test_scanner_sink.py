"""The ``scanner`` sink (issue 18): the rows it is given encoded into vector lists, sent as checked bytes and
executed by the emulated board; what it plays equals the table tick for tick (positions, laser, pulses)."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.format import EventKind, TableFile, TableWriter
from jaxcnc.hw.player import play
from jaxcnc.hw.sinks import open_sink
from jaxcnc.hw.sinks.scanner import ScannerSink
from jaxcnc.jobs import plan_file
from tests.conftest import GALVO_PATH, GALVO_XY

GALVO = (
    GALVO_XY
    + GALVO_PATH
    + """corner_tol_mm = 0.0
[galvo]
tracking_error_s = 150e-6
mirror_a_max_mm_s2 = 5e6
"""
)
# corners, short segments, arcs, two power levels, dark jumps
JOB = """G21 G90
G0 X0 Y0
M3 S1000
G1 X8 Y0 F60000
G1 X0.5 Y6
G1 X8 Y6
M5
G0 X10 Y0
M3 S400
G1 X10.2 Y0.4
G1 X10.4 Y0
G1 X10.6 Y0.4
G2 X12.6 Y0.4 I1 J0
G3 X14.6 Y0.4 I1 J0
M5
G0 X-5 Y-5
M2
"""


@pytest.fixture(scope="module")
def marking(tmp_path_factory):
    d = tmp_path_factory.mktemp("sink")
    (d / "galvo.toml").write_text(GALVO)
    (d / "job.ngc").write_text(JOB)
    plan_file(d / "job.ngc", d / "galvo.toml", d / "job.ticks")
    return TableFile(d / "job.ticks")


@pytest.mark.parametrize("list_rows", [997, 8192, 1 << 20])
def test_played_lists_equal_the_table_tick_for_tick(marking, list_rows):
    t = marking
    pos, power = np.asarray(t.positions), np.asarray(t.power)
    assert (power > 0).any() and len(set(power[power > 0].tolist())) == 2  # two laser powers in the job
    sink = ScannerSink(list_rows=list_rows)
    result = play(t, sink, chunk_rows=300)
    assert result.executed_tick == t.n_rows - 1
    np.testing.assert_array_equal(sink.recorded, pos)
    np.testing.assert_array_equal(sink.recorded_power, power)
    assert sink.lists_run == -(-t.n_rows // list_rows)
    assert sink.records_sent < t.n_rows / 2  # vectors, not ticks
    assert sink.bytes_sent > 40 * sink.records_sent


def test_power_given_per_row_is_played_as_given(marking):
    """A player that passes each row's power (an M4-like ramp here): the lists carry it exactly."""
    t = marking
    pos = np.asarray(t.positions)
    power = np.where(np.asarray(t.power) > 0, 1.0 + (np.arange(t.n_rows) % 7) * 0.125, 0.0).astype(np.float32)
    sink = ScannerSink(list_rows=1500)
    sink.open(t.header)
    none = np.zeros(0, t.events.dtype)
    for a in range(0, t.n_rows, 400):  # the player's loop: write while there is room, else let the board run
        b = min(a + 400, t.n_rows)
        while a < b:
            if sink.free_rows() == 0:
                sink.wait()
                continue
            k = min(sink.free_rows(), b - a)
            sink.write(a, pos[a : a + k], none, power[a : a + k])
            a += k
    sink.close()
    np.testing.assert_array_equal(sink.recorded, pos)
    np.testing.assert_array_equal(sink.recorded_power, power)


def test_pulses_travel_in_the_lists(tmp_path):
    n = 5000
    rng = np.random.default_rng(3)
    pos = np.cumsum(rng.integers(-2, 3, (n, 2)), axis=0).astype(np.int32)
    ticks = np.sort(rng.choice(np.arange(1, n), 40, replace=False))
    from jaxcnc.format import EVENT_DTYPE

    ev = np.zeros(ticks.size, EVENT_DTYPE)
    ev["tick"], ev["kind"], ev["aux"], ev["value"] = ticks, EventKind.WORK_PULSE, np.arange(ticks.size), 2.5
    ev["kind"][::5] = EventKind.IDLE_PULSE
    with TableWriter(tmp_path / "p.ticks", axes=["x", "y"], tick_hz=100_000, discrete_mm=0.001, n_rows=n) as w:
        w.write(pos, np.zeros_like(pos))
        w.events = ev
    t = TableFile(tmp_path / "p.ticks")
    sink = ScannerSink(list_rows=777)
    play(t, sink, chunk_rows=250)
    np.testing.assert_array_equal(sink.recorded, pos)
    got = sink.recorded_pulses
    np.testing.assert_array_equal(got["tick"], ticks)
    np.testing.assert_array_equal(got["kind"], ev["kind"])
    work = ev["kind"] == EventKind.WORK_PULSE
    np.testing.assert_array_equal(got["aux"][work], ev["aux"][work])


def test_a_list_that_would_not_reproduce_its_rows_is_refused(marking, monkeypatch):
    import jaxcnc.hw.sinks.scanner as mod

    real = mod.encode_rows

    def lossy(rows, power, pulses=None):  # drop one vector from every list: the execution comes out short
        rec = real(rows, power, pulses)
        return np.concatenate([rec[:2], rec[3:]])

    monkeypatch.setattr(mod, "encode_rows", lossy)
    with pytest.raises(RuntimeError, match=r"scanner list 1: the encoded list does not reproduce row"):
        play(marking, ScannerSink(list_rows=2000), chunk_rows=500)


def test_too_many_axes_is_a_clean_error(tmp_path):
    from jaxcnc.errors import JaxcncError

    with TableWriter(tmp_path / "a.ticks", axes=["x", "y", "z", "a"], tick_hz=1000, discrete_mm=0.001, n_rows=2) as w:
        w.write(np.zeros((2, 4), np.int32), np.zeros((2, 4), np.int32))
    with pytest.raises(JaxcncError, match="at most 3 axes"):
        open_sink("scanner").open(TableFile(tmp_path / "a.ticks").header)
