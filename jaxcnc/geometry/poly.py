"""Polynomial spans at build time (NumPy): rational Bézier pieces with a timing polynomial.

A polynomial span — a NURBS piece or a corner blend — is the rational Bézier
``P(u) = origin + N(u) / w(u)``, ``[N, w](u) = sum_k c_k u^k``, traversed by path parameter
``s ∈ [0, L]`` through a *timing polynomial* ``u = V(σ)``, ``σ = s / L``, a quintic in power basis.
``V`` is the quintic Hermite interpolant of the exact inverse of arc length at both ends: with
``g = |P'|`` and ``g' = P'·P''/|P'|``,

    V(0) = 0,  V'(0) = L / g(0),  V''(0) = -L² g'(0) / g(0)³      (and the same at σ = 1, V(1) = 1),

so at both ends ``q(s) = P(V(s/L))`` has unit speed, ``q' = T``, and ``q'' = K`` (the curvature
vector, no tangential part): spans join one another exactly as the geometry does (G1 or G2), in
the planner's parameter as well as in space. Inside, ``|q'| = g(V) V' / L`` stays close to 1; the
planner uses the exact ``q'`` and ``q''`` of this parametrisation, so nothing depends on how close.
NURBS pieces are subdivided until ``|q'|`` is within ``SPEED_TOL`` of 1 (the feed is then kept to
that accuracy inside them); blends, which are short corners, are not.

Everything is vectorised over spans (Horner's scheme on ``(S, q)`` arrays; a few subdivision
rounds, no loop over spans or points).
"""

from __future__ import annotations

import numpy as np

from jaxcnc.geometry.bezier import restrict

GL_ORDER = 16
LENGTH_TOL_MM = 1e-10
#: NURBS pieces are split until the path parameter's speed ``|q'|`` is within this of 1.
SPEED_TOL = 1e-6
#: Blends (corners: not run at a constant feed) are split until it is within this of 1.
BLEND_SPEED_TOL = 1e-3
#: A blend is halved at most this many times (a 150° corner needs about four).
MAX_SPLITS = 6
#: Interior points where a timing polynomial is checked (and maxima are sampled).
N_CHECK = 33
_GX, _GW = np.polynomial.legendre.leggauss(GL_ORDER)
_GX = (_GX + 1) / 2
_GW = _GW / 2
_GOLD = (np.sqrt(5) - 1) / 2

#: Quintic Hermite basis on [0, 1] in power form: rows h0, h1, h2 (value, slope, curvature at 0)
#: and h3, h4, h5 (the same at 1); columns the coefficients of σ^0..σ^5.
_HERMITE5 = np.array(
    [
        [1, 0, 0, -10, 15, -6],
        [0, 1, 0, -6, 8, -3],
        [0, 0, 0.5, -1.5, 1.5, -0.5],
        [0, 0, 0, 10, -15, 6],
        [0, 0, 0, -4, 7, -3],
        [0, 0, 0, 0.5, -1, 0.5],
    ]
)


def hom_horner(coeffs: np.ndarray, u: np.ndarray, order: int) -> list[np.ndarray]:
    """``[H, H', ...]`` of ``H = sum_k c_k u^k``: coeffs ``(S, p+1, 4)``, u ``(S, q)`` → each ``(S, q, 4)``."""
    p = coeffs.shape[1] - 1
    uu = u[..., None]
    d = [np.broadcast_to(coeffs[:, None, p, :], u.shape + (4,)).copy()] + [np.zeros(u.shape + (4,))] * order
    for k in range(p - 1, -1, -1):
        for r in range(min(order, p - k), 0, -1):
            d[r] = d[r] * uu + d[r - 1]
        d[0] = d[0] * uu + coeffs[:, None, k, :]
    fact = 1.0
    for r in range(2, order + 1):
        fact *= r
        d[r] = d[r] * fact
    return d


