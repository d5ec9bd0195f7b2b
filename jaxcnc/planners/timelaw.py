"""The time law ``s(t)``: trapezoidal speed profiles per span, aligned to the tick grid.

Given ``v²`` at the junction nodes (from :mod:`jaxcnc.planners.lookahead`), span ``k`` accelerates
from ``v0`` at ``a``, may cruise at ``vp``, and decelerates to ``v1``. The peak comes from meeting
the two parabolas: ``vp² = min(cap, (v0² + v1²)/2 + a L)``; the phase lengths are
``L_acc = (vp² - v0²)/(2a)``, ``L_dec = (vp² - v1²)/(2a)``, ``L_cru = L - L_acc - L_dec`` and the
times ``t = 2 L / (v_begin + v_end)`` per ramp, ``L_cru / vp`` for the cruise.

Tick alignment. Between two junctions where the motion is at rest (a *group*: rest-to-rest
motion, or a dwell) the motion takes ``T`` seconds; the group is given ``ceil(T f)`` ticks and the
machine simply stays at rest for the fraction of a tick left at its end. Every group therefore
starts on a tick, every rest point — every block that ends at rest — is reached exactly on a
tick, and speeds are exactly as planned (no stretching). Time is kept as an int64 group start
tick plus a float offset (in ticks) inside the group, so an hour at 100 kHz loses no precision.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)


@dataclass(frozen=True, eq=False)
class Plan:
    """The time law of a whole program as segments (NumPy arrays ``(n_segments,)``).

    A segment is a span or, where a planner cuts curved spans finer, a piece of one: it covers
    ``length[k]`` mm of span ``span[k]`` from ``s_start[k]`` mm after the span's start (spans in
    path order, each covered by consecutive segments). Segment ``k`` starts at tick
    ``group_tick[k] + offset_ticks[k]`` (fractional), runs ``t_acc, t_cru, t_dec`` seconds (a dwell
    is all cruise at zero speed), with speeds ``v0 → vp → v1`` mm/s and ramp accelerations
    ``a_acc``, ``a_dec`` mm/s². ``first_tick[k]`` is the first tick at or after its start. The
    table has ticks ``0..n_ticks``.
    """

    length: np.ndarray
    v0: np.ndarray
    vp: np.ndarray
    v1: np.ndarray
    a_acc: np.ndarray
    a_dec: np.ndarray
    t_acc: np.ndarray
    t_cru: np.ndarray
    t_dec: np.ndarray
    group_tick: np.ndarray
    offset_ticks: np.ndarray
    first_tick: np.ndarray
    n_ticks: int
    tick_hz: float
    span: np.ndarray
    s_start: np.ndarray

    def __len__(self) -> int:
        return int(self.length.shape[0])

    @property
    def total_time_s(self) -> float:
        return self.n_ticks / self.tick_hz

    @property
    def duration_s(self) -> np.ndarray:
        return self.t_acc + self.t_cru + self.t_dec

    def span_first_segment(self, n_spans: int) -> np.ndarray:
        """``(n_spans,)`` index of the first segment of each span."""
        return np.searchsorted(self.span, np.arange(n_spans), side="left")

    def span_start_ticks(self, n_spans: int) -> np.ndarray:
        """``(n_spans,)`` the first tick at or after each span's start."""
        return self.first_tick[self.span_first_segment(n_spans)]


#: The per-segment outputs of :func:`trapezoids` + :func:`align_to_ticks` that a :class:`Plan` keeps.
_PROFILE_KEYS = (
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
)


