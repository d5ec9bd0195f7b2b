"""Pulsed engraving: the source documents' 14-program table, three planners side by side.

    python benchmarks/bench_pulsed.py [--programs 4 8] [--check]

For each of the documents' programs (same point counts; the clouds are generated, see
``jaxcnc.bench_pulsed``) prints the burn time of stop-and-go, of the documents' per-block method
and of jaxcnc's whole-job planner, the lower bound and the reductions, beside the documents' own
figures; then the cold planning time of the 108,400-point program. Same as ``jaxcnc bench pulsed``.
"""

from __future__ import annotations

import argparse

from jaxcnc.bench_pulsed import run_pulsed_benchmarks

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--programs", type=int, nargs="+", help="only these programs (1-14)")
    ap.add_argument("--check", action="store_true", help="also write and verify every table")
    args = ap.parse_args()
    run_pulsed_benchmarks(programs=args.programs, check=args.check)
