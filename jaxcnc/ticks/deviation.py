"""Independent check of the path: how far every tick of a table lies from the *programmed* geometry.

The planner may replace a corner between two motion rows by a curve within the blend tolerance the
program allows there; everywhere else the table should follow the programmed lines, arcs and splines.
This module measures that on the table itself, with nothing from the planner: the inputs are the table
(exact positions = integer discretes + fine residual, streamed in chunks), the machine file (axis names,
``path.corner_tol_mm``) and the :class:`~jaxcnc.program.Program` the table was planned from. It imports
neither :mod:`jaxcnc.geometry` nor :mod:`jaxcnc.planners` (nor JAX): lines, arcs and helices are measured
in closed form here, splines with ``scipy.interpolate.BSpline``.

What is compared with what, tick by tick:

* **Which row runs.** The table's ``BLOCK`` events (``aux`` = source line, ``value`` = program row) say
  which program row runs from which tick; tick ``k`` belongs to the row of the last ``BLOCK`` event at or
  before ``k`` (ticks before the first event: the first event's row).
* **Geometry compared.** A blended corner spans the end of one motion row and the start of the next, so
  the tick is compared with its own row ``r`` and with the nearest *moving* rows before and after it,
  ``P`` and ``N`` (moving: a line longer than ``program.MIN_MOVE_MM``, an arc or a spline; dwells, events and
  shorter moves, which the planner gives no span, are skipped). The distance is the smallest of the three
  distances. Rows that do not move (dwell, event, a line not longer than that) are the point where they stand.
* **Tolerance allowed.** The tolerance of the junction between consecutive moving rows ``a < b`` is the lower
  of the two rows' ``blend_tol`` (G64 P; the machine's ``corner_tol_mm`` where it is ``inf``, G64 without P),
  the second row's only where it has one: the mode a move is programmed in says how it ends, so 0 — an exact
  corner — after a row programmed under G61, G61.1 or G64 P0 (``blend_tol[a]`` = 0), and where any row in
  ``a+1 .. b`` must start at rest (``stop_before``: after G61.1, the laser switched, a dwell, an event) or where
  there is no row on one side.
  A tick of a moving row ``r`` may lie up to ``max(J(P, r), J(r, N))`` from the geometry; a tick of a row
  that does not move up to ``J(P, N)``. On top of that a numeric slack of :data:`SLACK_MM` (1e-6 mm).
  G61 (exact path) therefore allows 1e-6 mm everywhere. A table shaped against vibration (issue 20) is allowed,
  at every tick, the contour error shaping was planned with (header ``shaping_tol_mm``, at most 1 mm): the
  convolution rounds every curve a little, which is the price of the shaper, stated and bounded.
* **Distances.** Line segments: closed form. Circular arcs (G17/G18/G19, ``turn`` +1 counter-clockwise
  seen from the plane normal, a full circle where end = start in the plane): exact — the nearest point is
  at the query's angle when that lies in the sweep, else the nearer end. Helices (the normal coordinate
  rises linearly with the angle): the smallest distance over 8 samples per turn and Newton's method
  started from the best of them, from the height match and from the in-plane matches next to it; every
  candidate is a point of the helix, so the figure is never below the true distance (an upper bound,
  exact where Newton converged — to ~1e-12 mm in practice). Splines (clamped NURBS): the
  homogeneous control points ``(w·P, w)`` evaluated with ``scipy.interpolate.BSpline``, sampled densely
  (one sample per :data:`CURVE_SPACING_MM` of control polygon, at least 8 per knot span), the nearest
  sample found with a k-d tree and refined by Newton projection on the curve; again every candidate is a
  curve point, so the distance reported is an upper bound of the true one (a check that passes is sound).

Reported besides the maximum: the largest deviation **away from corners** — at ticks farther from every
blendable corner point of the rows compared than ``16·J / (3·sin(θ/2))`` (``θ`` the programmed turn at
the corner, ``J`` its tolerance; twice the reach of a line–line blend that uses the whole tolerance;
junctions turning by less than :data:`CORNER_MIN_TURN_RAD` are tangent joins, no corners). There the
table should follow the program to numerical precision; the figure is information, not part of the
verdict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from jaxcnc.errors import JaxcncError
from jaxcnc.format import EventKind, TableFile
from jaxcnc.machine import MachineConfig
from jaxcnc.program import MIN_MOVE_MM, PROGRAM_AXES, Kind, Program, program_start
from jaxcnc.ticks.verify import TableRows, Violation, _runs, check_threads, map_chunks

#: Numeric slack added to every tolerance (mm): far above the table's fixed point (2^-32 discrete) and
#: float rounding, far below any tolerance a program states.
SLACK_MM = 1e-6
#: A tick this close to its own row (mm) is not compared with the neighbouring rows (it cannot matter).
ON_PATH_MM = 1e-9
#: Spline sampling: about one sample per this much control-polygon length (mm).
CURVE_SPACING_MM = 0.05
#: At most this many samples per spline (the spacing grows for longer ones).
CURVE_MAX_SAMPLES = 1 << 20
#: Ticks per chunk read from the table.
CHUNK_ROWS = 1 << 16
#: Program axes (first, second, normal) of each arc plane, as RS274NGC defines them (G18 is Z-X).
PLANE_AXES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}
#: In-plane chord (mm) below which an arc's end equals its start: a full circle (the program's threshold of a move,
#: as the planner's spans use it).
FULL_CIRCLE_MM = MIN_MOVE_MM
#: Junctions turning less than this are no corners for the "away from corners" figure (tangent joins).
CORNER_MIN_TURN_RAD = 1e-6
#: Samples per turn of a helix that start its Newton refinement (with the height match).
HELIX_SAMPLES = 8
#: Newton steps refining the nearest point on a helix or spline.
NEWTON_STEPS = 8
_TWO_PI = 2.0 * math.pi


@dataclass
class PathDeviation:
    """Distances of a table's ticks from the programmed path (module docstring for the definition)."""

    n_ticks: int
    max_mm: float  # the largest distance of a tick from the programmed geometry
    worst_tick: int
    worst_row: int  # program row running at the worst tick
    worst_line: int  # its source line
    allowed_at_worst_mm: float  # tolerance + slack allowed at the worst tick
    n_over: int  # ticks farther than allowed
    max_away_mm: float  # the largest distance at ticks away from blendable corners (nan: none there)
    n_away: int  # how many ticks are away from corners
    max_tol_mm: float  # the largest tolerance any tick was allowed (without the slack)
    slack_mm: float
    violations: list[Violation] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.n_over == 0


