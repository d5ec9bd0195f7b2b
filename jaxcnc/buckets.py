"""Static shapes for compiled kernels: sizes are padded to a few buckets, so a new job of similar
size reuses the compiled program instead of compiling again.

Buckets are ``2^k · (1, 1.25, 1.5, 1.75)`` (at least ``MIN_BUCKET``): at most a quarter of a kernel's
work is padding, and a run compiles each kernel once, for the bucket its size falls in.
"""

from __future__ import annotations

import numpy as np

MIN_BUCKET = 256
#: Buckets per doubling of the size.
STEPS = 4


def bucket_size(n: int) -> int:
    """The padded length for ``n`` items (see the module docstring)."""
    if n <= MIN_BUCKET:
        return MIN_BUCKET
    base = 1 << (int(n - 1).bit_length() - 1)  # the largest power of two below n
    step = base // STEPS
    return base + step * -(-(n - base) // step)


def pad_rows(a: np.ndarray, n: int, fill) -> np.ndarray:
    """``a`` followed by rows of ``fill`` up to ``n`` rows."""
    pad = [(0, n - a.shape[0])] + [(0, 0)] * (a.ndim - 1)
    return np.pad(a, pad, constant_values=fill)
