"""The per-blend arithmetic of :mod:`jaxcnc.geometry.blend` as one jitted kernel over all blends.

A blend is a quintic Bézier (weights 1). Everything a blend span needs — its arc length, its timing
polynomial, how far its path parameter strays from arc length, the maxima of ``|q'|``, ``|q''|`` and
the curvature, its hull, and its distance to the two straight pieces it replaces — is a fixed
amount of arithmetic per blend, so the kernel is elementwise over blends and XLA fuses it into a
few passes (100k blends in tens of milliseconds; the same in NumPy allocates ``(J, points, 3)``
temporaries at every step and takes seconds). Shapes are padded to buckets by the caller.

Formulas as in :mod:`jaxcnc.geometry.poly` (arc length by 16-point Gauss–Legendre, the quintic
Hermite timing polynomial from the end derivatives) — written here for polynomial pieces, in
closed form where the control points give it: ``P'(0) = 5 (P1 - P0)``, ``P''(0) = 20 (P2 - 2 P1 + P0)``.
"""

from __future__ import annotations

from functools import cache
from math import comb

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.geometry import poly
from jaxcnc.jitcache import cached_jit, remembered

#: Points where a blend's parameter speed and maxima are checked (its check points).
N_CHECK = 9
#: Newton steps for the point where a blend crosses its corner's bisecting plane, and the largest
#: distance from that plane (mm) at which the point found counts as the crossing.
CROSS_NEWTON = 6
CROSS_RESIDUAL_MM = 1e-9
#: The widest gap between a blend's distance samples (the ends and the 16 quadrature nodes), and where
#: beside the crossing the distance is measured too, in that gap.
H_MAX = float(np.max(np.diff(np.concatenate([[0.0], poly._GX, [1.0]]))))
CROSS_LADDER = (1 / 4, 1 / 32)

_M5 = np.array([[comb(5, k) * comb(k, i) * (-1) ** (k - i) for i in range(6)] for k in range(6)], float)
_GX, _GW = poly._GX, poly._GW


def _horner(c: list[jnp.ndarray], u, order: int) -> list[jnp.ndarray]:
    """``[f, f', ...]`` of ``sum_k c[k] u^k`` (``c[k]`` arrays, ``u`` broadcastable)."""
    deg = len(c) - 1
    d = [c[deg] + 0 * u] + [jnp.zeros_like(c[0] * u) for _ in range(order)]
    for k in range(deg - 1, -1, -1):
        for r in range(min(order, deg - k), 0, -1):
            d[r] = d[r] * u + d[r - 1]
        d[0] = d[0] * u + c[k]
    fact = 1.0
    for r in range(2, order + 1):
        fact *= r
        d[r] = d[r] * fact
    return d


#: XLA:CPU hands reductions and small dots to its YNNPACK fusions by default; on a blend's handful of
#: values per row (sums of 3 squares, a 6×6 basis change) they cost more than XLA's own loops: the kernel
#: of 65,536 blends 0.24 → 0.10 s CPU without them (the same formulas; sums in another order, so results
#: differ in the last bits).
_NO_YNN = {"xla_cpu_experimental_ynn_fusion_type": ""}


@cache
def cpu_loop_options() -> dict[str, str]:
    """Compiler options that keep XLA:CPU's YNNPACK fusions out of small elementwise kernels (``{}`` where this
    jaxlib does not know the option). Probed by a compile once per jaxlib and cache directory
    (:func:`~jaxcnc.jitcache.remembered`): in a process that loads its executables, the probe's lowering and
    compile were ~0.1 s of a warm 'jaxcnc plan'."""
    return dict(_NO_YNN) if remembered("xla-cpu-ynn-fusion-option", _knows_no_ynn) else {}


def _knows_no_ynn() -> bool:
    try:
        jax.jit(lambda x: x + 1.0, compiler_options=_NO_YNN).lower(1.0).compile()
    except jax.errors.JaxRuntimeError:
        return False
    return True


def blend_kernel(pts: jnp.ndarray, corner: jnp.ndarray) -> dict[str, jnp.ndarray]:
    """:func:`_blend_kernel` compiled with :func:`cpu_loop_options`; the arrays as it documents."""
    return _compiled(_blend_kernel)(pts, corner)


