"""Laser benchmarks (``docs/laser.md``): M4's energy per millimetre through corners beside constant power."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

#: A star with 10 sharp corners (36° tips) and 5 blunt ones, then a square: corners of every kind, at 3 m/min.
STAR_GCODE = (
    "G21 G90\nG0 X20 Y10\n{mode} S100\nG1 F3000 X{x0:.4f} Y{y0:.4f}\n{moves}\nG1 X5 Y5\nG1 X35 Y5\nG1 X35 Y35\n"
    "G1 X5 Y35\nG1 X5 Y5\nM5\nM2\n"
)
MACHINE = """[machine]
name = "m4-bench"
tick_hz = 10000
discrete_mm = 0.001
[axes.x]
v_max = 200
a_max = 2000
min = 0
max = 100
[axes.y]
v_max = 200
a_max = 2000
min = 0
max = 100
[axes.z]
v_max = 50
a_max = 500
min = -10
max = 10
[path]
feed = 50
rapid = 200
"""


def star_program(mode: str = "M4", tips: int = 5, r_out_mm: float = 12.0, r_in_mm: float = 5.0) -> str:
    """G-code of a star centred at (20, 20) traced at 3 m/min in ``mode`` (``"M3"`` or ``"M4"``), then a square."""
    ang = np.pi / 2 + np.arange(2 * tips + 1) * np.pi / tips
    r = np.where(np.arange(2 * tips + 1) % 2 == 0, r_out_mm, r_in_mm)
    x, y = 20 + r * np.cos(ang), 20 + r * np.sin(ang)
    moves = "\n".join(f"G1 X{a:.4f} Y{b:.4f}" for a, b in zip(x[1:], y[1:], strict=True))
    return STAR_GCODE.format(mode=mode, x0=x[0], y0=y[0], moves=moves)


def energy_per_mm(p_mm: np.ndarray, power: np.ndarray, tick_hz: float, bin_mm: float) -> np.ndarray:
    """Energy per mm (power·s/mm) in consecutive ``bin_mm`` bins of path length over the lit ticks.

    ``p_mm`` ``(n, n_axes)`` positions, ``power`` ``(n,)`` held over each tick; tick ``k`` deposits
    ``power[k] / tick_hz`` along ``|p[k+1] - p[k]|``, shared by the bins it covers in proportion to its length.
    Returns ``(n_bins,)``; only whole bins of lit path (ticks where ``power > 0``).
    """
    d = np.linalg.norm(np.diff(p_mm, axis=0), axis=1)
    e = power[:-1].astype(np.float64) / tick_hz
    lit = power[:-1] > 0
    d, e = d[lit], e[lit]
    s1 = np.cumsum(d)
    n_bins = int(s1[-1] // bin_mm)
    edges = np.arange(n_bins + 1) * bin_mm
    # cumulative energy at each edge, linear within a tick (the beam moves at a constant speed within one)
    cum_e = np.concatenate([[0.0], np.cumsum(e)])
    s_nodes = np.concatenate([[0.0], s1])
    keep = np.concatenate([[True], d > 0])  # ticks at rest put their energy at one point
    e_edges = np.interp(edges, s_nodes[keep], cum_e[keep])
    return np.diff(e_edges) / bin_mm


def run_laser_benchmarks(bin_mm: float = 0.5) -> dict:
    """The M4 corner figure: a star and a square planned at 3 m/min in M4 and in M3 (constant power); the energy
    per mm along the lit path in ``bin_mm`` bins relative to the straight-run value S/F. Prints and returns the
    worst deviations of each mode."""
    from jaxcnc.format import TableFile
    from jaxcnc.gcode import parse_gcode
    from jaxcnc.jobs import check_table
    from jaxcnc.machine import parse_machine
    from jaxcnc.planners import plan_job, program_start
    from jaxcnc.ticks.table import write_table

    out: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        mfile = Path(tmp) / "m.toml"
        mfile.write_text(MACHINE)
        machine = parse_machine(MACHINE, str(mfile))
        start = program_start(machine)
        for mode in ("M4", "M3"):
            src = Path(tmp) / f"star-{mode}.ngc"
            src.write_text(star_program(mode))
            job = plan_job(parse_gcode(src.read_text(), str(src), start=start, home=start), machine)
            path = write_table(job, Path(tmp) / f"{mode}.ticks", progress=False)
            table, meas = check_table(path, mfile)
            table = TableFile(path)
            epm = energy_per_mm(table.exact_mm(), table.power, table.header.tick_hz, bin_mm)
            straight = 100.0 / 50.0  # S / F (power·s per mm at the programmed feed)
            rel = epm / straight - 1.0
            out[mode] = {
                "ok": meas.ok,
                "max_over": float(rel.max()),
                "max_under": float(-rel.min()),
                "bins": int(rel.size),
                "time_s": job.plan.total_time_s,
            }
            print(
                f"  {mode}: energy per mm in {rel.size} bins of {bin_mm:g} mm: {100 * rel.min():+.2f} % to "
                f"{100 * rel.max():+.2f} % of the straight run (S/F); check {'OK' if meas.ok else 'FAILED'}"
            )
    return out
