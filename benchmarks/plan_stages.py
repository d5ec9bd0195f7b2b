"""CPU time of each stage of a blended plan of the CAM contour (issue 13), min over repeats after a warm call.

    python benchmarks/plan_stages.py --blocks 100000 --repeats 5

Wraps the stage functions of the planning pipeline (building the blends, the grid and its boxes, the solve,
the interior check) with ``time.process_time`` and prints the split of the repeat with the least total CPU.
Stages nest: ``build_spans`` includes ``blend_path``, which includes the four after it, ``build_grid`` includes
``boxes_at`` (``_boxes_into`` from b938340 on) and ``frames_at``; ``_solve_grid`` waits for the solve's compiled
programs. Windows without blends (``--corner-tol-mm 0``) take ``_plain_window`` instead of ``build_grid``,
``_solve_grid`` and the interior check (``grid_excess`` from this issue's compiled check on, ``interior_excess``
before it). Works on any revision that has these functions (``PYTHONPATH=<checkout>`` for another).
"""

from __future__ import annotations

import argparse
import os
import time
from collections import defaultdict

import jaxcnc.geometry.blend as blend
import jaxcnc.geometry.path as path
import jaxcnc.planners.grid as grid
import jaxcnc.planners.job as job_module
import jaxcnc.planners.topp as topp
from jaxcnc.bench.plan import bench_machine
from jaxcnc.bench.programs import cam_polyline
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job

STAGES = (
    (job_module, "build_spans"),
    (path, "blend_path"),
    (blend, "_kernel"),
    (blend, "_deviation"),
    (blend, "_blend_points"),
    (blend, "_trim"),
    (topp, "build_grid"),
    (grid, "boxes_at"),
    (grid, "_boxes_into"),
    (grid, "frames_at"),
    (topp, "_solve_grid"),
    (topp, "interior_excess"),
    (topp, "grid_excess"),
    (topp, "device_spans"),
    (topp, "_compact_device_spans"),
    (topp, "_plain_window"),
)


def _wrap(module, name: str, spent: dict[str, float]) -> None:
    """Replace ``module.name`` by a wrapper adding its CPU time to ``spent[name]``."""
    fn = getattr(module, name)

    def timed(*args, **kwargs):
        c0 = time.process_time()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[name] += time.process_time() - c0

    setattr(module, name, timed)


def main() -> None:
    """Parse the arguments, plan the contour ``repeats`` times after a warm call, print the best split."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--blocks", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--corner-tol-mm", type=float, default=0.01)
    args = ap.parse_args()
    spent: dict[str, float] = defaultdict(float)
    for module, name in STAGES:
        if hasattr(module, name):
            _wrap(module, name, spent)
    program = cam_polyline(args.blocks)
    machine = parse_machine(bench_machine(args.corner_tol_mm), "<bench>")
    plan_job(program, machine)  # compile
    best = None
    for _ in range(args.repeats):
        spent.clear()
        c0, t0 = time.process_time(), time.perf_counter()
        job = plan_job(program, machine)
        total = (time.perf_counter() - t0, time.process_time() - c0)
        if best is None or total[1] < best[0][1]:
            best = (total, dict(spent))
    (wall, cpu), split = best
    print(f"{args.blocks} blocks, corner_tol {args.corner_tol_mm} mm, load average {os.getloadavg()[0]:.2f}: ")
    print(f"  plan_job wall {wall:.3f} s, CPU {cpu:.3f} s (the repeat of least CPU of {args.repeats})")
    print(f"  planned {job.plan.total_time_s:.4f} s, {len(job.plan)} segments")
    for name, s in split.items():
        print(f"  {name:16s} {s:.3f} s CPU")


if __name__ == "__main__":
    main()