@cache
def _compiled(fn, *static: str):
    """``fn`` jitted with :func:`cpu_loop_options` (arguments ``static`` static)."""
    return cached_jit(fn, static_argnames=static, compiler_options=cpu_loop_options())


def _blend_kernel(pts: jnp.ndarray, corner: jnp.ndarray) -> dict[str, jnp.ndarray]:
    """Fields of blends with control points ``pts`` ``(J, 6, 3)`` (absolute mm) at corners ``(J, 3)``.

    Returns a dict of arrays: ``coeffs`` ``(J, 6, 3)`` (power basis relative to ``P0``; a blend's weight is 1, so
    its poly table keeps no weight column: :class:`~jaxcnc.geometry.spans.PolyTable`),
    ``length``, ``timing`` ``(J, 6)``, ``err``, ``d1_max``, ``d2_max``, ``kappa_max`` (at ``N_CHECK``
    points), ``lo``, ``hi`` ``(J, 3)`` (hull), ``t0``, ``t1`` (unit end tangents) and ``dev``: the
    largest distance from the blend to the segments ``P0``–corner and corner–``P5`` (an upper bound: sampled
    at the 16 quadrature nodes and both ends, bounded between them, and measured where it peaks), or
    ``inf`` where the kernel cannot certify its peak (then :func:`deviation_kernel` measures it).
    """
    rel = pts - pts[:, :1, :]
    c = jnp.einsum("ki,jid->jkd", jnp.asarray(_M5), rel)  # power-basis coefficients (J, 6, 3)
    cx = [[c[:, k, i] for k in range(6)] for i in range(3)]
    # arc length: 16 Gauss–Legendre nodes of |P'|
    gx = jnp.asarray(_GX)[None, :]
    d1g = [_horner([ci[:, None] for ci in cx[i]], gx, 1)[1] for i in range(3)]
    speed_g = jnp.sqrt(d1g[0] ** 2 + d1g[1] ** 2 + d1g[2] ** 2)
    length = speed_g @ jnp.asarray(_GW)
    # end derivatives from the control points
    p1_0, p1_1 = 5 * (rel[:, 1] - rel[:, 0]), 5 * (rel[:, 5] - rel[:, 4])
    p2_0, p2_1 = 20 * (rel[:, 2] - 2 * rel[:, 1] + rel[:, 0]), 20 * (rel[:, 5] - 2 * rel[:, 4] + rel[:, 3])
    data = []
    for d1, d2 in ((p1_0, p2_0), (p1_1, p2_1)):
        g = jnp.linalg.norm(d1, axis=1)
        g1 = jnp.sum(d1 * d2, axis=1) / g
        data.append((length / g, -(length**2) * g1 / g**3))
    v = jnp.stack([jnp.zeros_like(length), data[0][0], data[0][1], jnp.ones_like(length), data[1][0], data[1][1]], 1)
    timing = v @ jnp.asarray(poly._HERMITE5)
    # check points: q' = P'(V) V'/L, q'' = P''(V) (V'/L)² + P'(V) V''/L²
    sig = jnp.linspace(0.0, 1.0, N_CHECK)[None, :]
    vv = _horner([timing[:, k, None] for k in range(6)], sig, 2)
    u = vv[0]
    v1, v2 = vv[1] / length[:, None], vv[2] / length[:, None] ** 2
    q1, q2 = [], []
    for i in range(3):
        _, d1, d2 = _horner([ci[:, None] for ci in cx[i]], u, 2)
        q1.append(d1 * v1)
        q2.append(d2 * v1**2 + d1 * v2)
    s1 = jnp.sqrt(q1[0] ** 2 + q1[1] ** 2 + q1[2] ** 2)
    cross = jnp.sqrt(
        (q1[1] * q2[2] - q1[2] * q2[1]) ** 2
        + (q1[2] * q2[0] - q1[0] * q2[2]) ** 2
        + (q1[0] * q2[1] - q1[1] * q2[0]) ** 2
    )
    err = jnp.where(jnp.all(vv[1] > 0, axis=1), jnp.max(jnp.abs(s1 - 1.0), axis=1), jnp.inf)
    # distance to the two straight pieces P0–C, C–P5 (the distance to the corner's polyline is their
    # minimum). Where one piece is the nearer it is smooth: sampled at the quadrature nodes and the ends,
    # and between samples h apart it rises above them by at most the sag M h²/8 (M bounds |P''| on the
    # interval). Where the nearer piece changes it peaks: on the plane through C normal to
    # t_in + t_out. The blend crosses that plane once where the control points' signed distances to it
    # change sign once (a Bézier curve crosses a plane no more often than its control polygon); there the
    # crossing uc (Newton on the quintic (P(u) - C)·n = 0, its residual checked) is measured, and points
    # closing in on it (CROSS_LADDER), so the pieces next to the peak are narrow and their sag tiny. A blend
    # without that certificate gets inf: "not measured here" (the caller measures it with
    # deviation_kernel, which bounds any number of crossings).
    # (points as three (J, Q) columns, not (J, Q, 3): XLA:CPU vectorises along the last axis)
    us = jnp.concatenate([jnp.zeros((1, 1)), gx, jnp.ones((1, 1))], axis=1)
    gaps = us[:, 1:] - us[:, :-1]
    d = [_horner([ci[:, None] for ci in cx[i]], us, 2) for i in range(3)]

    def polyline_distance(p: list[jnp.ndarray]) -> jnp.ndarray:
        """Distance from points (three ``(J, Q)`` columns) to the polyline P0–C–P5."""
        return jnp.minimum(_segment_distance_cols(p, pts[:, 0], corner), _segment_distance_cols(p, corner, pts[:, 5]))

    nearer = polyline_distance([d[i][0] + pts[:, :1, i] for i in range(3)])
    # |P''| on a sample interval: at most the larger end value plus max|P''''| h²/8 (P'' is a cubic, P''''
    # linear: largest at an end)
    d2 = jnp.sqrt(d[0][2] ** 2 + d[1][2] ** 2 + d[2][2] ** 2)
    d4 = jnp.maximum(
        jnp.sqrt(sum((24 * cx[i][4]) ** 2 for i in range(3))),
        jnp.sqrt(sum((24 * cx[i][4] + 120 * cx[i][5]) ** 2 for i in range(3))),
    )
    m_k = jnp.maximum(d2[:, :-1], d2[:, 1:]) + d4[:, None] * gaps * gaps / 8
    bound = jnp.max(jnp.maximum(nearer[:, :-1], nearer[:, 1:]) + m_k * gaps * gaps / 8, axis=1)
    t_in = corner - pts[:, 0]
    t_out = pts[:, 5] - corner
    n = t_in / jnp.linalg.norm(t_in, axis=1, keepdims=True) + t_out / jnp.linalg.norm(t_out, axis=1, keepdims=True)
    side = [jnp.sign(sum((pts[:, m, i] - corner[:, i]) * n[:, i] for i in range(3))) for m in range(6)]
    once = sum((side[m + 1] != side[m]).astype(jnp.int32) for m in range(5)) == 1
    for m in range(6):
        once = once & (side[m] != 0)
    c0 = pts[:, 0] - corner
    uc = jnp.full(length.shape, 0.5)
    for _ in range(CROSS_NEWTON):
        g = [_horner([ci for ci in cx[i]], uc, 1) for i in range(3)]
        f = sum((g[i][0] + c0[:, i]) * n[:, i] for i in range(3))
        fp = sum(g[i][1] * n[:, i] for i in range(3))
        uc = jnp.clip(uc - f / jnp.where(fp != 0, fp, 1.0), 0.0, 1.0)

    # points as three (J, 1) columns each: a (J, 1, 3) or (J, 3) array's sums over its last axis cost half
    # the kernel (XLA:CPU vectorises along that last axis)
    def nearer_at(u):
        return polyline_distance([(_horner(cx[i], u, 0)[0] + pts[:, 0, i])[:, None] for i in range(3)])[:, 0]

    at = [_horner(cx[i], uc, 3) for i in range(3)]  # position and derivatives at the crossing
    pc = [(at[i][0] + pts[:, 0, i])[:, None] for i in range(3)]
    at_cross = polyline_distance(pc)[:, 0]
    residual = jnp.abs(sum((pc[i][:, 0] - corner[:, i]) * n[:, i] for i in range(3)))
    # the sample interval holding uc is not smooth: it is covered by a ladder of points closing in on uc
    # from both sides (the pieces next to the peak narrow, their sag tiny) and the rest of it beyond the
    # ladder. All lie within H_MAX of uc, where |P''| <= |P''(uc)| + |P'''(uc)| H_MAX + max|P''''| H_MAX²/2
    m_uc = (
        jnp.sqrt(sum(at[i][2] ** 2 for i in range(3)))
        + jnp.sqrt(sum(at[i][3] ** 2 for i in range(3))) * H_MAX
        + d4 * H_MAX**2 / 2
    )
    for direction in (-1.0, 1.0):
        knots = [jnp.clip(uc + direction * H_MAX * step, 0.0, 1.0) for step in CROSS_LADDER] + [uc]
        values = [nearer_at(u) for u in knots[:-1]] + [at_cross]
        bound = jnp.maximum(bound, values[0] + m_uc * H_MAX**2 / 8)  # the rest of the interval, beyond
        for q in range(len(knots) - 1):
            w = knots[q + 1] - knots[q]
            bound = jnp.maximum(bound, jnp.maximum(values[q], values[q + 1]) + m_uc * w * w / 8)
    certified = once & (residual <= CROSS_RESIDUAL_MM)
    dev = jnp.where(certified, bound, jnp.inf)
    t0 = p1_0 / jnp.linalg.norm(p1_0, axis=1, keepdims=True)
    t1 = p1_1 / jnp.linalg.norm(p1_1, axis=1, keepdims=True)
    return {
        "coeffs": c,
        "length": length,
        "timing": timing,
        "err": err,
        "d1_max": jnp.max(s1, axis=1),
        "d2_max": jnp.max(jnp.sqrt(q2[0] ** 2 + q2[1] ** 2 + q2[2] ** 2), axis=1),
        "kappa_max": jnp.max(cross / s1**3, axis=1),
        "lo": jnp.min(pts, axis=1),
        "hi": jnp.max(pts, axis=1),
        "t0": t0,
        "t1": t1,
        "dev": dev,
    }


