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

Everything is NumPy and vectorised over gaps and candidates; a job of 100k points takes
milliseconds to a fraction of a second.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jaxcnc.planners.pulsed.windows import PulseWindow, snap_up_ticks

#: Relative slack taken off every continuous time before it is rounded up to ticks, so that
#: floating-point rounding can never lift the bound above a true optimum.
ROUND_SLACK = 1e-9
#: How many blocks of admissible tick counts of a neighbour gap the window bound enumerates (about
#: nine periods at the documents' machine); longer neighbours are covered by the velocity bound.
N_BLOCKS = 64
#: Consecutive candidate counts are bounded together in blocks of this many ticks per period.
BLOCK_TICKS = 4


@dataclass(frozen=True)
class TravelBound:
    """What :func:`lower_bound_travel` found.

    Attributes:
        ticks: the bound on the burn time, in ticks (first to last work pulse).
        gap_ticks: ``(n-1,)`` per-gap bounds from admissibility and velocity alone.
        window_centre: ``(w,)`` gaps at the centre of the three-gap windows used.
        window_ticks: ``(w,)`` each window's bound on the sum of its three gaps.
        tick_hz: ticks per second.
    """

    ticks: int
    gap_ticks: np.ndarray
    window_centre: np.ndarray
    window_ticks: np.ndarray
    tick_hz: float

    @property
    def seconds(self) -> float:
        return self.ticks / self.tick_hz


def tent_time_s(dist_mm, a_mm_s, b_mm_s, v_max, a_max):
    """Least ``h`` with ``∫_0^h min(a + A t, b + A (h - t), V) dt >= dist`` (arrays, broadcast).

    ``a``, ``b`` (``<= V``) bound the speed at the start and end of the move, ``A``/``V`` the axis'
    acceleration and speed. The integrand bounds the speed of any motion with those ends from above,
    so no motion covers ``dist`` faster. Cases: one ramp only (``|a - b| > A h``), a tent, a tent cut
    at ``V``.
    """
    D = np.asarray(dist_mm, dtype=np.float64)
    a = np.minimum(np.asarray(a_mm_s, dtype=np.float64), v_max)
    b = np.minimum(np.asarray(b_mm_s, dtype=np.float64), v_max)
    A, V = a_max, v_max
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    # one ramp from the lower end speed: G = c h + A h²/2 while A h < |a - b|
    t_ramp = (np.sqrt(lo * lo + 2.0 * A * D) - lo) / A
    # a tent: peak u = (a + b + A h)/2, G = (2u² - a² - b²)/(2A)
    u = np.sqrt(0.5 * (2.0 * A * D + a * a + b * b))
    t_tent = (2.0 * u - a - b) / A
    # a tent cut at V
    t_cut = (D - (2.0 * V * V - a * a - b * b) / (2.0 * A)) / V + (2.0 * V - a - b) / A
    t = np.where(u <= V, t_tent, t_cut)
    return np.where(A * t_ramp < hi - lo, t_ramp, t)


def _ticks_at_least(t_s, tick_hz: float) -> np.ndarray:
    """Least whole tick count that lasts ``t_s`` (with :data:`ROUND_SLACK` off)."""
    return np.ceil(np.asarray(t_s) * tick_hz * (1.0 - ROUND_SLACK) - 1e-6).astype(np.int64)


