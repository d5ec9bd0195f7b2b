"""Blocks as rational Bézier spans in homogeneous power basis.

Every motion block becomes one or more spans ``P(u) = origin + N(u) / w(u)`` for ``u`` in [0, 1],
with ``[N, w](u) = sum_k c_k u^k`` — coefficients of shape ``(n_spans, degree+1, 4)``, relative
to each span's origin (see :mod:`jaxcnc.geometry.bezier`). One representation serves every block
kind, so evaluation is one batched kernel:

* a line is degree 1, padded to the common degree (which keeps ``u`` proportional to length);
* a circular arc is split into pieces of at most 90°, each the *exact* rational quadratic with
  middle weight ``cos(φ/2)`` (φ the piece's sweep);
* a B-spline or NURBS (G5 cubic, G5.1 quadratic, G5.2/G6.2/BSPLINE NURBS, degree ≤ 7) is cut at
  its knots into rational Bézier pieces, which are subdivided until their length is certified and
  their ``s(u)``/``u(s)`` fits converge (:mod:`jaxcnc.geometry.arclength`);
* a dwell or machine event is a point span (zero length), so the planner's time line has a
  segment for it.

The common degree is bucketed (2, 3, 5 or 7: the smallest that holds the program's curves) so
programs of similar content share compiled kernels. Building is vectorised NumPy over blocks.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from jaxcnc.geometry.arclength import CHEB_N, derivatives, refine_curved
from jaxcnc.geometry.bezier import elevate, homogeneous_power, nurbs_to_bezier
from jaxcnc.geometry.curvature import curvature, curvature_max, extents
from jaxcnc.program import Kind, Program

#: Span degrees are bucketed to these values.
DEGREE_BUCKETS = (2, 3, 5, 7)
#: Motion rows shorter than this (mm) move nothing and produce no span.
MIN_LENGTH_MM = 1e-9
#: Curve spans are split until their curvature varies by at most this factor (above the floor).
CURVATURE_SPREAD = 1.5
CURVATURE_FLOOR = 1e-3  # 1/mm: curvature below this (radius over 1 m) does not limit speed
#: Helical arcs are represented within this distance (mm) of the true helix.
HELIX_TOL_MM = 1e-4
#: z departure from "linear in the angle" of a 90° rational quadratic piece, per unit rise.
HELIX_Z_ERR = 0.0211


class SpanKind(IntEnum):
    POINT = 0  # dwell or event: zero length
    LINE = 1
    ARC = 2
    CURVE = 3  # a piece of a B-spline / NURBS


@dataclass(frozen=True, eq=False)
class Spans:
    """The path as spans; every array has ``n_spans`` rows (in path order).

    Attributes:
        coeffs: ``(n, degree+1, 4)`` homogeneous power-basis coefficients relative to ``origin``.
        origin: ``(n, 3)`` mm.
        kind: ``(n,)`` int8 :class:`SpanKind`.
        length: ``(n,)`` mm, arc length (exact for lines and arcs, certified quadrature for curves).
        length_err: ``(n,)`` mm, bound on the length's error (0 for lines and arcs).
        radius: ``(n,)`` mm, arc radius (``inf`` otherwise).
        half_angle: ``(n,)`` rad, half of an arc span's sweep (0 otherwise).
        kappa_max: ``(n,)`` 1/mm, maximum curvature over the span.
        tangent_in, tangent_out: ``(n, 3)`` unit tangents at ``u = 0`` and ``u = 1`` (0 for points).
        lo, hi: ``(n, 3)`` mm, the span's axis-aligned extent.
        block: ``(n,)`` int32 index of the Program row the span comes from.
        cheb_s: ``(n, CHEB_N+1)`` Chebyshev series of ``s(x)``, ``x = 2u - 1`` (curves; width 0 when
            the program has no curves).
        cheb_u: ``(n, CHEB_N)`` Chebyshev series of ``u(y)``, ``y = 2 s / length - 1`` (curves).
    """

    coeffs: np.ndarray
    origin: np.ndarray
    kind: np.ndarray
    length: np.ndarray
    length_err: np.ndarray
    radius: np.ndarray
    half_angle: np.ndarray
    kappa_max: np.ndarray
    tangent_in: np.ndarray
    tangent_out: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    block: np.ndarray
    cheb_s: np.ndarray
    cheb_u: np.ndarray

    def __len__(self) -> int:
        return int(self.kind.shape[0])

    @property
    def degree(self) -> int:
        return int(self.coeffs.shape[1] - 1)

    @property
    def s0(self) -> np.ndarray:
        """``(n,)`` mm, path length from the program start to each span's start."""
        return np.cumsum(self.length) - self.length

    @property
    def start(self) -> np.ndarray:
        """``(n, 3)`` start points (``u = 0``)."""
        c = self.coeffs[:, 0, :]
        return self.origin + c[:, :3] / c[:, 3:]

    @property
    def end(self) -> np.ndarray:
        """``(n, 3)`` end points (``u = 1``)."""
        c = self.coeffs.sum(axis=1)
        return self.origin + c[:, :3] / c[:, 3:]


