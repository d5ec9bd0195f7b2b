"""Spline blocks of the LinuxCNC dialect, turned into the exact curves they specify.

* ``G5 X Y I J P Q`` — a cubic Bézier in XY: ``I J`` is the first control point relative to the
  start, ``P Q`` the second relative to the end. A G5 without ``I J`` continues the previous cubic
  tangentially (``I J = -P Q`` of the previous one).
* ``G5.1 X Y I J`` — a quadratic Bézier with control point start + ``(I, J)``.
* ``G5.2 [P] [L] X Y [P]`` … ``G5.3`` — a NURBS: the current position is the first control point
  (``G5.2 P`` alone sets its weight), each block adds a control point with weight ``P`` (default 1);
  ``L`` is the order (default 3); the knots are LinuxCNC's clamped uniform integers
  ``0…0, 1, 2, …, n-k, n-k+1…n-k+1``.
* ``BSPLINE X Y PW= SD= PL=`` (Siemens) — the programmed points are control points after the
  current one, ``PW`` their weights, ``SD`` the degree (default 3), the running sums of ``PL`` the
  knots (chord lengths without PL), clamped at both ends; the spline ends with the next motion
  word or the end of the program.
* ``G6.2 X Y R K P Q1`` … ``G6.2 K`` — a NURBS with explicit knots: ``P`` the order, each block a
  control point ``X Y`` with weight ``R`` and knot ``K``; blocks with only ``K`` add the trailing
  knots; the curve is complete when it has (control points + order) knots. ``Q1`` (as the
  LinuxCNC examples write it) is accepted; other values are refused.

The builders check what a dialect's manual says is an error and return ``(degree, points,
weights, knots)`` for :func:`~jaxcnc.program.make_curve_table`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

Curve = tuple[int, np.ndarray, np.ndarray, np.ndarray]


def bezier_curve(points: np.ndarray) -> Curve:
    """A (non-rational) Bézier with the given control points ``(p+1, 3)`` as a clamped B-spline."""
    p = points.shape[0] - 1
    return p, points, np.ones(p + 1), np.concatenate([np.zeros(p + 1), np.ones(p + 1)])


def g5_knots(n_points: int, order: int) -> np.ndarray:
    """LinuxCNC's G5.2 knot vector: clamped, uniform integer interior knots."""
    k = order
    return np.concatenate([np.zeros(k), np.arange(1, n_points - k + 1), np.full(k, n_points - k + 1)]).astype(float)


@dataclass
class NurbsBlock:
    """A NURBS being read block by block (G5.2 or G6.2)."""

    kind: str  # "G5.2", "G6.2" or "BSPLINE"
    line: int
    column: int
    order: int
    points: list[np.ndarray] = field(default_factory=list)
    weights: list[float] = field(default_factory=list)
    knots: list[float] = field(default_factory=list)
    start: np.ndarray | None = None  # where the machine stood when the curve began (G6.2)

    @property
    def complete(self) -> bool:
        """G6.2: all knots given."""
        return (
            self.kind == "G6.2" and len(self.points) >= self.order and len(self.knots) == len(self.points) + self.order
        )

    def curve(self) -> Curve:
        pts = np.asarray(self.points, dtype=np.float64)
        w = np.asarray(self.weights, dtype=np.float64)
        if self.kind == "G5.2":
            knots = g5_knots(len(pts), self.order)
        elif self.kind == "BSPLINE":
            knots = bspline_knots(pts, self.knots, self.order - 1)
        else:
            knots = np.asarray(self.knots, dtype=np.float64)
        return self.order - 1, pts, w, knots


def bspline_knots(points: np.ndarray, intervals: list[float | None], degree: int) -> np.ndarray:
    """Siemens BSPLINE knots: running sums of the blocks' ``PL`` intervals, clamped at both ends.

    ``intervals[k]`` is block k's PL (the block that programs control point k+1). Without PL the
    intervals are the chord lengths between consecutive control points. The first
    ``n - degree - 1`` running sums are the interior knots; the last knot is their total.
    """
    n = points.shape[0]
    if all(v is None for v in intervals):
        steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    else:
        steps = np.asarray(intervals, dtype=np.float64)
    sums = np.cumsum(steps)
    total = sums[-1] if sums.size else 0.0
    return np.concatenate([np.zeros(degree + 1), sums[: n - degree - 1], np.full(degree + 1, total)])
