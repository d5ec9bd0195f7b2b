"""``jaxcnc bench split``: the stage + scanner split on a part with sharp corners and small holes.

The part (made here with ezdxf, so the figure needs no outside file): a 50 x 30 mm plate whose four edges are
serrated (0.3 mm pitch, 0.15 mm teeth: 90° corners every 0.21 mm) with ten 0.6 mm holes; contour speed 6 m/min
(100 mm/s); main stage x, y at 0.5 g (4903.325 mm/s², 1000 mm/s); scanner u, v: a 20 x 20 mm field, 5000 mm/s
(300 m/min), 5e6 mm/s² (about 510 g, a galvo's order); 10 kHz ticks, 1 µm discretes. Methods side by side:
``own`` (low-pass stage path), ``seed`` (the documents' chord smoothing) and ``none`` (the stage alone,
``topp``, corners within one discrete: the same tolerance as the tool point's). Every table is written and
checked (limits of both axis groups, the field, the tool point). Throughput: contour points (ticks of the
tool path) planned per second by the split, min/median of repeated runs.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from jaxcnc.bench.common import measure, run_header

MACHINE = """\
[machine]
name = "stage-0.5g-scanner-20mm"
tick_hz = 10000
discrete_mm = 0.001
[axes.x]
v_max = 1000
a_max = 4903.325
min = -10
max = 600
[axes.y]
v_max = 1000
a_max = 4903.325
min = -10
max = 600
[axes.u]
v_max = 5000
a_max = 5e6
min = -10
max = 10
[axes.v]
v_max = 5000
a_max = 5e6
min = -10
max = 10
[path]
feed = 100
rapid = 1000
corner_tol_mm = 0.001
[scanner]
axes = ["u", "v"]
field_mm = [20, 20]
"""


def make_part(path: str | Path, pitch_mm: float = 0.3, w_mm: float = 50.0, h_mm: float = 30.0,
              holes: int = 10, hole_d_mm: float = 0.6, x0: float = 5.0, y0: float = 5.0) -> Path:  # fmt: skip
    """Write the serrated plate with small holes as a DXF file (module docstring)."""
    import ezdxf

    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    corners = [np.array(v, float) for v in [(x0, y0), (x0 + w_mm, y0), (x0 + w_mm, y0 + h_mm), (x0, y0 + h_mm)]]
    outward = [np.array(v, float) for v in [(0, -1), (1, 0), (0, 1), (-1, 0)]]
    edges = []
    for i in range(4):
        a, b = corners[i], corners[(i + 1) % 4]
        n = int(round(np.linalg.norm(b - a) / pitch_mm))
        n += n % 2
        pts = a[None] + np.linspace(0, 1, n + 1)[:-1, None] * (b - a)[None]
        pts[1::2] += outward[i] * pitch_mm / 2
        edges.append(pts)
    msp.add_lwpolyline(np.concatenate(edges).tolist(), close=True)
    for i in range(holes):
        msp.add_circle((x0 + (i + 0.5) * w_mm / holes, y0 + h_mm / 2), hole_d_mm / 2)
    doc.saveas(path)
    return Path(path)


def run_split_benchmarks(repeats: int = 5) -> dict:
    """Plan the part three ways, check every table, print the figures; the results as a dict."""
    from jaxcnc.format import TableFile
    from jaxcnc.front_ends import load_input
    from jaxcnc.machine import parse_machine
    from jaxcnc.planners import plan_job
    from jaxcnc.planners.split import plan_split
    from jaxcnc.ticks.deviation import path_deviation
    from jaxcnc.ticks.split import check_split, write_split_table
    from jaxcnc.ticks.table import write_table
    from jaxcnc.ticks.verify import measure_table

    run_header("split")
    folder = Path(tempfile.mkdtemp(prefix="jaxcnc-bench-split-"))
    mfile = folder / "machine.toml"
    mfile.write_text(MACHINE)
    machine = parse_machine(MACHINE, str(mfile))
    part = make_part(folder / "part.dxf")
    program = load_input(part, machine)
    out: dict = {"part": "serrated 50 x 30 mm plate, 0.3 mm pitch, ten 0.6 mm holes", "feed_mm_s": 100.0}
    rows = []
    for method in ("own", "seed"):
        plan = plan_split(program, machine, method)
        stat = measure(lambda m=method: plan_split(program, machine, m), repeats)
        table = TableFile(write_split_table(plan, program, machine, folder / f"{method}.ticks"))
        meas = measure_table(table, machine)
        chk = check_split(table, machine, program)
        rows.append((method, plan.total_time_s, meas, chk, stat, plan))
        out[method] = {
            "time_s": plan.total_time_s,
            "path_length_mm": plan.path_length_mm,
            "ratio_to_length_over_feed": plan.total_time_s / (plan.path_length_mm / plan.feed_mm_s),
            "max_main_accel_mm_s2": max(meas.max_abs_a["x"], meas.max_abs_a["y"]),
            "field_use": chk.max_field_use,
            "max_tool_deviation_mm": chk.max_tool_deviation_mm,
            "violations": len(meas.violations) + len(chk.violations),
            "points_per_s": plan.n_ticks / stat.wall_median,
            "plan": stat.as_dict(),
            **({"seed_figures": plan.stats["seed"]} if method == "seed" else {}),
        }
    job = plan_job(program, machine)
    table = TableFile(write_table(job, folder / "none.ticks", progress=False))
    meas = measure_table(table, machine)
    dev = path_deviation(table, machine, program)
    out["none"] = {
        "time_s": job.plan.total_time_s,
        "max_main_accel_mm_s2": max(meas.max_abs_a["x"], meas.max_abs_a["y"]),
        "max_tool_deviation_mm": dev.max_mm,
        "violations": len(meas.violations) + len(dev.violations),
    }
    own, none = out["own"], out["none"]
    out["speedup_own_vs_stage"] = none["time_s"] / own["time_s"]
    print(f"part: {out['part']}; contour speed 6 m/min; stage 0.5 g; scanner 20 x 20 mm, 5e6 mm/s², 5000 mm/s")
    print(f"{'method':8} {'job s':>8} {'/(L/F)':>7} {'max a main':>11} {'field':>6} {'tool dev mm':>12} {'viol':>5}")
    for name in ("own", "seed", "none"):
        r = out[name]
        ratio = f"{r['ratio_to_length_over_feed']:.4f}" if "ratio_to_length_over_feed" in r else "-"
        field = f"{100 * r['field_use']:.1f}%" if "field_use" in r else "-"
        print(f"{name:8} {r['time_s']:8.4f} {ratio:>7} {r['max_main_accel_mm_s2']:11.1f} {field:>6} "
              f"{r['max_tool_deviation_mm']:12.3g} {r['violations']:5d}")  # fmt: skip
    print(f"own is {out['speedup_own_vs_stage']:.2f}x faster than the stage alone (same tolerance: one discrete)")
    f = out["seed"]["seed_figures"]
    print(
        f"documents' method: chord {f['step_mm']:.3g} mm, alpha_kr {f['alpha_kr_deg']:.2f} deg ({f['passes']} "
        f"passes), their time {f['paper_time_s']:.4f} s, max Abig {f['paper_max_abig_mm_s2']:.4g} and Asmall "
        f"{f['paper_max_asmall_mm_s2']:.4g} mm/s²; the stage at constant tool speed would need "
        f"{f['intent_max_stage_accel_mm_s2']:.4g} mm/s², scanner reach {f['max_scanner_reach_mm']:.3g} mm"
    )
    for name in ("own", "seed"):
        print(f"split {name}: {out[name]['points_per_s']:.3g} contour points/s ({rows[0 if name == 'own' else 1][4]})")
    return out