def _quadratic(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, w1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quadratic rational Bézier (end weights 1, middle ``w1``): relative coefficients and origin."""
    pts = np.stack([p0, p1, p2], axis=1)
    w = np.stack([np.ones_like(w1), w1, np.ones_like(w1)], axis=1)
    return homogeneous_power(pts, w, p0), p0.copy()


def _line_spans(p: Program, rows: np.ndarray) -> dict[str, np.ndarray]:
    return line_spans(p.start[rows], p.end[rows], rows)


def line_spans(a: np.ndarray, b: np.ndarray, rows: np.ndarray) -> dict[str, np.ndarray]:
    """Span fields of straight moves from ``a`` to ``b`` ``(n, 3)`` (program rows ``rows``)."""
    d = b - a
    length = np.linalg.norm(d, axis=1)
    t = d / length[:, None]
    coeffs, origin = _quadratic(a, (a + b) / 2, b, np.ones(len(rows)))
    return dict(
        coeffs=coeffs,
        origin=origin,
        kind=SpanKind.LINE,
        length=length,
        radius=np.inf,
        half_angle=0.0,
        kappa_max=0.0,
        tangent_in=t,
        tangent_out=t,
        lo=np.minimum(a, b),
        hi=np.maximum(a, b),
        block=rows,
    )


def _plane_perm(p: Program, rows: np.ndarray) -> np.ndarray:
    """``(n, 3)`` program axes (first, second, normal) of each row's arc plane (G17/G18/G19)."""
    table = np.zeros((20, 3), np.int64)
    for plane, axes in ((17, (0, 1, 2)), (18, (2, 0, 1)), (19, (1, 2, 0))):
        table[plane] = axes
    return table[p.plane[rows]]


def _permute(a: np.ndarray, perm: np.ndarray) -> np.ndarray:
    """Program coordinates → plane coordinates (first, second, normal)."""
    return np.take_along_axis(a, perm, axis=1)


def _unpermute(a: np.ndarray, perm: np.ndarray) -> np.ndarray:
    """Plane coordinates → program coordinates."""
    out = np.empty_like(a)
    np.put_along_axis(out, perm, a, axis=1)
    return out


def _arc_frame(p: Program, rows: np.ndarray) -> tuple[np.ndarray, ...]:
    """Arc rows in plane coordinates: ``(perm, start, end, centre, turn, radius, start angle, sweep)``.

    The sweep is in ``(0, 2π]`` in the row's direction; an end equal to the start is a full circle.
    """
    perm = _plane_perm(p, rows)
    s, e, c = (_permute(a[rows], perm) for a in (p.start, p.end, p.center))
    turn = p.turn[rows].astype(np.float64)
    r = np.hypot(*(s - c)[:, :2].T)
    th_s = np.arctan2(*(s - c)[:, 1::-1].T)
    th_e = np.arctan2(*(e - c)[:, 1::-1].T)
    sweep = np.mod(turn * (th_e - th_s), 2 * np.pi)  # in [0, 2π)
    sweep = np.where(np.hypot(*(e - s)[:, :2].T) < MIN_LENGTH_MM, 2 * np.pi, sweep)
    return perm, s, e, c, turn, r, th_s, sweep


def _arc_spans(p: Program, rows: np.ndarray) -> dict[str, np.ndarray]:
    """Split arcs into ≤ 90° pieces, each an exact rational quadratic (computed in plane coordinates)."""
    perm_rows, s, e, c, turn, r, th_s, sweep = _arc_frame(p, rows)
    n_pieces = np.maximum(1, np.ceil(sweep / (np.pi / 2) - 1e-12)).astype(np.int64)
    idx = np.repeat(np.arange(len(rows)), n_pieces)
    j = np.arange(idx.size) - np.repeat(np.cumsum(n_pieces) - n_pieces, n_pieces)  # piece number
    phi = (sweep / n_pieces)[idx]  # piece sweep
    tn, rr, cc = turn[idx], r[idx], c[idx]
    a0 = th_s[idx] + tn * j * phi
    a1 = th_s[idx] + tn * (j + 1) * phi  # the same expression as the next piece's a0: joints agree exactly
    am = a0 + tn * phi / 2

    def on_circle(angle: np.ndarray, scale: np.ndarray | float = 1.0) -> np.ndarray:
        pts = cc.copy()
        pts[:, 0] += rr * scale * np.cos(angle)
        pts[:, 1] += rr * scale * np.sin(angle)
        return pts

    p0, p2 = on_circle(a0), on_circle(a1)
    first = j == 0
    last = j == n_pieces[idx] - 1
    p0[first] = s[idx[first]]  # the programmed points, bit for bit
    p2[last] = e[idx[last]]
    w1 = np.cos(phi / 2)
    p1 = on_circle(am, 1.0 / w1)

    def tangent(angle: np.ndarray) -> np.ndarray:
        return np.stack([-np.sin(angle) * tn, np.cos(angle) * tn, np.zeros_like(angle)], axis=1)

    # Extent: the end points plus every axis extreme (multiple of 90°) the piece sweeps over.
    lo, hi = np.minimum(p0, p2), np.maximum(p0, p2)
    lo_a, hi_a = np.minimum(a0, a1), np.maximum(a0, a1)
    for k, (dx, dy) in enumerate(((1, 0), (0, 1), (-1, 0), (0, -1))):
        ang = k * np.pi / 2
        # smallest representative of ang + 2πm that is ≥ lo_a
        rep = ang + 2 * np.pi * np.ceil((lo_a - ang) / (2 * np.pi) - 1e-15)
        inside = rep <= hi_a + 1e-15
        ext = cc + rr[:, None] * np.array([dx, dy, 0.0])
        lo = np.where(inside[:, None], np.minimum(lo, ext), lo)
        hi = np.where(inside[:, None], np.maximum(hi, ext), hi)
    perm = perm_rows[idx]
    back = [_unpermute(a, perm) for a in (p0, p1, p2, tangent(a0), tangent(a1), lo, hi)]
    coeffs, origin = _quadratic(back[0], back[1], back[2], w1)
    return dict(
        coeffs=coeffs,
        origin=origin,
        kind=SpanKind.ARC,
        length=rr * phi,
        radius=rr,
        half_angle=phi / 2,
        kappa_max=1.0 / rr,
        tangent_in=back[3],
        tangent_out=back[4],
        lo=back[5],
        hi=back[6],
        block=rows[idx],
    )


def _unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=1, keepdims=True)
    f = np.linalg.norm(fallback, axis=1, keepdims=True)
    use = n > 1e-12
    return np.where(use, v / np.where(use, n, 1.0), fallback / np.where(f > 0, f, 1.0))


