"""``jaxcnc bench scanner``: galvo vector lists (issue 18) — list compilation rate and emulation speed.

The job (made here, no outside file): a marking job of ``n_glyphs`` small "glyphs" on a 40 x 40 mm field — each a
five-pointed star (36° tips, 10 segments of about 1 mm) and a 0.5 mm circle (G2), marked at 2000 mm/s, jumps at
5000 mm/s — planned on a scanner-only machine (``[galvo]``, 100 kHz board clock, 1 µm discretes, τ = 150 µs).

Measured, each min/median of ``repeats`` runs, wall and CPU, beside **real time** (the job's duration on the
board: ticks × 10 µs):

- compilation: ``exact`` lists (timed vectors reproducing the table tick for tick, ``encode_rows``) and ``board``
  lists (lit runs as polylines at mark speed with delays and sky-writing from the head model) — vectors/s and
  the factor against real time; the model's delay search (``auto_settings``) apart;
- the ``scanner`` sink: rows encoded per list, sent as checked bytes, executed and verified — rows/s;
- emulation at the 10 µs tick: the board's reference interpolation (``execute``, NumPy) and the head model
  (``simulate``, JAX; its JIT compile timed apart as the first call) — ticks/s and the factor against real time.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from jaxcnc.bench.common import first_call, measure, run_header

MACHINE = """\
[machine]
name = "galvo-100k"
tick_hz = 100000
discrete_mm = 0.001
[axes.x]
v_max = 5000
a_max = 2e6
min = -25
max = 25
[axes.y]
v_max = 5000
a_max = 2e6
min = -25
max = 25
[path]
feed = 2000
rapid = 5000
corner_tol_mm = 0.0
[galvo]
tracking_error_s = 150e-6
mirror_a_max_mm_s2 = 5e6
"""


def marking_program(n_glyphs: int) -> str:
    """G-code for ``n_glyphs`` stars with a small circle each, on a square grid centred on 0."""
    side = math.ceil(math.sqrt(n_glyphs))
    pitch = 40.0 / side
    ang = np.pi / 2 + np.arange(11) * np.pi / 5
    rad = np.where(np.arange(11) % 2 == 0, 0.45 * pitch, 0.18 * pitch)
    star = np.stack([rad * np.cos(ang), rad * np.sin(ang)], 1)
    out = ["G21 G90", "G0 X0 Y0", "F120000"]
    for k in range(n_glyphs):
        cx, cy = -20 + pitch * (k % side + 0.5), -20 + pitch * (k // side + 0.5)
        p = star + (cx, cy)
        out += [f"G0 X{p[0, 0]:.4f} Y{p[0, 1]:.4f}", "M3 S1000"]
        out += [f"G1 X{x:.4f} Y{y:.4f}" for x, y in p[1:]]
        out += ["M5", f"G0 X{cx + 0.25:.4f} Y{cy:.4f}", "M3 S600", f"G2 X{cx + 0.25:.4f} Y{cy:.4f} I-0.25 J0", "M5"]
    out += ["G0 X0 Y0", "M2"]
    return "\n".join(out) + "\n"


def run_scanner_benchmarks(n_glyphs: int = 16, repeats: int = 5) -> dict:
    """Print and return the figures (module docstring)."""
    from jaxcnc.format import TableFile
    from jaxcnc.format.vectors import VectorHeader, execute
    from jaxcnc.hw.player import play
    from jaxcnc.hw.sinks.scanner import ScannerSink
    from jaxcnc.jobs import plan_file
    from jaxcnc.machine import load_machine
    from jaxcnc.scanner.compile import auto_settings, compile_board, compile_exact, lit_runs
    from jaxcnc.scanner.head import HeadModel, simulate

    info = run_header("scanner")
    repeats = max(5, repeats)
    with tempfile.TemporaryDirectory() as d:
        m, prog, out = Path(d) / "galvo.toml", Path(d) / "marking.ngc", Path(d) / "marking.ticks"
        m.write_text(MACHINE)
        prog.write_text(marking_program(n_glyphs))
        plan_file(prog, m, out, progress=False)
        machine = load_machine(m)
        t = TableFile(out)
        pos, power, events = np.asarray(t.positions).copy(), np.asarray(t.power).copy(), t.events.copy()
        h = VectorHeader(t.header.tick_hz, t.header.discrete_mm, tuple(t.header.axes))
        n = t.n_rows
        real_s = n * h.dt
        head = HeadModel.from_machine(machine)
        print(f"job: {n_glyphs} glyphs (stars + circles), {n} ticks = {real_s:.3f} s on the board at 100 kHz")
        res: dict = {"info": info, "n_glyphs": n_glyphs, "ticks": n, "real_time_s": real_s}
        rows = []

        def row(name: str, stat, count: int, unit: str) -> None:
            rate = count / stat.wall_median
            # against the duration of what was compiled or run: the table's, or the emulated ticks'
            factor = (count * h.dt if unit == "ticks" else real_s) / stat.wall_median
            rows.append((name, stat, count, unit, rate, factor))
            res[name] = {**stat.as_dict(), unit: count, f"{unit}_per_s": rate, "x_real_time": factor}

        rec_exact = compile_exact(pos, power, events)
        row("compile exact", measure(lambda: compile_exact(pos, power, events), repeats), len(rec_exact), "vectors")

        jit_s = first_call(lambda: auto_settings(head, 2000.0, h.dt, h.discrete_mm, 0.01, jump_speed_mm_s=5000.0))
        st = measure(lambda: auto_settings(head, 2000.0, h.dt, h.discrete_mm, 0.01, jump_speed_mm_s=5000.0), repeats)
        settings = auto_settings(head, 2000.0, h.dt, h.discrete_mm, 0.01, jump_speed_mm_s=5000.0)
        res["auto_settings"] = {**st.as_dict(), "first_call_s": jit_s, "settings": settings.__dict__}

        def board():
            runs = lit_runs(pos, power, h.discrete_mm, h.dt)
            return compile_board(runs, h, settings, 5000.0, start_mm=pos[0] * h.discrete_mm, mark_speed_mm_s=2000.0)

        rec_board = board()
        row("compile board", measure(board, repeats), len(rec_board), "vectors")

        def sink():
            s = ScannerSink(list_rows=8192)
            play(t, s, chunk_rows=4096)
            return s

        row("scanner sink", measure(sink, repeats), n, "ticks")
        row("execute exact", measure(lambda: execute(rec_exact, h), repeats), n, "ticks")
        ex_b = execute(rec_board, h)
        res["board_list_s"] = ex_b.positions.shape[0] * h.dt
        print(
            f"board list: {len(rec_board)} records, {res['board_list_s']:.3f} s on the board ({settings}); "
            f"exact list: {len(rec_exact)} records"
        )
        row("execute board", measure(lambda: execute(rec_board, h), repeats), ex_b.positions.shape[0], "ticks")
        cmd = pos * h.discrete_mm
        jit_sim = first_call(lambda: simulate(cmd, head, h.dt))
        row("head model", measure(lambda: simulate(cmd, head, h.dt), repeats), n, "ticks")
        res["head model"]["first_call_s"] = jit_sim

    print(f"{'':16} {'count':>9} {'wall min/median s':>19} {'CPU min/median s':>18} {'per s':>12} {'x real time':>11}")
    for name, stat, count, unit, rate, factor in rows:
        print(
            f"{name:16} {count:>9} {stat.wall_min:>9.4f}/{stat.wall_median:<9.4f} {stat.cpu_min:>8.4f}/"
            f"{stat.cpu_median:<9.4f} {rate:>8.3g} {unit[:3]} {factor:>11.1f}"
        )
    a = res["auto_settings"]
    print(
        f"auto_settings (delays + sky-writing searched on the model): {a['wall_median_s']:.3f} s median, "
        f"first call {a['first_call_s']:.3f} s (JIT compile); head model first call {jit_sim:.3f} s"
    )
    return res
