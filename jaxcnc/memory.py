"""The C heap of the planning process (glibc only; elsewhere nothing happens).

A plan of a million blocks frees and allocates arrays of hundreds of megabytes in total, from NumPy and
from XLA's worker threads alike. glibc gives each thread that meets a locked heap an arena of its own (up
to eight per core), and memory freed into one arena serves only that arena's next allocations: the pages
stay resident, spread over the arenas. :func:`limit_arenas` caps the arenas at two (``mallopt(M_ARENA_MAX)``)
once, by the planning entry points (:func:`jaxcnc.jaxconfig.configure_jax`, called first by the ``jaxcnc``
commands and the jobs API; importing does nothing; set later, once the arenas exist, it does not help):
1 M blocks with exact corners, peak resident 957-1018 -> 938-945 MB; CPU within the process-to-process spread,
though a 100k-block plan more often runs in its page-faulting mode (docs/planning.md, "Memory").
``MALLOC_ARENA_MAX`` in the environment, if set, is the user's choice and is left as it is.

Measured and not done: fixing glibc's mmap threshold (``M_MMAP_THRESHOLD``, so that large arrays are unmapped
when freed) lowers the peak as far, but every plan then faults its working memory in again: +60-130 % CPU.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

#: ``mallopt`` parameter numbers (glibc's malloc.h).
M_ARENA_MAX = -8
#: Arenas the planning process uses at most.
PLANNING_ARENAS = 2


def limit_arenas(arenas: int = PLANNING_ARENAS) -> bool:
    """Cap glibc's malloc arenas at ``arenas`` unless ``MALLOC_ARENA_MAX`` is set; ``True`` when applied.
    A no-op (``False``) on other C libraries or when ``mallopt`` cannot be called."""
    if os.environ.get("MALLOC_ARENA_MAX"):
        return False
    try:
        if not (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc"):
            return False
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return bool(libc.mallopt(M_ARENA_MAX, int(arenas)))
    except (OSError, AttributeError, ValueError):  # no confstr name, no libc, no mallopt
        return False


__all__ = ["PLANNING_ARENAS", "limit_arenas"]
