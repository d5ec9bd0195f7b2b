"""An exact reference for pulsed jobs on windows of points: period counts and motion chosen jointly.

:func:`exact_window` answers "how fast could *any* motion burn these points, in this order?" for a window
of a few hundred points, to measure how far a planner is from optimal. The motion of each axis is
piecewise-constant acceleration on ``S`` equal steps per gap (bang-bang motions, whose switches fall on
the step grid, included); the unknowns are the gap durations ``h_g``, the accelerations and the speeds and
positions at the steps. Three stages:

1. **Relaxed.** A nonlinear program (CasADi, IPOPT): minimise ``Σ h_g`` subject to the dynamics
   ``v_{j+1} = v_j + a_j τ_j``, ``p_{j+1} = p_j + v_j τ_j + a_j τ_j²/2`` (``τ_j = h_g / S``), the beam on
   the points at the pulses, ``|a| <= A_k``, ``|v| <= V_k`` at every step end (exact: ``v`` is linear per
   step), ``h_g >= n_min / f``. Free speeds at the window's first and last point (a window cut out of a
   job). Its optimum ``relaxed_s`` ignores that a gap is whole ticks in the lamp's windows.
2. **Rounded.** Each gap's period count is fixed at ``m_g = ceil(h_g f / n_max)``, the program solved
   again with ``m_g n_min <= h_g f <= m_g n_max``; its durations are rounded up to whole ticks.
3. **Verified.** With the durations fixed the problem is a linear program per axis (HiGHS); the rounded
   ticks are kept only if it is feasible, else every gap is stretched by 0.1 % steps (and snapped to the
   windows) until it is. ``ticks`` is therefore the time of a motion that exists; IPOPT is a local solver,
   so it is an upper bound on the optimum of this motion class, and ``relaxed_s`` is the figure to
   compare against when judging how far it could still be.

The limits are the planner's (the request's, below the machine's by the numeric margin, each axis at
most the path feed), so a planner's answer on the same points can be compared with ``ticks`` directly,
and the certified :func:`~.bound.lower_bound_travel` (at the machine's limits) lies below both.
Optional dependency: ``pip install 'jaxcnc[ref]'`` (CasADi).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jaxcnc.errors import PlanningError
from jaxcnc.planners.pulsed.windows import PulseWindow, snap_up_ticks
from jaxcnc.planners.reference import import_optional

#: Steps of constant acceleration per gap.
STEPS_PER_GAP = 4


@dataclass(frozen=True)
class ExactWindow:
    """What :func:`exact_window` found for one window.

    Attributes:
        relaxed_s: the optimum with continuous gap durations (only ``h >= n_min / f``).
        ticks: ``(g,)`` admissible tick counts of a motion the linear program proves feasible.
        periods: ``(g,)`` lamp periods in each gap (``m``; ``m - 1`` idle pulses).
        tick_hz: ticks per second.
        stretch: the common factor the rounded durations needed (1.0: none).
    """

    relaxed_s: float
    ticks: np.ndarray
    periods: np.ndarray
    tick_hz: float
    stretch: float

    @property
    def seconds(self) -> float:
        """First to last pulse of the verified motion."""
        return float(self.ticks.sum()) / self.tick_hz


def _nlp(ca, pts, lo_s, hi_s, guess_s, v_max, a_max, steps, tol, feed=None, rapid=None):
    """Minimise the window's time with each ``h_g`` in ``[lo_s, hi_s]``; returns ``h`` ``(g,)``.

    ``feed``/``rapid``: the path speed (Euclidean) at most ``feed`` at the pulses and ``rapid`` at every
    step end (so everywhere: the speed is linear per step, its norm convex).
    """
    g, dims = pts.shape[0] - 1, pts.shape[1]
    n = g * steps
    opti = ca.Opti()
    h = opti.variable(g)
    a = opti.variable(n, dims)
    v = opti.variable(n + 1, dims)
    p = opti.variable(n + 1, dims)
    pick = np.zeros((n, g))
    pick[np.arange(n), np.arange(n) // steps] = 1.0 / steps
    tau = ca.repmat(ca.mtimes(ca.DM(pick), h), 1, dims)
    opti.subject_to(v[1:, :] == v[:-1, :] + a * tau)
    opti.subject_to(p[1:, :] == p[:-1, :] + v[:-1, :] * tau + 0.5 * a * tau * tau)
    opti.subject_to(p[list(range(0, n + 1, steps)), :] == ca.DM(pts))
    for k in range(dims):
        opti.subject_to(opti.bounded(-a_max[k], a[:, k], a_max[k]))
        opti.subject_to(opti.bounded(-v_max[k], v[:, k], v_max[k]))
    speed2 = ca.sum2(v * v)  # (n + 1, 1)
    if rapid is not None:
        opti.subject_to(speed2 <= rapid * rapid)
    if feed is not None:
        opti.subject_to(speed2[list(range(0, n + 1, steps))] <= feed * feed)
    opti.subject_to(opti.bounded(ca.DM(lo_s), h, ca.DM(hi_s)))
    opti.minimize(ca.sum1(h) / float(np.sum(guess_s)))
    # a start: the guess durations, positions interpolated linearly, speeds the mean speeds
    t_guess = np.concatenate([[0.0], np.cumsum(np.repeat(guess_s / steps, steps))])
    knots = np.concatenate([[0.0], np.cumsum(guess_s)])
    p0 = np.column_stack([np.interp(t_guess, knots, pts[:, k]) for k in range(dims)])
    v0 = np.clip(np.gradient(p0, t_guess, axis=0), -v_max, v_max)
    cap = min(x for x in (feed, rapid, np.inf) if x is not None)
    if np.isfinite(cap):  # start inside the path caps
        v0 = v0 * np.minimum(1.0, 0.9 * cap / np.maximum(np.linalg.norm(v0, axis=1, keepdims=True), 1e-12))
    opti.set_initial(h, guess_s)
    opti.set_initial(p, p0)
    opti.set_initial(v, v0)
    opti.set_initial(a, np.zeros((n, dims)))
    opti.solver(
        "ipopt", {"print_time": 0, "expand": True}, {"print_level": 0, "sb": "yes", "tol": tol, "max_iter": 3000}
    )
    try:
        sol = opti.solve()
    except RuntimeError as exc:
        raise PlanningError(f"IPOPT found no motion for the window: {exc}") from exc
    return np.asarray(sol.value(h), dtype=np.float64).reshape(-1)


#: Sides of the polygon inside the circle of a path cap, in the plane of two moving axes.
POLYGON_SIDES = 16
#: With three moving axes, the least-moving one's share of a path cap (the other two share the rest).
Z_SHARE = 0.3
#: A side's distance from the centre of the polygon inscribed in the unit circle.
POLYGON_INSET = np.cos(np.pi / POLYGON_SIDES)


def step_caps(n_steps: int, steps: int, feed_mm_s, rapid_mm_s, rest_ends: bool) -> np.ndarray:
    """``(n_steps + 1,)`` the path-speed cap at each step end: the rapid everywhere, the feed at the pulses
    (every ``steps``-th end), 0 at the window's ends when they are at rest; ``inf`` where none applies."""
    caps = np.full(n_steps + 1, np.inf)
    if rapid_mm_s is not None:
        caps[:] = rapid_mm_s
    if feed_mm_s is not None:
        caps[::steps] = np.minimum(caps[::steps], feed_mm_s)
    if rest_ends:
        caps[[0, -1]] = 0.0
    return caps


