"""The planner protocols: what a planner is asked (:class:`PlanRequest`), what it is (:class:`Planner`), what it
answers (:class:`TimeLaw`), and the one safety margin below the machine's limits.

A third-party planner subclasses :class:`Planner`, declares its capabilities as class attributes and
implements :meth:`Planner.plan`; it returns a :class:`TimeLaw` — in practice a
:class:`~jaxcnc.planners.timelaw.Plan` (per-segment trapezoids on the tick grid), which every built-in
planner returns and which the S-curve stage needs. The tick stage samples any :class:`TimeLaw` through
:meth:`TimeLaw.device_law` without knowing which planner made it.

>>> class Gentle(Planner):                                      # doctest: +SKIP
...     name = "gentle"
...     def plan(self, request):
...         slower = dataclasses.replace(request, v_max=request.v_max / 2, a_max=request.a_max / 2)
...         return get_planner("topp").plan(slower)

The margin. The table is verified at the tick rate from positions that carry a resolution of 2^-32
discrete, so a plan exactly at a limit reads at the limit plus rounding. Every limit a planner is given
(:attr:`PlanRequest.v_max`, ``a_max``, ``j_max``, and the same in a pulse request) is therefore the
machine's limit times ``1 - NUMERIC_MARGIN`` already (:func:`with_margin`, applied once, by
:func:`request_limits`): a planner plans *at* the request's limits and its table passes ``jaxcnc check``.
Where the float64 rounding of the positions the tick stage computes provably reads inside half the
check's own rounding slack (:func:`rounding_fits`: small coordinates, low tick rates), speed and
acceleration get no margin: the plan runs at the machine's limits, so a time-optimal motion whose optimum
is a whole number of ticks plans to exactly that number (a margin of any size makes it one tick longer).
Programmed speeds (feed, rapid cap) are not machine limits and are passed as programmed. A planner's
own discretisation allowance (``topp``'s ``GRID_MARGIN`` for what the path's derivatives do between
grid nodes) is its business and stays inside it.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from jaxcnc.geometry.spans import Spans
    from jaxcnc.machine import MachineConfig

#: Relative margin below every machine limit, so that values measured on the table — whose positions
#: carry a resolution of 2^-32 discrete — read below the limit rather than on it.
NUMERIC_MARGIN = 1e-5


#: ``jaxcnc check``'s relative slack for floating-point rounding when it compares a value read on the table
#: with a limit (:data:`jaxcnc.ticks.verify.REL_SLACK`; a test holds the two equal).
CHECK_REL_SLACK = 1e-9
#: How far past a whole tick a rest-to-rest group's motion may end and still be given that tick
#: (:func:`~jaxcnc.planners.timelaw.align_to_ticks`): float sums of durations land a hair past it. The tick
#: that ends such a group reads its last deceleration over ``1 + GROUP_END_TOL_TICKS`` ticks beside the next
#: group's first acceleration (a reversal): ``a (1 + GROUP_END_TOL_TICKS)``, half the check's slack.
GROUP_END_TOL_TICKS = CHECK_REL_SLACK / 2
#: The rate at which the S-curve stage measures jerk, at least (:func:`jerk_substeps`): the motion between a coarse
#: table's ticks keeps ``j_max`` too, and the plan does not depend on the tick rate (the peers' meander520 with
#: ``j_max`` 1e6 planned to 38.63 s at 1 kHz and 39.42 s at 10 kHz when measured at each rate).
JERK_MEASURE_HZ = 10_000.0


def jerk_substeps(tick_hz: float) -> int:
    """Fine ticks per tick at which jerk is measured and capped: the least whole ``k`` with ``k f`` at least
    :data:`JERK_MEASURE_HZ`. Finite differences at a tick ``k`` times as long are weighted means of the fine ones
    (``Δ_{kh} = Δ_h (1 + E + … + E^{k-1})``, ``E`` the fine shift): values within the limits on the fine grid are
    within them on the table's."""
    return max(1, math.ceil(JERK_MEASURE_HZ / tick_hz - 1e-9))


def jerk_limits(request: PlanRequest) -> np.ndarray | None:
    """``(axes,)`` the request's jerk limits where any is finite (the planner keeps them), else ``None``."""
    j_max = request.j_max
    return np.asarray(j_max, np.float64) if j_max is not None and bool(np.any(np.isfinite(j_max))) else None