def _segment_distance_cols(p: list[jnp.ndarray], a: jnp.ndarray, b: jnp.ndarray) -> jnp.ndarray:
    """Distance ``(J, Q)`` from points given as three ``(J, Q)`` coordinate columns to segments ``a``–``b``
    ``(J, 3)``."""
    ab = [b[:, i, None] - a[:, i, None] for i in range(3)]
    den = jnp.maximum(ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2], 1e-300)
    t = jnp.clip(sum((p[i] - a[:, i, None]) * ab[i] for i in range(3)) / den, 0.0, 1.0)
    d = [p[i] - (a[:, i, None] + t * ab[i]) for i in range(3)]
    return jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])


#: Points of a blend where its distance to the replaced pieces is sampled (:func:`deviation_kernel`).
N_DEVIATION = 25


def deviation_kernel(
    coeffs: jnp.ndarray, start: jnp.ndarray, piece_in: dict, piece_out: dict, helix: bool | None = None
) -> jnp.ndarray:
    """``(J,)`` distance from each blend to the two pieces it replaces (an upper bound), compiled with
    :func:`cpu_loop_options`. ``helix``: whether a part may be an arc that rises (a helix; ``None``: whether one
    given does) — measured then by the helix's formulas (exact on circles too), else by the circle's alone, which
    take no angle per point (:func:`_piece_distance`). A caller that knows its path sets it once for all its
    calls: one compiled program per run.

    ``coeffs`` ``(J, 6, 4)``: the blends' homogeneous power-basis coefficients (weights 1) relative to their
    start ``start`` ``(J, 3)``. ``piece_in``, ``piece_out``: each a dict of ``(J, ...)`` arrays: ``a``, ``b``
    (the part's ends, ``(J, 3)``), ``is_arc`` (bool), and for arcs ``center``, ``e1``, ``e2``, ``axis``
    ``(J, 3)``, ``radius``, ``rise``, ``lo``, ``hi`` (the part's angles) — zeros where ``is_arc`` is false.

    The bound holds between the ``N_DEVIATION`` samples too, however often the nearer piece changes
    (:func:`deviation_bound`).
    """
    if helix is None:
        helix = any(
            bool(np.any(np.asarray(pc["is_arc"]) & (np.asarray(pc["rise"]) != 0))) for pc in (piece_in, piece_out)
        )
    return _compiled(_deviation_kernel, "helix")(coeffs, start, piece_in, piece_out, helix=bool(helix))


