"""Geometry benchmark: NURBS evaluation and tick generation, peers in the same run.

    python benchmarks/bench_geometry.py [--points N] [--repeats R]

On the corpus butterfly (when ../shared/corpus is present) and a 1000-control-point cubic NURBS:
points/s of the batched evaluation against scipy.interpolate.BSpline and geomdl, and tick
generation (t -> s -> u(s) -> position -> integers) in ticks/s against the 10 kHz real-time rate.
JIT compile time is reported apart.
"""

from __future__ import annotations

import argparse

from jaxcnc.bench import run_geometry_benchmarks

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    run_geometry_benchmarks(n_eval=args.points, repeats=args.repeats)
