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

import queue
import threading
from collections.abc import Callable, Iterable, Iterator
from typing import NamedTuple, Protocol, TypeVar

import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size
from jaxcnc.format import FINE_SCALE
from jaxcnc.geometry.evaluate import evaluate_path, span_arrays, window_span_arrays
from jaxcnc.geometry.spans import pad_spans
from jaxcnc.jitcache import cached_jit
from jaxcnc.planners.job import PlannedJob
from jaxcnc.planners.protocol import LawWindow

T = TypeVar("T")

CHUNK_TICKS = 1 << 16


@cached_jit(static_argnames=("chunk", "law_fn"))
def _positions_chunk(
    first: jnp.ndarray, n_last: jnp.ndarray, law_fn, law: dict, spans: dict, chunk: int
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Exact program-axis positions ``(chunk, 3)`` and their span, for ticks ``first + i``:
    tick → (span, s) by the time law's ``law_fn`` → position."""
    tick = jnp.minimum(first + jnp.arange(chunk, dtype=jnp.int64), n_last)
    span, s = law_fn(law, tick)
    (p,) = evaluate_path(spans, span, s, xp=jnp)
    return p, span


@cached_jit
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


def sampled_ahead(chunks: Iterable[T], depth: int = 2) -> Iterator[T]:
    """The items of ``chunks``, made on a worker thread up to ``depth`` items ahead of the caller.

    The tick stage samples a chunk (XLA, which releases the GIL) while the writer quantises, derives the laser
    and checksums and writes the chunk before it (NumPy, zlib and file writes, which release it too): on a 2-core
    machine the two overlap instead of taking turns. The items and their order are those of ``chunks``; an
    exception raised making one is raised here, in its place. When the caller stops early (an error, Ctrl-C), the
    worker is told to stop and joined: it finishes at most the chunk it is making.
    """
    out: queue.Queue = queue.Queue(maxsize=max(1, depth))
    stop = threading.Event()
    end = object()

    def put(item: tuple) -> bool:
        while not stop.is_set():
            try:
                out.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def work() -> None:
        try:
            for item in chunks:
                if not put((item, None)):
                    return
            put((end, None))
        except BaseException as exc:  # handed to the caller, raised there
            put((end, exc))

    worker = threading.Thread(target=work, name="jaxcnc-ticks-ahead", daemon=True)
    worker.start()
    try:
        while True:
            item, exc = out.get()
            if item is end:
                if exc is not None:
                    raise exc
                return
            yield item
    finally:
        stop.set()
        worker.join()


def machine_axes(program_p: np.ndarray, axis_source: np.ndarray, home: np.ndarray) -> np.ndarray:
    """Map program x, y, z columns ``(m, 3)`` to machine axes (``axis_source[i] = -1``: stays at home)."""
    out = np.empty((program_p.shape[0], len(axis_source)))
    for i, src in enumerate(axis_source):
        out[:, i] = program_p[:, src] if src >= 0 else home[i]
    return out


#: Segments of a time law the tick stage holds on the device at once. A longer plan is sampled window by window
#: (:meth:`~jaxcnc.planners.protocol.TimeLaw.device_window`): its segments and the spans under them uploaded a window
#: at a time, every window in one shape, so the tick stage's memory does not grow with the job (a 1 M-block blended
#: contour, 5.2 M segments: 2.8 GB peak with the whole law on the device, docs/planning.md "Memory").
WINDOW_SEGMENTS = 1 << 17
#: Fewest span rows a window's spans are padded to.
WINDOW_MIN_SPANS = 1 << 12


class _Window(NamedTuple):
    """The part of a long job on the device: ticks ``tick_from..tick_end-1``, its law, its spans from ``span0``."""

    tick_from: int
    tick_end: int
    fn: Callable
    law: dict
    spans: dict
    span0: int


class TickSampler:
    """Samples a planned job at its tick rate, chunk by chunk, in machine-axis order (any time law).

    A time law of more than ``window_segments`` segments that offers windows is held on the device a window at a
    time (:data:`WINDOW_SEGMENTS`): the same positions, bit for bit."""

    def __init__(self, job: PlannedJob, chunk: int = CHUNK_TICKS, window_segments: int = WINDOW_SEGMENTS):
        self.job, self.chunk = job, chunk
        m_axes = job.machine.axis_names
        self._src = np.asarray(job.axis_source)
        self._home = np.array([job.machine.axis(a).home for a in m_axes])
        self._window_segments = window_segments
        self._window: _Window | None = None
        first = job.plan.device_window(0, window_segments) if len(job.plan) > window_segments else None
        self._windowed = first is not None  # (None: a law sampled whole)
        if self._windowed:
            self._window = self._upload(0, first)
        else:
            self._law_fn, self._law = job.plan.device_law()
            self._spans = span_arrays(pad_spans(job.spans, bucket_size(len(job.spans))), xp=jnp)

    @property
    def n_rows(self) -> int:
        return self.job.plan.n_ticks + 1

    def program_positions(self, first: int, count: int) -> tuple[np.ndarray, np.ndarray]:
        """Exact x, y, z positions ``(count, 3)`` mm and span index of ticks ``first..`` (at most a chunk)."""
        n_last = np.int64(self.job.plan.n_ticks)
        if not self._windowed:
            p, span = _positions_chunk(np.int64(first), n_last, self._law_fn, self._law, self._spans, self.chunk)
            return np.asarray(p)[:count], np.asarray(span)[:count]
        p_out, span_out = np.empty((count, 3)), np.empty(count, np.int64)
        done = 0
        while done < count:  # the chunk's ticks from the window that holds them (more than one where a window ends)
            tick = first + done
            w = self._window_at(tick)
            p, span = _positions_chunk(np.int64(tick), n_last, w.fn, w.law, w.spans, self.chunk)
            k = min(count - done, w.tick_end - tick)
            p_out[done : done + k] = np.asarray(p)[:k]
            span_out[done : done + k] = np.asarray(span)[:k] + w.span0
            done += k
            del w, p, span  # the next window is made with this one freed
        return p_out, span_out

    def _window_at(self, tick: int) -> _Window:
        """The device window that holds ``tick`` (the current one, or the next one uploaded in its place)."""
        w = self._window
        if w is None or not w.tick_from <= tick < w.tick_end:
            self._window = w = None  # the one before freed first
            tick_in = min(tick, self.job.plan.n_ticks)
            w = self._window = self._upload(tick, self.job.plan.device_window(tick_in, self._window_segments))
        return w

    def _upload(self, tick: int, win: LawWindow) -> _Window:
        """The window ``win`` (asked for at ``tick``) with the spans under it, on the device."""
        n_ticks = self.job.plan.n_ticks
        if win.tick_end <= min(tick, n_ticks):
            raise RuntimeError(f"tick {tick}: no window of {self._window_segments} segments holds it (a bug)")
        # the spans under a window, padded to a power of two: every window's law has the same shape, but a window
        # holds fewer spans than segments (a blended contour: ~31k of 131k), and copying and uploading padding
        # rows was a third of the tick stage; a job's windows fall in one or two such sizes (each compiles once)
        rows = max(WINDOW_MIN_SPANS, 1 << int(win.span_last - win.span_first - 1).bit_length())
        spans = window_span_arrays(self.job.spans, win.span_first, win.span_last, rows, rows)
        end = win.tick_end if win.tick_end <= n_ticks else np.iinfo(np.int64).max  # the last: and past the end
        return _Window(tick, end, win.law.fn, win.law.arrays, spans, win.span_first)

    def machine_positions(self, program_p: np.ndarray) -> np.ndarray:
        """Map program x, y, z columns to the machine's axes (undriven axes stay at home)."""
        return machine_axes(program_p, self._src, self._home)

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(first_tick, positions_mm)`` chunks covering ticks ``0..n_ticks``."""
        for first in range(0, self.n_rows, self.chunk):
            count = min(self.chunk, self.n_rows - first)
            p, _ = self.program_positions(first, count)
            yield first, self.machine_positions(p)
