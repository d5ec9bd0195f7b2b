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

import os
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size
from jaxcnc.errors import PlanningError, RowPlanningError
from jaxcnc.geometry.blend_kernel import cpu_loop_options
from jaxcnc.geometry.evaluate import junction_curvatures, span_arrays
from jaxcnc.geometry.kinds import SpanKind
from jaxcnc.geometry.spans import Spans, pad_spans, pad_tables, take_spans
from jaxcnc.jitcache import cached_jit, compile_ahead
from jaxcnc.memory import available_memory_bytes, release_free_heap
from jaxcnc.planners.grid import (
    GRID_MARGIN,
    Grid,
    GridPiece,
    aligned_array,
    build_grid,
    cut_spans,
    device_spans,
    frames_at,
    interval_counts,
    is_curved,
    join_pieces,
    node_frames,
)
from jaxcnc.planners.limits import JERK_SHARE, JUNCTION_SHARE, chord_speed, curvature_columns, junctions
from jaxcnc.planners.lookahead_planner import plan_lookahead
from jaxcnc.planners.phaseplane import (
    backward_pieces,
    constraint_rows,
    forward_pieces,
    line_reach,
    solve_pieces,
    solve_window,
    static_cap,
    window_pieces,
)
from jaxcnc.planners.protocol import Planner, PlanRequest, jerk_limits, range_min, step_rate_hz
from jaxcnc.planners.registry import register_planner
from jaxcnc.planners.timelaw import (
    RAMP_COLUMNS,
    RAMP_GENERAL,
    GroupTicks,
    Plan,
    Ramps,
    SegmentCuts,
    align_to_ticks,
    ramp_accel,
    trapezoids,
)

#: Rounds of cutting curved spans finer where the interior check fails, and the factor per round.
MAX_REFINE = 6
REFINE_FACTOR = 4
#: Stand-in for an infinite limit (absent axis) that keeps the eliminations free of inf - inf.
BIG = 1e30
#: Most intervals a line is cut into so that a hold inside it has nodes (see :func:`hold_counts`).
MAX_HOLD_CUTS = 4096


def speed_cap(
    t: tuple, k: tuple, v_max: tuple, feed: jnp.ndarray, chord_tol_mm, tick_hz, v_chord: jnp.ndarray | None = None
) -> jnp.ndarray:
    """``(m,)`` cap on ``x = ṡ²`` at nodes with ``q' = t``, ``q'' = k``: axis speeds, feed, chord error.

    ``t``, ``k``: one ``(m,)`` column per axis (x, y, z); ``v_max``: per axis, each a scalar or ``(m,)``.
    The tool moves at ``|q'| ṡ``, axis ``i`` at ``|q'_i| ṡ``; the curvature is ``|q' × q''| / |q'|³``.
    ``v_chord``: :func:`~.limits.node_chord_speed` of ``t``, ``k`` where a program before computed it (else here).
    """
    x_axis = _axis_speed_cap(tuple(jnp.abs(c) for c in t), v_max)
    speed, safe, kappa = curvature_columns(t, k)
    v_chord = chord_speed(kappa, chord_tol_mm, tick_hz) if v_chord is None else v_chord
    v_tool = jnp.minimum(feed, v_chord)  # the tool's own speed caps
    return jnp.minimum(x_axis, jnp.where(speed > 0, (v_tool / safe) ** 2, jnp.inf))


def _axis_speed_cap(t_abs: tuple, v_max: tuple) -> jnp.ndarray:
    """``(m,)`` ``min_i (V_i / |q'_i|)²`` over the axes with ``q'_i ≠ 0`` (``inf`` where none moves)."""
    x = jnp.inf
    for c, v in zip(t_abs, v_max, strict=True):
        x = jnp.minimum(x, jnp.where(c > 0, (v / jnp.where(c > 0, c, 1.0)) ** 2, jnp.inf))
    return x


def box_speed_cap(t_lo: tuple, t_hi: tuple, v_max: tuple, feed: jnp.ndarray, speed_hi: jnp.ndarray) -> jnp.ndarray:
    """``(m,)`` cap on ``x`` from the axis speeds and the feed anywhere in a box ``t_lo ≤ q' ≤ t_hi`` (columns)
    where ``|q'| ≤ speed_hi`` ``(m,)`` (:attr:`~.grid.Grid.speed_hi`).

    The tool moves at ``|q'| ṡ``: the feed caps ``x`` at ``(F / max|q'|)²``. The box's corner bounds ``|q'|`` too,
    but loosely — on an interval turning by ``φ`` it exceeds ``|q'|`` by up to ``~φ/2`` (1.2 % on the 1.45°
    intervals of a 50 mm arc blended whole), which slowed feed-bound blends below the feed: of the two bounds the
    smaller holds."""
    t_abs = tuple(jnp.maximum(jnp.abs(lo), jnp.abs(hi)) for lo, hi in zip(t_lo, t_hi, strict=True))
    x_axis = _axis_speed_cap(t_abs, v_max)
    speed = jnp.minimum(jnp.sqrt(t_abs[0] ** 2 + t_abs[1] ** 2 + t_abs[2] ** 2), speed_hi)
    return jnp.minimum(x_axis, jnp.where(speed > 0, (feed / jnp.where(speed > 0, speed, 1.0)) ** 2, jnp.inf))


def jerk_cap(k_a: tuple, k_b: tuple, delta: jnp.ndarray, j_max: jnp.ndarray) -> jnp.ndarray:
    """``(m,)`` cap on ``x = v²`` on intervals where the curvature changes, from the axes' jerk limits.

    At constant speed an axis on a curve has jerk ``K' ṡ³`` (``K' = dK/ds``, here the change of the
    curvature vector across the interval over its length); keeping it within ``JERK_SHARE`` of
    ``J_i`` leaves the rest for the time law's own jerk: ``x ≤ (share J_i / |K'_i|)^(2/3)``.
    ``k_a``, ``k_b``: one ``(m,)`` column per axis; ``j_max`` ``(3,)``.
    """
    inv_d = 1.0 / jnp.where(delta > 0, delta, 1.0)
    x = jnp.inf
    for i, (ka, kb) in enumerate(zip(k_a, k_b, strict=True)):
        kp = jnp.abs(kb - ka) * inv_d
        ok = (kp > 0) & jnp.isfinite(j_max[i])
        j = jnp.where(jnp.isfinite(j_max[i]), j_max[i], 1.0)
        x = jnp.minimum(x, jnp.where(ok, (JERK_SHARE * j / jnp.where(ok, kp, 1.0)) ** (2.0 / 3.0), jnp.inf))
    return x


#: The grid's per-axis fields, passed to :func:`plan_grid` as ``(3, m)`` (one row per axis).
_AXIS_FIELDS = ("t_a", "k_a", "t_b", "k_b", "t_lo", "t_hi", "k_lo", "k_hi")


def plan_grid(
    g: dict,
    v_max,
    a_max,
    chord_tol,
    tick_hz,
    x_start,
    curved_any: bool,
    axes: tuple[int, ...] = (0, 1, 2),
    j_max=None,
    boxed_any: bool = True,
) -> dict:
    """The planner as array programs over ``m`` (padded) intervals; see the module docstring.

    ``g`` holds the grid (``delta, curved, boxed, feed, dwell`` and the holds ``(m,)``; ``t_a, k_a, t_b,
    k_b`` and the box ``t_lo, t_hi, k_lo, k_hi`` as ``(3, m)``, one row per axis: every step is elementwise
    over intervals, and rows of one axis are contiguous vectors) and what the junctions give each interval:
    ``at_kink`` (its span starts or ends at a kink passed with a velocity step), ``is_point``, ``cap_first`` /
    ``cap_last`` (the junction's cap on ``x`` where the interval starts / ends its span, ``inf`` inside).
    ``x_start``: ``x`` at the first node (0 at the program's start). ``axes``: the axes whose acceleration
    rows can bind (finite limit, some motion): the others' rows are ``0 ≤ A`` and are left out (a planar
    program on a three-axis machine has two thirds of the rows). Returns the segments' trapezoids,
    ``x_node``, ``share`` (each interval's share of the axes' acceleration, see :func:`interval_share`) and
    :func:`~.phaseplane.solve_window`'s ``exact`` and ``k0``. ``boxed_any``: some interval has a box.

    Three forms, the same plan (measured on a 131k-interval window of a CAM contour, CPU time):

    * no curved interval: the look-ahead scans (:func:`_plan_lines`);
    * curved, no box: the axes' bands (a quarter of the row work), in two compiled programs — every
      interval's rows, caps and pieces (:func:`_band_pieces`), then the passes and the trapezoids
      (:func:`_band_solve`); XLA would copy the divisions into each consumer of one program
      (:func:`~.phaseplane.window_pieces`): 58 → 31 ms against the chunked form;
    * boxes: the row pairs, the pieces in five programs (:func:`_box_pieces`), the passes in the second
      program of the bands: 96 → 38 ms against the chunked form (rows built chunk by chunk inside the passes,
      once per pass), the same plan bit for bit (2026-11-23, a 131k-interval window of the 100k-block contour).
    """
    if not curved_any:
        return _plan_lines(g, v_max, a_max, chord_tol, tick_hz, x_start, axes=axes, j_max=j_max)
    if boxed_any:
        pieces, laws = _box_pieces(g, v_max, a_max, chord_tol, tick_hz, axes, j_max)
    else:
        pieces, laws = _band_pieces(g, v_max, a_max, chord_tol, tick_hz, axes=axes, j_max=j_max)
    return _band_solve(pieces, laws, x_start)


