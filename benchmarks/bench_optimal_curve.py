"""How close jaxcnc's planners come to the time optimum on a curve; see :mod:`jaxcnc.bench_planners`.

python benchmarks/bench_optimal_curve.py [--points 16000]
"""

from __future__ import annotations

import argparse

from jaxcnc.bench_planners import run_planner_benchmarks

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=16_000, help="grid points of the references")
    run_planner_benchmarks(fine_points=ap.parse_args().points)
