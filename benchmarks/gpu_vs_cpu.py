"""Planning and tick generation on whatever device JAX picks (run once as is, once with JAX_PLATFORMS=cpu).

    python benchmarks/gpu_vs_cpu.py [--sizes 10000 100000 1000000] [--repeats 3]

Prints one JSON line per measurement: the program (CAM contour, blended or with exact corners), its
size, the first call (JIT compile included), the steady wall time (min and median of the repeats),
blocks/s, and the tick generation rate on the planned job. Used for the GPU-against-CPU figures in
docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import jax

from jaxcnc.bench.plan import bench_machine, tick_rate
from jaxcnc.bench.programs import cam_polyline
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    device = str(jax.devices()[0])
    for n in args.sizes:
        prog = cam_polyline(n)
        for tol in (0.0, 0.01):
            m = parse_machine(bench_machine(tol), "<bench>")
            t0 = time.perf_counter()
            job = plan_job(prog, m)
            first = time.perf_counter() - t0
            walls = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                job = plan_job(prog, m)
                walls.append(time.perf_counter() - t0)
            rate, tick_compile = tick_rate(job, 20, args.repeats)
            print(
                json.dumps(
                    dict(
                        device=device,
                        blocks=n,
                        corners="blended" if tol else "exact",
                        first_s=round(first, 3),
                        wall_min_s=round(min(walls), 4),
                        wall_median_s=round(statistics.median(walls), 4),
                        blocks_per_s=round(n / min(walls)),
                        ticks_per_s=round(rate),
                        tick_compile_s=round(tick_compile, 3),
                        planned_s=round(job.plan.total_time_s, 4),
                    )
                ),
                flush=True,
            )


if __name__ == "__main__":
    main()