@cached_jit(static_argnames=("axes",))
def _plan_lines(g: dict, v_max, a_max, chord_tol, tick_hz, x_start, axes: tuple[int, ...], j_max) -> dict:
    """:func:`plan_grid` of a window without curved intervals: the look-ahead scans, one program."""
    c = _interval_rows(g, v_max, a_max, chord_tol, tick_hz, axes, j_max)
    x_node, exact, k0 = solve_window(c["rows"], c["delta"], c["cap_a"], jnp.zeros(()), False, x_start)
    out = _segment_laws(_law_inputs(c), x_node)
    out.update(x_node=x_node, share=interval_share(g["at_kink"], g["curved"]), exact=exact, k0=k0)
    return out


@cached_jit(static_argnames=("axes",))
def _band_pieces(
    g: dict, v_max, a_max, chord_tol, tick_hz, axes: tuple[int, ...], j_max, caps: dict | None = None
) -> tuple[dict, dict]:
    """The first program of a window without boxes: :func:`~.phaseplane.window_pieces` from the bands and
    what the trapezoids need. ``caps``: :func:`_interval_caps` of ``g``, made by an earlier program (XLA would
    copy their square roots and arc sines into each consumer here; see :func:`_box_pieces`)."""
    c = _interval_rows(g, v_max, a_max, chord_tol, tick_hz, axes, j_max, caps)
    laws = _law_inputs(c)
    laws["share"] = interval_share(g["at_kink"], _margined(g))
    return window_pieces(c["rows"], c["delta"], c["cap_a"], bands=True), laws


def _box_pieces(g: dict, v_max, a_max, chord_tol, tick_hz, axes: tuple[int, ...], j_max) -> tuple[dict, dict]:
    """:func:`_band_pieces` of a window with boxes (the row-pair forms of :func:`~.phaseplane.window_pieces`),
    in five compiled programs (:func:`_box_part`): the caps, then the static cap, the backward pieces, the
    forward pieces and the trapezoids' inputs, each from the caps and the grid. The same values as one program,
    bit for bit, in 40 % less CPU (a 131k-interval window of the 100k-block contour, 2026-11-23: 52 → 31 ms): XLA
    fuses one program's many outputs into loops that spill, and copies the caps' square roots and arc cosines into
    each consumer. Two of the four after the caps are called in the compile-ahead thread
    (:func:`~jaxcnc.jitcache.compile_ahead`): a first run compiles them beside the other two (4.4 s of compile for
    the five on the development machine, one after the other)."""
    limits = (v_max, a_max, chord_tol, tick_hz)
    caps = _box_part(g, None, *limits, axes=axes, j_max=j_max, part="caps")
    later = {
        p: compile_ahead(_box_part, g, caps, *limits, axes=axes, j_max=j_max, part=p) for p in ("backward", "laws")
    }
    x_static = _box_part(g, caps, *limits, axes=axes, j_max=j_max, part="static")
    a_fwd, b_fwd = _box_part(g, caps, *limits, axes=axes, j_max=j_max, part="forward")
    alpha, beta = later["backward"].result()
    laws = later["laws"].result()
    pieces = dict(x_static=x_static, alpha=alpha, beta=beta, cap_b=caps["cap_b"], a=a_fwd, b=b_fwd, delta=g["delta"])
    return pieces, laws


@cached_jit(static_argnames=("axes", "part"))
def _box_part(g: dict, caps: dict | None, v_max, a_max, chord_tol, tick_hz, axes: tuple[int, ...], j_max, part: str):
    """One program of :func:`_box_pieces`: ``part`` ``"caps"`` (:func:`_interval_caps`), ``"static"``
    (:func:`~.phaseplane.static_cap`), ``"backward"`` / ``"forward"`` (the pieces) or ``"laws"``
    (:func:`_law_inputs` and the share), from ``g`` and the caps."""
    if part == "caps":
        return _interval_caps(g, v_max, chord_tol, tick_hz, j_max)
    c = _interval_rows(g, v_max, a_max, chord_tol, tick_hz, axes, j_max, caps)
    gu, gx, h = c["rows"]
    if part == "static":
        return static_cap(gu, gx, h, c["cap_a"])
    if part == "backward":
        return backward_pieces(gu, gx, h, c["delta"])
    if part == "forward":
        return forward_pieces(gu, gx, h, c["delta"])
    laws = _law_inputs(c)
    laws["share"] = interval_share(g["at_kink"], _margined(g))
    return laws


@cached_jit
def _band_solve(pieces: dict, laws: dict, x_start, check: dict | None = None) -> dict:
    """The second program of a curved window: the backward and forward scans, then the trapezoids;
    with ``check`` (:func:`_interior_bad`'s frames and ``a_max``) also each interval's ``bad``."""
    x_node, exact, k0 = solve_pieces(pieces, jnp.zeros(()), x_start)
    out = _segment_laws(laws, x_node)
    out.update(x_node=x_node, share=laws["share"], exact=exact, k0=k0)
    if check is not None:
        out["bad"] = _interior_bad(check, x_node, laws["delta"], laws["curved"], laws["share"])
    return out


def _interior_bad(check: dict, x_node, delta, curved, share) -> jnp.ndarray:
    """:func:`interior_excess` of a window without boxes, compiled over all ``(m,)`` intervals with the same
    operations (lines and points masked): ``check`` holds ``t_a, k_a, t_b, k_b`` and ``t_m, k_m`` (``q'``, ``q''``
    at the intervals' midpoints) as ``(3, m)`` and ``a_max`` ``(3,)``."""
    on = curved & (delta > 0)
    frame = tuple(check[f] for f in ("t_a", "k_a", "t_m", "k_m", "t_b", "k_b"))
    return _excess(frame, x_node[:-1], x_node[1:], delta, on, check["a_max"], share, range(3))


def _excess(frame: tuple, xa, xb, delta, on, a_max, share, axes) -> jnp.ndarray:
    """The interior check (:func:`interior_excess`) of intervals ``(n,)``: ``frame`` = ``t_a, k_a, t_m, k_m, t_b,
    k_b``, each ``(3, n)`` (rows x, y, z); ``xa``, ``xb``: ``x`` at the ends; ``on``: the intervals checked; only
    the rows of ``axes`` are read (the others' acceleration rows are left out of the solve as well)."""
    u = (xb - xa) / (2.0 * jnp.where(on, delta, 1.0))
    bad = jnp.zeros(on.shape, bool)
    for i in axes:
        t_a, k_a, t_m, k_m, t_b, k_b = (f[i] for f in frame)
        a0 = t_a * u + k_a * xa
        am = t_m * u + k_m * ((xa + xb) / 2)
        a1 = t_b * u + k_b * xb
        lin, quad = -3.0 * a0 + 4.0 * am - a1, 2.0 * a0 - 4.0 * am + 2.0 * a1
        tau = jnp.clip(jnp.nan_to_num(-lin / (2.0 * quad), nan=0.0), 0.0, 1.0)
        peak = jnp.maximum(jnp.abs(a0 + lin * tau + quad * tau**2), jnp.abs(am))
        acc = jnp.minimum(a_max[i], BIG) * share
        bad = bad | (peak > acc * (1.0 - GRID_MARGIN / 2) / (1.0 - GRID_MARGIN))
    return on & bad


def _pad_aligned(a: np.ndarray, n: int, fill) -> np.ndarray:
    """:func:`~jaxcnc.buckets.pad_rows` into an :func:`~jaxcnc.planners.grid.aligned_array` (read in place by a
    compiled program)."""
    out = aligned_array((n,) + a.shape[1:], a.dtype)
    out[: a.shape[0]] = a
    out[a.shape[0] :] = fill
    return out


def _interval_caps(g: dict, v_max, chord_tol, tick_hz, j_max) -> dict:
    """Each interval's caps on ``x`` (elementwise, ``(m,)`` each; ``g`` as :func:`plan_grid`'s): ``vcap_a``,
    ``vcap_b`` from the speeds and the chord error at its ends (in its box where it has one), ``cap_a``,
    ``cap_b`` with the junctions, holds and jerk caps too."""
    boxed = "boxed" in g  # windows without blends leave the box fields out (rows as without boxes: same values)
    col = {f: tuple(g[f][i] for i in range(3)) for f in (_AXIS_FIELDS if boxed else _AXIS_FIELDS[:4])}
    vel_share = jnp.where(_margined(g), 1.0 - GRID_MARGIN, 1.0)
    vel = tuple(jnp.minimum(v_max[i], BIG) * vel_share for i in range(3))
    vcap_a = speed_cap(col["t_a"], col["k_a"], vel, g["feed"], chord_tol, tick_hz, g.get("chord_a"))
    vcap_b = speed_cap(col["t_b"], col["k_b"], vel, g["feed"], chord_tol, tick_hz, g.get("chord_b"))
    if boxed:  # in a box the axis speeds and the feed are capped everywhere inside, not at the ends alone
        vcap_box = box_speed_cap(col["t_lo"], col["t_hi"], vel, g["feed"], g["speed_hi"])
        vcap_a = jnp.where(g["boxed"], jnp.minimum(vcap_a, vcap_box), vcap_a)
        vcap_b = jnp.where(g["boxed"], jnp.minimum(vcap_b, vcap_box), vcap_b)
    is_point = g["is_point"]
    cap_a = jnp.where(is_point, 0.0, jnp.minimum(vcap_a, g["cap_first"]))
    cap_b = jnp.where(is_point, 0.0, jnp.minimum(vcap_b, g["cap_last"]))
    cap_a, cap_b = jnp.minimum(cap_a, g["hold_a"]), jnp.minimum(cap_b, g["hold_b"])  # requested holds (nodes)
    # ... and inside an interval held at both ends: a line's trapezoid would otherwise rise between two held nodes
    # (from 6.6 to ~26 mm/s on a 0.06 mm piece at 10,000 mm/s²) right where the speed must stay flat
    x_hold = jnp.maximum(g["hold_a"], g["hold_b"])
    if j_max is not None:  # jerk limits: the curvature may change only so fast at speed
        x_jerk = jerk_cap(col["k_a"], col["k_b"], g["delta"], j_max)
        cap_a, cap_b = jnp.minimum(cap_a, x_jerk), jnp.minimum(cap_b, x_jerk)
    return dict(vcap_a=vcap_a, vcap_b=vcap_b, cap_a=cap_a, cap_b=cap_b, x_hold=x_hold)