def plan_from_outputs(out: dict, length: np.ndarray, span: np.ndarray, s_start: np.ndarray, tick_hz: float) -> Plan:
    """A read-only :class:`Plan` from the (possibly padded) outputs of :func:`align_to_ticks`.

    ``length``, ``span``, ``s_start`` ``(n_segments,)`` describe the segments; ``out`` rows past
    ``n_segments`` (bucket padding) are dropped.
    """
    n = length.shape[0]
    arrays = {k: np.asarray(out[k][:n]) for k in _PROFILE_KEYS}
    for v in arrays.values():
        v.setflags(write=False)
    return Plan(length=length, n_ticks=int(out["n_ticks"]), tick_hz=tick_hz, span=span, s_start=s_start, **arrays)


def _safe_div(num: jnp.ndarray, den: jnp.ndarray) -> jnp.ndarray:
    ok = den > 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


def trapezoids(
    x_node: jnp.ndarray, x_cap: jnp.ndarray, a: jnp.ndarray, length: jnp.ndarray, dwell_s: jnp.ndarray
) -> dict[str, jnp.ndarray]:
    """Per-span trapezoid from node ``v²`` ``(n+1,)`` and span caps/accel/length/dwell ``(n,)``."""
    x0, x1 = x_node[:-1], x_node[1:]
    a_fin = jnp.where(jnp.isfinite(a), a, 0.0)
    xp = jnp.minimum(x_cap, 0.5 * (x0 + x1) + a_fin * length)
    xp = jnp.maximum(xp, jnp.maximum(x0, x1))  # rounding of the passes
    l_acc = _safe_div(xp - x0, 2.0 * a_fin)
    l_dec = _safe_div(xp - x1, 2.0 * a_fin)
    over = l_acc + l_dec
    shrink = jnp.where(over > length, _safe_div(length, over), 1.0)
    l_acc, l_dec = l_acc * shrink, l_dec * shrink
    l_cru = jnp.maximum(length - l_acc - l_dec, 0.0)
    v0, vp, v1 = jnp.sqrt(x0), jnp.sqrt(xp), jnp.sqrt(x1)
    t_acc = _safe_div(2.0 * l_acc, v0 + vp)
    t_dec = _safe_div(2.0 * l_dec, vp + v1)
    t_cru = _safe_div(l_cru, vp) + dwell_s
    # Ramp accelerations from the realised times: s(t) then ends exactly at L.
    return dict(
        v0=v0,
        vp=vp,
        v1=v1,
        t_acc=t_acc,
        t_cru=t_cru,
        t_dec=t_dec,
        a_acc=_safe_div(vp - v0, t_acc),
        a_dec=_safe_div(vp - v1, t_dec),
    )


def _segmented_cumsum(values: jnp.ndarray, starts: jnp.ndarray) -> jnp.ndarray:
    """Inclusive cumulative sum that restarts where ``starts`` is True (parallel scan)."""

    def op(a, b):
        fa, va = a
        fb, vb = b
        return fa | fb, jnp.where(fb, vb, va + vb)

    _, out = jax.lax.associative_scan(op, (starts, values))
    return out


def align_to_ticks(prof: dict[str, jnp.ndarray], rest_start: jnp.ndarray, tick_hz: float) -> dict[str, jnp.ndarray]:
    """Give each rest-to-rest group a whole number of ticks and place segments on the grid.

    Args:
        prof: output of :func:`trapezoids`.
        rest_start: ``(n,)`` bool, the motion is at rest at the start of the span (a group starts).
    Returns:
        ``prof`` plus ``group_tick`` (int64), ``offset_ticks``, ``first_tick`` (int64) and
        ``n_ticks`` (scalar int64).
    """
    n = rest_start.shape[0]
    dur_ticks = (prof["t_acc"] + prof["t_cru"] + prof["t_dec"]) * tick_hz
    group = jnp.cumsum(rest_start.astype(jnp.int64)) - 1
    g_ticks = jax.ops.segment_sum(dur_ticks, group, num_segments=n)
    # 1e-9 guards against ceil(5.000000000001) = 6 from rounding of the sums
    g_whole = jnp.ceil(g_ticks - 1e-9).astype(jnp.int64)
    g_whole = jnp.maximum(g_whole, 0)
    out = dict(prof)
    dur = dur_ticks
    g_start = jnp.cumsum(g_whole) - g_whole
    offset = jnp.where(rest_start, 0.0, _segmented_cumsum(dur, rest_start) - dur)  # exclusive, exact 0 at starts
    out["group_tick"] = g_start[group]
    out["offset_ticks"] = offset
    out["first_tick"] = out["group_tick"] + jnp.ceil(offset).astype(jnp.int64)
    out["n_ticks"] = jnp.sum(g_whole)
    return out


