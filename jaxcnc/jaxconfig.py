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
is kept.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)


def configure_jax(cache_dir: str | None = None) -> str | None:
    """Float64 on, and the persistent compile cache in ``cache_dir`` (default ``$JAXCNC_CACHE_DIR`` or
    ``~/.cache/jaxcnc/jax``; ``""`` for none). Idempotent; returns the cache directory in use, if any."""
    jax.config.update("jax_enable_x64", True)
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


__all__ = ["configure_jax", "jax"]
