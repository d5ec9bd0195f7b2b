"""PSO: a pulse every pso_mm of lit path, as tick events, through accelerations and corners."""

from __future__ import annotations

import numpy as np

from jaxcnc.format import EventKind
from jaxcnc.machine import parse_machine
from tests.conftest import machine_text
from tests.helpers import table_of

PROGRAM = """G0 X0 Y0
M3 S100
G1 X10 F3000
G3 X20 Y0 I5 J0
G1 Y-7.3
M5
G0 X30 Y0
M3 S100
G1 X33.3
M5
M2
"""


def test_pso_pulses_are_pso_mm_apart_along_the_path(tmp_path):
    m = parse_machine(machine_text() + '[laser]\nmode = "pso"\npso_mm = 0.25\n', "pso.toml")
    job, table, meas = table_of(PROGRAM, m, tmp_path)
    assert meas.ok
    ev = table.events[table.events["kind"] == EventKind.PSO_PULSE]
    run_len = (10 + np.pi * 5 + 7.3, 3.3)
    expected = sum(int(np.floor(L / 0.25 + 1e-9)) + 1 for L in run_len)
    assert ev.shape[0] == expected
    # independent: path length walked on the table itself (exact positions), tick by tick
    p = table.exact_mm()[:, :2]
    s_tick = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    starts = np.flatnonzero(ev["value"] == 0.0)
    assert starts.size == 2
    run = np.cumsum(np.isin(np.arange(ev.shape[0]), starts)) - 1
    walked = s_tick[ev["tick"]] - s_tick[ev["tick"][starts]][run]
    v_max = 50.0  # the test machine's feed cap: a tick moves at most v dt, rounding to a tick half that
    assert np.max(np.abs(walked - ev["value"])) <= v_max / m.tick_hz / 2 + 1e-6
    assert np.all(np.diff(ev["tick"]) > 0)


def test_no_pso_events_on_cw_machines(tmp_path):
    m = parse_machine(machine_text(), "cw.toml")
    _, table, _ = table_of(PROGRAM, m, tmp_path)
    assert not np.any(table.events["kind"] == EventKind.PSO_PULSE)