def _curvature_varies(coeffs: np.ndarray) -> np.ndarray:
    """``(S,)`` bool: the curvature over the span varies by more than ``CURVATURE_SPREAD``.

    The planner caps a span's speed by its maximum curvature, so a span whose curvature varies a
    lot is planned slower than it could go: such spans are split.
    """
    kappa = curvature(coeffs, np.broadcast_to(np.linspace(0, 1, 17), (coeffs.shape[0], 17)))
    hi, lo = kappa.max(axis=1), kappa.min(axis=1)
    return hi > CURVATURE_SPREAD * lo + CURVATURE_FLOOR


def _certified(coeffs: np.ndarray, origin: np.ndarray, owner: np.ndarray) -> dict[str, np.ndarray]:
    """Curve pieces → certified spans (subdivided until length and ``u(s)`` fits converge and the
    curvature is nearly constant on each)."""
    fit = refine_curved(coeffs, origin, owner, split=_curvature_varies)
    c = fit["coeffs"]
    _, d1_0, d2_0 = (x[:, 0] for x in derivatives(c, np.zeros((c.shape[0], 1)), 2))
    _, d1_1, d2_1 = (x[:, 0] for x in derivatives(c, np.ones((c.shape[0], 1)), 2))
    lo, hi = extents(c, fit["origin"])
    return dict(
        coeffs=c,
        origin=fit["origin"],
        kind=SpanKind.CURVE,
        length=fit["length"],
        length_err=fit["length_err"],
        radius=np.inf,
        half_angle=0.0,
        kappa_max=curvature_max(c),
        tangent_in=_unit(d1_0, d2_0),
        tangent_out=_unit(d1_1, -d2_1),
        lo=lo,
        hi=hi,
        block=fit["owner"],
        cheb_s=fit["cheb_s"],
        cheb_u=fit["cheb_u"],
    )


