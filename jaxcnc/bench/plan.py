"""The planning benchmark behind ``jaxcnc bench plan``.

1. Scaling: a CAM-style contour (:func:`~jaxcnc.bench.programs.cam_polyline`: 50–150 µm lines turning
   0.1–5° at every junction, an arc every 50 blocks) of 1k … 1M blocks, planned with exact corners
   (``corner_tol_mm = 0``) and blended (0.01 mm), each size in a fresh process: the first call
   (JIT compile included, apart), steady wall and CPU time (min/median of the repeats), blocks/s, and
   the process's peak resident memory (VmHWM) beside its resident memory before planning (the JAX
   runtime). With ``baseline=REV`` the same table is measured on that git revision (a worktree of
   this checkout) in the same run: the before/after of a change.
2. The look-ahead passes alone against the classic sequential two-loop planner (pure Python) and a
   NumPy closed form (``cumsum`` + ``cummin``), same inputs.
3. Tick sampling (t → s → position → integers) on lines, on the blended contour and on a NURBS.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.bench.common import REPEATS, Stat, measure, run_header
from jaxcnc.bench.programs import BENCH_MACHINE, cam_polyline, random_cubic_nurbs, synthetic_program
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job
from jaxcnc.planners.lookahead import lookahead
from jaxcnc.program import PROGRAM_COLUMNS
from jaxcnc.ticks.sample import TickSampler, quantize

SIZES = (1_000, 10_000, 100_000, 1_000_000)

#: Plans a program saved by :func:`_save_program` in a fresh interpreter; works on any revision that
#: has ``plan_job``, ``parse_machine`` and ``program_from_columns`` (so a baseline checkout runs it too).
_WORKER = """
import json, os, sys, time
import numpy as np
def rss():
    st = dict(l.split(':', 1) for l in open('/proc/self/status'))
    return int(st['VmRSS'].split()[0]) / 1024, int(st['VmHWM'].split()[0]) / 1024
try:  # as the jaxcnc commands do first (jaxconfig.configure_jax), without the compile cache
    from jaxcnc.memory import tune_heap
except ImportError:  # a baseline revision before it
    from jaxcnc.memory import limit_arenas as tune_heap
tune_heap()
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job
from jaxcnc.program import program_from_columns
data = np.load(sys.argv[1])
prog = program_from_columns(file='<bench>', **{k: data[k] for k in data.files})
machine = parse_machine(open(sys.argv[2]).read(), '<bench>')
repeats = int(sys.argv[3])
rss_before = rss()[0]
t0 = time.perf_counter(); job = plan_job(prog, machine); first = time.perf_counter() - t0
walls, cpus = [], []
for _ in range(repeats):
    job = None  # one plan at a time: the peak is one plan_job's
    c0, t0 = time.process_time(), time.perf_counter()
    job = plan_job(prog, machine)
    walls.append(time.perf_counter() - t0); cpus.append(time.process_time() - c0)
print(json.dumps(dict(first=first, walls=walls, cpus=cpus, rss_before_mb=rss_before, peak_mb=rss()[1],
                      planned_s=job.plan.total_time_s, segments=len(job.plan))))
"""


def sequential_lookahead(cap: list[float], delta: list[float]) -> list[float]:
    """The classic planner's two loops over junctions (backward, then forward), pure Python."""
    x = list(cap)
    for k in range(len(x) - 2, -1, -1):
        x[k] = min(x[k], x[k + 1] + delta[k])
    for k in range(1, len(x)):
        x[k] = min(x[k], x[k - 1] + delta[k - 1])
    return x