def step_rate_hz(request: PlanRequest) -> float:
    """The rate whose one tick a velocity step (a kink passed moving) or a curvature step is spread over, for the
    planners' caps on them: the machine's tick rate, or under jerk limits the rate they are measured at (tick rate
    times :func:`jerk_substeps`: caps that hold there hold on the table's ticks, the same at 1 and 10 kHz)."""
    f = request.machine.tick_hz
    return f * jerk_substeps(f) if jerk_limits(request) is not None else f


#: Bound on the error of a position the tick stage computes in float64 (a line's ``origin + s t``, an arc's
#: ``centre + r (cos ψ e1 + sin ψ e2)``, a polynomial piece's origin plus its local value), in units in the
#: last place of the largest magnitude involved (:func:`coordinate_extent_mm`). Measured 0.25–2.0 against a long-double
#: evaluation of the same plans (docs/planning.md; ``tests/test_margin.py`` holds the bound).
POSITION_ULPS = 8


def range_min(size: int, lo: np.ndarray, count: np.ndarray, value: np.ndarray) -> np.ndarray:
    """``(size,)``: at each index the least ``value[k]`` of the ranges ``lo[k] .. lo[k] + count[k] - 1`` that reach
    it (``inf`` where none does; ranges of no length reach nothing) — the spans or nodes the rows of ``hold_caps``
    reach, each capped by the lowest of them.

    Without listing every (range, index) pair, whose number grows with how much the ranges overlap (the S-curve
    stage's holds accumulate round after round: 7.4 M pairs for 284k holds on laser_parts_a's grid). A range of
    ``c`` indices is the union of two blocks of ``2^⌊log2 c⌋`` (they overlap, which a minimum does not mind): each
    block's value goes to the table of its size (``np.minimum.at``, two entries per range), and each table, from
    the largest blocks down, passes its values on to the two halves of each block in the table below — the same
    minima as over the pairs, exactly (a minimum is the same in any order; only which of a tied ``0.0`` and ``-0.0``
    is kept may differ, and caps are never negative), in ``O(size · log2(longest range))``.
    """
    out = np.full(size, np.inf)
    keep = count > 0
    if not keep.any():
        return out
    lo, count, value = lo[keep], count[keep], np.asarray(value, dtype=np.float64)[keep]
    level = np.frexp(count.astype(np.float64))[1] - 1  # ⌊log2 c⌋, exact for integers
    table = None  # blocks of 2^k indices from k = top down; entry i covers i .. i + 2^k - 1
    for k in range(int(level.max()), -1, -1):
        below = out if k == 0 else np.full(size - (1 << k) + 1, np.inf)
        if table is not None:  # the blocks of 2^(k+1): each is its two halves
            half = 1 << k
            n = table.size
            np.minimum(below[:n], table, out=below[:n])
            np.minimum(below[half : half + n], table, out=below[half : half + n])
        sel = level == k
        if sel.any():
            np.minimum.at(below, lo[sel], value[sel])
            np.minimum.at(below, lo[sel] + count[sel] - (1 << k), value[sel])
        table = below
    return out


def with_margin(limit):
    """``limit`` (a number or an array) reduced by :data:`NUMERIC_MARGIN`: what a planner may reach."""
    return limit * (1.0 - NUMERIC_MARGIN)


def coordinate_extent_mm(spans: Spans) -> float:
    """The largest magnitude, mm, of a coordinate the tick stage adds up while evaluating ``spans``.

    The spans' extents (``lo``, ``hi``) and, for arcs, ``|centre| + radius`` (the centre of a large arc
    may lie far outside the part).
    """
    # max |x| as the larger of |max x| and |min x| (each with 0): the same value, without the (n, 3) magnitudes
    extent = max(0.0, *(abs(float(f(a, initial=0.0))) for a in (spans.lo, spans.hi) for f in (np.max, np.min)))
    arcs = spans.arcs
    if len(arcs):
        extent = max(extent, float(np.max(np.abs(arcs.center).max(axis=1) + np.abs(arcs.radius))))
    return extent


def rounding_fits(limit, order: int, extent_mm: float, tick_hz: float) -> np.ndarray:
    """Whether the float64 rounding of the table's positions reads within half the check's slack of ``limit``.

    The ``order``-th difference (1: speed, 2: acceleration) of positions each within ``e =
    POSITION_ULPS · ulp(extent_mm)`` of exact is within ``2^order e`` of the exact one; divided by
    ``tick⁻ᵒʳᵈᵉʳ`` it is a speed or acceleration error of ``2^order e f^order``. Where that is at most
    ``CHECK_REL_SLACK / 2`` of the limit, a plan *at* the limit reads within the check's slack: the other half
    is :data:`GROUP_END_TOL_TICKS`, the fixed-point rounding has the check's own allowance. ``limit``: a
    number or an array (``inf`` fits).
    """
    error = 2.0**order * POSITION_ULPS * float(np.spacing(max(extent_mm, 1.0))) * tick_hz**order
    return np.asarray(error <= 0.5 * CHECK_REL_SLACK * np.asarray(limit, dtype=np.float64))


