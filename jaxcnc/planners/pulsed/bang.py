"""``bang``: constant-acceleration pieces between pulses, knot speeds by interval propagation.

``sync`` passes one C² spline through the points: the smoothest motion (least ``∫a²``), not the one with
the least peak acceleration, so at a row change (the x axis reverses, y steps 125 µm) and across jumps it
needs about three extra periods. Here each gap is two halves of constant acceleration per axis (three
phases, ¼ ½ ¼, accelerate / cruise / decelerate, on jumps long enough to reach the cap) between the point
positions and *free* knot speeds; every limit on a gap is then *linear* in its pair of knot speeds
(:func:`_rows`): a convex polygon, whose projection (:func:`project`) maps an interval of entry speeds to
the interval of reachable exit speeds, per axis, in closed form.

Durations are chosen by greedy sweeps (``lax.scan`` s over the gaps, nothing sampled):

1. A forward sweep over a few candidates per gap (:func:`candidates`) gives each gap the shortest whose exit
   interval meets the most look-ahead sets (:func:`ahead_sets`: the speeds from which the next 1..
   :data:`LOOKAHEAD` gaps pass at their shortest; all depths up to the deepest any candidate meets).
2. Up to :data:`PASSES` sweeps, alternately backward and forward, each against the previous durations: the
   speeds from which the rest of the job can still be completed are those reachable from the far end's
   rest with the previous durations (a :func:`reachable` scan the other way, time reversed), so a sweep
   takes each gap's shortest candidate (:func:`near_candidates`) whose exit interval meets that set — it
   never boxes itself in, the previous duration is always a candidate, and the total never grows. A stage
   ends after a sweep gaining less than :data:`MIN_GAIN`.
3. A backward scan picks each knot's speed inside the last sweep's intervals (nearest the mean of its
   neighbours' mean speeds), turned to the forward direction where that sweep ran backward.

Speed caps (path speed, Euclidean, made linear as a per-axis box whose diagonal is the cap,
:func:`path_caps`): at a pulse the beam burns, so the path speed there is within the feed; between pulses
the beam is dark, so the rapid applies, shared among the axes by the gap's direction; every axis within
its ``v_max``. The knot boxes start at ``feed/√3`` per axis; after the sweeps they are turned towards the
planned velocities (:func:`recap`: each box still contains its knot's velocity, the slack goes along the
direction of travel), and :data:`RECAP_PASSES` more sweeps run against the plan — never longer.
The speed is piecewise linear in time, so these hold on the whole gap.

4. The polish (:mod:`.polish`): windows of five gaps around each gap above its shortest period count re-timed
   jointly between pinned knot velocities — a jump one to three periods shorter or a few ticks per period
   shorter in its count, its neighbours a little or a period longer, a cruising jump's ramp fraction ``q``,
   and every two-phase gap of the window in the *lens* (:func:`lens_project`: the exact set of end speeds of
   every motion with ``|a| <= A``, of which the ½–½ polygon is the inscribed rhombus; each axis then switches
   at its own instant, :func:`lens_profile`); a second round near the first's changes; then windows with two
   centres (two jumps shortened together while the gap between them takes an idle pulse).

The axes' accelerations step at the knots, so a machine with a jerk limit is planned with ``sync`` instead;
the first point is reached from rest (a straight move from the start) and the last is left at rest.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size
from jaxcnc.planners.pulsed.request import PulsePlan, PulseRequest, register_pulse_planner
from jaxcnc.planners.pulsed.stop_and_go import rest_to_rest
from jaxcnc.planners.pulsed.trajectory import Trajectory, move_pieces, rest_pieces
from jaxcnc.planners.pulsed.windows import PulseWindow, snap_up_ticks

#: The first sweep's candidates per gap, in ticks per period of the shortest range (``m0`` periods, from the
#: shortest admissible count), then fractions of the next range, the ends of four more, and geometric steps.
FIRST_STEPS = (0, 2, 4, 8, 14, 24)
NEXT_FRACTIONS = (0.0, 0.25, 0.5, 1.0)
LATER_RANGES = (2, 4, 6, 8)
GEOMETRIC = (1, 5)


def candidates(lo: np.ndarray, window: PulseWindow) -> np.ndarray:
    """The first sweep's admissible tick counts ``(g, C)`` at or above ``lo`` ``(g,)``, ascending per row."""
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    first, m0 = snap_up_ticks(np.asarray(lo, np.int64), n_min, n_max, idle)
    if not idle:  # one period: every other tick of the window
        steps = np.arange(0, n_max - n_min + 2, 2)
        return np.minimum(first[:, None] + steps[None], np.maximum(n_max, first[:, None]))
    m0 = m0[:, None]
    cols = [np.minimum(first[:, None] + np.array(FIRST_STEPS)[None] * m0, m0 * n_max)]
    m = m0 + 1
    cols.append(np.round(m * n_min + np.array(NEXT_FRACTIONS)[None] * m * (n_max - n_min)).astype(np.int64))
    cols.append((m0 + np.array(LATER_RANGES)[None]) * n_max)
    top = (m0[:, 0] + LATER_RANGES[-1] + 1) * n_max
    for r in GEOMETRIC:
        cols.append(snap_up_ticks(np.ceil(top * 1.3**r).astype(np.int64), n_min, n_max, idle)[0][:, None])
    out = np.maximum(np.concatenate(cols, axis=1), first[:, None])  # long jumps: the period ranges overlap
    tangled = np.flatnonzero(np.any(np.diff(out, axis=1) < 0, axis=1))
    out[tangled] = np.sort(out[tangled], axis=1)
    return out


#: Candidates of a sweep against a plan (:func:`near_candidates`): steps below the plan's count, in ticks per
#: period, within the first two period ranges and beyond.
FINE_STEP, COARSE_STEP = 2, 6
PREV_STEPS = (5, 4, 3, 2, 1)


