"""``bang``'s polish: short windows of gaps re-timed jointly between pinned knot velocities (issue 21).

The sweeps of :mod:`.bang` change one gap at a time against sets computed with the other gaps' durations
fixed, and only ever shorten a gap. On 40-point windows of the short-rows and text clouds the window optimum
(:mod:`.optimum`) differs from ``bang`` in two ways, both joint moves the sweeps cannot make:

- a **jump** (0.5–12 mm) takes one or more periods fewer, while the row gaps around it set up the speed
  differently (the sweeps offer one period fewer per sweep and the neighbours' sets are those of the plan);
- a **row change** (a step across and a reversal) takes one period instead of two, the next gap being
  *lengthened* within its period range (238 → 259 ticks): a few ticks spent to save a period;
- and the optimum's ticks are not feasible in the ½–½ profile at all: its row gaps next to a jump gain or
  shed more speed than the rhombus allows, which the lens does.

On sparse clouds (chains of 0.1–4 mm jumps) and at short rows' jumps the optimum makes moves that span two
single windows' centres or reach past their neighbours (docs/pulsed.md, "Jump chains and moves across two
centres"): at a reversal the last row gap before it takes an idle pulse (and the one before it the top of its
range) while the reversal drops one or two periods; two 14 mm jumps either side of a one-point row both shorten
while the point between takes an idle pulse; long jumps end a few ticks per period long within their count.

Here every gap whose period count is above its shortest is the centre of a window of ``2 half + 1`` gaps;
the velocities at the window's two end knots are pinned to the plan's, so windows are independent (the
plan outside is untouched, its knots keep their speeds) and every window is solved at once (NumPy, batched,
no loop over gaps). Inside, every combination of a few candidate counts per gap (the centre: its count, a few
ticks per period shorter in it, and the tops of the one to three period ranges below it; its neighbours:
their count, a few ticks longer or shorter within their range, one period more up to that range's top, and
— jumps themselves — one or two periods fewer; the outer gaps: their count or its range's top, or fixed
next to a cruising centre; a cruising centre also its ramp fraction ``q`` or the lens) is checked exactly in
``bang``'s motion model, every two-phase gap of the window in the lens (:func:`~.bang.lens_project`): the
speed intervals are propagated from the pinned entry velocity forward and from the pinned exit velocity
backward (:func:`~.bang.project`, time reversed) to the knot after the centre, where they must meet
(:func:`meet`: as exact as propagating every combination through the window, with the two halves'
combinations projected instead of their product). The feasible combination with the least total is kept when
it is shorter than the plan's, and the interior knot velocities are picked backwards from the pinned exit
inside the forward intervals.
Windows centred on gaps in one residue class modulo ``2 half + 1`` are disjoint, so a round runs class by
class; a second round tries only the windows near the first one's changes. Then **pair windows**
(:func:`_pair_windows`): two centres one or two gaps apart, both above their shortest count, each with a
few counts within and below its own (and, cruising, a few ramp fractions), the gap between them longer or
one period more, their outer neighbours a few ticks either way — the moves across two centres. Last, **end
windows** (:func:`_end_windows`): the job's first and last few gaps, which no centre reaches, re-timed jointly
against the rest at the job's end (periods traded among the last gaps: one fewer on two, one more on a third).
"""

from __future__ import annotations

import numpy as np

from jaxcnc.planners.pulsed.bang import EPS_MM_S, LENS_Q, phase_fraction, project
from jaxcnc.planners.pulsed.windows import PulseWindow, snap_up_ticks

#: Gaps on each side of a window's centre.
HALF = 2
#: The centre's candidates: one to three period ranges fewer (each range's longest count and a few below it).
CENTRE_DROPS = (1, 2, 3)
CENTRE_BELOW = (0, 8, 24)
#: ... and its own period count a few ticks per period shorter (long jumps end a few ticks per period long).
CENTRE_SHORTER = (4, 8, 16)
#: The neighbours' candidates (ticks per period, relative to the plan's count, within its period range).
NEIGHBOUR_STEPS = (0, 8, 16, -8)
#: ... and one period more (ticks per period above that range's shortest): an idle pulse moved off the centre.
NEIGHBOUR_UP = (0, 12, 24)
#: ... and the longest counts of one and two periods fewer (two jumps either side of a short gap).
NEIGHBOUR_DROPS = (1, 2)
#: Ramp fractions ``q`` tried at a window's centre (besides its own): ½ two halves, less a cruise between.
Q_CHOICES = (LENS_Q, 0.5, 0.375, 0.25, 0.1875, 0.125)


