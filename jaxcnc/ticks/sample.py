"""Sampling the time law at the tick rate: tick → (span, s) → position, batched on the device.

Any planner's time law (:class:`~jaxcnc.planners.protocol.TimeLaw`) hands this stage its
:class:`~jaxcnc.planners.protocol.DeviceLaw`: device arrays and a pure function giving, for each tick,
the span and the path parameter within it (for a :class:`~jaxcnc.planners.timelaw.Plan`: a search over
segment first ticks, then the segment's trapezoid). The position comes from the span's closed form
(:mod:`jaxcnc.geometry.evaluate`), in the same compiled program. Ticks are processed in fixed-size chunks
(one compiled program per kind of time law and bucket size); positions are quantised from the exact
position each tick — rounding never accumulates.
"""

from __future__ import annotations

from collections.abc import Iterator
from functools import partial
from typing import Protocol

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size
from jaxcnc.format import FINE_SCALE
from jaxcnc.geometry.evaluate import evaluate_path, span_arrays
from jaxcnc.geometry.spans import pad_spans
from jaxcnc.planners.job import PlannedJob

CHUNK_TICKS = 1 << 16


@partial(jax.jit, static_argnames=("chunk", "law_fn"))
def _positions_chunk(
    first: jnp.ndarray, n_last: jnp.ndarray, law_fn, law: dict, spans: dict, chunk: int
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Exact program-axis positions ``(chunk, 3)`` and their span, for ticks ``first + i``:
    tick → (span, s) by the time law's ``law_fn`` → position."""
    tick = jnp.minimum(first + jnp.arange(chunk, dtype=jnp.int64), n_last)
    span, s = law_fn(law, tick)
    (p,) = evaluate_path(spans, span, s, xp=jnp)
    return p, span


@jax.jit
def quantize(p_mm: jnp.ndarray, discrete_mm: float) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Integer discretes ``round(p / q)`` and the residual in 2^-32 discretes (both int32)."""
    x = p_mm / discrete_mm
    n = jnp.round(x)
    frac = jnp.clip(jnp.round((x - n) * FINE_SCALE), -(2.0**31), 2.0**31 - 1)
    return n.astype(jnp.int32), frac.astype(jnp.int32)


class Sampler(Protocol):
    """Anything the table writer can sample: ``n_rows`` and chunks of machine-axis positions."""

    @property
    def n_rows(self) -> int: ...

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]: ...


class ArraySampler:
    """A :class:`Sampler` of positions already computed: ``pos`` ``(n, n_axes)`` mm, handed out ``chunk`` rows at a
    time (split and stage + galvo plans are sampled at the tick rate when they are planned)."""

    def __init__(self, pos: np.ndarray, chunk: int = CHUNK_TICKS):
        self.pos, self.chunk = pos, chunk

    @property
    def n_rows(self) -> int:
        return int(self.pos.shape[0])

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        for first in range(0, self.n_rows, self.chunk):
            yield first, self.pos[first : first + self.chunk]


def machine_axes(program_p: np.ndarray, axis_source: np.ndarray, home: np.ndarray) -> np.ndarray:
    """Map program x, y, z columns ``(m, 3)`` to machine axes (``axis_source[i] = -1``: stays at home)."""
    out = np.empty((program_p.shape[0], len(axis_source)))
    for i, src in enumerate(axis_source):
        out[:, i] = program_p[:, src] if src >= 0 else home[i]
    return out


class TickSampler:
    """Samples a planned job at its tick rate, chunk by chunk, in machine-axis order (any time law)."""

    def __init__(self, job: PlannedJob, chunk: int = CHUNK_TICKS):
        self.job, self.chunk = job, chunk
        m_axes = job.machine.axis_names
        self._src = np.asarray(job.axis_source)
        self._home = np.array([job.machine.axis(a).home for a in m_axes])
        self._law_fn, self._law = job.plan.device_law()
        self._spans = span_arrays(pad_spans(job.spans, bucket_size(len(job.spans))), xp=jnp)

    @property
    def n_rows(self) -> int:
        return self.job.plan.n_ticks + 1

    def program_positions(self, first: int, count: int) -> tuple[np.ndarray, np.ndarray]:
        """Exact x, y, z positions ``(count, 3)`` mm and span index of ticks ``first..``."""
        p, span = _positions_chunk(
            np.int64(first), np.int64(self.job.plan.n_ticks), self._law_fn, self._law, self._spans, self.chunk
        )
        return np.asarray(p)[:count], np.asarray(span)[:count]

    def machine_positions(self, program_p: np.ndarray) -> np.ndarray:
        """Map program x, y, z columns to the machine's axes (undriven axes stay at home)."""
        return machine_axes(program_p, self._src, self._home)

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(first_tick, positions_mm)`` chunks covering ticks ``0..n_ticks``."""
        for first in range(0, self.n_rows, self.chunk):
            count = min(self.chunk, self.n_rows - first)
            p, _ = self.program_positions(first, count)
            yield first, self.machine_positions(p)