def _candidates(window: PulseWindow, lo: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Blocks of admissible tick counts at or above ``lo`` ``(h,)``: ``(first, last)`` each ``(h, count)``.

    A block holds consecutive admissible counts (at most ``m`` × :data:`BLOCK_TICKS` in the range of
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
        end = np.minimum(cur + BLOCK_TICKS * m - 1, top)  # wider blocks for longer times
        first[:, c], last[:, c] = cur, end
        cur, _ = snap_up_ticks(end + 1, n_min, n_max, idle)
    return first, last


def lower_bound_travel(
    points: np.ndarray, window: PulseWindow, v_max: np.ndarray, a_max: np.ndarray, min_gain_ticks: int = 1
) -> TravelBound:
    """A certified lower bound on the burn time of ``points`` ``(n, 3)`` mm burned in this order.

    ``v_max``, ``a_max`` ``(3,)``: the machine's axis limits (mm/s, mm/s²; ``inf`` where absent) —
    the limits the table is verified against, not a planner's reduced ones. See the module docstring
    for the argument; ``min_gain_ticks``: only windows that gain at least this much are searched.
    """
    f = window.tick_hz
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[0] < 2:
        return TravelBound(0, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), f)
    V = np.asarray(v_max, dtype=np.float64)
    A = np.asarray(a_max, dtype=np.float64)
    D = np.abs(np.diff(pts, axis=0))  # (g, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_v = np.max(np.where(D > 0, D / V, 0.0), axis=1)
    gap = snap_up_ticks(np.maximum(_ticks_at_least(t_v, f), n_min), n_min, n_max, idle)[0]
    total = int(gap.sum())
    g = gap.shape[0]
    if g < 3:
        return TravelBound(total, gap, np.zeros(0, np.int64), np.zeros(0, np.int64), f)
    # windows p, c, q: each centre c in 1..g-2; bound the centre gap with entry/exit speeds limited by
    # its neighbours' durations, at the neighbours' least durations first (a quick screen)
    c = np.arange(1, g - 1)
    axes = np.flatnonzero(np.isfinite(A))
    screen = _window_ticks(D, c, gap[c - 1][:, None], gap[c + 1][:, None], V, A, axes, f, n_min, n_max, idle)[:, 0, 0]
    base = gap[c - 1] + gap[c] + gap[c + 1]
    # the screen puts both neighbours at their least durations: an upper estimate of the window's gain
    c = c[screen - base >= min_gain_ticks]
    if c.size == 0:
        return TravelBound(total, gap, np.zeros(0, np.int64), np.zeros(0, np.int64), f)
    count = N_BLOCKS
    win = np.empty(c.shape[0], np.int64)
    for s in range(0, c.shape[0], 256):  # bounded memory: windows × candidates × candidates
        cs = c[s : s + 256]
        p_lo, p_hi = _candidates(window, gap[cs - 1], count)
        q_lo, q_hi = _candidates(window, gap[cs + 1], count)
        best = _window_min(D, cs, p_lo, p_hi, q_lo, q_hi, V, A, axes, f, n_min, n_max, idle)
        # counts beyond the enumerated ones: the neighbour alone is longer than its last block, the
        # centre at least its velocity bound
        tail_p = p_hi[:, -1] + 1 + gap[cs] + gap[cs + 1]
        tail_q = q_hi[:, -1] + 1 + gap[cs] + gap[cs - 1]
        win[s : s + 256] = np.minimum(best, np.minimum(tail_p, tail_q))
    gain = win - (gap[c - 1] + gap[c] + gap[c + 1])
    keep = _disjoint(c, gain)
    c, win = c[keep], win[keep]
    total += int((win - (gap[c - 1] + gap[c] + gap[c + 1])).sum())
    return TravelBound(total, gap, c, win, f)


def _entry_speed(D_side, ticks, A, f):
    """Bound on the speed at the shared pulse: ``|D|/h + A h/2`` over a neighbour of ``ticks``."""
    h = ticks / f
    return D_side / h + 0.5 * A * h


def _window_ticks(D, c, p_ticks, q_ticks, V, A, axes, f, n_min, n_max, idle):
    """Sum of the window's bound for neighbour durations ``p_ticks`` ``(w, P)``, ``q_ticks`` ``(w, Q)``.

    Returns ``(w, P, Q)`` ticks: ``p + q + snap(centre)`` with the centre's least time over all axes.
    The entry speeds are taken at these durations exactly.
    """
    return _window_block(D, c, p_ticks, p_ticks, q_ticks, q_ticks, V, A, axes, f, n_min, n_max, idle)


def _window_block(D, c, p_lo, p_hi, q_lo, q_hi, V, A, axes, f, n_min, n_max, idle):
    """Like :func:`_window_ticks` for blocks ``[p_lo, p_hi]`` × ``[q_lo, q_hi]``: a bound over each block."""
    t_c = np.zeros((c.shape[0], p_lo.shape[1], q_lo.shape[1]))
    for k in axes:  # three axes at most
        a = np.maximum(
            _entry_speed(D[c - 1, k][:, None], p_lo, A[k], f), _entry_speed(D[c - 1, k][:, None], p_hi, A[k], f)
        )
        b = np.maximum(
            _entry_speed(D[c + 1, k][:, None], q_lo, A[k], f), _entry_speed(D[c + 1, k][:, None], q_hi, A[k], f)
        )
        t = tent_time_s(D[c, k][:, None, None], a[:, :, None], b[:, None, :], V[k], A[k])
        t_c = np.maximum(t_c, t)
    d_c = snap_up_ticks(np.maximum(_ticks_at_least(t_c, f), n_min), n_min, n_max, idle)[0]
    return p_lo[:, :, None] + q_lo[:, None, :] + d_c


def _window_min(D, c, p_lo, p_hi, q_lo, q_hi, V, A, axes, f, n_min, n_max, idle):
    """Least bound over all candidate blocks of both neighbours: ``(w,)`` ticks."""
    return _window_block(D, c, p_lo, p_hi, q_lo, q_hi, V, A, axes, f, n_min, n_max, idle).min(axis=(1, 2))


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
