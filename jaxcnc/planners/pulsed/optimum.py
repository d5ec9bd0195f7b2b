"""The optimum of a pulsed window by branch and bound over tick counts: period counts and ticks enumerated.

:func:`optimum_window` finds the least burn time (first to last pulse, whole ticks) of a window of points
burned in order, over a fixed **motion model** — the one the verifying linear program of
:func:`~.exact.feasible_ticks` checks:

- each axis moves with piecewise-constant acceleration on ``S`` equal steps per gap (``S`` =
  :data:`~.exact.STEPS_PER_GAP`; step length ``h_g / S``), ``|a| <= A_k``, ``|v| <= V_k``;
- the path speed within ``feed`` at every pulse and within ``rapid`` at every step end (hence everywhere:
  the speed is linear per step), both through the same polygon *inside* the Euclidean caps as the verifying
  LP (:data:`~.exact.POLYGON_SIDES` sides for the two axes that move most, the third within
  :data:`~.exact.Z_SHARE` of the cap);
- the beam on each point at its pulse, the window's end speeds free (a window cut out of a job) or, with
  ``rest_ends``, zero (the window planned alone, as the planners plan it);
- each gap a whole number of ticks ``d_g`` with ``m n_min <= d_g <= m n_max`` for some ``m >= 1``.

It is the minimum of ``Σ d_g`` over the admissible tick vectors at which that linear program is feasible;
up to the LP solver's tolerances (HiGHS, 1e-7) it is exact, not a local search.

**The relaxation.** Eliminating the accelerations (``a_j = (v_{j+1} - v_j)/τ_g``) the model at given
durations is linear in the step-end speeds ``v``: ``|v_{j+1} - v_j| <= A τ_g`` and, per gap and axis,
``τ_g M_gk = D_gk`` with ``M_gk = Σ_j (v_j + v_{j+1})/2`` (each step covers ``τ (v_j + v_{j+1})/2``). With
the durations free in a box ``[lo_g, hi_g]`` the only non-linear relation left is the hyperbola
``M = D/τ``; it is convex in ``τ`` (for ``D > 0``; mirrored for ``D < 0``), so it lies above its tangents and
below its chord on the box. Replacing it by those (tangents at both ends and the middle, the chord) gives a
linear program whose optimum ``min Σ d_g`` is a lower bound on every feasible tick vector inside the box;
for a box of one tick per gap chord and tangents meet the curve and the program *is* the verifying LP.

**Branch and bound.** Nodes are boxes of tick counts per gap; the root box runs from each gap's own
certified bound (:func:`~.bound.lower_bound_travel`'s per-gap ticks at the machine's limits, which contain
this model's) to what the incumbent leaves (``UB − 1 − Σ`` the others' lower ends). A node is pruned when
its relaxation is infeasible or its bound reaches the incumbent. Otherwise its relaxed durations are rounded
up to admissible ticks and checked by the exact LP (a new incumbent where feasible), and the gap whose
hyperbola the relaxation misses most (weighted by its box's width) is split: at a period boundary while the
box spans several period counts (so period counts are enumerated first), else at the relaxed count. Best
first; every admissible tick vector in the root box lies in exactly one leaf, so when the queue empties the
incumbent is the optimum. The first incumbent is the given plan's ticks (e.g. ``bang``'s) where the LP finds
them feasible, else every gap's own bound stretched by a common factor.

**Monotonicity.** Feasibility is *not* monotone in a gap's ticks: between two knots at high speed a short
gap cannot be lengthened at will (the least distance covered from ``v`` back to ``v`` grows with the time
while the speed cannot reverse), so no search upward from a lower corner is exact; that is why the boxes
are split rather than searched.
"""

from __future__ import annotations

import heapq
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linprog
from scipy.sparse import coo_matrix, csr_matrix, diags, vstack