# ----------------------------------------------------------------------------------------------
# Distances from points to programmed geometry (vectorised over points)


def segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points ``p`` ``(m, 3)`` to segments ``a``–``b`` (``(m, 3)`` or ``(3,)``); a point when
    ``a == b``."""
    ab = b - a
    den = np.sum(ab * ab, axis=-1)
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.where(den > 0, den, 1.0), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


@dataclass(frozen=True)
class Arcs:
    """Arcs and helices in their plane's coordinates ``(u, v, w)`` = program columns ``perm``.

    Every array has one entry per arc: ``perm`` ``(k, 3)`` (first, second, normal axis), ``cu, cv`` the
    centre in the plane, ``radius``, ``phi0`` the start angle, ``sweep`` the signed angle travelled
    (``+`` counter-clockwise), ``w0`` the start's normal coordinate and ``rise`` the normal travel,
    ``start``/``end`` ``(k, 3)`` in program coordinates.
    """

    perm: np.ndarray
    cu: np.ndarray
    cv: np.ndarray
    radius: np.ndarray
    phi0: np.ndarray
    sweep: np.ndarray
    w0: np.ndarray
    rise: np.ndarray
    start: np.ndarray
    end: np.ndarray

    def take(self, idx: np.ndarray) -> Arcs:
        """The arcs ``idx`` (one per point, for :func:`arc_distance`)."""
        return Arcs(*(getattr(self, f)[idx] for f in self.__dataclass_fields__))

    def tangents(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit directions of travel ``(k, 3)`` at the start and at the end of each arc."""
        out = []
        for phi in (self.phi0, self.phi0 + self.sweep):
            s = np.sign(self.sweep)
            dwdphi = self.rise / np.where(self.sweep != 0, np.abs(self.sweep), 1.0)
            t_uvw = np.stack([-self.radius * np.sin(phi) * s, self.radius * np.cos(phi) * s, dwdphi], axis=1)
            t = np.empty_like(t_uvw)
            np.put_along_axis(t, self.perm, t_uvw, axis=1)
            out.append(t / np.linalg.norm(t, axis=1, keepdims=True))
        return out[0], out[1]


