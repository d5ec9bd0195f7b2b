"""The planner ``topp``: time-optimal speed along the whole program, per-axis limits coupled exactly.

Spans → grid (:mod:`~jaxcnc.planners.grid`: lines whole, curves cut fine) → per-interval
constraint rows → phase-plane passes (:mod:`~jaxcnc.planners.phaseplane`) → one segment per
interval (a trapezoid on lines, a constant-acceleration ramp on curved intervals) → tick
alignment (:mod:`~jaxcnc.planners.timelaw`), the whole in one jitted array program.

What each interval is allowed (per axis ``i``, ``x = v²``):

* speed: ``x ≤ (V_i / |T_i|)²`` at both ends, ``x ≤ feed²``, and the chord cap: a drive
  interpolates linearly between ticks, and a chord subtending ``Δθ`` on radius ``1/κ`` has
  sagitta ``(1 - cos(Δθ/2))/κ``, so ``v ≤ 2 acos(1 - tol κ)/κ · f``;
* acceleration: ``|T_i s̈ + K_i ṡ²| ≤ A_i`` at both ends — tangential and centripetal parts with
  their signs, on each axis separately (a diagonal move uses both axes' budgets, a curve
  accelerates while it turns where the axes allow it);
* junctions between spans as in the ``lookahead`` planner (:func:`~jaxcnc.planners.limits.junctions`):
  exact stop at corners, velocity steps within ``JUNCTION_SHARE`` of a tick's acceleration at
  near-tangent kinks (the spans beside them keep the rest).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size, pad_rows
from jaxcnc.errors import PlanningError
from jaxcnc.geometry.kinds import SpanKind
from jaxcnc.planners.grid import GRID_MARGIN, Grid, build_grid, device_spans, frames_at, interval_counts, is_curved
from jaxcnc.planners.limits import JUNCTION_SHARE, NUMERIC_MARGIN, chord_speed, junctions
from jaxcnc.planners.phaseplane import constraint_rows, line_reach, solve
from jaxcnc.planners.registry import PlanRequest, register_planner
from jaxcnc.planners.timelaw import Plan, align_to_ticks, plan_from_outputs, trapezoids
from jaxcnc.planners.trapezoid import plan_lookahead

#: Rounds of cutting curved spans finer where the interior check fails, and the factor per round.
MAX_REFINE = 6
REFINE_FACTOR = 4
#: Stand-in for an infinite limit (absent axis) that keeps the eliminations free of inf - inf.
BIG = 1e30
#: Most intervals a line is cut into so that a hold inside it has nodes (see :func:`hold_counts`).
MAX_HOLD_CUTS = 4096
#: Share of an axis' jerk limit the curvature's change may take at constant speed (see :func:`jerk_cap`).
JERK_SHARE = 0.5


def speed_cap(t: jnp.ndarray, k: jnp.ndarray, v_max: jnp.ndarray, feed: jnp.ndarray, chord_tol_mm, tick_hz):
    """``(m,)`` cap on ``x = ṡ²`` at nodes with ``q' = t``, ``q'' = k`` ``(m, 3)``: axis speeds, feed, chord error.

    The tool moves at ``|q'| ṡ``, axis ``i`` at ``|q'_i| ṡ``; the curvature is ``|q' × q''| / |q'|³``.
    """
    comp = jnp.abs(t)
    x_axis = jnp.min(jnp.where(comp > 0, (v_max / jnp.where(comp > 0, comp, 1.0)) ** 2, jnp.inf), axis=1)
    speed = jnp.linalg.norm(t, axis=1)
    safe = jnp.where(speed > 0, speed, 1.0)
    kappa = jnp.linalg.norm(jnp.cross(t, k), axis=1) / safe**3
    v_tool = jnp.minimum(feed, chord_speed(kappa, chord_tol_mm, tick_hz))  # the tool's own speed caps
    return jnp.minimum(x_axis, jnp.where(speed > 0, (v_tool / safe) ** 2, jnp.inf))


def box_speed_cap(t_lo: jnp.ndarray, t_hi: jnp.ndarray, v_max: jnp.ndarray, feed: jnp.ndarray) -> jnp.ndarray:
    """``(m,)`` cap on ``x`` from the axis speeds and the feed anywhere in a box ``t_lo ≤ q' ≤ t_hi`` ``(m, 3)``."""
    t_abs = jnp.maximum(jnp.abs(t_lo), jnp.abs(t_hi))
    x_axis = jnp.min(jnp.where(t_abs > 0, (v_max / jnp.where(t_abs > 0, t_abs, 1.0)) ** 2, jnp.inf), axis=1)
    speed = jnp.linalg.norm(t_abs, axis=1)
    return jnp.minimum(x_axis, jnp.where(speed > 0, (feed / jnp.where(speed > 0, speed, 1.0)) ** 2, jnp.inf))