from jaxcnc.errors import PlanningError
from jaxcnc.planners.pulsed.exact import (
    POLYGON_INSET,
    POLYGON_SIDES,
    STEPS_PER_GAP,
    Z_SHARE,
    cap_polygon,
    feasible_ticks,
    step_caps,
)
from jaxcnc.planners.pulsed.windows import PulseWindow, snap_up_ticks

#: Tangents of each gap's hyperbola per box (at geometrically spaced durations, both ends included).
TANGENTS = 6
#: Re-solves of a box after its reduced costs shrank it.
TIGHTEN_ROUNDS = 4
#: Relative tolerance of the relaxation's optimum before it is rounded up to whole ticks.
BOUND_TOL = 1e-7


@dataclass(frozen=True)
class OptimumWindow:
    """What :func:`optimum_window` found.

    Attributes:
        ticks: ``(g,)`` the best admissible tick counts found (verified by :func:`~.exact.feasible_ticks`).
        lower_ticks: a lower bound on the optimum of the motion model (equal to ``ticks.sum()`` when proven).
        proven: whether the search finished (``ticks`` is then the optimum).
        nodes: boxes evaluated (one relaxation each).
        lps: linear programs solved (relaxations and exact checks).
        seconds_wall: wall time of the search.
        start_ticks: the first incumbent's total (the given plan's, or the stretched bound's).
        tick_hz: ticks per second.
    """

    ticks: np.ndarray
    lower_ticks: int
    proven: bool
    nodes: int
    lps: int
    seconds_wall: float
    start_ticks: int
    tick_hz: float
    periods: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def seconds(self) -> float:
        """First to last pulse of the best motion found."""
        return float(self.ticks.sum()) / self.tick_hz