def _centre_candidates(prev: np.ndarray, first: np.ndarray, window: PulseWindow) -> np.ndarray:
    """Candidate counts ``(w, C)`` for window centres: the plan's, and the tops of lower period ranges."""
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    m = snap_up_ticks(prev, n_min, n_max, idle)[1]
    cols = [prev] + [np.maximum(prev - s * m, m * n_min) for s in CENTRE_SHORTER]
    for k in CENTRE_DROPS:
        mk = np.maximum(m - k, 1)
        for b in CENTRE_BELOW:
            cols.append(np.maximum(mk * n_max - b * mk, mk * n_min))
    out = np.stack(cols, axis=1)
    out = np.maximum(out, first[:, None])
    return snap_up_ticks(out, n_min, n_max, idle)[0]


def _neighbour_candidates(prev: np.ndarray, first: np.ndarray, window: PulseWindow) -> np.ndarray:
    """Candidate counts ``(w, C)`` for a centre's neighbours: the plan's, a few ticks either side in its range,
    and the shortest of the next range (and a little above it)."""
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    m = snap_up_ticks(prev, n_min, n_max, idle)[1]
    out = _steps_candidates(prev, first, window, NEIGHBOUR_STEPS, NEIGHBOUR_UP)  # within its range, one more
    down = np.maximum(m[:, None] - np.array(NEIGHBOUR_DROPS)[None], 1) * n_max  # a neighbour that is a jump too
    return snap_up_ticks(np.maximum(np.concatenate([out, down], axis=1), first[:, None]), n_min, n_max, idle)[0]


def _forward(v_in, D, tk, qk, capm, capk, A, f):
    """Speed intervals through a window, every combination of candidates, expanded gap by gap.

    ``v_in`` ``(w, 3)`` the pinned entry; per gap ``j``: ``tk[j]``, ``qk[j]`` ``(w, C_j)`` its candidate
    counts and ramp fractions, ``D`` ``(w, k, 3)``, ``capm`` ``(w, k, 3)``, ``capk`` ``(w, k+1, 3)``. After
    gap ``j`` the combinations of gaps ``0..j`` are ``P_j = C_0 … C_j`` (C order). Returns ``(ok (w, P),
    total (w, P) ticks, los, his)``, ``los[j]`` ``(w, P_{j-1}, 3)`` the interval at knot ``j`` (``j >= 1``).
    """
    w = v_in.shape[0]
    lo = hi = v_in[:, None]
    ok = np.ones((w, 1), bool)
    total = np.zeros((w, 1), np.int64)
    los, his = [lo], [hi]
    for j in range(len(tk)):  # the window's few gaps, each batched over windows and combinations
        C = tk[j].shape[1]
        h = tk[j][:, None, :, None] / f  # (w, 1, C, 1)
        okj, lo, hi = project(
            lo[:, :, None],
            hi[:, :, None],
            D[:, None, None, j],
            h,
            A,
            capm[:, None, None, j],
            capk[:, None, None, j + 1],
            qk[j][:, None, :, None],
            xp=np,
        )
        P = lo.shape[1] * C
        lo, hi = lo.reshape(w, P, 3), hi.reshape(w, P, 3)
        ok = (ok[:, :, None] & np.all(okj, axis=-1)).reshape(w, P)
        total = (total[:, :, None] + tk[j][:, None, :]).reshape(w, P)
        los.append(lo)
        his.append(hi)
    return ok, total, los, his


#: Combinations (windows × candidate combinations) solved at once: bounds the memory (~100 MB).
COMBINATIONS = 1 << 19


def _pair_candidates(prev: np.ndarray, first: np.ndarray, window: PulseWindow) -> np.ndarray:
    """Candidate counts ``(w, C)`` for the two centres of a pair window: the plan's, a few ticks per period
    shorter within its range, the longest count of one period fewer (and a few below it), of two fewer."""
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    m = snap_up_ticks(prev, n_min, n_max, idle)[1]
    cols = [prev]
    cols += [np.maximum(prev - s * m, m * n_min) for s in PAIR_SHORTER]
    for k, below in PAIR_DROPS:
        mk = np.maximum(m - k, 1)
        cols.append(np.maximum(mk * n_max - below * mk, mk * n_min))
    out = np.maximum(np.stack(cols, axis=1), first[:, None])
    return snap_up_ticks(out, n_min, n_max, idle)[0]


