"""Planning and tick generation on whatever device JAX picks (run once as is, once with JAX_PLATFORMS=cpu).

    python benchmarks/gpu_vs_cpu.py [--sizes 10000 100000 1000000] [--repeats 5]

Prints one JSON line per measurement: the device, the program (the CAM contour of ``bench plan``, blended or
with exact corners), its size, the first call (JIT compile included), the steady wall time (min and median of
the repeats) with the process's CPU time beside it, blocks/s, and the tick generation rate on the planned job
(20 chunks; compile apart). Used for the GPU-against-CPU figures in docs/planning.md.
"""

from __future__ import annotations

import argparse
import json
import os

import jax

from jaxcnc.bench.common import first_call, measure
from jaxcnc.bench.plan import bench_machine, tick_rate
from jaxcnc.bench.programs import cam_polyline
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    device = str(jax.devices()[0])
    print(json.dumps(dict(device=device, load_average=os.getloadavg()[0], cpus=os.cpu_count())), flush=True)
    for n in args.sizes:
        prog = cam_polyline(n)
        for tol in (0.0, 0.01):
            m = parse_machine(bench_machine(tol), "<bench>")
            first = first_call(lambda: plan_job(prog, m))  # noqa: B023  (called at once)
            plan = measure(lambda: plan_job(prog, m), args.repeats)  # noqa: B023
            job = plan_job(prog, m)
            ticks, tick_stat, tick_compile = tick_rate(job, 20, args.repeats)
            row = dict(
                device=device,
                blocks=n,
                corners="blended" if tol else "exact",
                first_s=round(first, 3),
                wall_min_s=round(plan.wall_min, 4),
                wall_median_s=round(plan.wall_median, 4),
                cpu_min_s=round(plan.cpu_min, 4),
                blocks_per_s=round(n / plan.wall_min),
                ticks=ticks,
                ticks_per_s=round(ticks / tick_stat.wall_min),
                tick_compile_s=round(tick_compile, 3),
                planned_s=round(job.plan.total_time_s, 4),
            )
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