def _interval_rows(
    g: dict, v_max, a_max, chord_tol, tick_hz, axes: tuple[int, ...], j_max, caps: dict | None = None
) -> dict:
    """Each interval's caps and constraint rows (elementwise; ``g`` as :func:`plan_grid`'s, or a chunk of it):
    ``rows``, ``delta``, ``cap_a`` for the passes, ``vcap_a``, ``vcap_b``, ``curved``, ``dwell`` for
    :func:`_segment_laws`. ``caps``: :func:`_interval_caps` of ``g`` where the caller has them already."""
    boxed = "boxed" in g
    col = {f: tuple(g[f][i] for i in range(3)) for f in (_AXIS_FIELDS if boxed else _AXIS_FIELDS[:4])}
    caps = _interval_caps(g, v_max, chord_tol, tick_hz, j_max) if caps is None else caps
    curved = g["curved"]
    share = interval_share(g["at_kink"], _margined(g))
    acc = [jnp.minimum(a_max[i], BIG) * share for i in axes]
    on = {f: [col[f][i] for i in axes] for f in col}  # the axes whose rows can bind
    box = (g["boxed"], on["t_lo"], on["t_hi"], on["k_lo"], on["k_hi"]) if boxed else None
    rows = constraint_rows(g["delta"], on["t_a"], on["k_a"], on["t_b"], on["k_b"], acc, caps["cap_b"], box)
    return dict(rows=rows, delta=g["delta"], curved=curved, dwell=g["dwell"]) | {
        k: caps[k] for k in ("cap_a", "vcap_a", "vcap_b", "x_hold")
    }


def _law_inputs(c: dict) -> dict:
    """What the trapezoids need besides ``x`` at the nodes, from :func:`_interval_rows`' ``c`` (each ``(m,)``):
    ``delta``, ``curved``, ``dwell``, a line's tangential acceleration ``a_line`` and speed cap ``x_cap_line``."""
    delta = c["delta"]
    two_d = 2.0 * jnp.where(delta > 0, delta, 1.0)
    return dict(
        delta=delta,
        curved=c["curved"],
        dwell=c["dwell"],
        a_line=line_reach(c["rows"][0], c["rows"][2], delta) / two_d,
        x_cap_line=jnp.minimum(jnp.minimum(c["vcap_a"], c["vcap_b"]), c["x_hold"]),
    )


def _segment_laws(laws: dict, x_node: jnp.ndarray) -> dict:
    """The segments' trapezoids from :func:`_law_inputs` and ``x`` at the ``(m+1,)`` nodes.

    Lines: a trapezoid under the span's speed cap with the axes' tangential budget. Curved intervals:
    ``x`` linear in ``s`` between the nodes (constant ``s̈``), as planned.
    """
    delta, curved = laws["delta"], laws["curved"]
    x0, x1 = x_node[:-1], x_node[1:]
    two_d = 2.0 * jnp.where(delta > 0, delta, 1.0)
    x_cap = jnp.where(curved, jnp.maximum(x0, x1), laws["x_cap_line"])
    a_seg = jnp.where(curved, jnp.abs(x1 - x0) / two_d, laws["a_line"])
    return trapezoids(x_node, x_cap, a_seg, delta, laws["dwell"])


def _margined(g: dict):
    """``(m,)`` the intervals that keep ``GRID_MARGIN`` of the limits back: curved ones without a box (a box bounds
    what ``q'`` and ``q''`` do inside its interval; elsewhere the ends' values stand for the interval)."""
    return g["curved"] & ~g["boxed"] if "boxed" in g else g["curved"]


def interval_share(at_kink, curved):
    """``(m,)`` the share of each axis' acceleration an interval may use: less ``JUNCTION_SHARE`` beside a kink
    passed moving, less ``GRID_MARGIN`` on curved intervals (NumPy or JAX arrays)."""
    xp = jnp if isinstance(at_kink, jax.Array) else np
    return xp.where(at_kink, 1.0 - JUNCTION_SHARE, 1.0) * xp.where(curved, 1.0 - GRID_MARGIN, 1.0)


def _junction_facts(kind, tangent_in, tangent_out, stop_before, a_max, tick_hz, j_max=None):
    """:func:`~jaxcnc.planners.limits.junctions` of the whole program (padded span arrays), compiled without
    XLA:CPU's YNNPACK fusions (:func:`~jaxcnc.geometry.blend_kernel.cpu_loop_options`): its norms, maxima and
    minima over rows of three went to them, and took twice the time (1 M blocks: 24 -> 11 ms CPU; the same bits
    on the CAM contour — minima and maxima in any order are the same, and the norms' sums of three squares
    decide a corner only at a turn within a rounding of 1°)."""
    return _junction_program()(kind, tangent_in, tangent_out, stop_before, a_max, tick_hz, j_max)


@cache
def _junction_program():
    """:func:`~jaxcnc.planners.limits.junctions` jitted with :func:`~jaxcnc.geometry.blend_kernel.cpu_loop_options`
    (made on first use: the options are probed by a compile)."""
    return cached_jit(junctions, compiler_options=cpu_loop_options())


@cached_jit
def _align_total(duration: jnp.ndarray, rest_start: jnp.ndarray, tick_hz) -> dict:
    """:func:`~jaxcnc.planners.timelaw.align_to_ticks` of segments given by their whole durations ``(m,)``
    (``t_acc + t_cru + t_dec``, summed on the host as the alignment sums them), returning only what it adds to the
    segments. Every plan of the grid is aligned by this one program, whether it keeps its trapezoids' columns or
    their ramps: the same inputs give the same bits on any CPU (two programs, one summing the times itself, differed
    in the last bit of some offsets on a machine whose XLA:CPU contracted the sums into its scan differently)."""
    zero = jnp.zeros_like(duration)
    out = align_to_ticks({"t_acc": duration, "t_cru": zero, "t_dec": zero}, rest_start, tick_hz)
    return {k: out[k] for k in _ALIGN_KEYS}


#: What the alignment adds that a plan of the grid keeps: the groups' first ticks, the offsets and the ticks in all.
_ALIGN_KEYS = ("g_start", "offset_ticks", "n_ticks")


def interior_excess(
    arrays: dict, grid: Grid, x_node: np.ndarray, acc: np.ndarray, first: int = 0, only: str | None = None
) -> np.ndarray:
    """``(m,)`` bool: on a curved interval the planned acceleration may exceed the budget inside.

    The limit holds at both ends by construction. Inside, ``q̈ = T(s) u + K(s) x(s)`` is
    evaluated at the midpoint too; the parabola through the three values bounds it (``T``, ``K``
    vary smoothly and little on an interval), and an interval whose parabola peaks above
    ``1 - GRID_MARGIN/2`` of the budget is cut finer. ``arrays``: :func:`~jaxcnc.planners.grid.device_spans`
    of the spans from ``first`` on (row 0 is span ``first``); ``only``: as :func:`~.grid.frames_at`'s (``"arc"``
    where every curved interval without a box lies on an arc: the same values, a third of the work).
    """
    idx = np.flatnonzero(grid.curved & ~grid.boxed & (grid.delta > 0))  # boxes hold inside by construction
    bad = np.zeros(len(grid), bool)
    if idx.size == 0:
        return bad
    t_m, k_m = frames_at(arrays, grid.span[idx] - first, grid.s_start[idx] + grid.delta[idx] / 2, only=only)
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


def excess_midpoints(arrays: dict, grid: Grid, first: int = 0, only: str | None = None) -> tuple | None:
    """What :func:`grid_excess` checks, from the grid alone: the curved intervals without a box ``(q,)`` and the
    frames at their midpoints (:func:`~.grid.node_frames`); ``None`` where there are none. Independent of the
    solve: :func:`_solve_refined` has it made in the compile-ahead thread while the window is solved."""
    idx = np.flatnonzero(grid.curved & ~grid.boxed & (grid.delta > 0))  # boxes hold inside by construction
    if idx.size == 0:
        return None
    return idx, node_frames(arrays, grid.span[idx] - first, grid.s_start[idx] + grid.delta[idx] / 2, only)


def grid_excess(
    arrays: dict,
    grid: Grid,
    out: dict[str, np.ndarray],
    a_max: np.ndarray,
    axes: tuple[int, ...],
    first: int = 0,
    only: str | None = None,
    midpoints: tuple | None | bool = False,
) -> np.ndarray:
    """``(m,)`` :func:`interior_excess` of a window's grid as :func:`_solve_grid` planned it (``out``: its
    ``x_node`` and ``share``), by compiled programs: the frames at the midpoints of the curved intervals without
    a box (:func:`~.grid.node_frames`, their cosines and sines apart on arcs), then the check on the moving ``axes``
    (:func:`_excess`, reading the ends' frames from the grid's axis-major storage in place). The same values as
    :func:`interior_excess`, which evaluates it in NumPy (tested against it). On the 100k-block contour (98k arc
    intervals beside 400k boxed ones; ``benchmarks/plan_stages.py``, two interleaved runs against the NumPy check):
    35-39 -> 19-25 ms CPU a plan. ``midpoints``: :func:`excess_midpoints` of the same grid, where made already.
    """
    bad = np.zeros(len(grid), bool)
    if midpoints is False:
        midpoints = excess_midpoints(arrays, grid, first, only)
    if midpoints is None:
        return bad
    idx, mid = midpoints
    q = idx.size
    qb = bucket_size(q)
    at = _pad_aligned(idx, qb, 0)
    rows = {
        "x_a": _pad_aligned(out["x_node"][idx], qb, 0.0),
        "x_b": _pad_aligned(out["x_node"][idx + 1], qb, 0.0),
        "delta": _pad_aligned(grid.delta[idx], qb, 0.0),  # 0 on the padding rows: not checked
        "share": _pad_aligned(out["share"][idx], qb, 1.0),
    }
    ends = {f: grid.axis_major[f] for f in ("t_a", "k_a", "t_b", "k_b")}
    bad[idx] = np.asarray(_grid_excess(ends, at, mid, rows, np.asarray(a_max), axes))[:q]
    return bad


