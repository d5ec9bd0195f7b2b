"""Benchmarks behind ``jaxcnc bench`` (and ``benchmarks/bench_plan.py``).

Planning and tick sampling of a synthetic CAM-like program of short line blocks, timed in one
run beside baselines on the same data:

* the look-ahead passes against the classic sequential two-loop planner (pure Python, the
  structure of a controller's planner) and a plain NumPy closed form (``cumsum`` + ``cummin``);
* tick sampling against real time at the documents' 10 kHz interpolation rate.

JIT compile time (first call) is reported apart from steady state (best of ``repeats``).
Absolute times on shared machines are noise; read the ratios.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.machine import MachineConfig, parse_machine
from jaxcnc.planners import plan_job
from jaxcnc.planners.lookahead import lookahead
from jaxcnc.program import Kind, Program, program_from_columns
from jaxcnc.ticks.sample import TickSampler, quantize

BENCH_MACHINE = """\
[machine]
name = "bench"
tick_hz = 10000
[axes.x]
v_max = 250.0
a_max = 3000.0
min = -1000.0
max = 1000.0
[axes.y]
v_max = 250.0
a_max = 3000.0
min = -1000.0
max = 1000.0
[path]
feed = 100.0
rapid = 250.0
"""


def synthetic_program(n_blocks: int, seed: int = 0) -> Program:
    """A smooth curve cut into ``n_blocks`` lines of 50–150 µm (CAM output of a spline).

    The curvature oscillates between -0.01 and 0.06 /mm around a positive mean, so the curve
    winds around and stays within about 200 mm; headings change by at most 0.6° per block, so
    junctions are passed moving and only curvature and block length limit the speed.
    """
    rng = np.random.default_rng(seed)
    step = rng.uniform(0.05, 0.15, n_blocks)
    s = np.cumsum(step)
    curvature = 1 / 40 + 0.035 * np.sin(s / 5.0)
    heading = np.cumsum(step * curvature)
    pts = np.zeros((n_blocks + 1, 3))
    pts[1:, 0] = np.cumsum(step * np.cos(heading))
    pts[1:, 1] = np.cumsum(step * np.sin(heading))
    pts[:, :2] -= pts[:, :2].mean(axis=0)
    return program_from_columns(
        file="<synthetic>",
        kind=np.full(n_blocks, Kind.LINE),
        start=pts[:-1],
        end=pts[1:],
        feed=np.full(n_blocks, 100.0),
        line=np.arange(1, n_blocks + 1),
    )


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


def _best(fn: Callable[[], object], repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def tick_rate(job, n_chunks: int, repeats: int) -> tuple[float, float]:
    """Steady ticks/s of sampling and quantising up to ``n_chunks`` chunks of ``job``, and the compile time."""
    sampler = TickSampler(job)
    n_ticks = min(sampler.n_rows, n_chunks * sampler.chunk)

    def sample_all() -> None:
        for first in range(0, n_ticks, sampler.chunk):
            p, _ = sampler.program_positions(first, min(sampler.chunk, n_ticks - first))
            quantize(p, job.machine.discrete_mm)

    t0 = time.perf_counter()
    sampler.program_positions(0, sampler.chunk)
    compile_s = time.perf_counter() - t0
    return n_ticks / _best(sample_all, repeats), compile_s


def run_benchmarks(n_blocks: int = 100_000, repeats: int = 5, machine: MachineConfig | None = None) -> dict:
    """Run and print the benchmarks; return the figures as a dict."""
    m = machine or parse_machine(BENCH_MACHINE, "<bench>")
    prog = synthetic_program(n_blocks)
    print(f"jaxcnc bench: {n_blocks} line blocks of 50-150 um, {m.tick_hz:g} Hz ticks, JAX on {jax.devices()[0]}")

    t0 = time.perf_counter()
    job = plan_job(prog, m)
    first_plan = time.perf_counter() - t0
    plan_s = _best(lambda: plan_job(prog, m), repeats)
    print(
        f"  planning (parse excluded): first call {first_plan:.2f} s incl. JIT compile; "
        f"steady {plan_s * 1e3:.1f} ms = {n_blocks / plan_s:,.0f} blocks/s"
    )
    v_min = float(np.min(job.plan.vp))
    print(
        f"  planned job: {job.plan.total_time_s:.2f} s, {job.path_length_mm:.0f} mm, "
        f"slowest block peak {v_min:.1f} mm/s (feed 100)"
    )

    # look-ahead passes alone, same inputs for all three
    rng = np.random.default_rng(1)
    cap = rng.uniform(0, 1e4, n_blocks + 1)
    cap[0] = cap[-1] = 0.0
    delta = rng.uniform(0, 300.0, n_blocks)
    cap_j, delta_j = jnp.asarray(cap), jnp.asarray(delta)
    jitted = jax.jit(lookahead)
    t0 = time.perf_counter()
    ref_jax = np.asarray(jitted(cap_j, delta_j))
    jit_compile = time.perf_counter() - t0
    t_jax = _best(lambda: jitted(cap_j, delta_j).block_until_ready(), repeats)
    t_np = _best(lambda: numpy_lookahead(cap, delta), repeats)
    cap_l, delta_l = cap.tolist(), delta.tolist()
    t_py = _best(lambda: sequential_lookahead(cap_l, delta_l), max(1, min(repeats, 3)))
    ref_py = np.asarray(sequential_lookahead(cap_l, delta_l))
    err = float(np.max(np.abs(ref_jax - ref_py)))
    print(f"  look-ahead passes on {n_blocks} junctions (compile {jit_compile:.2f} s apart):")
    print(f"    jaxcnc associative scan   {t_jax * 1e3:8.2f} ms  {n_blocks / t_jax:14,.0f} blocks/s")
    print(
        f"    NumPy cumsum/cummin       {t_np * 1e3:8.2f} ms  {n_blocks / t_np:14,.0f} blocks/s"
        f"  (jaxcnc {t_np / t_jax:.1f}x)"
    )
    print(
        f"    sequential Python loops   {t_py * 1e3:8.2f} ms  {n_blocks / t_py:14,.0f} blocks/s"
        f"  (jaxcnc {t_py / t_jax:.1f}x); max |diff| {err:.2e} (mm/s)^2"
    )

    rate, sample_compile = tick_rate(job, 20, max(1, repeats // 2))
    print(
        f"  tick sampling t -> s -> u -> position -> integers: first chunk {sample_compile:.2f} s incl. compile; "
        f"steady {rate:,.0f} ticks/s = {rate / 1e4:,.0f}x the documents' 10 kHz real-time rate"
    )
    return {
        "n_blocks": n_blocks,
        "plan_first_call_s": first_plan,
        "plan_steady_s": plan_s,
        "plan_blocks_per_s": n_blocks / plan_s,
        "lookahead_jax_s": t_jax,
        "lookahead_numpy_s": t_np,
        "lookahead_python_s": t_py,
        "lookahead_compile_s": jit_compile,
        "ticks_per_s": rate,
        "tick_compile_s": sample_compile,
    }


# ---- geometry: NURBS evaluation and tick generation --------------------------------------------


def random_cubic_nurbs(n_points: int = 1000, seed: int = 0) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """A planar cubic NURBS with ``n_points`` control points winding through a 200 mm field."""
    rng = np.random.default_rng(seed)
    ang = np.cumsum(rng.normal(0.0, 0.25, n_points))
    pts = np.cumsum(np.stack([np.cos(ang), np.sin(ang)], axis=1) * rng.uniform(1.0, 3.0, (n_points, 1)), axis=0)
    pts = np.c_[pts - pts.mean(axis=0), np.zeros(n_points)]
    w = rng.uniform(0.5, 2.0, n_points)
    knots = np.concatenate([np.zeros(4), np.linspace(0, 1, n_points - 2)[1:-1], np.ones(4)])
    return 3, pts, w, knots


def _find_butterfly() -> tuple | None:
    from pathlib import Path

    from jaxcnc.io.curves import read_curves_json

    here = Path(__file__).resolve()
    for base in (Path.cwd(), Path.cwd().parent, here.parents[1], here.parents[2]):
        f = base / "shared" / "corpus" / "nurbs" / "butterfly_deg3_iges.json"
        if f.is_file():
            return read_curves_json(f)[0]
    return None


def bench_curve(name: str, curve: tuple, n_eval: int = 1_000_000, repeats: int = 3, feed: float = 10.0) -> dict:
    """Evaluation points/s (jaxcnc vs scipy vs geomdl) and tick generation ticks/s on one curve."""
    from scipy.interpolate import BSpline

    from jaxcnc.geometry.bezier import homogeneous_power, nurbs_to_bezier
    from jaxcnc.geometry.evaluate import evaluate_spans
    from jaxcnc.io.curves import curves_program

    p, pts, w, knots = curve
    pts = np.c_[pts, np.zeros(len(pts))] if pts.shape[1] == 2 else pts
    bp, bw, iv = nurbs_to_bezier(p, pts, w, knots)
    coeffs_t = jnp.asarray(np.ascontiguousarray(np.transpose(homogeneous_power(bp, bw, bp[:, 0]), (1, 2, 0))))
    origin_t = jnp.asarray(np.ascontiguousarray(bp[:, 0].T))
    breaks = jnp.asarray(iv[:, 0])
    width = jnp.asarray(iv[:, 1] - iv[:, 0])

    @jax.jit
    def eval_params(t):  # NURBS parameter -> span -> local u -> position, all on the device
        k = jnp.clip(jnp.searchsorted(breaks, t, side="right") - 1, 0, breaks.shape[0] - 1)
        (pos,) = evaluate_spans(coeffs_t, origin_t, k, (t - breaks[k]) / width[k])
        return pos

    t = jnp.asarray(np.random.default_rng(2).uniform(knots[0], knots[-1], n_eval))
    t0 = time.perf_counter()
    ref = np.asarray(eval_params(t))
    compile_s = time.perf_counter() - t0
    t_jax = _best(lambda: eval_params(t).block_until_ready(), repeats)
    spl = BSpline(knots, np.c_[pts * w[:, None], w], p)
    t_np = np.asarray(t)

    def scipy_eval():
        h = spl(t_np)
        return h[:, :3] / h[:, 3:]

    t_scipy = _best(scipy_eval, repeats)
    err = float(np.max(np.abs(scipy_eval() - ref)))
    print(f"  {name}: {len(pts)} control points, degree {p}, {len(iv)} Bezier spans")
    print(
        f"    evaluation of {n_eval:,} points (compile {compile_s:.2f} s apart): jaxcnc {n_eval / t_jax:,.0f} pts/s; "
        f"scipy BSpline {n_eval / t_scipy:,.0f} pts/s (jaxcnc {t_scipy / t_jax:.2f}x); max |diff| {err:.1e} mm"
    )
    out = {"eval_jax_pts_s": n_eval / t_jax, "eval_scipy_pts_s": n_eval / t_scipy, "eval_compile_s": compile_s}
    try:
        from geomdl import NURBS

        crv = NURBS.Curve()
        crv.degree = p
        crv.ctrlptsw = (np.c_[pts * w[:, None], w]).tolist()
        crv.knotvector = knots.tolist()
        n_g = 20_000
        tg = ((np.asarray(t[:n_g]) - knots[0]) / (knots[-1] - knots[0])).tolist()
        t_geomdl = _best(lambda: crv.evaluate_list(tg), 1)
        print(
            f"    geomdl (pure Python) {n_g / t_geomdl:,.0f} pts/s on {n_g:,} points (jaxcnc "
            f"{(n_g / t_geomdl) and (n_eval / t_jax) / (n_g / t_geomdl):.0f}x)"
        )
        out["eval_geomdl_pts_s"] = n_g / t_geomdl
    except ImportError:
        print("    geomdl not installed (pip install geomdl): skipped")

    m = parse_machine(BENCH_MACHINE.replace("a_max = 3000.0", "a_max = 1.0e5"), "<bench>")
    prog = curves_program([(p, pts, w, knots)], feed, start=pts[0])
    t0 = time.perf_counter()
    job = plan_job(prog, m)
    plan_first = time.perf_counter() - t0
    rate, tick_compile = tick_rate(job, 30, repeats)
    print(
        f"    plan (incl. span certification and compile) {plan_first:.2f} s; tick generation t -> s -> u(s) -> "
        f"position -> integers: {rate:,.0f} ticks/s = {rate / 1e4:,.0f}x the documents' 10 kHz "
        f"(compile {tick_compile:.2f} s apart)"
    )
    out.update({"ticks_per_s": rate, "tick_compile_s": tick_compile, "plan_first_s": plan_first})
    return out


def run_geometry_benchmarks(n_eval: int = 1_000_000, repeats: int = 3) -> dict:
    print(f"jaxcnc bench (geometry): NURBS evaluation and tick generation, JAX on {jax.devices()[0]}")
    out = {}
    bfly = _find_butterfly()
    if bfly is not None:
        out["butterfly"] = bench_curve("butterfly (corpus)", bfly, n_eval, repeats, feed=2.0)
    else:
        print("  butterfly: shared/corpus not found, skipped")
    out["nurbs1000"] = bench_curve("random cubic NURBS", random_cubic_nurbs(1000), n_eval, repeats)
    return out


# ---- player: throughput into sinks, memory on a long table -------------------------------------


def run_player_benchmarks(seconds: float = 60.0, rates: tuple[float, ...] = (10_000.0, 100_000.0)) -> dict:
    """Play synthetic 3-axis tables of ``seconds`` into ``sim`` and into the TCP receiver process.

    Prints ticks/s and the multiple of real time, and the player's peak memory growth (the table is
    memory-mapped and streamed, so it stays far below the table's size).
    """
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    from jaxcnc.hw.player import play
    from jaxcnc.hw.receiver import spawn
    from jaxcnc.hw.sinks.sim import SimSink
    from jaxcnc.hw.sinks.stream import StreamSink
    from jaxcnc.hw.tablefile import TableFile, TableWriter

    out: dict = {}
    print(f"jaxcnc bench (player): {seconds:g} s 3-axis tables")
    with tempfile.TemporaryDirectory() as tmp:
        for hz in rates:
            n = int(seconds * hz)
            path = Path(tmp) / f"t{int(hz)}.ticks"
            with TableWriter(path, axes=["x", "y", "z"], tick_hz=hz, discrete_mm=0.001, n_rows=n) as w:
                chunk = 1 << 20
                for first in range(0, n, chunk):
                    k = np.arange(first, min(n, first + chunk))
                    p = np.stack([k % 100_000, (k // 7) % 50_000, np.zeros_like(k)], axis=1).astype(np.int32)
                    w.write(p, np.zeros_like(p))
            size_mb = path.stat().st_size / 2**20
            table = TableFile(path)
            res = play(table, SimSink(buffer_rows=65536, keep=False), chunk_rows=65536)
            # memory of a fresh process that opens (verifies) and plays the table into sim: anonymous memory
            # stays bounded; the memory-mapped file's pages are page cache the kernel can drop
            code = (
                "import sys; from jaxcnc.hw.tablefile import TableFile; from jaxcnc.hw.player import play; "
                "from jaxcnc.hw.sinks.sim import SimSink; "
                "play(TableFile(sys.argv[1]), SimSink(buffer_rows=65536, keep=False), chunk_rows=65536); "
                "st = dict(l.split(':', 1) for l in open('/proc/self/status')); "
                "print(int(st['RssAnon'].split()[0]) / 1024, int(st['VmHWM'].split()[0]) / 1024)"
            )
            anon, hwm = map(
                float,
                subprocess.run(
                    [sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True
                ).stdout.split(),
            )
            print(
                f"  {hz / 1000:g} kHz, {n:,} rows ({size_mb:.0f} MB file): sim {n / res.wall_s:,.0f} ticks/s = "
                f"{res.real_time_factor:,.0f}x real time; player process: {anon:.0f} MB anonymous memory "
                f"(peak resident {hwm:.0f} MB incl. mapped file pages)"
            )
            proc, addr = spawn("tcp://127.0.0.1:0", "--speed", "1e6", "--capacity", "65536")
            try:
                res_tcp = play(table, StreamSink(addr), chunk_rows=65536)
                proc.communicate(timeout=120)
            finally:
                proc.kill()
            print(
                f"    tcp receiver (loopback, other process): {n / res_tcp.wall_s:,.0f} ticks/s = "
                f"{res_tcp.real_time_factor:,.1f}x real time"
            )
            out[hz] = {
                "sim_ticks_s": n / res.wall_s,
                "tcp_ticks_s": n / res_tcp.wall_s,
                "anon_mb": anon,
                "peak_resident_mb": hwm,
                "file_mb": size_mb,
            }
    return out