def _steps_candidates(prev: np.ndarray, first: np.ndarray, window: PulseWindow, steps, up) -> np.ndarray:
    """Candidate counts ``(w, C)``: the plan's moved by ``steps`` ticks per period within its range, and
    ``up`` ticks per period above the shortest count of one period more."""
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    m = snap_up_ticks(prev, n_min, n_max, idle)[1]
    out = np.clip(prev[:, None] + np.array(steps)[None] * m[:, None], (m * n_min)[:, None], (m * n_max)[:, None])
    if up:
        more = ((m + 1) * n_min)[:, None] + np.array(up)[None] * (m + 1)[:, None]
        out = np.concatenate([out, more], axis=1)
    return snap_up_ticks(np.maximum(out, first[:, None]), n_min, n_max, idle)[0]


#: Pair windows (two centres, :func:`polish`): each centre's counts a few ticks per period shorter within its
#: range, and ``(k, b)``: the longest count of ``k`` periods fewer less ``b`` ticks per period.
PAIR_SHORTER = (8, 16, 24)
PAIR_DROPS = ((1, 0), (1, 8), (1, 24), (2, 0))
#: ... a cruising centre's ramp fractions (besides its own).
PAIR_Q = (0.375, 0.3125, 0.25)
#: ... the gap between two centres: ticks per period longer within its range, and one period more.
PAIR_MIDDLE_STEPS, PAIR_MIDDLE_UP = (0, 8, 16), (0, 12)
#: ... the centres' outer neighbours.
PAIR_OUTER_STEPS = (0, 8, -8)
#: A single window's outer gaps (two-phase windows): their count and up to the top of its range (ticks per
#: period above the plan's, within the range).
OUTER_STEPS = (0, 24)
#: Pair layouts: the second centre one gap after the first (adjacent) or two (a gap between them).
PAIR_OFFSETS = (1, 2)


#: End windows (:func:`_end_windows`): the last (and first) :data:`END_GAPS` gaps of the job, between its
#: rest and a pinned knot; each gap's count moved by these ticks per period within its range, one period more
#: (ticks per period above that range's shortest), and the longest and shortest counts of one and of two
#: periods fewer (a 16-point text window ending in a 1.2 mm jump and a 0.12 mm gap into rest: 6452 → 6118
#: ticks, the optimum at rest 6045; with one period fewer alone the final gap could not drop from 4 to 2).
END_GAPS = 6
END_STEPS, END_UP, END_DROPS = (0, 8, -24), (0, 12), (1, 2)


def _end_candidates(prev: np.ndarray, first: np.ndarray, window: PulseWindow) -> np.ndarray:
    """Candidate counts ``(w, C)`` for the gaps of an end window (:data:`END_STEPS`, :data:`END_UP`,
    :data:`END_DROPS`)."""
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    m = snap_up_ticks(prev, n_min, n_max, idle)[1]
    out = _steps_candidates(prev, first, window, END_STEPS, END_UP)
    fewer = np.maximum(m[:, None] - np.array(END_DROPS)[None], 1)  # periods: both ends of each range
    down = np.concatenate([fewer * n_max, fewer * n_min], axis=1)
    return snap_up_ticks(np.maximum(np.concatenate([out, down], axis=1), first[:, None]), n_min, n_max, idle)[0]


