"""The reference planner ``toppra``: time-optimal, acceleration-limited, by toppra's reachability analysis.

toppra (Pham & Pham 2018) plans on a grid of the path parameter. Its path here is jaxcnc's own
geometry as a function of arc length plus a fourth coordinate ``s`` itself, whose velocity limit
is the programmed feed; per-axis speed and acceleration limits are toppra's joint constraints.
``scheme="collocation"`` imposes the acceleration limit at each grid point only (toppra's classic
discretisation, the source of its overshoot between coarse grid points); ``"interpolation"`` also
at the interval's end, as :mod:`jaxcnc.planners.phaseplane` does. Optional dependency
(``pip install 'jaxcnc[ref]'``).
"""

from __future__ import annotations

import numpy as np

from jaxcnc.errors import PlanningError
from jaxcnc.planners.protocol import Planner, PlanRequest
from jaxcnc.planners.reference import DEFAULT_POINTS, RefProblem, import_optional, plan_from_nodes, ref_problem
from jaxcnc.planners.registry import register_planner
from jaxcnc.planners.timelaw import Plan

#: Stand-in for "no limit" (toppra needs finite bounds).
FREE = 1e12


def _path(p: RefProblem, a: int, b: int):
    """A toppra geometric path over nodes ``a..b``: ``(x, y, z, s)`` with exact derivatives at the nodes."""
    toppra = import_optional("toppra")
    s = p.s[a : b + 1]
    d1 = np.concatenate([p.t[a : b + 1], np.ones((b + 1 - a, 1))], axis=1)
    d2 = np.concatenate([p.k[a : b + 1], np.zeros((b + 1 - a, 1))], axis=1)

    class NodePath(toppra.interpolator.AbstractGeometricPath):
        """Derivatives looked up at the grid nodes (toppra only evaluates there)."""

        def __call__(self, path_positions, order=0):
            q = np.atleast_1d(np.asarray(path_positions, dtype=np.float64))
            i = np.clip(np.searchsorted(s, q - 1e-9 * max(s[-1], 1.0)), 0, s.size - 1)
            if np.any(np.abs(s[i] - q) > 1e-9 * max(s[-1], 1.0)):
                raise PlanningError("toppra asked for the path between grid nodes")
            if order == 0:
                out = np.concatenate([np.zeros((i.size, 3)), q[:, None]], axis=1)
            elif order == 1:
                out = d1[i]
            elif order == 2:
                out = d2[i]
            else:
                out = np.zeros((i.size, 4))
            return out if np.ndim(path_positions) else out[0]

        @property
        def dof(self):
            return 4

        @property
        def path_interval(self):
            return np.array([s[0], s[-1]])

        @property
        def waypoints(self):
            return None

    return NodePath(), s


class ToppraPlanner(Planner):
    """toppra on about ``n_points`` grid points with the given discretisation (see the module docstring)."""

    name = "toppra"
    handles_jerk = False
    honours_holds = False

    def __init__(self, n_points: int = DEFAULT_POINTS, scheme: str = "interpolation"):
        self.n_points, self.scheme = n_points, scheme

    def plan(self, req: PlanRequest) -> Plan:
        n_points, scheme = self.n_points, self.scheme
        toppra = import_optional("toppra")
        constraint = toppra.constraint
        kind = {
            "interpolation": constraint.DiscretizationType.Interpolation,
            "collocation": constraint.DiscretizationType.Collocation,
        }[scheme]
        p = ref_problem(req, n_points)
        v = np.minimum(np.asarray(p.v_max, dtype=np.float64), FREE)
        acc = np.minimum(np.asarray(p.a_max, dtype=np.float64), FREE)
        alim = np.stack([-np.append(acc, FREE), np.append(acc, FREE)], axis=1)
        x = np.zeros(p.s.size)
        for a, b in p.pieces:
            path, s = _path(p, a, b)
            feed = p.feed[a : b + 1]

            def vlim(q, s=s, feed=feed):
                f = feed[np.clip(np.searchsorted(s, q - 1e-9), 0, s.size - 1)]
                return np.stack([-np.append(v, f), np.append(v, f)], axis=1)

            cons = [
                constraint.JointVelocityConstraintVarying(vlim),
                constraint.JointAccelerationConstraint(alim, discretization_scheme=kind),
            ]
            algo = toppra.algorithm.TOPPRA(cons, path, gridpoints=s, solver_wrapper="seidel")
            algo.compute_parameterization(0.0, 0.0)
            data = algo.problem_data
            if data.sd_vec is None or np.isnan(data.sd_vec).any():
                raise PlanningError(f"toppra failed on nodes {a}..{b}: {data.return_code}")
            x[a : b + 1] = np.asarray(data.sd_vec) ** 2
        return plan_from_nodes(p, x, req)


def toppra_planner(n_points: int = DEFAULT_POINTS, scheme: str = "interpolation") -> ToppraPlanner:
    """A :class:`ToppraPlanner` on about ``n_points`` grid points with the given discretisation."""
    return ToppraPlanner(n_points, scheme)


register_planner("toppra", ToppraPlanner())