def near_candidates(first: np.ndarray, prev: np.ndarray, window: PulseWindow) -> np.ndarray:
    """Admissible tick counts ``(g, 8)`` from ``first`` (the shortest) up to ``prev``, ascending per row.

    The plan's own count ``prev`` (``m`` periods), a few below it in its range (``prev − k s m`` for ``k`` in
    :data:`PREV_STEPS`, ``s`` = :data:`FINE_STEP` in the first two ranges above ``first``, else
    :data:`COARSE_STEP`; at least ``m n_min``), the longest count with one period fewer ``(m − 1) n_max``, and
    ``first``; each at least ``first``.
    """
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    m0 = snap_up_ticks(first, n_min, n_max, idle)[1]
    m = snap_up_ticks(prev, n_min, n_max, idle)[1]
    step = np.where(m <= m0 + 1, FINE_STEP, COARSE_STEP) * m
    floor = np.maximum(first, m * n_min)
    cols = [first, np.maximum(first, np.where(m > 1, (m - 1) * n_max, first))]
    cols += [np.maximum(floor, prev - k * step) for k in PREV_STEPS]
    cols.append(prev)
    return np.sort(np.minimum(np.stack(cols, axis=1), prev[:, None]), axis=1)


def phase_fraction(cruise, xp=jnp):
    """Each gap's ramp fraction ``q``: ``cruise`` boolean (¼ cruising, else ½: two halves) or ``q`` itself."""
    cruise = xp.asarray(cruise)
    if cruise.dtype == bool:
        return xp.where(cruise, 0.25, 0.5)
    return cruise  # a ramp fraction in (0, ½], or LENS_Q


def _coefficients(m, h, A, cap_mid, cruise, xp=jnp):
    """``(p, c, e, w)`` of a gap whose phases are ``q``, ``1 − 2q``, ``q`` of it (``q`` from ``cruise``).

    The middle speed ``v_c = (m − q (v0 + v1)/2)/(1 − q)``; ``|v_c − v0| <= A q h`` and ``|v1 − v_c| <= A q h``
    read ``|c − p v0 − v1| <= e`` and ``|c − v0 − p v1| <= e``, ``|v_c| <= cap`` reads ``|c − v0 − v1| <= w``,
    with ``p = 2/q − 1``, ``c = (p + 1) m``, ``e = 2 (1 − q) A h``, ``w = (p − 1) cap`` (``q = ½``: ``3, 4m,
    A h, 2 cap``; ``q = ¼``: ``7, 8m, 1.5 A h, 6 cap``).
    """
    q = phase_fraction(cruise, xp)
    p = 2.0 / q - 1.0
    return p, (p + 1.0) * m, 2.0 * (1.0 - q) * A * h, (p - 1.0) * cap_mid


def _rows(D, h, A, cap_mid, cap_knot, cruise, xp=jnp):
    """The gap's linear conditions ``l <= α v0 + β v1 <= u``: four rows, last axis ``(..., 4)``.

    Two phases (``cruise`` false; halves at ``a1``, ``a2``): ``a1 h = 4m − 3v0 − v1``, ``a2 h = −4m + v0 + 3v1``,
    mid speed ``2m − (v0 + v1)/2`` (``m = D/h``). Three (quarter at ``a1``, half cruising at ``v_c``, quarter
    at ``a3``): ``v_c = 4m/3 − (v0 + v1)/6``, ``a1 h/4 = v_c − v0``, ``a3 h/4 = v1 − v_c``. The speed is
    piecewise linear, so its extremes are at the knots (``|v1| <= cap_knot``, the last row) and the middle
    (``|v_c| <= cap_mid``).
    """
    m = D / h
    one = xp.ones_like(m)
    p, c, acc, vel = _coefficients(m, h, A, cap_mid, cruise, xp)
    p = p * one
    alpha = xp.stack([p, one, one, 0.0 * one], axis=-1)
    beta = xp.stack([one, p, one, one], axis=-1)
    lo = xp.stack([c - acc, c - acc, c - vel, -cap_knot * one], axis=-1)
    hi = xp.stack([c + acc, c + acc, c + vel, cap_knot * one], axis=-1)
    return alpha, beta, lo, hi


#: The ramp fraction that marks a gap moving in the lens of every two-phase motion (:func:`lens_project`)
#: instead of a polygon; the polish (:mod:`.polish`) gives it to the gaps of its windows, the sweeps keep the
#: polygons (booleans: ``q`` ¼ or ½).
LENS_Q = 1.0


def is_lens(cruise, xp=jnp):
    """Whether each gap moves in the lens model: ``q`` (:func:`phase_fraction`) is :data:`LENS_Q`."""
    return phase_fraction(cruise, xp) > 0.5


def project(lo0, hi0, D, h, A, cap_mid, cap_knot, cruise, xp=jnp):
    """Speeds ``v1`` reachable from ``v0 ∈ [lo0, hi0]`` over a gap: ``(ok, L, U)``, broadcast.

    Gaps marked :data:`LENS_Q` in the lens of every two-phase motion (:func:`lens_project`), the others in
    their polygon of phases ``q, 1 − 2q, q`` (:func:`polygon_project`); both closed form. ``cruise`` boolean
    (the sweeps): polygons only; else both computed where both occur (no branch).
    """
    if xp.asarray(cruise).dtype == bool:  # the sweeps: polygons only
        return polygon_project(lo0, hi0, D, h, A, cap_mid, cap_knot, cruise, xp)
    use = is_lens(cruise, xp)
    if xp is np and np.all(use):  # NumPy callers with lens gaps only (the polish): one model to compute
        return lens_project(lo0, hi0, D, h, A, cap_mid, cap_knot, xp)
    poly = polygon_project(lo0, hi0, D, h, A, cap_mid, cap_knot, xp.where(use, 0.5, cruise), xp)
    if xp is np and not np.any(use):
        return poly
    lens = lens_project(lo0, hi0, D, h, A, cap_mid, cap_knot, xp)
    return tuple(xp.where(use, a, b) for a, b in zip(lens, poly, strict=True))


def _lens_bounds(x, m, E, xp):
    """The lens' exit speeds from entry ``x``: ``(y_lo(x), y_hi(x))``, both non-increasing in ``x``."""
    u = 4.0 * E * (x - m)
    two = 2.0 * E * E
    return x + E - xp.sqrt(xp.maximum(0.0, two + u)), x - E + xp.sqrt(xp.maximum(0.0, two - u))


