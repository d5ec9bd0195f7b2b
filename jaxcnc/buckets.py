"""Static shapes for compiled kernels: sizes are padded to a few buckets, so a new job of similar
size reuses the compiled program instead of compiling again."""

from __future__ import annotations

import numpy as np

MIN_BUCKET = 256


def bucket_size(n: int) -> int:
    """The padded length for ``n`` items: the next power of two, at least ``MIN_BUCKET``."""
    return max(MIN_BUCKET, 1 << max(0, int(n - 1).bit_length()))


def pad_rows(a: np.ndarray, n: int, fill) -> np.ndarray:
    """``a`` followed by rows of ``fill`` up to ``n`` rows."""
    pad = [(0, n - a.shape[0])] + [(0, 0)] * (a.ndim - 1)
    return np.pad(a, pad, constant_values=fill)