def jerk_cap(k_a: jnp.ndarray, k_b: jnp.ndarray, delta: jnp.ndarray, j_max: jnp.ndarray) -> jnp.ndarray:
    """``(m,)`` cap on ``x = v²`` on intervals where the curvature changes, from the axes' jerk limits.

    At constant speed an axis on a curve has jerk ``K' ṡ³`` (``K' = dK/ds``, here the change of the
    curvature vector across the interval over its length); keeping it within ``JERK_SHARE`` of
    ``J_i`` leaves the rest for the time law's own jerk: ``x ≤ (share J_i / |K'_i|)^(2/3)``.
    """
    kp = jnp.abs(k_b - k_a) / jnp.where(delta > 0, delta, 1.0)[:, None]
    ok = (kp > 0) & jnp.isfinite(j_max)[None, :]
    x = jnp.where(
        ok, (JERK_SHARE * jnp.where(ok, j_max[None, :], 1.0) / jnp.where(ok, kp, 1.0)) ** (2.0 / 3.0), jnp.inf
    )
    return jnp.min(x, axis=1)


@partial(jax.jit, static_argnames=("curved_any", "axes"))
def plan_grid(
    g: dict, sp: dict, v_max, a_max, chord_tol, tick_hz, curved_any: bool, axes: tuple[int, ...] = (0, 1, 2), j_max=None
):
    """The planner as one array program over ``m`` (padded) intervals; see the module docstring.

    ``g`` holds the grid (``span, delta, t_a, k_a, t_b, k_b, curved, feed, dwell``), ``sp`` the span
    arrays the junctions need (``kind, tangent_in, tangent_out, stop_before``). ``axes``: the axes
    whose acceleration rows can bind (finite limit, some motion): the others' rows are ``0 ≤ A`` and
    are left out (a planar program on a three-axis machine has two thirds of the rows).
    """
    at_kink, j_cap = junctions(sp["kind"], sp["tangent_in"], sp["tangent_out"], sp["stop_before"], a_max, tick_hz)
    span, curved = g["span"], g["curved"]
    n = sp["kind"].shape[0]
    first = jnp.concatenate([jnp.ones(1, bool), span[1:] != span[:-1]])
    last = jnp.concatenate([span[1:] != span[:-1], jnp.ones(1, bool)])
    # junction caps at the span ends (0 before the first and after the last span: rest)
    cap_start = jnp.concatenate([jnp.zeros(1), j_cap])
    cap_end = jnp.concatenate([j_cap, jnp.zeros(1)])
    share = jnp.where(at_kink[span], 1.0 - JUNCTION_SHARE, 1.0) * jnp.where(curved, 1.0 - GRID_MARGIN, 1.0)
    acc = jnp.minimum(a_max, BIG)[None, :] * share[:, None]
    vel = jnp.minimum(v_max, BIG)[None, :] * jnp.where(curved, 1.0 - GRID_MARGIN, 1.0)[:, None]
    vcap_a = speed_cap(g["t_a"], g["k_a"], vel, g["feed"], chord_tol, tick_hz)
    vcap_b = speed_cap(g["t_b"], g["k_b"], vel, g["feed"], chord_tol, tick_hz)
    # in a box the axis speeds and the feed are capped everywhere inside, not at the ends alone
    vcap_box = box_speed_cap(g["t_lo"], g["t_hi"], vel, g["feed"])
    vcap_a = jnp.where(g["boxed"], jnp.minimum(vcap_a, vcap_box), vcap_a)
    vcap_b = jnp.where(g["boxed"], jnp.minimum(vcap_b, vcap_box), vcap_b)
    is_point = sp["kind"][span] == SpanKind.POINT
    cap_a = jnp.where(is_point, 0.0, jnp.where(first, jnp.minimum(vcap_a, cap_start[span]), vcap_a))
    cap_b = jnp.where(is_point, 0.0, jnp.where(last, jnp.minimum(vcap_b, cap_end[jnp.clip(span, 0, n - 1)]), vcap_b))
    cap_a, cap_b = jnp.minimum(cap_a, g["hold_a"]), jnp.minimum(cap_b, g["hold_b"])  # requested holds (nodes)
    if j_max is not None:  # jerk limits: the curvature may change only so fast at speed
        x_jerk = jerk_cap(g["k_a"], g["k_b"], g["delta"], j_max)
        cap_a, cap_b = jnp.minimum(cap_a, x_jerk), jnp.minimum(cap_b, x_jerk)
    delta = g["delta"]
    box = (g["boxed"], g["t_lo"], g["t_hi"], g["k_lo"], g["k_hi"])
    ax = list(axes)
    box = (box[0],) + tuple(b[:, ax] for b in box[1:])
    t_a, k_a, t_b, k_b = (g[f][:, ax] for f in ("t_a", "k_a", "t_b", "k_b"))
    rows = constraint_rows(delta, t_a, k_a, t_b, k_b, acc[:, ax], cap_b, box)
    x_node = solve(rows, delta, cap_a, jnp.zeros(()), curved_any)
    x0, x1 = x_node[:-1], x_node[1:]
    # Lines: a trapezoid under the span's speed cap with the axes' tangential budget.
    # Curved intervals: x linear in s between the nodes (constant s̈), as planned.
    two_d = 2.0 * jnp.where(delta > 0, delta, 1.0)
    a_line = line_reach(rows[0], rows[2], delta) / two_d
    x_cap = jnp.where(curved, jnp.maximum(x0, x1), jnp.minimum(vcap_a, vcap_b))
    a_seg = jnp.where(curved, jnp.abs(x1 - x0) / two_d, a_line)
    prof = trapezoids(x_node, x_cap, a_seg, delta, g["dwell"])
    out = align_to_ticks(prof, x0 == 0.0, tick_hz)
    out["x_node"], out["acc"] = x_node, acc
    return out


