"""Jerk-limited time laws: each rest-to-rest group's ``s(t)`` averaged over a window of ``W`` seconds.

A planner's time law has piecewise-constant ``s̈`` — its jerk is unbounded where ``s̈`` steps.
Averaging the path position over the last ``W`` seconds,

    s_W(t) = (1/W) ∫_{t-W}^{t} s(τ) dτ,     ṡ_W = (s(t) - s(t-W)) / W,
    s̈_W = (ṡ(t) - ṡ(t-W)) / W,              s⃛_W = (s̈(t) - s̈(t-W)) / W,

keeps the path (positions are still ``p(s)``), makes ``s̈_W`` a mean of ``s̈`` (never larger) and
bounds the path jerk by the swing of ``s̈`` over ``W``. On a line an axis moves ``x = T s`` with
``|T s̈| ≤ A``; where ``s̈`` steps by ``A`` (into and out of a ramp) its jerk is ``|T s⃛_W| = A / W``,
so ``W = A / J`` honours ``J`` — a trapezoid averaged this way is the classical 7-phase S-curve, and
where the move reaches its speed ``v ≥ A²/J``, its time ``D/v + v/A + A/J`` is that curve's optimum
(below, the optimum reaches a lower peak acceleration, and averaging loses up to ~6 % of the ramp
time). Where ``s̈`` swings from ``+A`` to ``-A`` within ``W`` the jerk doubles; the measurement below
finds such places and stretches ``W`` (up to 2.5×). Each group starts and ends at rest, so the
average runs per group and a moving group grows by ``W`` (whole ticks: rest points stay on ticks).

On curves the axis jerk also has ``3 K ṡ s̈ + K' ṡ³`` terms, and the averaged speed near a slow
point can exceed the slow point's cap; :func:`jerk_limited` therefore holds the plan's speed minima
flat, measures the result at every tick (exact positions, finite differences) and re-plans with
local remedies (a wider window, lower feeds on the offending curves, less acceleration) until every
limit holds — with a global slow-down as the last resort, so it always ends with a valid plan.

``s_W`` is evaluated in closed form: ``A(t) = ∫_0^t s`` of a trapezoid segment is a piecewise cubic,
and ``s_W = (A(t) - A(t - W)) / W`` per group.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from functools import cached_property, reduce

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size
from jaxcnc.errors import PlanningError
from jaxcnc.geometry.evaluate import evaluate_path, span_arrays
from jaxcnc.geometry.kinds import SpanKind
from jaxcnc.geometry.spans import Spans, pad_spans, row_norm
from jaxcnc.jitcache import cached_jit
from jaxcnc.planners.motion import trapezoid_integral
from jaxcnc.planners.protocol import (
    DeviceLaw,
    Planner,
    PlanRequest,
    TimeLaw,
    jerk_substeps,
    machine_limits,
    range_min,
    with_margin,
)
from jaxcnc.planners.timelaw import PLAN_COLUMNS, PLAN_KEYS, Plan, segment_of_tick

CHUNK = 1 << 16
log = logging.getLogger(__name__)
#: Width of a held speed minimum, in windows (measured on the butterfly at J = 1e5: 1 → 5.52 s,
#: 0.5 → 5.51 s, 0.25 → 5.34 s, all without violations; what a narrow hold leaves, the loop fixes).
HOLD_WIDEN = 0.25
#: Rounds of slowing down only where the limits still break once the stage's loop has stalled, and the share of the
#: speed measured there each round keeps (before the global slow-down; :func:`jerk_limited`).
SQUEEZE_ROUNDS = 6
SQUEEZE = 0.7
#: Plans measured to narrow each group's window once the stage holds the limits (:func:`narrow_windows`).
NARROW_ROUNDS = 4
#: Share of a limit the stage's measurements must stay within (the table is sampled from these very positions; the
#: verifier allows its rounding).
MEASURE_MARGIN = 1.0 - 1e-6
#: The search's windows are whole multiples of this (s; at least one tick): the same windows at 1 kHz and at 10 kHz,
#: so the two rates measure the same motions and take the same remedies (windows of 0.1 ms steps at 10 kHz and 1 ms
#: at 1 kHz had plasmatest's search part ways at the third widening: 57.88 s against 58.49 s). The valid plan's
#: windows are then narrowed tick by tick (:func:`narrow_windows`).
WINDOW_STEP_S = 1e-3


@dataclass(frozen=True, eq=False)
class SmoothPlan(TimeLaw):
    """A :class:`Plan` whose groups' ``s(t)`` are averaged over windows of whole ticks (a :class:`TimeLaw`).

    Group arrays ``(n_groups,)``: ``g_window`` (the group's window, in ticks), ``g_start`` (tick where the group
    starts in the base plan),
    ``g_ticks`` (its whole ticks there), ``g_new_start`` (where it starts here), ``g_s0`` (path
    length at its start), ``g_len`` (its path length). ``span_s0`` ``(n_spans,)``: path length from the
    program start to each span's start. ``alpha``: the acceleration scale the base plan was made with.
    """

    base: Plan
    g_window: np.ndarray
    g_start: np.ndarray
    g_ticks: np.ndarray
    g_new_start: np.ndarray
    g_s0: np.ndarray
    g_len: np.ndarray
    g_first_seg: np.ndarray  # (n_groups,) the group's first and last segment
    g_last_seg: np.ndarray
    seg_s_in_group: np.ndarray  # (n_segments,) path length from the group start to the segment start
    seg_prefix: np.ndarray  # (n_segments,) ∫ s dt from the group start to the segment start (mm·s)
    span_s0: np.ndarray  # (n_spans,) path length from the program start to each span's start
    alpha: float = 1.0

    @property
    def tick_hz(self) -> float:
        return self.base.tick_hz

    @property
    def n_ticks(self) -> int:
        return self.base.n_ticks + int(np.sum(self.g_growth))

    @property
    def g_growth(self) -> np.ndarray:
        """``(n_groups,)`` ticks each group lasts longer than in the base plan (:func:`group_growth`)."""
        return group_growth(self.g_len, self.g_window)

    @property
    def window_ticks(self) -> int:
        """The widest group's window, in ticks."""
        return int(self.g_window.max(initial=0))

    @property
    def total_time_s(self) -> float:
        return self.n_ticks / self.tick_hz

    # the base plan's segments, for what maps path lengths to spans (events, PSO)
    @property
    def span(self) -> np.ndarray:
        return self.base.span

    @property
    def length(self) -> np.ndarray:
        return self.base.length

    @property
    def s_start(self) -> np.ndarray:
        return self.base.s_start

    def __len__(self) -> int:
        return len(self.base)

    def span_start_ticks(self, n_spans: int) -> np.ndarray:
        """``(n_spans,)`` the tick where each span starts (a group's first span: the group's first tick)."""
        base = self.base
        first = base.span_first_segment(n_spans)
        group = np.searchsorted(self.g_start, base.group_tick[first], side="right") - 1
        ticks = self.ticks_at_s(self.g_s0[group] + self.seg_s_in_group[first])
        return np.where(base.offset_ticks[first] == 0.0, self.g_new_start[group], ticks)

    def finer(self, k: int) -> SmoothPlan:
        """The same motion on a tick grid ``k`` times finer (:meth:`~jaxcnc.planners.timelaw.Plan.finer`, the
        window ``k`` times as many ticks): tick ``k i`` there is tick ``i`` here."""
        return self if k == 1 else smooth(self.base.finer(k), self.g_window * k, self.span_s0, self.alpha)

    def ticks_at(self, seg: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The first tick at which segment ``seg`` has covered ``s`` mm (of the averaged motion)."""
        return self.ticks_at_s(self.span_s0[self.span[seg]] + self.s_start[seg] + s)

    def device_law(self) -> DeviceLaw:
        """The group and segment arrays, the spans' starts (padded with ``inf``: never found) and :class:`SmoothLaw`."""
        n = self.span_s0.shape[0]
        span_s0 = np.full(bucket_size(n), np.inf)
        span_s0[:n] = self.span_s0
        arrays = dict(self._device, span_s0=jax.device_put(span_s0))
        return DeviceLaw(SmoothLaw(self.tick_hz), arrays)

    @cached_property
    def _device(self) -> dict[str, jnp.ndarray]:
        """The arrays :func:`s_of_ticks` reads (segments padded to a bucket size), uploaded once."""
        base = self.base
        n = len(base)
        m = bucket_size(n)
        big = np.iinfo(np.int64).max

        def pad(a: np.ndarray, fill=0) -> jnp.ndarray:
            return jax.device_put(np.pad(a, (0, m - n), constant_values=fill))

        out = {k: pad(getattr(base, k), big if k == "first_tick" else 0) for k in PLAN_KEYS}
        out["length"] = pad(base.length)
        out["seg_s_in_group"] = pad(self.seg_s_in_group)
        out["seg_prefix"] = pad(self.seg_prefix)
        for k in ("g_window", "g_start", "g_ticks", "g_new_start", "g_s0", "g_len", "g_first_seg", "g_last_seg"):
            out[k] = jax.device_put(getattr(self, k))
        return out

    def s_at(self, ticks: np.ndarray) -> np.ndarray:
        """Path length from the program start at integer ``ticks`` ``(m,)`` (NumPy in and out)."""
        arrays = self._device
        t = np.asarray(ticks, dtype=np.int64)
        out = np.empty(t.shape[0])
        for i in range(0, t.shape[0], CHUNK):
            part = t[i : i + CHUNK]
            padded = np.pad(part, (0, CHUNK - part.shape[0]), mode="edge") if part.size else part
            out[i : i + part.shape[0]] = np.asarray(s_of_ticks(arrays, padded, self.tick_hz))[: part.shape[0]]
        return out

    def ticks_at_s(self, s: np.ndarray) -> np.ndarray:
        """The first tick at which the path length reaches each of ``s`` ``(m,)`` (bisection; s_W is monotone)."""
        s = np.asarray(s, dtype=np.float64)
        lo = np.zeros(s.shape, np.int64)  # s_at(lo) < s or lo = 0
        hi = np.full(s.shape, self.n_ticks, np.int64)  # s_at(hi) >= s (the end reaches everything)
        eps = 1e-9
        while np.any(hi - lo > 1):
            mid = (lo + hi) // 2
            reached = self.s_at(mid) >= s - eps
            hi = np.where(reached, mid, hi)
            lo = np.where(reached, lo, mid)
        at_lo = self.s_at(lo) >= s - eps
        return np.where(at_lo, lo, hi)


def _segment_integral(plan: dict, seg: jnp.ndarray, tau: jnp.ndarray) -> jnp.ndarray:
    """``∫_0^τ s_local`` (mm·s) of segment ``seg`` ``τ`` seconds after its start (linear past its end)."""
    keys = ("v0", "vp", "a_acc", "a_dec", "t_acc", "t_cru", "t_dec", "length")
    return trapezoid_integral(*(plan[k][seg] for k in keys), tau, xp=jnp)


_segment_integral_jit = jax.jit(lambda plan, seg, tau: _segment_integral(plan, seg, tau))


def _group_integral(plan: dict, g: jnp.ndarray, tau: jnp.ndarray, tick_hz: float) -> jnp.ndarray:
    """``A_g(τ) = ∫ s_g`` from group ``g``'s start to ``τ`` ticks after it (0 before, linear after its end)."""
    whole = plan["g_ticks"][g]
    tc = jnp.clip(tau, 0, whole)
    tick = plan["g_start"][g] + tc
    seg = jnp.clip(segment_of_tick(plan["first_tick"], tick), plan["g_first_seg"][g], plan["g_last_seg"][g])
    t_seg = ((tick - plan["group_tick"][seg]).astype(jnp.float64) - plan["offset_ticks"][seg]) / tick_hz
    t_seg = jnp.maximum(t_seg, 0.0)
    a = plan["seg_prefix"][seg] + plan["seg_s_in_group"][seg] * t_seg + _segment_integral(plan, seg, t_seg)
    a = a + plan["g_len"][g] * jnp.maximum(tau - whole, 0).astype(jnp.float64) / tick_hz
    return jnp.where(tau <= 0, 0.0, a)


@dataclass(frozen=True)
class SmoothLaw:
    """A :class:`SmoothPlan`'s :class:`~jaxcnc.planners.protocol.DeviceLaw` function (static: hashable by value)."""

    tick_hz: float

    def __call__(self, arrays: dict, tick: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
        """``(span, s in span)`` at integer ``tick``: ``s_W`` from the program start, then its span."""
        s = s_of_ticks(arrays, tick, self.tick_hz)
        span_s0 = arrays["span_s0"]
        span = jnp.clip(jnp.searchsorted(span_s0, s, side="right") - 1, 0, span_s0.shape[0] - 1)
        return span, s - span_s0[span]


@cached_jit(static_argnames=("tick_hz",))
def s_of_ticks(plan: dict, ticks: jnp.ndarray, tick_hz: float) -> jnp.ndarray:
    """Averaged path length ``s_W`` at integer ``ticks`` ``(m,)``: ``(A(t) - A(t - W)) / W`` in its group (``W``
    the group's window)."""
    g = jnp.clip(jnp.searchsorted(plan["g_new_start"], ticks, side="right") - 1, 0, plan["g_new_start"].shape[0] - 1)
    tau = ticks - plan["g_new_start"][g]
    window_ticks = plan["g_window"][g]
    w_s = window_ticks / tick_hz
    area = _group_integral(plan, g, tau, tick_hz) - _group_integral(plan, g, tau - window_ticks, tick_hz)
    return plan["g_s0"][g] + jnp.clip(area / w_s, 0.0, plan["g_len"][g])


def _segment_integral_np(plan: Plan) -> np.ndarray:
    """``∫ s_local`` over each whole segment (NumPy), from the same closed form."""
    arrays = {k: getattr(plan, k) for k in PLAN_KEYS}
    arrays["length"] = plan.length
    return np.asarray(_segment_integral_jit(arrays, np.arange(len(plan)), plan.duration_s))


def group_growth(g_len: np.ndarray, g_window: np.ndarray) -> np.ndarray:
    """``(n_groups,)`` ticks the averaging adds to each group: its window where it moves (dwells and events keep
    their ticks)."""
    return np.where(g_len > 0, g_window, 0)


def segment_groups(plan: Plan) -> np.ndarray:
    """``(n_segments,)`` the rest-to-rest group of each segment of ``plan`` (0, 1, … in order)."""
    group_tick = plan.group_tick
    return np.cumsum(np.concatenate([[True], group_tick[1:] != group_tick[:-1]])) - 1


def smooth(plan: Plan, window_ticks: int | np.ndarray, span_s0: np.ndarray, alpha: float = 1.0) -> SmoothPlan:
    """Average ``plan``'s groups over ``window_ticks`` ticks (one for all, or ``(n_groups,)``, each group's own);
    ``span_s0``: path length at each span's start."""
    s_start_of_segment = span_s0[plan.span] + plan.s_start
    group = segment_groups(plan)
    starts = np.flatnonzero(np.diff(group, prepend=-1))  # each group's first segment
    g_start = plan.group_tick[starts].astype(np.int64)
    g_ticks = np.diff(np.concatenate([g_start, [plan.n_ticks]])).astype(np.int64)
    g_s0 = s_start_of_segment[starts]
    g_len = np.bincount(group, weights=plan.length, minlength=starts.size)
    seg_s_in_group = s_start_of_segment - g_s0[group]
    # ∫ s_g dt over each whole segment: s at its start times its duration, plus its own integral
    whole = seg_s_in_group * plan.duration_s + _segment_integral_np(plan)
    csum = np.cumsum(whole)
    seg_prefix = csum - whole - (csum - whole)[starts][group]  # exclusive sum within the group
    g_window = np.broadcast_to(np.asarray(window_ticks, np.int64), starts.shape).copy()
    grow = group_growth(g_len, g_window)
    g_new_start = g_start + (np.cumsum(grow) - grow)
    return SmoothPlan(
        base=plan,
        g_window=g_window,
        g_start=g_start,
        g_ticks=g_ticks,
        g_new_start=g_new_start,
        g_s0=g_s0,
        g_len=g_len,
        g_first_seg=starts.astype(np.int64),
        g_last_seg=np.concatenate([starts[1:] - 1, [len(plan) - 1]]).astype(np.int64),
        seg_s_in_group=seg_s_in_group,
        seg_prefix=seg_prefix,
        span_s0=span_s0,
        alpha=alpha,
    )


# ---- measuring a smoothed plan at every tick -------------------------------------------------------
def span_starts(spans) -> tuple[dict, jnp.ndarray]:
    """Device arrays of ``spans`` padded to a bucket and each span's start ``s`` (padding: never found)."""
    n = len(spans)
    padded = pad_spans(spans, bucket_size(n))
    span_s0 = padded.s0
    span_s0[n:] = np.inf
    return span_arrays(padded, xp=jnp), jax.device_put(span_s0)


@cached_jit
def positions_at_s(spans: dict, span_s0: jnp.ndarray, s: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Program-axis positions ``(m, 3)`` at path lengths ``s`` ``(m,)`` from the program start, and their span."""
    span = jnp.clip(jnp.searchsorted(span_s0, s, side="right") - 1, 0, span_s0.shape[0] - 1)
    (p,) = evaluate_path(spans, span, s - span_s0[span], xp=jnp)
    return p, span


def span_peaks(
    plan: SmoothPlan, spans, v_max: np.ndarray, a_max: np.ndarray, j_max: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per span: the worst ``max(|v|/v_max, |a|/a_max)`` and ``|j|/j_max`` over axes and ticks, the peak speed, and
    where the worst jerk is.

    Exact positions at every tick (the machine at rest before the first and after the last),
    finite differences at the tick rate — what the table verifier will measure, less rounding.
    Chunked: memory stays bounded for any job. Returns ``(2, n_spans)`` ratios, ``(n_spans,)`` speeds and
    ``(2, n_spans)``: the path length ``s`` (from the program start) and the speed at the span's worst jerk.
    """
    f = plan.tick_hz
    n = len(spans)
    arrays, span_s0 = span_starts(spans)
    limits = np.stack([v_max, a_max, j_max])  # (3 quantities, 3 axes)
    inv = np.where(np.isfinite(limits) & (limits > 0), 1.0 / np.where(limits > 0, limits, 1.0), 0.0)
    worst = np.zeros((2, n))  # (v and a, j)
    speed = np.zeros(n)
    where = np.zeros((2, n))  # (s, speed) at each span's worst jerk
    tail = None  # the last 3 positions of the previous chunk
    total = plan.n_ticks + 1
    for first in range(0, total, CHUNK):
        last_chunk = first + CHUNK >= total
        ticks = np.arange(first, min(first + CHUNK, total))
        s = plan.s_at(ticks)
        p, span = positions_at_s(arrays, span_s0, s)
        p, span = np.asarray(p), np.asarray(span)
        if tail is None:
            tail = np.repeat(p[:1], 3, axis=0)
        x = np.concatenate([tail, p] + ([np.repeat(p[-1:], 3, axis=0)] if last_chunk else []))
        at = np.concatenate([span, np.repeat(span[-1:], 3)]) if last_chunk else span
        s = np.concatenate([s, np.repeat(s[-1:], 3)]) if last_chunk else s
        runs = _runs(at)
        diff = np.diff(x, axis=0)
        v = row_norm(diff[-at.shape[0] :]) * f  # (np.linalg.norm's sum, column by column: ~3x faster)
        _max_into(speed, at, v, runs)
        for k in range(3):
            if k:
                diff = np.diff(diff, axis=0)  # (np.diff of order k + 1: the same differences, bit for bit)
            d = np.abs(diff[-at.shape[0] :]) * f ** (k + 1)  # rows ending in this chunk
            # the worst axis: an elementwise maximum over the columns (a reduction along a row of 3 is ~10x slower)
            ratio = reduce(np.maximum, (d[:, i] * inv[k][i] for i in range(d.shape[1])))
            _max_into(worst[k // 2], at, ratio, runs)
            if k == 2:
                hit = (ratio > 0) & (ratio >= worst[1][at])
                where[0][at[hit]], where[1][at[hit]] = s[hit], v[hit]
        tail = x[-3:]
    return worst, speed, where


def _runs(at: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Where the runs of equal entries of ``at`` ``(q,)`` start and their values, if ``at`` is sorted (the spans of
    ticks in time order), else ``None``."""
    if at.size == 0 or np.any(at[1:] < at[:-1]):
        return None
    starts = np.flatnonzero(np.concatenate([[True], at[1:] != at[:-1]]))
    return starts, at[starts]


def _max_into(target: np.ndarray, at: np.ndarray, value: np.ndarray, runs) -> None:
    """``np.maximum.at(target, at, value)``, one maximum per run where ``runs`` (:func:`_runs`) says ``at`` is
    sorted (a reduction over each run, ~10x faster than the unbuffered ``at``; the same maxima, exactly)."""
    if runs is None:
        np.maximum.at(target, at, value)
        return
    starts, keys = runs
    target[keys] = np.maximum(target[keys], np.maximum.reduceat(value, starts))


def passed_speed(speed: np.ndarray) -> np.ndarray:
    """``(n,)`` the speeds :func:`span_peaks` measured, where a span holds no tick (shorter than a tick's step:
    measured 0) the larger of the nearest measured ones before and after it — the speed it was passed at lies
    between them. Capping such a span at its measured 0 (the floor, 1e-3 mm/s) made a 12 µm blend piece take
    12 s: meander520 with j_max 1e6 planned to 271 s against 34 s without the jerk limit."""
    n = speed.size
    measured = speed > 0
    if measured.all() or not measured.any():
        return speed
    idx = np.arange(n)
    before = np.maximum.accumulate(np.where(measured, idx, -1))
    after = np.minimum.accumulate(np.where(measured, idx, n)[::-1])[::-1]
    near = np.maximum(
        np.where(before >= 0, speed[np.maximum(before, 0)], 0.0),
        np.where(after < n, speed[np.minimum(after, n - 1)], 0.0),
    )
    return np.where(measured, speed, near)


def minima_holds(plan: Plan, s_seg: np.ndarray, window_s: float, widen: float) -> np.ndarray:
    """``(k, 3)`` hold rows ``(s_lo, s_hi, v)`` that flatten ``plan``'s moving speed minima.

    Averaged over ``W``, the speed at a V-shaped minimum becomes the mean of the faster speeds
    around it — above the cap that made the minimum. Held flat for ``W`` (``v W`` of path, centred),
    the average there is the minimum itself. ``widen`` scales the half-width ``v W / 2``.
    """
    v = np.concatenate([plan.v0, plan.v1[-1:]])
    s = np.concatenate([s_seg, s_seg[-1:] + plan.length[-1:]])
    lower = np.concatenate([[False], (v[1:-1] <= v[:-2]) & (v[1:-1] <= v[2:]), [False]]) & (v > 0)
    return _holds_around(s[lower], v[lower], widen * v[lower] * window_s / 2.0)


def _holds_around(s: np.ndarray, v: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """``(k, 3)`` hold rows ``(s - reach, s + reach, v)``: the speed at most ``v`` within ``reach`` mm of ``s``."""
    return np.stack([s - reach, s + reach, v], axis=1)


def _with_neighbours(mask: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: ``mask`` and the entries just before and after each of its ``True`` entries."""
    return mask | np.concatenate([[False], mask[:-1]]) | np.concatenate([mask[1:], [False]])


def _widen_where_bad(rows: np.ndarray, span_s0: np.ndarray, bad: np.ndarray, window_s: float) -> np.ndarray:
    """Hold rows (:func:`minima_holds`) whose minimum lies on a span that breaks a limit (``bad``: the jerk, or the
    acceleration where a velocity steps at a kink) or next to one, held
    over the whole window: half a window's path ``v W / 2`` either side, so that the average at the minimum is the
    minimum itself.

    A narrow hold leaves a sharp notch to the loop's feed caps, which the window averages away: a 14 µm blend of
    meander520 (``K`` up to 7.8 /mm) capped at 6.6 mm/s was passed at 13 mm/s, 4.5x ``J`` at 10 kHz, and the stage
    ended in its global slow-down (152 s against 51 s at 1 kHz; 34 s without ``j_max``). Held this wide everywhere,
    gentle minima cost time for nothing (the butterfly at ``J`` = 1e5: 5.72 s against 5.32 s)."""
    if rows.size == 0 or not bad.any():
        return rows
    centre = 0.5 * (rows[:, 0] + rows[:, 1])
    span = np.clip(np.searchsorted(span_s0, centre, side="right") - 1, 0, span_s0.size - 1)
    half = np.maximum(0.5 * rows[:, 2] * window_s, 0.5 * (rows[:, 1] - rows[:, 0]))
    wide = _with_neighbours(bad)[span]
    out = rows.copy()
    out[wide] = _holds_around(centre[wide], rows[wide, 2], half[wide])
    return out


def _end_excess(
    curved: np.ndarray,
    spans: Spans,
    span_s0: np.ndarray,
    excess: np.ndarray,
    where: np.ndarray,
    window_s: float,
    margin: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Of the curved spans ``curved`` the stage would slow down, those whose worst jerk (``where``: its ``s`` and
    speed, :func:`span_peaks`) lies within a window's path of one of their ends and that are longer than four such
    paths: hold rows ``(k, 3)`` that slow the motion there alone (a whole window either side, at the speed measured
    there times the cube root of the excess, at least 0.5 and at most 0.97 of it); and the spans left to the feed
    caps."""
    s_w, v_w = where[0][curved], where[1][curved]
    reach = np.maximum(v_w, 1e-3) * window_s
    into = s_w - span_s0[curved]
    length = spans.length[curved]
    end = (excess[curved] > margin) & (np.minimum(into, length - into) <= reach) & (length > 4.0 * reach)
    factor = np.clip((margin / np.maximum(excess[curved[end]], margin)) ** (1.0 / 3.0), 0.5, 0.97)
    v = np.maximum(v_w[end], 1e-3) * factor
    return _holds_around(s_w[end], v, v * window_s), curved[~end]


def blends_slower_than_stops(
    spans: Spans, feed_mm_s: np.ndarray, v_max: np.ndarray, a_max: np.ndarray, j_max: np.ndarray, rows: int
) -> np.ndarray:
    """``(rows,)`` bool: the program rows whose junction before them is passed faster at rest than blended under
    the jerk limits (the blend spans of that junction carry the second row's block).

    A blend turns its curvature from that of the span before it, ``K_a``, up to its peak ``K`` and back to that of
    the span after it, ``K_b``, within its length ``L``: ``|K'| ≥ (2 K - K_a - K_b) / L`` somewhere (the total
    variation; a neighbour that is a blend too, where two meet on a line they consume, counts with its peak, which
    leans towards blending). Until 2026-11-28 the larger neighbour's curvature stood for both ends,
    ``2 (K - max(K_a, K_b)) / L``: a 17 nm blend beside another one (a 40 nm line between them, consumed) read no
    ``K'`` at all and was kept: a red-team program of tiny arcs (``benchmarks/programs/jerk_redteam/fz_1.ngc``)
    planned to 570.7 s at 10 kHz that way, 16.1 s with the total variation. At speed ``v`` an axis sees ``K' v³`` of
    jerk, so the S-curve stage passes it at
    ``v_p ≤ min((s J / K')^(1/3), √(A / K), V)`` (``s`` = ``limits.JERK_SHARE``, ``V`` the feed, ``A`` and ``J``
    the axes' limits), at a constant speed from ``v_p W / 2`` before it to as far
    after it (:func:`minima_holds`; ``W = A / J``, the window). Against a stop at the corner (one more
    rest-to-rest group: ``W`` more), a pass from ``V`` down to ``v_p`` and back takes

        ΔT = L / v_p - 2 v_p / A + (v_p² / A - L - v_p W) / V

    longer (the ramps from ``v_p`` to rest and back are saved; what the pass covers at ``v_p`` is covered at ``V``
    otherwise). That model passes the blend at ``v_p`` throughout; the stage does better on blends longer than the
    window's path (its holds are narrower, the speed rises off the curvature's peak), so a blend is given up only
    where ``ΔT > 0`` and ``L < 2 v_p W`` as well: the square of ``tests/test_jerk.py`` (``A`` = 1000, ``J`` =
    20,000, F3000) keeps its ``P0.5`` blends (``L`` = 3.2 mm = 2.7 ``v_p W``; 1.106 s against 1.201 s with exact
    corners) and stops at its ``P0.05`` corners (1.2 ``v_p W``; blended 1.236 s). A 90° corner at ``G64 P0.01`` on
    the laser cutter with ``J = 1e5``: ``L`` = 0.075 mm = 0.55 ``v_p W``, ``v_p`` ≈ 3.4 mm/s, ``ΔT`` ≈ +19 ms: it
    stops (a serpentine of 100 mm lines and 0.1 mm step-overs: 5.77 s against 8.18 s blended, and planned in
    seconds). A 1° kink of a CAM contour keeps its blend. The estimates lean towards blending (the lower bound
    of ``K'``, the largest ``J``, the smallest ``A`` of the axes the blend moves).
    """
    from jaxcnc.planners.limits import JERK_SHARE

    out = np.zeros(rows, bool)
    is_blend = spans.kind == SpanKind.BLEND
    n = len(spans)
    if not is_blend.any() or not np.any(np.isfinite(j_max)):
        return out
    # the blends: runs of blend pieces of one junction (each piece carries the junction's second row)
    start = is_blend & ~np.concatenate([[False], is_blend[:-1] & (spans.block[:-1] == spans.block[1:])])
    first = np.flatnonzero(start)
    group = np.cumsum(start) - 1
    piece = np.flatnonzero(is_blend)
    g = group[piece]
    last = np.zeros(first.size, np.int64)
    np.maximum.at(last, g, piece)
    length = np.bincount(g, weights=spans.length[piece], minlength=first.size)
    peak = np.zeros(first.size)
    np.maximum.at(peak, g, spans.kappa_max[piece])
    lo, hi = np.full((first.size, 3), np.inf), np.full((first.size, 3), -np.inf)
    np.minimum.at(lo, g, spans.lo[piece])
    np.maximum.at(hi, g, spans.hi[piece])
    moves = hi - lo > 0  # (blends, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        k_a = spans.kappa_max[np.maximum(first - 1, 0)]
        k_b = spans.kappa_max[np.minimum(last + 1, n - 1)]
        k_rate = np.maximum(2.0 * peak - k_a - k_b, 0.0) / length
        jerk = np.max(np.where(moves & np.isfinite(j_max), j_max, 0.0), axis=1)
        accel = np.min(np.where(moves, a_max, np.inf), axis=1)
        window = np.max(np.where(moves & np.isfinite(j_max), a_max / j_max, 0.0), axis=1)
        cruise = np.minimum(feed_mm_s[first], np.min(np.where(moves, v_max, np.inf), axis=1))
        v_jerk = np.where(k_rate > 0, np.cbrt(JERK_SHARE * jerk / k_rate), np.inf)
        v_pass = np.minimum(np.minimum(v_jerk, np.sqrt(accel / peak)), cruise)
        slower = length / v_pass - 2.0 * v_pass / accel + (v_pass**2 / accel - length - v_pass * window) / cruise
    stop = (jerk > 0) & np.isfinite(slower) & (slower > 0) & (length < 2.0 * v_pass * window)
    out[spans.block[first[stop]]] = True
    return out


def narrow_windows(sp: SmoothPlan, floor: int, measure) -> SmoothPlan:
    """``sp`` (within the limits) with each rest-to-rest group's window narrowed, where the limits still hold, towards
    ``floor`` ticks (``W = A/J``): bisection per group between the widest window measured to break a limit and the
    narrowest that holds, ``NARROW_ROUNDS`` plans measured (``measure(plan)``: :func:`span_peaks`' ``(2, n_spans)``
    ratios).

    The stage widens one window for the whole program while that helps; a window costs its length once per group,
    and most groups did not need it wider. Given the base plan, a group's averaged motion depends on its own window
    alone (groups start and end at rest), so one plan measures a trial window for every group at once; a group that
    breaks a limit there keeps a wider one. The windows kept are measured together once more (the finite differences
    across a junction of two groups read both); should anything break, ``sp`` is returned as it was."""
    base = sp.base
    n_groups = sp.g_window.size
    good = sp.g_window.copy()  # the narrowest window measured to keep the limits
    fail = np.full(n_groups, floor - 1)  # the widest measured to break one (floor - 1: none yet)
    for r in range(NARROW_ROUNDS):
        open_ = good - fail > 1  # groups whose narrowest window is not settled yet
        if not open_.any():
            break
        trial = good.copy()
        trial[open_] = floor if r == 0 else (fail[open_] + good[open_]) // 2  # first W = A/J itself
        candidate = smooth(base, trial, sp.span_s0, sp.alpha)
        bad = group_bad(candidate, measure(candidate), MEASURE_MARGIN)
        fail = np.where(open_ & bad, trial, fail)
        good = np.where(open_ & ~bad, trial, good)
    if np.array_equal(good, sp.g_window):
        return sp
    out = smooth(base, good, sp.span_s0, sp.alpha)
    return out if measure(out).max() <= MEASURE_MARGIN else sp


def group_bad(sp: SmoothPlan, worst: np.ndarray, margin: float) -> np.ndarray:
    """``(n_groups,)`` bool: the rest-to-rest groups of ``sp`` that hold a span breaking a limit (``worst``:
    :func:`span_peaks`' ``(2, n_spans)`` ratios, compared with ``margin``)."""
    bad = np.zeros(sp.g_window.size, bool)
    bad[segment_groups(sp.base)[(worst.max(axis=0) > margin)[sp.base.span]]] = True
    return bad


def splice_groups(plans: list[SmoothPlan], choice: np.ndarray) -> SmoothPlan:
    """One plan whose rest-to-rest group ``g`` is group ``g`` of ``plans[choice[g]]`` (its segments and window).

    The plans have the same groups (the same rests: ``g_s0`` equal). A group starts and ends at rest, so its motion
    is its own: the groups' segments are joined in order, each group's ticks placed after the ones before it."""
    first = plans[0]
    g_ticks = np.array([plans[c].g_ticks[g] for g, c in enumerate(choice)], np.int64)
    g_start = np.cumsum(g_ticks) - g_ticks
    parts: dict[str, list[np.ndarray]] = {name: [] for name in PLAN_COLUMNS}
    for g, c in enumerate(choice):
        sp = plans[c]
        k0, k1 = int(sp.g_first_seg[g]), int(sp.g_last_seg[g]) + 1
        for name in PLAN_COLUMNS:
            col = sp.base.column(name, k0, k1)
            if name in ("group_tick", "first_tick"):
                col = col - sp.base.column("group_tick", k0, k1) + g_start[g]
            parts[name].append(col)
    columns = {name: np.concatenate(cols) for name, cols in parts.items()}
    base = Plan(columns, int(g_ticks.sum()), first.base.tick_hz)
    window = np.array([plans[c].g_window[g] for g, c in enumerate(choice)], np.int64)
    return smooth(base, window, first.span_s0, first.alpha)


def jerk_limited(request: PlanRequest, planner: Planner, iterations: int = 30) -> SmoothPlan:
    """Plan ``request`` with ``planner`` so that the machine's ``j_max`` also holds at every tick.

    ``planner`` must return a :class:`~jaxcnc.planners.timelaw.Plan` (its trapezoids are averaged). Each
    attempt hands it the request with the acceleration scaled by ``alpha`` (the margin applied by
    :func:`~jaxcnc.planners.protocol.with_margin`), lowered feeds and — if it declares ``honours_holds`` —
    the held minima; the result is measured against the machine's own limits.

    The window starts at ``W = A/J`` (the largest over the axes that move: an axis's jerk is ``T_i`` times the swing
    of ``s̈`` over ``W``, at most ``A_i / W``). The speed minima of the plan are held
    flat (:func:`minima_holds`) and the program planned again. Where the averaged table still breaks a
    limit, jerk excess first widens the window (up to 2×) while that helps; then, on curves and at
    their junctions (the ``3 K ṡ s̈ + K' ṡ³`` terms), those spans and their curved neighbours get a lower
    feed cap from the speed measured there and the excess (a long curve whose worst jerk lies at one of its ends is
    held there instead, :func:`_end_excess`); acceleration excess scales the acceleration down. If that stalls, the
    places that still break a limit are slowed down alone (``SQUEEZE_ROUNDS``), then a global slow-down ends the
    search with a valid plan, or a :class:`~jaxcnc.errors.PlanningError`. A planner that does not honour holds skips
    the local slow-down; where its search ends on the global one, the search runs again with the holds as caps on
    whole spans' feeds (:func:`held_feed`) and the faster valid plan of the two is kept. Each rest-to-rest group of
    the valid plan
    then takes the fastest motion any attempt measured within the limits for it (:func:`splice_groups`: the later
    rounds' remedies serve the groups that still broke one), and its window is narrowed where the limits still hold
    (:func:`narrow_windows`).

    Every measurement is made at ``jerk_substeps(f)`` fine ticks per tick (10 kHz at least): what holds there holds
    on the table's ticks; and the search's windows are whole multiples of ``WINDOW_STEP_S`` at any rate, so a 1 kHz
    and a 10 kHz table of the same program take the same path through it and plan to the same time.
    """
    if planner.honours_holds:
        return _jerk_search(request, planner, iterations, by_span=False)[0]
    first, error = None, None
    try:
        first, fell_back = _jerk_search(request, planner, iterations, by_span=False)
    except PlanningError as exc:
        error, fell_back = exc, True
    if not fell_back:
        return first
    # a planner that cannot honour holds ended on the global slow-down, whose steps fall otherwise at other tick rates
    # (meander520, j_max 1e6: 133.85 s at 1 kHz, 129.99 s at 10 kHz): the search again with the holds as caps on whole
    # spans (held_feed, which any planner honours) — local slow-downs, the same at any rate (91.22 / 91.30 s) but
    # slower than the global one on other programs (plasmatest 65.8 against 59.8 s) — and the faster of the two
    try:
        second, _ = _jerk_search(request, planner, iterations, by_span=True)
    except PlanningError:
        if first is None:
            raise error from None
        return first
    return second if first is None or second.total_time_s < first.total_time_s else first


def held_feed(spans: Spans, span_s0: np.ndarray, feed: np.ndarray, holds: np.ndarray) -> np.ndarray:
    """``(n,)`` each span's feed ``feed`` capped by the held speeds ``holds`` (rows ``s_lo, s_hi, v``) that reach it:
    for a planner whose caps are constant along a span (``honours_holds`` false), a hold caps the whole span (a hold
    of no length, none). ``span_s0``: ``(n,)`` where each span starts along the path."""
    rows = np.asarray(holds, dtype=np.float64).reshape(-1, 3)
    s1 = span_s0 + spans.length
    first = np.searchsorted(s1, rows[:, 0], side="right")  # the first span ending past s_lo
    count = np.maximum(np.searchsorted(span_s0, rows[:, 1], side="left") - first, 0)  # ... to the last before s_hi
    return np.minimum(feed, range_min(feed.size, first, count, rows[:, 2]))


def _jerk_search(request: PlanRequest, planner: Planner, iterations: int, by_span: bool) -> tuple[SmoothPlan, bool]:
    """:func:`jerk_limited`'s search and whether it ended on the global slow-down. ``by_span``: a planner that does
    not honour holds is handed them as caps on whole spans' feeds (:func:`held_feed`) and searched as one that does.
    """
    honours = planner.honours_holds or by_span
    margin = MEASURE_MARGIN
    f = request.machine.tick_hz
    substeps = jerk_substeps(f)
    spans = request.spans
    v_max, a_max, j_max = machine_limits(request.machine)  # what the table is verified against
    span_s0 = spans.s0
    feed = np.asarray(request.feed_mm_s, dtype=np.float64).copy()
    moves = spans.moving_axes

    def attempt(feed: np.ndarray, alpha: float, holds, stretch: float) -> tuple[SmoothPlan, np.ndarray, ...]:
        a = a_max * alpha
        if by_span and holds is not None:
            feed, holds = held_feed(spans, span_s0, feed, holds), None
        elif not planner.honours_holds:
            holds = None
        # the speed keeps the margin too: s_W is a difference of two integrals ∫ s dt over a group, whose rounding
        # (~ulp(length x duration) / W) reads a cruise at v_max up to ~1e-9 above it at 10 kHz, beyond the check's slack
        limits = dict(v_max=with_margin(v_max), a_max=with_margin(a))
        base = planner.plan(dataclasses.replace(request, **limits, feed_mm_s=feed, hold_caps=holds))
        if not isinstance(base, Plan):
            raise PlanningError(
                f"planner {planner.name!r} returned a {type(base).__name__}; the S-curve stage (j_max is set) "
                "averages a Plan's trapezoids: return a Plan, or declare handles_jerk = True"
            )
        sp = smooth(base, window_ticks(alpha, stretch, step), span_s0, alpha)
        worst, speed, where = measured(sp)
        keep_best_groups(sp, worst)
        return sp, worst, speed, where

    def measured(sp: SmoothPlan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:func:`span_peaks` of ``sp`` on a grid of at least ``JERK_MEASURE_HZ`` (whose limits hold on the table's
        ticks as well): a and j compared with the margin, speeds with the limit itself (the plan keeps the margin
        below it)."""
        return span_peaks(sp.finer(substeps), spans, v_max / margin, a_max, j_max)

    # each rest-to-rest group's fastest motion measured within the limits so far (the groups are the same in every
    # attempt where the rests are): the remedies of later rounds serve the groups that still broke a limit
    seen: dict = {"g_s0": None, "time": None, "at": None, "plans": {}, "count": 0}

    def keep_best_groups(sp: SmoothPlan, worst: np.ndarray) -> None:
        if seen["g_s0"] is None:
            seen.update(g_s0=sp.g_s0, time=np.full(sp.g_s0.size, np.inf), at=np.full(sp.g_s0.size, -1))
        if not np.array_equal(sp.g_s0, seen["g_s0"]):
            return
        duration = sp.g_ticks + sp.g_growth
        better = ~group_bad(sp, worst, margin) & (duration < seen["time"])
        if better.any():
            seen["count"] += 1
            seen["time"][better], seen["at"][better] = duration[better], seen["count"]
            used = set(seen["at"].tolist())
            seen["plans"] = {k: v for k, v in seen["plans"].items() if k in used} | {seen["count"]: sp}

    def fastest(sp: SmoothPlan) -> SmoothPlan:
        """``sp`` (within the limits) or, faster, each group's fastest motion measured within them."""
        at = seen["at"]
        if at is None or not np.array_equal(sp.g_s0, seen["g_s0"]) or np.any(at < 0):
            return sp
        keys = sorted(seen["plans"])
        spliced = splice_groups([seen["plans"][k] for k in keys], np.searchsorted(keys, at))
        if spliced.n_ticks >= sp.n_ticks:
            return sp
        worst = measured(spliced)[0]
        log.debug("jerk stage: groups' fastest motions %.4f s against %.4f s", spliced.total_time_s, sp.total_time_s)
        return spliced if worst.max() <= margin else sp

    def narrowed(sp: SmoothPlan) -> SmoothPlan:
        """``sp`` with each group's window as narrow as the limits allow (:func:`narrow_windows`)."""
        return narrow_windows(sp, window_ticks(sp.alpha), lambda c: measured(c)[0])

    def window_ticks(alpha: float, stretch: float = 1.0, step: int = 1) -> int:
        """The window: ``stretch`` times ``A/J`` of the base plan's acceleration (the margin below ``a_max * alpha``)
        over the axes that move, in whole multiples of ``step`` ticks; a line's jerk ``A/W`` keeps the margin below
        ``J`` (an ``A/J`` of whole steps is that many steps)."""
        a = with_margin(a_max * alpha)
        with np.errstate(invalid="ignore"):  # (an axis that never moves has no jerk: its A/J does not count)
            ratio = np.where(np.isfinite(j_max) & np.isfinite(a) & moves, a / (j_max * margin), 0.0)
        return step * max(1, math.ceil(float(np.max(ratio)) * stretch * f / step - 1e-9))

    step = max(1, round(f * WINDOW_STEP_S))  # the search's windows: whole steps (WINDOW_STEP_S)

    alpha, holds, stretch, widening, previous_j = 1.0, None, 1.0, True, np.inf
    widen, best_j, stalled = HOLD_WIDEN, np.inf, 0
    for it in range(iterations):
        sp, worst, speed, where = attempt(feed, alpha, holds, stretch)
        excess_a, excess_j = float(worst[0].max()), float(worst[1].max())
        log.debug(
            "jerk stage %d: v/a %.4f, j %.4f (on %d spans), alpha %.4f, window %d ticks, %.4f s",
            *(it, excess_a, excess_j, int((worst[1] > margin).sum()), alpha, sp.window_ticks, sp.total_time_s),
        )
        if max(excess_a, excess_j) <= margin:
            return narrowed(fastest(sp)), False
        if not widening:
            if excess_j < 0.98 * best_j:
                best_j, stalled = excess_j, 0
            else:
                # the caps do not reach it: the window still averages in the faster speeds around a
                # slow place, so hold the minima flat over more of the window
                stalled += 1
                widen = min(2.0 * widen, 1.0)
                stretch = min(2.5, stretch * 1.25)  # and s̈ swinging between a slow place's ramps
                if stalled > 4:
                    break
        rows = minima_holds(sp.base, span_s0[sp.base.span] + sp.base.s_start, sp.window_ticks / f, widen)
        rows = _widen_where_bad(rows, span_s0, worst.max(axis=0) > margin, sp.window_ticks / f)
        holds = rows if holds is None else np.concatenate([holds, rows])
        if it == 0:
            continue  # first let the held minima act
        if excess_a > margin:
            # the averaged acceleration on curves (T and K vary across the window): less of it everywhere
            alpha *= float(np.clip(margin / excess_a, 0.7, 0.995))
        bad = worst[1] > margin
        is_curve = (spans.kind != SpanKind.LINE) & (spans.kind != SpanKind.POINT)
        near_curve = _with_neighbours(is_curve)
        on_line = bad & ~near_curve
        if widening and bad.any() and stretch < 2.0 and excess_j < 0.98 * previous_j:
            # T s⃛ doubles where s̈ swings from +A to -A within the window: widen it while that helps
            # (it costs its length once per rest-to-rest group)
            previous_j = excess_j
            stretch *= min(1.25, excess_j / margin * 1.01)
            continue
        widening = False
        if on_line.any() and stretch < 2.5:
            stretch *= min(1.25, excess_j / margin * 1.01)  # on lines the jerk is T s⃛ alone
        # a line's excess next to a curve is the curve's (its curvature's change at the junction)
        near = bad & near_curve
        curved = np.unique(
            np.concatenate([np.flatnonzero(near & is_curve)] + [np.flatnonzero(near & ~is_curve) + d for d in (-1, 1)])
        )
        curved = curved[(curved >= 0) & (curved < len(spans))]
        curved = curved[is_curve[curved]]
        if honours and curved.size:
            # a long curve whose excess lies at one of its ends (a junction: a tiny circle's curvature step beside it)
            # is held down there alone, not slowed down as a whole (a 21 mm arc was taken at 1.7 mm/s for it)
            ends, curved = _end_excess(curved, spans, span_s0, worst[1], where, sp.window_ticks / f, margin)
            if ends.size:
                holds = np.concatenate([holds, ends])
        if curved.size:
            # on curves the curvature's change adds 3 K ṡ s̈ + K' ṡ³ (it grows like v³): slow those spans
            # and their curved neighbours to the speed measured there times a cube-root share of the excess
            speed = passed_speed(speed)
            excess_near = np.maximum.reduce([worst[1][np.clip(curved + d, 0, len(spans) - 1)] for d in (-1, 0, 1)])
            factor = np.clip((margin / excess_near) ** (1.0 / 3.0), 0.5, 0.97)
            cap = np.full(len(spans), np.inf)
            for di in (-1, 0, 1):
                idx = np.clip(curved + di, 0, len(spans) - 1)
                np.minimum.at(cap, idx, np.maximum(speed[curved], 1e-3) * factor)
            cap[spans.kind == SpanKind.LINE] = np.inf  # a line next to a curve keeps its cruise
            feed = np.minimum(feed, cap)
    if honours and holds is not None:
        # stalled: before the whole program, slow down where a limit still breaks and only there (the spans and two
        # on either side, and a window around each worst jerk), a share SQUEEZE at a time
        for _ in range(SQUEEZE_ROUNDS):
            bad = np.flatnonzero(np.max(worst, axis=0) > margin)
            near = np.unique(np.clip(bad[:, None] + np.arange(-2, 3)[None, :], 0, len(spans) - 1))
            feed = feed.copy()
            feed[near] = np.minimum(feed[near], np.maximum(passed_speed(speed)[near], 1e-3) * SQUEEZE)
            jerky = bad[(worst[1][bad] > margin) & (where[1][bad] > 0)]
            v = where[1][jerky] * SQUEEZE
            holds = np.concatenate([holds, _holds_around(where[0][jerky], v, v * sp.window_ticks / f)])
            if worst[0].max() > margin:
                alpha *= float(np.clip(margin / worst[0].max(), 0.7, 0.995))
            sp, worst, speed, where = attempt(feed, alpha, holds, stretch)
            log.debug("jerk squeeze: v/a %.4f, j %.4f, %.4f s", worst[0].max(), worst[1].max(), sp.total_time_s)
            if worst.max() <= margin:
                return narrowed(fastest(sp)), False
    best = None  # fall back: the whole program slower (jerk falls like v³ on curves, v² A on lines)
    for use_holds in (holds, None):
        a_fb, feed_fb, speed_fb = alpha, feed, speed
        for _ in range(12):
            a_fb, feed_fb = a_fb * 0.8, np.minimum(feed_fb, speed_fb.max()) * 0.8
            sp, worst, speed_fb, _ = attempt(feed_fb, a_fb, use_holds, stretch)
            log.debug("jerk fallback: v/a %.4f, j %.4f, %.4f s", worst[0].max(), worst[1].max(), sp.total_time_s)
            if worst.max() <= margin:
                if best is None or sp.total_time_s < best.total_time_s:
                    best = sp
                break
    if best is not None:
        return narrowed(fastest(best)), True
    raise PlanningError(
        f"{request.machine.source}: no plan keeps the jerk limits j_max = {j_max} mm/s³ "
        "(is j_max tiny against a_max and the tick rate?)"
    )