def lens_project(lo0, hi0, D, h, A, cap_mid, cap_knot, xp=jnp):
    """Speeds ``v1`` reachable from ``v0 ∈ [lo0, hi0]`` over a gap with *any* two-phase motion: ``(ok, L, U)``.

    With ``|a| <= A`` the pairs ``(x, y) = (v0, v1)`` that cover ``D`` in ``h`` form a convex lens:
    ``|(x + y)/2 − m| <= E/4 − (y − x)²/(4E)`` (``m = D/h``, ``E = A h``; the farthest and nearest motions
    are tents), realised by two phases of accelerations ``±a``, ``a <= A`` (:func:`lens_profile`); its
    peak is at most ``2m − min(x, y)`` and its valley at least ``2m − max(x, y)``, so ``|2m − x| <= W`` and
    ``|2m − y| <= W`` with ``|x|, |y| <= W`` keep each axis within ``W = cap_mid`` all along (the axes switch
    at different instants, so unlike the common-phase polygons the box must hold at the knots too), and
    ``|y| <= K``. The ½–½ polygon of
    :func:`_rows` is this lens' inscribed rhombus (a third less area): the lens lets a row gap shed or
    gain more speed. For ``x ∈ [m − E/2, m + E/2]`` the exit speeds are ``[y_lo(x), y_hi(x)]``
    (:func:`_lens_bounds`, both non-increasing); the lens is symmetric in ``x ↔ y``, so the entries that
    reach an exit interval ``[Y0, Y1]`` are ``[y_lo(Y1), y_hi(Y0)]``: closed form, like :func:`project`.
    """
    m = D / h
    E = A * h
    W, K = cap_mid, cap_knot
    dlo, dhi = m - 0.5 * E, m + 0.5 * E
    Ylo = xp.maximum(xp.maximum(-xp.minimum(K, W), 2.0 * m - W), dlo)
    Yhi = xp.minimum(xp.minimum(xp.minimum(K, W), 2.0 * m + W), dhi)
    a = xp.maximum(xp.maximum(lo0, _lens_bounds(Yhi, m, E, xp)[0]), xp.maximum(xp.maximum(2.0 * m, 0.0) - W, dlo))
    b = xp.minimum(xp.minimum(hi0, _lens_bounds(Ylo, m, E, xp)[1]), xp.minimum(xp.minimum(2.0 * m, 0.0) + W, dhi))
    tol = 1e-12 * (1 + xp.abs(b))
    ok = (a <= b + tol) & (Ylo <= Yhi + tol)
    b = xp.maximum(a, b)
    U = xp.minimum(_lens_bounds(a, m, E, xp)[1], Yhi)
    L = xp.maximum(_lens_bounds(b, m, E, xp)[0], Ylo)
    return ok & (L <= U + 1e-12 * (1 + xp.abs(U))), L, xp.maximum(L, U)


def lens_profile(v0, v1, D, h):
    """The two-phase motion of a lens point: ``(t_s, a1, a2)`` (switch time, accelerations ``±a``), NumPy.

    ``e = m − (v0 + v1)/2``, ``δ = v1 − v0``: ``a h = 2|e| + √(4e² + δ²)``, a tent (``+a`` then ``−a``,
    ``t_s = (h + δ/a)/2``) where ``e >= 0``, else a valley (``t_s = (h − δ/a)/2``); ``a <= A`` inside the lens.
    """
    e = D / h - 0.5 * (v0 + v1)
    d = v1 - v0
    ah = 2.0 * np.abs(e) + np.sqrt(4.0 * e * e + d * d)
    s = np.where(e >= 0.0, 1.0, -1.0)
    a = ah / h
    safe = ah > 1e-12
    ts = np.where(safe, 0.5 * (h + s * d * h / np.where(safe, ah, 1.0)), 0.5 * h)
    return np.clip(ts, 0.0, h), s * a, -s * a


def polygon_project(lo0, hi0, D, h, A, cap_mid, cap_knot, cruise, xp=jnp):
    """Speeds ``v1`` reachable from ``v0 ∈ [lo0, hi0]`` over a gap of phases ``q, 1 − 2q, q``: ``(ok, L, U)``.

    The rows of :func:`_rows` are ``c − e <= p x + y <= c + e``, ``c − e <= x + p y <= c + e``,
    ``c − w <= x + y <= c + w``, ``|y| <= K`` (``x = v0``, ``y = v1``; ``p = 3``, ``c = 4m``, ``e = A h``,
    ``w = 2 cap_mid``, or cruising ``p = 7``, ``c = 8m``, ``e = 1.5 A h``, ``w = 6 cap_mid``; ``K =
    cap_knot``). Upper limits on ``y`` are ``u_i(x)`` and lower ones ``l_j(x)``, all non-increasing in
    ``x``; ``x`` is feasible where every ``u_i(x) >= l_j(x)``: twelve linear conditions, six bounding ``x``
    below and six above (written out below, closed form, no pairwise tensor). Over the feasible ``[a, b]``
    the largest ``y`` is ``min_i u_i(a)``, the smallest ``max_j l_j(b)``. ``xp``: ``jax.numpy`` (in the
    scans) or ``numpy``.
    """
    p, c, e, w = _coefficients(D / h, h, A, cap_mid, cruise, xp)
    K = cap_knot
    hi_, lo_ = c + e, c - e
    q = p * p - 1.0
    lower = [
        (p * lo_ - hi_) / q,
        (p * (c - w) - hi_) / (p - 1.0),
        -(e + w) / (p - 1.0),
        (lo_ - K) / p,
        lo_ - p * K,
        c - w - K,
    ]
    upper = [
        (p * hi_ - lo_) / q,
        (e + w) / (p - 1.0),
        (hi_ + K) / p,
        hi_ + p * K,
        (p * (c + w) - lo_) / (p - 1.0),
        c + w + K,
    ]
    a, b = lo0, hi0
    for x in lower:
        a = xp.maximum(a, x)
    for x in upper:
        b = xp.minimum(b, x)
    ok = a <= b + 1e-12 * (1 + xp.abs(b))
    b = xp.maximum(a, b)
    U = xp.minimum(xp.minimum(hi_ - p * a, (hi_ - a) / p), xp.minimum(c + w - a, K))
    L = xp.maximum(xp.maximum(lo_ - p * b, (lo_ - b) / p), xp.maximum(c - w - b, -K))
    return ok & (L <= U + 1e-12 * (1 + xp.abs(U))), L, xp.maximum(L, U)


