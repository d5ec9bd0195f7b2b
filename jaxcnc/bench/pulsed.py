"""The pulsed-engraving benchmark behind ``jaxcnc bench pulsed``: the documents' 14-program table.

The source documents measured 14 in-glass engraving programs on LaserGraphicArt machines (40 Hz,
5 % tolerance, 300 mm/s², 1800 mm/min, points 100–150 µm apart): the old stop-and-go scheme and
their synchronised look-ahead (../shared/SEEDS.md §1). Their point clouds are not published, so
this benchmark generates one per program with the same point count: a raster-engraved solid
(:func:`jaxcnc.io.raster.superellipsoid_raster`), serpentine rows over layers, spacing drawn from
100–150 µm. On each it runs the three pulse planners on the same machine and prints their burn
times (first to last work pulse), the lower bound (intervals × shortest allowed period) and the
reductions, beside the documents' own figures. ``check=True`` also writes every table and
verifies limits at every tick, every pulse interval and every hit.

The program table has ``bang`` beside ``sync`` (burn, ratio to LBt, planning time). A second table
(:func:`run_hard_cases`) runs ``sync`` and ``bang`` on the hard-case clouds of
:mod:`jaxcnc.io.clouds` (holes, short rows, misaligned rows, sparse, 3-D text, and points inside a
real STL of the corpus) against the travel-aware lower bound ``LBt``
(:mod:`jaxcnc.planners.pulsed.bound`).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from importlib import resources
from pathlib import Path

import numpy as np

from jaxcnc.io import clouds
from jaxcnc.io.points import PointJob
from jaxcnc.io.raster import superellipsoid_raster
from jaxcnc.machine import MachineConfig, parse_machine
from jaxcnc.planners.pulsed import plan_points

#: The real mesh the hard-case table samples (skipped when the corpus is absent).
CORPUS_STL = Path(__file__).resolve().parents[3] / "shared" / "corpus" / "stl" / "nut.stl"

#: (points, old mm:ss, new mm:ss) of the documents' 14 programs.
DOCUMENT_PROGRAMS = (
    (34_800, "30:11", "18:15"),
    (12_100, "10:29", "7:01"),
    (23_200, "20:19", "14:08"),
    (108_400, "92:08", "48:16"),
    (65_200, "55:36", "31:14"),
    (30_900, "26:12", "16:01"),
    (38_600, "33:19", "24:02"),
    (8_600, "7:52", "4:58"),
    (26_700, "23:28", "13:36"),
    (52_000, "44:26", "28:13"),
    (31_200, "26:51", "17:54"),
    (28_000, "23:49", "14:28"),
    (35_200, "30:43", "19:45"),
    (21_100, "18:17", "10:11"),
)


def glass_engraver() -> MachineConfig:
    """The documents' machine (bundled as ``jaxcnc/data/glass-engraver.toml``)."""
    text = resources.files("jaxcnc.data").joinpath("glass-engraver.toml").read_text()
    return parse_machine(text, "glass-engraver.toml")


def _seconds(mmss: str) -> float:
    m, s = mmss.split(":")
    return 60.0 * int(m) + int(s)


def program_points(index: int, n_points: int) -> np.ndarray:
    """The generated point cloud of program ``index`` (1-based): a solid 16–28 mm wide, layers 0.25 mm apart."""
    rng = np.random.default_rng(1000 + index)
    a, b = rng.uniform(8.0, 14.0), rng.uniform(5.0, 9.0)
    layer = 0.25
    per_layer = 0.9 * 4 * a * b / (0.125 * 0.125)  # points in a full layer (p = 4 fills ~90 % of the box)
    c = max(layer, 0.75 * n_points / per_layer * layer)  # enough layers (the outer ones are smaller)
    return superellipsoid_raster(
        (a, b, c), layer_mm=layer, center_mm=(50.0, 50.0, 20.0), seed=index, max_points=n_points
    )