def polish(
    D,
    ticks,
    v,
    cruise,
    capm,
    capk,
    first,
    A,
    f,
    window: PulseWindow,
    half: int | None = None,
    rounds: int = 1,
    pairs: bool = True,
    ends: bool = True,
):
    """Re-time windows of ``2 half + 1`` gaps jointly between pinned knot velocities (module docstring).

    ``D`` ``(g, 3)``, ``ticks`` ``(g,)`` the plan, ``v`` ``(g+1, 3)`` its knot velocities, ``cruise`` ``(g,)``
    (boolean, or each gap's ramp fraction ``q``), ``capm`` ``(g, 3)``, ``capk`` ``(g+1, 3)`` (the caps the
    plan keeps), ``first`` ``(g,)`` each gap's shortest admissible count. ``rounds``: the later rounds only
    where the round before changed the plan. ``pairs``: then windows with two centres (:func:`_pair_windows`),
    once; ``ends``: then the job's first and last gaps (:func:`_end_windows`). Returns ``(ticks, v, q)``:
    never longer in total than the plan, every gap feasible in ``bang``'s model with the returned velocities
    and ramp fractions ``q`` ``(g,)``.
    """
    ticks, v = ticks.copy(), v.copy()
    q = np.array(phase_fraction(cruise, np), dtype=np.float64)
    half = HALF if half is None else half
    g, K = ticks.shape[0], 2 * half + 1
    if g < K:
        return ticks, v, q
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    m0 = snap_up_ticks(first, n_min, n_max, idle)[1]
    capk = np.broadcast_to(capk, (g + 1, 3))
    near = np.ones(g, bool)  # where a window may gain: everywhere, then around the last round's changes
    args = (D, ticks, v, q, capm, capk, first, A, f, window)
    for _ in range(rounds):
        before = ticks.copy()
        for r in range(K):
            m = snap_up_ticks(ticks, n_min, n_max, idle)[1]
            centre = np.flatnonzero((m > m0) & (np.arange(g) % K == r) & near)
            centre = centre[(centre >= half) & (centre + half < g)]
            jumps = q[centre] < 0.5  # cruising jumps try ramp fractions too: their own batches
            for group, roles in ((centre[jumps], _single_roles(half, "F")), (centre[~jumps], _single_roles(half))):
                if group.size:
                    _solve(group[:, None] + np.arange(-half, half + 1)[None], roles, *args)
        changed = np.flatnonzero(ticks != before)
        if changed.size == 0:
            break
        near = np.zeros(g, bool)
        near[np.clip(changed[:, None] + np.arange(-K, K + 1)[None], 0, g - 1)] = True
    if pairs:
        _pair_windows(m0, *args)
    if ends:
        _end_windows(*args)
    return ticks, v, q


def _end_windows(D, ticks, v, q, capm, capk, first, A, f, window) -> None:
    """The job's first and last :data:`END_GAPS` gaps re-timed jointly (every gap :func:`_end_candidates`).

    Single and pair windows keep ``half`` gaps each side of their centres, so the gaps next to the job's
    ends are never centres: there the optimum at rest trades periods among the last few gaps (sparse, 16
    points from 40: the last two row gaps one period fewer each, the final one a period more, the gap before
    the row's end 8 ticks per period longer). Two windows per job, updated in place (the second one only
    where the job is long enough for the two to be disjoint)."""
    g, K = ticks.shape[0], END_GAPS
    if g < K:
        return
    roles = ("R",) * K
    starts = (g - K, 0) if g >= 2 * K else (g - K,)
    for s0 in starts:  # the job's two ends, one window each
        _solve(np.arange(s0, s0 + K)[None], roles, D, ticks, v, q, capm, capk, first, A, f, window)


def _single_roles(half: int, outer: str = "E") -> tuple[str, ...]:
    """A single-centre window's roles: the centre, its neighbours, the outer gaps ``outer`` (``E``: their
    count or the top of its range — a row slowed before a reversal —, ``F``: fixed)."""
    return tuple("C" if j == half else "N" if abs(j - half) == 1 else outer for j in range(2 * half + 1))


def _pair_windows(m0, D, ticks, v, q, capm, capk, first, A, f, window) -> None:
    """Windows with two centres (both above their shortest period count), re-timed jointly.

    A move across two single windows' centres: two jumps either side of a short gap both shortened while the
    gap between them takes an idle pulse (short rows: a one-point row between two 14 mm jumps), two adjacent
    jumps shortened together (sparse chains). Layout: a fixed gap, the first centre's outer neighbour, the
    centres (with the gap between them, if any), the second's outer neighbour, a fixed gap; updated in place.
    """
    n_min, n_max, idle = window.n_min, window.n_max, window.idle_pulses
    g = ticks.shape[0]
    for off in PAIR_OFFSETS:
        roles = ("F", "O", "P") + ("M",) * (off - 1) + ("P", "O", "F")
        K = len(roles)
        for r in range(K):
            m = snap_up_ticks(ticks, n_min, n_max, idle)[1]
            above = m > m0
            c1 = np.flatnonzero(above[: g - off] & above[off:] & (np.arange(g - off) % K == r))
            c1 = c1[(c1 >= 2) & (c1 + off + 2 < g)]
            cruising = (q[c1] < 0.5) | (q[c1 + off] < 0.5)  # ramp fractions tried: their own batches
            for group in (c1[cruising], c1[~cruising]):
                if group.size:
                    gaps = group[:, None] + np.arange(-2, K - 2)[None]
                    _solve(gaps, roles, D, ticks, v, q, capm, capk, first, A, f, window)