#: Look-ahead depths of the first sweep (:func:`ahead_sets`): candidates are ranked by how many they meet.
LOOKAHEAD = 4
#: Passes after the first: each scans the other way and keeps every gap at most as long as before.
PASSES = 1
#: Tolerance on interval overlaps (mm/s).
EPS_MM_S = 1e-9


#: XLA options for the sweeps: LLVM's optimisation level 1 compiles in ~3/4 of the time, runs as fast.
COMPILER_OPTIONS = {"xla_backend_optimization_level": 1}


@partial(jax.jit, compiler_options=COMPILER_OPTIONS)
def forward(D, cand, cruise, capm, capk, blo, bhi, slo, shi, A, tick_hz):
    """Forward scan over gaps: ``D`` ``(g, 3)``, ``cand`` ``(g, C)`` ticks, ``cruise`` ``(g,)``.

    ``capm`` ``(g, 3)`` caps each gap's mid speed, ``capk`` ``(g+1, 3)`` each knot's speed; ``blo``, ``bhi``
    ``(g+1, 3)``: the speeds at each knot from which the rest can still be completed (the last knot: rest);
    ``slo``, ``shi`` ``(g+1, K, 3)``: those from which the next ``1..K`` gaps can be passed at their shortest
    candidates (the look-ahead, :func:`ahead_sets`). ``cand`` is a few candidates per gap (ascending; all
    are tried). Each gap takes its shortest candidate whose reachable
    exit speeds, within ``[blo, bhi]``, meet the sets on every axis for the most look-ahead depths (``1..k``
    all met, ``k`` as large as any candidate reaches); else its shortest candidate that fits itself; else its
    longest. Returns ``(ticks (g,), lo (g+1, 3), hi (g+1, 3), ok (g,))``: the chosen tick counts,
    the reachable (and completable) speed interval at every knot (knot 0 at rest), and whether a candidate
    met the sets.
    """

    depth = slo.shape[1]

    def choose(lo0, hi0, x, c):
        """The best candidate among ``c`` ``(C,)``: ``(level, tick, L, U)``."""
        d, _, cr, cm, ck, bl, bh, sl, sh = x
        h = c.astype(jnp.float64)[:, None] / tick_hz  # (C, 1)
        ok, L, U = project(lo0[None], hi0[None], d[None], h, A[None], cm[None], ck[None], cr)  # (C, 3)
        L, U = jnp.maximum(L, bl[None]), jnp.minimum(U, bh[None])
        fit = jnp.all(ok, axis=1)
        meets = [fit & jnp.all(L <= U + EPS_MM_S, axis=1)]
        for k in range(depth):
            meet = jnp.maximum(L, sl[k][None]) <= jnp.minimum(U, sh[k][None]) + EPS_MM_S
            meets.append(meets[-1] & jnp.all(meet, axis=1))
        level = fit.astype(jnp.int32) + sum(m.astype(jnp.int32) for m in meets)
        k = jnp.where(jnp.max(level) > 0, jnp.argmax(level), c.shape[0] - 1)
        return level[k].astype(jnp.int32), c[k], L[k], jnp.maximum(L[k], U[k])

    def step(state, x):
        lo0, hi0 = state
        # every candidate at once, no branch: a taken ``lax.cond`` branch costs ~0.1 ms on a CPU, so a search
        # only where the shortest fails was slower than a few well-spread candidates for every gap
        level, tick, L, U = choose(lo0, hi0, x, x[1])
        return (L, U), (tick, L, U, level >= 2)

    z = jnp.zeros(D.shape[1])
    xs = (D, cand, cruise, capm, capk[1:], blo[1:], bhi[1:], slo[1:], shi[1:])
    _, (ticks, L, U, ok) = jax.lax.scan(step, (z, z), xs)
    return ticks, jnp.concatenate([z[None], L]), jnp.concatenate([z[None], U]), ok


#: An empty speed interval is ``[EMPTY_MM_S, -EMPTY_MM_S]`` (finite: no ``0 · inf`` in the rows).
EMPTY_MM_S = 1e30


def ahead_sets(D, ticks, cruise, capm, capk, blo, bhi, A, tick_hz, depth):
    """Speeds at each knot ``(g+1, depth, 3)`` (lo, hi) from which the next ``1..depth`` gaps pass in ``ticks``.

    Knot ``i``'s set is the backward projection of knot ``i+1``'s through gap ``i`` (time reversed: the
    forward :func:`project` of the negated speeds over ``−D``), within ``[blo, bhi]`` and the knot's cap;
    ``depth`` rounds, each vectorised over all knots at once (NumPy: no scan, nothing to compile). An empty
    set is ``[EMPTY_MM_S, −EMPTY_MM_S]``. Whether a gap's exit interval meets the set is whether the next
    ``depth`` gaps can follow at those durations: the forward sweep's look-ahead without stepping through them.
    """
    h = (np.asarray(ticks, np.float64) / tick_hz)[:, None]
    lo0, hi0 = np.maximum(blo, -capk), np.minimum(bhi, capk)
    lo, hi = lo0, hi0
    los, his = [], []
    for _ in range(depth):
        ok, L, U = project(-hi[1:], -lo[1:], -D, h, A, capm, capk[:-1], cruise[:, None], xp=np)
        nlo, nhi = np.maximum(-U, lo0[:-1]), np.minimum(-L, hi0[:-1])
        empty = ~ok | (nlo > nhi + EPS_MM_S)
        nlo, nhi = np.where(empty, EMPTY_MM_S, nlo), np.where(empty, -EMPTY_MM_S, nhi)
        lo, hi = np.concatenate([nlo, lo0[-1:]]), np.concatenate([nhi, hi0[-1:]])
        los.append(lo)
        his.append(hi)
    return np.stack(los, axis=1), np.stack(his, axis=1)


