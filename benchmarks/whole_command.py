"""The whole ``jaxcnc plan`` command on a long CAM program, as a user runs it: parse, plan, ticks, verify.

    python benchmarks/whole_command.py --blocks 1000000 --repeats 5 --baseline 4555874

Writes :func:`jaxcnc.bench.programs.cam_gcode` (lines of 50–150 µm turning 0.1–5°, an arc every 50 blocks) as a
G-code file and the bench machine (10 kHz, 0.01 mm corner tolerance) as a machine file, then runs
``python -m jaxcnc plan FILE --machine M --output T --report R --quiet`` in fresh processes, this tree and, with
``--baseline REV``, a worktree of that revision, interleaved (one run of each per repeat). Both share one
compile cache, warmed by a run of each first (not counted): the figures are a user's second and later runs.
Printed per tree: wall and CPU seconds (min/median), the peak resident memory of the process (min–max; the
child's ``ru_maxrss``), each stage's seconds (median; the report's ``timings_s``) and the planned time.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from jaxcnc.bench.common import run_header
from jaxcnc.bench.plan import _baseline_tree, bench_machine
from jaxcnc.bench.programs import cam_gcode

ROOT = Path(__file__).resolve().parents[1]


def run_once(tree: Path, program: Path, machine: Path, out: Path, cache: Path) -> dict:
    """One ``jaxcnc plan`` in a fresh process of ``tree``: wall, CPU, peak RSS (MB), the report."""
    env = dict(os.environ, PYTHONPATH=str(tree), JAXCNC_CACHE_DIR=str(cache))
    report = out.with_suffix(".json")
    cmd = [sys.executable, "-m", "jaxcnc", "plan", str(program), "--machine", str(machine)]
    cmd += ["--output", str(out), "--report", str(report), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, cwd=out.parent, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode() if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{tree}: jaxcnc plan failed: {err.strip()[-500:]}")
    rep = json.loads(report.read_text())
    return dict(wall=wall, cpu=usage.ru_utime + usage.ru_stime, peak_mb=usage.ru_maxrss / 1024, report=rep)


def main() -> None:
    """Parse the arguments, write the inputs, run the trees interleaved, print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--blocks", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--baseline", default=None, help="a git revision measured beside this tree")
    args = ap.parse_args()
    run_header(f"the whole jaxcnc plan command, CAM contour of {args.blocks} blocks")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        program, machine, cache = folder / f"cam{args.blocks}.ngc", folder / "machine.toml", folder / "cache"
        program.write_text(cam_gcode(args.blocks))
        machine.write_text(bench_machine(0.01))
        trees = [("this", ROOT)] + ([(args.baseline, _baseline_tree(args.baseline, folder))] if args.baseline else [])
        runs: dict[str, list[dict]] = {name: [] for name, _ in trees}
        for name, tree in trees:  # the compile cache warmed, as a user's second run finds it
            run_once(tree, program, machine, folder / f"{name}.ticks", cache)
        for _ in range(args.repeats):
            for name, tree in trees:
                runs[name].append(run_once(tree, program, machine, folder / f"{name}.ticks", cache))
        if args.baseline:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(trees[1][1])], check=False)
    for name, rs in runs.items():
        walls, cpus, peaks = [r["wall"] for r in rs], [r["cpu"] for r in rs], [r["peak_mb"] for r in rs]
        stages = {k: statistics.median(r["report"].get("timings_s", {}).get(k, float("nan")) for r in rs)
                  for k in ("parse", "plan", "ticks", "verify")}  # fmt: skip
        rep = rs[0]["report"]
        print(
            f"{name:>10}: wall {min(walls):.2f}/{statistics.median(walls):.2f} s, CPU {min(cpus):.2f}/"
            f"{statistics.median(cpus):.2f} s (min/median of {len(rs)}), peak {min(peaks):.0f}-{max(peaks):.0f} MB; "
            + ", ".join(f"{k} {v:.2f}" for k, v in stages.items())
            + f" s; {rep['n_ticks']} ticks, planned {rep['total_time_s']:.3f} s"
        )


if __name__ == "__main__":
    main()