def cap_polygon(travel: list[float]) -> tuple[list[int], np.ndarray, float]:
    """How the speed cap is made linear for moving axes with ``travel`` ``(m,)`` (total distance each, m ≥ 2).

    The two axes that move most share a polygon of :data:`POLYGON_SIDES` sides inscribed in the circle of
    radius ``r`` × the cap; a third gets a box of :data:`Z_SHARE` × the cap, with ``r = sqrt(1 - Z_SHARE²)``,
    so the speed stays within the ball. Returns ``(order, angles, r)``: the axes by travel (most first),
    the polygon's side directions, and its circle's radius per unit cap (a side at ``r`` × :data:`POLYGON_INSET`).
    """
    m = len(travel)
    order = sorted(range(m), key=lambda i: -travel[i])
    r = 1.0 if m == 2 else np.sqrt(1.0 - Z_SHARE**2)
    ang = np.arange(POLYGON_SIDES) * 2 * np.pi / POLYGON_SIDES
    return order, ang, r


def feasible_ticks(
    pts: np.ndarray,
    ticks: np.ndarray,
    tick_hz: float,
    v_max,
    a_max,
    steps: int = STEPS_PER_GAP,
    feed_mm_s: float | None = None,
    rapid_mm_s: float | None = None,
    rest_ends: bool = False,
) -> bool:
    """Whether a motion with ``steps`` constant accelerations per gap burns ``pts`` ``(n, d)`` at gaps ``ticks``.

    A linear program (HiGHS): unknowns the speeds at the step ends and the accelerations, each axis
    ``|v| <= V``, ``|a| <= A``; the speeds linear per step, so the bounds at the step ends hold
    everywhere. Free end speeds. Path caps (``feed_mm_s`` at every pulse, ``rapid_mm_s`` at every step
    end) are kept *inside* the Euclidean ones, so a feasible answer is a real motion within them: one
    moving axis, its box; two, a polygon of :data:`POLYGON_SIDES` sides inside the circle; three, the
    least-moving axis within :data:`Z_SHARE` of the cap and the polygon inside the rest.
    Without path caps the axes are independent (one program each). ``rest_ends``: at rest at the first and
    last point instead (a window planned alone, as the planners plan it).
    """
    from scipy.optimize import linprog
    from scipy.sparse import block_diag, bmat, coo_matrix, csr_matrix, hstack, vstack

    g = ticks.shape[0]
    n = g * steps
    tau = np.repeat(np.asarray(ticks, dtype=np.float64) / tick_hz / steps, steps)
    j = np.arange(n)
    # v_{j+1} - v_j - tau_j a_j = 0
    ones = np.ones(n)
    dyn_v = coo_matrix((np.concatenate([ones, -ones]), (np.tile(j, 2), np.concatenate([j + 1, j]))), (n, n + 1))
    dyn_a = coo_matrix((-tau, (j, j)), (n, n))
    # per gap: sum over its steps of v_j tau_j + a_j tau_j^2 / 2 = D_g
    gap = j // steps
    pos_v = coo_matrix((tau, (gap, j)), (g, n + 1))
    pos_a = coo_matrix((0.5 * tau * tau, (gap, j)), (g, n))
    A_eq = bmat([[dyn_v, dyn_a], [pos_v, pos_a]]).tocsr()
    moving = [k for k in range(pts.shape[1]) if np.any(np.diff(pts[:, k]) != 0)]
    caps = step_caps(n, steps, feed_mm_s, rapid_mm_s, rest_ends)
    if not np.isfinite(caps).any() or len(moving) <= 1:
        for k in moving:
            D = np.diff(pts[:, k])
            if not np.isfinite(a_max[k]) and not np.isfinite(v_max[k]):
                continue
            vb = np.minimum(v_max[k], caps)
            res = linprog(
                np.zeros(2 * n + 1),
                A_eq=A_eq,
                b_eq=np.concatenate([np.zeros(n), D]),
                bounds=[(-c, c) for c in vb] + [(-a_max[k], a_max[k])] * n,
                method="highs",
            )
            if res.status != 0:
                return False
        return True
    m = len(moving)
    size = 2 * n + 1
    b_eq = np.concatenate([np.concatenate([np.zeros(n), np.diff(pts[:, k])]) for k in moving])
    order, ang, r = cap_polygon([np.abs(np.diff(pts[:, k])).sum() for k in moving])
    zero = csr_matrix((n + 1, size))
    pick = [hstack([np.eye(n + 1), csr_matrix((n + 1, n))]) for _ in moving]
    rows = []
    for t in ang:
        blocks = [zero] * m
        blocks[order[0]], blocks[order[1]] = np.cos(t) * pick[0], np.sin(t) * pick[1]
        rows.append(hstack(blocks))
    keep = np.tile(np.isfinite(caps), POLYGON_SIDES)
    A_ub = vstack(rows).tocsr()[keep]
    b_ub = np.tile(caps * r * POLYGON_INSET, POLYGON_SIDES)[keep]
    box = [np.full(n + 1, np.inf)] * m
    if m == 3:
        box[order[2]] = caps * Z_SHARE
    bounds = []
    for i, k in enumerate(moving):
        vb = np.minimum(v_max[k], box[i])
        bounds += [(-c, c) for c in vb] + [(-a_max[k], a_max[k])] * n
    res = linprog(
        np.zeros(m * size),
        A_ub=A_ub,
        b_ub=b_ub,
        A_eq=block_diag([A_eq] * m).tocsr(),
        b_eq=b_eq,
        bounds=bounds,
        method="highs",
    )
    return res.status == 0


