"""The power plot (issue 16, Deliver 6): the path coloured by power, power over time beside speed."""

from __future__ import annotations

import numpy as np
from PIL import Image

from jaxcnc.cli.main import main
from jaxcnc.machine import parse_machine
from jaxcnc.plot.power import plot_power, power_series
from tests.conftest import machine_text
from tests.helpers import table_of

STAR = "G0 X10 Y0\nM4 S100\nG1 X20 Y10 F1200\nG1 X10 Y20\nG1 X0 Y10\nG1 X10 Y0\nM5\nG0 X0 Y0\n"


def _count(img: np.ndarray, rgb: tuple[int, int, int], tol: int = 40) -> int:
    return int((np.abs(img[..., :3].astype(int) - np.array(rgb)).sum(axis=-1) < tol).sum())


def test_power_series_follows_m4_and_latency(tmp_path):
    m = parse_machine(machine_text() + "[laser]\non_delay_s = 0.0005\noff_delay_s = 0.0002\n", "d.toml")
    _, table, _ = table_of(STAR, m, tmp_path)
    ser = power_series(table, n_bins=table.n_rows)  # one bin per tick: the series are the ticks themselves
    power = table.read_power(0, table.n_rows)
    np.testing.assert_array_equal(ser["power_hi"], power)
    lit = ser["out_hi"] > 0
    assert lit.any() and not np.array_equal(ser["out_hi"], ser["power_hi"])  # the output is the command, late
    assert np.flatnonzero(lit)[0] == np.flatnonzero(power > 0)[0] + 5
    # M4: where lit, the output's power per speed is S / F at every tick (corners dimmed)
    on = np.flatnonzero(lit)
    np.testing.assert_allclose(ser["out_hi"][on] / ser["speed"][on], 100 / 20, rtol=1e-4)
    assert ser["out_hi"][on].min() < 50  # the corners


def test_plot_power_draws_path_and_curves(tmp_path):
    _, table, _ = table_of(STAR, parse_machine(machine_text(), "m.toml"), tmp_path)
    out = plot_power(table, tmp_path / "power.png")
    img = np.asarray(Image.open(out).convert("RGB"))
    assert img.shape[0] > 600 and img.shape[1] > 1200
    assert _count(img, (0xFF, 0x7F, 0x0E)) > 200  # the power curve
    assert _count(img, (0x1F, 0x77, 0xB4)) > 200  # the speed curve
    _, dark, _ = table_of(STAR.replace("M4 S100", "M5"), parse_machine(machine_text(), "m.toml"), tmp_path, "d.ticks")
    unlit = np.asarray(Image.open(plot_power(dark, tmp_path / "dark.png")).convert("RGB"))

    def full_power(a: np.ndarray) -> int:  # plasma_r's purple-blue top end, antialiased (the colour bar has it too)
        r, g, b = (a[..., i].astype(int) for i in range(3))
        return int(((r > 50) & (b - g > 80) & (b - r > 40)).sum())

    assert full_power(img) > full_power(unlit) + 1000  # the lit path drawn at full power
    assert _count(unlit, (0xA6, 0xA6, 0xA6), tol=30) > _count(img, (0xA6, 0xA6, 0xA6), tol=30)  # grey dashes


def test_cli_plot_power(tmp_path, capsys):
    mp = tmp_path / "m.toml"
    mp.write_text(machine_text())
    prog = tmp_path / "star.ngc"
    prog.write_text(STAR)
    assert main(["plan", str(prog), "--machine", str(mp), "-o", str(tmp_path / "s.ticks")]) == 0
    assert main(["plot", str(tmp_path / "s.ticks"), "-o", str(tmp_path / "p.png"), "--power"]) == 0
    assert "wrote" in capsys.readouterr().out and Image.open(tmp_path / "p.png").size[0] > 1200
