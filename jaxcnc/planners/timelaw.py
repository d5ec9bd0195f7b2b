"""The time law ``s(t)`` the built-in planners return: trapezoidal speed profiles per segment, on the tick grid.

Given ``v²`` at the junction nodes (from :mod:`jaxcnc.planners.lookahead`), each span is a trapezoid
(:func:`~jaxcnc.planners.motion.trapezoids`: accelerate from ``v0``, cruise at ``vp``, decelerate to
``v1``). :class:`Plan` implements the :class:`~jaxcnc.planners.protocol.TimeLaw` protocol the tick
stage samples.

Tick alignment. Between two junctions where the motion is at rest (a *group*: rest-to-rest
motion, or a dwell) the motion takes ``T`` seconds; the group is given ``ceil(T f)`` ticks and the
machine simply stays at rest for the fraction of a tick left at its end. Every group therefore
starts on a tick, every rest point — every block that ends at rest — is reached exactly on a
tick, and speeds are exactly as planned (no stretching). Time is kept as an int64 group start
tick plus a float offset (in ticks) inside the group, so an hour at 100 kHz loses no precision.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size
from jaxcnc.jitcache import cached_jit
from jaxcnc.planners.motion import trapezoid_position, trapezoid_speed, trapezoid_time_at, trapezoids
from jaxcnc.planners.protocol import GROUP_END_TOL_TICKS, DeviceLaw, LawWindow, TimeLaw

__all__ = [
    "PLAN_COLUMNS",
    "PLAN_KEYS",
    "GroupTicks",
    "Plan",
    "RAMP_COLUMNS",
    "Ramps",
    "SegmentCuts",
    "align_to_ticks",
    "plan_from_outputs",
    "ramp_accel",
    "sample_plan",
    "trapezoids",
]


#: A :class:`Plan`'s per-segment columns, in the order of its documentation.
PLAN_COLUMNS = (
    "length",
    "v0",
    "vp",
    "v1",
    "a_acc",
    "a_dec",
    "t_acc",
    "t_cru",
    "t_dec",
    "group_tick",
    "offset_ticks",
    "first_tick",
    "span",
    "s_start",
)


def ramp_accel(vp: np.ndarray, v: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``(n,)`` a ramp's acceleration ``(vp - v) / t`` (0 where ``t`` is not positive), as :func:`trapezoids`
    computes ``a_acc`` (``v = v0``, ``t = t_acc``) and ``a_dec`` (``v1``, ``t_dec``): the same operations, bit for
    bit. In blocks of :data:`_ACCEL_BLOCK` rows (the temporaries stay small)."""
    out = np.empty(vp.shape[0])
    for a in range(0, vp.shape[0], _ACCEL_BLOCK):
        b = slice(a, a + _ACCEL_BLOCK)
        ok = t[b] > 0
        out[b] = np.where(ok, (vp[b] - v[b]) / np.where(ok, t[b], 1.0), 0.0)
    return out


#: Segments per block of :func:`ramp_accel`.
_ACCEL_BLOCK = 1 << 18
#: Spans per block where a :class:`SegmentCuts` makes where many segments lie.
_CUT_BLOCK = 1 << 16


#: A segment's shape as :class:`Ramps` records it: one ramp up, one ramp down, a cruise, or any trapezoid.
RAMP_ACC, RAMP_DEC, RAMP_CRUISE, RAMP_GENERAL = 0, 1, 2, 3
#: The trapezoid columns :class:`Ramps` holds.
RAMP_COLUMNS = ("vp", "t_acc", "t_cru", "t_dec")


