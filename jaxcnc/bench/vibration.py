"""``jaxcnc bench vibration``: none / each input shaper / speed-band avoidance on cornered parts (issue 20).

The machine: x and y at 250 mm/s, 3000 mm/s², each with a 40 Hz, ζ = 0.05 mode; 10 kHz ticks, 1 µm
discretes. The parts (written here, no outside file):

* ``hexagon``: six exact corners (G61) cut at 100 mm/s — every corner a stop;
* ``bracket``: G64 corners (blended within the machine's 0.01 mm), a sharp kink and an R10 arc at 100 mm/s
  — shaping must keep to the corner tolerance (wide corners become stops, the arc is slowed);
* ``serration``: 60 teeth of 1 mm at 90 mm/s (a 2 mm pitch: 45 Hz at 90 mm/s, near the mode), G64.

Per part and method: the job's time (and its cost over unshaped per rest point against the shaper's
duration), the residual vibration after stops (max, mean), the same with the real mode 20 % below and above
the design (the shaper's robustness), the simulated contour error, the command's distance from the
programmed path, the check's verdict (limits at every tick and the path), and the planning wall time
(plan + shape + write, min of ``repeats``). The sweep: the serration cut at feeds across the resonant band
with and without band avoidance (its vibration amplitude over the middle half of the cut, away from the
start and end transients, and the speed it ran at).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from jaxcnc.bench.common import run_header

MACHINE = """\
[machine]
name = "vibration-40Hz"
tick_hz = 10000
discrete_mm = 0.001
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
corner_tol_mm = 0.01
"""


def _lines(points, feed_mm_s: float, mode: str) -> str:
    body = "".join(f"G1 X{x:g} Y{y:g} F{feed_mm_s * 60:g}\n" for x, y in points[1:])
    return f"G21 G90 {mode}\nG0 X{points[0][0]:g} Y{points[0][1]:g}\nM3 S1000\n{body}M5\nM2\n"


def serration(feed_mm_s: float, teeth: int = 60, tooth_mm: float = 1.0, depth_mm: float = 0.1) -> str:
    """A serrated edge: ``teeth`` rows of about ``tooth_mm`` zigzagging ``depth_mm`` deep (G64)."""
    pts = [(i * tooth_mm, depth_mm / 2 if i % 2 else -depth_mm / 2) for i in range(teeth + 1)]
    return _lines(pts, feed_mm_s, "G64")


PARTS = {
    "hexagon": _lines([(0, 0), (40, 0), (40, 25), (20, 35), (0, 25), (10, 10), (0, 0)], 100.0, "G61"),
    "bracket": "G21 G90 G64\nG0 X0 Y0\nM3 S1000\nG1 X30 Y0 F6000\nG1 X30.5 Y0.2\nG1 X40 Y10\nG2 X50 Y0 I10 J0\n"
    "G1 X20 Y-10\nG1 X0 Y0\nM5\nM2\n",
    "serration": serration(90.0),
}
METHODS = ("none", "zv", "mzv", "zvd", "ei", "2hump_ei", "3hump_ei", "bands")


def run_case(folder: Path, machine, part: str, method: str, repeats: int = 1) -> dict:
    """Plan ``part`` with ``method`` (a shaper, ``none`` or ``bands``: auto speed bands), check, simulate."""
    from jaxcnc.dynamics import Mode, simulate_table
    from jaxcnc.format import TableFile
    from jaxcnc.jobs import plan_dynamic_file

    src = folder / f"{part}.ngc"
    src.write_text(PARTS[part])
    out = folder / f"{part}-{method}.ticks"
    shaper = None if method in ("none", "bands") else method
    bands = "auto" if method == "bands" else None
    walls = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        r = plan_dynamic_file(src, machine, out, shaper, progress=False, bands=bands, simulate=False)
        walls.append(time.perf_counter() - t0)
    table = TableFile(out)
    sim = simulate_table(table, machine)
    off = [
        simulate_table(table, machine, {a: [Mode(40.0 * k, 0.05)] for a in ("x", "y")}).max_residual_mm
        for k in (0.8, 1.2)
    ]
    return {
        "part": part,
        "method": method,
        "time_s": r["total_time_s"],
        "rest_points": r.get("shaping", {}).get("rest_points"),
        "shaper_s": r.get("shaping", {}).get("duration_s"),
        "residual_max_mm": sim.max_residual_mm,
        "residual_mean_mm": sim.mean_residual_mm,
        "residual_max_32hz_mm": off[0],
        "residual_max_48hz_mm": off[1],
        "n_stops": int(sim.stop_ticks.size),
        "contour_max_mm": sim.max_contour_mm,
        "path_deviation_mm": r["max_path_deviation_mm"],
        "check_ok": not r["violations"],
        "plan_wall_s": min(walls),
    }


def band_sweep(folder: Path, machine, feeds=(40, 60, 70, 80, 90, 100, 120)) -> list[dict]:
    """The serration at each feed, with and without speed-band avoidance: vibration amplitude during the cut."""
    from jaxcnc.dynamics import simulate_table
    from jaxcnc.format import TableFile
    from jaxcnc.jobs import plan_dynamic_file

    rows = []
    for v in feeds:
        src = folder / f"sweep-{v}.ngc"
        src.write_text(serration(float(v)))
        row: dict = {"feed_mm_s": v}
        for label, bands in (("plain", None), ("avoid", "auto")):
            out = folder / f"sweep-{v}-{label}.ticks"
            r = plan_dynamic_file(src, machine, out, None, progress=False, bands=bands, simulate=False)
            table = TableFile(out)
            sim = simulate_table(table, machine, keep=True)
            n = table.header.n_rows
            mid = slice(n // 4, 3 * n // 4)  # the middle half of the cut: steady cutting, no start or end transient
            row[label] = {
                "vibration_mm": float(np.abs(sim.error[mid]).max()),
                "max_speed_mm_s": float(np.max(np.linalg.norm(np.diff(sim.commanded[:n], axis=0), axis=1)))
                * machine.tick_hz,
                "time_s": r["total_time_s"],
                "check_ok": not r["violations"],
            }
            if bands:
                row["bands_mm_s"] = r["speed_bands"]["bands_mm_s"]
        rows.append(row)
    return rows


def run_vibration_benchmarks(repeats: int = 3) -> dict:
    """Run and print the suite; the figures as a dict."""
    from jaxcnc.jaxconfig import configure_jax
    from jaxcnc.machine import parse_machine

    configure_jax()
    info = run_header("vibration")
    results: dict = {"run": info, "cases": [], "sweep": []}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        mpath = folder / "machine.toml"
        mpath.write_text(MACHINE)
        machine = parse_machine(MACHINE, str(mpath))
        run_case(folder, machine, "hexagon", "zvd")  # compile once, outside the figures
        print(
            f"{'part':10} {'method':9} {'time s':>7} {'cost/stop ms':>12} {'shaper ms':>9} {'resid µm':>9} "
            f"{'x less':>7} {'@32Hz':>7} {'@48Hz':>7} {'contour µm':>10} {'path µm':>8} {'check':>5} {'plan s':>6}"
        )
        for part in PARTS:
            base = None
            for method in METHODS:
                c = run_case(folder, machine, part, method, repeats)
                results["cases"].append(c)
                if method == "none":
                    base = c
                cost = (c["time_s"] - base["time_s"]) / c["rest_points"] * 1e3 if c["rest_points"] else float("nan")
                less = base["residual_max_mm"] / c["residual_max_mm"] if c["residual_max_mm"] > 0 else float("inf")
                c["reduction"] = less
                c["reduction_32hz"] = base["residual_max_32hz_mm"] / max(c["residual_max_32hz_mm"], 1e-300)
                c["reduction_48hz"] = base["residual_max_48hz_mm"] / max(c["residual_max_48hz_mm"], 1e-300)
                shaper_ms = c["shaper_s"] * 1e3 if c["shaper_s"] else float("nan")
                print(
                    f"{part:10} {method:9} {c['time_s']:7.3f} {cost:12.2f} {shaper_ms:9.2f} "
                    f"{c['residual_max_mm'] * 1e3:9.3f} {less:7.1f} {c['reduction_32hz']:7.1f} "
                    f"{c['reduction_48hz']:7.1f} {c['contour_max_mm'] * 1e3:10.3f} {c['path_deviation_mm'] * 1e3:8.3g} "
                    f"{'ok' if c['check_ok'] else 'FAIL':>5} {c['plan_wall_s']:6.2f}"
                )
        print(
            "  x less: residual vibration after stops, unshaped / this; @32Hz, @48Hz: the same with the mode 20 % off"
        )
        print("serration sweep (feed across the 40 Hz band, 2 mm pitch): vibration in the middle half of the cut")
        print(f"{'feed':>5} {'plain µm':>9} {'at mm/s':>8} {'avoid µm':>9} {'at mm/s':>8} {'time s':>13}")
        for row in band_sweep(folder, machine):
            results["sweep"].append(row)
            p, a = row["plain"], row["avoid"]
            print(
                f"{row['feed_mm_s']:5g} {p['vibration_mm'] * 1e3:9.1f} {p['max_speed_mm_s']:8.1f} "
                f"{a['vibration_mm'] * 1e3:9.1f} {a['max_speed_mm_s']:8.1f} {p['time_s']:6.3f}/{a['time_s']:.3f}"
                + ("" if p["check_ok"] and a["check_ok"] else "  CHECK FAILED")
            )
        bands = results["sweep"][0].get("bands_mm_s")
        print(f"  bands avoided (auto: modes x repeat lengths +-20 %): {bands}")
    return results
