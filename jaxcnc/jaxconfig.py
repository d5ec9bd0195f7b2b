"""JAX configuration of the planning side: float64 on import, the compile cache by an explicit call.

Planning needs float64: a 1 h job at 100 kHz has 3.6e8 ticks and µm positions on metre-long axes, and
a planning function traced in float32 would be silently wrong. JAX's precision is one process-wide
switch that must be on before anything is traced, so every planning module imports this module, which
turns it on (``jax_enable_x64``); nothing else happens on import. The player side (:mod:`jaxcnc.hw`,
:mod:`jaxcnc.format`) never imports it (an import-linter contract checks that).

The persistent compile cache is the caller's choice: :func:`configure_jax` — called by the planning
entry points (:mod:`jaxcnc.jobs`, ``jaxcnc`` commands, benchmarks), not by importing — points JAX at
``$JAXCNC_CACHE_DIR`` (default ``~/.cache/jaxcnc/jax``), so a command-line run after the first skips
most of the JIT compile. ``JAXCNC_CACHE_DIR=""`` disables it; a cache directory the process already set
is kept. The planners' programs and their executables are stored in the same directory by
:mod:`jaxcnc.jitcache`, which loads them itself.

Planning runs on the host CPU whatever the default backend (:func:`planning_scope`): its passes are
sequential scans over the intervals, latency-bound, and a GPU pays a kernel launch and a host round trip
for every loop iteration. Measured on an H100 beside its own 16-core CPU (``benchmarks/gpu_vs_cpu.py``,
2026-11-23): a 10k-block contour planned in 0.81 s on the GPU against 0.024 s on the CPU; unrolling the
scans 64 steps per iteration brought the GPU to 0.064 s and its compile from 9 to 14–47 s. The spans' build
(the blends' kernels) runs in the same scope: on an H200's default device it gained nothing and cost 6–7 s of GPU
compile in a first plan, and its spans differed in their last bits from a CPU machine's, so plans were not the same
on every machine (2026-11-28). The tick stage and the other batched programs stay on the default device, where a
GPU is 2× the CPU.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)


def configure_jax(cache_dir: str | None = None) -> str | None:
    """Float64 on, the planning process's C heap tuned (:func:`jaxcnc.memory.tune_heap`: two malloc arenas, which
    only helps before JAX starts its threads, so entry points call this first; fixed thresholds), and the
    persistent compile cache in ``cache_dir`` (default ``$JAXCNC_CACHE_DIR`` or ``~/.cache/jaxcnc/jax``; ``""``
    for none). Idempotent; returns the cache directory in use, if any."""
    from jaxcnc.memory import tune_heap

    jax.config.update("jax_enable_x64", True)
    tune_heap()
    if jax.config.jax_compilation_cache_dir is not None:
        return jax.config.jax_compilation_cache_dir
    if cache_dir is None:
        cache_dir = os.environ.get("JAXCNC_CACHE_DIR", str(Path.home() / ".cache" / "jaxcnc" / "jax"))
    if not cache_dir:
        return None
    try:
        Path(cache_dir).mkdir(parents=True, exist_ok=True)
    except OSError:  # read-only home: run without the cache
        return None
    jax.config.update("jax_compilation_cache_dir", cache_dir)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.05)
    return cache_dir


def planning_device() -> jax.Device:
    """The device the planners run on: the host CPU where JAX has one, else the default device."""
    try:
        return jax.devices("cpu")[0]
    except RuntimeError:  # JAX_PLATFORMS names no cpu
        return jax.devices()[0]


def planning_scope() -> contextlib.AbstractContextManager:
    """Where the planners run: a context with :func:`planning_device` as JAX's default device where that changes
    anything (a GPU is the default), else nothing — an unneeded default-device context costs a compile of every
    program again in threads that do not inherit it (bang compiles in threads: 1.1 s more of a cold plan)."""
    device = planning_device()
    if jax.config.jax_default_device is None and jax.default_backend() == device.platform:
        return contextlib.nullcontext()
    return jax.default_device(device)


def on_cpu() -> bool:
    """Whether programs traced now run on a CPU (the default device in force, else the default backend)."""
    device = jax.config.jax_default_device
    if device is None:
        return jax.default_backend() == "cpu"
    return (device if isinstance(device, str) else device.platform) == "cpu"


__all__ = ["configure_jax", "jax", "on_cpu", "planning_device", "planning_scope"]
