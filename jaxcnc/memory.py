"""The C heap of the planning process (glibc only; elsewhere nothing happens).

A plan of a million blocks frees and allocates arrays of hundreds of megabytes in total, from NumPy and
from XLA's worker threads alike. glibc gives each thread that meets a locked heap an arena of its own (up
to eight per core), and memory freed into one arena serves only that arena's next allocations: the pages
stay resident, spread over the arenas. :func:`limit_arenas` caps the arenas at two (``mallopt(M_ARENA_MAX)``)
once, by the planning entry points (:func:`tune_heap` from :func:`jaxcnc.jaxconfig.configure_jax`, called first
by the ``jaxcnc`` commands and the jobs API; importing does nothing; set later, once the arenas exist, it does
not help):
1 M blocks with exact corners, peak resident 957-1018 -> 938-945 MB; CPU within the process-to-process spread,
though a 100k-block plan more often runs in its page-faulting mode (docs/planning.md, "Memory").
``MALLOC_ARENA_MAX`` in the environment, if set, is the user's choice and is left as it is.

The heap's thresholds (:func:`fix_thresholds`). glibc serves a request above its mmap threshold (128 KiB at
start) with a fresh mapping, unmapped again when freed, and raises the threshold to the size of such a block
when one is freed (up to 32 MiB; the trim threshold to twice that). So a process plans in one of two modes:
where no large block has been freed yet, or the heap was trimmed, every window's arrays are fresh pages again
(100k-block exact plan: 10-20k page faults, 0.20-0.26 s CPU); once the thresholds have risen, none (0.18 s).
Which mode a process is in depended on the order of its first frees. :func:`fix_thresholds` sets both to the
values glibc's own adjustment ends at (mmap 32 MiB, trim 64 MiB) from the start: every plan runs in the second
mode (0-3 page faults per 100k-block plan after the first). The explicit trims of large plans
(:func:`release_free_heap`) still hand memory back: 1 M blocks exact peaks at 913-951 MB (940 before).

Measured and not done: a *small* fixed mmap threshold (128 KiB-4 MiB, so that large arrays are unmapped when
freed) lowers the 1 M-block peak a little, but every plan then faults its working memory in again: +60-130 %
CPU; fixing the trim threshold alone fixes the mmap threshold at 128 KiB (134k page faults per 100k-block plan).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from functools import cache

#: ``mallopt`` parameter numbers (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
M_ARENA_MAX = -8
#: Arenas the planning process uses at most.
PLANNING_ARENAS = 2
#: The mmap and trim thresholds :func:`fix_thresholds` sets: where glibc's dynamic adjustment ends on 64-bit
#: systems (``DEFAULT_MMAP_THRESHOLD_MAX`` = 32 MiB, the trim threshold twice the mmap threshold).
MMAP_THRESHOLD_BYTES = 32 << 20
TRIM_THRESHOLD_BYTES = 64 << 20


def _glibc_mallopt():
    """glibc's ``mallopt``, or ``None`` on other C libraries."""
    try:
        if not (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc"):
            return None
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError, ValueError):  # no confstr name, no libc, no mallopt
        return None


def limit_arenas(arenas: int = PLANNING_ARENAS) -> bool:
    """Cap glibc's malloc arenas at ``arenas`` unless ``MALLOC_ARENA_MAX`` is set; ``True`` when applied.
    A no-op (``False``) on other C libraries or when ``mallopt`` cannot be called."""
    if os.environ.get("MALLOC_ARENA_MAX"):
        return False
    mallopt = _glibc_mallopt()
    return mallopt is not None and bool(mallopt(M_ARENA_MAX, int(arenas)))


def fix_thresholds(mmap_bytes: int = MMAP_THRESHOLD_BYTES, trim_bytes: int = TRIM_THRESHOLD_BYTES) -> bool:
    """Fix glibc's mmap and trim thresholds (module docstring); ``True`` when applied. Left alone when the
    environment sets either (``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_TRIM_THRESHOLD_`` or ``GLIBC_TUNABLES``); a
    no-op (``False``) on other C libraries."""
    if any(os.environ.get(k) for k in ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES")):
        return False
    mallopt = _glibc_mallopt()
    if mallopt is None:
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, int(mmap_bytes))) and bool(mallopt(M_TRIM_THRESHOLD, int(trim_bytes)))


def tune_heap() -> bool:
    """:func:`limit_arenas` and :func:`fix_thresholds`, what the planning entry points call once, first;
    ``True`` when both applied."""
    arenas = limit_arenas()
    return fix_thresholds() and arenas


@cache
def _malloc_trim():
    """glibc's ``malloc_trim``, or ``None`` on other C libraries."""
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):  # not glibc: nothing to do
        return None


def release_free_heap() -> None:
    """Hand the C heap's free pages back to the operating system (glibc's ``malloc_trim``; a no-op elsewhere).

    The arrays of a planning stage or window (NumPy's and XLA's alike) are freed to glibc's heap, which keeps
    pages it cannot trim from the top mapped, in pieces a later stage's larger arrays do not fit: the resident
    memory of a long program would grow by what earlier stages left behind. The cost is in the page faults
    of memory used again afterwards, so large plans call it between stages only (``topp.TRIM_SEGMENTS``).
    """
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


def available_memory_bytes() -> int | None:
    """The memory the system could give this process now without swapping (Linux's ``MemAvailable``), or
    ``None`` where it does not say."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


__all__ = [
    "PLANNING_ARENAS",
    "available_memory_bytes",
    "fix_thresholds",
    "limit_arenas",
    "release_free_heap",
    "tune_heap",
]
