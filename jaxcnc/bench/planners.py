"""Planner benchmark: jaxcnc's ``topp`` beside the time-optimal references on the butterfly.

``jaxcnc bench planners`` (or ``python benchmarks/bench_planners.py``). The curve is the
corpus butterfly (``../shared/corpus``) or, without it, a built-in cubic NURBS; the machine is the
issue's: x and y at v = 100 mm/s and a = 1000 mm/s², feed 100 mm/s, chord 1 µm, 10 kHz. Every
plan is written as a tick table and measured by the independent verifier, so "violation factor"
is the largest |a| found on the table at the tick rate over a_max (1 or less: within limits).
Times are wall times of planning in this process; the first ``topp`` call includes JIT compile.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from jaxcnc.bench.programs import find_butterfly, random_cubic_nurbs
from jaxcnc.format import TableFile
from jaxcnc.io.curves import curves_program
from jaxcnc.machine import MachineConfig, parse_machine
from jaxcnc.planners import plan_job, register_planner
from jaxcnc.ticks.table import write_table
from jaxcnc.ticks.verify import measure_table

MACHINE = """\
[machine]
name = "bench-xy"
tick_hz = 10000
[axes.x]
v_max = {v}
a_max = {a}
min = -1000.0
max = 1000.0
[axes.y]
v_max = {v}
a_max = {a}
min = -1000.0
max = 1000.0
[path]
feed = {feed}
rapid = {feed}
chord_tol_mm = 0.001
"""


def butterfly_program(feed: float):
    """The corpus butterfly (or a stand-in cubic NURBS) as a program at ``feed``; and its name."""
    curve = find_butterfly()
    name = "butterfly (corpus)"
    if curve is None:
        curve, name = random_cubic_nurbs(60), "cubic NURBS, 60 points (corpus absent)"
    pts = curve[1] if curve[1].shape[1] == 3 else np.c_[curve[1], np.zeros(len(curve[1]))]
    return curves_program([curve], feed, start=pts[0]), name


def measured(job, machine: MachineConfig, folder: Path, name: str) -> tuple[float, int]:
    """Violation factor (max |a| over a_max on the table) and the number of violations."""
    path = write_table(job, folder / f"{name}.ticks", progress=False, planner=name)
    meas = measure_table(TableFile(path), machine)
    factor = max(meas.max_abs_a[a] / machine.axis(a).a_max for a in ("x", "y"))
    return factor, len(meas.violations)


def run_planner_benchmarks(
    fine_points: int = 16_000,
    coarse: tuple[int, ...] = (100, 500, 2000),
    v: float = 100.0,
    a: float = 1000.0,
    jerks: tuple[float, ...] = (1e5, 1e6),
) -> dict:
    """Run and print the comparison; return the figures."""
    from jaxcnc.planners.casadi_ref import casadi_planner
    from jaxcnc.planners.toppra_ref import toppra_planner

    machine = parse_machine(MACHINE.format(v=v, a=a, feed=v), "<bench>")
    prog, name = butterfly_program(v)
    print(f"jaxcnc bench planners: {name}; x, y: v {v:g} mm/s, a {a:g} mm/s², feed {v:g} mm/s, 10 kHz")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)

        def run(label: str, planner: str) -> dict:
            t0 = time.perf_counter()
            job = plan_job(prog, machine, planner)
            wall = time.perf_counter() - t0
            factor, n_bad = measured(job, machine, folder, planner)
            row = dict(label=label, time_s=job.plan.total_time_s, wall_s=wall, factor=factor, violations=n_bad)
            rows.append(row)
            return row

        first = run("jaxcnc topp (first call, JIT compile)", "topp")
        t0 = time.perf_counter()
        plan_job(prog, machine, "topp")
        first["steady_s"] = time.perf_counter() - t0
        run("jaxcnc lookahead (span-constant caps)", "lookahead")
        register_planner("bench-casadi")(casadi_planner(fine_points))
        run(f"CasADi/IPOPT, {fine_points} uniform points", "bench-casadi")
        register_planner("bench-toppra")(toppra_planner(fine_points, "interpolation"))
        run(f"toppra interpolation, {fine_points} points", "bench-toppra")
        for n in coarse:
            register_planner(f"bench-toppra-{n}")(toppra_planner(n, "collocation"))
            run(f"toppra collocation, {n} points", f"bench-toppra-{n}")
    ref = next(r for r in rows if r["label"].startswith("CasADi"))["time_s"]
    print(f"  {'planner':44s} {'time s':>8s} {'/ CasADi':>9s} {'max|a|/a_max':>13s} {'violations':>10s} {'wall s':>7s}")
    for r in rows:
        print(
            f"  {r['label']:44s} {r['time_s']:8.4f} {r['time_s'] / ref:9.4f} {r['factor']:13.4f} "
            f"{r['violations']:10d} {r['wall_s']:7.2f}"
        )
    print(f"  topp steady (compiled) planning: {first['steady_s']:.3f} s")
    jerk_rows = run_jerk_benchmarks(prog, v, a, ref, jerks, fine_points)
    return {"rows": rows, "reference_s": ref, "jerk": jerk_rows}


def run_jerk_benchmarks(prog, v: float, a: float, free_s: float, jerks: tuple[float, ...], fine_points: int) -> list:
    """The same program with ``j_max`` on x and y: jaxcnc (verified at every tick) beside CasADi's NLP."""
    from jaxcnc.planners.casadi_ref import casadi_planner

    register_planner("bench-casadi-jerk")(casadi_planner(fine_points))
    print(f"  with jerk limits (acceleration-limited optimum, CasADi above: {free_s:.4f} s)")
    print(
        f"  {'j_max mm/s³':>12s} {'planner':28s} {'time s':>8s} {'/ a-only':>9s} {'max|j|/j_max':>13s} "
        f"{'violations':>10s} {'wall s':>7s}"
    )
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for j in jerks:
            text = MACHINE.format(v=v, a=a, feed=v).replace(f"a_max = {a}\n", f"a_max = {a}\nj_max = {j}\n")
            machine = parse_machine(text, "<bench>")
            for label, planner in (
                ("jaxcnc topp + S-curve stage", "topp"),
                (f"CasADi/IPOPT {fine_points} pts", "bench-casadi-jerk"),
            ):
                t0 = time.perf_counter()
                job = plan_job(prog, machine, planner)
                wall = time.perf_counter() - t0
                path = write_table(job, Path(tmp) / f"j{planner}.ticks", progress=False, planner=planner)
                meas = measure_table(TableFile(path), machine)
                factor = max(meas.max_abs_j[x] / j for x in ("x", "y"))
                t = job.plan.total_time_s
                print(
                    f"  {j:12.0f} {label:28s} {t:8.4f} {t / free_s:9.4f} {factor:13.3f} {len(meas.violations):10d} "
                    f"{wall:7.2f}"
                )
                out.append(
                    dict(j_max=j, label=label, time_s=t, factor=factor, violations=len(meas.violations), wall_s=wall)
                )
    print("  (CasADi's jerk rows act on its grid; its plan holds s̈ constant per interval, so its table steps s̈)")
    return out