@partial(jax.jit, compiler_options=COMPILER_OPTIONS)
def reachable(D, ticks, cruise, capm, capk, A, tick_hz):
    """Speeds reachable from rest at every knot ``(g+1, 3)`` (lo, hi) with the tick counts fixed; and ``ok``."""

    def step(state, x):
        lo0, hi0 = state
        d, t, cr, cm, ck = x
        ok, L, U = project(lo0, hi0, d, t.astype(jnp.float64) / tick_hz, A, cm, ck, cr)
        return (L, U), (L, U, jnp.all(ok))

    z = jnp.zeros(D.shape[1])
    _, (L, U, ok) = jax.lax.scan(step, (z, z), (D, ticks, cruise, capm, capk[1:]))
    return jnp.concatenate([z[None], L]), jnp.concatenate([z[None], U]), ok


@partial(jax.jit, compiler_options=COMPILER_OPTIONS)
def backward(D, ticks, cruise, capm, capk, lo, hi, A, tick_hz):
    """Backward scan: each knot's speed ``(g+1, 3)`` inside its interval and fitting the gap after it."""
    h = ticks.astype(jnp.float64)[:, None] / tick_hz
    mean = D / h
    pref = jnp.concatenate([jnp.zeros((1, D.shape[1])), 0.5 * (mean[:-1] + mean[1:]), jnp.zeros((1, D.shape[1]))])

    def step(v1, x):
        d, hh, cr, cm, ck, l0, h0, p = x
        alpha, beta, l, u = _rows(d, hh, A, cm, ck, cr)
        lo_v0 = jnp.max((l[:, :3] - beta[:, :3] * v1[:, None]) / alpha[:, :3], axis=1)
        hi_v0 = jnp.min((u[:, :3] - beta[:, :3] * v1[:, None]) / alpha[:, :3], axis=1)
        if cr.dtype != bool:  # the lens is symmetric in (v0, v1): the entries that reach v1 are [y_lo(v1), y_hi(v1)]
            m, E = d / hh, A * hh
            ylo, yhi = _lens_bounds(v1, m, E, jnp)
            ylo = jnp.maximum(ylo, jnp.maximum(jnp.maximum(2.0 * m, 0.0) - cm, m - 0.5 * E))
            yhi = jnp.minimum(yhi, jnp.minimum(jnp.minimum(2.0 * m, 0.0) + cm, m + 0.5 * E))
            use = is_lens(cr)
            lo_v0, hi_v0 = jnp.where(use, ylo, lo_v0), jnp.where(use, yhi, hi_v0)
        a, b = jnp.maximum(l0, lo_v0), jnp.minimum(h0, hi_v0)
        v0 = jnp.clip(p, a, jnp.maximum(a, b))
        return v0, v0

    v_end = jnp.clip(pref[-1], lo[-1], hi[-1])
    xs = (D, h, cruise, capm, capk[1:], lo[:-1], hi[:-1], pref[:-1])
    _, v = jax.lax.scan(step, v_end, xs, reverse=True)
    return jnp.concatenate([v, v_end[None]])


#: Floor on an axis' share of a path-speed cap (see :func:`path_caps`).
CAP_FLOOR = 0.05


def path_caps(direction: np.ndarray, path_mm_s: float, v_max: np.ndarray, floor: float = CAP_FLOOR) -> np.ndarray:
    """Per-axis speed caps ``(k, 3)`` whose box keeps the path speed within ``path_mm_s``.

    ``direction`` ``(k, 3)`` (any length): each axis gets the share ``w_i = sqrt((u_i² + δ)/(1 + n δ))`` of
    the cap (``u`` the unit direction, ``δ`` = :data:`CAP_FLOOR`, ``n`` axes), so ``Σ w_i² = 1`` and any
    velocity inside the box ``|v_i| <= w_i path`` has a path speed ``<= path``; each axis also ``<= v_max``.
    """
    n = direction.shape[1]
    norm = np.linalg.norm(direction, axis=1, keepdims=True)
    u2 = np.where(norm > 0, direction / np.where(norm > 0, norm, 1.0), 1.0 / np.sqrt(n)) ** 2
    w = np.sqrt((u2 + floor) / (1.0 + n * floor))
    return np.minimum(w * path_mm_s, v_max[None])


def knot_directions(D: np.ndarray, h_s: np.ndarray) -> np.ndarray:
    """Direction of travel through each knot ``(g+1, 3)``: the sum of the mean velocities of its two gaps.

    ``D`` ``(g, 3)`` the gaps' displacements, ``h_s`` ``(g,)`` an estimate of their durations (the
    velocity-bound ones). The end knots take their one gap's direction. Any direction gives a valid cap
    (:func:`path_caps`); this one is where the beam is heading as it passes the point.
    """
    mean = D / h_s[:, None]
    return np.concatenate([mean[:1], mean[:-1] + mean[1:], mean[-1:]])


def _pad(a: np.ndarray, size: int, fill) -> np.ndarray:
    out = np.empty((size,) + a.shape[1:], a.dtype)
    out[: a.shape[0]] = a
    out[a.shape[0] :] = fill
    return out


class _Gaps:
    """The gaps' data in one direction of travel (reversed: the points backwards, speeds negated), padded."""

    def __init__(self, D, cruise, capm, capk, size, reverse):
        if reverse:
            D, cruise, capm, capk = -D[::-1], cruise[::-1], capm[::-1], capk[::-1]
        self.g, self.size, self.reverse = D.shape[0], size, reverse
        self.D = _pad(D, size, 0.0)
        self.cruise = _pad(cruise, size, False)
        self.capm = _pad(capm, size, 1.0)
        self.capk = _pad(capk, size + 1, 1.0)

    def orient(self, a: np.ndarray, fill) -> np.ndarray:
        """Per-gap (or per-knot) array in this direction, padded."""
        return _pad(a[::-1] if self.reverse else a, self.size + (a.shape[0] - self.g), fill)

    def pick(self, ticks: np.ndarray, lo: np.ndarray, hi: np.ndarray, A, f) -> np.ndarray:
        """Knot velocities ``(g+1, 3)`` in this direction (:func:`backward`, padded: the padding's knots at rest)."""
        g, size = self.g, self.size
        args = (self.D, self.orient(ticks, 1), self.cruise, self.capm, self.capk)
        v = backward(*args, _pad(lo, size + 1, 0.0), _pad(hi, size + 1, 0.0), A, f)
        return np.asarray(v)[: g + 1]

    def reachable(self, ticks: np.ndarray, A, f):
        """``(lo, hi, ok)``: the speeds reachable from rest at each knot, in this direction (unpadded)."""
        lo, hi, ok = reachable(self.D, self.orient(ticks, 1), self.cruise, self.capm, self.capk, A, f)
        g = self.g
        return np.array(lo)[: g + 1], np.array(hi)[: g + 1], bool(np.all(np.asarray(ok)[:g]))


