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
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.planners.lookahead import lookahead

#: ``|gu|`` below this is treated as 0 (the row bounds ``x`` alone).
GU_EPS = 1e-12


def constraint_rows(
    delta: jnp.ndarray,
    t_a: jnp.ndarray,
    k_a: jnp.ndarray,
    t_b: jnp.ndarray,
    k_b: jnp.ndarray,
    a_max: jnp.ndarray,
    cap_b: jnp.ndarray,
    box: tuple[jnp.ndarray, ...] | None = None,
) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """Rows ``gu·u + gx·x_a ≤ h`` of every interval, each ``(m, 4·n_axes + 2)``.

    Args:
        delta: ``(m,)`` interval lengths (mm); t_a, k_a, t_b, k_b: ``(m, n_axes)`` ``q'`` and ``q''`` at
            the start and the end.
        a_max: ``(m, n_axes)`` acceleration budget of each axis on each interval (mm/s²).
        cap_b: ``(m,)`` cap on ``x`` at the interval's end.
        box: optional ``(boxed (m,), t_lo, t_hi, k_lo, k_hi (m, n_axes))``: where ``boxed``, the rows
            hold for every ``q'`` and ``q''`` in the box. Each axis keeps four rows either way: in a
            box the rows of one side share ``gx`` (``K_hi`` resp. ``-K_lo``) and differ in ``gu`` alone
            (``T`` or ``T + 2Δ K`` for ``T`` in ``{T_lo, T_hi}``), so the largest and the smallest ``gu``
            imply the other two.
    """
    two_d = 2.0 * delta[:, None]
    up = [(t_a, k_a), (t_b + two_d * k_b, k_b)]
    lo = [(-t_a, -k_a), (-(t_b + two_d * k_b), -k_b)]
    if box is not None:
        boxed, t_lo, t_hi, k_lo, k_hi = box
        b = boxed[:, None]
        g_up = [t_lo, t_hi, t_lo + two_d * k_hi, t_hi + two_d * k_hi]
        g_lo = [-t_lo, -t_hi, -(t_lo + two_d * k_lo), -(t_hi + two_d * k_lo)]
        box_up = [
            (jnp.maximum(jnp.maximum(g_up[0], g_up[1]), jnp.maximum(g_up[2], g_up[3])), k_hi),
            (jnp.minimum(jnp.minimum(g_up[0], g_up[1]), jnp.minimum(g_up[2], g_up[3])), k_hi),
        ]
        box_lo = [
            (jnp.maximum(jnp.maximum(g_lo[0], g_lo[1]), jnp.maximum(g_lo[2], g_lo[3])), -k_lo),
            (jnp.minimum(jnp.minimum(g_lo[0], g_lo[1]), jnp.minimum(g_lo[2], g_lo[3])), -k_lo),
        ]
        up = [(jnp.where(b, bu, pu), jnp.where(b, bx, px)) for (pu, px), (bu, bx) in zip(up, box_up, strict=True)]
        lo = [(jnp.where(b, bu, pu), jnp.where(b, bx, px)) for (pu, px), (bu, bx) in zip(lo, box_lo, strict=True)]
    rows = up + lo
    gu = [r[0] for r in rows] + [two_d, -two_d]
    gx = [r[1] for r in rows] + [jnp.ones_like(two_d), -jnp.ones_like(two_d)]
    h = [a_max] * len(rows) + [cap_b[:, None], jnp.zeros_like(two_d)]
    return jnp.concatenate(gu, axis=1), jnp.concatenate(gx, axis=1), jnp.concatenate(h, axis=1)


def _ratio(num: jnp.ndarray, den: jnp.ndarray, ok: jnp.ndarray) -> jnp.ndarray:
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), jnp.inf)


def static_cap(gu: jnp.ndarray, gx: jnp.ndarray, h: jnp.ndarray, cap_a: jnp.ndarray) -> jnp.ndarray:
    """``(m,)`` largest ``x_a`` for which some ``u`` satisfies every row but ``x_b ≤ cap_b`` (Fourier–Motzkin).

    Every pair of a lower row ``j`` (``gu < 0``) and an upper row ``m`` (``gu > 0``) bounds ``x`` from
    above; so does a row without ``u``. The row ``x_b ≤ cap_b`` is left to the backward step, whose
    ``K_b`` never exceeds ``cap_b``: an interval that must slow down towards its end is entered
    faster than its end allows.
    """
    n_rows = gu.shape[1]
    cols = [*range(n_rows - 2), n_rows - 1]  # the axis rows and x_b ≥ 0
    g, x, hh = ([a[:, c] for c in cols] for a in (gu, gx, h))
    up = [gi > GU_EPS for gi in g]
    lo = [gi < -GU_EPS for gi in g]
    safe = [jnp.where(up[i] | lo[i], g[i], 1.0) for i in range(len(g))]
    r = [x[i] / safe[i] for i in range(len(g))]  # u ≤ or ≥ c - r x, by the sign of gu
    c = [hh[i] / safe[i] for i in range(len(g))]
    best = cap_a
    for i in range(len(g)):  # rows without u bound x alone
        flat = ~up[i] & ~lo[i] & (x[i] > 0)
        best = jnp.minimum(best, jnp.where(flat, hh[i] / jnp.where(flat, x[i], 1.0), jnp.inf))
    # u ≤ c_m - r_m x (upper m) and u ≥ c_j - r_j x (lower j): x (r_m - r_j) ≤ c_m - c_j. The pairs are
    # unrolled: XLA fuses them into one pass over the intervals (an (m, R, R) tensor would not be).
    for a in range(len(g)):
        for b in range(a + 1, len(g)):
            a_up = up[a] & lo[b]
            coef = jnp.where(a_up, r[a] - r[b], r[b] - r[a])
            rhs = jnp.where(a_up, c[a] - c[b], c[b] - c[a])
            ok = (a_up | (up[b] & lo[a])) & (coef > 0)
            best = jnp.minimum(best, jnp.where(ok, rhs / jnp.where(ok, coef, 1.0), jnp.inf))
    return jnp.maximum(best, 0.0)


