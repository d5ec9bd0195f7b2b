"""Blocks as rational Bézier spans in homogeneous power basis.

Every motion block becomes one or more spans ``P(u) = N(u) / w(u)`` for ``u`` in [0, 1], with
``[N, w](u) = sum_k c_k u^k`` — the coefficients ``c`` of shape ``(n_spans, degree+1, ndim+1)``
(homogeneous coordinates ``(w·x, w·y, w·z, w)``). One representation serves every block kind,
so evaluation is one batched kernel:

* a line is degree 1 (padded to the common degree, which keeps its uniform parametrisation);
* a circular arc is split into pieces of at most 90° and each piece is the *exact* rational
  quadratic with end weights 1 and middle weight ``cos(φ/2)`` (φ the piece's sweep);
* a dwell or machine event is a point span (zero length), so the planner's time line has a
  segment for it.

Building is vectorised NumPy over blocks (no Python loop over blocks or points).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from jaxcnc.program import Kind, Program

#: Common degree of all spans so far (lines and arcs); the NURBS issue adds buckets.
DEGREE = 2
#: Motion rows shorter than this (mm) move nothing and produce no span.
MIN_LENGTH_MM = 1e-9


class SpanKind(IntEnum):
    POINT = 0  # dwell or event: zero length
    LINE = 1
    ARC = 2


@dataclass(frozen=True, eq=False)
class Spans:
    """The path as spans; every array has ``n_spans`` rows (in path order).

    Attributes:
        coeffs: ``(n, DEGREE+1, 4)`` homogeneous power-basis coefficients.
        kind: ``(n,)`` int8 :class:`SpanKind`.
        length: ``(n,)`` mm, exact arc length of the span.
        radius: ``(n,)`` mm, arc radius (``inf`` for lines and points).
        half_angle: ``(n,)`` rad, half of an arc span's sweep (0 otherwise).
        tangent_in, tangent_out: ``(n, 3)`` unit tangents at ``u = 0`` and ``u = 1``
            (zero for points).
        lo, hi: ``(n, 3)`` mm, the span's exact axis-aligned extent.
        block: ``(n,)`` int32 index of the Program row the span comes from.
    """

    coeffs: np.ndarray
    kind: np.ndarray
    length: np.ndarray
    radius: np.ndarray
    half_angle: np.ndarray
    tangent_in: np.ndarray
    tangent_out: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    block: np.ndarray

    def __len__(self) -> int:
        return int(self.kind.shape[0])

    @property
    def start(self) -> np.ndarray:
        """``(n, 3)`` start points (``u = 0``)."""
        c = self.coeffs[:, 0, :]
        return c[:, :3] / c[:, 3:]

    @property
    def end(self) -> np.ndarray:
        """``(n, 3)`` end points (``u = 1``)."""
        c = self.coeffs.sum(axis=1)
        return c[:, :3] / c[:, 3:]


def _homogeneous_power(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, w1: np.ndarray) -> np.ndarray:
    """Quadratic rational Bézier (end weights 1, middle ``w1``) in homogeneous power basis.

    ``B(u) = (1-u)² P0 + 2u(1-u) P1 + u² P2 = P0 + 2(P1 - P0) u + (P0 - 2 P1 + P2) u²``,
    applied to the homogeneous points ``(P0, 1)``, ``(w1 P1, w1)``, ``(P2, 1)``.

    Args: ``p0, p1, p2`` of shape ``(m, 3)``, ``w1`` of shape ``(m,)``. Returns ``(m, 3, 4)``.
    """
    ones = np.ones_like(w1)[:, None]
    h0 = np.concatenate([p0, ones], axis=1)
    h1 = np.concatenate([p1 * w1[:, None], w1[:, None]], axis=1)
    h2 = np.concatenate([p2, ones], axis=1)
    return np.stack([h0, 2.0 * (h1 - h0), h0 - 2.0 * h1 + h2], axis=1)


def _line_spans(p: Program, rows: np.ndarray) -> dict[str, np.ndarray]:
    a, b = p.start[rows], p.end[rows]
    d = b - a
    length = np.linalg.norm(d, axis=1)
    t = d / length[:, None]
    return dict(
        coeffs=_homogeneous_power(a, (a + b) / 2, b, np.ones(len(rows))),
        kind=SpanKind.LINE,
        length=length,
        radius=np.inf,
        half_angle=0.0,
        tangent_in=t,
        tangent_out=t,
        lo=np.minimum(a, b),
        hi=np.maximum(a, b),
        block=rows,
    )


def _arc_spans(p: Program, rows: np.ndarray) -> dict[str, np.ndarray]:
    """Split XY arcs into ≤ 90° pieces, each an exact rational quadratic."""
    s, e, c, turn = p.start[rows], p.end[rows], p.center[rows], p.turn[rows].astype(np.float64)
    r = np.hypot(*(s - c)[:, :2].T)
    th_s = np.arctan2(*(s - c)[:, 1::-1].T)
    th_e = np.arctan2(*(e - c)[:, 1::-1].T)
    sweep = np.mod(turn * (th_e - th_s), 2 * np.pi)  # in [0, 2π)
    full = np.hypot(*(e - s)[:, :2].T) < MIN_LENGTH_MM
    sweep = np.where(full, 2 * np.pi, sweep)
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
    return dict(
        coeffs=_homogeneous_power(p0, p1, p2, w1),
        kind=SpanKind.ARC,
        length=rr * phi,
        radius=rr,
        half_angle=phi / 2,
        tangent_in=tangent(a0),
        tangent_out=tangent(a1),
        lo=lo,
        hi=hi,
        block=rows[idx],
    )


def _point_spans(p: Program, rows: np.ndarray) -> dict[str, np.ndarray]:
    a = p.end[rows]
    z = np.zeros_like(a)
    return dict(
        coeffs=_homogeneous_power(a, a, a, np.ones(len(rows))),
        kind=SpanKind.POINT,
        length=0.0,
        radius=np.inf,
        half_angle=0.0,
        tangent_in=z,
        tangent_out=z,
        lo=a,
        hi=a,
        block=rows,
    )


def build_spans(program: Program) -> Spans:
    """Turn a Program's rows into spans in path order (vectorised over rows).

    Zero-length moves produce no span; dwell and event rows produce point spans.
    """
    kind = program.kind
    move_len = np.linalg.norm(program.end - program.start, axis=1)
    is_line = (kind == Kind.LINE) & (move_len > MIN_LENGTH_MM)
    is_arc = kind == Kind.ARC
    is_point = (kind == Kind.DWELL) | (kind == Kind.EVENT)
    parts = [
        f(program, np.flatnonzero(m))
        for f, m in ((_line_spans, is_line), (_arc_spans, is_arc), (_point_spans, is_point))
        if m.any()
    ]
    if not parts:
        empty = np.zeros((0, 3))
        return Spans(
            np.zeros((0, DEGREE + 1, 4)),
            np.zeros(0, np.int8),
            np.zeros(0),
            np.zeros(0),
            np.zeros(0),
            empty,
            empty,
            empty,
            empty,
            np.zeros(0, np.int32),
        )
    n_of = [len(np.atleast_1d(pt["block"])) for pt in parts]
    cols = {}
    for key in ("coeffs", "kind", "length", "radius", "half_angle", "tangent_in", "tangent_out", "lo", "hi", "block"):
        cols[key] = np.concatenate(
            [
                np.broadcast_to(np.asarray(pt[key]), (n,) + np.shape(pt[key])[1:])
                if np.ndim(pt[key]) == 0
                else np.asarray(pt[key])
                for pt, n in zip(parts, n_of, strict=False)
            ]
        )
    # Path order: by program row, then by piece order within an arc (stable sort keeps it).
    order = np.argsort(cols["block"], kind="stable")
    out = {k: np.ascontiguousarray(v[order]) for k, v in cols.items()}
    out["kind"] = out["kind"].astype(np.int8)
    out["block"] = out["block"].astype(np.int32)
    for v in out.values():
        v.setflags(write=False)
    return Spans(**out)
