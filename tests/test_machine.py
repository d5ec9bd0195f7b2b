"""Machine files: valid ones load into an immutable config; every mistake names file, key, line."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import pytest

from jaxcnc.errors import MachineFileError
from jaxcnc.machine import load_machine, parse_machine
from tests.conftest import EXAMPLE_MACHINE, machine_text


def test_example_machine_loads():
    m = load_machine(EXAMPLE_MACHINE)
    assert m.name == "laser-cutter"
    assert m.axis_names == ("x", "y", "z")
    assert m.tick_hz == 10000 and m.discrete_mm == 0.001
    assert m.axis("x").v_max == 250.0 and m.axis("y").a_max == 4000.0
    assert m.axis("x").j_max is None
    assert m.path.rapid == 250.0 and m.path.corner_tol_mm == 0.01
    assert m.laser.mode == "cw"


def test_corner_tolerance_defaults_to_a_bounded_blend_and_zero_keeps_corners_exact():
    from jaxcnc.machine import DEFAULT_CORNER_TOL_MM

    unset = machine_text().replace("corner_tol_mm = 0.0\n", "")
    assert "corner_tol_mm" not in unset
    assert parse_machine(unset).path.corner_tol_mm == DEFAULT_CORNER_TOL_MM == 0.01
    assert parse_machine(machine_text()).path.corner_tol_mm == 0.0


def test_config_is_immutable():
    m = parse_machine(machine_text())
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.tick_hz = 5  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.axes[0].v_max = 1  # type: ignore[misc]


def test_defaults_and_home():
    m = parse_machine(machine_text())
    assert m.path.chord_tol_mm == 0.001
    assert m.axis("x").home == 0.0
    text = machine_text().replace("min = -500.0\nmax = 500.0\n\n[axes.y]", "min = 10.0\nmax = 500.0\n\n[axes.y]")
    assert parse_machine(text).axis("x").home == 10.0  # 0 is outside the travel: home defaults to min


def _err(text: str) -> MachineFileError:
    with pytest.raises(MachineFileError) as info:
        parse_machine(text, "bad.toml")
    return info.value


def _line_of(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), 1) if needle in line)


@pytest.mark.parametrize(
    ("old", "new", "key", "reason"),
    [
        ("tick_hz = 10000", "tick_hz = 10000\nspeed = 3", "machine.speed", "unknown key"),
        ("a_max = 1000", "a_max = 0", "axes.x.a_max", "positive"),
        ("a_max = 1000", "a_max = -5", "axes.x.a_max", "positive"),
        ("v_max = 100", 'v_max = "fast"', "axes.x.v_max", "expected a number"),
        ("v_max = 100", "v_max = true", "axes.x.v_max", "expected a number"),
        ("min = -500.0", "min = 600.0", "axes.x.min", "must be below max"),
        ("v_max = 100", "v_max = 6000000", "axes.x.v_max", "mm/min"),
        ("discrete_mm = 0.001", "discrete_mm = 1", "machine.discrete_mm", "did you mean"),
        ("chord_tol_mm = 0.001", "chord_tol_mm = -0.001", "path.chord_tol_mm", "positive"),
        ("rapid = 100", "rapid = 0", "path.rapid", "positive"),
        ("corner_tol_mm = 0.0", 'corner_tol_mm = "none"', "path.corner_tol_mm", "expected a number"),
    ],
)
def test_each_mistake_is_named(old, new, key, reason):
    text = machine_text().replace(old, new, 1)
    assert text != machine_text()
    e = _err(text)
    assert e.file == "bad.toml"
    assert e.key == key
    assert reason in e.reason
    assert e.line == _line_of(text, new.splitlines()[-1])
    assert str(e).startswith(f"bad.toml:{e.line}: [{key}]")


def test_missing_axis():
    text = machine_text()
    start = text.index("[axes.y]")
    end = text.index("[axes.z]")
    e = _err(text[:start] + text[end:])
    assert e.key == "axes.y" and "missing axis" in e.reason


def test_unknown_axis_and_table():
    e = _err(machine_text() + "\n[axes.q]\nv_max = 1\n")
    assert e.key == "axes.q" and "unknown axis" in e.reason
    e = _err(machine_text() + "\n[spindle]\nrpm = 1\n")
    assert e.key == "spindle" and "unknown table" in e.reason


def test_missing_required_key_and_table():
    e = _err(machine_text().replace("a_max = 500.0\n", ""))
    assert e.key == "axes.z" and "missing required key 'a_max'" in e.reason
    assert e.line == _line_of(machine_text(), "[axes.z]")
    text = machine_text()
    e = _err(text[: text.index("[path]")])
    assert e.key == "path" and "missing required table" in e.reason


def test_home_outside_travel_and_laser_modes():
    e = _err(machine_text().replace("min = -100.0", "min = -100.0\nhome = 200.0"))
    assert e.key == "axes.z.home"
    e = _err(machine_text() + '\n[laser]\nmode = "pulsed"\n')
    assert e.key == "laser" and "pulse_hz" in e.reason
    e = _err(machine_text() + '\n[laser]\nmode = "plasma"\n')
    assert e.key == "laser.mode"
    e = _err(machine_text() + "\n[laser]\ntolerance = 1.0\n")
    assert e.key == "laser.tolerance"


def test_scanner_section():
    text = machine_text() + '\n[scanner]\naxes = ["u", "v"]\nfield_mm = [50.0, 50.0]\n'
    e = _err(text)
    assert e.key == "scanner.axes" and "'u'" in e.reason


def test_toml_syntax_error_has_line():
    text = machine_text().replace("v_max = 100", "v_max = = 100", 1)
    e = _err(text)
    assert "not valid TOML" in e.reason and e.line == _line_of(text, "v_max = = 100")


def test_unreadable_file(tmp_path):
    with pytest.raises(MachineFileError) as info:
        load_machine(tmp_path / "nope.toml")
    assert "cannot read" in str(info.value)


def test_cli_reports_machine_mistake_without_traceback(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(machine_text().replace("a_max = 1000", "a_max = -1", 1))
    prog = tmp_path / "p.ngc"
    prog.write_text("G1 X1 F100\n")
    r = subprocess.run(
        [sys.executable, "-m", "jaxcnc", "plan", str(prog), "-m", str(bad), "-o", str(tmp_path / "o.ticks")],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert f"{bad}:" in r.stderr and "[axes.x.a_max]" in r.stderr
    assert not (tmp_path / "o.ticks").exists()


def test_tool_table_mistakes_name_their_line():
    text = machine_text() + "\n[tools.1]\nz_mm = 12.5\n\n[tools.7]\nz_mm = 1.0\nlength = 3\n"
    e = _err(text)
    assert (e.key, e.line) == ("tools.7.length", _line_of(text, "length = 3")) and "unknown key 'length'" in e.reason
    text = machine_text() + "\n[tools.0]\nz_mm = 1.0\n"
    e = _err(text)
    assert (e.key, e.line) == ("tools.0", _line_of(text, "[tools.0]")) and "H0 means no offset" in e.reason
    text = machine_text() + '\n[tools.2]\nz_mm = "long"\n'
    e = _err(text)
    assert (e.key, e.line) == ("tools.2.z_mm", _line_of(text, 'z_mm = "long"')) and "expected a number" in e.reason
    m = parse_machine(machine_text() + "\n[tools.12]\nz_mm = -2.0\ny_mm = 0.5\n")
    assert m.tool_offsets() == {12: (0.0, 0.5, -2.0)} and parse_machine(machine_text()).tool_offsets() == {}