#: Sub-intervals the interval with the largest bound is cut into and measured again (:func:`deviation_bound`),
#: and how many times in a row.
REFINE = 4
REFINE_LEVELS = 4


def interval_bounds(f: jnp.ndarray, g: jnp.ndarray, excess_f, excess_g, chord_err) -> jnp.ndarray:
    """``(J, Q-1)`` upper bound of ``max min(f(u), g(u))`` on each interval between samples ``f``, ``g``
    ``(J, Q)`` of a blend's distances to the two pieces it replaces.

    Between two samples ``u_k``, ``u_k+1`` the blend ``P`` strays from its chord ``Q`` by at most
    ``chord_err`` (``(J, Q-1)``: ``max|P''| h²/8``), and a distance is 1-Lipschitz, so
    ``f(P(u)) <= f(Q(u)) + chord_err``. Along the straight chord the distance to a segment is convex
    (below the line through its two samples); the distance to an arc from inside it is not, but
    rises above that line by at most ``excess`` (``(J, Q-1)``, or 0; see :func:`_arc_excess`). So on
    each interval ``min(f, g)`` lies below the lower of two straight lines, each raised by its
    excess, plus ``chord_err``; the maximum of that minimum is at an end, or where the two lines cross
    inside the interval. No single crossing is assumed: the nearer piece may change in any interval.
    """
    f0, f1 = f[:, :-1] + excess_f, f[:, 1:] + excess_f
    g0, g1 = g[:, :-1] + excess_g, g[:, 1:] + excess_g
    ends = jnp.maximum(jnp.minimum(f0, g0), jnp.minimum(f1, g1))
    d0, d1 = f0 - g0, f1 - g1
    crosses = d0 * d1 < 0  # the lines cross strictly inside: there they are equal, and min(f, g) peaks
    s = jnp.where(crosses, d0 / jnp.where(crosses, d0 - d1, 1.0), 0.0)
    at_cross = jnp.where(crosses, f0 + (f1 - f0) * s, ends)
    return jnp.maximum(ends, at_cross) + chord_err