def machine_limits(machine: MachineConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(v_max, a_max, j_max)``, each ``(3,)`` for x, y, z, as the machine file gives them.

    ``inf`` where the machine lacks the axis or sets no ``j_max``. These are the limits the table is
    verified against; planners get :func:`request_limits`.
    """
    from jaxcnc.program import PROGRAM_AXES

    lim = machine.limits(PROGRAM_AXES)
    return tuple(np.where(np.isnan(lim[k]), np.inf, lim[k]) for k in ("v_max", "a_max", "j_max"))


def request_limits(machine: MachineConfig, extent_mm: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(v_max, a_max, j_max)`` ``(3,)`` a planner must honour: :func:`machine_limits` with the margin.

    With ``extent_mm`` (:func:`coordinate_extent_mm` of the path), speed and acceleration limits whose
    table readings :func:`rounding_fits` are given whole: the plan may run at the machine's limits. Jerk
    always keeps the margin.
    """
    v_max, a_max, j_max = machine_limits(machine)
    if extent_mm is None:
        return with_margin(v_max), with_margin(a_max), with_margin(j_max)
    f = machine.tick_hz
    v = np.where(rounding_fits(v_max, 1, extent_mm, f), v_max, with_margin(v_max))
    a = np.where(rounding_fits(a_max, 2, extent_mm, f), a_max, with_margin(a_max))
    return v, a, with_margin(j_max)


@dataclass(frozen=True, eq=False)
class PlanRequest:
    """What a planner is asked to plan.

    Attributes:
        spans: the path.
        feed_mm_s: ``(n,)`` programmed speed of each span (feed, or the rapid cap for G0), as programmed.
        dwell_s: ``(n,)`` dwell time of each (point) span.
        stop_before: ``(n,)`` bool, the motion must be at rest where the span starts.
        v_max, a_max: ``(3,)`` limits of the x, y, z axes to plan at: the machine's, already reduced by
            :data:`NUMERIC_MARGIN` (``inf`` where the machine lacks an axis).
        machine: the machine (tick rate, tolerances, ...).
        j_max: optional ``(3,)`` jerk limits of the x, y, z axes, reduced the same way (``inf`` where unset
            or absent).
        hold_caps: optional ``(k, 3)`` rows ``(s_lo, s_hi, v)``: the speed stays ≤ ``v`` mm/s between
            path lengths ``s_lo`` and ``s_hi`` mm from the program start. The S-curve stage asks for flat
            speed minima this way, of planners that declare ``honours_holds``; the others get ``None``.
    """

    spans: Spans
    feed_mm_s: np.ndarray
    dwell_s: np.ndarray
    stop_before: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray
    machine: MachineConfig
    j_max: np.ndarray | None = None
    hold_caps: np.ndarray | None = None


class DeviceLaw(NamedTuple):
    """A time law as the tick stage's compiled kernel reads it.

    Attributes:
        fn: a pure, jittable function ``fn(arrays, ticks) -> (span, s)``: for integer ``ticks`` ``(m,)``
            (int64) the span index ``(m,)`` and the path parameter within that span ``(m,)`` (mm). It is a
            *static* argument of the kernel: hashable, and equal for time laws that share a compiled
            program (a module-level function, or a frozen dataclass with ``__call__``).
        arrays: a dict of device arrays (any pytree) ``fn`` reads; sizes padded to buckets
            (:mod:`jaxcnc.buckets`) so that jobs of similar size share the compiled kernel.
    """

    fn: Callable[[Any, Any], tuple[Any, Any]]
    arrays: dict


class LawWindow(NamedTuple):
    """Part of a time law as the tick stage samples a long job, window by window (:meth:`TimeLaw.device_window`).

    Attributes:
        law: the window's :class:`DeviceLaw`; its ``fn`` gives span indices counted from ``span_first``.
        span_first, span_last: the spans the window's ticks lie on (``span_last`` excluded).
        tick_end: the window holds ticks from the one it was asked for up to ``tick_end`` (excluded).
    """

    law: DeviceLaw
    span_first: int
    span_last: int
    tick_end: int


class TimeLaw(abc.ABC):
    """The time law ``s(t)`` of a whole program, whatever planned it: what the tick stage samples.

    The path is described in *segments* (a span, or a piece of one) in path order; every time law has
    these attributes (dataclass fields or properties):

    Attributes:
        tick_hz: the tick rate (Hz).
        n_ticks: the table has ticks ``0..n_ticks``.
        span: ``(n_segments,)`` the span each segment lies on.
        s_start: ``(n_segments,)`` mm from the span's start to the segment's start.
        length: ``(n_segments,)`` mm of path the segment covers.
    """

    tick_hz: float
    n_ticks: int
    span: np.ndarray
    s_start: np.ndarray
    length: np.ndarray

    @property
    def total_time_s(self) -> float:
        return self.n_ticks / self.tick_hz

    def __len__(self) -> int:
        return int(self.length.shape[0])

    @abc.abstractmethod
    def span_start_ticks(self, n_spans: int) -> np.ndarray:
        """``(n_spans,)`` int64, the first tick at or after each span's start (block and laser events)."""

    @abc.abstractmethod
    def ticks_at(self, seg: np.ndarray, s: np.ndarray) -> np.ndarray:
        """``(m,)`` int64, the tick at which segment ``seg`` ``(m,)`` has covered ``s`` ``(m,)`` mm (PSO pulses)."""

    @abc.abstractmethod
    def device_law(self) -> DeviceLaw:
        """The arrays and the static function the tick stage's kernel samples (see :class:`DeviceLaw`)."""

    def device_window(self, tick: int, segments: int) -> LawWindow | None:
        """The law over at most ``segments`` segments from the one that holds ``tick``, its arrays padded to
        ``segments`` rows (one compiled shape for every window): what the tick stage holds on the device at once
        for a long job. ``None`` (this default): the law is sampled whole (:meth:`device_law`)."""
        return None


class Planner(abc.ABC):
    """A velocity planner: a :class:`PlanRequest` in, a :class:`TimeLaw` out.

    Capabilities are declared as class attributes (an instance may override them):

    Attributes:
        name: the name it is registered under by default (``--planner NAME``).
        handles_jerk: it honours ``request.j_max`` itself. Otherwise, when the machine sets ``j_max``,
            :func:`~jaxcnc.planners.plan_job` runs it inside the S-curve stage
            (:mod:`jaxcnc.planners.smoothing`), which averages its time law — it must then return a
            :class:`~jaxcnc.planners.timelaw.Plan`.
        honours_holds: it honours ``request.hold_caps`` (speed caps on stretches of the path, which the
            S-curve stage asks for); a planner without it is never given any.

    Limits: plan at the request's limits; they are already below the machine's by the margin (module
    docstring). ``jaxcnc check`` verifies the table independently, whatever the planner did.
    """

    name: str = ""
    handles_jerk: bool = False
    honours_holds: bool = False

    @abc.abstractmethod
    def plan(self, request: PlanRequest) -> TimeLaw:
        """The time law of the request's whole program."""

    def __call__(self, request: PlanRequest) -> TimeLaw:
        return self.plan(request)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}>"


class FunctionPlanner(Planner):
    """A plain function ``(PlanRequest) -> TimeLaw`` as a :class:`Planner`, its capabilities declared here."""

    def __init__(
        self,
        fn: Callable[[PlanRequest], TimeLaw],
        name: str | None = None,
        *,
        handles_jerk: bool = False,
        honours_holds: bool = False,
    ):
        self.fn = fn
        self.name = name or getattr(fn, "__name__", "")
        self.handles_jerk, self.honours_holds = handles_jerk, honours_holds

    def plan(self, request: PlanRequest) -> TimeLaw:
        return self.fn(request)


def as_planner(obj: Any, name: str | None = None) -> Planner:
    """A :class:`Planner` from a Planner instance, a Planner subclass (instantiated without arguments) or a
    plain function (wrapped in :class:`FunctionPlanner`, no capabilities)."""
    if isinstance(obj, Planner):
        return obj
    if isinstance(obj, type) and issubclass(obj, Planner):
        return obj()
    if callable(obj) and not isinstance(obj, type):
        return FunctionPlanner(obj, name)
    raise TypeError(f"{obj!r} is not a Planner (subclass jaxcnc.planners.Planner and implement plan())")
