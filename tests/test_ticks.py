"""Ticks: quantisation from exact positions, rest points on the grid, events, verification."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.format import FINE_SCALE, EventKind, TableWriter
from jaxcnc.ticks.sample import TickSampler
from jaxcnc.ticks.verify import measure_table
from tests.conftest import make_machine
from tests.helpers import table_of

PROGRAM = """\
G21 G90 F1200 S300
G0 X1.0004 Y2.0006
M3
G4 P0.25
G1 X20.5 Y2.0006
S600
G2 X30.5 Y12.0006 I0 J10
G1 Y30
M5
M1
G0 X0 Y0
M30
"""


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    return table_of(PROGRAM, make_machine(), tmp_path_factory.mktemp("t"))


def test_positions_are_rounded_exact_positions(planned):
    job, table, meas = planned
    assert meas.ok, meas.violations
    sampler = TickSampler(job, chunk=4096)
    q = job.machine.discrete_mm
    for first in (0, 4096 * 3, table.n_rows - 100):
        count = min(4096, table.n_rows - first)
        p, _ = sampler.program_positions(first, count)
        exact = sampler.machine_positions(p)
        np.testing.assert_array_equal(table.positions[first : first + count], np.round(exact / q))
        # the quantisation error is at most half a discrete; the fine channel recovers the rest
        assert np.all(np.abs(table.positions_mm(first, first + count) - exact) <= q / 2 + 1e-12)
        np.testing.assert_allclose(table.exact_mm(first, first + count), exact, atol=1e-12)


def test_start_end_and_rest_points_are_exact(planned):
    job, table, _ = planned
    q = job.machine.discrete_mm
    np.testing.assert_array_equal(table.positions[0], [0, 0, 0])
    np.testing.assert_array_equal(table.positions[-1], [0, 0, 0])
    # the G0 ends at rest exactly on (1.0004, 2.0006) -> discretes (1000, 2001)
    g0_end = job.plan.group_tick[1]
    np.testing.assert_array_equal(table.positions[g0_end], np.round(np.array([1.0004, 2.0006, 0]) / q))
    assert table.fine[g0_end, 0] == round((1.0004 / q - 1000) * FINE_SCALE)


def test_events(planned):
    job, table, _ = planned
    ev = table.events
    f = job.machine.tick_hz
    kinds = [int(k) for k in ev["kind"]]
    blocks = ev[ev["kind"] == EventKind.BLOCK]
    assert list(blocks["aux"]) == [2, 4, 5, 7, 8, 10, 11, 12]  # source lines of the blocks with spans
    laser = ev[ev["kind"] == EventKind.LASER]
    # on for the pierce dwell at S300, up to S600 on the arc, off at M5 — rapids are dark
    assert list(laser["value"]) == [300.0, 600.0, 0.0]
    assert list(laser["aux"]) == [3, 3, 0]
    dwell = ev[ev["kind"] == EventKind.DWELL]
    assert dwell["value"][0] == 0.25
    # the dwell holds the position for its whole duration
    t = int(dwell["tick"][0])
    held = table.positions[t : t + int(0.25 * f) + 1]
    assert np.all(held == held[0])
    assert laser["tick"][0] == t  # the beam comes on at the dwell (pierce)
    assert EventKind.OPTIONAL_STOP in kinds
    end = ev[ev["kind"] == EventKind.PROGRAM_END]
    assert end["tick"][0] == table.n_rows - 1
    assert np.all(np.diff(ev["tick"]) >= 0)


def test_verify_flags_each_limit_with_tick_axis_value(tmp_path):
    # a hand-made table: x jumps at tick 50 (speed and acceleration spike), y leaves its travel
    n = 200
    pos = np.zeros((n, 3), np.int32)
    pos[50:, 0] = 100  # 0.1 mm in one tick at 1 kHz = 100 mm/s
    pos[120:, 1] = 600_000  # 600 mm > travel 500 mm
    m = make_machine(tick_hz=1000)
    with TableWriter(tmp_path / "v.ticks", axes=["x", "y", "z"], tick_hz=1000, discrete_mm=0.001, n_rows=n) as w:
        w.write(pos, np.zeros_like(pos))
    from jaxcnc.format import TableFile

    meas = measure_table(TableFile(tmp_path / "v.ticks"), m)
    text = [str(v) for v in meas.violations]
    assert any(v.axis == "x" and v.quantity == "a" and v.first_tick == 50 for v in meas.violations), text
    assert any(v.axis == "y" and v.quantity == "v" and v.first_tick == 120 for v in meas.violations), text
    assert any(v.axis == "y" and v.quantity == "pos" and v.value == 600.0 for v in meas.violations), text
    assert meas.max_abs_v["x"] == pytest.approx(100.0)
    assert not any(v.axis == "x" and v.quantity == "v" for v in meas.violations)  # exactly at v_max: allowed
    assert all("limit" in t and "axis" in t and "tick" in t for t in text)


def test_verify_requires_rest_at_both_ends(tmp_path):
    n = 100
    pos = np.zeros((n, 3), np.int32)
    pos[:, 0] = np.arange(n) * 50  # moving at 50 mm/s from the first row to the last
    with TableWriter(tmp_path / "m.ticks", axes=["x", "y", "z"], tick_hz=1000, discrete_mm=0.001, n_rows=n) as w:
        w.write(pos, np.zeros_like(pos))
    from jaxcnc.format import TableFile

    meas = measure_table(TableFile(tmp_path / "m.ticks"), make_machine(tick_hz=1000))
    bad = {(v.first_tick, v.quantity) for v in meas.violations if v.axis == "x"}
    assert (1, "a") in bad and (n - 1, "a") in bad  # starting and stopping with a jump


def test_jobs_are_plain_picklable_data(planned, tmp_path):
    """Program, machine, spans and plan pickle (one job per process scales out unchanged)."""
    import pickle

    from jaxcnc.ticks.table import write_table

    job, table, _ = planned
    clone = pickle.loads(pickle.dumps(job))
    path = write_table(clone, tmp_path / "clone.ticks", progress=False)
    from jaxcnc.format import TableFile

    np.testing.assert_array_equal(TableFile(path).positions, table.positions)