def bezier_derivatives(coeffs: np.ndarray, u: np.ndarray, order: int = 2) -> list[np.ndarray]:
    """``[P - origin, P', P'', P''']`` (up to ``order``), each ``(S, q, 3)``, by the quotient rule."""
    h = hom_horner(coeffs, u, order)
    w = [x[..., 3:] for x in h]
    n = [x[..., :3] for x in h]
    q = n[0] / w[0]
    out = [q]
    if order >= 1:
        out.append((n[1] - q * w[1]) / w[0])
    if order >= 2:
        out.append((n[2] - 2 * out[1] * w[1] - q * w[2]) / w[0])
    if order >= 3:
        out.append((n[3] - 3 * out[2] * w[1] - 3 * out[1] * w[2] - q * w[3]) / w[0])
    return out


def speed(coeffs: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``|dP/du|`` ``(S, q)``."""
    return np.linalg.norm(bezier_derivatives(coeffs, u, 1)[1], axis=-1)


def _gl(coeffs: np.ndarray, span: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    u = a[:, None] + (b - a)[:, None] * _GX[None, :]
    return (b - a) * (speed(coeffs[span], u) @ _GW)


def gl_length(coeffs: np.ndarray, tol: float = LENGTH_TOL_MM, max_rounds: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Adaptive Gauss–Legendre arc length of each span and its error bound, both ``(S,)`` mm.

    An interval is accepted when its halves agree with the whole to ``tol · width``; the sum of
    those differences bounds the error.
    """
    n = coeffs.shape[0]
    length, err = np.zeros(n), np.zeros(n)
    span, a, b = np.arange(n), np.zeros(n), np.ones(n)
    whole = _gl(coeffs, span, a, b)
    for rnd in range(max_rounds):
        if span.size == 0:
            break
        m = (a + b) / 2
        left, right = _gl(coeffs, span, a, m), _gl(coeffs, span, m, b)
        diff = np.abs(left + right - whole)
        done = (diff <= tol * (b - a)) | (rnd == max_rounds - 1)
        np.add.at(length, span[done], (left + right)[done])
        np.add.at(err, span[done], diff[done])
        keep = ~done
        span = np.concatenate([span[keep], span[keep]])
        a, b = np.concatenate([a[keep], m[keep]]), np.concatenate([m[keep], b[keep]])
        whole = np.concatenate([left[keep], right[keep]])
    return length, err


def fixed_length(coeffs: np.ndarray) -> np.ndarray:
    """Arc length ``(S,)`` by one 16-point Gauss–Legendre rule (short smooth spans such as blends)."""
    return _gl(coeffs, np.arange(coeffs.shape[0]), np.zeros(coeffs.shape[0]), np.ones(coeffs.shape[0]))


def timing(coeffs: np.ndarray, length: np.ndarray) -> np.ndarray:
    """``(S, 6)`` power-basis coefficients of each span's timing polynomial ``u = V(σ)`` (module docstring)."""
    ends = np.broadcast_to(np.array([0.0, 1.0]), (coeffs.shape[0], 2))
    _, d1, d2 = bezier_derivatives(coeffs, ends, 2)
    g = np.linalg.norm(d1, axis=-1)
    L = length[:, None]
    # at a cusp (|P'| = 0) arc length grows like u²: no polynomial inverts it; there V' = 1 and the
    # path parameter slows to a stop with the tool (the junction there is a corner anyway)
    ok = g > 1e-9 * np.maximum(L, 1e-300)
    safe = np.where(ok, g, 1.0)
    g1 = np.sum(d1 * d2, axis=-1) / safe
    slope = np.where(ok, L / safe, 1.0)
    curv = np.where(ok, -(L**2) * g1 / safe**3, 0.0)
    data = np.stack([np.zeros_like(length), slope[:, 0], curv[:, 0], np.ones_like(length), slope[:, 1], curv[:, 1]], 1)
    return data @ _HERMITE5


def timing_derivatives(tcoef: np.ndarray, sigma: np.ndarray, order: int) -> list[np.ndarray]:
    """``[V, V', ...]`` (in σ) of timing polynomials ``(S, 6)`` at ``sigma`` ``(S, q)``."""
    d = [np.broadcast_to(tcoef[:, 5:6], sigma.shape).copy()] + [np.zeros(sigma.shape)] * order
    for k in range(4, -1, -1):
        for r in range(min(order, 5 - k), 0, -1):
            d[r] = d[r] * sigma + d[r - 1]
        d[0] = d[0] * sigma + tcoef[:, k : k + 1]
    fact = 1.0
    for r in range(2, order + 1):
        fact *= r
        d[r] = d[r] * fact
    return d


def path_derivatives(
    coeffs: np.ndarray, tcoef: np.ndarray, length: np.ndarray, sigma: np.ndarray, order: int = 2
) -> list[np.ndarray]:
    """``[q - origin, q', q'', q''']`` in the path parameter ``s = σ L`` (chain rule through ``V``)."""
    v = timing_derivatives(tcoef, sigma, order)
    p = bezier_derivatives(coeffs, v[0], order)
    L = length[:, None, None]
    out = [p[0]]
    if order >= 1:
        v1 = v[1][..., None] / L
        out.append(p[1] * v1)
    if order >= 2:
        v2 = v[2][..., None] / L**2
        out.append(p[2] * v1**2 + p[1] * v2)
    if order >= 3:
        v3 = v[3][..., None] / L**3
        out.append(p[3] * v1**3 + 3 * p[2] * v1 * v2 + p[1] * v3)
    return out


def check(coeffs: np.ndarray, tcoef: np.ndarray, length: np.ndarray, n_check: int = N_CHECK) -> dict[str, np.ndarray]:
    """One pass over ``n_check`` points of each span: how far ``|q'|`` strays from 1, and the maxima.

    Returns ``(S,)`` arrays: ``err`` (max ``||q'| - 1|``; ``inf`` where ``V`` is not increasing),
    ``d1_max``, ``d2_max`` (maxima of ``|q'|``, ``|q''|`` in the path parameter) and ``kappa_max`` (the
    curvature). Sampled maxima size the planner's grid and the look-ahead planner's caps; the tick
    table is verified independently, and the ``topp`` planner checks between its nodes.
    """
    sig = np.broadcast_to(np.linspace(0.0, 1.0, n_check), (coeffs.shape[0], n_check))
    v1 = timing_derivatives(tcoef, sig, 1)[1]
    _, d1, d2 = path_derivatives(coeffs, tcoef, length, sig, 2)
    s1 = np.linalg.norm(d1, axis=-1)
    err = np.max(np.abs(s1 - 1.0), axis=1)
    moving = s1 > 1e-6 * np.max(s1, axis=1, keepdims=True)  # a cusp's own point has no curvature to speak of
    kappa = np.where(moving, np.linalg.norm(np.cross(d1, d2), axis=-1) / np.where(moving, s1, 1.0) ** 3, 0.0)
    return {
        "err": np.where(np.all(v1 > 0, axis=1), err, np.inf),
        "d1_max": s1.max(axis=1),
        "d2_max": np.linalg.norm(d2, axis=-1).max(axis=1),
        "kappa_max": kappa.max(axis=1),
    }


def certify_curves(
    coeffs: np.ndarray,
    origin: np.ndarray,
    owner: np.ndarray,
    max_rounds: int = 10,
    speed_tol: float = SPEED_TOL,
    adaptive: bool = True,
    n_check: int = N_CHECK,
) -> dict[str, np.ndarray]:
    """Subdivide rational Bézier pieces until their lengths are certified and their timing polynomials
    keep ``|q'|`` within ``speed_tol`` of 1 (at ``n_check`` points).

    Args:
        coeffs ``(S, p+1, 4)``, origin ``(S, 3)``, owner ``(S,)`` (a per-piece tag carried along).
        adaptive: adaptive quadrature with an error bound (else one 16-point rule, for short smooth
            pieces such as blends; the bound is then 0 — the length only scales the parameter).
    Returns:
        ``coeffs, origin, owner, length, length_err, timing`` and the maxima of :func:`check`, in path
        order (halves stay in place).
    """
    done: list[dict[str, np.ndarray]] = []
    order = np.arange(coeffs.shape[0], dtype=np.float64)  # keys that keep path order through splits
    width = 1.0
    for rnd in range(max_rounds):
        length, err = gl_length(coeffs) if adaptive else (fixed_length(coeffs), np.zeros(coeffs.shape[0]))
        tcoef = timing(coeffs, length)
        found = check(coeffs, tcoef, length, n_check)
        ok = (found.pop("err") <= speed_tol) | (rnd == max_rounds - 1)
        done.append(
            dict(
                coeffs=coeffs[ok],
                origin=origin[ok],
                owner=owner[ok],
                length=length[ok],
                length_err=err[ok],
                timing=tcoef[ok],
                key=order[ok],
                **{k: v[ok] for k, v in found.items()},
            )
        )
        bad = ~ok
        if not bad.any():
            break
        n_bad = int(bad.sum())
        half = np.full(n_bad, 0.5)
        c0, o0 = restrict(coeffs[bad], origin[bad], np.zeros(n_bad), half)
        c1, o1 = restrict(coeffs[bad], origin[bad], half, np.ones(n_bad))
        width /= 2
        coeffs = np.concatenate([c0, c1])
        origin = np.concatenate([o0, o1])
        owner = np.concatenate([owner[bad], owner[bad]])
        order = np.concatenate([order[bad], order[bad] + width])
    out = {k: np.concatenate([d[k] for d in done]) for k in done[0]}
    idx = np.argsort(out.pop("key"), kind="stable")
    return {k: v[idx] for k, v in out.items()}


def end_frames(coeffs: np.ndarray) -> tuple[np.ndarray, ...]:
    """Unit tangents and curvature vectors at ``u = 0`` and ``u = 1``: ``(t0, k0, t1, k1)``, each ``(S, 3)``.

    Where ``P'`` vanishes (a degenerate end) the tangent comes from ``P''``.
    """
    ends = np.broadcast_to(np.array([0.0, 1.0]), (coeffs.shape[0], 2))
    _, d1, d2 = bezier_derivatives(coeffs, ends, 2)
    g = np.linalg.norm(d1, axis=-1, keepdims=True)
    ok = g > 1e-12 * np.maximum(np.linalg.norm(d2, axis=-1, keepdims=True), 1e-300)
    t = np.where(ok, d1 / np.where(ok, g, 1.0), d2 * np.array([1.0, -1.0])[None, :, None])
    t = t / np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-300)
    k = np.where(ok, (d2 - t * np.sum(t * d2, axis=-1, keepdims=True)) / np.where(ok, g, 1.0) ** 2, 0.0)
    return t[:, 0], k[:, 0], t[:, 1], k[:, 1]


