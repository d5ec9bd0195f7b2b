"""Planning and tick-sampling benchmark: 100k short line blocks, baselines in the same run.

    python benchmarks/bench_plan.py [--blocks N] [--repeats R]

Prints blocks/s for planning (JIT compile apart from steady state), the look-ahead passes
against a sequential Python planner and a NumPy closed form, and ticks/s for sampling against
the 10 kHz real-time rate. Same as ``jaxcnc bench``.
"""

from __future__ import annotations

import argparse

from jaxcnc.bench import run_benchmarks

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--blocks", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    run_benchmarks(n_blocks=args.blocks, repeats=args.repeats)