def _sweep(gaps: _Gaps, other: _Gaps, cand, prev, A, f, window: PulseWindow, lookahead=0, ready=None):
    """One greedy sweep in ``gaps``' direction; with ``prev`` ticks, every gap at most as long as in ``prev``.

    The speeds from which the rest can be completed are those reachable, the other way, from the far
    end's rest with ``prev``'s durations: the sweep never boxes itself in, and ``prev`` is always a choice.
    Without ``prev``, each gap looks ``lookahead`` gaps ahead (:func:`ahead_sets`). ``ready``: a compile of the
    sweep's program under way in a thread, waited for rather than compiled twice.
    """
    g, size = gaps.g, gaps.size
    if prev is None:
        blo = np.full((g + 1, 3), -np.inf)
        bhi = np.full((g + 1, 3), np.inf)
        blo[-1] = bhi[-1] = 0.0
        c = cand
    else:
        lo, hi, _ = other.reachable(prev, A, f)  # in the other direction: negate and reverse
        blo, bhi = -hi[::-1], -lo[::-1]
        # prev is always good (every speed in the state is completable with it): the shortest few up to it
        c = near_candidates(cand[:, 0], prev, window)
    c = gaps.orient(c, window.n_min)
    knots = (_pad(blo, size + 1, 0.0), _pad(bhi, size + 1, 0.0))
    if prev is None:
        ahead = ahead_sets(gaps.D, c[:, 0], gaps.cruise, gaps.capm, gaps.capk, *knots, A, f, max(lookahead, 1))
    else:
        ahead = tuple(k[:, None] for k in knots)
    if ready is not None:
        ready.result()
    ticks, lo, hi, ok = forward(gaps.D, c, gaps.cruise, gaps.capm, gaps.capk, *knots, *ahead, A, f)
    ticks = np.asarray(ticks, np.int64)[:g]
    lo, hi = np.array(lo)[: g + 1], np.array(hi)[: g + 1]
    return (ticks[::-1] if gaps.reverse else ticks), bool(np.all(np.asarray(ok)[:g])), lo, hi


def _improve(gaps: _Gaps, other: _Gaps, cand, tried, A, f, window: PulseWindow, passes, v=None):
    """``passes`` sweeps against ``tried[-1]``, alternating direction (the first in ``other``'s direction),
    until one gains less than :data:`MIN_GAIN`; then the knot velocities (:meth:`_Gaps.pick`).

    The last sweep's own intervals serve the pick: reachable along its direction, the far knot at rest (every
    gap met its completable set). Returns ``(ticks, v (g+1, 3), tried)``; with no sweep shorter, ``v`` as
    given (or, without one, picked from a :func:`reachable` check); ``None`` when no durations check out.
    """
    ticks, last = tried[-1], None
    for p in range(passes):
        one, two = (other, gaps) if p % 2 == 0 else (gaps, other)
        new, good, lo, hi = _sweep(one, two, cand, ticks, A, f, window)
        if not good or new.sum() >= ticks.sum():
            break
        gain = 1.0 - new.sum() / ticks.sum()
        ticks = new  # never longer than the plan's: its count is the last candidate
        tried = [*tried, ticks]
        last = (one, lo, hi)
        if gain < MIN_GAIN:  # another sweep would gain less still
            break
    if last is not None:
        one, lo, hi = last
        lo[-1] = hi[-1] = 0.0
        w = one.pick(ticks, lo, hi, A, f)
        return ticks, (-w[::-1] if one.reverse else w), tried
    if v is not None:
        return ticks, v, tried
    fwd = gaps if not gaps.reverse else other
    for ticks in tried[::-1]:  # the shortest whose speeds check out (the last, barring a rounding slip)
        lo, hi, ok = fwd.reachable(ticks, A, f)
        if ok and np.all(lo[-1] <= EPS_MM_S) and np.all(hi[-1] >= -EPS_MM_S):
            lo[-1] = hi[-1] = 0.0
            return ticks, fwd.pick(ticks, lo, hi, A, f), tried
    return None


#: A sweep that shortens the total by less than this fraction is the last of its stage.
MIN_GAIN = 1e-4
#: Rounds of knot boxes turned towards the planned velocities, and the sweeps against each.
RECAPS = 1
RECAP_PASSES = 2
#: The recap stage runs when the main stage's last sweep shortened the total by at least this fraction.
RECAP_GAIN = 3e-3


def recap(v: np.ndarray, direction: np.ndarray, path_mm_s: float, v_max: np.ndarray) -> np.ndarray:
    """Knot boxes ``(g+1, 3)`` that contain the planned knot velocities ``v`` and keep the path within the cap.

    Each axis gets ``w_i² = v_i²/F² + s u_i²`` (``F`` the cap, ``u`` the unit ``direction``, ``s = 1 −
    |v|²/F²`` the unused share): ``Σ w_i² = |v|²/F² + s = 1``, so any velocity in the box ``|x_i| <= w_i F``
    has ``|x|² <= Σ w_i² F² = F²`` — the path speed within the cap — and ``|v_i| <= w_i F``: the plan the
    velocities come from stays feasible, so sweeps against it never lengthen it. The slack goes along the
    direction of travel. (``|v| <= F`` holds since ``v`` lies in a box of the same kind; rounding is clipped.)
    """
    r2 = (v / path_mm_s) ** 2
    used = r2.sum(axis=1, keepdims=True)
    r2 = r2 / np.maximum(used, 1.0)
    norm = np.linalg.norm(direction, axis=1, keepdims=True)
    n = direction.shape[1]
    u2 = np.where(norm > 0, direction / np.where(norm > 0, norm, 1.0), 1.0 / np.sqrt(n)) ** 2
    w2 = r2 + np.maximum(0.0, 1.0 - r2.sum(axis=1, keepdims=True)) * u2
    return np.minimum(np.sqrt(w2) * path_mm_s, v_max[None])