def extents(coeffs: np.ndarray, origin: np.ndarray, iters: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned extent ``(lo, hi)``, each ``(S, 3)`` mm: sampled, then refined by golden section."""
    n = coeffs.shape[0]
    m = 65
    u = np.broadcast_to(np.linspace(0.0, 1.0, m), (n, m))
    p = bezier_derivatives(coeffs, u, 0)[0]  # (S, m, 3)
    lo, hi = p.min(axis=1), p.max(axis=1)
    rows = np.arange(n)
    for sign, best in ((1.0, hi), (-1.0, lo)):
        k = np.argmax(sign * p, axis=1)  # (S, 3)
        for axis in range(3):
            a = np.clip(k[:, axis] - 1, 0, m - 1) / (m - 1)
            b = np.clip(k[:, axis] + 1, 0, m - 1) / (m - 1)

            def f(x: np.ndarray, axis: int = axis, sign: float = sign) -> np.ndarray:
                return sign * bezier_derivatives(coeffs, x[:, None], 0)[0][:, 0, axis]

            x1, x2 = b - _GOLD * (b - a), a + _GOLD * (b - a)
            f1, f2 = f(x1), f(x2)
            for _ in range(iters):
                left = f1 > f2
                b, a = np.where(left, x2, b), np.where(left, a, x1)
                x2n = np.where(left, x1, a + _GOLD * (b - a))
                x1n = np.where(left, b - _GOLD * (b - a), x2)
                new = f(np.where(left, x1n, x2n))
                f1, f2 = np.where(left, new, f2), np.where(left, f1, new)
                x1, x2 = x1n, x2n
            cand = np.maximum(f1, f2) * sign
            if sign > 0:
                best[rows, axis] = np.maximum(best[:, axis], cand)
            else:
                best[rows, axis] = np.minimum(best[:, axis], cand)
    return lo + origin, hi + origin


def hull_extents(coeffs: np.ndarray, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Extent of each span's Bézier control points (positive weights: the curve lies in their hull)."""
    from jaxcnc.geometry.bezier import power_to_bezier

    pts = power_to_bezier(coeffs)
    return pts.min(axis=1) + origin, pts.max(axis=1) + origin
