"""Arc length of rational spans, certified, and the fits behind ``s(u)`` and ``u(s)`` (build time).

Length. ``L = ∫_0^1 |P'(u)| du`` by adaptive Gauss–Legendre quadrature (16 nodes): an interval is
accepted when its two halves agree with the whole to ``tol · width``; the sum of those
differences is the a-posteriori error bound reported with each span (``length_err``), which is
at most ``tol`` per span.

Fits. On each curved span the speed ``|P'(u)|`` is interpolated at 32 Chebyshev points; the
integral of that series is ``s(u)`` (Clenshaw–Curtis), and a second Chebyshev series fits the
inverse ``u(s)``, whose nodes are solved by Newton's method on ``s(u)``. A span is subdivided
(exactly, by reparametrisation) until the speed series has converged to rounding level, ``s(1)``
agrees with the quadrature length and the inverse fit is within ``INVERSE_TOL_MM`` of arc length
between its nodes — so the tick stage needs one series evaluation per tick.

Everything is vectorised NumPy over spans (a few refinement rounds, no loop over spans or points).
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev as C

from jaxcnc.geometry.bezier import restrict

GL_ORDER = 16
LENGTH_TOL_MM = 1e-10
#: Certified accuracy of the u(s) fit, as arc length between its nodes (mm).
INVERSE_TOL_MM = 1e-11
CHEB_N = 32
_GX, _GW = np.polynomial.legendre.leggauss(GL_ORDER)
_GX = (_GX + 1) / 2
_GW = _GW / 2
_CX = np.cos(np.pi * (np.arange(CHEB_N) + 0.5) / CHEB_N)  # first-kind Chebyshev nodes in [-1, 1]
_DCT = 2.0 / CHEB_N * np.cos(np.pi * np.outer(np.arange(CHEB_N), np.arange(CHEB_N) + 0.5) / CHEB_N)
_DCT[0] /= 2


def hom_derivatives(coeffs: np.ndarray, u: np.ndarray, order: int) -> list[np.ndarray]:
    """``[H, H', ...]`` of ``H = sum_k c_k u^k`` for coeffs ``(S, p+1, 4)``, u ``(S, q)`` → ``(S, q, 4)``."""
    p = coeffs.shape[1] - 1
    k = np.arange(p + 1, dtype=np.float64)
    out, fac = [], np.ones(p + 1)
    for r in range(order + 1):
        powers = np.where(k >= r, u[..., None] ** np.maximum(k - r, 0), 0.0)  # (S, q, K)
        out.append(np.einsum("sqk,skd->sqd", powers * fac, coeffs))
        fac = fac * (k - r)
    return out


def derivatives(coeffs: np.ndarray, u: np.ndarray, order: int = 2) -> list[np.ndarray]:
    """Local position and its u-derivatives ``[P - origin, P', P'', ...]`` each ``(S, q, 3)``."""
    h = hom_derivatives(coeffs, u, order)
    w = [x[..., 3:] for x in h]
    p = h[0][..., :3] / w[0]
    out = [p]
    if order >= 1:
        p1 = (h[1][..., :3] - p * w[1]) / w[0]
        out.append(p1)
    if order >= 2:
        out.append((h[2][..., :3] - 2 * p1 * w[1] - p * w[2]) / w[0])
    return out


def speed(coeffs: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``|dP/du|`` ``(S, q)``."""
    return np.linalg.norm(derivatives(coeffs, u, 1)[1], axis=-1)


def _gl(coeffs: np.ndarray, span: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    u = a[:, None] + (b - a)[:, None] * _GX[None, :]
    return (b - a) * (speed(coeffs[span], u) @ _GW)


def gl_length(coeffs: np.ndarray, tol: float = LENGTH_TOL_MM, max_rounds: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Adaptive Gauss–Legendre length of each span and its error bound, both ``(S,)`` mm."""
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


def _cheb_coeffs(values: np.ndarray) -> np.ndarray:
    """Chebyshev coefficients ``(S, N)`` of the interpolant through values at the first-kind nodes."""
    return values @ _DCT.T


def _fits(coeffs: np.ndarray, length: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s(u) and u(σ) Chebyshev series of each span and whether they are converged."""
    u_nodes = np.broadcast_to((_CX + 1) / 2, (coeffs.shape[0], CHEB_N))
    g = speed(coeffs, u_nodes)
    a = _cheb_coeffs(g)
    s_series = C.chebint(a, m=1, lbnd=-1, scl=0.5, axis=1)  # s(x), x = 2u - 1, s(-1) = 0
    g_scale = np.maximum(np.abs(a[:, 0]), 1e-300)
    speed_ok = np.max(np.abs(a[:, -4:]), axis=1) <= 1e-13 * g_scale
    s_end = C.chebval(1.0, s_series.T)
    end_ok = np.abs(s_end - length) <= max(LENGTH_TOL_MM, 0) + 1e-13 * length
    # inverse: u at sigma nodes by Newton on the s-series (monotone), then its Chebyshev series
    target = ((_CX + 1) / 2)[None, :] * length[:, None]
    u = np.broadcast_to((_CX + 1) / 2, target.shape).copy()
    ds = C.chebder(s_series, axis=1)  # ds/dx
    for _ in range(60):
        x = 2 * u - 1
        f = _chebval_rows(s_series, x) - target
        if np.all(np.abs(f) <= 1e-14 * np.maximum(length, 1.0)[:, None]):
            break  # converged (quadratically: a handful of steps)
        fp = 2 * _chebval_rows(ds, x)
        u = np.clip(u - f / np.where(fp > 0, fp, np.inf), 0.0, 1.0)
    u_series = _cheb_coeffs(u)
    sig = (_CX + 1) / 2
    # accuracy of the inverse fit off the nodes, checked at midpoints
    mid = np.cos(np.pi * np.arange(1, CHEB_N) / CHEB_N)
    u_mid = _chebval_rows(u_series, np.broadcast_to(mid, (u.shape[0], mid.size)))
    s_mid = _chebval_rows(s_series, 2 * np.clip(u_mid, 0, 1) - 1)
    inv_err = np.max(np.abs(s_mid - ((mid + 1) / 2)[None, :] * length[:, None]), axis=1)
    u_tail = np.max(np.abs(u_series[:, -4:]), axis=1)
    inv_ok = (inv_err <= INVERSE_TOL_MM) & (u_tail <= 1e-14)
    del sig
    return s_series, u_series, speed_ok & end_ok & inv_ok


def _chebval_rows(series: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Evaluate row ``i``'s series at ``x[i, :]`` (Clenshaw, vectorised over rows)."""
    b1 = np.zeros_like(x)
    b2 = np.zeros_like(x)
    for k in range(series.shape[1] - 1, 0, -1):
        b1, b2 = 2 * x * b1 - b2 + series[:, k : k + 1], b1
    return x * b1 - b2 + series[:, :1]


def refine_curved(
    coeffs: np.ndarray, origin: np.ndarray, owner: np.ndarray, max_rounds: int = 12, split=None, split_rounds: int = 3
) -> dict[str, np.ndarray]:
    """Subdivide curved spans until their length and ``s(u)``/``u(s)`` fits are certified.

    Args:
        coeffs ``(S, p+1, 4)``, origin ``(S, 3)``, owner ``(S,)`` (any per-span tag carried along).
        split: optional ``coeffs -> (S,) bool``, more spans to subdivide (e.g. where the curvature
            varies too much for one speed cap), in the first ``split_rounds`` rounds only (at most
            ``2**split_rounds`` pieces per span for that reason: near a cusp the ratio never settles).
    Returns:
        dict of ``coeffs, origin, owner, length, length_err, cheb_s (S', N+1), cheb_u (S', N)``
        in path order (a split span's halves stay in place).
    """
    done: list[dict[str, np.ndarray]] = []
    order = np.arange(coeffs.shape[0], dtype=np.float64)  # keys that keep path order through splits
    width = 1.0
    for rnd in range(max_rounds):
        length, err = gl_length(coeffs)
        s_series, u_series, ok = _fits(coeffs, length)
        if split is not None and rnd < split_rounds:
            ok = ok & ~split(coeffs)
        ok = ok | (rnd == max_rounds - 1)
        done.append(
            dict(
                coeffs=coeffs[ok],
                origin=origin[ok],
                owner=owner[ok],
                length=length[ok],
                length_err=err[ok],
                cheb_s=s_series[ok],
                cheb_u=u_series[ok],
                key=order[ok],
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
