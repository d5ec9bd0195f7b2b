"""HP-GL plot files as Programs: the instructions, plotter units, errors naming the line, fuzz."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.errors import SourceError
from jaxcnc.io.drawing import DrawingOptions, assemble
from jaxcnc.io.hpgl import parse_hpgl, read_hpgl
from jaxcnc.program import Kind, LaserMode
from tests.conftest import machine_text

START = np.zeros(3)
PART = """IN;SP1;
PU0,0;PD4000,0,4000,2000,0,2000,0,0;
PU1000,800;PD;PR0,400,400,0;PR0,-400,-400,0;PU;
PA;PU3000,1000;PD3200,1000 3200 1200;PD3000,1200,3000,1000;
SP0;PD0,0,100,100;
"""


def test_part_in_plotter_units_cut_inner_first(tmp_path):
    p = tmp_path / "part.plt"
    p.write_text(PART)
    d = read_hpgl(p, START)
    assert len(d.contours) == 3 and [c.depth for c in d.contours] == [1, 1, 0]
    outer = d.contours[-1].poly
    assert np.ptp(outer[:, 0]) == pytest.approx(100.0) and np.ptp(outer[:, 1]) == pytest.approx(50.0)  # 40/mm
    hole = np.concatenate([c.poly for c in d.contours[:2]])
    assert hole.min(axis=0) == pytest.approx([25.0, 20.0])  # PR relative moves from (1000, 800) units
    prog = d.program
    assert np.all(prog.kind == Kind.LINE) and np.all(prog.end[:-1] == prog.start[1:])
    assert np.all(prog.laser[~prog.rapid] == LaserMode.CONSTANT)
    assert 3 <= len(set(prog.line[~prog.rapid].tolist())) <= 5  # rows carry their source lines


@pytest.mark.parametrize(
    ("text", "where", "what"),
    [
        ("IN;\nPD10,10,20;", 2, "x,y pairs"),
        ("IN;\nSP1;\nCI50;", 3, "CI: instruction not supported"),
        ("IN;PD999999999999,0;", 1, "beyond"),
        ("IN;\n\nPD10,1.2.3;", 3, "must be numbers"),
        ("IN;\n5,5;", 2, "unexpected '5'"),
        ("IN;PD400,0;PD400,400;", 1, "open contour"),
    ],
)
def test_errors_name_the_line(text, where, what):
    with pytest.raises(SourceError) as exc:
        assemble(parse_hpgl(text, "x.plt"), DrawingOptions(), START, "x.plt")
    assert str(exc.value).startswith(f"x.plt:{where}:") and what in str(exc.value)


def test_open_contours_when_engraving():
    d = assemble(parse_hpgl("IN;PD400,0;PD400,400;", "x.plt"), DrawingOptions(allow_open=True), START, "x.plt")
    assert len(d.contours) == 1 and not d.contours[0].closed


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet="INSPUDARC0123456789,;.- \n\x1be", max_size=80), st.booleans())
def test_fuzz_text_is_read_or_refused_with_its_line(text, allow_open):
    try:
        assemble(parse_hpgl(text, "f.plt"), DrawingOptions(allow_open=allow_open), START, "f.plt")
    except SourceError as exc:
        msg = str(exc)
        assert msg.startswith("f.plt") and "\n" not in msg


def test_cli_plans_a_plot_file(tmp_path):
    from jaxcnc.cli.main import main

    machine = tmp_path / "m.toml"
    machine.write_text(machine_text(tick_hz=1000, v=200.0, a=2000.0, rapid=200.0))
    part = tmp_path / "part.plt"
    part.write_text(PART)
    table = tmp_path / "part.ticks"
    assert main(["plan", str(part), "-m", str(machine), "-o", str(table), "-q"]) == 0
    assert main(["check", str(table), "-m", str(machine)]) == 0