def make_arcs(start: np.ndarray, end: np.ndarray, center: np.ndarray, turn: np.ndarray, plane: np.ndarray) -> Arcs:
    """Arcs of program rows: ``start, end, center`` ``(k, 3)``, ``turn`` ±1, ``plane`` 17/18/19."""
    start, end, center = (np.atleast_2d(np.asarray(x, np.float64)) for x in (start, end, center))
    turn = np.atleast_1d(np.asarray(turn, np.float64))
    plane = np.atleast_1d(np.asarray(plane))
    perm = np.array([PLANE_AXES[int(g)] for g in plane], dtype=np.int64).reshape(-1, 3)
    s = np.take_along_axis(start, perm, axis=1)
    e = np.take_along_axis(end, perm, axis=1)
    c = np.take_along_axis(center, perm, axis=1)
    phi0 = np.arctan2(s[:, 1] - c[:, 1], s[:, 0] - c[:, 0])
    phi1 = np.arctan2(e[:, 1] - c[:, 1], e[:, 0] - c[:, 0])
    part = np.mod(turn * (phi1 - phi0), _TWO_PI)
    # an end at the start, or at the start's angle (off it along the radius): a whole turn
    full = (np.hypot(e[:, 0] - s[:, 0], e[:, 1] - s[:, 1]) < FULL_CIRCLE_MM) | (part == 0)
    sweep = np.where(full, _TWO_PI, part) * turn
    return Arcs(
        perm=perm,
        cu=c[:, 0],
        cv=c[:, 1],
        radius=np.hypot(s[:, 0] - c[:, 0], s[:, 1] - c[:, 1]),
        phi0=phi0,
        sweep=sweep,
        w0=s[:, 2],
        rise=e[:, 2] - s[:, 2],
        start=start,
        end=end,
    )


def arc_distance(p: np.ndarray, arcs: Arcs) -> np.ndarray:
    """Distance from points ``p`` ``(m, 3)`` to arcs ``arcs`` (one per point, see :meth:`Arcs.take`).

    Planar arcs: exact. Helices: an upper bound that is exact where the refinement converged (the
    distance to a point of the helix; module docstring).
    """
    p = np.asarray(p, np.float64)
    q = np.take_along_axis(p, arcs.perm, axis=1)
    u, v, w = q[:, 0] - arcs.cu, q[:, 1] - arcs.cv, q[:, 2] - arcs.w0
    rho = np.hypot(u, v)
    sgn = np.where(arcs.sweep < 0, -1.0, 1.0)
    span = np.abs(arcs.sweep)
    t0 = np.mod(sgn * (np.arctan2(v, u) - arcs.phi0), _TWO_PI)  # the query's angle from the start, travelled
    ends = np.minimum(np.linalg.norm(p - arcs.start, axis=1), np.linalg.norm(p - arcs.end, axis=1))
    out = np.where(t0 <= span, np.hypot(rho - arcs.radius, w), ends)
    helix = np.flatnonzero(arcs.rise != 0)
    if helix.size:
        h = helix
        out[h] = _helix_distance(rho[h], t0[h], w[h], arcs.radius[h], span[h], arcs.rise[h])
    return out