@cached_jit(static_argnames=("axes",))
def _grid_excess(ends: dict, at: jnp.ndarray, mid: tuple, rows: dict, a_max, axes: tuple[int, ...]) -> jnp.ndarray:
    """The check of :func:`grid_excess`: ``ends`` the grid's ``t_a, k_a, t_b, k_b`` ``(3, mb)``, ``at`` ``(q,)`` the
    checked intervals' columns, ``mid`` :func:`~.grid.frame_columns`' six ``(q,)`` columns at their midpoints, ``rows``
    their ``x_a``, ``x_b``, ``delta``, ``share`` ``(q,)``."""
    t_m, k_m = jnp.stack(mid[:3]), jnp.stack(mid[3:6])
    frame = (ends["t_a"][:, at], ends["k_a"][:, at], t_m, k_m, ends["t_b"][:, at], ends["k_b"][:, at])
    delta = rows["delta"]
    return _excess(frame, rows["x_a"], rows["x_b"], delta, delta > 0, a_max, rows["share"], axes)


def plan_topp(req: PlanRequest) -> Plan:
    """Plan with exact per-axis coupling on a fine grid (see the module docstring).

    The grid is planned in windows of about ``WINDOW_INTERVALS`` intervals (all at once when it is
    smaller): each starts from the speed the one before reached and is kept up to its last node that does
    not depend on what follows it (:func:`~jaxcnc.planners.phaseplane.solve_window`) — the whole program's
    plan, in bounded working memory.
    """
    spans = req.spans
    if not is_curved(spans.kind).any() and (req.hold_caps is None or len(req.hold_caps) == 0):
        # lines only: one interval per line, where the rows reduce to the look-ahead planner's span caps
        # and junction caps — the same plan from span arrays alone, without a grid
        return plan_lookahead(req)
    n = len(spans)
    counts = hold_counts(req, interval_counts(spans))
    capacity = int(counts.sum())
    _check_plan_memory(spans, counts, capacity)
    large = bucket_size(capacity) >= TRIM_SEGMENTS  # where handing free memory back is worth its CPU
    if large:
        release_free_heap()  # what building the spans left (and a plan made before and freed)
    facts = _ProgramFacts.of(req)
    # large plans derive where the segments lie from the counts (refined in place) rather than store it
    segments = _SegmentTable(capacity, *((spans.length, counts) if large else ()))
    segments.prepare(req.machine.tick_hz, ahead=not large)  # (large: compiled now, before the windows' memory)
    if large:
        release_free_heap()  # what the junctions and the alignment's compile left
    first, x_start, window = 0, 0.0, WINDOW_INTERVALS
    with _GridAhead(req, counts) as ahead:
        while first < n:
            last = _window_end(counts, first, window)
            built = ahead.take(first, last)  # (None: built in _solve_refined)
            ahead.build(last, first)  # the spans after this window, while it is solved
            grid, out = _solve_refined(req, facts, counts, first, last, x_start, built)
            del built
            m = len(grid)
            if last == n:
                commit = m  # the program ends at rest: every node is the whole program's
            else:
                starts = np.flatnonzero(out["exact"][:m] & (grid.s_start == 0))
                starts = starts[starts > 0]
                enough = out["k0"] >= x_start * (1.0 - 1e-9) - 1e-9  # the window can stop from x_start
                if not (enough and starts.size):
                    window *= 2  # no node of this window is settled yet: look further ahead
                    ahead.keep(grid, 0)
                    del grid, out
                    continue
                commit = int(starts[-1])
            ahead.keep(grid, commit)  # the next window starts with this one's rows from commit on
            segments.append(out, grid, commit)
            x_start = float(out["x_node"][commit])
            first = int(grid.span[commit]) if commit < m else n
            window = WINDOW_INTERVALS
            del grid, out  # freed before the next window's are made, not after
            if large and segments.n == commit:
                release_free_heap()  # the first window's working memory and its programs' compile (a first call)
    del facts  # (n,) arrays: dead before the alignment
    if large:
        release_free_heap()  # the windows' working memory, in pieces too small for the alignment's arrays
    return segments.plan(req.machine.tick_hz)


#: What a grid interval costs to plan at the peak, bytes: measured 95 on three blocks of ``G2 I0.001 P10000`` (10.8 M
#: intervals, 1.3 GB above the runtime), where the intervals are all the work. An estimate for refusing the plans far
#: beyond the memory, not a bound: where the spans weigh more (the 1 M-block blended contour, 5.2 M intervals) the
#: peak is ~0.8 GB above the runtime.
PLAN_BYTES_PER_INTERVAL = 100


def _check_plan_memory(spans: Spans, counts: np.ndarray, capacity: int) -> None:
    """Refuse a plan whose grid would not fit in the memory available, before it is made (a red-team pass,
    2026-12-08: 202 lines of 1 µm circles with ``P10000`` turns each — 360 M intervals, 1° apiece — took the
    machine's 23 GB and were killed after 36 s with nothing said), naming the block whose spans have the most.
    ``capacity``: the intervals, ``counts.sum()``."""
    need = capacity * PLAN_BYTES_PER_INTERVAL
    available = available_memory_bytes()
    if available is None or need <= available:
        return
    by_row = np.bincount(spans.block, weights=counts)
    raise RowPlanningError(
        int(np.argmax(by_row)),
        f"planning needs {capacity:,} grid intervals (~{need / 2**30:.1f} GiB), more than the "
        f"{available / 2**30:.1f} GiB of memory available; {{on_line}} of them on this block's path (arcs and "
        "curves are cut every 1°: many turns of a tiny arc add up)",
        per_row=by_row,
    )


def curvature_step_caps(spans: Spans, j_max: np.ndarray, tick_hz: float) -> np.ndarray:
    """``(n-1,)`` cap on ``x = v²`` at each junction where the curvature vector steps (by ``ΔK``, per axis): passed at
    ``v`` the axis's acceleration steps by ``ΔK_i v²`` within one tick, a jerk of ``ΔK_i v² f`` at tick rate ``f``,
    kept within ``JERK_SHARE`` of ``J_i``. Such steps remain where a junction may not be blended (G61, a beam that
    changes, no tolerance); blended junctions are G2 under jerk limits (:func:`~jaxcnc.geometry.blend.blend_path`).
    Inherently tied to a rate: the jerk of a step is measured one tick wide (the planner passes the rate the
    S-curve stage measures at)."""
    n = len(spans)
    caps = np.full(max(n - 1, 0), np.inf)
    curved = is_curved(spans.kind)
    j = np.flatnonzero(curved[:-1] | curved[1:])
    if j.size == 0:
        return caps
    k_end, k_start = junction_curvatures(spans, j)
    step = np.abs(k_end - k_start)  # (k, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where((step > 0) & np.isfinite(j_max), JERK_SHARE * j_max / (step * tick_hz), np.inf)
    caps[j] = np.min(x, axis=1)
    return caps


#: Intervals planned at once; a longer program is planned window by window (the same plan).
WINDOW_INTERVALS = 1 << 17
#: Build the grid of the spans after a window in a worker thread while the window is solved (:class:`_GridAhead`;
#: the same plan either way). Off: on the 2-core development machine the 100k-block contour planned in 0.441-0.446 s
#: without it and 0.445-0.463 s with it (quiet, min of 7), for 6-9 % more CPU and ~100 MB more at the peak — XLA
#: already keeps both cores busy in the grid and the solve, and two threads at once each run 1.6-1.9x slower. For a
#: machine with cores to spare (docs/planning.md).
OVERLAP_WINDOWS = False
_SEGMENT_KEYS = ("v0", "vp", "v1", "t_acc", "t_cru", "t_dec", "a_acc", "a_dec")


@dataclass(frozen=True, eq=False)
class _ProgramFacts:
    """What every window needs from the whole program: the junctions and the moving axes."""

    at_kink: np.ndarray
    cap_start: np.ndarray
    cap_end: np.ndarray
    is_point: np.ndarray
    axes: tuple[int, ...]

    @staticmethod
    def of(req: PlanRequest) -> _ProgramFacts:
        spans = req.spans
        n = len(spans)
        nb = bucket_size(n)
        step_hz = step_rate_hz(req)  # a velocity or curvature step is one tick of it wide
        j_max = jerk_limits(req)
        at_kink, x_junction = _junction_facts(
            _pad_aligned(spans.kind, nb, SpanKind.POINT),
            _pad_aligned(spans.tangent_in, nb, 0.0),
            _pad_aligned(spans.tangent_out, nb, 0.0),
            _pad_aligned(req.stop_before, nb, True),
            np.asarray(req.a_max),
            step_hz,
            j_max,
        )
        x_junction = np.asarray(x_junction)[: n - 1]
        if j_max is not None:
            x_junction = np.minimum(x_junction, curvature_step_caps(spans, j_max, step_hz))
        zero = np.zeros(1)
        moves = spans.moving_axes & np.isfinite(req.a_max)
        return _ProgramFacts(
            at_kink=np.asarray(at_kink)[:n],
            cap_start=np.concatenate([zero, x_junction]),  # rest before the first span and after the last
            cap_end=np.concatenate([x_junction, zero]),
            is_point=spans.kind == SpanKind.POINT,
            axes=tuple(int(i) for i in np.flatnonzero(moves)),
        )


def _window_end(counts: np.ndarray, first: int, window: int) -> int:
    """The end of the window of spans from ``first`` on whose intervals add up to at most ``window`` (one span at
    least). Every span has an interval at least: the first ``window + 1`` spans' counts decide it."""
    reach = np.cumsum(counts[first : first + window + 1])
    return min(len(counts), first + max(1, int(np.searchsorted(reach, window, side="right"))))


