"""What the reference planners (``toppra``, ``casadi``) share: a uniform grid, rest-to-rest pieces, a Plan.

The references are grid methods: they choose ``x = ṡ²`` at grid nodes and hold ``s̈`` constant in
between, like :mod:`jaxcnc.planners.phaseplane` but solved by an external library, so researchers
can compare profiles through the same interface and the same verified tick table. They plan each
piece between rests (corners, programmed stops, dwells) from rest to rest; they do not model the
velocity steps the built-in planners allow at near-tangent kinks, nor the chord-error cap.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import numpy as np

from jaxcnc.geometry.kinds import SpanKind
from jaxcnc.planners.grid import Grid, build_grid
from jaxcnc.planners.limits import junctions
from jaxcnc.planners.motion import trapezoids
from jaxcnc.planners.protocol import PlanRequest
from jaxcnc.planners.timelaw import Plan, align_to_ticks, plan_from_outputs

#: Grid points of a reference plan unless the request's machine says otherwise.
DEFAULT_POINTS = 16_000


@dataclass(frozen=True, eq=False)
class RefProblem:
    """A request on a uniform grid: frames at the nodes and the rest-to-rest pieces.

    Attributes:
        grid: the intervals (every span boundary is a node).
        s: ``(m+1,)`` node positions (mm from the program start).
        t, k: ``(m+1, 3)`` tangent and curvature vector at the nodes (one-sided at span boundaries:
            the value of the interval that starts there).
        feed: ``(m+1,)`` programmed speed at the nodes (the lower of the two spans at a boundary).
        pieces: list of ``(first_node, last_node)`` planned from rest to rest.
        v_max, a_max: ``(3,)`` axis limits: the request's (the machine's less the margin).
        j_max: ``(3,)`` axis jerk limits, the same way (``inf`` where unset or absent).
    """

    grid: Grid
    s: np.ndarray
    t: np.ndarray
    k: np.ndarray
    feed: np.ndarray
    pieces: list[tuple[int, int]]
    v_max: np.ndarray
    a_max: np.ndarray
    j_max: np.ndarray


def ref_problem(req: PlanRequest, n_points: int = DEFAULT_POINTS) -> RefProblem:
    """Cut the request's spans into about ``n_points`` equal-length intervals and find the pieces."""
    spans = req.spans
    total = float(np.sum(spans.length))
    h = total / max(n_points - 1, 1)
    counts = np.where(spans.kind == SpanKind.POINT, 1, np.maximum(1, np.ceil(spans.length / h - 1e-9)))
    grid = build_grid(spans, counts.astype(np.int64))
    t = np.concatenate([grid.t_a, grid.t_b[-1:]])
    k = np.concatenate([grid.k_a, grid.k_b[-1:]])
    s = np.concatenate([[0.0], np.cumsum(grid.delta)])
    f_int = req.feed_mm_s[grid.span]
    feed = np.minimum(np.concatenate([f_int, f_int[-1:]]), np.concatenate([f_int[:1], f_int]))
    _, x_junction = jax.jit(junctions, static_argnames=("tick_hz",))(
        spans.kind, spans.tangent_in, spans.tangent_out, req.stop_before, req.a_max, tick_hz=req.machine.tick_hz
    )
    rest_span = np.concatenate([[True], np.asarray(x_junction) == 0.0, [True]])  # rest at span boundary b
    first_node = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)  # node index of each span boundary
    rest_nodes = np.unique(first_node[rest_span])
    pieces = [(int(a), int(b)) for a, b in zip(rest_nodes[:-1], rest_nodes[1:], strict=True) if s[b] > s[a]]
    j_max = np.full(3, np.inf) if req.j_max is None else req.j_max
    return RefProblem(grid, s, t, k, feed, pieces, req.v_max, req.a_max, j_max)


def node_caps(p: RefProblem) -> np.ndarray:
    """``(m+1,)`` cap on ``x = ṡ²`` at the nodes from the axis speeds and the feed (the tool moves at ``|q'| ṡ``)."""
    comp = np.abs(p.t)
    with np.errstate(divide="ignore"):
        x_axis = np.min(np.where(comp > 0, (p.v_max / comp) ** 2, np.inf), axis=1)
        x_feed = (p.feed / np.linalg.norm(p.t, axis=1)) ** 2
    return np.minimum(x_axis, x_feed)


def plan_from_nodes(p: RefProblem, x_node: np.ndarray, req: PlanRequest) -> Plan:
    """A Plan holding ``s̈`` constant on every interval between the nodes' ``x`` ``(m+1,)``."""
    g = p.grid
    x = np.maximum(np.asarray(x_node, dtype=np.float64), 0.0)
    x0, x1 = x[:-1], x[1:]
    two_d = 2.0 * np.where(g.delta > 0, g.delta, 1.0)
    dwell = np.where(g.s_start == 0, req.dwell_s[g.span], 0.0)
    out = _profile(x, np.maximum(x0, x1), np.abs(x1 - x0) / two_d, g.delta, dwell, x0 == 0.0, req.machine.tick_hz)
    return plan_from_outputs(out, g.delta, g.span, g.s_start, req.machine.tick_hz)


@partial(jax.jit, static_argnames=("tick_hz",))
def _profile(x, x_cap, a, delta, dwell, rest, tick_hz: float) -> dict:
    return align_to_ticks(trapezoids(x, x_cap, a, delta, dwell), rest, tick_hz)


def import_optional(name: str):
    """Import an optional reference library or say how to install it."""
    import importlib

    from jaxcnc.errors import PlanningError

    try:
        return importlib.import_module(name)
    except ImportError:
        raise PlanningError(
            f"the {name!r} reference planner needs the {name} package: pip install 'jaxcnc[ref]'"
        ) from None