#: Rounds of :func:`~.polish.polish` (windows re-timed jointly between pinned knot velocities) after the sweeps.
POLISH_ROUNDS = 2

_COMPILER = ThreadPoolExecutor(max_workers=2, thread_name_prefix="bang-compile")


def _precompile(size: int, n_first: int, A: np.ndarray, f: float) -> list[Future]:
    """Compile the sweeps' programs for ``size`` gaps (``n_first`` candidates in the first) in threads.

    XLA compiles outside the GIL, so on a machine with two cores this hides most of the compile time (a
    fresh process compiles four programs) behind the first sweep's preparation and run; a program already
    compiled (or in the persistent cache) costs a lookup. The first future is the first sweep's program.
    """

    def spec(shape, dtype):
        return jax.ShapeDtypeStruct(shape, np.dtype(dtype))

    n = A.shape[0]
    gaps = (spec((size, n), "f8"), None, spec((size,), bool), spec((size, n), "f8"), spec((size + 1, n), "f8"))
    knots = spec((size + 1, n), "f8")
    sets = spec((size + 1, 1, n), "f8")
    ticks = spec((size,), "i8")
    near = spec((size, 2 + len(PREV_STEPS) + 1), "i8")
    jobs = [
        (
            forward,
            (
                gaps[0],
                spec((size, n_first), "i8"),
                *gaps[2:],
                knots,
                knots,
                *[spec((size + 1, LOOKAHEAD, n), "f8")] * 2,
                A,
                f,
            ),
        ),
        (forward, (gaps[0], near, *gaps[2:], knots, knots, sets, sets, A, f)),
        (reachable, (gaps[0], ticks, *gaps[2:], A, f)),
        (backward, (gaps[0], ticks, *gaps[2:], knots, knots, A, f)),
    ]
    device = jax.config.jax_default_device  # the caller's (planning_scope): threads do not inherit it

    def compile_one(fn, args):
        with jax.default_device(device):
            return fn.lower(*args).compile()

    return [_COMPILER.submit(compile_one, fn, args) for fn, args in jobs]


def gap_pieces(pts, D, ticks, v, cruise, work, f):
    """The gaps' motion as pieces: ``(starts (p,) ticks, coeffs (p, 4, 3))``, in time order.

    A polygon gap (``q <= ½``) has three pieces, switching at ``q h`` and ``(1 − q) h`` on every axis, the
    cruise at ``v_c = (m − q (v0 + v1)/2)/(1 − q)`` (the middle one of zero length at ``q = ½``). A lens gap
    (:data:`LENS_Q`) switches each axis at its own ``t_s`` (:func:`lens_profile`): pieces from ``0`` and
    the three sorted switch instants (:func:`_lens_pieces`). Each piece's coefficients are every axis'
    position, velocity and half acceleration at its start. ``work`` ``(g+1,)``: the pulses' ticks.
    """
    lens = np.asarray(is_lens(cruise, np))
    poly = np.flatnonzero(~lens)
    h = (ticks[poly] / f)[:, None]
    v0, v1, Dp, p0 = v[:-1][poly], v[1:][poly], D[poly], pts[:-1][poly]
    q1 = phase_fraction(cruise, np)[poly]
    q2 = 1.0 - q1
    vc = (Dp / h - 0.5 * q1[:, None] * (v0 + v1)) / q2[:, None]
    a1 = (vc - v0) / (q1[:, None] * h)
    a3 = (v1 - vc) / (q1[:, None] * h)
    t1, t2 = q1[:, None] * h, (q2 - q1)[:, None] * h
    c = np.zeros((poly.size, 3, 4, 3))
    c[:, 0, 0], c[:, 0, 1], c[:, 0, 2] = p0, v0, 0.5 * a1
    c[:, 1, 0], c[:, 1, 1] = p0 + v0 * t1 + 0.5 * a1 * t1 * t1, vc
    c[:, 2, 0], c[:, 2, 1], c[:, 2, 2] = c[:, 1, 0] + vc * t2, vc, 0.5 * a3
    w0 = work[:-1][poly]
    starts = np.column_stack([w0, w0 + q1 * ticks[poly], w0 + q2 * ticks[poly]]).astype(np.float64)
    gap = np.repeat(poly, 3)
    starts, c = starts.reshape(-1), c.reshape(-1, 4, 3)
    if np.any(lens):
        idx = np.flatnonzero(lens)
        ls, lc, lg = _lens_pieces(pts, D, ticks, v, work, f, idx)
        order = np.argsort(np.concatenate([gap, lg]), kind="stable")  # each gap's pieces stay in time order
        starts, c = np.concatenate([starts, ls])[order], np.concatenate([c, lc])[order]
    return starts, c


