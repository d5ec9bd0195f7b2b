"""The simulated axis (issue 20): machine-file modes, exact discretisation against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxcnc.dynamics.axis import Mode, ModeFilter, amplitude
from jaxcnc.errors import MachineFileError
from jaxcnc.machine import parse_machine
from tests.conftest import machine_text


def modes_machine(extra_x: str = "mode_hz = [40.0]\nmode_zeta = [0.05]\n") -> str:
    return machine_text().replace("[axes.y]", extra_x + "[axes.y]", 1)


def test_machine_file_modes_load():
    m = parse_machine(modes_machine("mode_hz = [40.0, 95.5]\nmode_zeta = [0.05, 0.1]\n"))
    assert m.axis("x").modes == ((40.0, 0.05), (95.5, 0.1))
    assert m.axis("y").modes == ()


@pytest.mark.parametrize(
    ("extra", "key", "reason"),
    [
        ("mode_hz = [40.0]\n", "mode_zeta", "0 damping ratios for 1 mode frequencies"),
        ("mode_hz = [40.0]\nmode_zeta = [1.0]\n", "mode_zeta", "must lie in [0, 1)"),
        ("mode_hz = [-3.0]\nmode_zeta = [0.1]\n", "mode_hz", "a mode must lie in (0, tick_hz / 2"),
        ("mode_hz = [6000.0]\nmode_zeta = [0.1]\n", "mode_hz", "5000"),
        ("mode_hz = 40.0\nmode_zeta = [0.1]\n", "mode_hz", "expected a list of numbers"),
        ("modes = [40.0]\n", "modes", "unknown key 'modes'"),
    ],
)
def test_machine_file_mode_mistakes_are_named(extra, key, reason):
    with pytest.raises(MachineFileError) as exc:
        parse_machine(modes_machine(extra), "m.toml")
    msg = str(exc.value)
    assert f"axes.x.{key}" in msg and reason in msg and msg.startswith("m.toml:")


# ------------------------------------------------------------------------------------------------
# The simulated axis against closed forms


def ramp_error(mode: Mode, v: float, t: np.ndarray) -> np.ndarray:
    """Closed form: the error of a base-excited damped oscillator when the base starts ``u = v t`` at t = 0."""
    wd = mode.omega_d
    return np.where(t > 0, -(v / wd) * np.exp(-mode.zeta * mode.omega * t) * np.sin(wd * np.maximum(t, 0)), 0.0)


@pytest.mark.parametrize(
    ("f_hz", "zeta", "tick_hz"), [(40.0, 0.05, 10000.0), (7.3, 0.3, 1000.0), (180.0, 0.0, 20000.0)]
)
def test_ramp_response_matches_closed_form(f_hz, zeta, tick_hz):
    mode = Mode(f_hz, zeta)
    n, v = 4000, 100.0
    x = ModeFilter(mode, tick_hz).step(np.full(n, v))
    t = np.arange(1, n + 1) / tick_hz
    e = ramp_error(mode, v, t)
    assert np.abs(x[:, 0] - e).max() < 1e-10 * v / mode.omega
    # the tool's velocity q = d(y)/dt = v + de/dt, de/dt in closed form
    wd, s = mode.omega_d, mode.zeta * mode.omega
    de = -(v / wd) * np.exp(-s * t) * (wd * np.cos(wd * t) - s * np.sin(wd * t))
    assert np.abs(x[:, 1] - (v + de)).max() < 1e-9 * v


def test_step_over_one_tick_is_two_ramps_and_chunks_do_not_matter():
    """A position step of 1 mm made in one tick: the closed form is the difference of two ramp responses."""
    mode, f = Mode(40.0, 0.05), 10000.0
    n = 5000
    w = np.zeros(n)
    w[0] = 1.0 * f  # 1 mm in the first tick, then still
    whole = ModeFilter(mode, f).step(w)
    flt = ModeFilter(mode, f)
    parts = np.vstack([flt.step(w[i : i + 777]) for i in range(0, n, 777)])
    assert np.array_equal(whole, parts)
    t = np.arange(1, n + 1) / f
    e = ramp_error(mode, f, t) - ramp_error(mode, f, t - 1 / f)
    assert np.abs(whole[:, 0] - e).max() < 1e-12
    # the free vibration's amplitude decays as exp(-zeta omega t) once the base stands still
    a = amplitude(mode, whole[:, 0], whole[:, 1])
    assert a[100] > 0 and np.allclose(a[200:] / a[100], np.exp(-mode.zeta * mode.omega * (t[200:] - t[100])), rtol=1e-9)


# ------------------------------------------------------------------------------------------------
# A table through the simulated axes

VIB_MACHINE = """[machine]
name = "vib"
tick_hz = 10000
[axes.x]
v_max = 250.0
a_max = 3000.0
min = -1000.0
max = 1000.0
mode_hz = [40.0]
mode_zeta = [0.05]
[axes.y]
v_max = 250.0
a_max = 3000.0
min = -1000.0
max = 1000.0
mode_hz = [40.0]
mode_zeta = [0.05]
[path]
feed = 100.0
rapid = 250.0
"""
#: A cornered part: a hexagon of exact corners (G61) cut at 100 mm/s.
CORNERED = [(0, 0), (40, 0), (40, 25), (20, 35), (0, 25), (10, 10), (0, 0)]


def cornered_gcode(points=CORNERED, feed_mm_min: float = 6000.0, mode: str = "G61") -> str:
    body = "".join(f"G1 X{x:g} Y{y:g} F{feed_mm_min:g}\n" for x, y in points[1:])
    return f"G21 G90 {mode}\nG0 X{points[0][0]:g} Y{points[0][1]:g}\nM3 S1000\n{body}M5\nM2\n"


@pytest.fixture
def vib_files(tmp_path):
    m = tmp_path / "vib.toml"
    m.write_text(VIB_MACHINE)
    part = tmp_path / "part.ngc"
    part.write_text(cornered_gcode())
    return m, part


def test_simulated_table_finds_every_stop_and_chunking_does_not_change_figures(vib_files, tmp_path):
    from jaxcnc.dynamics import simulate_table
    from jaxcnc.format import TableFile
    from jaxcnc.jobs import plan_file
    from jaxcnc.machine import load_machine

    m_path, part = vib_files
    plan_file(part, m_path, tmp_path / "p.ticks", progress=False)
    machine = load_machine(m_path)
    table = TableFile(tmp_path / "p.ticks")
    a = simulate_table(table, machine, keep=True)
    b = simulate_table(table, machine, chunk_rows=1000)
    assert a.stop_ticks.size == len(CORNERED) - 1  # five corners and the end (G61: each corner stops)
    assert np.array_equal(a.stop_ticks, b.stop_ticks) and np.allclose(a.residual_mm, b.residual_mm, rtol=1e-9)
    assert math.isclose(a.max_contour_mm, b.max_contour_mm, rel_tol=1e-9)
    # an undamped-ish 40 Hz mode behind a 3000 mm/s² stop rings at about a / omega^2
    assert 0.2 * 3000 / (2 * math.pi * 40) ** 2 < a.max_residual_mm < 3 * 3000 / (2 * math.pi * 40) ** 2
    assert a.commanded.shape == a.error.shape == (table.header.n_rows + round(0.2 * 10000), 2)