def _helix_distance(
    rho: np.ndarray, t0: np.ndarray, w: np.ndarray, radius: np.ndarray, span: np.ndarray, rise: np.ndarray
) -> np.ndarray:
    """Distance to helices ``θ ↦ (R cos θ, R sin θ, rise·θ/span)``, ``θ ∈ [0, span]``, from points at angle
    ``t0``, radius ``rho`` and height ``w`` (all relative to the helix start): the minimum of the squared
    distance ``f(θ) = ρ² + R² − 2ρR cos(θ − t0) + (w − κθ)²`` over samples and Newton refinements."""
    kappa = rise / span

    def f(th: np.ndarray) -> np.ndarray:
        return (
            rho[:, None] ** 2
            + radius[:, None] ** 2
            - 2 * rho[:, None] * radius[:, None] * np.cos(th - t0[:, None])
            + (w[:, None] - kappa[:, None] * th) ** 2
        )

    n = HELIX_SAMPLES * max(1, int(np.ceil(np.max(span) / _TWO_PI))) + 1
    samples = span[:, None] * np.linspace(0.0, 1.0, n)[None, :]
    fv = f(samples)
    best = fv.min(axis=1)
    # Newton from the best sample, the height match and the in-plane matches t0 + 2πn next to it
    th_h = np.clip(w / kappa, 0.0, span)
    n_h = np.floor((th_h - t0) / _TWO_PI)
    x = np.stack(
        [samples[np.arange(n_h.size), np.argmin(fv, axis=1)], th_h, t0 + n_h * _TWO_PI, t0 + (n_h + 1) * _TWO_PI],
        axis=1,
    )
    # refine every start on its own (flattened); each stops when its step vanishes
    cols = x.shape[1]
    x = np.clip(x, 0.0, span[:, None]).ravel()
    a, k, ww, tt, hi = (np.repeat(v, cols) for v in (rho * radius, kappa, w, t0, span))
    todo = np.arange(x.size)
    for _ in range(NEWTON_STEPS):
        xt, at, kt = x[todo], a[todo], k[todo]
        d1 = 2 * at * np.sin(xt - tt[todo]) - 2 * kt * (ww[todo] - kt * xt)
        d2 = 2 * at * np.cos(xt - tt[todo]) + 2 * kt * kt
        x_new = np.clip(xt - np.where(d2 > 0, d1 / np.where(d2 > 0, d2, 1.0), 0.0), 0.0, hi[todo])
        x[todo] = x_new
        todo = todo[np.abs(x_new - xt) > 1e-13]
        if todo.size == 0:
            break
    best = np.minimum(best, f(x.reshape(-1, cols)).min(axis=1))
    return np.sqrt(np.maximum(best, 0.0))


def point_arc_distance(
    p: np.ndarray, start: np.ndarray, end: np.ndarray, center: np.ndarray, turn: int, plane: int = 17
) -> np.ndarray:
    """Distance from points ``p`` ``(m, 3)`` to one arc or helix given as a program row would give it."""
    p = np.atleast_2d(np.asarray(p, np.float64))
    arcs = make_arcs(start, end, center, turn, plane)
    return arc_distance(p, arcs.take(np.zeros(p.shape[0], np.int64)))


