"""Time-optimal speed along a fixed path in the phase plane ``(s, x = ṡ²)``, per-axis limits coupled.

On a grid interval of length ``Δ`` the path acceleration ``u = s̈`` is held constant, so ``x``
is linear in ``s``: ``x_b = x_a + 2 Δ u``. Axis ``i`` accelerates at ``q̈_i = q'_i u + q''_i x``
(:mod:`jaxcnc.planners.grid`). The limit ``|q̈_i| ≤ A_i`` is imposed at *both* ends of the interval
(at the end with ``x_b`` substituted), which makes every constraint linear in ``(u, x_a)``. Where
the grid gives an interval a *box* — bounds ``q'_i ∈ [T_lo, T_hi]``, ``q''_i ∈ [K_lo, K_hi]`` over the
whole interval (blends) — the rows use its corners: as ``x ≥ 0`` and ``x(s)`` lies between ``x_a``
and ``x_b``,

    T u + K_hi x ≤ A      and      -(T u + K_lo x) ≤ A      for T ∈ {T_lo, T_hi}, x ∈ {x_a, x_b}

bound ``q̈_i`` everywhere inside, so such an interval needs no check between its nodes. At a plain
end ``T_lo = T_hi`` and ``K_lo = K_hi`` are the values there. With the speed rows
``x_a + 2Δ u ≤ cap_b``, ``x_a + 2Δ u ≥ 0``, ``x_a ≤ cap_a`` these are rows ``gu·u + gx·x ≤ h`` of shape
``(m, R)``, four per axis. Tangential and centripetal acceleration share each axis' budget exactly, with their
signs (toppra's "interpolation" discretisation; its default collocation imposes the limit only at
the start, which is why its profiles overshoot between grid points).

What the planner needs, without a solver:

* every pair of a lower row ``j`` (``gu < 0``) and an upper row ``m`` (``gu > 0``) bounds ``x`` from
  above; their minimum is the largest admissible ``x`` at the interval's start (``static_cap``: the
  maximum-velocity curve, with both ends and the velocity caps);
* eliminating ``u`` between each lower row ``j`` and the row ``x_a + 2Δ u ≤ K_b`` gives
  the backward (controllable-set) step ``K_a = min(x_static, min_j (α_j K_b + β_j))``; the forward
  step takes the largest ``u`` at the reached ``x_a``. Both are one ``lax.scan`` over the intervals
  (on a CPU a sequential scan costs ~20 ns a step and compiles in milliseconds).

On lines (``K = 0``) every ``α_j = 1``: the steps reduce to
``min(B, x + D)`` and the look-ahead scan (:mod:`jaxcnc.planners.lookahead`) computes them.

A long program is planned in windows (:mod:`jaxcnc.planners.topp`): :func:`solve_window` starts from the
speed the window before reached and assumes rest after the window's end, and says up to which node that
assumption changes nothing (the backward step there depends on its own interval alone), so a window is kept
up to there and the next starts from that node — the same plan as the whole program at once.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.planners.lookahead import forward_pass

#: ``|gu|`` below this is treated as 0 (the row bounds ``x`` alone).
GU_EPS = 1e-12


Rows = tuple[list[jnp.ndarray], list[jnp.ndarray], list[jnp.ndarray]]


def constraint_rows(
    delta: jnp.ndarray,
    t_a: jnp.ndarray,
    k_a: jnp.ndarray,
    t_b: jnp.ndarray,
    k_b: jnp.ndarray,
    a_max: jnp.ndarray,
    cap_b: jnp.ndarray,
    box: tuple[jnp.ndarray, ...] | None = None,
) -> Rows:
    """Rows ``gu·u + gx·x_a ≤ h`` of every interval: three lists of ``4·n_axes + 2`` vectors ``(m,)``.

    Column lists rather than ``(m, R)`` matrices: every later step is elementwise over intervals, and
    XLA fuses lists of vectors into single passes (matrices it concatenates and transposes).

    Args:
        delta: ``(m,)`` interval lengths (mm); t_a, k_a, t_b, k_b: ``(m, n_axes)`` ``q'`` and ``q''`` at
            the start and the end, or sequences of ``n_axes`` columns ``(m,)`` (as every argument here).
        a_max: ``(m, n_axes)`` acceleration budget of each axis on each interval (mm/s²).
        cap_b: ``(m,)`` cap on ``x`` at the interval's end.
        box: optional ``(boxed (m,), t_lo, t_hi, k_lo, k_hi (m, n_axes))``: where ``boxed``, the rows
            hold for every ``q'`` and ``q''`` in the box. Each axis keeps four rows either way: in a
            box the rows of one side share ``gx`` (``K_hi`` resp. ``-K_lo``) and differ in ``gu`` alone
            (``T`` or ``T + 2Δ K`` for ``T`` in ``{T_lo, T_hi}``), so the largest and the smallest ``gu``
            imply the other two.
    The last two rows are ``x_b ≤ cap_b`` and ``x_b ≥ 0``.
    """
    two_d = 2.0 * delta
    gu, gx, h = [], [], []
    t_a, k_a, t_b, k_b, a_max = (_columns(x) for x in (t_a, k_a, t_b, k_b, a_max))
    if box is not None:
        box = (box[0],) + tuple(_columns(x) for x in box[1:])
    for i in range(len(t_a)):
        ta, ka, tb, kb = t_a[i], k_a[i], t_b[i], k_b[i]
        end_b = tb + two_d * kb
        rows = [(ta, ka), (end_b, kb), (-ta, -ka), (-end_b, -kb)]  # upper side at a, b; lower side at a, b
        if box is not None:
            boxed, t_lo, t_hi, k_lo, k_hi = (box[0],) + tuple(x[i] for x in box[1:])
            g_up = (t_lo, t_hi, t_lo + two_d * k_hi, t_hi + two_d * k_hi)
            g_lo = (-t_lo, -t_hi, -(t_lo + two_d * k_lo), -(t_hi + two_d * k_lo))
            in_box = [
                (_max4(g_up), k_hi),
                (_min4(g_up), k_hi),
                (_max4(g_lo), -k_lo),
                (_min4(g_lo), -k_lo),
            ]
            rows = [
                (jnp.where(boxed, bu, pu), jnp.where(boxed, bx, px))
                for (pu, px), (bu, bx) in zip(rows, in_box, strict=True)
            ]
        for u_coef, x_coef in rows:
            gu.append(u_coef)
            gx.append(x_coef)
            h.append(a_max[i])
    one = jnp.ones_like(delta)
    gu += [two_d, -two_d]
    gx += [one, -one]
    h += [cap_b, jnp.zeros_like(delta)]
    return gu, gx, h


def _columns(a) -> list:
    """The columns of an ``(m, n)`` array, or a sequence of ``(m,)`` columns as given."""
    return list(a) if isinstance(a, (list, tuple)) else [a[:, i] for i in range(a.shape[1])]


def _max4(v: tuple[jnp.ndarray, ...]) -> jnp.ndarray:
    return jnp.maximum(jnp.maximum(v[0], v[1]), jnp.maximum(v[2], v[3]))


def _min4(v: tuple[jnp.ndarray, ...]) -> jnp.ndarray:
    return jnp.minimum(jnp.minimum(v[0], v[1]), jnp.minimum(v[2], v[3]))


def _ratio(num: jnp.ndarray, den: jnp.ndarray, ok: jnp.ndarray) -> jnp.ndarray:
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), jnp.inf)


def static_cap(gu: list, gx: list, h: list, cap_a: jnp.ndarray) -> jnp.ndarray:
    """``(m,)`` largest ``x_a`` for which some ``u`` satisfies every row but ``x_b ≤ cap_b`` (Fourier–Motzkin).

    Every pair of a lower row ``j`` (``gu < 0``) and an upper row ``m`` (``gu > 0``) bounds ``x`` from
    above; so does a row without ``u``. The row ``x_b ≤ cap_b`` is left to the backward step, whose
    ``K_b`` never exceeds ``cap_b``: an interval that must slow down towards its end is entered
    faster than its end allows.
    """
    keep = [*range(len(gu) - 2), len(gu) - 1]  # the axis rows and x_b ≥ 0
    g, x, hh = ([a[c] for c in keep] for a in (gu, gx, h))
    up = [gi > GU_EPS for gi in g]
    lo = [gi < -GU_EPS for gi in g]
    safe = [jnp.where(up[i] | lo[i], g[i], 1.0) for i in range(len(g))]
    r = [x[i] / safe[i] for i in range(len(g))]  # u ≤ or ≥ c - r x, by the sign of gu
    c = [hh[i] / safe[i] for i in range(len(g))]
    best = cap_a
    for i in range(len(g)):  # rows without u bound x alone
        flat = ~up[i] & ~lo[i] & (x[i] > 0)
        best = jnp.minimum(best, jnp.where(flat, hh[i] / jnp.where(flat, x[i], 1.0), jnp.inf))
    # u ≤ c_m - r_m x (upper m) and u ≥ c_j - r_j x (lower j): x (r_m - r_j) ≤ c_m - c_j
    for a in range(len(g)):
        for b in range(a + 1, len(g)):
            a_up = up[a] & lo[b]
            coef = jnp.where(a_up, r[a] - r[b], r[b] - r[a])
            rhs = jnp.where(a_up, c[a] - c[b], c[b] - c[a])
            ok = (a_up | (up[b] & lo[a])) & (coef > 0)
            best = jnp.minimum(best, jnp.where(ok, rhs / jnp.where(ok, coef, 1.0), jnp.inf))
    return jnp.maximum(best, 0.0)


class Band(NamedTuple):
    """One axis and end of :func:`constraint_rows` without a box (each field ``(m,)``); see :func:`_bands`."""

    active: jnp.ndarray  # |T| > GU_EPS: the rows bound u
    t: jnp.ndarray  # T with the sign of the band's first row
    t_abs: jnp.ndarray  # |T| where active, else 1
    r: jnp.ndarray  # K/T
    w: jnp.ndarray  # A/|T|
    a: jnp.ndarray  # A
    k: jnp.ndarray  # K with the sign of the band's first row


def _bands(gu: list, gx: list, h: list) -> list[Band]:
    """The axis rows of :func:`constraint_rows` without a box as *bands*, one per axis and end.

    Without a box an axis' four rows are ``±(T u + K x) ≤ A`` at the start and at the end: the same ``T``,
    ``K`` with both signs, i.e. ``|T u + K x| ≤ A``, the band ``u ∈ [-w - r x, w - r x]`` with ``r = K/T``
    and ``w = A/|T|`` where ``|T| > GU_EPS``. ``r`` and ``w`` are computed with exactly the operations the
    row-pair forms use (``(-K)/(-T)`` is ``K/T`` in floating point, ``-A/(-|T|)`` is ``A/|T|``), so the band
    forms below give the same bits (compiled, a pass may still contract a multiply-add differently: the plan
    agrees to the last bit or so).
    """
    bands = []
    for i in range(0, len(gu) - 2, 4):
        for t, k, a in ((gu[i], gx[i], h[i]), (gu[i + 1], gx[i + 1], h[i + 1])):
            active = jnp.abs(t) > GU_EPS
            t_abs = jnp.where(active, jnp.abs(t), 1.0)
            bands.append(Band(active, t, t_abs, k / jnp.where(active, t, 1.0), a / t_abs, a, k))
    return bands


def static_cap_bands(gu: list, gx: list, h: list, cap_a: jnp.ndarray) -> jnp.ndarray:
    """:func:`static_cap` of rows without a box, from the bands (the same value; ~a quarter of the work).

    Two bands ``p, q`` leave some ``u`` iff ``w_p - r_p x ≥ -w_q - r_q x`` both ways, i.e.
    ``x |r_p - r_q| ≤ w_p + w_q`` (the pairs of one band's upper with the other's lower row); a band with
    ``|T| ≤ GU_EPS`` bounds ``x`` alone, ``|K| x ≤ A``; the row ``x_b ≥ 0`` is the lower row
    ``u ≥ -x/(2Δ)`` (``r_z = 1/(2Δ)``, ``w_z = 0``), against each band's upper row
    ``x (r_p - r_z) ≤ w_p``. Pairs within one band have ``r_p = r_q`` and bound nothing.
    """
    bands = _bands(gu, gx, h)
    best = cap_a
    for b in bands:  # |T| ≤ GU_EPS: the rows bound x alone, |K| x ≤ A
        flat = ~b.active & (jnp.abs(b.k) > 0)
        best = jnp.minimum(best, jnp.where(flat, b.a / jnp.where(flat, jnp.abs(b.k), 1.0), jnp.inf))
    for p in range(len(bands)):
        bp = bands[p]
        for bq in bands[p + 1 :]:
            coef = jnp.abs(bp.r - bq.r)
            ok = bp.active & bq.active & (coef > 0)
            best = jnp.minimum(best, jnp.where(ok, (bp.w + bq.w) / jnp.where(ok, coef, 1.0), jnp.inf))
    two_d = -gu[-1]  # the row x_b ≥ 0 is (-2Δ) u + (-1) x ≤ 0
    z_on = two_d > GU_EPS
    r_z = gx[-1] / jnp.where(z_on, gu[-1], 1.0)
    for b in bands:
        coef = b.r - r_z
        ok = b.active & z_on & (coef > 0)
        best = jnp.minimum(best, jnp.where(ok, b.w / jnp.where(ok, coef, 1.0), jnp.inf))
    return jnp.maximum(best, 0.0)


def backward_pieces(gu: list, gx: list, h: list, delta: jnp.ndarray) -> tuple[list, list]:
    """Slopes and intercepts (lists of ``(m,)``): ``K_a = min(x_static, min_j (α_j K_b + β_j))``.

    Lower row ``j`` with the row ``x_a + 2Δ u ≤ K_b``: ``x (1/(2Δ) - gx_j/gu_j) ≤ K_b/(2Δ) - h_j/gu_j``.
    Rows that give no upper bound have ``α = 0, β = inf``.
    """
    inv = jnp.where(delta > 0, 0.5 / jnp.where(delta > 0, delta, 1.0), 0.0)
    alpha, beta = [], []
    for g, x, hh in zip(gu[:-2], gx[:-2], h[:-2], strict=True):
        lo = g < -GU_EPS
        coef = inv - jnp.where(lo, x / jnp.where(lo, g, 1.0), 0.0)
        use = lo & (coef > 0) & (inv > 0)
        alpha.append(jnp.where(use, inv / jnp.where(use, coef, 1.0), 0.0))
        beta.append(jnp.where(use, -hh / jnp.where(use, g * coef, 1.0), jnp.inf))
    return alpha, beta


def forward_pieces(gu: list, gx: list, h: list, delta: jnp.ndarray) -> tuple[list, list]:
    """Slopes and intercepts (lists of ``(m,)``) of the forward step ``x_b = min_m (A_m x_a + B_m)``.

    The largest ``u`` an upper row ``m`` allows at ``x_a`` is ``(h_m - gx_m x_a) / gu_m``, so
    ``x_b = x_a + 2Δ u`` is affine in ``x_a``; rows that are not upper have ``A = 0, B = inf``.
    """
    a_list, b_list = [], []
    for g, x, hh in zip(gu, gx, h, strict=True):
        up = g > GU_EPS
        inv = jnp.where(up, 2.0 * delta / jnp.where(up, g, 1.0), 0.0)
        a_list.append(jnp.where(up, 1.0 - x * inv, 0.0))
        b_list.append(jnp.where(up, hh * inv, jnp.inf))
    return a_list, b_list


def backward_pieces_bands(gu: list, gx: list, h: list, delta: jnp.ndarray) -> tuple[list, list]:
    """:func:`backward_pieces` of rows without a box: one piece per band (its lower row), the same step."""
    inv = jnp.where(delta > 0, 0.5 / jnp.where(delta > 0, delta, 1.0), 0.0)
    alpha, beta = [], []
    for b in _bands(gu, gx, h):
        coef = inv - jnp.where(b.active, b.r, 0.0)
        use = b.active & (coef > 0) & (inv > 0)
        alpha.append(jnp.where(use, inv / jnp.where(use, coef, 1.0), 0.0))
        beta.append(jnp.where(use, b.a / jnp.where(use, b.t_abs * coef, 1.0), jnp.inf))
    return alpha, beta


def forward_pieces_bands(gu: list, gx: list, h: list, delta: jnp.ndarray) -> tuple[list, list]:
    """:func:`forward_pieces` of rows without a box: one piece per band (its upper row) and the row
    ``x_b ≤ cap_b``, the same step."""
    a_list, b_list = [], []
    for b in _bands(gu, gx, h):
        inv = jnp.where(b.active, 2.0 * delta / b.t_abs, 0.0)
        a_list.append(jnp.where(b.active, 1.0 - jnp.where(b.t > 0, b.k, -b.k) * inv, 0.0))
        b_list.append(jnp.where(b.active, b.a * inv, jnp.inf))
    a_cap, b_cap = forward_pieces(gu[-2:-1], gx[-2:-1], h[-2:-1], delta)
    return a_list + a_cap, b_list + b_cap


def backward_scan(
    x_static: jnp.ndarray, alpha: list, beta: list, x_end: jnp.ndarray, cap_b: jnp.ndarray | None = None
) -> jnp.ndarray:
    """``(m+1,)`` the controllable set's upper ends: the largest ``x`` from which the end is reachable.

    ``cap_b``: ``(m,)`` each interval's own cap at its end, where it is lower than the next interval's
    cap at its start (a node between two intervals may be capped differently by each).
    """
    if cap_b is None:
        cap_b = jnp.full(x_static.shape, jnp.inf)

    _, k = jax.lax.scan(_backward_step, x_end, (x_static, alpha, beta, cap_b), reverse=True)
    return jnp.concatenate([k, x_end[None]])


def _backward_step_exact(k_next, row):
    """:func:`_backward_step`, also saying whether ``K_a`` is the row's ``F_j(∞)`` (see :func:`solve_window`).

    Inside the step rather than after the scan: XLA would fuse a second evaluation of :func:`static_cap`
    into an expression of the scan's inputs.
    """
    xs, a, b, cb = row
    k_a, _ = _backward_step(k_next, row)
    unbounded = xs
    for aj, bj in zip(a, b, strict=True):
        unbounded = jnp.minimum(unbounded, jnp.where(aj > 0, aj * cb + bj, bj))
    return k_a, (k_a, k_a >= unbounded)


def _backward_step(k_next, row):
    """One backward step: ``K_a = min(x_static, min_j (α_j min(K_b, cap_b) + β_j))``."""
    xs, a, b, cb = row
    k_b = jnp.minimum(k_next, cb)
    k_a = xs
    for aj, bj in zip(a, b, strict=True):
        k_a = jnp.minimum(k_a, aj * k_b + bj)
    return k_a, k_a


def forward_scan(
    a: list, b: list, delta: jnp.ndarray, k: jnp.ndarray, x_start: jnp.ndarray | float = 0.0
) -> jnp.ndarray:
    """``(m+1,)`` ``x`` at the nodes: from ``x_start`` (rest by default), the largest admissible ``u`` on
    each interval."""
    x0 = jnp.minimum(jnp.asarray(x_start, k.dtype), k[0])
    _, x = jax.lax.scan(_forward_step, x0, (a, b, delta, k[1:]))
    return jnp.concatenate([x0[None], x])


def _forward_step(x_a, row):
    """One forward step: ``x_b = clip(min_m (A_m x_a + B_m), 0, K_b)`` (``x_a`` kept on a point)."""
    ar, br, d, k_b = row
    reach = jnp.inf
    for am, bm in zip(ar, br, strict=True):
        reach = jnp.minimum(reach, am * x_a + bm)
    x_b = jnp.where(d > 0, reach, x_a)
    x_b = jnp.clip(x_b, 0.0, k_b)
    return x_b, x_b


def line_reach(gu: list, h: list, delta: jnp.ndarray) -> jnp.ndarray:
    """``(m,)`` reach ``2 Δ a_t`` of intervals without curvature (``gx = 0`` on the axis rows)."""
    a_t = jnp.full(delta.shape, jnp.inf)
    for g, hh in zip(gu[:-2], h[:-2], strict=True):
        a_t = jnp.minimum(a_t, _ratio(hh, g, g > GU_EPS))
    return jnp.where(delta > 0, 2.0 * delta * a_t, 0.0)


def solve(
    rows: Rows,
    delta: jnp.ndarray,
    cap_a: jnp.ndarray,
    x_end: jnp.ndarray,
    curved: bool,
) -> jnp.ndarray:
    """``(m+1,)`` time-optimal ``x`` at the nodes under the rows (``curved`` static: any ``K ≠ 0``)."""
    return solve_window(rows, delta, cap_a, x_end, curved)[0]


def solve_window(
    rows: Rows,
    delta: jnp.ndarray,
    cap_a: jnp.ndarray,
    x_end: jnp.ndarray,
    curved: bool,
    x_start: jnp.ndarray | float = 0.0,
    bands: bool = False,
) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """:func:`solve` from ``x_start`` at the first node, and which nodes do not depend on ``x_end``.

    Returns ``(x, exact, k0)``: ``x`` ``(m+1,)``; ``exact`` ``(m,)`` bool, the backward step at node ``j``
    took its value from the rows of interval ``j`` alone — the controllable set there would be the same for
    any larger ``x_end`` (the step ``K_j = F_j(K_{j+1})`` is non-decreasing in ``K_{j+1}``, and here
    ``F_j(K_{j+1}) = F_j(∞)``), so ``x`` at every node up to the last such ``j`` is that of the whole
    program, whatever follows the window; ``k0``: the controllable set's end at the first node (below
    ``x_start`` where the window is too short to stop from there). ``bands`` (static): no interval has a
    box, so the band forms (:func:`static_cap_bands`, ...) give the same values with a quarter of the work.
    """
    gu, gx, h = rows
    cap_b = h[-2]
    if curved:
        return solve_pieces(window_pieces(rows, delta, cap_a, bands), x_end, x_start)
    # Lines only (gx = 0 on the axis rows): the node caps and min(B, x + D) in both directions.
    node_cap = jnp.concatenate([cap_a, x_end[None]])
    node_cap = node_cap.at[1:].min(cap_b)  # x_b ≤ cap_b
    zero = jnp.zeros((1,), delta.dtype)
    reach = line_reach(gu, h, delta)
    back = forward_pass(node_cap[::-1], jnp.concatenate([zero, reach[::-1]]))[::-1]
    x = forward_pass(back.at[0].min(x_start), jnp.concatenate([zero, reach]))
    return x, back[:-1] >= node_cap[:-1], back[0]


def window_pieces(rows: Rows, delta: jnp.ndarray, cap_a: jnp.ndarray, bands: bool = False) -> dict:
    """What the two passes of a curved window read, each ``(m,)`` (lists of them for the pieces).

    ``x_static``, the backward pieces ``alpha``/``beta``, ``cap_b``, the forward pieces ``a``/``b``.
    Elementwise work over the whole window, meant to be compiled apart from the passes
    (:func:`solve_pieces`): XLA's CPU backend copies an elementwise producer into each of its consumers, so
    compiled with anything more that reads ``x_static`` or the pieces (the scans, each node's ``F_j(∞)``)
    the divisions of the static cap and the pieces are computed two or three times over (measured: 2–3×
    the time of this alone).
    """
    gu, gx, h = rows
    cap_fn, back_fn, fwd_fn = _forms(bands)
    cap_b = h[-2]
    x_static = cap_fn(gu, gx, h, cap_a)
    alpha, beta = back_fn(gu, gx, h, delta)
    a_fwd, b_fwd = fwd_fn(gu, gx, h, delta)
    return dict(x_static=x_static, alpha=alpha, beta=beta, cap_b=cap_b, a=a_fwd, b=b_fwd, delta=delta)


def solve_pieces(
    pieces: dict, x_end: jnp.ndarray, x_start: jnp.ndarray | float = 0.0
) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """:func:`solve_window` (curved) from :func:`window_pieces`: the backward and the forward scan."""
    x_static, alpha, beta, cap_b = (pieces[k] for k in ("x_static", "alpha", "beta", "cap_b"))
    k = backward_scan(x_static, alpha, beta, x_end, cap_b)
    unbounded = x_static  # F_j(∞): each term with K_{j+1} replaced by its own end cap
    for a, b in zip(alpha, beta, strict=True):
        unbounded = jnp.minimum(unbounded, jnp.where(a > 0, a * cap_b + b, b))
    x = forward_scan(pieces["a"], pieces["b"], pieces["delta"], k, x_start)
    return x, k[:-1] >= unbounded, k[0]


def _forms(bands: bool) -> tuple[Callable, Callable, Callable]:
    """The static cap and the pieces: the band forms where no interval has a box, else the row-pair forms."""
    if bands:
        return static_cap_bands, backward_pieces_bands, forward_pieces_bands
    return static_cap, backward_pieces, forward_pieces
