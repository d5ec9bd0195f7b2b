"""The planning benchmark behind ``jaxcnc bench plan`` (and ``benchmarks/bench_plan.py``).

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
from jaxcnc.bench.programs import BENCH_MACHINE, synthetic_program
from jaxcnc.machine import MachineConfig, parse_machine
from jaxcnc.planners import plan_job
from jaxcnc.planners.lookahead import lookahead
from jaxcnc.ticks.sample import TickSampler, quantize


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
