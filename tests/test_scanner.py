"""Galvo scanner lists (issue 18): plans compiled into lists, the emulator reproducing the table tick for tick,
underruns switching the laser off, delays and sky-writing chosen from the head model on a marking job."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.format import TableFile
from jaxcnc.format.vectors import Op, VectorHeader, make, records
from jaxcnc.jobs import plan_file
from jaxcnc.scanner.compile import NO_DELAYS, auto_settings, compile_board, compile_exact, lit_runs
from jaxcnc.scanner.emulator import emulate, write_table
from jaxcnc.scanner.head import HeadModel
from jaxcnc.scanner.metrics import burn_figures
from tests.conftest import GALVO_PATH, GALVO_XY

GALVO = GALVO_XY + GALVO_PATH + "corner_tol_mm = 0.0\n"

# a "Z" with 30-degree corners, a zigzag of 0.4 mm segments and a triangle with a 20-degree tip
MARKING = """G21 G90
G0 X0 Y0
M3 S1000
G1 X8 Y0 F60000
G1 X0.5 Y6
G1 X8 Y6
M5
G0 X10 Y0
M3 S1000
G1 X10.2 Y0.4
G1 X10.4 Y0
G1 X10.6 Y0.4
G1 X10.8 Y0
G1 X11.0 Y0.4
G1 X11.2 Y0
G1 X11.4 Y0.4
G1 X11.6 Y0
M5
G0 X14 Y0
M3 S1000
G1 X20 Y1
G1 X14 Y2.06
G1 X14 Y0
M5
M2
"""
H = VectorHeader(100000.0, 0.001)


@pytest.fixture(scope="module")
def marking(tmp_path_factory):
    d = tmp_path_factory.mktemp("scanner")
    (d / "galvo.toml").write_text(GALVO)
    (d / "marking.ngc").write_text(MARKING)
    plan_file(d / "marking.ngc", d / "galvo.toml", d / "marking.ticks")
    t = TableFile(d / "marking.ticks")
    return d, np.asarray(t.positions), np.asarray(t.power), t.events


def test_exact_list_reproduces_the_table_tick_for_tick(marking):
    d, pos, power, events = marking
    rec = compile_exact(pos, power, events)
    em = emulate(rec, H, load_s=None)
    assert np.array_equal(em.positions[:, :2], pos) and np.array_equal(em.power, power)
    assert len(rec) < pos.shape[0] / 2  # vectors, not ticks
    write_table(em, H, d / "emulated.ticks")
    t = TableFile(d / "emulated.ticks")
    assert t.axes == ["x", "y", "xa", "ya"] and np.array_equal(np.asarray(t.positions)[:, :2], pos)


def test_underrun_turns_the_laser_off_and_holds_the_beam():
    lst = [
        make(Op.LIST_START),
        make(Op.SET_MARK_SPEED, value=1000.0),
        make(Op.SET_LASER, value=5.0),
        make(Op.MARK_ABS, pos=(1000, 0)),
        make(Op.LIST_END),
        make(Op.LIST_START, pos=(1000, 0)),
        *[make(Op.MARK_ABS, pos=(1000 + 10 * (k % 2), 10 * k)) for k in range(1, 400)],
        make(Op.LIST_END),
    ]
    rec = records(lst)
    slow = emulate(rec, H, load_s=lambda n: n * 5e-6)  # list 2 (400 records) loads in 2 ms; list 1 runs 1 ms
    fast = emulate(rec, H, load_s=None)
    gap = slow.underrun
    assert gap.sum() > 0 and slow.commanded.shape[0] == fast.commanded.shape[0] + gap.sum()
    assert np.all(slow.power[gap] == 0)
    held = slow.positions[gap]
    assert np.all(held == held[0]) and np.array_equal(held[0, :2], [1000, 0])
    assert np.array_equal(slow.positions[~gap], fast.positions)  # otherwise the same execution


def test_marking_job_delays_and_sky_writing_from_the_model(marking):
    """Must show: automatic delays + sky-writing burn within 10 um and 1.2x corner dose; a naive list does not."""
    d, pos, power, events = marking
    head = HeadModel(tracking_error_s=150e-6, damping=1.0, a_max_mm_s2=5e6)
    runs = lit_runs(pos, power, H.discrete_mm, H.dt)
    assert len(runs.paths) == 3
    v = 1000.0
    figs = {}
    for name, sky in (("auto", True), ("none", None)):
        s = auto_settings(head, v, H.dt, H.discrete_mm, 0.01, sky=True, jump_speed_mm_s=5000.0) if sky else NO_DELAYS
        rec = compile_board(runs, H, s, 5000.0, start_mm=pos[0, :2] * H.discrete_mm, mark_speed_mm_s=v)
        em = emulate(rec, H, head)
        figs[name] = burn_figures(runs.paths, [v] * 3, em.actual, em.power, H.dt)
    auto, none = figs["auto"], figs["none"]
    print("auto", auto, "\nnone", none)
    assert auto["max_deviation_mm"] <= 0.010
    assert auto["corner_dose_max"] <= 1.2 and auto["end_dose_max"] <= 1.2
    assert 0.95 <= auto["straight_dose_median"] <= 1.05
    assert none["max_deviation_mm"] > 3 * auto["max_deviation_mm"]
    assert none["corner_dose_max"] > 1.5