def _curve_spans(p: Program, rows: np.ndarray, degree: int) -> dict[str, np.ndarray]:
    """B-spline / NURBS rows → certified rational Bézier pieces."""
    coeffs, origin, owner = [], [], []
    for r in rows:
        deg, pts, wts, kns = p.curves.curve(int(p.curve[r]))
        bp, bw, _ = nurbs_to_bezier(deg, pts, wts, kns)
        moving = np.ptp(bp, axis=1).max(axis=1) > MIN_LENGTH_MM  # drop pieces that do not move
        bp, bw = bp[moving], bw[moving]
        coeffs.append(elevate(homogeneous_power(bp, bw, bp[:, 0]), degree))
        origin.append(bp[:, 0])
        owner.append(np.full(bp.shape[0], r))
    return _certified(np.concatenate(coeffs), np.concatenate(origin), np.concatenate(owner))


def _helix_spans(p: Program, rows: np.ndarray, degree: int) -> dict[str, np.ndarray]:
    """Helical arcs (XY arc with Z moving in proportion to the angle), within ``HELIX_TOL_MM``.

    Each piece is the exact rational quadratic of its XY arc with ``z`` control values
    ``z0, (z0 + z2)/2, z2``; its ``z`` then departs from "linear in the angle" by at most
    ``0.0211 · (φ / 90°)² · Δz`` (measured over the piece's parameter), so a helix of sweep ``Φ``
    and rise ``H`` is cut into ``n ≥ cbrt(0.0211 (Φ / 90°)² |H| / HELIX_TOL_MM)`` equal pieces
    (and at least one per 90°). The pieces are certified like spline pieces.
    """
    perm_rows, s, e, c, turn, r, th_s, sweep = _arc_frame(p, rows)
    rise = e[:, 2] - s[:, 2]
    quarters = np.ceil(sweep / (np.pi / 2) - 1e-12)
    by_tol = np.ceil(np.cbrt(HELIX_Z_ERR * (sweep / (np.pi / 2)) ** 2 * np.abs(rise) / HELIX_TOL_MM))
    n_pieces = np.maximum(1, np.maximum(quarters, by_tol)).astype(np.int64)
    idx = np.repeat(np.arange(len(rows)), n_pieces)
    j = np.arange(idx.size) - np.repeat(np.cumsum(n_pieces) - n_pieces, n_pieces)
    n = n_pieces[idx]
    phi = (sweep / n_pieces)[idx]
    tn, rr, cc = turn[idx], r[idx], c[idx]
    a0 = th_s[idx] + tn * j * phi
    a1 = th_s[idx] + tn * (j + 1) * phi
    am = a0 + tn * phi / 2
    z0 = s[idx, 2] + rise[idx] * j / n
    z2 = s[idx, 2] + rise[idx] * (j + 1) / n

    def point(angle: np.ndarray, z: np.ndarray, scale: np.ndarray | float = 1.0) -> np.ndarray:
        return np.stack([cc[:, 0] + rr * scale * np.cos(angle), cc[:, 1] + rr * scale * np.sin(angle), z], axis=1)

    w1 = np.cos(phi / 2)
    p0, p1, p2 = point(a0, z0), point(am, (z0 + z2) / 2, 1.0 / w1), point(a1, z2)
    p0[j == 0] = s[idx[j == 0]]  # the programmed points, bit for bit
    p2[j == n - 1] = e[idx[j == n - 1]]
    perm = perm_rows[idx]
    coeffs, origin = _quadratic(_unpermute(p0, perm), _unpermute(p1, perm), _unpermute(p2, perm), w1)
    return _certified(elevate(coeffs, degree), origin, rows[idx])


def _point_spans(p: Program, rows: np.ndarray) -> dict[str, np.ndarray]:
    a = p.end[rows]
    z = np.zeros_like(a)
    coeffs, origin = _quadratic(a, a, a, np.ones(len(rows)))
    return dict(
        coeffs=coeffs,
        origin=origin,
        kind=SpanKind.POINT,
        length=0.0,
        radius=np.inf,
        half_angle=0.0,
        kappa_max=0.0,
        tangent_in=z,
        tangent_out=z,
        lo=a,
        hi=a,
        block=rows,
    )


def span_degree(program: Program, min_degree: int = 2) -> int:
    """The bucketed common degree for a program's spans (at least ``min_degree``)."""
    need = min_degree
    if program.curves is not None and np.any(program.kind == Kind.CURVE):
        used = program.curve[program.kind == Kind.CURVE]
        need = max(need, int(np.max(program.curves.degree[used])))
    return next(d for d in DEGREE_BUCKETS if d >= need)