def numpy_lookahead(cap: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Plain NumPy closed form: ``x_i = D_i + cummin(b - D)_i`` per pass."""

    def forward(b: np.ndarray, d: np.ndarray) -> np.ndarray:
        dd = np.concatenate([[0.0], np.cumsum(d)])
        return dd + np.minimum.accumulate(b - dd)

    back = forward(cap[::-1], delta[::-1])[::-1]
    return forward(back, delta)


def tick_rate(job, n_chunks: int, repeats: int) -> tuple[int, Stat, float]:
    """Sampling and quantising up to ``n_chunks`` chunks of ``job``: ``(ticks, timing, compile seconds)``."""
    sampler = TickSampler(job)
    n_ticks = min(sampler.n_rows, n_chunks * sampler.chunk)

    def sample_all() -> None:
        for first in range(0, n_ticks, sampler.chunk):
            p, _ = sampler.program_positions(first, min(sampler.chunk, n_ticks - first))
            quantize(p, job.machine.discrete_mm)

    t0 = time.perf_counter()
    sampler.program_positions(0, sampler.chunk)
    compile_s = time.perf_counter() - t0
    return n_ticks, measure(sample_all, repeats), compile_s


def bench_machine(corner_tol_mm: float) -> str:
    """The benchmark machine's TOML with the given corner tolerance (0: exact corners)."""
    return BENCH_MACHINE.replace("rapid = 250.0", f"rapid = 250.0\ncorner_tol_mm = {corner_tol_mm}")


def _save_program(n: int, folder: Path) -> Path:
    prog = cam_polyline(n)
    path = folder / f"cam{n}.npz"
    np.savez(path, **{k: getattr(prog, k) for k in PROGRAM_COLUMNS})
    return path


def _baseline_tree(rev: str, folder: Path) -> Path:
    """A git worktree of ``rev`` of this checkout in ``folder`` (the caller's temporary directory)."""
    root = Path(__file__).resolve().parents[2]
    tree = folder / f"baseline-{rev}"
    out = subprocess.run(["git", "-C", str(root), "worktree", "add", "--detach", str(tree), rev], capture_output=True)
    if out.returncode != 0:
        raise RuntimeError(f"cannot check out {rev}: {out.stderr.decode().strip()}")
    return tree


def scaling(sizes=SIZES, repeats: int = REPEATS, baseline: str | None = None) -> list[dict]:
    """The scaling table (module docstring), printed; one dict per size, corner mode and revision."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        machines = {}
        for tol in (0.0, 0.01):
            machines[tol] = folder / f"machine{tol}.toml"
            machines[tol].write_text(bench_machine(tol))
        trees = [("this", None)]
        if baseline:
            trees.append((baseline, _baseline_tree(baseline, folder)))
        print(
            "  blocks   corners  revision   first call  steady min/median wall   CPU min    blocks/s   "
            "peak RSS (JAX runtime)  planned s"
        )
        try:
            for n in sizes:
                prog = _save_program(n, folder)
                for tol in (0.0, 0.01):
                    for label, tree in trees:
                        env = dict(os.environ)
                        if tree is not None:
                            env["PYTHONPATH"] = str(tree)
                        reps = repeats if n < 1_000_000 or tol == 0.0 else max(3, repeats // 2 + 1)
                        try:
                            out = subprocess.run(
                                [sys.executable, "-c", _WORKER, str(prog), str(machines[tol]), str(reps)],
                                capture_output=True, text=True, env=env, cwd=str(tree or folder),
                            )  # fmt: skip
                            if out.returncode != 0:
                                raise RuntimeError(out.stderr[-600:])
                            r = json.loads(out.stdout.strip().splitlines()[-1])
                        except RuntimeError as exc:
                            print(f"  {n:>8} {'blended' if tol else 'exact':>8}  {label:<9}  failed: {exc}")
                            continue
                        w = np.array(r["walls"])
                        row = dict(
                            blocks=n,
                            corner_tol_mm=tol,
                            revision=label,
                            first_s=r["first"],
                            wall_min_s=float(w.min()),
                            wall_median_s=float(np.median(w)),
                            cpu_min_s=float(min(r["cpus"])),
                            blocks_per_s=n / float(w.min()),
                            peak_mb=r["peak_mb"],
                            runtime_mb=r["rss_before_mb"],
                            planned_s=r["planned_s"],
                            repeats=reps,
                        )
                        rows.append(row)
                        print(
                            f"  {n:>8} {'blended' if tol else 'exact':>8}  {label:<9} {row['first_s']:>9.2f}s "
                            f"{row['wall_min_s']:>10.3f}/{row['wall_median_s']:.3f} s {row['cpu_min_s']:>9.3f}s "
                            f"{row['blocks_per_s']:>11,.0f} {row['peak_mb']:>8.0f} MB ({row['runtime_mb']:.0f} MB)"
                            f"   {row['planned_s']:>9.2f}"
                        )
        finally:
            for _, tree in trees[1:]:
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], capture_output=True,
                               cwd=str(Path(__file__).resolve().parents[2]))  # fmt: skip
    return rows


def run_benchmarks(n_blocks: int = 100_000, repeats: int = REPEATS, sizes=SIZES, baseline: str | None = None) -> dict:
    """Run and print the benchmarks; return the figures as a dict."""
    info = run_header("plan")
    print(f"  scaling: a CAM contour (50-150 um lines, 0.1-5 deg kinks, an arc every 50 blocks), {repeats} repeats")
    rows = scaling(sizes, repeats, baseline)

    # look-ahead passes alone, same inputs for all three
    rng = np.random.default_rng(1)
    cap = rng.uniform(0, 1e4, n_blocks + 1)
    cap[0] = cap[-1] = 0.0
    delta = rng.uniform(0, 300.0, n_blocks)
    cap_j, delta_j = jax.device_put(cap), jax.device_put(delta)
    jitted = jax.jit(lookahead)
    t0 = time.perf_counter()
    ref_jax = np.asarray(jitted(cap_j, delta_j))
    jit_compile = time.perf_counter() - t0
    s_jax = measure(lambda: jitted(cap_j, delta_j).block_until_ready(), repeats)
    s_np = measure(lambda: numpy_lookahead(cap, delta), repeats)
    cap_l, delta_l = cap.tolist(), delta.tolist()
    s_py = measure(lambda: sequential_lookahead(cap_l, delta_l), max(1, min(repeats, 3)))
    err = float(np.max(np.abs(ref_jax - np.asarray(sequential_lookahead(cap_l, delta_l)))))
    print(f"  look-ahead passes on {n_blocks} junctions (compile {jit_compile:.2f} s apart), wall min/median:")
    print(f"    jaxcnc scan               {s_jax}  {n_blocks / s_jax.wall_min:14,.0f} blocks/s")
    print(f"    NumPy cumsum/cummin       {s_np}  (jaxcnc {s_np.wall_min / s_jax.wall_min:.1f}x)")
    print(f"    sequential Python loops   {s_py}  (jaxcnc {s_py.wall_min / s_jax.wall_min:.1f}x); max |diff| {err:.2e}")

    ticks = {}
    m = parse_machine(bench_machine(0.01), "<bench>")
    m_fast = parse_machine(bench_machine(0.01).replace("a_max = 3000.0", "a_max = 1.0e5"), "<bench>")
    from jaxcnc.io.curves import curves_program

    p, pts, w, knots = random_cubic_nurbs(1000)
    for name, prog, mach in (
        ("lines (exact corners)", synthetic_program(n_blocks), parse_machine(bench_machine(0.0), "<bench>")),
        ("blended CAM contour", cam_polyline(n_blocks), m),
        ("cubic NURBS, 1000 points", curves_program([(p, pts, w, knots)], 10.0, start=pts[0]), m_fast),
    ):
        job = plan_job(prog, mach)
        n_ticks, stat, compile_s = tick_rate(job, 20, repeats)
        ticks[name] = {
            "ticks": n_ticks,
            "ticks_per_s": n_ticks / stat.wall_min,
            **stat.as_dict(),
            "compile_s": compile_s,
        }
        print(
            f"  tick sampling t -> s -> position -> integers, {name}: {n_ticks / stat.wall_min:,.0f} ticks/s "
            f"(min; median {n_ticks / stat.wall_median:,.0f}; {n_ticks:,} ticks: {stat}; "
            f"compile {compile_s:.2f} s apart)"
        )
    return {
        "info": info,
        "scaling": rows,
        "lookahead": {"jax": s_jax.as_dict(), "numpy": s_np.as_dict(), "python": s_py.as_dict(), "max_diff": err},
        "ticks": ticks,
    }
