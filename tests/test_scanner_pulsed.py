"""A pulsed point job on a galvo scanner (issue 18): the pulses as timed marks in the lists; every pulse inside its
window, every point burned once, the beam within a quarter discrete of its point at its pulse."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxcnc.format import EventKind, TableFile
from jaxcnc.format.vectors import VectorHeader
from jaxcnc.io.points import read_points
from jaxcnc.jobs import plan_file
from jaxcnc.machine import load_machine
from jaxcnc.scanner.compile import compile_pulsed
from jaxcnc.scanner.emulator import emulate
from jaxcnc.scanner.head import HeadModel
from jaxcnc.ticks.verify_pulses import check_pulses
from tests.conftest import GALVO_PATH, GALVO_XY

MACHINE = (
    GALVO_XY.replace('name = "galvo"', 'name = "galvo-pulsed"')
    + """[axes.z]
v_max = 100.0
a_max = 10000.0
min = -1.0
max = 1.0
"""
    + GALVO_PATH
    + """[laser]
mode = "pulsed"
pulse_hz = 1000.0
tolerance = 0.05
[galvo]
tracking_error_s = 150e-6
mirror_a_max_mm_s2 = 5e6
"""
)


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    d = tmp_path_factory.mktemp("pulsed")
    rng = np.random.default_rng(1)
    g = np.stack(np.meshgrid(np.arange(20) * 0.1, np.arange(10) * 0.12), -1).reshape(-1, 2)
    g += rng.uniform(-0.02, 0.02, g.shape)  # off the discrete grid
    (d / "pts.xyz").write_text("".join(f"{x:.7f} {y:.7f} 0\n" for x, y in g))
    (d / "m.toml").write_text(MACHINE)
    plan_file(d / "pts.xyz", d / "m.toml", d / "pts.ticks")
    machine = load_machine(d / "m.toml")
    return TableFile(d / "pts.ticks"), machine, read_points(d / "pts.xyz")


def test_pulsed_points_on_a_scanner_as_timed_marks(job):
    table, machine, pts = job
    assert check_pulses(table, machine, pts).ok  # the table itself (planner-independent check)
    h = table.header
    header = VectorHeader(h.tick_hz, h.discrete_mm, tuple(h.axes))
    head = HeadModel.from_machine(machine)
    pos, fine = np.asarray(table.positions), np.asarray(table.fine)
    n_min = math.ceil(h.tick_hz / machine.laser.pulse_hz * (1 - machine.laser.tolerance))
    n_max = math.floor(h.tick_hz / machine.laser.pulse_hz * (1 + machine.laser.tolerance))
    quarter = 0.25 * h.discrete_mm
    figures = {}
    for name, model in (("compensated", head), ("plain", None)):
        rec, lh = compile_pulsed(pos, fine, table.events, model, header)
        em = emulate(rec, lh, head, load_s=None)
        assert em.commanded.shape[0] == table.n_rows
        iv = np.diff(np.sort(em.pulses["tick"]))
        assert n_min <= iv.min() and iv.max() <= n_max  # every pulse (work and idle) inside its window
        work = em.pulses[em.pulses["kind"] == EventKind.WORK_PULSE]
        assert np.array_equal(np.sort(work["aux"]), np.arange(len(pts.points)))  # every point burned once
        target = pts.points[work["aux"]]
        figures[name] = {
            "commanded_miss_disc": float(np.abs(em.positions[work["tick"], :3] * lh.discrete_mm - target).max())
            / h.discrete_mm,
            "actual_miss_disc": float(np.abs(em.actual[work["tick"]] - target[:, :2]).max()) / h.discrete_mm,
        }
        if model is None:  # the board's command at each pulse: the table's unquantised path
            assert figures[name]["commanded_miss_disc"] * h.discrete_mm <= quarter
    print(figures)
    comp, plain = figures["compensated"], figures["plain"]
    assert comp["actual_miss_disc"] <= 0.25  # the mirrors, lag and all, on the point at its pulse
    assert plain["actual_miss_disc"] > 20 * comp["actual_miss_disc"]  # uncompensated: the lag τ·v
