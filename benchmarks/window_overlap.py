"""Blended planning with and without the worker that builds the next window's grid (``topp.OVERLAP_WINDOWS``).

    python benchmarks/window_overlap.py --blocks 100000 --repeats 10

Plans the CAM contour blended in one process, the two modes interleaved (a warm call of each first, then
``repeats`` rounds alternating which goes first), and prints per mode the wall and CPU time of ``plan_job``, the
wall time of ``plan_topp`` inside it, and the page faults per plan (min / median). The plans are the same bit for
bit either way (``tests/test_window_overlap.py``); the heap is set up as the ``jaxcnc`` commands do
(``memory.tune_heap``). Compare on a quiet machine: the worker competes for the cores.
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np

from jaxcnc.memory import tune_heap

tune_heap()

import jaxcnc.planners.topp as topp  # noqa: E402  (after the heap's setup, as the commands do)
from jaxcnc.bench.plan import bench_machine  # noqa: E402
from jaxcnc.bench.programs import cam_polyline  # noqa: E402
from jaxcnc.machine import parse_machine  # noqa: E402
from jaxcnc.planners import plan_job  # noqa: E402


def main() -> None:
    """Parse the arguments, plan in both modes interleaved, print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--blocks", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--corner-tol-mm", type=float, default=0.01)
    args = ap.parse_args()
    inner = [0.0]
    plan_topp = topp.plan_topp

    def timed(req):
        t0 = time.perf_counter()
        try:
            return plan_topp(req)
        finally:
            inner[0] = time.perf_counter() - t0

    topp.plan_topp = timed
    program = cam_polyline(args.blocks)
    machine = parse_machine(bench_machine(args.corner_tol_mm), "<bench>")
    rows: dict[bool, list[tuple[float, float, float, int]]] = {False: [], True: []}
    for on in (False, True):
        topp.OVERLAP_WINDOWS = on
        plan_job(program, machine)  # compile
    load = os.getloadavg()[0]
    for r in range(args.repeats):
        for on in (False, True) if r % 2 == 0 else (True, False):
            topp.OVERLAP_WINDOWS = on
            f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
            c0, t0 = time.process_time(), time.perf_counter()
            job = plan_job(program, machine)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            rows[on].append((wall, cpu, inner[0], resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0))
            del job
    end = os.getloadavg()[0]
    print(f"{args.blocks} blocks, corner_tol {args.corner_tol_mm} mm, load average {load:.2f} -> {end:.2f}")
    for on in (False, True):
        a = np.array(rows[on])
        print(
            f"  worker {'on ' if on else 'off'}: plan_job wall {a[:, 0].min():.3f}/{np.median(a[:, 0]):.3f} s, "
            f"CPU {a[:, 1].min():.3f}/{np.median(a[:, 1]):.3f} s; plan_topp wall {a[:, 2].min():.3f}/"
            f"{np.median(a[:, 2]):.3f} s; page faults {np.median(a[:, 3]):.0f} (min/median of {args.repeats})"
        )


if __name__ == "__main__":
    main()