@dataclass(frozen=True, eq=False)
class Ramps:
    """A plan's trapezoids where most segments are one ramp or one cruise (a grid's intervals, each at constant
    ``s̈``): ``duration`` ``(n,)`` each segment's ``t_acc + t_cru + t_dec`` and ``phase`` ``(n,)`` int8 which one it
    is — :data:`RAMP_ACC` (``t_acc`` the duration, ``vp = v1``), :data:`RAMP_DEC` (``t_dec``, ``vp = v0``),
    :data:`RAMP_CRUISE` (``t_cru``, ``vp = v0 = v1``), the other times ``+0.0`` — or :data:`RAMP_GENERAL`: its
    ``vp`` and times stored whole in ``general`` ``(g, 4)`` at the rising segment indices ``general_at`` ``(g,)``.
    Every column bit for bit (:meth:`classify` admits a segment only where it is so), in 9 bytes a segment instead
    of 32: 5.2 M segments of the 1 M-block blended contour (92 % single ramps) 166 -> ~53 MB."""

    duration: np.ndarray
    phase: np.ndarray
    general_at: np.ndarray
    general: np.ndarray

    @staticmethod
    def classify(cols: dict[str, np.ndarray], v0: np.ndarray, v1: np.ndarray) -> tuple[np.ndarray, ...]:
        """``(duration, phase, general)`` of segments with trapezoid columns ``cols`` (``vp``, ``t_acc``, ``t_cru``,
        ``t_dec``, each ``(m,)``) and end speeds ``v0``, ``v1``: ``general`` ``(m,)`` bool the segments stored
        whole. The duration is summed as :func:`align_to_ticks` sums it."""
        vp, t_acc, t_cru, t_dec = (cols[k] for k in RAMP_COLUMNS)
        duration = t_acc + t_cru + t_dec
        zero = {k: cols[k].view(np.int64) == 0 for k in RAMP_COLUMNS[1:]}  # +0.0 (not -0.0)
        at_v0, at_v1 = _bits_equal(vp, v0), _bits_equal(vp, v1)
        phase = np.full(vp.shape[0], RAMP_GENERAL, np.int8)  # then each kind, the first listed last (it wins)
        phase[zero["t_acc"] & zero["t_dec"] & at_v0 & at_v1 & _bits_equal(duration, t_cru)] = RAMP_CRUISE
        phase[zero["t_acc"] & zero["t_cru"] & at_v0 & _bits_equal(duration, t_dec)] = RAMP_DEC
        phase[zero["t_cru"] & zero["t_dec"] & at_v1 & _bits_equal(duration, t_acc)] = RAMP_ACC
        return duration, phase, phase == RAMP_GENERAL

    def rows(self, k0: int, k1: int, v0: np.ndarray, v1: np.ndarray) -> dict[str, np.ndarray]:
        """``vp``, ``t_acc``, ``t_cru``, ``t_dec`` of segments ``k0..k1-1``, whose end speeds are ``v0``, ``v1``."""
        duration, phase = self.duration[k0:k1], self.phase[k0:k1]
        out = {
            "vp": np.where(phase == RAMP_ACC, v1, v0),
            "t_acc": np.where(phase == RAMP_ACC, duration, 0.0),
            "t_cru": np.where(phase == RAMP_CRUISE, duration, 0.0),
            "t_dec": np.where(phase == RAMP_DEC, duration, 0.0),
        }
        g0, g1 = np.searchsorted(self.general_at, [k0, k1])
        at = self.general_at[g0:g1] - k0
        for i, k in enumerate(RAMP_COLUMNS):
            out[k][at] = self.general[g0:g1, i]
        return out