#: The per-segment fields of :class:`Plan` the tick kernels read (as a dict of JAX arrays).
PLAN_KEYS = ("v0", "vp", "a_acc", "a_dec", "t_acc", "t_cru", "t_dec", "group_tick", "offset_ticks", "first_tick")


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
    v0, vp, aa, ad = plan["v0"][seg], plan["vp"][seg], plan["a_acc"][seg], plan["a_dec"][seg]
    ta, tc, td = plan["t_acc"][seg], plan["t_cru"][seg], plan["t_dec"][seg]
    l_acc = v0 * ta + 0.5 * aa * ta**2
    t1 = jnp.minimum(tau, ta)
    s_acc = v0 * t1 + 0.5 * aa * t1**2
    t2 = jnp.clip(tau - ta, 0.0, tc)
    t3 = jnp.clip(tau - ta - tc, 0.0, td)
    s = jnp.where(tau < ta, s_acc, l_acc + vp * t2 + vp * t3 - 0.5 * ad * t3**2)
    return jnp.clip(s, 0.0, length[seg])


def v_at(plan: dict[str, jnp.ndarray], seg: jnp.ndarray, tick: jnp.ndarray, tick_hz: float) -> jnp.ndarray:
    """Path speed (mm/s) on segment ``seg`` at integer ``tick`` (arrays ``(m,)``)."""
    tau = local_time(plan, seg, tick, tick_hz)
    ta, tc, td = plan["t_acc"][seg], plan["t_cru"][seg], plan["t_dec"][seg]
    v_acc = plan["v0"][seg] + plan["a_acc"][seg] * jnp.minimum(tau, ta)
    v_dec = plan["vp"][seg] - plan["a_dec"][seg] * jnp.clip(tau - ta - tc, 0.0, td)
    return jnp.maximum(jnp.where(tau < ta, v_acc, v_dec), 0.0)  # (rounding may leave -1e-14 at a rest)


def sample_plan(plan: Plan, ticks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The time law at integer ``ticks``: ``(segment, s_mm, v_mm_s)``, each ``(m,)``.

    ``s_mm`` is the path parameter from the program start (arc length on lines and arcs, within
    1e-6 of it on curves) — the ``s(t)`` researchers compare between planners; ``v_mm_s`` its
    derivative.
    """
    arrays = {k: getattr(plan, k) for k in PLAN_KEYS}
    out = _sample(arrays, plan.length, np.asarray(ticks, dtype=np.int64), plan.tick_hz)
    return tuple(np.asarray(a) for a in out)


@partial(jax.jit, static_argnames=("tick_hz",))
def _sample(arrays: dict, length: jnp.ndarray, t: jnp.ndarray, tick_hz: float):
    seg = segment_of_tick(arrays["first_tick"], t)
    s_local = s_at(arrays, length, seg, t, tick_hz)
    s0 = jnp.concatenate([jnp.zeros(1), jnp.cumsum(length)[:-1]])
    return seg, s0[seg] + s_local, v_at(arrays, seg, t, tick_hz)


def segment_of_tick(first_tick: jnp.ndarray, tick: jnp.ndarray) -> jnp.ndarray:
    """Index of the segment that holds each tick: the last one whose first tick is ≤ it."""
    return jnp.clip(jnp.searchsorted(first_tick, tick, side="right") - 1, 0, first_tick.shape[0] - 1)
