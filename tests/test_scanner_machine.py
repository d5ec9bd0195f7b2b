"""The ``[galvo]`` machine table (issue 18): a scanner-only machine's scan-head model, every key validated."""

from __future__ import annotations

import pytest

from jaxcnc.cli.main import main
from jaxcnc.errors import MachineFileError
from jaxcnc.machine import parse_machine
from jaxcnc.scanner.head import HeadModel
from tests.conftest import GALVO_PATH, GALVO_XY

BASE = GALVO_XY + GALVO_PATH
GALVO = (
    BASE
    + """[galvo]
tracking_error_s = 120e-6
mirror_a_max_mm_s2 = 4e6
damping = 0.8
"""
)


def test_galvo_table_builds_the_head_model():
    m = parse_machine(GALVO, "g.toml")
    assert m.galvo is not None and m.scanner is None
    head = HeadModel.from_machine(m)
    assert (head.tracking_error_s, head.damping, head.a_max_mm_s2) == (120e-6, 0.8, 4e6)
    d = parse_machine(GALVO.replace("damping = 0.8\n", ""), "g.toml")
    assert HeadModel.from_machine(d).damping == 1.0  # the documented default: critically damped


def test_a_machine_without_galvo_table_has_no_head():
    with pytest.raises(MachineFileError, match=r"g\.toml: \[galvo\] machine 'galvo' has no \[galvo\] table"):
        HeadModel.from_machine(parse_machine(BASE, "g.toml"))


@pytest.mark.parametrize(
    ("old", "new", "line", "message"),
    [
        ("damping = 0.8", "dampign = 0.8", 21, r"\[galvo.dampign\] unknown key 'dampign'; known keys here: "),
        ("damping = 0.8", "damping = 5.0", 21, r"\[galvo.damping\] 5.0: must lie in \[0.1, 2\]"),
        ("damping = 0.8", "damping = 0.0", 21, r"\[galvo.damping\] 0.0: must lie in \[0.1, 2\]"),
        ("tracking_error_s = 120e-6", "tracking_error_s = 150", 19, r"150 s is slower than any galvo"),
        ("tracking_error_s = 120e-6", "tracking_error_s = -1e-4", 19, r"must be a positive finite number"),
        ("tracking_error_s = 120e-6", "tracking_error_s = 1e-5", 19, r"shorter than two board ticks"),
        ("tracking_error_s = 120e-6", "tracking_error_s = '1e-4'", 19, r"expected a number, got '1e-4'"),
        ("mirror_a_max_mm_s2 = 4e6", "mirror_a_max_mm_s2 = 0", 20, r"must be a positive finite number"),
        ("mirror_a_max_mm_s2 = 4e6", "mirror_a_max_mm_s2 = 4e12", 20, r"beyond any galvo mirror"),
        ("mirror_a_max_mm_s2 = 4e6\n", "", 18, r"\[galvo\] missing required key 'mirror_a_max_mm_s2'"),
    ],
)
def test_galvo_key_errors_name_file_line_and_cause(old, new, line, message):
    with pytest.raises(MachineFileError, match=message) as info:
        parse_machine(GALVO.replace(old, new), "g.toml")
    assert info.value.line == line and str(info.value).startswith(f"g.toml:{line}: ")


def test_galvo_refuses_a_split_machine_and_non_beam_axes():
    split = GALVO + '[axes.u]\nv_max = 5000.0\na_max = 1e6\nmin = -25.0\nmax = 25.0\n[scanner]\naxes = ["u"]\n'
    split += "field_mm = [50.0]\nscale = [1.0]\noffset_mm = [0.0]\n"
    with pytest.raises(MachineFileError, match=r"g.toml:18: \[galvo\] \[galvo\] declares a scanner-only machine"):
        parse_machine(split, "g.toml")
    extra = GALVO + "[axes.a]\nv_max = 50.0\na_max = 100.0\nmin = -5.0\nmax = 5.0\n"
    with pytest.raises(MachineFileError, match=r"g.toml:22: \[axes.a\] a galvo machine drives x, y"):
        parse_machine(extra, "g.toml")


def test_plan_on_a_galvo_machine(tmp_path, capsys):
    """A scanner-only machine plans like any other (its table is the beam path the board executes); a bad
    [galvo] key is a one-line error with exit status 2."""
    m = tmp_path / "g.toml"
    m.write_text(GALVO)
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90\nG0 X0 Y0\nM3 S100\nG1 X5 Y0 F60000\nG1 X5 Y3\nM5\nM2\n")
    assert main(["plan", str(prog), "-m", str(m), "-o", str(tmp_path / "p.ticks"), "-q"]) == 0
    m.write_text(GALVO.replace("damping = 0.8", "damping = 9"))
    capsys.readouterr()
    assert main(["plan", str(prog), "-m", str(m), "-o", str(tmp_path / "q.ticks"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "g.toml:21: [galvo.damping] 9.0: must lie in [0.1, 2]" in err[0]


def test_galvo_delays_from_the_machine_file_override_the_model():
    from jaxcnc.scanner.compile import Settings, machine_settings

    text = GALVO + "laser_on_delay_s = 120e-6\njump_delay_s = 0.001\nsky_writing = 1\nrun_in_s = 50e-6\n"
    m = parse_machine(text, "g.toml")
    auto = Settings(laser_on=15, laser_off=15, jump=884, sky_mode=2, run_in=186, run_out=186, sky_limit_deg=2.0)
    s = machine_settings(m, auto)
    # given keys in seconds -> board ticks at 100 kHz; the others from the model's choice
    assert (s.laser_on, s.jump, s.sky_mode, s.run_in) == (12, 100, 1, 5)
    assert (s.laser_off, s.run_out, s.sky_limit_deg) == (15, 186, 2.0)
    assert machine_settings(parse_machine(GALVO, "g.toml"), auto) == auto


@pytest.mark.parametrize(
    ("key", "message"),
    [
        ("jump_delay_s = 5", r"\[galvo.jump_delay_s\] 5.0: must lie in \[0, 0.1\] s"),
        ("mark_delay_s = -1e-4", r"\[galvo.mark_delay_s\] -0.0001: must lie in \[0, 0.1\] s"),
        ("laser_off_delay_s = 200", r"must lie in \[-0.01, 0.1\] s"),
        ("sky_writing = 3", r"\[galvo.sky_writing\] 3.0: sky-writing mode is 0 \(off\), 1"),
        ("sky_limit_deg = 270", r"\[galvo.sky_limit_deg\] 270.0: must lie in \[0, 180\] degrees"),
        ("variable_polygon = 1", r"\[galvo.variable_polygon\] expected true or false"),
        ("run_in_ticks = 5", r"\[galvo.run_in_ticks\] unknown key 'run_in_ticks'"),
    ],
)
def test_galvo_delay_key_errors_name_file_line_and_cause(key, message):
    with pytest.raises(MachineFileError, match=message) as info:
        parse_machine(GALVO + key + "\n", "g.toml")
    assert info.value.line == 22 and str(info.value).startswith("g.toml:22: ")