def _bits_equal(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(m,)`` bool: ``a`` and ``b`` (float64) hold the same bits."""
    return a.view(np.int64) == b.view(np.int64)


@dataclass(frozen=True, eq=False)
class GroupTicks:
    """The groups of a plan (:func:`align_to_ticks`): ``first_segment`` ``(G,)`` the first segment of each (rising),
    ``tick`` ``(G,)`` int64 its first tick — every segment's ``group_tick`` with no per-segment storage."""

    first_segment: np.ndarray
    tick: np.ndarray

    def tick_of(self, k: np.ndarray) -> np.ndarray:
        """``group_tick`` of segments ``k`` (indices)."""
        return self.tick[np.searchsorted(self.first_segment, k, side="right") - 1]


@dataclass(frozen=True, eq=False)
class SegmentCuts:
    """Where the segments of a plan lie when span ``k`` was cut into ``counts[k]`` equal pieces of its length
    ``span_length[k]`` (:func:`~jaxcnc.planners.grid.cut_spans`, the grid the planner solved on): ``span``,
    ``s_start`` and ``length`` of any segment follow, bit for bit, with no per-segment storage."""

    span_length: np.ndarray
    counts: np.ndarray
    ends: np.ndarray  # (n_spans,) cumulative counts: the segment after each span's last

    @staticmethod
    def of(span_length: np.ndarray, counts: np.ndarray) -> SegmentCuts:
        counts = np.array(counts, np.int64)  # a copy: the planner refines its own in place
        return SegmentCuts(span_length, counts, np.cumsum(counts))

    def span_of(self, k: np.ndarray | int) -> np.ndarray:
        """The span that segment(s) ``k`` lie on."""
        return np.searchsorted(self.ends, k, side="right")

    def rows(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(span, s_start, length)`` of segments ``k0..k1-1``, made span block by span block."""
        from jaxcnc.planners.grid import cut_spans  # (the grid's own cut: the same bits)

        n = max(k1 - k0, 0)
        span, s_start, length = np.empty(n, np.int64), np.empty(n), np.empty(n)
        if n == 0:
            return span, s_start, length
        first, stop = int(self.span_of(k0)), int(self.span_of(k1 - 1)) + 1
        row = 0
        while first < stop:
            last = min(stop, first + _CUT_BLOCK)
            sp, a, b = cut_spans(self.span_length, self.counts, first, last)
            skip = k0 - int(self.ends[first - 1] if first else 0) if row == 0 else 0
            take = min(sp.size - skip, n - row)
            span[row : row + take] = sp[skip : skip + take]
            s_start[row : row + take] = a[skip : skip + take]
            length[row : row + take] = (b - a)[skip : skip + take]
            row, first = row + take, last
        return span, s_start, length


@dataclass(frozen=True, eq=False)
class Plan(TimeLaw):
    """The time law of a whole program as segments (NumPy arrays ``(n_segments,)``).

    A segment is a span or, where a planner cuts curved spans finer, a piece of one: it covers
    ``length[k]`` mm of span ``span[k]`` from ``s_start[k]`` mm after the span's start (spans in
    path order, each covered by consecutive segments). Segment ``k`` starts at tick
    ``group_tick[k] + offset_ticks[k]`` (fractional), runs ``t_acc, t_cru, t_dec`` seconds (a dwell
    is all cruise at zero speed), with speeds ``v0 → vp → v1`` mm/s and ramp accelerations
    ``a_acc``, ``a_dec`` mm/s². ``first_tick[k]`` is the first tick at or after its start. The
    table has ticks ``0..n_ticks``.

    Storage (``columns``): each of :data:`PLAN_COLUMNS` stored, or derived where it follows from the others bit for
    bit — ``v_nodes`` ``(n + 1,)`` in place of ``v0`` and ``v1`` (a segment ends at the speed the next starts at),
    ``a_acc``/``a_dec`` left out (:func:`ramp_accel` of the speeds and times), ``span``/``s_start``/``length`` left
    out with ``cuts`` (:class:`SegmentCuts`). The attributes read the same either way; the tick stage asks for
    windows of rows (:meth:`rows`), so a derived column is never made whole there. ``group_tick`` and ``first_tick``
    left out with ``groups`` (:class:`GroupTicks`: a group's segments share its first tick, and ``first_tick`` is
    ``group_tick + ceil(offset_ticks)``). ``vp``, ``t_acc``, ``t_cru``, ``t_dec`` left out with ``ramps``
    (:class:`Ramps`: most segments of a fine grid are one ramp). A 1 M-block blended contour (5.2 M segments)
    keeps 2 columns and the ramps instead of 14 columns: 579 -> 167 MB (with its SegmentCuts; 344 MB before the ramps
    and the groups).
    """

    columns: dict
    n_ticks: int
    tick_hz: float
    cuts: SegmentCuts | None = None
    groups: GroupTicks | None = None
    ramps: Ramps | None = None

    def __post_init__(self) -> None:
        for v in self.columns.values():
            v.setflags(write=False)

    def __len__(self) -> int:
        return int(self.columns["offset_ticks"].shape[0])

    def column(self, name: str, k0: int = 0, k1: int | None = None) -> np.ndarray:
        """Column ``name`` of segments ``k0..k1-1`` (all by default): stored rows are views, derived ones made."""
        n = len(self)
        k1 = n if k1 is None else min(k1, n)
        cols = self.columns
        if name in cols:
            return cols[name][k0:k1]
        if name in ("v0", "v1") and "v_nodes" in cols:
            return cols["v_nodes"][k0 + (name == "v1") : k1 + (name == "v1")]
        if name in RAMP_COLUMNS and self.ramps is not None:
            return self._ramp_rows(k0, k1)[name]
        if name in ("a_acc", "a_dec"):
            v, t = ("v0", "t_acc") if name == "a_acc" else ("v1", "t_dec")
            trap = self._ramp_rows(k0, k1) if self.ramps is not None else {k: cols[k][k0:k1] for k in ("vp", t)}
            return ramp_accel(trap["vp"], self.column(v, k0, k1), trap[t])
        if name in ("span", "s_start", "length") and self.cuts is not None:
            return self.cuts.rows(k0, k1)[("span", "s_start", "length").index(name)]
        if name in ("group_tick", "first_tick") and self.groups is not None:
            return self._ticks_of(name, np.arange(k0, max(k0, k1)))
        raise KeyError(f"a Plan has no column {name!r}")

    def finer(self, k: int) -> Plan:
        """The same motion on a tick grid ``k`` times finer (``tick_hz * k``; every stored column made whole): each
        group starts on the same instant (tick ``k`` times its tick here), each segment at the same offset (``k``
        times its offset in ticks) and lasts as long, and ``first_tick`` is the first fine tick at or after its
        start. A tick here is tick ``k`` times it there, at the same position."""
        if k == 1:
            return self
        cols = {name: self.column(name) for name in PLAN_COLUMNS}
        cols["group_tick"] = cols["group_tick"] * k
        cols["offset_ticks"] = cols["offset_ticks"] * k
        cols["first_tick"] = cols["group_tick"] + np.ceil(cols["offset_ticks"]).astype(np.int64)
        return Plan(cols, self.n_ticks * k, self.tick_hz * k)

    def _ramp_rows(self, k0: int, k1: int) -> dict[str, np.ndarray]:
        """``vp``, ``t_acc``, ``t_cru``, ``t_dec`` of segments ``k0..k1-1`` from :attr:`ramps`."""
        k1 = max(k0, k1)
        return self.ramps.rows(k0, k1, self.column("v0", k0, k1), self.column("v1", k0, k1))

    def _ticks_of(self, name: str, k: np.ndarray) -> np.ndarray:
        """``group_tick`` or ``first_tick`` of segments ``k`` (indices), without making the whole column."""
        if name in self.columns:
            return self.columns[name][k]
        group_tick = self.groups.tick_of(k)
        if name == "group_tick":
            return group_tick
        return group_tick + np.ceil(self.columns["offset_ticks"][k]).astype(np.int64)  # as align_to_ticks does

    def segment_at_tick(self, tick: int) -> int:
        """The last segment whose first tick is at or before ``tick`` (0 before the first)."""
        n = len(self)
        if "first_tick" in self.columns:
            k = int(np.searchsorted(self.columns["first_tick"], tick, side="right")) - 1
        else:  # the first ticks rise with the segments: bisect them, made one at a time
            first_tick = lambda i: int(self._ticks_of("first_tick", np.array([i]))[0])  # noqa: E731
            k = bisect.bisect_right(range(n), tick, key=first_tick) - 1
        return int(np.clip(k, 0, n - 1))

    def rows(self, k0: int, k1: int, names: tuple[str, ...] = PLAN_COLUMNS) -> dict[str, np.ndarray]:
        """Columns ``names`` of segments ``k0..k1-1`` (where the segments lie made once for all three)."""
        out = {}
        if self.cuts is not None and any(k in names and k not in self.columns for k in ("span", "s_start", "length")):
            out.update(zip(("span", "s_start", "length"), self.cuts.rows(k0, min(k1, len(self))), strict=True))
        if self.ramps is not None and any(k in names for k in RAMP_COLUMNS + ("a_acc", "a_dec")):
            ramps = self._ramp_rows(k0, min(k1, len(self)))
            out.update((k, v) for k, v in ramps.items() if k in names)
            for k, v, t in (("a_acc", "v0", "t_acc"), ("a_dec", "v1", "t_dec")):
                if k in names and k not in self.columns:
                    out[k] = ramp_accel(ramps["vp"], self.column(v, k0, k1), ramps[t])
        for k in names:
            if k not in out:
                out[k] = self.column(k, k0, k1)
        return {k: out[k] for k in names}

    length = property(lambda self: self.column("length"), doc="``(n,)`` mm of path each segment covers.")
    v0 = property(lambda self: self.column("v0"), doc="``(n,)`` mm/s at each segment's start.")
    vp = property(lambda self: self.column("vp"), doc="``(n,)`` mm/s, the trapezoid's peak.")
    v1 = property(lambda self: self.column("v1"), doc="``(n,)`` mm/s at each segment's end.")
    a_acc = property(lambda self: self.column("a_acc"), doc="``(n,)`` mm/s², the first ramp.")
    a_dec = property(lambda self: self.column("a_dec"), doc="``(n,)`` mm/s², the last ramp.")
    t_acc = property(lambda self: self.column("t_acc"), doc="``(n,)`` s of the first ramp.")
    t_cru = property(lambda self: self.column("t_cru"), doc="``(n,)`` s at the peak speed.")
    t_dec = property(lambda self: self.column("t_dec"), doc="``(n,)`` s of the last ramp.")
    group_tick = property(lambda self: self.column("group_tick"), doc="``(n,)`` int64, the group's first tick.")
    offset_ticks = property(lambda self: self.column("offset_ticks"), doc="``(n,)`` ticks from it to the start.")
    first_tick = property(lambda self: self.column("first_tick"), doc="``(n,)`` int64, the first tick at or after.")
    span = property(lambda self: self.column("span"), doc="``(n,)`` the span each segment lies on.")
    s_start = property(lambda self: self.column("s_start"), doc="``(n,)`` mm from the span's start.")

    @property
    def total_time_s(self) -> float:
        return self.n_ticks / self.tick_hz

    @property
    def duration_s(self) -> np.ndarray:
        return self.t_acc + self.t_cru + self.t_dec

    def span_first_segment(self, n_spans: int) -> np.ndarray:
        """``(n_spans,)`` index of the first segment of each span."""
        if self.cuts is not None and "span" not in self.columns and self.cuts.counts.shape[0] == n_spans:
            return self.cuts.ends - self.cuts.counts
        return np.searchsorted(self.span, np.arange(n_spans), side="left")

    def span_start_ticks(self, n_spans: int) -> np.ndarray:
        """``(n_spans,)`` the first tick at or after each span's start."""
        return self._ticks_of("first_tick", self.span_first_segment(n_spans))

    def ticks_at(self, seg: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The tick nearest to where segment ``seg`` has covered ``s`` mm (the trapezoid inverted exactly)."""
        k = seg
        tau = trapezoid_time_at(
            self.v0[k], self.vp[k], self.a_acc[k], self.a_dec[k], self.t_acc[k], self.t_cru[k], self.t_dec[k], s
        )
        group_tick = self._ticks_of("group_tick", np.asarray(k))
        return np.rint(group_tick + self.offset_ticks[k] + tau * self.tick_hz).astype(np.int64)

    def _span_at(self, k: int) -> int:
        """The span segment ``k`` lies on (without making the whole column where it is derived)."""
        return int(self.column("span", k, k + 1)[0])

    def device_law(self) -> DeviceLaw:
        """The segments padded to a bucket (padding never found: first tick ``int64 max``) and :func:`plan_span_s`."""
        n = len(self)
        return DeviceLaw(plan_span_s, self._device_rows(0, n, bucket_size(n)))

    def device_window(self, tick: int, segments: int) -> LawWindow:
        """Segments ``k0 .. k0 + segments`` (fewer at the end), ``k0`` the one that holds ``tick``, padded to
        ``segments`` rows, their spans counted from ``span[k0]``. Their ticks are found in the window as in the
        whole law (the last segment whose first tick is at or before the tick) up to the first tick of the
        segment after them: ``tick_end``."""
        n = len(self)
        k0 = self.segment_at_tick(tick)
        k1 = min(k0 + segments, n)
        tick_end = int(self.column("first_tick", k1, k1 + 1)[0]) if k1 < n else self.n_ticks + 1
        span0 = self._span_at(k0)
        law = DeviceLaw(plan_span_s, self._device_rows(k0, k1, segments, span0))
        return LawWindow(law, span0, self._span_at(k1 - 1) + 1, tick_end)

    def _device_rows(self, k0: int, k1: int, rows: int, span0: int = 0) -> dict:
        """Segments ``k0..k1-1`` as device arrays of ``rows`` rows (the padding's first tick ``int64 max``: never
        found), their span indices less ``span0``."""
        big = np.iinfo(np.int64).max
        arrays = {}
        for k, a in self.rows(k0, k1, PLAN_KEYS + ("length", "span", "s_start")).items():
            out = np.full(rows, big if k == "first_tick" else 0, a.dtype)
            out[: k1 - k0] = a - span0 if k == "span" else a
            arrays[k] = jax.device_put(out)
        arrays["tick_hz"] = jax.device_put(np.float64(self.tick_hz))
        return arrays


#: The per-segment outputs of :func:`trapezoids` + :func:`align_to_ticks` that a :class:`Plan` keeps (every column
#: but where the segments lie).
_PROFILE_KEYS = tuple(k for k in PLAN_COLUMNS if k not in ("length", "span", "s_start"))


def plan_from_outputs(out: dict, length: np.ndarray, span: np.ndarray, s_start: np.ndarray, tick_hz: float) -> Plan:
    """A read-only :class:`Plan` from the (possibly padded) outputs of :func:`align_to_ticks`, every column stored.

    ``length``, ``span``, ``s_start`` ``(n_segments,)`` describe the segments; ``out`` rows past
    ``n_segments`` (bucket padding) are dropped.
    """
    n = length.shape[0]
    columns = {k: np.asarray(out[k][:n]) for k in _PROFILE_KEYS} | {"length": length, "span": span, "s_start": s_start}
    return Plan(columns, int(out["n_ticks"]), tick_hz)


def _offsets_in_groups(dur: jnp.ndarray, starts: jnp.ndarray, group: jnp.ndarray) -> jnp.ndarray:
    """``(n,)`` each row's exclusive sum of ``dur`` since the start of its group (``starts`` True there, where it is
    exactly 0; ``group``: each row's group, 0, 1, …).

    The whole column's exclusive running sum less its value at the group's start: XLA compiles a running sum (a
    ``reduce_window``) and one scatter and gather in ~0.6 CPU-s, where the segmented ``associative_scan`` this
    replaces took 2.4 at 98k rows (a first run's alignment, on the development machine). Rounding follows the whole
    column's running sum (its last bits: ~1e-9 ticks at 5 M segments), not each group's own."""
    before = jnp.cumsum(dur) - dur
    at_start = jax.ops.segment_sum(jnp.where(starts, before, 0.0), group, num_segments=dur.shape[0])
    return jnp.where(starts, 0.0, before - at_start[group])


def align_to_ticks(prof: dict[str, jnp.ndarray], rest_start: jnp.ndarray, tick_hz: float) -> dict[str, jnp.ndarray]:
    """Give each rest-to-rest group a whole number of ticks and place segments on the grid.

    Args:
        prof: output of :func:`trapezoids`.
        rest_start: ``(n,)`` bool, the motion is at rest at the start of the span (a group starts).
    Returns:
        ``prof`` plus ``group_tick`` (int64), ``offset_ticks``, ``first_tick`` (int64), ``n_ticks`` (scalar int64)
        and ``g_start`` ``(n,)`` int64, the first tick of each group in order (rows past the last group: unused).
    """
    n = rest_start.shape[0]
    dur_ticks = (prof["t_acc"] + prof["t_cru"] + prof["t_dec"]) * tick_hz
    group = jnp.cumsum(rest_start.astype(jnp.int64)) - 1
    g_ticks = jax.ops.segment_sum(dur_ticks, group, num_segments=n)
    # the tolerance guards against ceil(5.000000000001) = 6 from rounding of the sums (protocol's derivation)
    g_whole = jnp.ceil(g_ticks - GROUP_END_TOL_TICKS).astype(jnp.int64)
    g_whole = jnp.maximum(g_whole, 0)
    out = dict(prof)
    dur = dur_ticks
    g_start = jnp.cumsum(g_whole) - g_whole
    offset = _offsets_in_groups(dur, rest_start, group)  # exact 0 at the starts
    out["g_start"] = g_start  # each group's first tick (groups 0..G-1; the rest of the rows: past the end)
    out["group_tick"] = g_start[group]
    out["offset_ticks"] = offset
    out["first_tick"] = out["group_tick"] + jnp.ceil(offset).astype(jnp.int64)
    out["n_ticks"] = jnp.sum(g_whole)
    return out


#: The per-segment fields of :class:`Plan` the tick kernels read (as a dict of JAX arrays).
PLAN_KEYS = ("v0", "vp", "a_acc", "a_dec", "t_acc", "t_cru", "t_dec", "group_tick", "offset_ticks", "first_tick")
#: A segment's trapezoid, in the argument order of :mod:`jaxcnc.planners.motion`.
_TRAPEZOID = ("v0", "vp", "a_acc", "a_dec", "t_acc", "t_cru", "t_dec")


def local_time(plan: dict[str, jnp.ndarray], seg: jnp.ndarray, tick: jnp.ndarray, tick_hz: float) -> jnp.ndarray:
    """Seconds since segment ``seg`` started at integer ``tick``, from exact integer tick differences."""
    tau = ((tick - plan["group_tick"][seg]).astype(jnp.float64) - plan["offset_ticks"][seg]) / tick_hz
    return jnp.maximum(tau, 0.0)


def s_at(
    plan: dict[str, jnp.ndarray], length: jnp.ndarray, seg: jnp.ndarray, tick: jnp.ndarray, tick_hz: float
) -> jnp.ndarray:
    """Arc length from the start of segment ``seg`` at integer ``tick`` (arrays ``(m,)``).

    ``plan`` holds the per-segment arrays of :class:`Plan` (as JAX arrays, ``PLAN_KEYS``).
    """
    tau = local_time(plan, seg, tick, tick_hz)
    s = trapezoid_position(*(plan[k][seg] for k in _TRAPEZOID), tau, xp=jnp)
    return jnp.clip(s, 0.0, length[seg])


def v_at(plan: dict[str, jnp.ndarray], seg: jnp.ndarray, tick: jnp.ndarray, tick_hz: float) -> jnp.ndarray:
    """Path speed (mm/s) on segment ``seg`` at integer ``tick`` (arrays ``(m,)``)."""
    tau = local_time(plan, seg, tick, tick_hz)
    return trapezoid_speed(*(plan[k][seg] for k in _TRAPEZOID), tau, xp=jnp)


def sample_plan(plan: Plan, ticks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The time law at integer ``ticks``: ``(segment, s_mm, v_mm_s)``, each ``(m,)``.

    ``s_mm`` is the path parameter from the program start (arc length on lines and arcs, within
    1e-6 of it on curves) — the ``s(t)`` researchers compare between planners; ``v_mm_s`` its
    derivative.
    """
    arrays = {k: getattr(plan, k) for k in PLAN_KEYS}
    out = _sample(arrays, plan.length, np.asarray(ticks, dtype=np.int64), plan.tick_hz)
    return tuple(np.asarray(a) for a in out)


@cached_jit(static_argnames=("tick_hz",))
def _sample(arrays: dict, length: jnp.ndarray, t: jnp.ndarray, tick_hz: float):
    seg = segment_of_tick(arrays["first_tick"], t)
    s_local = s_at(arrays, length, seg, t, tick_hz)
    s0 = jnp.concatenate([jnp.zeros(1), jnp.cumsum(length)[:-1]])
    return seg, s0[seg] + s_local, v_at(arrays, seg, t, tick_hz)


def segment_of_tick(first_tick: jnp.ndarray, tick: jnp.ndarray) -> jnp.ndarray:
    """Index of the segment that holds each tick ``(m,)``: the last one whose first tick (``(n,)``, sorted) is ≤ it.

    The tick stage asks for runs of consecutive ticks (a chunk ``t0 .. t0 + m - 1``): then the count of first ticks
    at or before each tick is a histogram of the segments' starts in the run, summed — one pass over the segments
    and one over the run, instead of a binary search of ``log2 n`` dependent gathers for every tick (a third of the
    tick kernel's time on a 131k-segment window). Any other ticks (the last chunk, clamped to the job's end) take
    the binary search; both give the same indices.
    """
    n, m = first_tick.shape[0], tick.shape[0]

    def search(_):
        return jnp.clip(jnp.searchsorted(first_tick, tick, side="right") - 1, 0, n - 1)

    if m < 2:
        return search(None)

    def count(_):
        t0 = tick[0]
        inside = (first_tick > t0) & (first_tick - m < t0)  # starts at a later tick of the run (no overflow)
        at = jnp.where(inside, first_tick - t0, m)  # which one (m: outside the run, dropped)
        starts = jnp.zeros(m, first_tick.dtype).at[at].add(1, mode="drop")
        seg = jnp.clip(jnp.sum(first_tick <= t0) + jnp.cumsum(starts) - 1, 0, n - 1)
        return seg.astype(jax.eval_shape(search, None).dtype)

    run = jnp.all(tick[1:] - tick[:-1] == 1)
    return jax.lax.cond(run, count, search, None)


def plan_span_s(arrays: dict, tick: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """A :class:`Plan`'s :class:`~jaxcnc.planners.protocol.DeviceLaw` function: ``(span, s in span)`` at ``tick``."""
    seg = segment_of_tick(arrays["first_tick"], tick)
    s = arrays["s_start"][seg] + s_at(arrays, arrays["length"], seg, tick, arrays["tick_hz"])
    return arrays["span"][seg], s