_KEYS = (
    "coeffs",
    "origin",
    "kind",
    "length",
    "length_err",
    "radius",
    "half_angle",
    "kappa_max",
    "tangent_in",
    "tangent_out",
    "lo",
    "hi",
    "block",
    "cheb_s",
    "cheb_u",
)


def build_spans(program: Program, corner_tol_mm: float = 0.0) -> Spans:
    """Turn a Program's rows into spans in path order (vectorised over rows).

    Zero-length moves produce no span; dwell and event rows produce point spans. Corners between
    lines are blended within the program's G64 P tolerance (``corner_tol_mm`` where G64 has no P;
    see :mod:`jaxcnc.geometry.blend`).
    """
    from jaxcnc.geometry.blend import BLEND_DEGREE, blend_tolerances, corner_blends

    kind = program.kind
    move_len = np.linalg.norm(program.end - program.start, axis=1)
    is_line = (kind == Kind.LINE) & (move_len > MIN_LENGTH_MM)
    tol = blend_tolerances(program, is_line, corner_tol_mm)
    blending = bool(np.any(tol > 0))
    degree = span_degree(program, BLEND_DEGREE if blending else 2)
    parts = []
    normal = _plane_perm(program, np.arange(len(program)))[:, 2]
    rise = np.take_along_axis(program.end - program.start, normal[:, None], axis=1)[:, 0]
    helical = (kind == Kind.ARC) & (np.abs(rise) > MIN_LENGTH_MM)
    has_curves = bool(np.any(kind == Kind.CURVE)) or bool(helical.any())
    n_cheb = (CHEB_N + 1, CHEB_N) if has_curves else (0, 0)
    line_rows = np.flatnonzero(is_line)
    if blending:
        lines, blends = corner_blends(program, line_rows, tol)
        parts.append(lines)
        if blends is not None:
            parts.append(_certified(elevate(blends[0], degree), blends[1], blends[2]))
            parts[-1]["blend"] = True
            has_curves = True
            n_cheb = (CHEB_N + 1, CHEB_N)
        is_line = np.zeros_like(is_line)
    for build, mask in (
        (_line_spans, is_line),
        (_arc_spans, (kind == Kind.ARC) & ~helical),
        (_point_spans, (kind == Kind.DWELL) | (kind == Kind.EVENT)),
    ):
        if mask.any():
            parts.append(build(program, np.flatnonzero(mask)))
    if np.any(kind == Kind.CURVE):
        parts.append(_curve_spans(program, np.flatnonzero(kind == Kind.CURVE), degree))
    if helical.any():
        parts.append(_helix_spans(program, np.flatnonzero(helical), degree))
    if not parts:
        parts.append(_point_spans(program, np.zeros(0, np.int64)))
    cols = {}
    for key in _KEYS:
        chunks = []
        for pt in parts:
            n = np.size(pt["block"])
            v = pt.get(key, 0.0)
            if key == "coeffs":
                v = elevate(v, degree)
            elif key in ("cheb_s", "cheb_u"):
                width = n_cheb[0] if key == "cheb_s" else n_cheb[1]
                v = v if np.ndim(v) == 2 else np.zeros((n, width))
            elif np.ndim(v) == 0:
                v = np.full(n, v)
            chunks.append(np.asarray(v))
        cols[key] = np.concatenate(chunks)
    # Path order: by program row, a corner blend first (it ends where its row's line starts),
    # then by piece order within a block (the sort is stable).
    blend = np.concatenate([np.full(np.size(pt["block"]), bool(pt.get("blend", False))) for pt in parts])
    order = np.lexsort((~blend, cols["block"]))
    out = {k: np.ascontiguousarray(v[order]) for k, v in cols.items()}
    out["kind"] = out["kind"].astype(np.int8)
    out["block"] = out["block"].astype(np.int32)
    for v in out.values():
        v.setflags(write=False)
    return Spans(**out)


def pad_spans(spans: Spans, n: int) -> Spans:
    """``spans`` followed by point spans up to ``n`` rows (static shapes for compiled kernels)."""
    extra = n - len(spans)
    if extra < 0:
        raise ValueError("cannot pad to fewer spans")
    fill = {"kind": SpanKind.POINT, "length": 0.0, "radius": np.inf, "block": -1}
    out = {}
    for key in _KEYS:
        a = getattr(spans, key)
        value = fill.get(key, 0.0)
        pad = np.full((extra,) + a.shape[1:], value, dtype=a.dtype)
        if key == "coeffs":
            pad[:, 0, 3] = 1.0  # w = 1: a point at the origin
        out[key] = np.concatenate([a, pad])
    return Spans(**out)