class _GridAhead:
    """Builds the grid of the spans after a window in one worker thread while the window is solved.

    A window's grid rows depend on their spans and counts alone, bit for bit (:class:`~.grid.GridPiece`), and the
    next window starts inside this one (at its commit point, a few spans before its end) and ends at most
    ``WINDOW_INTERVALS`` intervals past its end: the worker builds the spans from a little before this window's end
    (twice the last window's tail) to there, with their :func:`~.grid.device_spans` (which the next window's
    interior check reads), from the counts as they were when it started. The next window's grid is joined from
    those rows and this window's from its commit point on (:func:`~.grid.join_pieces`), or built as before where
    they do not cover it with its counts (a window grown because none of its nodes settled, spans cut finer since).
    The same grids, hence the same plan, whatever the threads' timing. Only programs with blends (whose boxes make
    the grid's cost) use it; the worker runs under the caller's default device, and its exceptions surface where
    its grid is taken.
    """

    #: Spans before a window's end the worker starts at, at least (the last window's tail times two, else).
    BACK_SPANS = 64

    def __init__(self, req: PlanRequest, counts: np.ndarray) -> None:
        self.spans, self.counts = req.spans, counts
        blend = req.spans.kind == SpanKind.BLEND
        on = OVERLAP_WINDOWS and blend.any() and _cpus() > 1
        self.pool = ThreadPoolExecutor(1, thread_name_prefix="jaxcnc-grid") if on else None
        self.blend_end = np.cumsum(blend) if on else None  # blends among the spans before k + 1 (where it builds)
        self.device = jax.config.jax_default_device  # thread-local: the worker enters the same
        self.back = self.BACK_SPANS
        self.tail: GridPiece | None = None  # the last window's rows from its commit point on
        self.pending: Future | None = None

    def __enter__(self) -> _GridAhead:
        return self

    def __exit__(self, *exc) -> None:
        self.pending = None
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)

    def _build(self, first: int, last: int, counts: np.ndarray) -> GridPiece:
        """(In the worker, under the caller's default device) the piece of spans ``first..last-1`` cut by
        ``counts`` (valid there)."""
        with jax.default_device(self.device) if self.device is not None else nullcontext():
            arrays = device_spans(self.spans, first, last)
            grid = build_grid(self.spans, counts, arrays, first, last)
        return GridPiece(first, last, counts[first:last], grid, arrays)

    def build(self, start: int, first: int) -> None:
        """Start building the spans the window after the one of spans ``first..start-1`` may cover (where there
        are blends)."""
        n = len(self.counts)
        if self.pool is None or start >= n:
            return
        end = _window_end(self.counts, start, WINDOW_INTERVALS)
        if self.blend_end[end - 1] - (self.blend_end[start - 1] if start else 0) == 0:
            return  # a window without blends is planned without this grid
        begin = max(first, start - self.back)
        counts = np.empty(end, np.int64)  # (only begin..end-1 set) as they are now: this window may refine its own
        counts[begin:end] = self.counts[begin:end]
        self.pending = self.pool.submit(self._build, begin, end, counts)

    def take(self, first: int, last: int) -> tuple[Grid, dict | None, int] | None:
        """The grid of spans ``first..last-1`` as :func:`~.grid.build_grid` makes it for a window and the
        :func:`~.grid.device_spans` of spans from the int on that cover it (``None``, 0 where not uploaded), or
        ``None`` where not built ahead."""
        ahead, self.pending = (None if self.pending is None else self.pending.result()), None  # (its exception)
        pieces = [p for p in (ahead, self.tail) if p is not None]
        self.tail = None
        if not pieces or not np.any(self.spans.kind[first:last] == SpanKind.BLEND):
            return None
        grid = join_pieces(pieces, self.counts, first, last, bucket_size(int(self.counts[first:last].sum())))
        if grid is None:
            return None
        if ahead is not None and ahead.first <= first and last <= ahead.last:
            return grid, ahead.arrays, ahead.first
        return grid, None, 0

    def keep(self, grid: Grid | _Intervals, row: int) -> None:
        """Keep the rows of ``grid`` (a window's) from ``row`` (the first of a span) on for the next window."""
        if self.pool is not None and isinstance(grid, Grid) and row < len(grid):
            self.tail = GridPiece.of(grid, self.counts, row)
            if row:  # where the next window starts: the worker starts twice as far back
                self.back = max(self.BACK_SPANS, 2 * (self.tail.last - self.tail.first))