def deviation_bound(measure, u: jnp.ndarray) -> jnp.ndarray:
    """``(J,)`` upper bound of a blend's distance to the two pieces it replaces.

    ``measure(u)`` takes parameters ``(J, Q)`` (or ``(1, Q)``) and returns ``f``, ``g`` ``(J, Q)`` (the
    distances there), the excesses ``(J, Q-1)`` or scalars of :func:`interval_bounds`, and the second
    and third derivatives of the blend at ``u`` (each three ``(J, Q)`` columns); ``u`` ``(1, Q)``: the
    samples, 0 to 1. The interval with the largest bound — mostly where the nearer piece changes, where
    the chords' crossing (or the kink where a point's nearest point of a segment becomes its end)
    stands above the true peak — is cut into ``REFINE`` and bounded again, ``REFINE_LEVELS`` times
    (each time the piece with the largest bound); every interval left behind keeps its own bound, so
    the result stays a bound however the peaks lie, and hugs the highest.
    """

    def bounds(u):
        f, g, ef, eg, d2, d3 = measure(u)
        h = u[:, 1:] - u[:, :-1]
        return interval_bounds(f, g, ef, eg, _second_derivative_bound(d2, d3, h) * (h * h / 8))

    cut = jnp.asarray(np.linspace(0.0, 1.0, REFINE + 1))[None, :]

    def largest(per, u, others):
        """The ends ``(J, 1)`` of the interval with the largest bound, and ``others`` raised to the rest's."""
        k = jnp.argmax(per, axis=1)
        others = jnp.maximum(others, jnp.max(jnp.where(jnp.arange(per.shape[1]) == k[:, None], -jnp.inf, per), axis=1))
        lo = jnp.take_along_axis(u, k[:, None], axis=1)
        return lo, jnp.take_along_axis(u, k[:, None] + 1, axis=1), others

    def refine(_, state):
        """Cut the interval with the largest bound into ``REFINE`` and bound those again."""
        lo, hi, others, _ = state
        u = lo + (hi - lo) * cut
        per = bounds(u)
        return *largest(per, u, others), per

    per = bounds(u)
    state = largest(per, jnp.broadcast_to(u, (per.shape[0], u.shape[1])), jnp.full(per.shape[:1], -jnp.inf))
    # every level in a loop: one copy of the measurement in the program for all of them (the kernel compiled in
    # 3.3-3.9 s and loaded from the compile cache in ~0.5 s with the levels written out). The last level's
    # intervals raise ``others`` too, which its maximum covers anyway.
    _, _, others, per = jax.lax.fori_loop(0, REFINE_LEVELS, refine, (*state, jnp.zeros((per.shape[0], REFINE))))
    return jnp.maximum(others, jnp.max(per, axis=1))


