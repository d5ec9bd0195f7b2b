"""The external motion module (issue 18): one G-code program cuts on the stage, marks on the galvo scanner
(M170 ... M171), cuts again; one table carries both groups, the stage waits while the scanner marks."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.errors import JaxcncError, MachineFileError, SourceError
from jaxcnc.format import EventKind, TableFile
from jaxcnc.format.vectors import execute
from jaxcnc.gcode import parse_gcode
from jaxcnc.jobs import check_table, load_program, plan_file
from jaxcnc.machine import parse_machine
from jaxcnc.program import Event, Kind
from jaxcnc.ticks.external import check_external, scanner_lists, sections_of

STAGE_GALVO = """[machine]
name = "stage-galvo"
tick_hz = 100000
discrete_mm = 0.001
[axes.x]
v_max = 500.0
a_max = 5000.0
min = -100.0
max = 100.0
[axes.y]
v_max = 500.0
a_max = 5000.0
min = -100.0
max = 100.0
[axes.u]
v_max = 5000.0
a_max = 2000000.0
min = -20.0
max = 20.0
[axes.v]
v_max = 5000.0
a_max = 2000000.0
min = -20.0
max = 20.0
[path]
feed = 100.0
rapid = 400.0
corner_tol_mm = 0.0
[galvo]
axes = ["u", "v"]
tracking_error_s = 150e-6
mirror_a_max_mm_s2 = 5e6
"""

# cut on the stage, mark a square with a round end on the scanner (1 m/s), cut again
PROGRAM = """G21 G90
G0 X10 Y0
M3 S500
G1 X30 Y0 F6000
M5
M170
G0 X32 Y2
M3 S800
G1 X38 Y2 F60000
G1 X38 Y8
G2 X32 Y8 I-3 J0
G1 X32 Y2
M5
M171
G0 X30 Y20
M3 S500
G1 X10 Y20 F6000
M5
M2
"""


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    d = tmp_path_factory.mktemp("external")
    (d / "m.toml").write_text(STAGE_GALVO)
    (d / "p.ngc").write_text(PROGRAM)
    report = plan_file(d / "p.ngc", d / "m.toml", d / "p.ticks")
    m = parse_machine(STAGE_GALVO, str(d / "m.toml"))
    return d, m, report, TableFile(d / "p.ticks")


def test_cut_mark_cut_one_table_both_groups(planned):
    d, m, report, t = planned
    assert report["violations"] == [] and t.axes == ["x", "y", "u", "v"]
    assert [s[0] for s in report["sections"]] == [0, 1, 0]
    pos, power = np.asarray(t.positions), np.asarray(t.power)
    (_, a0, b0), (_, a1, b1), (_, a2, b2) = report["sections"]
    assert a1 == b0 and a2 == b1 and b2 == t.n_rows - 1 and a0 == 0
    # the stage is at rest (bit for bit) while the scanner marks, where the first cut ended: (30, 0) mm
    assert np.all(pos[a1 : b1 + 1, :2] == [30000, 0])
    # the beam stays at the field's centre while the stage moves, and moves while the stage waits
    assert np.all(pos[a0 : b0 + 1, 2:] == 0) and np.all(pos[a2 : b2 + 1, 2:] == 0)
    assert np.abs(pos[a1 : b1 + 1, 2:]).max() == 8000  # the mark reaches (38, 8) = stage (30, 0) + beam (8, 8)
    # the laser burns in all three sections, at the power of each
    for (_, a, b), s in zip(report["sections"], (500, 800, 500), strict=True):
        assert power[a : b + 1].max() == s
    # the scanner marks at 1 m/s (its own limits), the stage cuts at 100 mm/s
    dp = np.diff(np.asarray(t.exact_mm(0, t.n_rows)), axis=0) * 1e5
    v = np.c_[np.hypot(dp[:, 0], dp[:, 1]), np.hypot(dp[:, 2], dp[:, 3])]  # stage, beam speed (mm/s)
    lit = power[1:] > 0
    assert 999 < v[a1:b1, 1][lit[a1:b1]].max() < 1000 + 1e-6 and 99 < v[a0:b0, 0][lit[a0:b0]].max() < 100 + 1e-6
    # the tool point (stage + beam) follows the program at every tick
    assert report["max_path_deviation_mm"] < 1e-9
    blocks = t.events[t.events["kind"] == EventKind.BLOCK]
    prog = load_program(d / "p.ngc", m)
    assert set(prog.line[blocks["value"].astype(int)]) >= {2, 4, 7, 9, 10, 11, 12, 15, 17}
    tab, meas = check_table(d / "p.ticks", d / "m.toml")
    assert meas.violations == [] and "stage still while the scanner runs" in meas.path_summary


def test_the_scanner_list_runs_its_section_tick_for_tick(planned):
    _, m, report, t = planned
    (lst,) = scanner_lists(t, m)
    a, b, rec, h = lst
    ex = execute(rec, h)
    pos = np.asarray(t.positions)[a : b + 1, 2:]
    assert np.array_equal(ex.positions[:, :2], pos) and np.array_equal(ex.power, np.asarray(t.power)[a : b + 1])
    assert len(rec) < (b - a) / 4  # vectors, not ticks


def test_check_finds_a_stage_that_moves_while_the_scanner_marks(planned):
    d, m, report, t = planned
    prog = load_program(d / "p.ngc", m)
    (_, a1, b1) = report["sections"][1]
    t.header.meta["external"][1][1] = a1 - 100  # claim the scanner section started while the stage still moved
    chk = check_external(t, m, prog)
    assert chk.max_stage_motion_in_scanner_mm > 0 and any("stage moves" in v for v in chk.violations)


def test_sections_and_hand_over_in_the_program():
    p = parse_gcode(PROGRAM, "p.ngc", external=True)
    ext = np.flatnonzero(p.event == Event.EXTERNAL)
    assert p.line[ext].tolist() == [6, 14] and p.event_value[ext].tolist() == [1, 0]
    back = ext[1] - 1  # M171: the beam returns (dark, rapid) to the centre: where the stage waits
    assert p.kind[back] == Kind.LINE and p.rapid[back] and p.end[back].tolist() == [30.0, 0.0, 0.0]
    assert [s.scanner for s in sections_of(p)] == [False, True, False]


@pytest.mark.parametrize(
    ("text", "external", "message"),
    [
        ("G0 X1\nM170\nG1 X2 F100\nM171\n", False, r"p\.ngc:2:1: M170 switches motion to a galvo scanner"),
        ("G0 X1\nM171\n", True, r"p\.ngc:2:1: M171 without M170"),
        ("M170\nG1 X2 F100\nM170\n", True, r"p\.ngc:3:1: M170: motion is on the scanner already \(since line 1\)"),
        ("M170\nG1 X2 F100\n", True, r"p\.ngc:1: M170 hands motion to the scanner; no M171 follows"),
        ("G1 X2 F100 M170\nM171\n", True, r"p\.ngc:1:12: M170 stands in a block without motion"),
        ("M172\n", True, r"p\.ngc:1:1: M172 runs a user-defined program"),
    ],
)
def test_switch_errors_name_file_line_and_cause(text, external, message):
    with pytest.raises(SourceError, match=message):
        parse_gcode(text, "p.ngc", external=external)


def test_a_scanner_section_refuses_focus_moves(tmp_path):
    (tmp_path / "m.toml").write_text(STAGE_GALVO + "[axes.z]\nv_max = 50.0\na_max = 500.0\nmin = -10.0\nmax = 10.0\n")
    (tmp_path / "z.ngc").write_text("G0 X1\nM170\nG1 X2 Z1 F100\nM171\nM2\n")
    with pytest.raises(SourceError, match=r"z\.ngc:3: moves Z: a scanner section marks in the plane"):
        plan_file(tmp_path / "z.ngc", tmp_path / "m.toml", tmp_path / "z.ticks")
    with pytest.raises(JaxcncError, match="not a split"):
        plan_file(tmp_path / "z.ngc", tmp_path / "m.toml", tmp_path / "z.ticks", split="own")


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('axes = ["u", "v"]', 'axes = ["u"]', r"\[galvo.axes\] \['u'\]: names the two beam axes"),
        ('axes = ["u", "v"]', 'axes = ["x", "v"]', r"\[galvo.axes\] 'x' is a stage axis"),
        ('axes = ["u", "v"]', 'axes = ["u", "w"]', r"\[galvo.axes\] beam axis 'w' has no \[axes.w\] table"),
        ("min = -20.0\nmax = 20.0\n[axes.v]", "min = 0.0\nmax = 20.0\n[axes.v]", r"\[axes.u.home\] a beam axis"),
    ],
)
def test_stage_galvo_machine_errors(old, new, message):
    with pytest.raises(MachineFileError, match=message):
        parse_machine(STAGE_GALVO.replace(old, new), "m.toml")
