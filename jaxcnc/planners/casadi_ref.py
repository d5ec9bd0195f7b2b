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
"""

from __future__ import annotations

import numpy as np

from jaxcnc.errors import PlanningError
from jaxcnc.planners.reference import DEFAULT_POINTS, import_optional, node_caps, plan_from_nodes, ref_problem
from jaxcnc.planners.registry import Planner, PlanRequest, register_planner
from jaxcnc.planners.timelaw import Plan


def casadi_planner(n_points: int = DEFAULT_POINTS, tol: float = 1e-9) -> Planner:
    """A planner solving the grid NLP with IPOPT on about ``n_points`` grid points."""

    def plan(req: PlanRequest) -> Plan:
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

    return plan


register_planner("casadi")(casadi_planner())