class CurveDistance:
    """Distances from points to one clamped (rational) B-spline, independent of jaxcnc's Bézier code.

    ``scipy.interpolate.BSpline`` evaluates the homogeneous curve ``(w·P, w)``; dense samples (one per
    ``spacing_mm`` of control polygon, at least 8 per knot span) give each point a start, Newton projection
    on the curve refines it. Every distance returned is to a point of the curve (an upper bound of the true
    distance, exact where the nearest sample lay in the basin of the nearest point).
    """

    def __init__(
        self,
        degree: int,
        points: np.ndarray,
        weights: np.ndarray,
        knots: np.ndarray,
        spacing_mm: float = CURVE_SPACING_MM,
        max_samples: int = CURVE_MAX_SAMPLES,
    ):
        from scipy.interpolate import BSpline
        from scipy.spatial import cKDTree

        points = np.asarray(points, np.float64)
        weights = np.asarray(weights, np.float64)
        knots = np.asarray(knots, np.float64)
        self.degree = p = int(degree)
        hom = np.concatenate([points * weights[:, None], weights[:, None]], axis=1)
        # derivatives evaluated span by span (``nu``): a B-spline with an interior knot repeated ``p`` times is
        # only C0 there, and scipy refuses to build its derivative as one spline
        self._h = BSpline(knots, hom, p)
        self.u0, self.u1 = float(knots[p]), float(knots[-p - 1])
        # samples: per non-empty knot span, by the length of its control polygon
        m = points.shape[0]
        i = np.arange(p, m)
        i = i[knots[i + 1] > knots[i]]
        seg = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
        poly_len = seg[i] - seg[i - p]
        spacing = max(spacing_mm, float(np.sum(poly_len)) / max_samples)
        count = np.maximum(8, np.ceil(poly_len / spacing)).astype(np.int64)
        first = np.repeat(np.cumsum(count) - count, count)
        frac = (np.arange(int(count.sum())) - first) / np.repeat(count, count)
        u = np.repeat(knots[i], count) + frac * np.repeat(knots[i + 1] - knots[i], count)
        self.u = np.append(u, self.u1)
        self.samples = self.eval(self.u)[0]
        self._tree = cKDTree(self.samples)

    def eval(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, first and second derivative ``(m, 3)`` of the curve at parameters ``u``."""
        u = np.clip(np.asarray(u, np.float64), self.u0, self.u1)
        p = self.degree
        h, h1, h2 = (self._h(u, nu=k) if p >= k else np.zeros((u.size, 4)) for k in (0, 1, 2))
        w, w1, w2 = h[:, 3:], h1[:, 3:], h2[:, 3:]
        c = h[:, :3] / w
        c1 = (h1[:, :3] - c * w1) / w
        c2 = (h2[:, :3] - 2 * c1 * w1 - c * w2) / w
        return c, c1, c2

    def end_tangents(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit directions of travel ``(3,)`` at the start and at the end."""
        _, d1, _ = self.eval(np.array([self.u0, self.u1]))
        n = np.linalg.norm(d1, axis=1, keepdims=True)
        d1 = d1 / np.where(n > 0, n, 1.0)
        return d1[0], d1[1]

    def distance(self, p: np.ndarray) -> np.ndarray:
        """Distance from points ``p`` ``(m, 3)`` to the curve (an upper bound, see the class)."""
        p = np.atleast_2d(np.asarray(p, np.float64))
        d, k = self._tree.query(p)
        best = d**2
        u = self.u[k]
        todo = np.arange(p.shape[0])
        for _ in range(NEWTON_STEPS):
            c, c1, c2 = self.eval(u[todo])
            r = c - p[todo]
            best[todo] = np.minimum(best[todo], np.einsum("ij,ij->i", r, r))
            g = np.einsum("ij,ij->i", r, c1)
            speed2 = np.einsum("ij,ij->i", c1, c1)
            dg = speed2 + np.einsum("ij,ij->i", r, c2)
            step = g / np.where(dg > 0, dg, np.maximum(speed2, 1e-300))
            u_new = np.clip(u[todo] - step, self.u0, self.u1)
            moved = np.abs(u_new - u[todo]) > 1e-15 * max(1.0, abs(self.u1))
            u[todo] = u_new
            todo = todo[moved]
            if todo.size == 0:
                break
        if todo.size:
            c = self.eval(u[todo])[0]
            best[todo] = np.minimum(best[todo], np.einsum("ij,ij->i", c - p[todo], c - p[todo]))
        return np.sqrt(best)


# ----------------------------------------------------------------------------------------------
# The program's rows: what each tick is compared with, and what it is allowed


class ProgramPath:
    """The programmed geometry of a Program's rows, with the rows and tolerance each row's ticks get."""

    def __init__(self, program: Program, corner_tol_mm: float):
        self.program = pr = program
        n = len(pr)
        kind = pr.kind
        self.is_arc = kind == Kind.ARC
        self.is_curve = (kind == Kind.CURVE) & (pr.curve >= 0)
        line_len = np.linalg.norm(pr.end - pr.start, axis=1)
        self.moving = self.is_arc | self.is_curve | ((kind == Kind.LINE) & (line_len > MIN_MOVE_MM))
        arc_rows = np.flatnonzero(self.is_arc)  # the arcs of the arc rows alone (row r is arc arc_of[r])
        self.arc_of = np.full(n, -1, np.int64)
        self.arc_of[arc_rows] = np.arange(arc_rows.size)
        self.arcs = make_arcs(
            pr.start[arc_rows], pr.end[arc_rows], np.nan_to_num(pr.center[arc_rows]),
            np.where(pr.turn[arc_rows] < 0, -1, 1), pr.plane[arc_rows],
        )  # fmt: skip
        self._curves: dict[int, CurveDistance] = {}
        # nearest moving rows strictly before and after each row (-1: none)
        idx = np.arange(n)
        prev_incl = np.maximum.accumulate(np.where(self.moving, idx, -1)) if n else idx
        next_incl = np.minimum.accumulate(np.where(self.moving, idx, n)[::-1])[::-1] if n else idx
        self.prev = np.concatenate([[-1], prev_incl[:-1]]).astype(np.int64)
        after = np.concatenate([next_incl[1:], [n]]).astype(np.int64)
        self.next = np.where(after < n, after, -1)
        # junction tolerances: 0 after a row programmed without one (G61, G61.1, G64 P0) and where a row in between
        # starts at rest, else the lower of the two rows' (the second's only where it has one)
        stops = np.concatenate([[0], np.cumsum(pr.stop_before.astype(np.int64))])  # stops[i]: in rows < i
        tol_of = np.where(np.isinf(pr.blend_tol), corner_tol_mm, pr.blend_tol)
        tol_after = np.where(pr.blend_tol > 0, tol_of, np.inf)

        def junction(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            ok = (a >= 0) & (b >= 0)
            a_, b_ = np.where(ok, a, 0), np.where(ok, b, 0)
            stop = stops[b_ + 1] - stops[a_ + 1] > 0
            return np.where(ok & ~stop & (pr.blend_tol[a_] > 0), np.minimum(tol_of[a_], tol_after[b_]), 0.0)

        self.tol_in = np.where(self.moving, junction(self.prev, idx), junction(self.prev, self.next))
        self.tol_out = np.where(self.moving, junction(idx, self.next), 0.0)
        self.allowed = np.maximum(self.tol_in, self.tol_out)
        # corner zones around start[r] and end[r] (for the "away from corners" figure only)
        t_in, t_out = self._tangents()

        def zone(a: np.ndarray, b: np.ndarray, tol: np.ndarray) -> np.ndarray:
            cos = np.sum(t_out[np.where(a >= 0, a, 0)] * t_in[np.where(b >= 0, b, 0)], axis=1)
            theta = np.arccos(np.clip(cos, -1.0, 1.0))
            ok = (a >= 0) & (b >= 0) & (tol > 0) & (theta > CORNER_MIN_TURN_RAD)
            return np.where(ok, 16.0 * tol / (3.0 * np.sin(np.maximum(theta, CORNER_MIN_TURN_RAD) / 2)), 0.0)

        self.zone_in = np.where(self.moving, zone(self.prev, idx, self.tol_in), 0.0)
        self.zone_out = np.where(self.moving, zone(idx, self.next, self.tol_out), 0.0)

    def prepare_curves(self) -> None:
        """Build the distance function of every spline the program has (:meth:`curve` builds them on first use;
        threads that share this path then only read them)."""
        for i in np.unique(self.program.curve[self.is_curve]):
            self.curve(int(i))

    def curve(self, i: int) -> CurveDistance:
        """The distance function of spline ``i`` of the program (built once)."""
        if i not in self._curves:
            self._curves[i] = CurveDistance(*self.program.curves.curve(i))
        return self._curves[i]

    def _tangents(self) -> tuple[np.ndarray, np.ndarray]:
        pr = self.program
        d = pr.end - pr.start
        ln = np.linalg.norm(d, axis=1, keepdims=True)
        t_in = d / np.where(ln > 0, ln, 1.0)
        t_out = t_in.copy()
        if self.is_arc.any():
            a = np.flatnonzero(self.is_arc)
            t_in[a], t_out[a] = self.arcs.tangents()
        for r in np.flatnonzero(self.is_curve):
            t_in[r], t_out[r] = self.curve(int(pr.curve[r])).end_tangents()
        return t_in, t_out

    def distance(self, p: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Distance from points ``p`` ``(m, 3)`` to the programmed geometry of ``rows`` ``(m,)``."""
        pr = self.program
        out = segment_distance(p, pr.start[rows], pr.end[rows])  # lines; points for rows that stand
        arc = np.flatnonzero(self.is_arc[rows])
        if arc.size:
            out[arc] = arc_distance(p[arc], self.arcs.take(self.arc_of[rows[arc]]))
        crv = np.flatnonzero(self.is_curve[rows])
        if crv.size:
            ids = pr.curve[rows[crv]]
            for i in np.unique(ids):
                sel = crv[ids == i]
                out[sel] = self.curve(int(i)).distance(p[sel])
        return out


# ----------------------------------------------------------------------------------------------
# Loading the program of a table, and the check itself


def _block_rows(table: TableFile, program: Program) -> tuple[np.ndarray, np.ndarray]:
    """Ticks and program rows of the table's BLOCK events, checked against the program."""
    ev = table.events[table.events["kind"] == EventKind.BLOCK]
    if ev.size == 0:
        raise JaxcncError(f"{table.path}: the table has no block events to tie its ticks to program rows")
    rows = ev["value"].astype(np.int64)
    bad = (rows < 0) | (rows >= len(program)) | (ev["value"] != rows)
    if not bad.any():
        bad = program.line[rows] != ev["aux"].astype(np.int64)
    if bad.any():
        i = int(np.argmax(bad))
        raise JaxcncError(
            f"{table.path}: block event at tick {int(ev['tick'][i])} names program row {ev['value'][i]:g} "
            f"(line {int(ev['aux'][i])}), which {program.file} does not have: not the program of this table"
        )
    n_meta = table.header.meta.get("n_blocks")
    if n_meta is not None and int(n_meta) != len(program):
        raise JaxcncError(
            f"{table.path}: planned from a program of {n_meta} blocks, {program.file} has {len(program)}: "
            "not the program of this table"
        )
    return ev["tick"].astype(np.int64), rows


def tool_rows_distance(table: TableFile, program: Program, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, int] | None:
    """Each tick's program row (the last BLOCK event at or before it), the distance of the tool point ``p``
    ``(n_rows, 3)`` mm from that row — or from the moving row before it, where a tick just past a joint may
    still lie — and the first block's tick (before it the machine has not reached the program). ``None``
    where the table's block events do not match the program (the caller records it)."""
    ev = table.events[table.events["kind"] == EventKind.BLOCK]
    rows_ev = ev["value"].astype(np.int64)
    if ev.size == 0 or np.any(rows_ev >= len(program)) or np.any(rows_ev < 0):
        return None
    row = rows_ev[np.maximum(np.searchsorted(ev["tick"], np.arange(table.n_rows), side="right") - 1, 0)]
    geo = ProgramPath(program, 0.0)
    prev = np.where(geo.prev[row] >= 0, geo.prev[row], row)
    return row, np.minimum(geo.distance(p, row), geo.distance(p, prev)), int(ev["tick"][0])


def tool_point_violations(tool: np.ndarray, d: np.ndarray, row: np.ndarray, program: Program, tol: float) -> list[str]:
    """One line for each of the first 20 ticks whose tool point ``tool`` ``(n_rows, 2)`` lies more than ``tol``
    mm from its program row (``d``, ``row`` from :func:`tool_rows_distance`)."""
    return [
        f"tick {k}: tool point ({tool[k, 0]:.6g}, {tool[k, 1]:.6g}) is {d[k]:.3g} mm from line "
        f"{program.line[row[k]]} (allowed {tol:.3g} mm)"
        for k in np.flatnonzero(d > tol)[:20]
    ]


def path_deviation(
    table: TableFile,
    machine: MachineConfig,
    program: Program,
    *,
    slack_mm: float = SLACK_MM,
    chunk_rows: int = CHUNK_ROWS,
    threads: int | None = None,
) -> PathDeviation:
    """Measure every tick's distance from the programmed path of ``program`` and compare it with the
    tolerance allowed there (module docstring). Streams the table ``chunk_rows`` ticks at a time, measured on
    ``threads`` threads (:func:`~jaxcnc.ticks.verify.check_threads` by default); the result depends on
    neither."""
    h = table.header
    geo = ProgramPath(program, machine.path.corner_tol_mm)
    shaping = h.meta.get("shaping_tol_mm", 0.0)
    if isinstance(shaping, bool) or not isinstance(shaping, (int, float)) or not 0.0 <= shaping <= 1.0:
        raise JaxcncError(f"{table.path}: header shaping_tol_mm = {shaping!r}: must be a number in 0..1 mm")
    ev_tick, ev_row = _block_rows(table, program)
    axes = h.axes
    cols = [(i, PROGRAM_AXES.index(a)) for i, a in enumerate(axes) if a in PROGRAM_AXES]
    fixed = [c for c in range(3) if c not in {c for _, c in cols}]
    start = program.start[0] if len(program) else program_start(machine)
    n = h.n_rows
    best, worst_tick, away_max, n_away, n_over, max_tol = -1.0, 0, -1.0, 0, 0, 0.0
    pending: list[tuple[int, int, float, float, int]] = []
    geo.prepare_curves()  # (built once, before the threads share them)

    def chunk(reader: TableRows, s: int) -> tuple:
        """Ticks ``s .. s + chunk_rows - 1``: their worst distance and its tick, the largest tolerance, the ticks
        away from corners and their worst distance, the ticks over the tolerance and their runs."""
        e = min(s + chunk_rows, n)
        m_pos = reader.exact_mm(s, e)
        p = np.empty((e - s, 3))
        for i, c in cols:
            p[:, c] = m_pos[:, i]
        for c in fixed:
            p[:, c] = start[c]
        ticks = np.arange(s, e)
        row = ev_row[np.maximum(np.searchsorted(ev_tick, ticks, side="right") - 1, 0)]
        dist = geo.distance(p, row)  # its own row; the neighbours only where that is not already ~0
        far = np.flatnonzero(dist > ON_PATH_MM)
        for other in (geo.prev[row[far]], geo.next[row[far]]):
            sel = far[other >= 0]
            dist[sel] = np.minimum(dist[sel], geo.distance(p[sel], other[other >= 0]))
        tol_row = np.maximum(geo.allowed[row], shaping)
        allowed = tol_row + slack_mm
        j = int(np.argmax(dist))
        z_in, z_out = geo.zone_in[row], geo.zone_out[row]
        away = ((z_in == 0) | (np.linalg.norm(p - program.start[row], axis=1) > z_in)) & (
            (z_out == 0) | (np.linalg.norm(p - program.end[row], axis=1) > z_out)
        )
        away_n = int(away.sum())
        over = dist > allowed
        runs = []
        for r0, r1 in _runs(over):
            w = r0 + int(np.argmax(dist[r0 : r1 + 1]))
            runs.append((s + r0, s + r1, float(dist[w]), float(allowed[w]), int(program.line[row[w]])))
        worst_away = float(dist[away].max()) if away_n else -1.0
        return float(dist[j]), s + j, float(tol_row.max()), away_n, worst_away, int(over.sum()), runs

    with TableRows(table) as reader:
        found = map_chunks(reader, chunk, range(0, n, chunk_rows), check_threads() if threads is None else threads)
        for c_best, c_tick, c_tol, c_away, c_away_max, c_over, runs in found:  # in chunk order
            max_tol = max(max_tol, c_tol)
            if c_best > best:
                best, worst_tick = c_best, c_tick
            if c_away:
                n_away += c_away
                away_max = max(away_max, c_away_max)
            n_over += c_over
            pending += runs
    merged: list[list] = []
    for r0, r1, v, lim, line in pending:  # join runs split by chunk boundaries
        if merged and r0 == merged[-1][1] + 1:
            if v > merged[-1][2]:
                merged[-1][2:] = [v, lim, line]
            merged[-1][1] = r1
        else:
            merged.append([r0, r1, v, lim, line])
    worst_row = int(ev_row[max(int(np.searchsorted(ev_tick, worst_tick, side="right")) - 1, 0)])
    return PathDeviation(
        n_ticks=n,
        max_mm=max(best, 0.0),
        worst_tick=worst_tick,
        worst_row=worst_row,
        worst_line=int(program.line[worst_row]),
        allowed_at_worst_mm=float(max(geo.allowed[worst_row], shaping) + slack_mm),
        n_over=n_over,
        max_away_mm=away_max if n_away else math.nan,
        n_away=n_away,
        max_tol_mm=max_tol,
        slack_mm=slack_mm,
        violations=[Violation(r0, r1, f"line {line}", "path", v, lim) for r0, r1, v, lim, line in merged],
    )
