"""Drawings to Programs: pieces (lines, arcs, splines) chained into contours, checked, ordered, cut.

The drawing front ends (:mod:`jaxcnc.io.dxf`, :mod:`jaxcnc.io.hpgl`) turn their entities into
:class:`Piece` records and call :func:`assemble`. It

1. drops zero-length pieces and duplicates (a piece whose end points and shape lie within the chaining
   tolerance of another's, in either direction), each noted;
2. joins piece ends closer than the tolerance (``DrawingOptions.tol_mm``, default 0.01 mm) into nodes
   (a k-d tree and connected components) and walks the chains; a gap left inside the tolerance is
   bridged by a straight cut so the Program stays continuous;
3. checks with shapely, unless open contours are allowed (engraving): every contour closed (a chain
   end names its entity and the point), no branch (three or more entities ending at one node), no
   contour crossing itself (``explain_validity``) or another (an ``STRtree`` query) — each refusal a
   :class:`~jaxcnc.errors.SourceError` naming the entity (handle, layer) or line and the place;
4. orders the cut: contours nested in others (holes, and islands in holes) before the contour around
   them, then the nearest one next (greedy from the machine's start), each closed contour started at
   its piece boundary nearest to where the tool stands; outer contours counter-clockwise, holes
   clockwise (the scrap on the right); an optional straight lead-in from the scrap side;
5. builds the :class:`~jaxcnc.program.Program`: rapids between contours (laser off), the contour at
   the job's feed (``nan``: the machine file's ``[path] feed``) with the laser on at the job's power,
   the laser switched at rest.

The Program's ``line`` column holds the 1-based number of the entity (DXF: in drawing order, INSERT
contents numbered after their block reference) or the source line (HPGL).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from jaxcnc.errors import SourceError
from jaxcnc.program import Kind, LaserMode, Program, make_curve_table, program_from_rows

Curve = tuple[int, np.ndarray, np.ndarray, np.ndarray]
#: Two chain ends closer than this (mm) are joined without a bridging cut.
SNAP_MM = 1e-9
#: Polyline points closer than this (mm) are merged for the shapely checks (rounding between entities).
POLY_MERGE_MM = 1e-6


@dataclass(frozen=True)
class DrawingOptions:
    """How a drawing becomes a job (all optional; the defaults suit laser cutting of parts).

    Attributes:
        tol_mm: chain ends closer than this are joined; pieces within it of each other are duplicates.
        allow_open: engraving: open and crossing contours are cut as drawn (no closure/crossing checks).
        feed_mm_s: contour speed; ``None``: the machine file's ``[path] feed``.
        power: laser power scale while cutting (the S word of G-code), 1 = full.
        lead_in_mm: length of a straight lead-in from the scrap side (0: none).
        chord_tol_mm: chord tolerance of the polylines the shapely checks use.
        layers: DXF only: cut only these layers (``None``: every visible layer).
    """

    tol_mm: float = 0.01
    allow_open: bool = False
    feed_mm_s: float | None = None
    power: float = 1.0
    lead_in_mm: float = 0.0
    chord_tol_mm: float = 0.002
    layers: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        """Refuse values no drawing can be cut with (``ValueError`` naming the option)."""

        def number(name: str, low: float, high: float, low_open: bool = False) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"option {name} = {v!r}: must be a finite number")
            if v < low or (low_open and v == low) or v > high:
                side = f"> {low:g}" if low_open else f">= {low:g}"
                raise ValueError(f"option {name} = {v!r}: must be {side} and <= {high:g}")
            object.__setattr__(self, name, float(v))

        number("tol_mm", 0.0, 1.0, low_open=True)
        number("chord_tol_mm", 0.0, 1.0, low_open=True)
        number("power", 0.0, 1e6)
        number("lead_in_mm", 0.0, 1e4)
        if self.feed_mm_s is not None:
            number("feed_mm_s", 0.0, 1e6, low_open=True)
        if not isinstance(self.allow_open, bool):
            raise ValueError(f"option allow_open = {self.allow_open!r}: must be true or false")
        if self.layers is not None:
            layers = (self.layers,) if isinstance(self.layers, str) else self.layers
            if not isinstance(layers, (list, tuple)) or not layers or not all(isinstance(x, str) for x in layers):
                raise ValueError(f"option layers = {self.layers!r}: must be one or more layer names")
            object.__setattr__(self, "layers", tuple(layers))


@dataclass(frozen=True, eq=False)
class Piece:
    """One drawn element in the XY plane (mm).

    Attributes:
        kind: :class:`~jaxcnc.program.Kind` LINE, ARC or CURVE.
        start, end: ``(2,)`` end points.
        center: ``(2,)`` arc centre (ARC only).
        turn: +1 counter-clockwise, -1 clockwise (ARC only).
        curve: ``(degree, points (m, 2), weights (m,), knots (m+degree+1,))`` (CURVE only).
        poly: ``(k, 2)`` points along the piece from start to end, within the chord tolerance.
        source: what drew it, for messages (``LINE #6F on layer 'CUT'``, ``line 12``).
        number: the Program's ``line`` value for its rows.
    """

    kind: int
    start: np.ndarray
    end: np.ndarray
    poly: np.ndarray
    source: str
    number: int
    center: np.ndarray | None = None
    turn: int = 0
    curve: Curve | None = None

    def reversed(self) -> Piece:
        """The same piece drawn the other way."""
        curve = self.curve
        if curve is not None:
            p, pts, w, kn = curve
            curve = (p, pts[::-1].copy(), w[::-1].copy(), (kn[0] + kn[-1]) - kn[::-1])
        return replace(self, start=self.end, end=self.start, poly=self.poly[::-1].copy(), turn=-self.turn, curve=curve)

    @property
    def length_mm(self) -> float:
        return float(np.sum(np.linalg.norm(np.diff(self.poly, axis=0), axis=1)))


def arc_piece(
    center: np.ndarray, radius: float, a0: float, sweep: float, source: str, number: int, chord_tol_mm: float
) -> list[Piece]:
    """Arc pieces from angle ``a0`` (rad) sweeping ``sweep`` (rad, signed: + counter-clockwise).

    A full circle (``|sweep|`` = 2π) is returned as two half circles (a Program arc needs distinct ends).
    """
    center = np.asarray(center, np.float64)
    if abs(abs(sweep) - 2 * math.pi) < 1e-12:
        half = math.copysign(math.pi, sweep)
        return arc_piece(center, radius, a0, half, source, number, chord_tol_mm) + arc_piece(
            center, radius, a0 + half, half, source, number, chord_tol_mm
        )
    step = 2 * math.acos(max(-1.0, 1 - chord_tol_mm / radius)) if radius > chord_tol_mm else math.pi / 2
    n = max(2, int(math.ceil(abs(sweep) / max(step, 1e-6))) + 1)
    ang = a0 + np.linspace(0.0, sweep, min(n, 20001))
    poly = center + radius * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    return [
        Piece(
            Kind.ARC, poly[0].copy(), poly[-1].copy(), poly, source, number, center=center, turn=1 if sweep > 0 else -1
        )
    ]


def line_piece(a: np.ndarray, b: np.ndarray, source: str, number: int) -> Piece:
    """A straight piece from ``a`` to ``b`` ``(2,)`` mm."""
    a, b = np.asarray(a, np.float64)[:2], np.asarray(b, np.float64)[:2]
    return Piece(Kind.LINE, a, b, np.stack([a, b]), source, number)


@dataclass(frozen=True, eq=False)
class Contour:
    """Pieces joined end to end, in cut order. ``closed``: ends where it starts; ``depth``: how many contours
    lie around it (0: an outer contour, 1: a hole, 2: an island in a hole, ...)."""

    pieces: tuple[Piece, ...]
    closed: bool
    depth: int = 0

    @property
    def poly(self) -> np.ndarray:
        """``(k, 2)`` the contour's polyline for the checks (a closed one without its closing point)."""
        # each joint (within the chaining tolerance) is taken at the end of the piece before it
        pts = np.concatenate([self.pieces[0].poly] + [p.poly[1:] for p in self.pieces[1:]])
        if self.closed and pts.shape[0] > 2:
            pts = pts[:-1]  # the ring closes itself at the first point
        keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > POLY_MERGE_MM])
        return pts[keep]