def _plan_wall_cold(n_points: int, planner: str = "sync") -> float:
    """Seconds to plan program 4 with ``planner`` in a fresh process without the compile cache (compile and
    plan; the imports come before the clock starts)."""
    code = (
        "import time, numpy as np\n"
        "from jaxcnc.bench.pulsed import glass_engraver, program_points\n"
        "from jaxcnc.io.points import PointJob\n"
        f"pts = program_points(4, {n_points})\n"
        "job = PointJob(pts, None, np.arange(1, len(pts) + 1), 'program-4')\n"
        "t0 = time.perf_counter()\n"
        "from jaxcnc.planners.pulsed import plan_points\n"
        f"plan_points(job, glass_engraver(), {planner!r})\n"
        "print(time.perf_counter() - t0)\n"
    )
    env = dict(os.environ, JAXCNC_CACHE_DIR="")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def run_pulsed_benchmarks(
    programs: list[int] | None = None, check: bool = False, cold: bool = True, hard: bool = True
) -> list[dict]:
    """Run the 14-program comparison (or the 1-based ``programs`` chosen); print and return the rows.

    ``hard``: then the hard-case table (:func:`run_hard_cases`) when all programs run.
    """
    machine = glass_engraver()
    chosen = programs or list(range(1, len(DOCUMENT_PROGRAMS) + 1))
    print("pulsed engraving, the documents' 14 programs (40 Hz ±5 %, 300 mm/s², 1800 mm/min, 100-150 µm)")
    print("times are burn times (first to last work pulse) in s; LB = intervals × shortest period (23.75 ms)")
    head = (
        f"{'#':>2} {'points':>7} | {'doc old':>7} {'doc new':>7} {'doc -%':>6} | {'stop&go':>8} {'ms/pt':>5} "
        f"{'seed':>8} {'-%':>5} {'sync':>8} {'-%':>5} {'LB':>8} {'sync/LB':>7} {'seed/LB':>7} | {'plan s':>6}"
    )
    print(head)
    print("-" * len(head))
    rows = []
    for i in chosen:
        n, old_doc, new_doc = DOCUMENT_PROGRAMS[i - 1]
        pts = program_points(i, n)
        job = PointJob(pts, None, np.arange(1, n + 1), f"program-{i}")
        res = {}
        for name in ("stop-and-go", "seed", "sync", "bang"):
            t0 = time.perf_counter()
            planned = plan_points(job, machine, name)
            res[name] = (planned, time.perf_counter() - t0)
        lb = res["sync"][0].lower_bound_s
        lbt = res["sync"][0].lower_bound_travel_s
        sg, seed, sync = (res[k][0].plan.burn_time_s for k in ("stop-and-go", "seed", "sync"))
        row = {
            "program": i,
            "n_points": n,
            "doc_old_s": _seconds(old_doc),
            "doc_new_s": _seconds(new_doc),
            "stop_and_go_s": sg,
            "seed_s": seed,
            "sync_s": sync,
            "lower_bound_s": lb,
            "lower_bound_travel_s": lbt,
            "sync_plan_wall_s": res["sync"][1],
            "sync_idle_pulses": res["sync"][0].plan.stats["idle_pulses"],
            "bang_s": res["bang"][0].plan.burn_time_s,
            "bang_plan_wall_s": res["bang"][1],
            "bang_idle_pulses": res["bang"][0].plan.stats["idle_pulses"],
        }
        if check:
            row["check"] = _check_tables({k: v[0] for k, v in res.items()}, machine)
        rows.append(row)
        doc_red = 1 - row["doc_new_s"] / row["doc_old_s"]
        print(
            f"{i:>2} {n:>7} | {row['doc_old_s']:>7.0f} {row['doc_new_s']:>7.0f} {100 * doc_red:>6.1f} | "
            f"{sg:>8.1f} {1e3 * sg / n:>5.1f} {seed:>8.1f} {100 * (1 - seed / sg):>5.1f} {sync:>8.1f} "
            f"{100 * (1 - sync / sg):>5.1f} {lb:>8.1f} {sync / lb:>7.4f} {seed / lb:>7.4f} | {res['sync'][1]:>6.2f}"
            f" | LBt {lbt:>8.1f} sync/LBt {sync / lbt:.4f} bang {row['bang_s']:>8.1f} bang/LBt "
            f"{row['bang_s'] / lbt:.4f} ({res['bang'][1]:.2f} s)" + (f"  {row['check']}" if check else "")
        )
    red = np.array([1 - r["sync_s"] / r["stop_and_go_s"] for r in rows])
    ratio = np.array([r["sync_s"] / r["lower_bound_s"] for r in rows])
    doc = np.array([1 - r["doc_new_s"] / r["doc_old_s"] for r in rows])
    print(
        f"sync: reduction against stop-and-go {100 * red.min():.1f}-{100 * red.max():.1f} % (mean "
        f"{100 * red.mean():.1f} %), {ratio.min():.4f}-{ratio.max():.4f} x the lower bound; documents' new "
        f"algorithm: {100 * doc.min():.1f}-{100 * doc.max():.1f} % (mean {100 * doc.mean():.1f} %)"
    )
    if cold and 4 in chosen:
        for planner in ("sync", "bang"):
            cold_s = _plan_wall_cold(n_points=108_400, planner=planner)
            print(f"planning program 4 (108,400 points) with {planner}, fresh process, no compile cache: {cold_s:.2f}s")
    if hard and programs is None:
        rows += run_hard_cases(check=check)
    return rows