def _solve(gaps, roles, D, ticks, v, q_out, capm, capk, first, A, f, window) -> None:
    """Solve the disjoint windows ``gaps`` ``(w, K)`` in batches of at most :data:`COMBINATIONS` combinations."""
    tk, qk = window_candidates(gaps, roles, ticks, q_out, first, window)
    step = max(1, COMBINATIONS // int(np.prod([t.shape[1] for t in tk], dtype=np.int64)))
    for i in range(0, gaps.shape[0], step):
        part = slice(i, i + step)
        _solve_batch(gaps[part], [t[part] for t in tk], [t[part] for t in qk], D, ticks, v, q_out, capm, capk, A, f)


def window_candidates(gaps, roles, ticks, q, first, window: PulseWindow) -> tuple[list, list]:
    """Each window gap's candidates by its role: ``(tk, qk)``, per position ``(w, C_j)`` counts and ramp fractions.

    ``gaps`` ``(w, K)``, ``ticks`` ``(g,)`` the plan, ``q`` ``(g,)`` its ramp fractions (two-phase gaps are
    given the lens, which holds every two-phase motion), ``first`` ``(g,)`` the shortest admissible counts.
    Roles: ``F`` fixed, ``E`` a single window's outer gap, ``N`` a centre's neighbour, ``C`` a centre (with its
    ramp fraction where it cruises), ``P`` one of a pair's centres, ``M`` the gap between them, ``O`` a pair's
    outer neighbour.
    """
    q = q.copy()
    q[gaps] = np.where(q[gaps] == 0.5, LENS_Q, q[gaps])
    tk, qk = [], []
    for j, role in enumerate(roles):
        gj = gaps[:, j]
        qs = q[gj, None]
        if role == "C":
            c = _centre_candidates(ticks[gj], first[gj], window)
            if np.any(q[gj] < 0.5):  # jumps that cruise: their ramp fraction is chosen with the counts
                qs = np.concatenate([qs, np.broadcast_to(np.array(Q_CHOICES), (gj.size, len(Q_CHOICES)))], 1)
        elif role == "P":
            c = _pair_candidates(ticks[gj], first[gj], window)
            cr = q[gj, None] < 0.5  # a cruising centre: a few ramp fractions (the others keep their own)
            if np.any(cr):
                qs = np.concatenate([qs, np.where(cr, np.array(PAIR_Q)[None], qs)], 1)
        elif role == "N":
            c = _neighbour_candidates(ticks[gj], first[gj], window)
        elif role == "M":
            c = _steps_candidates(ticks[gj], first[gj], window, PAIR_MIDDLE_STEPS, PAIR_MIDDLE_UP)
        elif role == "O":
            c = _steps_candidates(ticks[gj], first[gj], window, PAIR_OUTER_STEPS, ())
        elif role == "E":
            c = _steps_candidates(ticks[gj], first[gj], window, OUTER_STEPS, ())
        elif role == "R":
            c = _end_candidates(ticks[gj], first[gj], window)
        else:
            c = ticks[gj][:, None]
        tk.append(np.repeat(c, qs.shape[1], axis=1))
        qk.append(np.tile(qs, (1, c.shape[1])))
    return tk, qk


def meet(v_in, v_out, D, tk, qk, capm, capk, A, f):
    """Totals ``(w, Pf Pb)`` of every combination of candidates through windows between pinned velocities
    (``int64`` max where infeasible), ``s`` the split knot and ``Pb``.

    Meet in the middle: the speed intervals are propagated forward from the pinned entry ``v_in`` ``(w, 3)``
    through gaps ``0..s-1`` (:func:`_forward`) and backward — time reversed, speeds negated — from the pinned
    exit ``v_out`` through gaps ``K-1..s``; a combination is feasible exactly where the two intervals at knot
    ``s`` meet on every axis (each is the set of speeds there reachable from its end). The same answer as
    propagating every combination through the whole window, with ``Pf + Pb`` projections instead of ``Pf Pb``.
    Combination ``i`` is the forward one ``i // Pb`` (C order over gaps ``0..s-1``) with the backward ``i % Pb``
    (C order over gaps ``K-1..s``). Shapes as :func:`_forward`.
    """
    K = len(tk)
    s = K // 2 + 1
    okf, tf, lof, hif = _forward(v_in, D[:, :s], tk[:s], qk[:s], capm[:, :s], capk[:, : s + 1], A, f)
    rev = slice(K - 1, s - 1, -1)
    okb, tb, lob, hib = _forward(-v_out, -D[:, rev], tk[rev], qk[rev], capm[:, rev], capk[:, K : s - 1 : -1], A, f)
    lo, hi = lof[-1][:, :, None], hif[-1][:, :, None]  # (w, Pf, 1, 3)
    blo, bhi = -hib[-1][:, None], -lob[-1][:, None]  # (w, 1, Pb, 3)
    tol = EPS_MM_S * (1 + np.abs(lo))
    ok = okf[:, :, None] & okb[:, None, :] & np.all(np.maximum(lo, blo) <= np.minimum(hi, bhi) + tol, axis=-1)
    total = np.where(ok, tf[:, :, None] + tb[:, None, :], np.iinfo(np.int64).max)
    return total.reshape(v_in.shape[0], -1), s, tb.shape[1]


def _solve_batch(gaps, tk, qk, D, ticks, v, q_out, capm, capk, A, f) -> None:
    """Solve the disjoint windows ``gaps`` ``(w, K)``; ``ticks``, ``v``, ``q_out`` updated in place.

    Every combination of the gaps' candidates ``tk``, ``qk`` (:func:`window_candidates`) checked exactly
    (:func:`meet`); the least total kept where it is shorter than the plan's, its knot velocities picked
    backwards inside its forward intervals (:func:`_pick_back`).
    """
    K = gaps.shape[1]
    Dw, cmw = D[gaps], capm[gaps]
    ckw = capk[np.concatenate([gaps, gaps[:, -1:] + 1], axis=1)]
    v_in, v_out = v[gaps[:, 0]], v[gaps[:, -1] + 1]
    total, s, Pb = meet(v_in, v_out, Dw, tk, qk, cmw, ckw, A, f)
    rev = slice(K - 1, s - 1, -1)
    best = np.argmin(total, axis=1)
    gain = total[np.arange(len(gaps)), best] < ticks[gaps].sum(axis=1)
    if not np.any(gain):
        return
    w = np.flatnonzero(gain)
    pf, pb = np.divmod(best[w], Pb)
    idx = np.unravel_index(pf, [t.shape[1] for t in tk[:s]]) + np.unravel_index(pb, [t.shape[1] for t in tk[rev]])[::-1]
    new = np.stack([tk[j][w, idx[j]] for j in range(K)], axis=1)  # (w', K)
    newq = np.stack([qk[j][w, idx[j]] for j in range(K)], axis=1)
    # the chosen combination's forward intervals (one candidate per gap), then the velocities picked backwards
    ok1, _, los, his = _forward(v_in[w], Dw[w], list(new.T[:, :, None]), list(newq.T[:, :, None]), cmw[w], ckw[w], A, f)
    tol = EPS_MM_S * (1 + np.abs(v_out[w][:, None]))
    ok1 = ok1[:, 0] & np.all((los[-1] <= v_out[w][:, None] + tol) & (his[-1] >= v_out[w][:, None] - tol), axis=(1, 2))
    w, new, newq = w[ok1], new[ok1], newq[ok1]  # (a rounding slip at the split knot: that window keeps its plan)
    flo = np.stack([los[j][ok1, 0] for j in range(K + 1)], axis=1)
    fhi = np.stack([his[j][ok1, 0] for j in range(K + 1)], axis=1)
    vw = _pick_back(v_out[w], Dw[w], new, newq, cmw[w], ckw[w], flo, fhi, v[gaps[w]], A, f)
    ticks[gaps[w]] = new
    q_out[gaps[w]] = newq
    v[gaps[w, 1:]] = vw[:, 1:]


def _pick_back(v_out, D, ticks, q, capm, capk, flo, fhi, v_old, A, f):
    """Interior knot velocities ``(w, K, 3)`` (index 0, the pinned entry, unchanged) picked backwards.

    Knot ``j``'s velocity lies in its forward interval ``[flo, fhi]`` and reaches knot ``j+1``'s through gap
    ``j`` (the time-reversed :func:`~.bang.project` of that single speed): nearest the plan's old velocity.
    """
    K = ticks.shape[1]
    out = v_old.copy()
    nxt = v_out
    for j in range(K - 1, 0, -1):  # the window's few knots
        h = ticks[:, j, None] / f
        _, L, U = project(-nxt, -nxt, -D[:, j], h, A, capm[:, j], capk[:, j], q[:, j, None], xp=np)
        a, b = np.maximum(-U, flo[:, j]), np.minimum(-L, fhi[:, j])
        nxt = np.clip(v_old[:, j], a, np.maximum(a, b))
        out[:, j] = nxt
    return out