class _Model:
    """The window's linear program with durations boxed (see the module docstring); built once, re-bounded per node.

    Variables: per moving axis the speeds at the ``n + 1`` step ends, then the ``g`` gap durations in ticks.
    """

    def __init__(self, pts, tick_hz, v_max, a_max, steps, feed_mm_s, rapid_mm_s, rest_ends=False):
        D_all = np.diff(pts, axis=0)
        self.g = g = D_all.shape[0]
        self.steps = steps
        self.n = n = g * steps
        self.moving = moving = [k for k in range(pts.shape[1]) if np.any(D_all[:, k] != 0)]
        self.m = m = len(moving)
        self.size = m * (n + 1) + g
        c = 1.0 / (steps * tick_hz)  # seconds per step per tick of the gap
        self.D = D_all[:, moving]  # (g, m)
        self.E = self.D / c  # M = E / T with T the gap's ticks
        j = np.arange(n)
        gap = j // steps
        t_col = m * (n + 1) + gap
        rows, cols, vals, rhs = [], [], [], []
        r0 = 0
        for i, k in enumerate(moving):  # |v_{j+1} - v_j| <= A c T_g
            if not np.isfinite(a_max[k]):
                continue
            base = i * (n + 1)
            for sign in (1.0, -1.0):
                rr = r0 + j
                rows += [rr, rr, rr]
                cols += [base + j + 1, base + j, t_col]
                vals += [np.full(n, sign), np.full(n, -sign), np.full(n, -a_max[k] * c)]
                rhs.append(np.zeros(n))
                r0 += n
        self.A_acc = coo_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), (r0, self.size)
        ).tocsr()
        self.b_acc = np.concatenate(rhs) if rhs else np.zeros(0)
        # M_gk = Σ over the gap's steps of (v_j + v_{j+1}) / 2: a (g, n + 1) row per axis
        w = np.zeros((g, n + 1))
        w[gap, j] += 0.5
        w[gap, j + 1] += 0.5
        self.M_rows = [self._axis_block(i, csr_matrix(w)) for i in range(m)]
        zero = self.D == 0
        self.A_eq = vstack([self.M_rows[i][zero[:, i]] for i in range(m)]).tocsr() if zero.any() else None
        caps = step_caps(n, steps, feed_mm_s, rapid_mm_s, rest_ends)
        self.bounds_v = []
        box = [np.full(n + 1, np.inf)] * m
        self.A_cap, self.b_cap = None, None
        if np.isfinite(caps).any() and m >= 2:
            # the same polygon as feasible_ticks
            order, ang, r = cap_polygon([np.abs(self.D[:, i]).sum() for i in range(m)])
            keep = np.flatnonzero(np.isfinite(caps))
            eye = csr_matrix((np.ones(keep.size), (np.arange(keep.size), keep)), (keep.size, n + 1))
            blocks = [
                np.cos(t) * self._axis_block(order[0], eye) + np.sin(t) * self._axis_block(order[1], eye) for t in ang
            ]
            self.A_cap = vstack(blocks).tocsr()
            self.b_cap = np.tile(caps[keep] * r * POLYGON_INSET, POLYGON_SIDES)
            if m == 3:
                box = list(box)
                box[order[2]] = caps * Z_SHARE
        elif np.isfinite(caps).any():
            box = [caps] * m
        for i, k in enumerate(moving):
            vb = np.minimum(v_max[k], box[i])
            self.bounds_v += [(-b, b) if np.isfinite(b) else (None, None) for b in vb]

    def _axis_block(self, i: int, mat) -> csr_matrix:
        """``mat`` ``(r, n + 1)`` placed in the columns of axis ``i``'s speeds."""
        from scipy.sparse import hstack

        r = mat.shape[0]
        left = csr_matrix((r, i * (self.n + 1)))
        right = csr_matrix((r, self.size - (i + 1) * (self.n + 1)))
        return hstack([left, mat, right]).tocsr()

    def _hyperbola_block(self) -> None:
        """The fixed part of the tangent and chord rows: ``∓s M`` per moving (gap, axis); their ``T`` entries vary."""
        parts, gaps, mag = [], [], []
        for i in range(self.m):
            nz = self.E[:, i] != 0
            if nz.any():
                parts.append(diags(np.sign(self.E[nz, i])) @ self.M_rows[i][nz])
                gaps.append(np.flatnonzero(nz))
                mag.append(np.abs(self.E[nz, i]))
        self.h_gap = np.concatenate(gaps) if gaps else np.zeros(0, np.int64)
        self.h_mag = np.concatenate(mag) if mag else np.zeros(0)
        sM = vstack(parts).tocsr() if parts else csr_matrix((0, self.size))
        # TANGENTS tangents (-s M ...) then the chord (+s M ...)
        fixed = [-sM] * TANGENTS + [sM, self.A_acc] + ([self.A_cap] if self.A_cap is not None else [])
        self.A_fixed = vstack(fixed).tocsr()
        self.b_tail = np.concatenate([self.b_acc] + ([self.b_cap] if self.A_cap is not None else []))

    def solve(self, lo: np.ndarray, hi: np.ndarray, cost: np.ndarray | None = None, cap: float | None = None):
        """The relaxation on the box ``[lo, hi]`` ``(g,)`` ticks.

        Minimises ``Σ T`` (or ``cost · T``), with ``Σ T <= cap`` where given. Returns ``(feasible, value, T,
        reduced)``: ``reduced`` ``(g,)`` the reduced costs of the ``T`` bounds (positive at a lower bound,
        negative at an upper one).
        """
        if not hasattr(self, "A_fixed"):
            self._hyperbola_block()
        g, h = self.g, self.h_gap.size
        tcol = self.m * (self.n + 1) + np.arange(g)
        lo_f, hi_f = lo.astype(np.float64), hi.astype(np.float64)
        e, L, H = self.h_mag, lo_f[self.h_gap], hi_f[self.h_gap]
        # tangents at points spaced geometrically over the box: -s M - (e/Tt²) T <= -2e/Tt
        # the chord: s M + e/(lo hi) T <= e/lo + e/hi
        at = [L * (H / L) ** (i / (TANGENTS - 1)) for i in range(TANGENTS)]
        t_vals = np.concatenate([-e / Tt**2 for Tt in at] + [e / (L * H)])
        rows = np.arange((TANGENTS + 1) * h)
        cols = np.tile(tcol[self.h_gap], TANGENTS + 1)
        A_ub = self.A_fixed + csr_matrix((t_vals, (rows, cols)), self.A_fixed.shape)
        b_ub = np.concatenate([-2.0 * e / Tt for Tt in at] + [e / L + e / H, self.b_tail])
        if cap is not None:
            A_ub = vstack([A_ub, csr_matrix((np.ones(g), (np.zeros(g, np.int64), tcol)), (1, self.size))]).tocsr()
            b_ub = np.concatenate([b_ub, [cap]])
        c = np.zeros(self.size)
        c[tcol] = 1.0 if cost is None else cost
        bounds = self.bounds_v + list(zip(lo_f, hi_f, strict=True))
        eq = {}
        if self.A_eq is not None:
            eq = {"A_eq": self.A_eq, "b_eq": np.zeros(self.A_eq.shape[0])}
        res = linprog(c, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs", **eq)
        if res.status != 0:
            return False, np.inf, None, None
        self.last_x = res.x
        reduced = np.asarray(res.lower.marginals[tcol]) + np.asarray(res.upper.marginals[tcol])
        return True, float(res.fun), np.asarray(res.x[tcol]), reduced


def _snap_down(n: np.ndarray, window: PulseWindow) -> np.ndarray:
    """The largest admissible count ``<= n`` (``n >= n_min``)."""
    n = np.asarray(n, dtype=np.int64)
    if not window.idle_pulses:
        return np.minimum(n, window.n_max)
    m = n // window.n_min  # the most periods that fit
    return np.minimum(n, m * window.n_max)


def optimum_window(
    points: np.ndarray,
    window: PulseWindow,
    v_max: np.ndarray,
    a_max: np.ndarray,
    lower_ticks: np.ndarray,
    start_ticks: np.ndarray | None = None,
    steps: int = STEPS_PER_GAP,
    feed_mm_s: float | None = None,
    rapid_mm_s: float | None = None,
    max_nodes: int = 20_000,
    max_seconds: float = 120.0,
    tighten_root: bool = True,
    rest_ends: bool = False,
) -> OptimumWindow:
    """The least burn time of ``points`` ``(n, 3)`` mm in this order over the motion model (module docstring).

    ``v_max``, ``a_max`` ``(3,)``: the limits the motion keeps (a planner's: the request's);
    ``feed_mm_s``/``rapid_mm_s`` the path caps (``bang``'s). ``lower_ticks`` ``(n-1,)``: a certified lower
    bound on each gap alone (e.g. ``lower_bound_travel(...).gap_ticks`` at the machine's limits, which
    contain these). ``start_ticks``: a plan's tick counts ``(g,)`` or several ``(k, g)``, the first incumbent
    (the shortest the LP finds feasible). Stops after ``max_nodes`` boxes or ``max_seconds``; then ``proven``
    is false and ``lower_ticks`` of the result is the least bound among the boxes left. ``rest_ends``: at rest at the
    window's first and last point (as a planner plans the window alone) instead of free end speeds.
    """
    t0 = time.perf_counter()
    f, n_min, n_max, idle = window.tick_hz, window.n_min, window.n_max, window.idle_pulses
    pts = np.asarray(points, dtype=np.float64)
    pts = pts - pts[0]
    g = pts.shape[0] - 1
    if g < 1:
        raise PlanningError("the optimum needs at least two points")
    V, A = np.asarray(v_max, dtype=np.float64), np.asarray(a_max, dtype=np.float64)
    lo0 = snap_up_ticks(np.maximum(np.asarray(lower_ticks, dtype=np.int64), n_min), n_min, n_max, idle)[0]

    def feasible(ticks) -> bool:
        return feasible_ticks(pts, ticks, f, V, A, steps, feed_mm_s, rapid_mm_s, rest_ends)

    lps = 0
    best = None
    if start_ticks is not None:  # one plan's ticks (g,) or several (k, g): the shortest feasible one
        for st in sorted(np.atleast_2d(np.asarray(start_ticks, dtype=np.int64)), key=lambda t: int(t.sum())):
            lps += 1
            if feasible(st):
                best = st.copy()
                break
    if best is None:  # every gap's own bound stretched by a common factor until a motion exists
        for i in range(400):
            trial = snap_up_ticks(np.ceil(lo0 * (1.0 + 0.02 * i)).astype(np.int64), n_min, n_max, idle)[0]
            lps += 1
            if feasible(trial):
                best = trial
                break
        if best is None:
            raise PlanningError("no motion found for the window within 9 x its gaps' own bounds")
    start_total = int(best.sum())
    model = _Model(pts, f, V, A, steps, feed_mm_s, rapid_mm_s, rest_ends)

    def limit_hi(lo: np.ndarray, ub: int) -> np.ndarray:
        return _snap_down(ub - 1 - (lo.sum() - lo), window)

    heap: list = []
    counter = 0
    nodes = 0

    def push(lo, hi):
        nonlocal counter, nodes, lps, best
        for _ in range(TIGHTEN_ROUNDS):
            ub = int(best.sum())
            hi = np.minimum(hi, limit_hi(lo, ub))
            if np.any(hi < lo):
                return
            nodes += 1
            lps += 1
            ok, val, T, reduced = model.solve(lo, hi)
            if not ok:
                return
            bound = max(int(np.ceil(val * (1.0 - BOUND_TOL) - 1e-6)), int(lo.sum()))
            if bound >= ub:
                return
            # round the relaxed durations up to admissible ticks inside the box: a candidate incumbent
            cand = np.minimum(snap_up_ticks(np.ceil(T - 1e-6).astype(np.int64), n_min, n_max, idle)[0], hi)
            cand = np.maximum(cand, lo)
            if cand.sum() < ub:
                lps += 1
                if feasible(cand):
                    best = cand
                    ub = int(best.sum())
                    if bound >= ub:
                        return
            # reduced costs: T_k above its lower end by δ costs at least reduced_k δ more (and likewise below
            # its upper end), so a box point that could beat the incumbent lies within the slack's reach
            slack = (ub - 1) - val * (1.0 - BOUND_TOL)
            new_lo, new_hi = _tighten(lo, hi, reduced, slack, window)
            if np.any(new_hi < new_lo):
                return
            shrank = (hi - lo).sum() - (new_hi - new_lo).sum()
            lo, hi = new_lo, new_hi
            if shrank <= 0.05 * (hi - lo).sum() + 1:
                break
        counter += 1
        heapq.heappush(heap, (bound, counter, lo, hi, T, model.last_x))

    if tighten_root:  # the least and the most each gap can last in the relaxation of a better motion
        lo0, hi0 = lo0.copy(), limit_hi(lo0, int(best.sum()))
        for k in range(g):
            if np.any(hi0 < lo0):  # no vector in the box beats the incumbent: it is the optimum
                break
            for sign in (1.0, -1.0):
                cost = np.zeros(g)
                cost[k] = sign
                lps += 1
                ok, val, _, _ = model.solve(lo0, hi0, cost=cost, cap=best.sum() - 1.0)
                if not ok:  # no relaxed motion beats the incumbent: it is the optimum
                    hi0 = lo0 - 1
                    break
                if sign > 0:
                    lo0[k] = snap_up_ticks(np.int64(np.ceil(val - 1e-6)), n_min, n_max, idle)[0]
                else:
                    hi0[k] = _snap_down(np.int64(np.floor(-val + 1e-6)), window)
        if not np.any(hi0 < lo0):
            push(lo0, hi0)
    else:
        push(lo0, limit_hi(lo0, int(best.sum())))
    proven = True
    floor = int(best.sum())
    while heap:
        bound, _, lo, hi, T, x = heapq.heappop(heap)
        if bound >= best.sum():
            continue
        if nodes >= max_nodes or time.perf_counter() - t0 > max_seconds:
            proven = False
            floor = min(bound, int(best.sum()))
            break
        width = hi - lo
        if not width.any():  # a single tick vector whose relaxation is the exact LP: feasible, so an incumbent
            lps += 1
            if feasible(lo) and lo.sum() < best.sum():
                best = lo.copy()
            continue
        # the gap the relaxation misses most (its mean speeds against D / τ), among the boxes not yet single
        score = np.where(width > 0, _miss(model, x, T) + 1e-9 * width, -1.0)
        k = int(np.argmax(score))
        lo_k, hi_k, t_k = int(lo[k]), int(hi[k]), float(T[k])
        m_lo, m_hi = -(-lo_k // n_max), hi_k // n_min
        if idle and m_hi > m_lo:  # several period counts: split at one's edge
            m_t = int(np.clip(-(-int(np.ceil(t_k)) // n_max), m_lo, m_hi - 1))
            cut = int(np.clip(m_t * n_max, lo_k, hi_k - 1))
        else:
            cut = int(np.clip(np.floor(t_k), lo_k, hi_k - 1))
        left_hi, right_lo = hi.copy(), lo.copy()
        left_hi[k] = _snap_down(np.int64(cut), window)
        right_lo[k] = snap_up_ticks(np.int64(cut + 1), n_min, n_max, idle)[0]
        if left_hi[k] >= lo_k:
            push(lo, left_hi)
        if right_lo[k] <= hi_k:
            push(right_lo, hi)
    if proven:
        floor = int(best.sum())
    periods = snap_up_ticks(best, n_min, n_max, idle)[1]
    return OptimumWindow(
        ticks=best,
        lower_ticks=floor,
        proven=proven,
        nodes=nodes,
        lps=lps,
        seconds_wall=time.perf_counter() - t0,
        start_ticks=start_total,
        tick_hz=f,
        periods=periods,
    )


def _miss(model: _Model, x: np.ndarray, T: np.ndarray) -> np.ndarray:
    """How far the relaxed solution ``x`` is from a motion, per gap ``(g,)``, in ticks.

    Each moving axis' mean-speed sum ``M`` should be ``E / T``; the duration it implies, ``E / M``, differs
    from ``T`` where the relaxation used its chord or tangents. The largest difference over the axes.
    """
    out = np.zeros(model.g)
    for i in range(model.m):
        M = model.M_rows[i] @ x
        E = model.E[:, i]
        with np.errstate(divide="ignore", invalid="ignore"):
            implied = np.where(E != 0, E / np.where(M * E > 0, M, np.nan), T)
        out = np.maximum(out, np.where(np.isfinite(implied), np.abs(implied - T), 1e6))
    return out


def _tighten(lo, hi, reduced, slack, window):
    """Shrink the box ``[lo, hi]`` by reduced-cost fixing: ``(lo, hi)`` snapped to admissible counts.

    The relaxation on a sub-box lies inside this one's (the chord of a convex curve on a sub-interval is below
    the chord on the interval), so its optimum grows by at least ``reduced_k δ`` when ``T_k`` moves ``δ`` away
    from the bound it rests on; with ``slack`` ticks to the incumbent ``δ <= slack / |reduced_k|``.
    """
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    lo, hi = lo.copy(), hi.copy()
    with np.errstate(divide="ignore"):
        reach = np.floor(np.where(reduced != 0, slack / np.abs(reduced), np.inf) + 1e-9)
    up = (reduced > 1e-9) & np.isfinite(reach)
    down = (reduced < -1e-9) & np.isfinite(reach)
    hi[up] = np.minimum(hi[up], _snap_down(lo[up] + reach[up].astype(np.int64), window))
    lo[down] = np.maximum(lo[down], snap_up_ticks(hi[down] - reach[down].astype(np.int64), n_min, n_max, idle)[0])
    return lo, hi
