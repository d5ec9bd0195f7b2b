"""Import-time JAX configuration of the planning side: float64 everywhere, a compile cache.

Planning needs float64: a 1 h job at 100 kHz has 3.6e8 ticks and µm positions on metre-long
axes. Every planning module imports this module before using JAX. The player side
(:mod:`jaxcnc.hw`) never imports it.

Compiled planning programs are cached on disk (``$JAXCNC_CACHE_DIR``, default
``~/.cache/jaxcnc/jax``), so a command-line run after the first skips most of the JIT compile.
Set ``JAXCNC_CACHE_DIR=""`` to disable the cache.
"""

import os
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

_cache = os.environ.get("JAXCNC_CACHE_DIR", str(Path.home() / ".cache" / "jaxcnc" / "jax"))
if _cache and jax.config.jax_compilation_cache_dir is None:
    try:
        Path(_cache).mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", _cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.05)
    except OSError:  # read-only home: run without the cache
        pass

__all__ = ["jax"]