def interior_excess(arrays: dict, grid: Grid, x_node: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """``(m,)`` bool: on a curved interval the planned acceleration may exceed the budget inside.

    The limit holds at both ends by construction. Inside, ``q̈ = T(s) u + K(s) x(s)`` is
    evaluated at the midpoint too; the parabola through the three values bounds it (``T``, ``K``
    vary smoothly and little on an interval), and an interval whose parabola peaks above
    ``1 - GRID_MARGIN/2`` of the budget is cut finer. ``arrays``: :func:`~jaxcnc.planners.grid.device_spans`.
    """
    idx = np.flatnonzero(grid.curved & ~grid.boxed & (grid.delta > 0))  # boxes hold inside by construction
    bad = np.zeros(len(grid), bool)
    if idx.size == 0:
        return bad
    t_m, k_m = frames_at(arrays, grid.span[idx], grid.s_start[idx] + grid.delta[idx] / 2)
    xa, xb = x_node[idx], x_node[idx + 1]
    u = (xb - xa) / (2.0 * grid.delta[idx])
    a0 = grid.t_a[idx] * u[:, None] + grid.k_a[idx] * xa[:, None]
    am = t_m * u[:, None] + k_m * ((xa + xb) / 2)[:, None]
    a1 = grid.t_b[idx] * u[:, None] + grid.k_b[idx] * xb[:, None]
    lin, quad = -3.0 * a0 + 4.0 * am - a1, 2.0 * a0 - 4.0 * am + 2.0 * a1
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.clip(np.nan_to_num(-lin / (2.0 * quad), nan=0.0), 0.0, 1.0)
    peak = np.maximum(np.abs(a0 + lin * tau + quad * tau**2), np.abs(am))
    # acc already keeps GRID_MARGIN back on curved intervals: the ends sit at most at acc
    bad[idx] = np.any(peak > acc[idx] * (1.0 - GRID_MARGIN / 2) / (1.0 - GRID_MARGIN), axis=1)
    return bad


@register_planner("topp")
def plan_topp(req: PlanRequest) -> Plan:
    """Plan with exact per-axis coupling on a fine grid (see the module docstring)."""
    spans = req.spans
    if not is_curved(spans.kind).any() and (req.hold_caps is None or len(req.hold_caps) == 0):
        # lines only: one interval per line, where the rows reduce to the look-ahead planner's span caps
        # and junction caps — the same plan from span arrays alone, without a grid
        return plan_lookahead(req)
    counts = hold_counts(req, interval_counts(spans))
    arrays = device_spans(spans) if is_curved(spans.kind).any() else None  # uploaded once for all rounds
    for _ in range(MAX_REFINE):
        grid = build_grid(spans, counts, arrays)
        out = _solve_grid(req, grid)
        bad = interior_excess(arrays, grid, out["x_node"][: len(grid) + 1], out["acc"][: len(grid)])
        if not bad.any():
            break
        counts = counts * np.where(np.isin(np.arange(len(spans)), grid.span[bad]), REFINE_FACTOR, 1)
    else:
        raise PlanningError(f"the grid did not settle in {MAX_REFINE} refinements (a planner bug; please report it)")
    return plan_from_outputs(out, grid.delta, grid.span, grid.s_start, req.machine.tick_hz)


def hold_counts(req: PlanRequest, counts: np.ndarray) -> np.ndarray:
    """Cut lines that a hold reaches into intervals of half the hold's width (at most ``MAX_HOLD_CUTS``).

    A line is one grid interval: a hold inside it would have no node to act on, and the line's
    trapezoid would speed up right where the speed must stay flat.
    """
    if req.hold_caps is None or len(req.hold_caps) == 0:
        return counts
    spans = req.spans
    span_s0 = spans.s0
    rows = np.asarray(req.hold_caps, dtype=np.float64)
    first = np.clip(np.searchsorted(span_s0, rows[:, 0], side="right") - 1, 0, len(spans) - 1)
    last = np.clip(np.searchsorted(span_s0, rows[:, 1], side="right") - 1, 0, len(spans) - 1)
    which, span = _ranges(first, last - first + 1)
    width = np.full(len(spans), np.inf)
    np.minimum.at(width, span, np.maximum(rows[which, 1] - rows[which, 0], 1e-9))
    line = (spans.kind == SpanKind.LINE) & np.isfinite(width)
    cuts = np.ceil(spans.length / (0.5 * np.where(line, width, 1.0))).astype(np.int64)
    return np.where(line, np.maximum(counts, np.minimum(cuts, MAX_HOLD_CUTS)), counts)


def node_holds(req: PlanRequest, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """``(m,)`` caps on ``x = v²`` at each interval's start and end node from ``req.hold_caps``."""
    m = len(grid)
    hold_a, hold_b = np.full(m, np.inf), np.full(m, np.inf)
    if req.hold_caps is None or len(req.hold_caps) == 0:
        return hold_a, hold_b
    s_a = req.spans.s0[grid.span] + grid.s_start  # nodes in path order: sorted
    s_b = s_a + grid.delta
    rows = np.asarray(req.hold_caps, dtype=np.float64)
    for s_node, hold in ((s_a, hold_a), (s_b, hold_b)):
        lo = np.searchsorted(s_node, rows[:, 0], side="left")
        hi = np.searchsorted(s_node, rows[:, 1], side="right")
        which, idx = _ranges(lo, np.maximum(hi - lo, 0))
        np.minimum.at(hold, idx, rows[which, 2] ** 2)
    return hold_a, hold_b


def _ranges(lo: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range ``k`` is ``lo[k] .. lo[k] + count[k] - 1``: ``(which, index)`` over all of them, flattened."""
    which = np.repeat(np.arange(lo.size), count)
    return which, np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count) + lo[which]


def moving_axes(grid: Grid, a_max: np.ndarray) -> tuple[int, ...]:
    """The axes with a finite acceleration limit along which some interval moves or curves."""
    moves = np.zeros(len(a_max), bool)
    for f in (grid.t_a, grid.t_b, grid.k_a, grid.k_b, grid.t_lo, grid.t_hi, grid.k_lo, grid.k_hi):
        moves |= np.any(f != 0, axis=0)
    return tuple(int(i) for i in np.flatnonzero(moves & np.isfinite(a_max)))


def _solve_grid(req: PlanRequest, grid: Grid) -> dict[str, np.ndarray]:
    """Pad the grid to a bucket, run :func:`plan_grid`, return its outputs as NumPy arrays."""
    spans, machine = req.spans, req.machine
    n, m = len(spans), len(grid)
    mb, nb = bucket_size(m), bucket_size(n + 1)  # room for the padding point span n
    s = grid.span
    g = {
        "span": pad_rows(s, mb, n - 1),
        "delta": pad_rows(grid.delta, mb, 0.0),
        "t_a": pad_rows(grid.t_a, mb, 0.0),
        "k_a": pad_rows(grid.k_a, mb, 0.0),
        "t_b": pad_rows(grid.t_b, mb, 0.0),
        "k_b": pad_rows(grid.k_b, mb, 0.0),
        "curved": pad_rows(grid.curved, mb, False),
        "boxed": pad_rows(grid.boxed, mb, False),
        "t_lo": pad_rows(grid.t_lo, mb, 0.0),
        "t_hi": pad_rows(grid.t_hi, mb, 0.0),
        "k_lo": pad_rows(grid.k_lo, mb, 0.0),
        "k_hi": pad_rows(grid.k_hi, mb, 0.0),
        "feed": pad_rows(req.feed_mm_s[s], mb, 0.0),
        "dwell": pad_rows(np.where(grid.s_start == 0, req.dwell_s[s], 0.0), mb, 0.0),
    }
    hold_a, hold_b = node_holds(req, grid)
    g["hold_a"], g["hold_b"] = pad_rows(hold_a, mb, np.inf), pad_rows(hold_b, mb, np.inf)
    # padding intervals sit on a padding point span after the program
    g["span"][m:] = n
    sp = {
        "kind": pad_rows(spans.kind, nb, SpanKind.POINT),
        "tangent_in": pad_rows(spans.tangent_in, nb, 0.0),
        "tangent_out": pad_rows(spans.tangent_out, nb, 0.0),
        "stop_before": pad_rows(req.stop_before, nb, True),
    }
    keep = 1.0 - NUMERIC_MARGIN
    j_max = req.j_max
    out = plan_grid(
        g,
        sp,
        np.asarray(req.v_max) * keep,
        np.asarray(req.a_max) * keep,
        machine.path.chord_tol_mm,
        machine.tick_hz,
        curved_any=bool(grid.curved.any()),
        axes=moving_axes(grid, req.a_max),
        j_max=np.asarray(j_max) if j_max is not None and np.any(np.isfinite(j_max)) else None,
    )
    return {k: np.asarray(v) for k, v in jax.device_get(out).items()}
