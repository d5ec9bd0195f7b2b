"""The planning grid: spans cut into intervals of the path parameter, with the path's derivatives at their ends.

Along the path ``q(s)`` every axis moves as ``q̇ = q' ṡ`` and ``q̈ = q' s̈ + q'' ṡ²``, with ``q'`` and
``q''`` the derivatives in the path parameter ``s`` (:mod:`jaxcnc.geometry.evaluate`; on lines and
arcs ``s`` is arc length, ``q'`` the unit tangent and ``q''`` the curvature vector; on polynomial
spans ``|q'|`` is close to 1). The phase-plane planner (:mod:`jaxcnc.planners.phaseplane`) needs
``q'`` and ``q''`` at the ends of each interval on which it holds ``s̈`` constant:

* a line has constant ``q'`` and ``q'' = 0``: one interval per line is exact;
* an arc or NURBS piece is cut into equal intervals turning by at most ``MAX_TURN_RAD``
  each, so that ``q'`` and ``q''`` change little inside one (the planner keeps ``GRID_MARGIN`` of
  the acceleration for what they do change and checks interval midpoints, cutting finer where
  needed; the tick table is verified independently);
* a blend is cut into intervals turning by at most ``BLEND_TURN_RAD``, each with a *box*: bounds
  of ``q'`` and ``q''`` over the whole interval — ``BOX_SAMPLES`` samples, widened by ``h²/8`` times the
  largest second derivative of each (``q'''`` resp. ``q''''`` sampled, times ``BOX_SAFETY``),
  which bounds how far a function rises between samples ``h`` apart above the higher of them — so
  the planner's rows hold everywhere inside and a blend needs no refinement
  (:mod:`jaxcnc.planners.phaseplane`);
* a point span (dwell, event) is one interval of zero length.

The grid depends on the geometry alone — not on the feed or the tick rate — so a program plans to
the same motion at any tick rate.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import reduce

import jax.numpy as jnp
import numpy as np

from jaxcnc.buckets import bucket_size
from jaxcnc.geometry.evaluate import arc_trig, evaluate_path, window_span_arrays
from jaxcnc.geometry.kinds import CURVED_KINDS, SpanKind, kind_in
from jaxcnc.geometry.spans import Spans
from jaxcnc.jaxconfig import on_cpu  # (and float64)
from jaxcnc.jitcache import cached_jit
from jaxcnc.planners.limits import node_chord_speed

MAX_TURN_RAD = 0.0175  # 1°
#: A boxed (blend) interval turns at most this much, and a blend piece has at least this many
#: (the box of one interval spans the piece's whole range of q' and q''; four narrow them enough that
#: the CAM polylines and the peers' programs plan within 0.3 % of the unboxed planner's times).
BLEND_TURN_RAD = np.deg2rad(5.0)
BLEND_MIN_INTERVALS = 4
#: Samples of the path's derivatives 1-4 per boxed interval (ends included).
BOX_SAMPLES = 5
#: Safety factor on the sampled derivative maxima that widen a box.
BOX_SAFETY = 1.25
#: Fraction of the acceleration and the axis speeds kept back on curved intervals without a box for the change of q'
#: and q'' inside one (a box bounds that change: blends keep none back).
GRID_MARGIN = 2e-3
MAX_INTERVALS_PER_SPAN = 1 << 16


@dataclass(frozen=True, eq=False)
class Grid:
    """Intervals in path order (NumPy arrays with ``m`` rows).

    Attributes:
        span: ``(m,)`` the span each interval lies on.
        s_start: ``(m,)`` path parameter from the span's start to the interval's start (mm).
        delta: ``(m,)`` mm, the interval's length in the path parameter (0 for point spans).
        t_a, k_a: ``(m, 3)`` ``q'`` and ``q''`` (1/mm) at the interval's start.
        t_b, k_b: ``(m, 3)`` the same at its end.
        curved: ``(m,)`` bool, the interval lies on an arc, NURBS piece or blend.
        boxed: ``(m,)`` bool, the interval has a box (blends): ``t_lo ≤ q' ≤ t_hi`` and
            ``k_lo ≤ q'' ≤ k_hi`` ``(m, 3)`` componentwise everywhere inside it (elsewhere copies of
            the start's values, unused).
        speed_hi: ``(m,)`` where ``boxed``, a bound on ``|q'|`` everywhere inside the interval (the samples' largest
            ``|q'|`` plus the norm of the ``q'`` box's pad): the feed's cap there (the norm of the box's corner
            exceeds ``|q'|`` by about half the interval's turn; 0 elsewhere, unused).
        axis_major: the eight ``(m, 3)`` fields' storage, ``{name: (3, mb)}`` arrays aligned to
            ``ALIGN_BYTES`` and padded with zeros to ``mb ≥ m`` columns (each field is ``axis_major[name][:, :m].T``):
            the layout the planner's compiled programs read, in place.
    """

    span: np.ndarray
    s_start: np.ndarray
    delta: np.ndarray
    t_a: np.ndarray
    k_a: np.ndarray
    t_b: np.ndarray
    k_b: np.ndarray
    curved: np.ndarray
    boxed: np.ndarray
    t_lo: np.ndarray
    t_hi: np.ndarray
    k_lo: np.ndarray
    k_hi: np.ndarray
    speed_hi: np.ndarray
    axis_major: dict[str, np.ndarray] | None = None

    def __len__(self) -> int:
        return int(self.span.shape[0])


#: The grid's ``(m, 3)`` fields, stored axis-major (see :attr:`Grid.axis_major`).
AXIS_FIELDS = ("t_a", "k_a", "t_b", "k_b", "t_lo", "t_hi", "k_lo", "k_hi")
#: Alignment (bytes) at which the CPU backend takes a NumPy array without copying it (``jax.device_put``).
ALIGN_BYTES = 64


def aligned_array(shape: int | tuple[int, ...], dtype=np.float64, zeros: bool = False) -> np.ndarray:
    """An array whose data start on an ``ALIGN_BYTES`` boundary: a compiled program reads it in place (an
    unaligned array is copied on every call). ``zeros``: filled with zeros, else uninitialised."""
    dtype = np.dtype(dtype)
    size = int(np.prod(shape)) * dtype.itemsize
    raw = (np.zeros if zeros else np.empty)(size + ALIGN_BYTES, np.uint8)
    skip = -raw.ctypes.data % ALIGN_BYTES
    return raw[skip : skip + size].view(dtype).reshape(shape)


def is_curved(kind: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: the span kind has curvature (arc, NURBS piece or blend)."""
    return kind_in(kind, CURVED_KINDS)


def interval_counts(spans: Spans) -> np.ndarray:
    """``(n,)`` number of grid intervals of each span (1 for lines and points), from its turning."""
    turning = spans.length * spans.kappa_max
    blend = spans.kind == SpanKind.BLEND
    n = np.ceil(turning / np.where(blend, BLEND_TURN_RAD, MAX_TURN_RAD))
    n = np.where(blend, np.maximum(n, BLEND_MIN_INTERVALS), n)
    n = np.where(is_curved(spans.kind), np.clip(n, 1, MAX_INTERVALS_PER_SPAN), 1)
    return n.astype(np.int64)


@cached_jit(static_argnames=("order", "only"))
def path_frame(
    arrays: dict, span: jnp.ndarray, s: jnp.ndarray, order: int = 2, only: str | None = None
) -> tuple[jnp.ndarray, ...]:
    """The path's derivatives 1..``order`` (each ``(m, 3)``) at ``s`` along span ``span`` ``(m,)`` (``only``: as
    :func:`~jaxcnc.geometry.evaluate.evaluate_path`'s, every queried span of that family)."""
    return evaluate_path(arrays, span, s, order, xp=jnp, only=only)[1:]


def device_spans(spans: Spans, first: int = 0, last: int | None = None) -> dict[str, jnp.ndarray]:
    """The arrays :func:`frames_at` reads for spans ``first..last-1`` (all by default; row ``k`` is span
    ``first + k``): only those spans and the arc and poly rows they use, each table padded to a bucket, so
    that a window of a long program uploads its own rows alone and the compiled kernels see few sizes."""
    last = len(spans) if last is None else last
    return window_span_arrays(spans, first, last, bucket_size(last - first), None)


def frames_at(
    arrays: dict, span: np.ndarray, s: np.ndarray, order: int = 2, only: str | None = None
) -> tuple[np.ndarray, ...]:
    """:func:`path_frame` for NumPy queries ``(q,)``, padded to a bucket (few compiled sizes).

    ``arrays`` comes from :func:`device_spans`; ``only="arc"`` where every queried span is an arc or helix (the
    same values; the other kinds' formulas are not evaluated).
    """
    q = span.size
    m = bucket_size(q)
    which = np.zeros(m, np.int64)
    where = np.zeros(m)
    which[:q], where[:q] = span, s
    return tuple(np.asarray(d)[:q] for d in path_frame(arrays, which, where, order, only))


@cached_jit(static_argnames=("only",))
def frame_columns(
    arrays: dict, span: jnp.ndarray, s: jnp.ndarray, only: str | None, trig: tuple | None = None, chord=None
) -> tuple[jnp.ndarray, ...]:
    """``q'`` and ``q''`` at ``s`` along spans ``span`` ``(q,)`` (:func:`path_frame`) as six ``(q,)`` columns (x, y,
    z of each): separate outputs of one fused loop (a transposed ``(3, q)`` output would make XLA evaluate the
    frame once per row). ``trig``: :func:`arc_trig_columns` of the same points where all are on arcs. ``chord``:
    ``(chord_tol_mm, tick_hz)`` to append :func:`~.limits.node_chord_speed` at the points as a seventh column (its
    arc sine costs more than the rest of an interval's caps: once per curved node here, instead of at both ends
    of every interval)."""
    _, t, k = evaluate_path(arrays, span, s, 2, xp=jnp, only=only, trig=trig)
    cols = tuple(t[:, i] for i in range(3)) + tuple(k[:, i] for i in range(3))
    return cols if chord is None else cols + (node_chord_speed(cols[:3], cols[3:], *chord),)


@cached_jit
def arc_trig_columns(arrays: dict, span: jnp.ndarray, s: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """:func:`~jaxcnc.geometry.evaluate.arc_trig` ``(q,)`` as a program of its own: :func:`frame_columns`' six
    output loops read the angles' cosines and sines instead of evaluating them six times over (12 → 4 ms CPU
    for 160k points)."""
    return arc_trig(arrays, span, s, xp=jnp)


def node_frames(arrays: dict, span: np.ndarray, s: np.ndarray, only: str | None, chord=None) -> tuple:
    """:func:`frame_columns` at ``q`` points (span ``span``, ``s`` mm along it; NumPy), padded to a bucket in
    aligned arrays (read in place), the arcs' cosines and sines apart where ``only="arc"``
    (:func:`arc_trig_columns`): the columns as device arrays of the bucket's length, the first ``q`` rows the
    points'."""
    q = span.size
    which, where = aligned_array(bucket_size(q), np.int64), aligned_array(bucket_size(q))
    which[:q], where[:q] = span, s
    which[q:], where[q:] = 0, 0.0
    trig = arc_trig_columns(arrays, which, where) if only == "arc" else None
    return frame_columns(arrays, which, where, only, trig, chord)


#: Boxed intervals per call of :func:`_boxes` on a CPU: a chunk's intermediates stay in the core's cache (at
#: 100k blocks, 400k intervals: 0.12 s CPU in chunks of 8192, 0.17 s in chunks of 16384, 0.22 s in one call).
BOX_CHUNK = 8192


@cached_jit
def _boxes(arrays: dict, span: jnp.ndarray, s0: jnp.ndarray, delta: jnp.ndarray) -> tuple[jnp.ndarray, ...]:
    """Ends and boxes of ``q'`` and ``q''`` on intervals ``[s0, s0 + delta]`` of polynomial spans (``(m,)``
    each; returns eight ``(m, 3)`` arrays and the bound on ``|q'|`` ``(m,)`` as :func:`boxes_at`).

    ``BOX_SAMPLES`` points per interval, ends included, each an ``(m,)`` evaluation of its own: the samples'
    extremes are running minima and maxima of ``(m, 3)`` arrays, elementwise, with no ``(m, BOX_SAMPLES, 3)``
    array (whose reductions cost twice the arithmetic). Between samples ``h`` apart a function rises above the
    chord between them (so above the higher sample) by at most ``h²/8 max|f''|``. So ``q'`` lies within the pad
    of the polyline through its samples, componentwise, and ``|q'| ≤ max_j |q'(s_j)| + |pad|`` (the norm is convex:
    on a chord it stays below the higher end): a bound on the tool's speed per unit ``ṡ`` that does not grow with
    the interval's turn as the norm of the box's corner does.
    """
    t, k, d3, d4 = [], [], [], []
    for frac in np.linspace(0.0, 1.0, BOX_SAMPLES):
        _, d1_j, d2_j, d3_j, d4_j = evaluate_path(arrays, span, s0 + delta * frac, 4, jnp, only="blend")
        t.append(d1_j)
        k.append(d2_j)
        d3.append(jnp.abs(d3_j))
        d4.append(jnp.abs(d4_j))
    h2 = (BOX_SAFETY * (delta / (BOX_SAMPLES - 1)) ** 2 / 8)[:, None]
    t_pad = reduce(jnp.maximum, d3) * h2
    k_pad = reduce(jnp.maximum, d4) * h2
    speed_hi = reduce(jnp.maximum, [_norm3(d1_j) for d1_j in t]) + _norm3(t_pad)
    return (
        t[0], k[0], t[-1], k[-1],
        reduce(jnp.minimum, t) - t_pad, reduce(jnp.maximum, t) + t_pad,
        reduce(jnp.minimum, k) - k_pad, reduce(jnp.maximum, k) + k_pad,
        speed_hi,
    )  # fmt: skip


def _norm3(v: jnp.ndarray) -> jnp.ndarray:
    """``(m,)`` norms of ``(m, 3)`` rows, written out elementwise: the same bits whatever ``m`` (a reduction over the
    last axis is vectorised by shape, and its last bit changed between chunk sizes)."""
    return jnp.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2])