def _second_derivative_bound(d2: list[jnp.ndarray], d3: list[jnp.ndarray], h: jnp.ndarray) -> jnp.ndarray:
    """``(J, Q-1)`` bound of the second derivative's norm on each interval of width ``h`` between samples
    where the second and third derivatives are ``d2``, ``d3`` (three ``(J, Q)`` columns each).

    A quintic's second derivative ``D`` is a cubic; on an interval ``[a, b]`` its Bernstein coefficients
    are ``D(a)``, ``D(a) + h D'(a)/3``, ``D(b) - h D'(b)/3``, ``D(b)`` (the cubic Hermite form), and its
    values there are convex combinations of them: the largest of their norms bounds it (a bound, not a
    sample).
    """
    b = [
        [c[:, :-1], c[:, :-1] + h * e[:, :-1] / 3, c[:, 1:] - h * e[:, 1:] / 3, c[:, 1:]]
        for c, e in zip(d2, d3, strict=True)
    ]
    sq = [b[0][m] * b[0][m] + b[1][m] * b[1][m] + b[2][m] * b[2][m] for m in range(4)]
    return jnp.sqrt(jnp.maximum(jnp.maximum(sq[0], sq[1]), jnp.maximum(sq[2], sq[3])))


def _arc_excess(p: list[jnp.ndarray], pc: dict) -> jnp.ndarray:
    """``(J, Q-1)`` how far the distance to the arc parts ``pc`` rises above the line through its values
    at consecutive points ``p`` (three ``(J, Q)`` columns) along the chord between them (0 on lines).

    Outside a circle the distance ``ρ - r`` (``ρ``: distance from the centre in the arc's plane) is
    convex along a straight chord; inside, ``r - ρ`` bends down by ``ρ'' <= |Q'|²/ρ``, so over a chord
    of length ``δ`` it rises above its end values' line by at most ``δ²/(8 ρ_min)``, ``ρ_min`` the
    chord's nearest approach to the centre. Past the part's ends the distance is to an end point:
    convex. (A helix's parts rise a little: treated as their circle.)
    """
    rel = [p[i] - pc["center"][:, i, None] for i in range(3)]
    x = sum(rel[i] * pc["e1"][:, i, None] for i in range(3))
    y = sum(rel[i] * pc["e2"][:, i, None] for i in range(3))
    x0, y0, dx, dy = x[:, :-1], y[:, :-1], x[:, 1:] - x[:, :-1], y[:, 1:] - y[:, :-1]
    t = jnp.clip(-(x0 * dx + y0 * dy) / jnp.maximum(dx * dx + dy * dy, 1e-300), 0.0, 1.0)
    rho_min = jnp.sqrt((x0 + t * dx) ** 2 + (y0 + t * dy) ** 2)
    delta2 = sum((p[i][:, 1:] - p[i][:, :-1]) ** 2 for i in range(3))
    inside = rho_min < pc["radius"][:, None]
    excess = jnp.where(inside, delta2 / (8 * jnp.maximum(rho_min, 1e-300)), 0.0)
    return jnp.where(pc["is_arc"][:, None], excess, 0.0)