def backward_pieces(
    gu: jnp.ndarray, gx: jnp.ndarray, h: jnp.ndarray, delta: jnp.ndarray
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Slopes and intercepts ``(m, R)``: ``K_a = min(x_static, min_j (α_j K_b + β_j))``.

    Lower row ``j`` with the row ``x_a + 2Δ u ≤ K_b``: ``x (1/(2Δ) - gx_j/gu_j) ≤ K_b/(2Δ) - h_j/gu_j``.
    Rows that give no upper bound have ``α = 0, β = inf``.
    """
    lo = gu < -GU_EPS
    inv = jnp.where(delta > 0, 0.5 / jnp.where(delta > 0, delta, 1.0), 0.0)[:, None]
    coef = inv - jnp.where(lo, gx / jnp.where(lo, gu, 1.0), 0.0)
    use = lo & (coef > 0) & (inv > 0)
    alpha = jnp.where(use, inv / jnp.where(use, coef, 1.0), 0.0)
    beta = jnp.where(use, -h / jnp.where(use, gu * coef, 1.0), jnp.inf)
    return alpha, beta


def backward_scan(x_static: jnp.ndarray, alpha: jnp.ndarray, beta: jnp.ndarray, x_end: jnp.ndarray) -> jnp.ndarray:
    """``(m+1,)`` the controllable set's upper ends: the largest ``x`` from which the end is reachable."""

    def step(k_b, row):
        xs, a, b = row
        k_a = jnp.minimum(xs, jnp.min(a * k_b + b))
        return k_a, k_a

    _, k = jax.lax.scan(step, x_end, (x_static, alpha, beta), reverse=True)
    return jnp.concatenate([k, x_end[None]])


def forward_scan(gu: jnp.ndarray, gx: jnp.ndarray, h: jnp.ndarray, delta: jnp.ndarray, k: jnp.ndarray) -> jnp.ndarray:
    """``(m+1,)`` ``x`` at the nodes: from rest, the largest admissible ``u`` on each interval."""
    up = gu > GU_EPS
    inv_up = jnp.where(up, 1.0 / jnp.where(up, gu, 1.0), 0.0)

    def step(x_a, row):
        iu, gxr, hr, d, k_b = row
        u = jnp.min(jnp.where(iu != 0, (hr - gxr * x_a) * iu, jnp.inf))
        x_b = jnp.where(d > 0, x_a + 2.0 * d * jnp.minimum(u, 1e300), x_a)
        x_b = jnp.clip(x_b, 0.0, k_b)
        return x_b, x_b

    x0 = jnp.minimum(jnp.zeros((), k.dtype), k[0])
    _, x = jax.lax.scan(step, x0, (inv_up, gx, h, delta, k[1:]))
    return jnp.concatenate([x0[None], x])


def line_reach(gu: jnp.ndarray, h: jnp.ndarray, delta: jnp.ndarray) -> jnp.ndarray:
    """``(m,)`` reach ``2 Δ a_t`` of intervals without curvature (``gx = 0`` on the axis rows)."""
    up = gu > GU_EPS
    a_t = jnp.min(_ratio(h, gu, up), axis=1)
    return jnp.where(delta > 0, 2.0 * delta * a_t, 0.0)


def solve(
    gu: jnp.ndarray,
    gx: jnp.ndarray,
    h: jnp.ndarray,
    delta: jnp.ndarray,
    cap_a: jnp.ndarray,
    x_end: jnp.ndarray,
    curved: bool,
) -> jnp.ndarray:
    """``(m+1,)`` time-optimal ``x`` at the nodes under the rows (``curved`` static: any ``K ≠ 0``)."""
    if curved:
        x_static = static_cap(gu, gx, h, cap_a)
        alpha, beta = backward_pieces(gu, gx, h, delta)
        k = backward_scan(x_static, alpha, beta, x_end)
        return forward_scan(gu, gx, h, delta, k)
    # Lines only (gx = 0 on the axis rows): the node caps and min(B, x + D) in both directions.
    node_cap = jnp.concatenate([cap_a, x_end[None]])
    node_cap = node_cap.at[1:].min(h[:, -2])  # x_b ≤ cap_b
    return lookahead(node_cap, line_reach(gu[:, :-2], h[:, :-2], delta))