def _lens_pieces(pts, D, ticks, v, work, f, idx):
    """Pieces of the lens gaps ``idx``: ``(starts, coeffs, gap index)``; slivers under 1e-6 tick dropped."""
    g = idx.size
    h = (ticks[idx] / f)[:, None]
    v0, v1, Dl = v[:-1][idx], v[1:][idx], D[idx]
    ts, a1, a3 = lens_profile(v0, v1, Dl, np.broadcast_to(h, Dl.shape))  # (g, 3) each
    sliver = 1e-6 / f  # a piece shorter than this is dropped, the piece before covers it (~1e-10 s)
    ts = np.where(ts < sliver, 0.0, np.where(ts > h - sliver, h, ts))  # one phase: no sliver of the other
    at = np.sort(np.concatenate([np.zeros((g, 1)), ts], axis=1), axis=1)  # (g, 4) piece starts, s
    tau, T = at[:, :, None], ts[:, None]  # (g, 4, 1), (g, 1, 3)
    d1, d2 = np.minimum(tau, T), np.maximum(tau - T, 0.0)
    V0, A1, A3 = v0[:, None], a1[:, None], a3[:, None]
    u1 = V0 + A1 * d1
    c = np.zeros((g, 4, 4, 3))
    c[:, :, 0] = pts[:-1][idx][:, None] + V0 * d1 + 0.5 * A1 * d1 * d1 + u1 * d2 + 0.5 * A3 * d2 * d2
    c[:, :, 1] = u1 + A3 * d2
    keep = np.concatenate([np.ones((g, 1), bool), (np.diff(at, axis=1) > sliver) & (at[:, 1:] < h - sliver)], 1)
    # each kept piece runs to the next kept start (over the slivers): its accelerations are those at its middle
    later = np.concatenate([np.where(keep, at, h)[:, 1:], h], axis=1)
    end = np.minimum.accumulate(later[:, ::-1], axis=1)[:, ::-1][:, :, None]
    c[:, :, 2] = 0.5 * np.where(0.5 * (tau + end) < T, A1, A3)
    starts = work[:-1][idx][:, None] + at * f
    return starts[keep], c[keep], np.repeat(idx[:, None], 4, axis=1)[keep]


@register_pulse_planner("bang")
def plan_bang(req: PulseRequest) -> PulsePlan:
    """Plan with constant-acceleration pieces and knot speeds from interval propagation (module docstring)."""
    from jaxcnc.planners.pulsed.sync import plan_sync

    w, f = req.window, req.tick_hz
    pts = req.points
    n = len(pts)
    if n < 2 or np.any(np.isfinite(req.j_max)) or req.smooth:
        return plan_sync(req)  # acceleration steps at the knots need an unlimited jerk (and no galvo lag model)
    A = np.asarray(req.a_max, dtype=np.float64)
    V = np.asarray(req.v_max, dtype=np.float64)
    D = np.diff(pts, axis=0)
    g = D.shape[0]
    # dark between pulses: the path speed within the rapid; at a pulse (burning) within the feed
    capm = path_caps(D, req.rapid_mm_s, V)
    lo_ticks = np.maximum(np.ceil(np.max(np.abs(D) / capm, axis=1) * f), w.n_min)
    capk = np.broadcast_to(np.minimum(req.feed_mm_s / np.sqrt(D.shape[1]), V), (g + 1, D.shape[1]))
    cand = candidates(lo_ticks, w)
    # long jumps (a triangle from rest at A would pass the cap) cruise through their middle half
    cruise = np.any(np.abs(D) >= capm * capm / A, axis=1)
    size = bucket_size(g)
    pending = _precompile(size, cand.shape[1], A, f)
    fwd = _Gaps(D, cruise, capm, capk, size, reverse=False)
    bwd = _Gaps(D, cruise, capm, capk, size, reverse=True)
    ticks = _sweep(fwd, bwd, cand, None, A, f, w, lookahead=LOOKAHEAD, ready=pending[0])[0]
    for job in pending:  # compiled beside the first sweep: wait rather than compile them twice
        job.result()
    found = _improve(fwd, bwd, cand, [ticks], A, f, w, PASSES)
    if found is None:
        return plan_sync(req)
    ticks, v, tried = found
    # knot boxes turned towards the planned velocities (which stay inside): sweeps against these durations,
    # where the last sweep still gained (on rows and the nut it gained < 0.3 %, the next < 0.01 %)
    gained = 1.0 - tried[-1].sum() / tried[-2].sum() if len(tried) > 1 else 1.0
    for _ in range(RECAPS if gained >= RECAP_GAIN else 0):
        capk2 = recap(v, knot_directions(D, ticks / f), req.feed_mm_s, V)
        fwd2, bwd2 = (_Gaps(D, cruise, capm, capk2, size, reverse=r) for r in (False, True))
        more = _improve(bwd2, fwd2, cand, [ticks], A, f, w, RECAP_PASSES, v=v)
        if more is None or len(more[2]) == 1:
            break
        capk = capk2
        ticks, v, more = more
        tried += more[1:]
    if POLISH_ROUNDS:
        from jaxcnc.planners.pulsed.polish import polish

        polished, v, cruise = polish(D, ticks, v, cruise, capm, capk, cand[:, 0], A, f, w, rounds=POLISH_ROUNDS)
        if polished.sum() < ticks.sum():
            tried.append(polished)
        ticks = polished
    passes = [int(t.sum()) for t in tried]
    # the approach: rest to rest from the start to the first point, the first pulse on the next whole tick
    ua, length, vp, a, t = rest_to_rest(req, req.home[None], pts[:1], np.array([req.rapid_mm_s]))
    z = np.zeros(1)
    a_starts, a_coeffs, arrive = move_pieces(z, req.home[None], ua, z, vp, z, length, a, f)
    first = int(np.ceil(float(arrive[0]) - 1e-9))
    work = first + np.concatenate([[0], np.cumsum(ticks)])
    half, c = gap_pieces(pts, D, ticks, v, cruise, work, f)
    starts = np.concatenate([a_starts, arrive, half, work[-1:].astype(np.float64)])
    coeffs = np.concatenate([a_coeffs, rest_pieces(arrive, pts[:1]), c, rest_pieces(z, pts[-1:])])
    _, m = w.snap_up(ticks)
    idle = w.split(work[:-1], ticks, m if w.idle_pulses else np.ones_like(ticks))
    traj = Trajectory(start_tick=starts, coeffs=coeffs, n_ticks=int(work[-1]), tick_hz=f)
    return PulsePlan(
        trajectory=traj,
        work_tick=work,
        idle_tick=idle,
        planner="bang",
        stats={"idle_pulses": int(idle.shape[0]), "pass_ticks": passes},
    )


@register_pulse_planner("best")
def plan_best(req: PulseRequest) -> PulsePlan:
    """Plan with ``sync`` and ``bang`` and keep the shorter burn (twice the planning time)."""
    from jaxcnc.planners.pulsed.sync import plan_sync

    a, b = plan_sync(req), plan_bang(req)
    return a if a.burn_time_s <= b.burn_time_s else b