def _cpus() -> int:
    """The CPUs this process may run on (the worker thread needs a second one to gain anything)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _solve_refined(
    req: PlanRequest,
    facts: _ProgramFacts,
    counts: np.ndarray,
    first: int,
    last: int,
    x_start: float,
    ahead: tuple[Grid, dict | None, int] | None = None,
) -> tuple[Grid | _Intervals, dict[str, np.ndarray]]:
    """Grid and plan of spans ``first..last-1``, cutting curved spans finer (``counts``, in place) until the
    interior check passes. Only this window's spans are uploaded for the grid's evaluations (the working
    memory of a window does not grow with the program). A window without blends takes :func:`_plain_window`.
    ``ahead``: the window's grid (as :func:`~.grid.build_grid` makes it) where it is built already, and the
    :func:`~.grid.device_spans` of spans from the int on that cover the window, if uploaded with it."""
    kinds = req.spans.kind[first:last]
    curved = is_curved(kinds)
    plain = not np.any(kinds == SpanKind.BLEND)
    if plain:  # the frames read the window's curved spans alone: upload those
        rows = np.flatnonzero(curved)
        arrays = _compact_device_spans(req.spans, first + rows) if rows.size else None
        compact = np.cumsum(curved) - 1  # the window's span k is row compact[k] of arrays (where curved)
    else:  # blends: curved
        grid0, arrays, at = ahead or (None, None, first)  # (arrays: row 0 is span at)
        if arrays is None:
            arrays, at = device_spans(req.spans, first, last), first
    for _ in range(MAX_REFINE):
        if plain:
            grid, out = _plain_window(req, facts, counts, arrays, curved, compact, first, last, x_start)
            bad = out.pop("bad")[: len(grid)] if "bad" in out else np.zeros(len(grid), bool)
        else:
            if grid0 is None:
                pad_to = bucket_size(int(counts[first:last].sum()))
                grid = build_grid(req.spans, counts, arrays if at == first else None, first, last, pad_to=pad_to)
            else:
                grid, grid0 = grid0, None  # (a refinement builds it again)
            only = "arc" if np.all(kinds[curved & (kinds != SpanKind.BLEND)] == SpanKind.ARC) else None
            # the interior check's midpoint frames depend on the grid alone: made (and in a first run compiled)
            # in the compile-ahead thread while the window is solved
            midpoints = compile_ahead(excess_midpoints, arrays, grid, at, only)
            out = _solve_grid(req, facts, grid, x_start)
            bad = grid_excess(arrays, grid, out, req.a_max, facts.axes, at, only, midpoints.result())
        bad = bad | _stalled(curved[grid.span - first], grid, out["x_node"])
        if not bad.any():
            return grid, out
        counts[np.unique(grid.span[bad])] *= REFINE_FACTOR
    raise PlanningError(f"the grid did not settle in {MAX_REFINE} refinements (a planner bug; please report it)")


def _stalled(curved: np.ndarray, grid: Grid | _Intervals, x_node: np.ndarray) -> np.ndarray:
    """``(m,)`` curved intervals (``curved``, ``(m,)``) of some length at rest at both ends: ``s̈`` is constant on a
    curved interval, so ``x`` stays 0 all along it and its trapezoid would cover the interval in no time. A curved
    span alone between two rests (a 1 µm arc between two stops turns by less than ``MAX_TURN_RAD``: one interval)
    needs a node inside to move; cut finer, it gets one."""
    m = len(grid)
    return curved & (grid.delta > 0) & (x_node[:m] <= 0.0) & (x_node[1 : m + 1] <= 0.0)


@dataclass(frozen=True, eq=False)
class _Intervals:
    """Where the intervals of a window without blends lie (:class:`~.grid.Grid`'s first three fields)."""

    span: np.ndarray
    s_start: np.ndarray
    delta: np.ndarray

    def __len__(self) -> int:
        return int(self.span.shape[0])


def _compact_device_spans(spans: Spans, rows: np.ndarray) -> dict[str, jnp.ndarray]:
    """:func:`~.grid.device_spans` of spans ``rows`` alone (row ``k`` is span ``rows[k]``), padded to buckets."""
    sub = take_spans(spans, rows)
    sub = pad_tables(sub, *(bucket_size(len(t)) if len(t) else 0 for t in (sub.arcs, sub.polys)))
    return span_arrays(pad_spans(sub, bucket_size(len(sub))), xp=jnp)


def _plain_window(
    req: PlanRequest,
    facts: _ProgramFacts,
    counts: np.ndarray,
    arrays: dict | None,
    curved_span: np.ndarray,
    compact: np.ndarray,
    first: int,
    last: int,
    x_start: float,
) -> tuple[_Intervals, dict[str, np.ndarray]]:
    """:func:`build_grid`, :func:`_solve_grid` and :func:`interior_excess` of a window without blends (no boxes):
    the same values, bit for bit, made by compiled programs from the window's span arrays.

    The frames are evaluated once per node (an interval's end is the next one's start on the same span: the
    same ``s``, bit for bit) and at the curved intervals' midpoints, in one call (:func:`~.grid.frame_columns`, the
    arcs' cosines and sines from :func:`~.grid.arc_trig_columns`, the chord speed at the nodes with them);
    :func:`_plain_inputs` gathers each interval's fields from its span's (or its nodes' frames) into the padded
    axis-major ``(3, mb)`` layout, :func:`_interval_caps` and :func:`_band_pieces` follow, and :func:`_plain_solve`
    runs the passes and the interior check of the curved intervals (on the moving axes), which comes back as
    ``out["bad"]``. ``curved_span``: ``(last - first,)`` which of the window's spans are curved; ``arrays``:
    :func:`_compact_device_spans` of those alone (``None`` without curves), the window's span ``k`` their row
    ``compact[k]``. Measured on the 100k-block contour with exact corners (2026-11-23, CPU at load 5): 142 ms
    a plan with the inputs made by NumPy and every cap and check over all intervals, 97-102 ms so.
    """
    spans = req.spans
    span, s_start, s_end = cut_spans(spans.length, counts, first, last)
    local = span - first
    m, ns = span.size, last - first
    mb = bucket_size(m)  # the window's spans are padded to mb rows too (ns <= m): one shape per bucket
    delta = s_end - s_start
    curved = curved_span[local]
    idx = np.flatnonzero(curved)
    frames = None
    if idx.size:  # dispatched first: the frames are evaluated while the other inputs are made here
        last_iv = np.append(span[1:] != span[:-1], True)  # the last interval of its span
        ends = np.flatnonzero(last_iv[idx])
        n_c, n_e = idx.size, ends.size
        # nodes: every curved interval's start and each curved span's end; then the midpoints
        q = 2 * n_c + n_e
        row = compact[local[idx]]
        which = np.concatenate([row, row[ends], row])
        where = np.concatenate([s_start[idx], s_end[idx[ends]], s_start[idx] + delta[idx] / 2])
        only = "arc" if np.all(spans.kind[first:last][curved_span] == SpanKind.ARC) else None
        rank = np.cumsum(curved) - 1  # a curved interval's start node is frame rank[i], its midpoint q - n_c + rank[i]
        chord = (req.machine.path.chord_tol_mm, req.machine.tick_hz)
        frames = (node_frames(arrays, which, where, only, chord), np.array([n_c, n_e]))
    window = {
        "t_in": _pad_columns(spans.tangent_in[first:last], mb),
        "t_out": _pad_columns(spans.tangent_out[first:last], mb),
        "feed": _pad_aligned(req.feed_mm_s[first:last], mb, 0.0),
        "dwell": _pad_aligned(req.dwell_s[first:last], mb, 0.0),
        "at_kink": _pad_aligned(facts.at_kink[first:last], mb, False),
        "is_point": _pad_aligned(facts.is_point[first:last], mb, True),  # padding: points at rest after the window
        "cap_start": _pad_aligned(facts.cap_start[first:last], mb, 0.0),
        "cap_end": _pad_aligned(facts.cap_end[first:last], mb, 0.0),
        "curved": _pad_aligned(curved_span, mb, False),
    }
    iv = {
        "local": _pad_aligned(local, mb, ns),  # padding intervals read the padding row ns of the window's spans
        "s_start": _pad_aligned(s_start, mb, 0.0),
        "delta": _pad_aligned(delta, mb, 0.0),
    }
    if frames is not None:
        window["compact"] = _pad_aligned(compact, mb, 0)
        iv["rank"] = _pad_aligned(rank, mb, 0)
    grid = _Intervals(span, s_start, delta)
    holds = None
    if req.hold_caps is not None and len(req.hold_caps):
        hold_a, hold_b = node_holds(req, grid)
        holds = (_pad_aligned(hold_a, mb, np.inf), _pad_aligned(hold_b, mb, np.inf))
    limits = (
        np.asarray(req.v_max),
        np.asarray(req.a_max),
        req.machine.path.chord_tol_mm,
        req.machine.tick_hz,
    )
    j_max = jerk_limits(req)
    g = _plain_inputs(window, iv, frames, holds, np.array([m, x_start]))
    caps = _caps(g, limits[0], *limits[2:], j_max)
    if frames is None:
        out = _plan_lines(g, *limits, x_start, axes=facts.axes, j_max=j_max)
        return grid, {k: np.asarray(v) for k, v in jax.device_get(out).items()}
    pieces, laws = _band_pieces(g, *limits, axes=facts.axes, j_max=j_max, caps=caps)
    ncb = bucket_size(q) // 2  # n_c <= q / 2: the check's shape follows the frames' (fewer compiled shapes)
    at_b = np.arange(1, n_c + 1)  # a curved interval's end node: the next one's start, or its span's end
    at_b[ends] = n_c + np.arange(n_e)
    check = {"idx": _pad_aligned(idx, ncb, 0), "at_b": _pad_aligned(at_b, ncb, 0), "a_max": limits[1]}
    out = jax.device_get(_plain_solve(pieces, laws, x_start, frames, check, facts.axes))
    out = {k: np.asarray(v) for k, v in out.items()}
    out["bad"] = np.zeros(m, bool)
    out["bad"][idx] = out.pop("bad_curved")[:n_c]
    return grid, out


@cached_jit(static_argnames=("axes",))
def _plain_solve(pieces: dict, laws: dict, x_start, frames, check: dict, axes: tuple[int, ...]) -> dict:
    """:func:`_band_solve` of a window without blends, the interior check on its curved intervals alone
    (``bad_curved`` ``(ncb,)``, in their order): read from the nodes' frames as :func:`_plain_window` evaluates
    them (``frames``), ``check["idx"]`` the curved intervals, ``check["at_b"]`` each one's end node."""
    out = _band_solve(pieces, laws, x_start)
    out["bad_curved"] = _curved_excess(out["x_node"], laws, frames, check, axes)
    return out


def _curved_excess(x_node, laws: dict, frames, check: dict, axes: tuple[int, ...]) -> jnp.ndarray:
    """``(ncb,)`` :func:`interior_excess` of the curved intervals ``check["idx"]`` of a window without blends, in
    their order, from ``x`` at the nodes ``(mb+1,)``, :func:`_law_inputs`' ``delta`` and ``share``, and the nodes'
    frames as :func:`_plain_window` evaluates them."""
    cols, (n_c, n_e) = frames
    idx = check["idx"]
    rank = jnp.arange(idx.shape[0])
    at = (rank, rank, n_c + n_e + rank, n_c + n_e + rank, check["at_b"], check["at_b"])
    frame = tuple(jnp.stack([cols[3 * (f % 2) + i][at[f]] for i in range(3)]) for f in range(6))
    delta, share = laws["delta"][idx], laws["share"][idx]
    on = (rank < n_c) & (delta > 0)
    return _excess(frame, x_node[idx], x_node[idx + 1], delta, on, check["a_max"], share, axes)


_caps = cached_jit(_interval_caps)


def _pad_columns(rows: np.ndarray, n: int) -> np.ndarray:
    """``(k, 3)`` rows as an :func:`_aligned` ``(3, n)`` array of columns, zero after the ``k`` rows."""
    out = aligned_array((3, n))
    out[:, : rows.shape[0]] = rows.T
    out[:, rows.shape[0] :] = 0.0
    return out


@cached_jit
def _plain_inputs(window: dict, iv: dict, frames, holds, scalars):
    """The grid fields of a window without blends as :func:`plan_grid` reads them (``g``), gathered from the
    window's spans and the nodes' frames — the values the general grid has, bit for bit (moved, not computed),
    with the chord speeds at the curved nodes (``chord_a``, ``chord_b``: see :func:`~.grid.frame_columns`).

    ``window``: the window's span fields, ``(mb,)`` or ``(3, mb)`` (``t_in``, ``t_out``), padded after its spans
    with a point at rest; ``iv``: each interval's ``local`` span, ``s_start``, ``delta`` ``(mb,)``; ``frames``:
    ``None`` (no curved span) or :func:`~.grid.frame_columns`' seven columns with ``(n_c, n_e)``, laid out as
    :func:`_plain_window` evaluates them, and then ``iv["rank"]`` (a curved interval's rank among them) and
    ``window["compact"]`` (a curved span's rank); ``holds``: ``None`` or the node caps ``(hold_a, hold_b)``;
    ``scalars``: ``(m, x_start)``.
    """
    local, s_start = iv["local"], iv["s_start"]
    mb = local.shape[0]
    m, x_start = scalars[0].astype(local.dtype), scalars[1]
    real = jnp.arange(mb) < m
    first_iv = s_start == 0
    last_iv = jnp.concatenate([local[1:] != local[:-1], jnp.ones(1, bool)])
    curved = window["curved"][local]
    t_a, t_b = window["t_in"][:, local], window["t_out"][:, local]
    zero = jnp.zeros((3, mb))
    k_a = k_b = zero
    if frames is not None:
        cols, (n_c, n_e) = frames
        rank = iv["rank"]
        at = {"a": rank, "b": jnp.where(last_iv, n_c + window["compact"][local], rank + 1)}

        def node(which: str, part: int, other):
            return jnp.where(curved, jnp.stack([cols[3 * part + i][at[which]] for i in range(3)]), other)

        t_a, t_b = node("a", 0, t_a), node("b", 0, t_b)
        k_a, k_b = node("a", 1, zero), node("b", 1, zero)
        # the chord speed at the curved nodes; inf elsewhere, which is what it is where the curvature is 0
        chord = {f"chord_{e}": jnp.where(curved, cols[6][at[e]], jnp.inf) for e in "ab"}
    cap_first = jnp.where(first_iv, window["cap_start"][local], jnp.inf)
    g = {
        "delta": iv["delta"],
        "curved": curved,
        "t_a": t_a,
        "k_a": k_a,
        "t_b": t_b,
        "k_b": k_b,
        "feed": window["feed"][local],
        "dwell": jnp.where(first_iv, window["dwell"][local], 0.0),
        "at_kink": window["at_kink"][local],
        "is_point": window["is_point"][local],
        "cap_first": cap_first.at[0].set(x_start),  # where the window before left the motion
        "cap_last": jnp.where(real, jnp.where(last_iv, window["cap_end"][local], jnp.inf), 0.0),
    }
    inf = jnp.full(mb, jnp.inf)
    g["hold_a"], g["hold_b"] = (inf, inf) if holds is None else holds
    if frames is not None:
        g.update(chord)
    return g


#: Plans of at least this many segments derive where their segments lie instead of storing it (the check costs
#: ~3 % of a 100k-block plan's CPU) and hand the C heap's free pages back before the windows, after the first
#: window (its working memory and, in a first call, its programs' compile: 1 M blocks exact 1000 -> 962-974 MB
#: peak) and before the tick alignment (:func:`~jaxcnc.memory.release_free_heap`; 1 M blocks exact:
#: 1251 -> 1085 MB peak at no measurable CPU). Smaller plans do not: the page faults of memory used again cost
#: ~40 % of the CPU of a 100k-block plan. Nor does each window: 966 MB at 1 M blocks, but +25 % CPU (every 4th:
#: 1057 MB, +7 %). Fixing glibc's mmap threshold instead (``mallopt``, so that large arrays are unmapped when
#: freed) costs more: 962-991 MB but +60-130 % CPU at 1 M blocks exact (1.1 M page faults a plan at 128 KiB).
TRIM_SEGMENTS = 1 << 20

#: Buckets whose tick alignment this process has compiled (see :meth:`_SegmentTable.prepare`).
_ALIGN_COMPILED: set[int] = set()


class _SegmentTable:
    """The plan's segments as the windows commit them, written straight into arrays allocated once.

    ``capacity`` rows are allocated up front (the grid's interval count: every interval is a segment), so
    the windows' outputs are freed window by window instead of being kept as pieces and joined at the end;
    refinement that cuts more intervals grows the arrays. :meth:`plan` aligns them to ticks over the
    whole program; the plan keeps views of the first ``n`` rows, and what is derived here stays derived in the
    :class:`~.timelaw.Plan` (its storage). Five columns are not stored while they can be derived, bit for bit,
    from what is kept anyway (checked on every window):

    * a segment ends at the speed the next one starts at (the same node), so ``v1`` is a view of the ``v0``
      column shifted by one (the plan's ``v_nodes``) — kept apart only if some window's values ever differ in a bit;
    * where a segment lies (``span``, ``s_start``, ``length``) follows from the spans' lengths and the
      final ``counts`` (the windows cut span ``k`` into ``counts[k]`` equal intervals, :func:`_grid_rows`), so
      given ``span_length`` and ``counts`` (the array refinement updates in place) the plan gets them as
      :class:`~.timelaw.SegmentCuts` — stored only from the first window whose grid differs in a bit (never seen);
    * in the same large plans, the ramps' accelerations ``a_acc``, ``a_dec`` are what :func:`trapezoids` makes
      of the speeds and times kept anyway (:func:`~.timelaw.ramp_accel`), made by the plan where they are read —
      stored only from the first window where that differs in a bit (never seen).

    In the same large plans the trapezoids are kept as :class:`~.timelaw.Ramps` (a duration and which ramp, for the
    92 % of a fine grid's segments that are one ramp or cruise; the others whole), and the groups' first ticks once
    (:class:`~.timelaw.GroupTicks`). A 1 M-block blended contour's plan (5.2 M segments): 579 -> 167 MB.
    """

    _FILL = dict.fromkeys(_SEGMENT_KEYS, 0.0) | {
        "rest": True,
        "length": 0.0,
        "span": 0,
        "s_start": 0.0,
        "duration": 0.0,
        "phase": RAMP_GENERAL,
    }
    _DTYPES = {"rest": np.bool_, "span": np.int64, "phase": np.int8}
    _WHERE = ("length", "span", "s_start")
    _ACCEL = ("a_acc", "a_dec")

    def __init__(self, capacity: int, span_length: np.ndarray | None = None, counts: np.ndarray | None = None) -> None:
        self.n = 0
        rows = bucket_size(capacity)
        self.span_length, self.counts = span_length, counts
        self.derived = counts is not None  # where the segments lie: derived from counts (True) or stored
        self.derived_accel = self.derived  # the ramps' accelerations: derived from speeds and times, or stored
        self.next_span = 0  # the first span no committed segment covers yet
        self.ramps = self.derived  # the trapezoids as Ramps (True) or four columns
        derived = (self._WHERE if self.derived else ()) + (self._ACCEL if self.derived_accel else ())
        derived += RAMP_COLUMNS if self.ramps else ("duration", "phase")
        keep = [k for k in self._FILL if k != "v1" and k not in derived]
        # aligned: the tick alignment reads the duration columns in place (else XLA copies them, 3 x 8 bytes a row)
        self.cols = {k: aligned_array(rows + (k == "v0"), self._DTYPES.get(k, np.float64)) for k in keep}
        self.v1: np.ndarray | None = None  # None: v1[k] is v0[k + 1]
        self.general: list[tuple[np.ndarray, np.ndarray]] = []  # (segments, (g, 4) trapezoids) the Ramps store whole
        self.aligning: Future | None = None  # the alignment compiled ahead (prepare)

    def __len__(self) -> int:
        """Rows allocated (at least the segments expected)."""
        return int(self.cols["rest"].shape[0])

    def prepare(self, tick_hz: float, ahead: bool = False) -> None:
        """Compile the tick alignment for the bucket the plan will most likely have, now, while little memory
        is in use: compiled at the end, the compiler's working memory would sit on top of the whole plan's.
        Once per bucket and process (a run on zeros, discarded). ``ahead``: in the background while the windows
        are solved (:func:`~jaxcnc.jitcache.compile_ahead`; 1.6-2.0 s of a first run's compile on the development
        machine), :meth:`plan` waiting for it."""
        mb = len(self)
        if mb not in _ALIGN_COMPILED:
            args = (np.zeros(mb), np.ones(mb, bool), tick_hz)
            if ahead:
                self.aligning = compile_ahead(_align_total, *args)
            else:
                _align_total(*args)
            _ALIGN_COMPILED.add(mb)

    def _reserve(self, rows: int) -> None:
        have = len(self)
        if rows > have:
            grown = bucket_size(max(rows, have + have // 4))
            for k, a in self.cols.items():
                extra = int(k == "v0")
                self.cols[k] = aligned_array(grown + extra, a.dtype)
                self.cols[k][: self.n + extra] = a[: self.n + extra]
            if self.v1 is not None:
                v1, self.v1 = self.v1, np.empty(grown)
                self.v1[: self.n] = v1[: self.n]

    def _trapezoids(self, n: int) -> dict[str, np.ndarray]:
        """``vp``, ``t_acc``, ``t_cru``, ``t_dec`` of the first ``n`` segments (views, or made from the ramps)."""
        if not self.ramps:
            return {k: self.cols[k][:n] for k in RAMP_COLUMNS}
        return self._ramps(n).rows(0, n, self.cols["v0"][:n], self._v1(n))

    def _ramps(self, n: int) -> Ramps:
        """The first ``n`` segments' :class:`~.timelaw.Ramps` (views of the duration and phase columns)."""
        at = [a for a, _ in self.general]
        general = [g for _, g in self.general]
        return Ramps(
            self.cols["duration"][:n],
            self.cols["phase"][:n],
            np.concatenate(at) if at else np.zeros(0, np.int64),
            np.concatenate(general) if general else np.zeros((0, 4)),
        )

    def _derivable(self, grid: Grid, commit: int) -> bool:
        """The window's first ``commit`` grid rows are :func:`_grid_rows` of the spans they cover, bit for bit."""
        if not commit or int(grid.span[0]) != self.next_span or int(grid.span[commit - 1]) < self.next_span:
            return False
        last = int(grid.span[commit - 1]) + 1
        if int(self.counts[self.next_span : last].sum()) != commit:
            return False
        if isinstance(grid, _Intervals):  # cut_spans of these spans with these counts: _grid_rows would repeat it
            return True
        span, s_start, length = _grid_rows(self.span_length, self.counts, self.next_span, last)
        return (
            np.array_equal(span, grid.span[:commit])
            and _same_bits(s_start, grid.s_start[:commit])
            and _same_bits(length, grid.delta[:commit])
        )

    def _store_where(self) -> None:
        """From now on store where the segments lie; the rows so far are derived from the counts."""
        rows = len(self)
        for k, a in zip(self._WHERE, self._where(self.n), strict=True):
            self.cols[k] = np.empty(rows, self._DTYPES.get(k, np.float64))
            self.cols[k][: self.n] = a
        self.derived = False

    def _v1(self, n: int) -> np.ndarray:
        """``v1`` of the first ``n`` segments (a view)."""
        return self.cols["v0"][1 : n + 1] if self.v1 is None else self.v1[:n]

    def _accel(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``a_acc, a_dec`` of the first ``n`` segments from their speeds and times (:func:`~.timelaw.ramp_accel`)."""
        trap, v1 = self._trapezoids(n), self._v1(n)
        return tuple(ramp_accel(trap["vp"], v[:n], trap[t]) for v, t in ((self.cols["v0"], "t_acc"), (v1, "t_dec")))

    @staticmethod
    def _accel_derivable(out: dict[str, np.ndarray], commit: int) -> bool:
        """The window's first ``commit`` ramp accelerations are :func:`~.timelaw.ramp_accel` of its speeds and times."""
        return all(
            _same_bits(ramp_accel(out["vp"][:commit], out[v][:commit], out[t][:commit]), out[k][:commit])
            for k, v, t in (("a_acc", "v0", "t_acc"), ("a_dec", "v1", "t_dec"))
        )

    def _store_accel(self) -> None:
        """From now on store the ramps' accelerations; the rows so far are derived."""
        rows = len(self)
        for k, a in zip(self._ACCEL, self._accel(self.n), strict=True):
            self.cols[k] = aligned_array(rows)
            self.cols[k][: self.n] = a
        self.derived_accel = False

    def _where(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``length, span, s_start`` of the first ``n`` segments (derived mode), as :class:`~.timelaw.SegmentCuts`
        makes them."""
        span, s_start, length = SegmentCuts.of(self.span_length, self.counts).rows(0, n)
        return length, span, s_start

    def append(self, out: dict[str, np.ndarray], grid: Grid, commit: int) -> None:
        """The first ``commit`` intervals' segments (trapezoids and where they lie)."""
        if self.derived and not self._derivable(grid, commit):
            self._store_where()  # (never seen: the windows cut the spans as the counts say)
        if self.derived_accel and not self._accel_derivable(out, commit):
            self._store_accel()  # (never seen: the trapezoids divide the same speeds and times)
        self._reserve(self.n + commit)
        n, cols = self.n, self.cols
        rows = slice(n, n + commit)
        v0, v1 = out["v0"][:commit], out["v1"][:commit]
        if self.v1 is None and not (
            _same_bits(v1[:-1], v0[1:]) and (n == 0 or _same_bits(cols["v0"][n : n + 1], v0[:1]))
        ):
            self.v1 = np.empty(len(self))  # (never seen: the nodes are shared)
            self.v1[:n] = cols["v0"][1 : n + 1]
        for k in _SEGMENT_KEYS:
            if k in cols:
                cols[k][rows] = out[k][:commit]
        if self.ramps:
            duration, phase, general = Ramps.classify({k: out[k][:commit] for k in RAMP_COLUMNS}, v0, v1)
            cols["duration"][rows], cols["phase"][rows] = duration, phase
            at = np.flatnonzero(general)
            if at.size:
                self.general.append((n + at, np.stack([out[k][:commit][at] for k in RAMP_COLUMNS], axis=1)))
        if self.v1 is None:
            cols["v0"][n + commit] = v1[-1]
        else:
            self.v1[rows] = v1
        cols["rest"][rows] = out["x_node"][:commit] == 0.0
        if not self.derived:
            cols["length"][rows] = grid.delta[:commit]
            cols["span"][rows] = grid.span[:commit]
            cols["s_start"][rows] = grid.s_start[:commit]
        if commit:
            self.next_span = int(grid.span[commit - 1]) + 1
        self.n += commit

    def plan(self, tick_hz: float) -> Plan:
        """One :class:`Plan` of the segments, aligned to ticks over the whole program (padded to the bucket
        of their count, as the compiled alignment expects). The tick alignment reads the segments' durations
        alone: only those (and where the motion rests) are handed to the compiled program. The plan keeps the
        columns as stored here: what is derived here stays derived there (:class:`~.timelaw.Plan`'s storage)."""
        if self.aligning is not None:
            self.aligning.result()  # (its exception, if any)
            self.aligning = None
        n = self.n
        mb = bucket_size(n)
        self._reserve(mb)
        cols = self.cols
        for k in ("duration",) if self.ramps else ("t_acc", "t_cru", "t_dec"):
            cols[k][n:mb] = self._FILL[k]
        cols["rest"][n:mb] = True
        # the durations as Ramps.classify sums them (t_acc + t_cru + t_dec, left to right)
        duration = cols["duration"][:mb] if self.ramps else cols["t_acc"][:mb] + cols["t_cru"][:mb] + cols["t_dec"][:mb]
        out = jax.device_get(_align_total(duration, cols["rest"][:mb], tick_hz))
        del duration
        first_segment = np.flatnonzero(cols["rest"][:n])
        groups = GroupTicks(first_segment, np.array(out.pop("g_start")[: first_segment.size]))  # (not a view of mb)
        columns = {"offset_ticks": np.asarray(out["offset_ticks"][:n])}
        columns.update({k: cols[k][:n] for k in _SEGMENT_KEYS + self._WHERE if k in cols and k != "v0"})
        ramps = self._ramps(n) if self.ramps else None
        if self.v1 is None:
            columns["v_nodes"] = cols["v0"][: n + 1]
        else:
            columns["v0"], columns["v1"] = cols["v0"][:n], self.v1[:n]
        cuts = SegmentCuts.of(self.span_length, self.counts) if self.derived else None
        return Plan(columns, int(out["n_ticks"]), tick_hz, cuts, groups, ramps)


def _grid_rows(span_length: np.ndarray, counts: np.ndarray, first: int, last: int) -> tuple[np.ndarray, ...]:
    """``(span, s_start, delta)`` of spans ``first..last-1`` as :func:`~jaxcnc.planners.grid.build_grid` cuts
    them (:func:`~jaxcnc.planners.grid.cut_spans`; :meth:`_SegmentTable.append` checks every window against it)."""
    span, s_start, s_end = cut_spans(span_length, counts, first, last)
    return span, s_start, s_end - s_start


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """``a`` and ``b`` (float64) hold the same bits (``-0.0`` is not ``0.0``)."""
    return np.array_equal(a.view(np.int64), b.view(np.int64))


def hold_counts(req: PlanRequest, counts: np.ndarray) -> np.ndarray:
    """Cut the spans that a hold reaches into intervals of half the hold's width (at most ``MAX_HOLD_CUTS``).

    A line is one grid interval, an arc a few: a hold inside one would have no node to act on, and the
    speed would rise right where it must stay flat (arcs were left out until 2026-11-28: meander520's holds on
    its tiny blends did not hold on the arcs beside them).
    """
    if req.hold_caps is None or len(req.hold_caps) == 0:
        return counts
    spans = req.spans
    span_s0 = spans.s0
    rows = np.asarray(req.hold_caps, dtype=np.float64)
    first = np.clip(np.searchsorted(span_s0, rows[:, 0], side="right") - 1, 0, len(spans) - 1)
    last = np.clip(np.searchsorted(span_s0, rows[:, 1], side="right") - 1, 0, len(spans) - 1)
    width = range_min(len(spans), first, last - first + 1, np.maximum(rows[:, 1] - rows[:, 0], 1e-9))
    held = (spans.kind != SpanKind.POINT) & np.isfinite(width)
    cuts = np.ceil(spans.length / (0.5 * np.where(held, width, 1.0))).astype(np.int64)
    return np.where(held, np.maximum(counts, np.minimum(cuts, MAX_HOLD_CUTS)), counts)


def node_holds(req: PlanRequest, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """``(m,)`` caps on ``x = v²`` at each interval's start and end node from ``req.hold_caps``."""
    m = len(grid)
    if req.hold_caps is None or len(req.hold_caps) == 0:
        return np.full(m, np.inf), np.full(m, np.inf)
    s_a = req.spans.s0[grid.span] + grid.s_start  # nodes in path order: sorted
    s_b = s_a + grid.delta
    rows = np.asarray(req.hold_caps, dtype=np.float64)
    x_cap = rows[:, 2] ** 2

    def caps(s_node: np.ndarray) -> np.ndarray:
        lo = np.searchsorted(s_node, rows[:, 0], side="left")
        return range_min(m, lo, np.searchsorted(s_node, rows[:, 1], side="right") - lo, x_cap)

    return caps(s_a), caps(s_b)


def _solve_grid(req: PlanRequest, facts: _ProgramFacts, grid: Grid, x_start: float) -> dict[str, np.ndarray]:
    """Pad the grid to a bucket, run :func:`plan_grid`, return its outputs as NumPy arrays. The padded inputs are
    :func:`_aligned` (the compiled programs read them in place: a boxed window runs six of them on the same ~30 MB,
    which would otherwise be copied for each)."""
    machine = req.machine
    m = len(grid)
    mb = bucket_size(m)
    s = grid.span
    first = grid.s_start == 0
    last = np.concatenate([s[1:] != s[:-1], [True]])
    cap_first = np.where(first, facts.cap_start[s], np.inf)
    cap_first[0] = x_start  # where the window before left the motion (rest at the program's start)
    g = {
        "delta": _pad_aligned(grid.delta, mb, 0.0),
        "curved": _pad_aligned(grid.curved, mb, False),
        "boxed": _pad_aligned(grid.boxed, mb, False),
        "speed_hi": _pad_aligned(grid.speed_hi, mb, 0.0),
    }
    for f in _AXIS_FIELDS:  # (3, mb): one row per axis
        major = None if grid.axis_major is None else grid.axis_major[f]
        if major is not None and major.shape[1] == mb:  # built in this layout (zero padding): read in place
            g[f] = major
        else:
            g[f] = aligned_array((3, mb))
            g[f][:, :m] = getattr(grid, f).T
            g[f][:, m:] = 0.0
    g.update(
        {
            "feed": _pad_aligned(req.feed_mm_s[s], mb, 0.0),
            "dwell": _pad_aligned(np.where(first, req.dwell_s[s], 0.0), mb, 0.0),
            # padding intervals: points at rest after the window
            "at_kink": _pad_aligned(facts.at_kink[s], mb, False),
            "is_point": _pad_aligned(facts.is_point[s], mb, True),
            "cap_first": _pad_aligned(cap_first, mb, 0.0),
            "cap_last": _pad_aligned(np.where(last, facts.cap_end[s], np.inf), mb, 0.0),
        }
    )
    hold_a, hold_b = node_holds(req, grid)
    g["hold_a"], g["hold_b"] = _pad_aligned(hold_a, mb, np.inf), _pad_aligned(hold_b, mb, np.inf)
    out = plan_grid(
        g,
        np.asarray(req.v_max),
        np.asarray(req.a_max),
        machine.path.chord_tol_mm,
        machine.tick_hz,
        x_start,
        curved_any=bool(grid.curved.any()),
        boxed_any=bool(grid.boxed.any()),
        axes=facts.axes,
        j_max=jerk_limits(req),
    )
    return {k: np.asarray(v) for k, v in jax.device_get(out).items()}


@register_planner("topp")
class ToppPlanner(Planner):
    """``topp`` (the default): time-optimal, per-axis limits coupled exactly; honours the S-curve stage's holds."""

    name = "topp"
    handles_jerk = False  # under j_max, plan_job runs it inside the S-curve stage
    honours_holds = True

    def plan(self, request: PlanRequest) -> Plan:
        return plan_topp(request)
