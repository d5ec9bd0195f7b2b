"""Time-optimal speed along a fixed path in the phase plane ``(s, x = ṡ²)``, per-axis limits coupled.

On a grid interval of length ``Δ`` the path acceleration ``u = s̈`` is held constant, so ``x``
is linear in ``s``: ``x_b = x_a + 2 Δ u``. Axis ``i`` accelerates at ``q̈_i = T_i u + K_i x``
(:mod:`jaxcnc.planners.grid`); the limit ``|q̈_i| ≤ A_i`` is imposed at *both* ends of the
interval (at the end with ``x_b`` substituted), which makes every constraint linear in ``(u, x_a)``:

    ±( T_ia u + K_ia x_a )                  ≤ A_i      (start)
    ±( (T_ib + 2Δ K_ib) u + K_ib x_a )      ≤ A_i      (end)
    x_a + 2Δ u ≤ cap_b,   x_a + 2Δ u ≥ 0,   x_a ≤ cap_a

— rows ``gu·u + gx·x ≤ h`` of shape ``(m, R)``. Tangential and centripetal acceleration share
each axis' budget exactly, with their signs (toppra's "interpolation" discretisation; its
default collocation imposes the limit only at the start, which is why its profiles overshoot
between grid points).

Eliminating ``u`` (Fourier–Motzkin) gives what the planner needs without a solver:

* every pair of a lower row ``j`` (``gu < 0``) and an upper row ``m`` (``gu > 0``) bounds ``x``
  from above; their minimum is the largest admissible ``x`` at the interval's start
  (``static_cap``: the maximum-velocity curve, with both ends and the velocity caps);
* the pairs formed with the row ``x_a + 2Δ u ≤ K_b`` give the backward (controllable-set) step
  ``K_a = min(x_static, min_j (α_j K_b + β_j))``; the forward step takes the largest ``u``
  at the reached ``x_a``. Both are one ``lax.scan`` over the intervals.

On lines (``K = 0``) every ``α_j = 1``: the steps reduce to ``min(B, x + D)`` and the
associative look-ahead scan (:mod:`jaxcnc.planners.lookahead`) computes them in O(log m) depth.
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
) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """Rows ``gu·u + gx·x_a ≤ h`` of every interval, each ``(m, 4·n_axes + 2)``.

    Args:
        delta: ``(m,)`` interval lengths (mm); t_a, k_a, t_b, k_b: ``(m, n_axes)`` frames at the ends.
        a_max: ``(m, n_axes)`` acceleration budget of each axis on each interval (mm/s²).
        cap_b: ``(m,)`` cap on ``x`` at the interval's end.
    """
    two_d = 2.0 * delta[:, None]
    gu_end = t_b + two_d * k_b
    gu = jnp.concatenate([t_a, -t_a, gu_end, -gu_end, two_d, -two_d], axis=1)
    gx = jnp.concatenate([k_a, -k_a, k_b, -k_b, jnp.ones_like(two_d), -jnp.ones_like(two_d)], axis=1)
    h = jnp.concatenate([a_max, a_max, a_max, a_max, cap_b[:, None], jnp.zeros_like(two_d)], axis=1)
    return gu, gx, h


def _ratio(num: jnp.ndarray, den: jnp.ndarray, ok: jnp.ndarray) -> jnp.ndarray:
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), jnp.inf)


def static_cap(gu: jnp.ndarray, gx: jnp.ndarray, h: jnp.ndarray, cap_a: jnp.ndarray) -> jnp.ndarray:
    """``(m,)`` largest ``x_a`` for which some ``u`` satisfies all rows (Fourier–Motzkin on ``u``)."""
    up = gu > GU_EPS
    lo = gu < -GU_EPS
    flat = ~up & ~lo
    x_flat = jnp.min(_ratio(h, gx, flat & (gx > 0)), axis=1)
    # u ≤ (h_m - gx_m x)/gu_m and u ≥ (h_j - gx_j x)/gu_j: x (gx_m/gu_m - gx_j/gu_j) ≤ h_m/gu_m - h_j/gu_j
    r_up = jnp.where(up, gx / jnp.where(up, gu, 1.0), 0.0)
    c_up = jnp.where(up, h / jnp.where(up, gu, 1.0), 0.0)
    r_lo = jnp.where(lo, gx / jnp.where(lo, gu, 1.0), 0.0)
    c_lo = jnp.where(lo, h / jnp.where(lo, gu, 1.0), 0.0)
    coef = r_up[:, None, :] - r_lo[:, :, None]  # (m, lower j, upper m)
    rhs = c_up[:, None, :] - c_lo[:, :, None]
    pair = lo[:, :, None] & up[:, None, :] & (coef > 0)
    x_pair = jnp.min(_ratio(rhs, coef, pair), axis=(1, 2))
    return jnp.maximum(jnp.minimum(jnp.minimum(cap_a, x_flat), x_pair), 0.0)


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
