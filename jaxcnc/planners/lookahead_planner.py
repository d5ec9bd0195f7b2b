"""The planner ``lookahead``: whole-program acceleration-limited trapezoids with span-constant caps.

Caps (:mod:`~jaxcnc.planners.limits`) → two parallel look-ahead scans
(:mod:`~jaxcnc.planners.lookahead`) → trapezoid per span (:mod:`~jaxcnc.planners.motion`) and tick
alignment (:mod:`~jaxcnc.planners.timelaw`), all in one jitted array program. Inputs are padded to a
bucket size so a new job of similar size reuses the compiled program. The fastest planner to compute;
``topp`` (the default) plans a program of lines alone through it, where both give the same plan.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size, pad_rows
from jaxcnc.geometry.kinds import SpanKind
from jaxcnc.jitcache import cached_jit
from jaxcnc.planners.limits import junctions, span_caps
from jaxcnc.planners.lookahead import lookahead
from jaxcnc.planners.motion import trapezoids
from jaxcnc.planners.protocol import Planner, PlanRequest, jerk_limits, step_rate_hz
from jaxcnc.planners.registry import register_planner
from jaxcnc.planners.timelaw import Plan, align_to_ticks, plan_from_outputs

#: An axis whose extent within a span is below this (mm) does not move there.
MOVING_MM = 1e-12


@cached_jit
def plan_arrays(
    kind,
    length,
    kappa,
    d1,
    d2,
    moving,
    tangent_in,
    tangent_out,
    feed,
    dwell,
    stop_before,
    v_max,
    a_max,
    chord_tol,
    tick_hz,
    step_hz,
    j_max=None,
):
    """The planner as one array program; all span arrays ``(n,)`` or ``(n, 3)``. ``step_hz``: the rate whose tick a
    velocity step at a kink is spread over (the tick rate; under jerk limits the rate they are measured at);
    ``j_max``: ``(3,)`` the jerk limits that cap kinks too (:func:`~jaxcnc.planners.limits.kink_jerk_caps`), or
    ``None``.

    Returns the dict of :func:`~jaxcnc.planners.timelaw.align_to_ticks` plus ``x_node`` (v² at
    the ``n+1`` nodes).
    """
    at_kink, x_junction = junctions(kind, tangent_in, tangent_out, stop_before, a_max, step_hz, j_max)
    x_cap, a_t = span_caps(
        kind, length, kappa, d1, d2, tangent_in, moving, feed, v_max, a_max, chord_tol, tick_hz, at_kink
    )
    x_junction = jnp.minimum(x_junction, jnp.minimum(x_cap[:-1], x_cap[1:]))
    zero = jnp.zeros((1,), jnp.float64)
    node_cap = jnp.concatenate([zero, x_junction, zero])
    delta = jnp.where(kind == SpanKind.POINT, 0.0, 2.0 * a_t * length)
    x_node = lookahead(node_cap, delta)
    prof = trapezoids(x_node, x_cap, a_t, length, dwell)
    out = align_to_ticks(prof, x_node[:-1] == 0.0, tick_hz)
    del out["g_start"]  # (the plan stores group_tick per segment)
    out["x_node"] = x_node
    return out


def plan_lookahead(req: PlanRequest) -> Plan:
    """Plan with the whole-program trapezoidal look-ahead (see the module docstring), at the request's limits."""
    spans, machine = req.spans, req.machine
    n = len(spans)
    m = bucket_size(n)
    args = (
        pad_rows(spans.kind, m, SpanKind.POINT),
        pad_rows(spans.length, m, 0.0),
        pad_rows(spans.kappa_max, m, 0.0),
        pad_rows(spans.d1_max, m, 0.0),
        pad_rows(spans.d2_max, m, 0.0),
        pad_rows(spans.hi - spans.lo > MOVING_MM, m, False),
        pad_rows(spans.tangent_in, m, 0.0),
        pad_rows(spans.tangent_out, m, 0.0),
        pad_rows(req.feed_mm_s, m, 0.0),
        pad_rows(req.dwell_s, m, 0.0),
        pad_rows(req.stop_before, m, True),
    )
    out = plan_arrays(
        *args,
        np.asarray(req.v_max),
        np.asarray(req.a_max),
        machine.path.chord_tol_mm,
        machine.tick_hz,
        step_rate_hz(req),
        jerk_limits(req),
    )
    return plan_from_outputs(jax.device_get(out), spans.length, np.arange(n), np.zeros(n), machine.tick_hz)


@register_planner("lookahead")
class LookaheadPlanner(Planner):
    """``lookahead``: span-constant caps, two associative scans, one trapezoid per span."""

    name = "lookahead"
    handles_jerk = False  # under j_max, plan_job runs it inside the S-curve stage
    honours_holds = False

    def plan(self, request: PlanRequest) -> Plan:
        return plan_lookahead(request)
