"""The reference planner ``casadi``: the time-optimal problem as a nonlinear program, solved by IPOPT.

On each rest-to-rest piece's grid (nodes ``k = 0..N``, intervals of length ``Δ_k``) the unknowns
are the speeds ``c_k = ṡ`` at the nodes and the path accelerations ``u_k = s̈`` on the
intervals:

    minimise   Σ_k 2 Δ_k / (c_k + c_{k+1})                      (time, s̈ constant per interval)
    subject to c_{k+1}² = c_k² + 2 Δ_k u_k,   c_0 = c_N = 0,   0 ≤ c_k ≤ √cap_k
               |T_ik u_k + K_ik c_k²| ≤ A_i,   |T_i,k+1 u_k + K_i,k+1 c_{k+1}²| ≤ A_i

— the same discretisation as :mod:`jaxcnc.planners.phaseplane`, written as a textbook NLP and
handed to CasADi/IPOPT (started from a slow feasible guess, not from jaxcnc's answer), so it is
an independent check of the built-in planner's optimum. Optional dependency
(``pip install 'jaxcnc[ref]'``).

Jerk (where the machine sets ``j_max``): an axis moves with jerk ``T s⃛ + 3 K ṡ s̈ + K' ṡ³``
(``K' = d³x/ds³``, from the nodes' curvature by central differences). At node ``k``, ``s̈`` steps
from ``u_(k-1)`` to ``u_k`` over the time between the intervals' midpoints,
``(Δ_(k-1) + Δ_k) / (2 c_k)``, so ``s⃛ ≈ 2 c_k (u_k - u_(k-1)) / (Δ_(k-1) + Δ_k)`` and, with
``s̈ ≈ (u_(k-1) + u_k)/2``,

    |T_ik s⃛_k + 3 K_ik c_k s̈_k + K'_ik c_k³| ≤ J_i         (polynomial in the unknowns)

with ``s̈ = 0`` before the first and after the last interval (rest). This is the discretised
jerk-limited problem researchers solve; the plan built from its nodes still holds ``s̈``
constant per interval, so its table shows jerk steps between them (printed as its violation).
"""

from __future__ import annotations

import numpy as np

from jaxcnc.errors import PlanningError
from jaxcnc.planners.protocol import Planner, PlanRequest
from jaxcnc.planners.reference import DEFAULT_POINTS, import_optional, node_caps, plan_from_nodes, ref_problem
from jaxcnc.planners.registry import register_planner
from jaxcnc.planners.timelaw import Plan


class CasadiPlanner(Planner):
    """The grid NLP solved by IPOPT on about ``n_points`` grid points (see the module docstring)."""

    name = "casadi"
    handles_jerk = True  # plan_job does not average its time law: the NLP has the jerk rows
    honours_holds = False

    def __init__(self, n_points: int = DEFAULT_POINTS, tol: float = 1e-9):
        self.n_points, self.tol = n_points, tol

    def plan(self, req: PlanRequest) -> Plan:
        n_points, tol = self.n_points, self.tol
        ca = import_optional("casadi")
        p = ref_problem(req, n_points)
        cap = node_caps(p)
        axes = np.flatnonzero(np.isfinite(p.a_max))
        x = np.zeros(p.s.size)
        for a, b in p.pieces:
            n = b - a
            d = np.diff(p.s[a : b + 1])
            t, k = p.t[a : b + 1][:, axes], p.k[a : b + 1][:, axes]
            amax = p.a_max[axes]
            c = ca.MX.sym("c", n + 1)
            u = ca.MX.sym("u", n)
            c2 = c * c
            g = [c2[1:] - c2[:-1] - 2.0 * d * u]
            lo, hi = [np.zeros(n)], [np.zeros(n)]
            for i in range(axes.size):
                for end in (0, 1):  # the limit at both ends of each interval
                    sl = slice(end, n + end)
                    g.append(t[sl, i] * u + k[sl, i] * c2[sl])
                    lo.append(np.full(n, -amax[i]))
                    hi.append(np.full(n, amax[i]))
            v_cap = np.sqrt(cap[a : b + 1])
            v_cap[0] = v_cap[-1] = 0.0
            jmax = p.j_max[axes]
            if np.any(np.isfinite(jmax)):
                kp = _curvature_rate(p.s[a : b + 1], k)
                zero = ca.MX.zeros(1)
                u_prev, u_next = ca.vertcat(zero, u), ca.vertcat(u, zero)  # s̈ before/after each node
                d_prev = np.concatenate([[d[0]], d])
                d_next = np.concatenate([d, [d[-1]]])
                c_mid = ca.vertcat(c[1], c[1:-1], c[-2]) if n > 1 else ca.vertcat(c[1], c[0])
                # the end nodes are at rest: there s̈ ramps over the first/last interval at its far speed
                span = np.concatenate([[2.0 * d[0]], d_prev[1:-1] + d_next[1:-1], [2.0 * d[-1]]]) / 2.0
                s3 = (u_next - u_prev) * c_mid / span
                sdd = (u_prev + u_next) / 2.0
                for i in range(axes.size):
                    if np.isfinite(jmax[i]):
                        g.append(t[:, i] * s3 + 3.0 * k[:, i] * c * sdd + kp[:, i] * c * c * c)
                        lo.append(np.full(n + 1, -jmax[i]))
                        hi.append(np.full(n + 1, jmax[i]))
            nlp = {"x": ca.vertcat(c, u), "f": ca.sum1(2.0 * d / (c[:-1] + c[1:] + 1e-12)), "g": ca.vertcat(*g)}
            opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": 0, "ipopt.tol": tol}
            solver = ca.nlpsol("topp", "ipopt", nlp, opts)
            guess = np.concatenate([np.minimum(v_cap, 0.1 * np.sqrt(np.max(cap[a : b + 1]))), np.zeros(n)])
            guess[0] = guess[n] = 0.0
            res = solver(
                x0=guess,
                lbx=np.concatenate([np.zeros(n + 1), np.full(n, -np.inf)]),
                ubx=np.concatenate([v_cap, np.full(n, np.inf)]),
                lbg=np.concatenate(lo),
                ubg=np.concatenate(hi),
            )
            if not solver.stats()["success"]:
                raise PlanningError(f"IPOPT did not converge on nodes {a}..{b}: {solver.stats()['return_status']}")
            x[a : b + 1] = np.asarray(res["x"][: n + 1]).ravel() ** 2
        return plan_from_nodes(p, x, req)


def casadi_planner(n_points: int = DEFAULT_POINTS, tol: float = 1e-9) -> CasadiPlanner:
    """A :class:`CasadiPlanner` on about ``n_points`` grid points."""
    return CasadiPlanner(n_points, tol)


def _curvature_rate(s: np.ndarray, k: np.ndarray) -> np.ndarray:
    """``(m+1, n_axes)`` ``dK/ds`` at the nodes: central differences, one-sided at the ends."""
    if s.size < 3:
        return np.zeros_like(k)
    return np.gradient(k, s, axis=0)


register_planner("casadi", CasadiPlanner())