@dataclass(frozen=True, eq=False)
class Drawing:
    """A drawing as a job: the Program, its contours in cut order, notes (what was dropped or assumed)."""

    program: Program
    contours: tuple[Contour, ...]
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def cut_length_mm(self) -> float:
        return float(sum(p.length_mm for c in self.contours for p in c.pieces))


def _fmt(p: np.ndarray) -> str:
    return f"({p[0]:.4g}, {p[1]:.4g})"


def _nodes(pieces: list[Piece], tol: float) -> np.ndarray:
    """``(n, 2)`` node ids of each piece's start and end: ends within ``tol`` of each other share a node."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    ends = np.concatenate([np.stack([p.start for p in pieces]), np.stack([p.end for p in pieces])])
    pairs = cKDTree(ends).query_pairs(tol, output_type="ndarray")
    m = ends.shape[0]
    graph = coo_matrix((np.ones(pairs.shape[0]), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    _, label = connected_components(graph, directed=False)
    n = len(pieces)
    return np.stack([label[:n], label[n:]], axis=1)


def _dedupe(pieces: list[Piece], tol: float, notes: list[str]) -> list[Piece]:
    """Zero-length pieces and duplicates dropped (noted)."""
    from shapely import LineString

    kept = []
    for p in pieces:
        if p.length_mm <= tol and float(np.linalg.norm(p.end - p.start)) <= tol:
            notes.append(f"dropped {p.source}: zero length at {_fmt(p.start)}")
        else:
            kept.append(p)
    if not kept:
        return kept
    node = _nodes(kept, tol)
    out: list[Piece] = []
    seen: dict[tuple[int, int], list[int]] = {}
    for i, p in enumerate(kept):
        key = (int(min(node[i])), int(max(node[i])))
        dup = None
        for j in seen.get(key, []):
            q = kept[j]
            if LineString(p.poly).hausdorff_distance(LineString(q.poly)) <= tol:
                dup = q
                break
        if dup is not None:
            notes.append(f"dropped {p.source}: a duplicate of {dup.source}")
            continue
        seen.setdefault(key, []).append(i)
        out.append(p)
    return out


def _chains(pieces: list[Piece], tol: float, allow_open: bool, file: str, line_of) -> list[Contour]:
    """Walk the pieces into chains (closed where a chain returns to its first node)."""
    node = _nodes(pieces, tol)
    n_nodes = int(node.max()) + 1
    degree = np.bincount(node.ravel(), minlength=n_nodes)
    if not allow_open and np.any(degree > 2):
        k = int(np.flatnonzero(degree > 2)[0])
        at = [i for i in range(len(pieces)) if k in node[i]]
        where = pieces[at[0]].start if node[at[0], 0] == k else pieces[at[0]].end
        names = ", ".join(pieces[i].source for i in at[:4])
        raise SourceError(
            file,
            line_of(pieces[at[0]]),
            0,
            f"contours branch or touch at {_fmt(where)}: {int(degree[k])} entity ends meet there ({names})",
        )
    incident: list[list[int]] = [[] for _ in range(n_nodes)]
    for i in range(len(pieces)):
        incident[node[i, 0]].append(i)
        if node[i, 1] != node[i, 0]:
            incident[node[i, 1]].append(i)
    used = np.zeros(len(pieces), bool)
    chains: list[Contour] = []

    def walk(first_node: int) -> None:
        at, out = first_node, []
        while True:
            nxt = next((i for i in incident[at] if not used[i]), None)
            if nxt is None:
                break
            used[nxt] = True
            p = pieces[nxt]
            if node[nxt, 0] == at:
                out.append(p)
                at = int(node[nxt, 1])
            else:
                out.append(p.reversed())
                at = int(node[nxt, 0])
            if at == first_node:
                break
        if out:
            chains.append(Contour(tuple(out), closed=at == first_node))

    for k in np.flatnonzero(degree % 2 == 1):  # open chains from their ends first
        walk(int(k))
    for i in range(len(pieces)):
        if not used[i]:
            walk(int(node[i, 0]))
    if not allow_open:
        for c in chains:
            if not c.closed:
                a, b = c.pieces[0], c.pieces[-1]
                raise SourceError(
                    file,
                    line_of(b),
                    0,
                    f"open contour: {b.source} ends at {_fmt(b.end)} and {a.source} starts at {_fmt(a.start)} "
                    f"with no entity within {tol:g} mm (a closed contour is required; allow open contours to engrave)",
                )
    return chains


def _nearest_piece(c: Contour, pt) -> Piece:
    from shapely import LineString, Point

    d = [LineString(p.poly).distance(Point(pt)) if len(p.poly) > 1 else 0.0 for p in c.pieces]
    return c.pieces[int(np.argmin(d))]


def _check(chains: list[Contour], file: str, line_of) -> np.ndarray:
    """Self-intersection and crossing checks of closed contours; ``(n,)`` nesting depth of each."""
    import re

    from shapely import LinearRing, Polygon, STRtree
    from shapely.validation import explain_validity

    rings, polys = [], []
    for c in chains:
        pts = c.poly
        if pts.shape[0] < 3:
            p = c.pieces[0]
            raise SourceError(file, line_of(p), 0, f"contour of {p.source} at {_fmt(p.start)} encloses no area")
        ring = LinearRing(pts)
        if not ring.is_simple or Polygon(pts).area <= 0.0:
            why = explain_validity(Polygon(pts))
            m = re.search(r"\[([-\d.eE+]+) ([-\d.eE+]+)\]", why)
            at = np.array([float(m.group(1)), float(m.group(2))]) if m else pts[0]
            p = _nearest_piece(c, at)
            raise SourceError(file, line_of(p), 0, f"contour crosses itself at {_fmt(at)} ({p.source})")
        rings.append(ring)
        polys.append(Polygon(pts))
    tree = STRtree(rings)
    pairs = tree.query(rings, predicate="intersects")
    for i, j in pairs.T:
        if i < j:
            x = rings[i].intersection(rings[j])
            at = np.asarray(x.representative_point().coords[0])
            p, q = _nearest_piece(chains[i], at), _nearest_piece(chains[j], at)
            raise SourceError(file, line_of(p), 0, f"contours cross or touch at {_fmt(at)}: {p.source} and {q.source}")
    depth = np.zeros(len(polys), np.int64)
    inside = STRtree(polys).query(polys, predicate="contains_properly")
    for i, j in inside.T:
        if i != j:
            depth[j] += 1
    return depth


def _start_at(c: Contour, k: int) -> Contour:
    return replace(c, pieces=c.pieces[k:] + c.pieces[:k])


def _order(chains: list[Contour], start: np.ndarray) -> list[Contour]:
    """Inner contours before the contours around them, the nearest next; closed ones started nearest."""
    from shapely import Point, Polygon

    polys = [Polygon(c.poly) if c.closed else None for c in chains]
    around = [
        {j for j, q in enumerate(polys) if q is not None and j != i and q.contains(Point(chains[i].poly[0]))}
        for i in range(len(chains))
    ]
    left = set(range(len(chains)))
    at = np.asarray(start[:2], np.float64)
    out = []
    while left:
        ready = [i for i in left if not any(i in around[j] for j in left if j != i)] or sorted(left)
        best, best_d, best_c = None, math.inf, None
        for i in ready:
            c = chains[i]
            if c.closed:
                heads = np.stack([p.start for p in c.pieces])
                d = np.linalg.norm(heads - at, axis=1)
                k = int(np.argmin(d))
                cand, dist = _start_at(c, k), float(d[k])
            else:
                d0 = float(np.linalg.norm(c.pieces[0].start - at))
                d1 = float(np.linalg.norm(c.pieces[-1].end - at))
                cand = c if d0 <= d1 else replace(c, pieces=tuple(p.reversed() for p in reversed(c.pieces)))
                dist = min(d0, d1)
            if dist < best_d:
                best, best_d, best_c = i, dist, cand
        left.remove(best)
        out.append(best_c)
        at = best_c.pieces[-1].end
    return out


def _orient(c: Contour) -> Contour:
    """Outer contours (even depth) counter-clockwise, holes clockwise: the scrap on the right."""
    from shapely import LinearRing

    if not c.closed:
        return c
    ccw = LinearRing(c.poly).is_ccw
    if ccw == (c.depth % 2 == 0):
        return c
    return replace(c, pieces=tuple(p.reversed() for p in reversed(c.pieces)))


def _lead_in(c: Contour, length_mm: float, others) -> np.ndarray | None:
    """Where a lead-in of ``length_mm`` starts (on the scrap side, square to the first piece), or ``None``
    when it would cross a contour."""
    from shapely import LineString

    p = c.pieces[0]
    t = p.poly[1] - p.poly[0]
    t = t / np.linalg.norm(t)
    q = p.start + length_mm * np.array([t[1], -t[0]])
    seg = LineString([q, p.start])
    for ring in others:
        x = seg.intersection(ring)
        if not x.is_empty and x.distance(LineString([p.start, p.start])) > 1e-9:
            return None
        if not x.is_empty and ring.distance(LineString([q, q])) < 1e-9:
            return None
    return q


def assemble(
    pieces: list[Piece],
    options: DrawingOptions,
    start: np.ndarray,
    file: str,
    notes: list[str] | None = None,
) -> Drawing:
    """Chain, check, order and cut ``pieces`` (module docstring); ``start`` ``(3,)`` where the tool stands.

    Raises:
        SourceError: open, branching, self-intersecting or crossing contours (unless ``allow_open``), an
            empty drawing; named by entity and place.
    """
    from shapely import LinearRing

    notes = list(notes or [])
    tol = float(options.tol_mm)

    def line_of(p: Piece) -> int:
        return int(p.number)

    pieces = _dedupe(pieces, tol, notes)
    if not pieces:
        raise SourceError(file, 0, 0, "the drawing has nothing to cut (no lines, arcs or curves of non-zero length)")
    chains = _chains(pieces, tol, options.allow_open, file, line_of)
    closed = [c for c in chains if c.closed]
    if not options.allow_open:
        depth = _check(closed, file, line_of)
        chains = [replace(c, depth=int(d)) for c, d in zip(closed, depth, strict=True)]
    chains = [_orient(c) for c in chains]
    ordered = _order(chains, np.asarray(start, np.float64))
    rings = [LinearRing(c.poly) for c in ordered if c.closed]
    leads: list[np.ndarray | None] = []
    for c in ordered:
        q = None
        if options.lead_in_mm > 0 and c.closed:
            q = _lead_in(c, options.lead_in_mm, rings)
            if q is None:
                notes.append(f"no lead-in for the contour of {c.pieces[0].source}: it would cross a contour")
        leads.append(q)
    program = _program(ordered, leads, options, np.asarray(start, np.float64), file)
    return Drawing(program=program, contours=tuple(ordered), notes=tuple(notes))


def _program(
    contours: list[Contour], leads: list[np.ndarray | None], options: DrawingOptions, start: np.ndarray, file: str
) -> Program:
    z = float(start[2])
    feed = np.nan if options.feed_mm_s is None else float(options.feed_mm_s)
    rows: dict[str, list] = {
        k: [] for k in ("kind", "start", "end", "center", "turn", "rapid", "feed", "curve", "laser", "power", "line")
    }
    curves: list[Curve] = []
    pos = start.astype(np.float64).copy()
    nan3 = np.full(3, np.nan)

    def add(kind, end2, number, rapid=False, center=None, turn=0, curve=-1):
        nonlocal pos
        end = np.array([end2[0], end2[1], z])
        rows["kind"].append(kind)
        rows["start"].append(pos.copy())
        rows["end"].append(end)
        rows["center"].append(nan3 if center is None else np.array([center[0], center[1], z]))
        rows["turn"].append(turn)
        rows["rapid"].append(rapid)
        rows["feed"].append(np.nan if rapid else feed)
        rows["curve"].append(curve)
        rows["laser"].append(LaserMode.OFF if rapid else LaserMode.CONSTANT)
        rows["power"].append(0.0 if rapid else options.power)
        rows["line"].append(number)
        pos = end

    for c, lead in zip(contours, leads, strict=True):
        first = c.pieces[0]
        entry = first.start if lead is None else lead
        if np.linalg.norm(entry - pos[:2]) > 0 or pos[2] != z:
            add(Kind.LINE, entry, first.number, rapid=True)
        if lead is not None:
            add(Kind.LINE, first.start, first.number)
        for p in c.pieces:
            gap = float(np.linalg.norm(p.start - pos[:2]))
            if gap > SNAP_MM:  # joined within the tolerance: bridge the gap
                add(Kind.LINE, p.start, p.number)
            elif gap > 0:
                pos[:2] = p.start
            if p.kind == Kind.LINE:
                add(Kind.LINE, p.end, p.number)
            elif p.kind == Kind.ARC:
                add(Kind.ARC, p.end, p.number, center=p.center, turn=p.turn)
            else:
                deg, pts, w, kn = p.curve
                pts3 = np.concatenate([pts, np.full((pts.shape[0], 1), z)], axis=1)
                pts3[0, :2], pts3[-1, :2] = pos[:2], p.end  # exact ends (within SNAP_MM)
                curves.append((deg, pts3, w, kn))
                add(Kind.CURVE, p.end, p.number, curve=len(curves) - 1)
        if c.closed and np.linalg.norm(c.pieces[0].start - pos[:2]) > SNAP_MM:
            add(Kind.LINE, c.pieces[0].start, c.pieces[-1].number)
    return program_from_rows(file, rows, make_curve_table(curves) if curves else None)
