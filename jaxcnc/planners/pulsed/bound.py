"""A certified lower bound on the burn time of a pulsed job that accounts for travel across gaps.

The plain bound ``(n - 1) T (1 - tol)`` ignores motion. This one, :func:`lower_bound_travel`, bounds
from below the time between the first and last work pulse of *any* motion that keeps every axis
within its machine limits ``|v| <= V_k``, ``|a| <= A_k`` (a jerk limit or the path feed only add
constraints, so the bound holds with them too) and fires its pulses on ticks in the lamp's window.
The argument (``docs/pulsed.md``, "The travel-aware lower bound"):

1. *Admissible times.* The time between two consecutive work pulses is a whole number of ticks
   ``d`` with ``m n_min <= d <= m n_max`` for some ``m >= 1`` (``m = 1`` without idle pulses);
   :func:`~.windows.snap_up_ticks` gives the least such ``d`` at or above any wanted tick count.
2. *Velocity.* Between the pulses of gap ``g`` each axis moves by ``D_gk``; its speed never exceeds
   ``V_k``, so the gap lasts at least ``max_k |D_gk| / V_k``.
3. *Acceleration, over a window of three gaps* ``p, g, q`` (before, the gap, after). Over gap ``p``
   of duration ``h_p`` the mean velocity is ``D_p / h_p`` and ``|v(end) - v(t)| <= A (h_p - t)``, so
   at the pulse that opens gap ``g`` the speed is at most ``a = |D_p|/h_p + A h_p / 2`` (and ``V``);
   likewise at its end ``b = |D_q|/h_q + A h_q / 2``. Inside gap ``g`` then
   ``v(t) <= min(a + A t, b + A (h - t), V)``, whose integral ``G(h)`` must reach ``|D_g|``: ``h``
   is at least the root of ``G(h) = |D_g|`` (closed form, :func:`tent_time_s`). Every pair
   ``(d_p, d_q)`` of admissible tick counts is covered: blocks of consecutive counts are bounded by
   their smallest counts and their largest entry speeds (``a`` is convex in ``h_p``, so its maximum
   over a block is at an end), counts beyond the enumerated ones by the velocity bound of ``g``
   alone. The window's least sum is a lower bound on ``d_p + d_g + d_q``.
4. *Sum.* Gaps are split into disjoint windows (chosen where they gain most, never overlapping) and
   single gaps; the sum of their lower bounds is a lower bound on the burn time.
5. *Path limits* (``feed_mm_s``, ``rapid_mm_s``: the path speed at most the feed at every pulse, at most
   the rapid everywhere — what the planners honour). Projected on any unit direction ``w`` the motion
   ``s = w·p`` has ``|s''| <= Σ|w_k| A_k``, ``|s'| <= min(rapid, Σ|w_k| V_k)`` and ``|s'| <= feed`` at a
   pulse; steps 2-3 run on the axes and on the gap's own direction with these limits, every end speed
   at most the feed (a gap alone: the tent from the feed to the feed).
6. *Chains* (:mod:`.chain`). Per axis, a shortest path over the knot speed's intervals: the cost
   of a gap between two intervals is the least admissible count at which any speeds in them admit a
   motion covering the gap (closed form), so the path's cost is at most any motion's time. Stretches
   around every long gap are chained; each counts the best of its axes' chains and its own windows,
   the rest counts the gaps' own bounds and the windows outside the stretches. The bound is the larger
   of that and the window sum.

The windows are NumPy, vectorised over gaps and candidates; the chains one compiled JAX program (a second
or two on the 2,914 gaps of a sparse cloud, less on rows).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from jaxcnc.planners.pulsed.chain import chain_ticks
from jaxcnc.planners.pulsed.windows import PulseWindow, snap_up_ticks

#: Relative slack taken off every continuous time before it is rounded up to ticks, so that
#: floating-point rounding can never lift the bound above a true optimum.
ROUND_SLACK = 1e-9
#: How many blocks of admissible tick counts of a neighbour gap the window bound enumerates (about
#: nine periods at the documents' machine); longer neighbours are covered by the velocity bound.
N_BLOCKS = 64
#: Windows per block of the window bound's candidate tensors.
WINDOW_CHUNK = 256
#: Candidate blocks per gap in the chain bound (about 4.5 periods above the gap's own bound).
N_CHAIN = 32
#: Knot-speed intervals per axis in the chain bound: every axis is screened with the coarse count, the
#: best one is run again with up to ``CHAIN_BINS`` (a multiple of the coarse count, so the intervals nest)
#: while gaps × intervals² stays within ``CHAIN_WORK``.
CHAIN_BINS = 64
CHAIN_BINS_COARSE = 16
CHAIN_WORK = 2e7
#: Gaps of context on either side of a long gap in the chain bound.
CHAIN_CONTEXT = 3
#: Consecutive candidate counts are bounded together in blocks of this many ticks per period.
BLOCK_TICKS = 4
#: The same in the chain bound.
CHAIN_BLOCK_TICKS = 4


@dataclass(frozen=True)
class TravelBound:
    """What :func:`lower_bound_travel` found.

    Attributes:
        ticks: the bound on the burn time, in ticks (first to last work pulse).
        gap_ticks: ``(n-1,)`` per-gap bounds from admissibility and velocity alone.
        window_centre: ``(w,)`` gaps at the centre of the three-gap windows used.
        window_ticks: ``(w,)`` each window's bound on the sum of its three gaps.
        tick_hz: ticks per second.
        chain_ticks: the bound with chains (dynamic programming over knot speeds on the stretches around
            long gaps, the best axis per stretch, with the windows elsewhere; 0: not run).
        window_sum_ticks: the bound from the gaps and windows alone (``ticks`` is the larger of the two).
    """

    ticks: int
    gap_ticks: np.ndarray
    window_centre: np.ndarray
    window_ticks: np.ndarray
    tick_hz: float
    chain_ticks: int = 0
    window_sum_ticks: int = 0

    @property
    def seconds(self) -> float:
        return self.ticks / self.tick_hz


def tent_time_s(dist_mm, a_mm_s, b_mm_s, v_max, a_max, xp=np):
    """Least ``h`` with ``∫_0^h min(a + A t, b + A (h - t), V) dt >= dist`` (arrays, broadcast).

    ``a``, ``b`` (``<= V``) bound the speed at the start and end of the move, ``A``/``V`` the axis'
    acceleration and speed. The integrand bounds the speed of any motion with those ends from above,
    so no motion covers ``dist`` faster. Cases: one ramp only (``|a - b| > A h``), a tent, a tent cut
    at ``V``. ``xp``: the array module (``numpy``, or ``jax.numpy`` compiled: :func:`_tent_block`).
    """
    D = xp.asarray(dist_mm, dtype=xp.float64)
    a = xp.minimum(xp.asarray(a_mm_s, dtype=xp.float64), v_max)
    b = xp.minimum(xp.asarray(b_mm_s, dtype=xp.float64), v_max)
    A, V = a_max, v_max
    lo, hi = xp.minimum(a, b), xp.maximum(a, b)
    # one ramp from the lower end speed: G = c h + A h²/2 while A h < |a - b|
    t_ramp = (xp.sqrt(lo * lo + 2.0 * A * D) - lo) / A
    # a tent: peak u = (a + b + A h)/2, G = (2u² - a² - b²)/(2A)
    u = xp.sqrt(0.5 * (2.0 * A * D + a * a + b * b))
    t_tent = (2.0 * u - a - b) / A
    # a tent cut at V
    t_cut = (D - (2.0 * V * V - a * a - b * b) / (2.0 * A)) / V + (2.0 * V - a - b) / A
    t = xp.where(u <= V, t_tent, t_cut)
    return xp.where(A * t_ramp < hi - lo, t_ramp, t)


#: :func:`tent_time_s` compiled, for the windows' blocks of candidates (one shape: :data:`WINDOW_CHUNK` windows
#: × :data:`N_BLOCKS`², so one compile): fused, ~5× NumPy's passes over the ``(w, P, Q)`` arrays.
_tent_block = jax.jit(functools.partial(tent_time_s, xp=jnp))


def _ticks_at_least(t_s, tick_hz: float) -> np.ndarray:
    """Least whole tick count that lasts ``t_s`` (with :data:`ROUND_SLACK` off)."""
    return np.ceil(np.asarray(t_s) * tick_hz * (1.0 - ROUND_SLACK) - 1e-6).astype(np.int64)


def _candidates(
    window: PulseWindow, lo: np.ndarray, count: int, block_ticks: int = BLOCK_TICKS
) -> tuple[np.ndarray, np.ndarray]:
    """Blocks of admissible tick counts at or above ``lo`` ``(h,)``: ``(first, last)`` each ``(h, count)``.

    A block holds consecutive admissible counts (at most ``m`` × ``block_ticks`` in the range of
    ``m`` periods, never across a gap between period ranges); the blocks tile every admissible count
    from ``snap_up(lo)`` on.
    """
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    first = np.empty((lo.shape[0], count), np.int64)
    last = np.empty_like(first)
    cur, _ = snap_up_ticks(lo, n_min, n_max, idle)
    for c in range(count):  # a handful of columns, each vectorised over the windows
        m = np.maximum(-(-cur // n_max), 1)
        top = np.where(idle, m * n_max, np.maximum(n_max, cur))
        end = np.minimum(cur + block_ticks * m - 1, top)  # wider blocks for longer times
        first[:, c], last[:, c] = cur, end
        cur, _ = snap_up_ticks(end + 1, n_min, n_max, idle)
    return first, last


def _directions(D_vec: np.ndarray, with_own: bool) -> np.ndarray:
    """``(g, K, 3)`` unit directions the bound projects each gap on: the axes, and the gap's own direction.

    ``D_vec`` ``(g, 3)`` signed displacements; a gap of length 0 gets ``e_x`` as its own direction.
    """
    g = D_vec.shape[0]
    axes = np.broadcast_to(np.eye(3), (g, 3, 3))
    if not with_own:
        return np.array(axes)
    length = np.linalg.norm(D_vec, axis=1, keepdims=True)
    own = np.where(length > 0, D_vec / np.where(length > 0, length, 1.0), np.array([1.0, 0.0, 0.0]))
    return np.concatenate([axes, own[:, None, :]], axis=1)


def _direction_limits(W, v_max, a_max, feed, rapid):
    """Limits of the motion projected on directions ``W`` ``(..., 3)``: ``(A_w, Vc_w, F_w)`` each ``(...)``.

    ``s = w·p`` has ``|s''| <= Σ|w_k| A_k`` and ``|s'| <= Σ|w_k| V_k`` (each axis in its box), and
    ``|s'| <= ‖v‖ <= rapid`` everywhere, ``<= feed`` at a pulse (the path limits). ``inf`` where an axis
    with ``w_k != 0`` has no limit; ``feed``/``rapid`` ``inf`` when not applied.
    """
    aw = np.abs(W)
    A_w = np.sum(np.where(aw > 0, aw * a_max, 0.0), axis=-1)
    V_w = np.sum(np.where(aw > 0, aw * v_max, 0.0), axis=-1)
    Vc = np.minimum(V_w, rapid)
    return A_w, Vc, np.minimum(Vc, feed)


def lower_bound_travel(
    points: np.ndarray,
    window: PulseWindow,
    v_max: np.ndarray,
    a_max: np.ndarray,
    min_gain_ticks: int = 1,
    feed_mm_s: float | None = None,
    rapid_mm_s: float | None = None,
    chain_bins: int = CHAIN_BINS,
) -> TravelBound:
    """A certified lower bound on the burn time of ``points`` ``(n, 3)`` mm burned in this order.

    ``v_max``, ``a_max`` ``(3,)``: the machine's axis limits (mm/s, mm/s²; ``inf`` where absent) —
    the limits the table is verified against, not a planner's reduced ones. ``feed_mm_s``,
    ``rapid_mm_s``: the machine's path limits (its ``[path] feed`` and ``rapid``, not reduced): the
    path speed at every pulse instant at most the feed, everywhere at most the rapid, the limits the
    planners honour. ``None`` (both): the axis-only bound, certified against ``v_max``/``a_max`` alone.
    With the path limits the chain bound (:func:`.chain.chain_ticks`, at most ``chain_bins`` knot-speed
    intervals per axis; ``0``: not used) runs over the stretches around long gaps. See the module docstring for the
    argument; ``min_gain_ticks``: only windows that gain at least this much are searched.
    """
    bound = _window_bound(points, window, v_max, a_max, min_gain_ticks, feed_mm_s, rapid_mm_s)
    bound = dataclasses.replace(bound, window_sum_ticks=bound.ticks)
    if (feed_mm_s is None and rapid_mm_s is None) or chain_bins <= 0 or bound.gap_ticks.size == 0:
        return bound
    feed = np.inf if feed_mm_s is None else float(feed_mm_s)
    rapid = np.inf if rapid_mm_s is None else float(rapid_mm_s)
    gap = bound.gap_ticks
    # chains over every long gap with CHAIN_CONTEXT gaps on either side (stretches of consecutive such gaps).
    # Long: more than a period, or a mean speed over a shortest period that one period's acceleration
    # cannot reach
    d_all = np.diff(np.asarray(points, dtype=np.float64), axis=0)
    h_min = window.n_min / window.tick_hz
    with np.errstate(invalid="ignore"):
        fast = np.any(np.abs(d_all) > np.asarray(a_max) * h_min**2, axis=1)
    long = (gap > window.n_min) | fast
    spread = np.convolve(long, np.ones(2 * CHAIN_CONTEXT + 1), mode="full")
    hard = spread[CHAIN_CONTEXT : CHAIN_CONTEXT + gap.shape[0]] > 0
    start = hard & ~np.concatenate([[False], hard[:-1]])
    d_vec = d_all[hard]
    rest = int(gap[~hard].sum())
    lo, hi = _candidates(window, gap[hard], N_CHAIN, CHAIN_BLOCK_TICKS)
    axes = []  # (axis, its knot cap, cap, acceleration)
    for k in range(3):
        V_k, A_k = float(np.asarray(v_max)[k]), float(np.asarray(a_max)[k])
        if not (np.isfinite(A_k) and np.any(d_vec[:, k] != 0)):
            continue
        v_cap = min(V_k, rapid)
        knot = min(v_cap, feed)
        if np.isfinite(knot):
            axes.append((k, knot, v_cap, A_k))
    if not (axes and hard.any()):
        return bound
    # as many intervals as the work budget allows, O(gaps × intervals²): every axis at once where it allows
    # that, else every axis with the coarse intervals and the best one again finer (the intervals nest, so
    # the finer chain is at least the coarse one)
    coarse = min(chain_bins, CHAIN_BINS_COARSE)
    fine = coarse
    while fine + coarse <= chain_bins and hard.sum() * (fine + coarse) ** 2 <= CHAIN_WORK:
        fine += coarse
    if len(axes) * hard.sum() * fine**2 <= CHAIN_WORK:
        coarse = fine
    h_start = start[hard]
    per_axis = [chain_ticks(d_vec[:, k], lo, hi, h_start, window.tick_hz, *lim, coarse) for k, *lim in axes]
    if fine > coarse:
        k, *lim = axes[int(np.argmax([p.sum() for p in per_axis]))]
        per_axis.append(chain_ticks(d_vec[:, k], lo, hi, h_start, window.tick_hz, *lim, fine))
    # each chained stretch counts the best of its chains and its own windows (those wholly inside it);
    # the windows wholly outside every stretch keep their gains; windows across an end are dropped
    stretch = np.cumsum(h_start) - 1  # (hard gaps,) the stretch of each
    n_str = int(h_start.sum())
    c = bound.window_centre
    gains = bound.window_ticks - (gap[c - 1] + gap[c] + gap[c + 1])
    inside = hard[c - 1] & hard[c] & hard[c + 1]
    outside = ~(hard[c - 1] | hard[c] | hard[c + 1])
    h_index = np.cumsum(hard) - 1  # position of each hard gap among them
    own = np.bincount(stretch, gap[hard], n_str) + np.bincount(stretch[h_index[c[inside]]], gains[inside], n_str)
    best = np.max(np.stack([own.astype(np.int64), *per_axis]), axis=0)
    chain = rest + int(gains[outside].sum()) + int(best.sum())
    return dataclasses.replace(bound, ticks=max(bound.ticks, chain), chain_ticks=chain)


def _window_bound(points, window, v_max, a_max, min_gain_ticks, feed_mm_s, rapid_mm_s) -> TravelBound:
    """Steps 1-4 of the argument: the gaps' own bounds and the disjoint three-gap windows."""
    f = window.tick_hz
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[0] < 2:
        return TravelBound(0, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), f)
    V = np.asarray(v_max, dtype=np.float64)
    A = np.asarray(a_max, dtype=np.float64)
    path = feed_mm_s is not None or rapid_mm_s is not None
    feed = np.inf if feed_mm_s is None else float(feed_mm_s)
    rapid = np.inf if rapid_mm_s is None else float(rapid_mm_s)
    D_vec = np.diff(pts, axis=0)  # (g, 3)
    W = _directions(D_vec, with_own=path)  # (g, K, 3)
    A_w, Vc_w, F_w = _direction_limits(W, V, A, feed, rapid)
    P = np.abs(np.einsum("gkd,gd->gk", W, D_vec))  # (g, K) distance along each direction
    if path:  # from at most the feed at the opening pulse to at most the feed at the closing one
        t_v = np.max(_least_time(P, F_w, F_w, Vc_w, A_w), axis=1)
    else:  # the axis-only bound: the velocity bound alone
        with np.errstate(divide="ignore", invalid="ignore"):
            t_v = np.max(np.where(P > 0, P / Vc_w, 0.0), axis=1)
    gap = snap_up_ticks(np.maximum(_ticks_at_least(t_v, f), n_min), n_min, n_max, idle)[0]
    total = int(gap.sum())
    g = gap.shape[0]
    if g < 3:
        return TravelBound(total, gap, np.zeros(0, np.int64), np.zeros(0, np.int64), f)
    # windows p, c, q: each centre c in 1..g-2; bound the centre gap with entry/exit speeds limited by
    # its neighbours' durations, at the neighbours' least durations first (a quick screen)
    c = np.arange(1, g - 1)
    lim = (D_vec, W, V, A, feed, rapid, f, n_min, n_max, idle)
    screen = _window_ticks(c, gap[c - 1][:, None], gap[c + 1][:, None], *lim)[:, 0, 0]
    base = gap[c - 1] + gap[c] + gap[c + 1]
    # the screen puts both neighbours at their least durations: an upper estimate of the window's gain
    c = c[screen - base >= min_gain_ticks]
    if c.size == 0:
        return TravelBound(total, gap, np.zeros(0, np.int64), np.zeros(0, np.int64), f)
    count = N_BLOCKS
    win = np.empty(c.shape[0], np.int64)
    for s in range(0, c.shape[0], WINDOW_CHUNK):  # bounded memory: windows × candidates × candidates
        cs = c[s : s + WINDOW_CHUNK]
        n = cs.shape[0]
        padded = np.concatenate([cs, np.full(WINDOW_CHUNK - n, cs[0])])  # one shape: one compile
        p_lo, p_hi = _candidates(window, gap[padded - 1], count)
        q_lo, q_hi = _candidates(window, gap[padded + 1], count)
        best = _window_block(padded, p_lo, p_hi, q_lo, q_hi, *lim, tent=_tent_block).min(axis=(1, 2))[:n]
        p_hi, q_hi = p_hi[:n], q_hi[:n]
        # counts beyond the enumerated ones: the neighbour alone is longer than its last block, the
        # centre at least its own bound
        tail_p = p_hi[:, -1] + 1 + gap[cs] + gap[cs + 1]
        tail_q = q_hi[:, -1] + 1 + gap[cs] + gap[cs - 1]
        win[s : s + WINDOW_CHUNK] = np.minimum(best, np.minimum(tail_p, tail_q))
    gain = win - (gap[c - 1] + gap[c] + gap[c + 1])
    keep = _disjoint(c, gain)
    c, win = c[keep], win[keep]
    total += int((win - (gap[c - 1] + gap[c] + gap[c + 1])).sum())
    return TravelBound(total, gap, c, win, f)