def _piece_distance(p: list[jnp.ndarray], pc: dict, helix: bool) -> jnp.ndarray:
    """Distance ``(J, Q)`` from points ``p`` (three ``(J, Q)`` columns) to the parts ``pc``
    (:func:`deviation_kernel`).

    On an arc the nearest point of the part is at the query's own angle, clamped to the part (exact
    on a circle; an upper bound on a helix, whose tiny parts barely rise): with ``helix``. Without, the same
    distances on circles without an angle per point: a point within the part's
    angles (``u·m >= ρ cos α``, ``m`` the part's middle direction, ``α`` its half angle) is
    ``sqrt((ρ - r)² + z²)`` from it, any other is nearest the end on its side of ``m``.
    """
    seg = _segment_distance_cols(p, pc["a"], pc["b"])
    rel = [p[i] - pc["center"][:, i, None] for i in range(3)]
    x = sum(rel[i] * pc["e1"][:, i, None] for i in range(3))
    y = sum(rel[i] * pc["e2"][:, i, None] for i in range(3))
    lo, hi = pc["lo"][:, None], pc["hi"][:, None]
    mid = (lo + hi) / 2
    r = pc["radius"][:, None]

    def rising():
        phi = jnp.arctan2(y, x)
        psi = jnp.clip(mid + jnp.mod(phi - mid + jnp.pi, 2 * jnp.pi) - jnp.pi, lo, hi)
        cos, sin = jnp.cos(psi), jnp.sin(psi)
        d = [
            p[i]
            - (pc["center"][:, i, None] + r * (cos * pc["e1"][:, i, None] + sin * pc["e2"][:, i, None]))
            - pc["rise"][:, None] * psi * pc["axis"][:, i, None]
            for i in range(3)
        ]
        return jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])

    def circle():
        z = sum(rel[i] * pc["axis"][:, i, None] for i in range(3))
        rho = jnp.sqrt(x * x + y * y)
        mx, my, cos_half = jnp.cos(mid), jnp.sin(mid), jnp.cos((hi - lo) / 2)  # (J, 1): per part, not per point
        within = x * mx + y * my >= rho * cos_half
        at_hi = mx * y - my * x > 0  # the side of the middle direction: the end at hi (b), else lo (a)
        d_end = [p[i] - jnp.where(at_hi, pc["b"][:, i, None], pc["a"][:, i, None]) for i in range(3)]
        to_end = jnp.sqrt(d_end[0] * d_end[0] + d_end[1] * d_end[1] + d_end[2] * d_end[2])
        return jnp.where(within, jnp.sqrt((rho - r) ** 2 + z * z), to_end)

    return jnp.where(pc["is_arc"][:, None], rising() if helix else circle(), seg)


def _deviation_kernel(
    coeffs: jnp.ndarray, start: jnp.ndarray, piece_in: dict, piece_out: dict, helix: bool
) -> jnp.ndarray:
    """:func:`deviation_kernel` before compilation (``helix`` as it says)."""
    cx = [[coeffs[:, k, i][:, None] for k in range(6)] for i in range(3)]
    u = jnp.asarray(np.linspace(0.0, 1.0, N_DEVIATION))[None, :]

    def measure(u):
        d = [_horner(cx[i], u, 3) for i in range(3)]
        p = [d[i][0] + start[:, i, None] for i in range(3)]
        return (
            _piece_distance(p, piece_in, helix),
            _piece_distance(p, piece_out, helix),
            _arc_excess(p, piece_in),
            _arc_excess(p, piece_out),
            [di[2] for di in d],
            [di[3] for di in d],
        )

    return deviation_bound(measure, u)