def exact_window(
    points: np.ndarray,
    window: PulseWindow,
    v_max: np.ndarray,
    a_max: np.ndarray,
    guess_ticks: np.ndarray | None = None,
    steps: int = STEPS_PER_GAP,
    tol: float = 1e-8,
    feed_mm_s: float | None = None,
    rapid_mm_s: float | None = None,
    descend: bool = False,
) -> ExactWindow:
    """The reference for ``points`` ``(n, 3)`` mm burned in this order (see the module docstring).

    ``v_max``, ``a_max`` ``(3,)`` the axis limits the motion keeps (finite); ``guess_ticks`` ``(n-1,)`` a
    starting point for the durations (e.g. a planner's), else one period or the velocity bound per gap.
    ``feed_mm_s``/``rapid_mm_s``: the path limits ``bang`` keeps (speed at most the feed at the pulses,
    the rapid everywhere; Euclidean in the program, a polygon inside them in the verifying LP).
    ``descend``: then each gap with idle pulses is offered one period fewer (its longest count), kept
    where the LP still finds a motion — one pass in order, each answer a verified motion.
    """
    ca = import_optional("casadi")
    f, n_min, n_max, idle = window.tick_hz, window.n_min, window.n_max, window.idle_pulses
    pts = np.asarray(points, dtype=np.float64)
    pts = pts - pts[0]
    V, A = np.asarray(v_max, dtype=np.float64), np.asarray(a_max, dtype=np.float64)
    g = pts.shape[0] - 1
    if g < 1:
        raise PlanningError("the exact reference needs at least two points")
    D = np.abs(np.diff(pts, axis=0))
    if guess_ticks is None:
        t_v = np.max(D / V, axis=1) * f
        guess_ticks = snap_up_ticks(np.ceil(np.maximum(2.0 * t_v, n_min)).astype(np.int64), n_min, n_max, idle)[0]
    guess_s = np.asarray(guess_ticks, dtype=np.float64) / f
    big = np.full(g, 1e3)
    caps = {"feed": feed_mm_s, "rapid": rapid_mm_s}
    h = _nlp(ca, pts, np.full(g, n_min / f), big, guess_s, V, A, steps, tol, **caps)
    relaxed_s = float(h.sum())
    m = np.maximum(np.ceil(h * f / n_max - 1e-9), 1).astype(np.int64) if idle else np.ones(g, np.int64)
    try:
        lo, hi = m * n_min / f, m * n_max / f
        h2 = _nlp(ca, pts, lo, hi, np.clip(h, lo, hi), V, A, steps, tol, **caps)
    except PlanningError:  # those period counts admit no motion: round the relaxed durations instead
        h2 = h
    base = np.ceil(h2 * f - 1e-6).astype(np.int64)
    for i in range(200):
        stretch = 1.0 + 1e-3 * i
        ticks, periods = snap_up_ticks(np.ceil(base * stretch).astype(np.int64), n_min, n_max, idle)
        if feasible_ticks(pts, ticks, f, V, A, steps, feed_mm_s, rapid_mm_s):
            if descend and idle:
                ticks = _descend(pts, ticks, window, V, A, steps, feed_mm_s, rapid_mm_s)
                periods = snap_up_ticks(ticks, n_min, n_max, idle)[1]
            return ExactWindow(relaxed_s, ticks, periods, f, stretch)
    raise PlanningError("no feasible rounding of the exact reference's durations within 20 %")


def _descend(pts, ticks, window, V, A, steps, feed_mm_s, rapid_mm_s) -> np.ndarray:
    """One pass over the gaps with idle pulses: one period fewer (at its longest count) where still feasible."""
    ticks = ticks.copy()
    periods = snap_up_ticks(ticks, window.n_min, window.n_max, True)[1]
    for i in np.flatnonzero(periods > 1):
        trial = ticks.copy()
        trial[i] = min(ticks[i] - 1, (periods[i] - 1) * window.n_max)
        if feasible_ticks(pts, trial, window.tick_hz, V, A, steps, feed_mm_s, rapid_mm_s):
            ticks = trial
    return ticks