def _least_time(dist, a, b, v_cap, a_cap):
    """:func:`tent_time_s` where the acceleration is bounded, ``dist / v_cap`` where it is not (arrays)."""
    finite = np.isfinite(a_cap)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = tent_time_s(dist, a, b, v_cap, np.where(finite, a_cap, 1.0))
        return np.where(finite, t, np.where(dist > 0, dist / v_cap, 0.0))


def _entry_speed(D_side, ticks, A, f):
    """Bound on the speed at the shared pulse: ``|D|/h + A h/2`` over a neighbour of ``ticks``."""
    h = ticks / f
    return D_side / h + 0.5 * A * h


def _window_ticks(c, p_ticks, q_ticks, *lim):
    """Sum of the window's bound for neighbour durations ``p_ticks`` ``(w, P)``, ``q_ticks`` ``(w, Q)``.

    Returns ``(w, P, Q)`` ticks: ``p + q + snap(centre)`` with the centre's least time over all directions.
    The entry speeds are taken at these durations exactly.
    """
    return _window_block(c, p_ticks, p_ticks, q_ticks, q_ticks, *lim)


def _window_block(c, p_lo, p_hi, q_lo, q_hi, D_vec, W, V, A, feed, rapid, f, n_min, n_max, idle, tent=tent_time_s):
    """Like :func:`_window_ticks` for blocks ``[p_lo, p_hi]`` × ``[q_lo, q_hi]``: a bound over each block.

    Each of the centre's directions ``W[c]`` (the axes; with path limits also the centre gap's own) is a
    1-D motion with the projected limits (:func:`_direction_limits`); the centre's least time is the
    largest over them.
    """
    Wc = W[c]  # (w, K, 3)
    A_w, Vc_w, F_w = _direction_limits(Wc, V, A, feed, rapid)
    t_c = np.zeros((c.shape[0], p_lo.shape[1], q_lo.shape[1]))
    for k in range(Wc.shape[1]):  # three or four directions
        w = Wc[:, k]
        fin = np.isfinite(A_w[:, k])
        if not fin.any():
            continue
        Ak = np.where(fin, A_w[:, k], 1.0)[:, None]
        Dp = np.abs(np.sum(w * D_vec[c - 1], axis=1))[:, None]
        Dq = np.abs(np.sum(w * D_vec[c + 1], axis=1))[:, None]
        Dc = np.abs(np.sum(w * D_vec[c], axis=1))[:, None, None]
        Fk = F_w[:, k][:, None]
        a = np.minimum(Fk, np.maximum(_entry_speed(Dp, p_lo, Ak, f), _entry_speed(Dp, p_hi, Ak, f)))
        b = np.minimum(Fk, np.maximum(_entry_speed(Dq, q_lo, Ak, f), _entry_speed(Dq, q_hi, Ak, f)))
        t = np.asarray(tent(Dc, a[:, :, None], b[:, None, :], Vc_w[:, k][:, None, None], Ak[:, :, None]))
        t_c = np.maximum(t_c, np.where(fin[:, None, None], t, 0.0))
    d_c = snap_up_ticks(np.maximum(_ticks_at_least(t_c, f), n_min), n_min, n_max, idle)[0]
    return p_lo[:, :, None] + q_lo[:, None, :] + d_c


def _disjoint(centre: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """Mask of windows (three gaps around ``centre``) that share no gap: each kept one gains more than
    every other window within two gaps of it (ties: the earlier wins). Windows that gain nothing are dropped.
    """
    key = gain.astype(np.float64) - centre * 1e-12  # a strict total order: gain, then the earlier
    keep = gain > 0
    for shift in (1, 2):  # compare with the candidates up to two positions away on either side
        for sign in (-1, 1):
            other = np.roll(np.arange(centre.shape[0]), -sign * shift)
            near = np.abs(centre[other] - centre) <= 2
            near &= other != np.arange(centre.shape[0])
            keep &= ~near | (key > key[other])
    return keep