def boxes_at(arrays: dict, span: np.ndarray, s0: np.ndarray, delta: np.ndarray) -> tuple[np.ndarray, ...]:
    """:func:`_boxes` for NumPy queries ``(q,)``: ``(t_a, k_a, t_b, k_b, t_lo, t_hi, k_lo, k_hi)``, each ``(q, 3)``,
    and ``speed_hi`` ``(q,)`` (:attr:`Grid.speed_hi`).

    On a CPU in calls of ``BOX_CHUNK`` rows, the last one padded, however few (all dispatched before any is read;
    one row count for every window of every program), else in one call padded to a bucket.
    """
    q = span.size
    out = [np.empty((3, q)) for _ in range(8)] + [np.empty(q)]
    _boxes_into(arrays, span, s0, delta, out, np.arange(q))
    return tuple(o.T for o in out)


def _boxes_into(
    arrays: dict, span: np.ndarray, s0: np.ndarray, delta: np.ndarray, out: list[np.ndarray], cols: np.ndarray
) -> None:
    """:func:`boxes_at` written straight into columns ``cols`` ``(q,)`` of eight axis-major ``(3, n)`` arrays and
    an ``(n,)`` one, ``out`` (no joined ``(q, 3)`` results to scatter afterwards)."""
    q = span.size
    m = BOX_CHUNK if on_cpu() else bucket_size(q)
    n = max(-(-q // m), 1) * m
    which, a, d = np.zeros(n, np.int64), np.zeros(n), np.zeros(n)
    which[:q], a[:q], d[:q] = span, s0, delta
    which[q:] = span[0] if q else 0
    parts = [_boxes(arrays, which[i : i + m], a[i : i + m], d[i : i + m]) for i in range(0, n, m)]
    for i, part in zip(range(0, n, m), parts, strict=True):
        k = min(m, q - i)
        if k <= 0:
            break
        at = cols[i : i + k]
        for dest, res in zip(out, part, strict=True):
            res = np.asarray(res)
            if dest.ndim == 1:
                dest[at] = res[:k]
                continue
            for axis in range(3):
                dest[axis, at] = res[:k, axis]


def cut_spans(
    span_length: np.ndarray, counts: np.ndarray, first: int, last: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(span, s_start, s_end)`` ``(m,)`` of spans ``first..last-1`` cut into ``counts[k]`` equal intervals each
    (``counts`` and ``span_length`` over all spans). Elementwise, so any block of spans gives the same bits as
    the whole; a span's last interval ends at its length exactly."""
    counts = counts[first:last]
    span = np.repeat(np.arange(first, last), counts)
    j = np.arange(span.size) - np.repeat(np.cumsum(counts) - counts, counts)
    local = span - first
    step = span_length[first:last] / counts
    s_start = j * step[local]
    s_end = np.where(j == counts[local] - 1, span_length[span], (j + 1) * step[local])
    return span, s_start, s_end


def build_grid(
    spans: Spans,
    counts: np.ndarray,
    arrays: dict | None = None,
    first: int = 0,
    last: int | None = None,
    pad_to: int | None = None,
) -> Grid:
    """Cut spans ``first..last-1`` (all by default) into ``counts[k]`` equal intervals each and evaluate the
    frame at their ends.

    ``arrays``: :func:`device_spans` of ``spans`` for the same ``first``, ``last`` when the caller has them
    already (row 0 is span ``first``). ``pad_to``: columns of :attr:`Grid.axis_major` (at least the
    interval count; by default that count).
    """
    last = len(spans) if last is None else last
    span, s_start, s_end = cut_spans(spans.length, counts, first, last)
    m = span.size
    local = span - first
    delta = s_end - s_start
    kind = spans.kind[span]
    curved = is_curved(kind)
    boxed = kind == SpanKind.BLEND
    width = m if pad_to is None else pad_to
    # every column of the fields below is written (the padding zeroed), but k_a and k_b, whose lines stay 0
    major = {f: aligned_array((3, width), zeros=f in ("k_a", "k_b")) for f in AXIS_FIELDS}
    for f in AXIS_FIELDS:
        major[f][:, m:] = 0.0
    for f, field in (("t_a", spans.tangent_in), ("t_b", spans.tangent_out)):
        cols = np.ascontiguousarray(field[first:last].T)  # (3, the window's spans)
        for i in range(3):
            np.take(cols[i], local, out=major[f][i, :m])
    plain = np.flatnonzero(curved & ~boxed)
    box = np.flatnonzero(boxed)
    if plain.size or box.size:
        arrays = device_spans(spans, first, last) if arrays is None else arrays
    if plain.size:  # the frames once per node: an interval's end is the next one's start (the same s, bit for bit)
        only = "arc" if np.all(kind[plain] == SpanKind.ARC) else None
        ends = np.flatnonzero(np.append(span[plain[1:]] != span[plain[:-1]], True))  # each span's last interval
        n_c = plain.size
        which = np.concatenate([local[plain], local[plain[ends]]])
        where = np.concatenate([s_start[plain], s_end[plain[ends]]])
        cols = [np.asarray(c) for c in node_frames(arrays, which, where, only)]
        at_b = np.arange(1, n_c + 1)  # the end node: the next interval's start, or its span's end
        at_b[ends] = n_c + np.arange(ends.size)
        for i in range(3):
            major["t_a"][i, plain], major["k_a"][i, plain] = cols[i][:n_c], cols[3 + i][:n_c]
            major["t_b"][i, plain], major["k_b"][i, plain] = cols[i][at_b], cols[3 + i][at_b]
    for f, like in (("t_lo", "t_a"), ("t_hi", "t_a"), ("k_lo", "k_a"), ("k_hi", "k_a")):
        major[f][:, :m] = major[like][:, :m]  # copies of the start's values where there is no box
    speed_hi = np.zeros(m)
    if box.size:
        _boxes_into(arrays, local[box], s_start[box], delta[box], [major[f] for f in AXIS_FIELDS] + [speed_hi], box)
    return Grid(
        span=span,
        s_start=s_start,
        delta=delta,
        curved=curved,
        boxed=boxed,
        speed_hi=speed_hi,
        axis_major=major,
        **{f: major[f][:, :m].T for f in AXIS_FIELDS},
    )


@dataclass(frozen=True, eq=False)
class GridPiece:
    """The grid rows of spans ``first..last-1`` as cut with ``counts`` (``(last - first,)``, not shared): a part of
    a window's grid built ahead of it (with ``arrays``, the :func:`device_spans` of its spans), or the part of the
    window before that the next one starts with.

    Every row of a grid depends on its span and that span's count alone, bit for bit (:func:`cut_spans` is
    elementwise; the frames and boxes evaluate each interval alone), so a window's grid can be joined from
    pieces built for other span ranges (:func:`join_pieces`).
    """

    first: int
    last: int
    counts: np.ndarray
    grid: Grid
    arrays: dict | None = None

    @staticmethod
    def of(grid: Grid, counts: np.ndarray, row: int = 0) -> GridPiece:
        """The rows of ``grid`` from ``row`` (the first of its span) to its end, copied when ``row > 0`` (a small
        tail: the window's arrays are not kept alive by it)."""
        first, last = int(grid.span[row]), int(grid.span[-1]) + 1
        if row:
            grid = _grid_rows_copy(grid, row, len(grid))
        return GridPiece(first, last, counts[first:last].copy(), grid)

    def rows(self, first: int, last: int) -> tuple[int, int]:
        """The rows of spans ``first..last-1`` (within the piece's)."""
        start = int(self.counts[: first - self.first].sum())
        return start, start + int(self.counts[first - self.first : last - self.first].sum())


#: The grid's ``(m,)`` fields.
_ROW_FIELDS = ("span", "s_start", "delta", "curved", "boxed", "speed_hi")


def _grid_rows_copy(grid: Grid, start: int, stop: int) -> Grid:
    """Rows ``start..stop-1`` of ``grid``, copied (axis-major storage of exactly those columns)."""
    major = {f: aligned_array((3, stop - start)) for f in AXIS_FIELDS}
    for f in AXIS_FIELDS:
        major[f][...] = grid.axis_major[f][:, start:stop]
    one = {f: getattr(grid, f)[start:stop].copy() for f in _ROW_FIELDS}
    return Grid(**one, axis_major=major, **{f: major[f].T for f in AXIS_FIELDS})


def join_pieces(pieces: list[GridPiece], counts: np.ndarray, first: int, last: int, pad_to: int) -> Grid | None:
    """The grid :func:`build_grid` makes of spans ``first..last-1`` with ``counts`` and ``pad_to``, joined from
    ``pieces`` (the first that covers a span with its count, in their order), or ``None`` where they do not cover
    those spans with these counts (spans cut finer since the piece was built)."""
    parts, at = [], first
    while at < last:
        for piece in pieces:
            stop = min(last, piece.last)
            if piece.first <= at < stop and np.array_equal(
                piece.counts[at - piece.first : stop - piece.first], counts[at:stop]
            ):
                parts.append((piece.grid, *piece.rows(at, stop)))
                at = stop
                break
        else:
            return None
    m = sum(b - a for _, a, b in parts)
    major = {f: aligned_array((3, pad_to), zeros=True) for f in AXIS_FIELDS}
    col = 0
    for grid, a, b in parts:
        for f in AXIS_FIELDS:
            major[f][:, col : col + b - a] = grid.axis_major[f][:, a:b]
        col += b - a
    one = {f: np.concatenate([getattr(g, f)[a:b] for g, a, b in parts]) for f in _ROW_FIELDS}
    return Grid(**one, axis_major=major, **{f: major[f][:, :m].T for f in AXIS_FIELDS})