def hard_case_clouds() -> dict[str, np.ndarray]:
    """The hard-case clouds by name, with points inside the corpus' nut (when the corpus is present)."""
    out = {name: make() for name, make in clouds.HARD_CASES.items()}
    if CORPUS_STL.is_file():
        out["mesh:nut.stl"] = clouds.mesh_cloud(CORPUS_STL, size_mm=12.0, seed=6)
    return out


def run_hard_cases(check: bool = False) -> list[dict]:
    """``sync`` and ``bang`` on each hard-case cloud against both lower bounds; print and return the rows."""
    machine = glass_engraver()
    print("hard cases: sync and bang against LB (intervals x shortest period) and LBt (travel-aware, certified)")
    head = (
        f"{'cloud':>13} {'points':>7} | {'sync s':>8} {'bang s':>8} {'LB s':>8} {'LBt s':>8} {'sync/LBt':>8} "
        f"{'bang/LBt':>8} {'idle s/b':>11} | {'plan s/b':>11}"
    )
    print(head)
    print("-" * len(head))
    rows = []
    for name, pts in hard_case_clouds().items():
        job = PointJob(pts, None, np.arange(1, len(pts) + 1), name)
        planned, wall = {}, {}
        for planner in ("sync", "bang"):
            t0 = time.perf_counter()
            planned[planner] = plan_points(job, machine, planner)
            wall[planner] = time.perf_counter() - t0
        sync, bang = (planned[k].plan.burn_time_s for k in ("sync", "bang"))
        lb, lbt = planned["sync"].lower_bound_s, planned["sync"].lower_bound_travel_s
        idle = {k: v.plan.stats["idle_pulses"] for k, v in planned.items()}
        row = {
            "cloud": name,
            "n_points": len(pts),
            "sync_s": sync,
            "bang_s": bang,
            "lower_bound_s": lb,
            "lower_bound_travel_s": lbt,
            "sync_idle_pulses": idle["sync"],
            "bang_idle_pulses": idle["bang"],
            "sync_plan_wall_s": wall["sync"],
            "bang_plan_wall_s": wall["bang"],
        }
        if check:
            row["check"] = _check_tables(planned, machine)
        rows.append(row)
        print(
            f"{name:>13} {len(pts):>7} | {sync:>8.1f} {bang:>8.1f} {lb:>8.1f} {lbt:>8.1f} {sync / lbt:>8.4f} "
            f"{bang / lbt:>8.4f} {idle['sync']:>5}/{idle['bang']:<5} | {wall['sync']:>5.2f}/{wall['bang']:<5.2f}"
            + (f"  {row['check']}" if check else "")
        )
    return rows


def _check_tables(plans: dict, machine: MachineConfig) -> str:
    """Write each plan's table, verify limits and pulses; a short verdict."""
    from jaxcnc.format import TableFile
    from jaxcnc.ticks.pulses import write_pulse_table
    from jaxcnc.ticks.verify import measure_table
    from jaxcnc.ticks.verify_pulses import check_pulses

    verdicts = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, planned in plans.items():
            path = Path(tmp) / f"{name}.ticks"
            write_pulse_table(planned, path, progress=False)
            table = TableFile(path)
            bad = len(measure_table(table, machine).violations) + len(
                check_pulses(table, machine, planned.job).violations
            )
            verdicts.append(f"{name}: {'ok' if bad == 0 else f'{bad} violations'}")
            del table
            path.unlink()
    return ", ".join(verdicts)
