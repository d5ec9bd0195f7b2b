"""DXF drawings as Programs, read with ezdxf.

Entities cut: LINE, ARC, CIRCLE, LWPOLYLINE and 2-D POLYLINE (bulges become arcs: ezdxf's virtual
entities), SPLINE (a clamped NURBS kept exact as a Program curve; one ezdxf cannot give clamped is cut as
lines within the chord tolerance, noted), ELLIPSE (an exact rational quadratic B-spline), INSERT (block
references, expanded with their transformation, nested ones too). Annotations (TEXT, MTEXT, DIMENSION,
LEADER, MLEADER, ATTDEF, ATTRIB, POINT, VIEWPORT, HATCH fills) are skipped and noted; any other entity
type is refused by name, handle and layer. Entities on frozen or switched-off layers are skipped (noted);
``DrawingOptions.layers`` selects layers (a name the drawing lacks is an error). Coordinates are
drawing units times the ``$INSUNITS`` factor (unitless drawings are taken as mm, noted); Z is dropped,
and an arc or circle whose plane is not the XY plane (extrusion other than ±Z) is refused.

Everything else — chaining, duplicates, the shapely checks, cut order, lead-ins, feed and laser — is
:mod:`jaxcnc.io.drawing`. A file ezdxf cannot read is one error naming the file and ezdxf's reason.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from jaxcnc.errors import SourceError
from jaxcnc.io.drawing import Drawing, DrawingOptions, Piece, arc_piece, assemble, line_piece
from jaxcnc.program import Kind, make_curve_table

DXF_SUFFIXES = (".dxf",)
#: Entity types skipped as annotation (noted, not cut).
ANNOTATION = frozenset(
    {"TEXT", "MTEXT", "DIMENSION", "ARC_DIMENSION", "LEADER", "MLEADER", "MULTILEADER", "ATTDEF", "ATTRIB",
     "POINT", "VIEWPORT", "HATCH", "IMAGE", "WIPEOUT", "TOLERANCE", "XLINE", "RAY"}
)  # fmt: skip
#: INSERTs nested deeper than this are refused (a block that inserts itself).
MAX_NESTING = 16
# What ezdxf (and the data it hands back) raises on a damaged file or entity.
_READ_ERRORS = (OSError, UnicodeError, ValueError, KeyError, IndexError, TypeError, AttributeError, EOFError,
                ZeroDivisionError, OverflowError, AssertionError, RecursionError, StopIteration)  # fmt: skip


def _dxf_errors() -> tuple[type[BaseException], ...]:
    import ezdxf

    return (ezdxf.DXFError, *_READ_ERRORS)


def read_dxf(path: str | Path, start: np.ndarray, options: DrawingOptions | None = None) -> Drawing:
    """The DXF file at ``path`` as a job (:class:`~jaxcnc.io.drawing.Drawing`), starting at ``start`` ``(3,)``.

    Raises:
        SourceError: the file cannot be read, holds an unsupported entity, or its contours fail the checks
            (entity handle, layer and place named; see :mod:`jaxcnc.io.drawing`).
    """
    import ezdxf

    options = options or DrawingOptions()
    file = str(path)
    try:
        doc = ezdxf.readfile(file)
    except _dxf_errors() as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise SourceError(file, 0, 0, f"not a readable DXF drawing: {reason[:200]}") from None
    notes: list[str] = []
    try:
        pieces = _pieces(doc, options, file, notes)
    except SourceError:
        raise
    except _dxf_errors() as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise SourceError(file, 0, 0, f"damaged DXF drawing: {reason[:200]}") from None
    return assemble(pieces, options, start, file, notes)


def _scale(doc, notes: list[str]) -> float:
    from ezdxf import units

    code = int(doc.header.get("$INSUNITS", 0) or 0)
    if code == 0:
        notes.append("$INSUNITS is unset (unitless drawing): coordinates taken as mm")
        return 1.0
    try:
        return float(units.conversion_factor(code, units.MM))
    except (KeyError, IndexError, ValueError) as exc:
        raise SourceError(doc.filename or "<dxf>", 0, 0, f"$INSUNITS = {code} is not a length unit") from exc


def _pieces(doc, options: DrawingOptions, file: str, notes: list[str]) -> list[Piece]:
    scale = _scale(doc, notes)
    msp = doc.modelspace()
    # the layer table, and layers entities name without a table entry (allowed: CAD programs create them on load)
    names = {layer.dxf.name for layer in doc.layers} | {e.dxf.get("layer", "0") for e in msp}
    if options.layers is not None:
        missing = [n for n in options.layers if n not in names]
        if missing:
            raise SourceError(
                file, 0, 0, f"no layer {missing[0]!r} in the drawing (layers: {', '.join(sorted(names))})"
            )
    hidden = {layer.dxf.name for layer in doc.layers if layer.is_frozen() or layer.is_off()}
    out: list[Piece] = []
    skipped: dict[str, int] = {}
    counter = [0]

    def visit(e, depth: int, via: str, layer_of_insert: str | None) -> None:
        counter[0] += 1
        number = counter[0]
        kind = e.dxftype()
        layer = e.dxf.get("layer", "0")
        if layer == "0" and layer_of_insert is not None:
            layer = layer_of_insert  # block contents on layer 0 take the reference's layer
        handle = e.dxf.get("handle") or "?"
        source = f"{kind} #{handle}{via} on layer {layer!r}"
        if layer in hidden or (options.layers is not None and layer not in options.layers):
            skipped[f"layer {layer!r}"] = skipped.get(f"layer {layer!r}", 0) + 1
            return
        if kind in ANNOTATION:
            skipped[kind] = skipped.get(kind, 0) + 1
            return
        if kind == "INSERT":
            if depth >= MAX_NESTING:
                raise SourceError(file, number, 0, f"{source}: block references nested deeper than {MAX_NESTING}")
            for ve in e.virtual_entities():
                visit(ve, depth + 1, f" in block {e.dxf.name!r} of INSERT #{handle}", layer)
            return
        out.extend(_entity(e, kind, source, number, scale, options, file, notes))

    for e in msp:
        visit(e, 0, "", None)
    for what, n in sorted(skipped.items()):
        notes.append(f"skipped {n} {what} entit{'y' if n == 1 else 'ies'} (not cut)")
    return out


def _planar(e, source: str, number: int, file: str) -> float:
    """+1 or -1: the entity's extrusion is +Z or -Z; anything else is refused."""
    ex = e.dxf.get("extrusion", (0.0, 0.0, 1.0))
    if abs(ex[0]) > 1e-9 or abs(ex[1]) > 1e-9 or abs(ex[2]) < 1e-9:
        raise SourceError(file, number, 0, f"{source}: not in the XY plane (extrusion {tuple(ex)})")
    return 1.0 if ex[2] > 0 else -1.0


def _xy(v, scale: float) -> np.ndarray:
    return np.array([float(v[0]), float(v[1])]) * scale


def _entity(e, kind, source, number, scale, options: DrawingOptions, file, notes) -> list[Piece]:
    tol = options.chord_tol_mm
    if kind == "LINE":
        return [line_piece(_xy(e.dxf.start, scale), _xy(e.dxf.end, scale), source, number)]
    if kind in ("ARC", "CIRCLE"):
        sign = _planar(e, source, number, file)
        r = float(e.dxf.radius) * scale
        if not (r > 0 and math.isfinite(r)):
            raise SourceError(file, number, 0, f"{source}: radius {e.dxf.radius!r} is not positive")
        center = _xy(e.ocs().to_wcs(e.dxf.center), scale)
        if kind == "CIRCLE":
            return arc_piece(center, r, 0.0, 2 * math.pi * sign, source, number, tol)
        sp = _xy(e.start_point, scale) - center
        a0 = math.atan2(sp[1], sp[0])
        sweep = math.radians((float(e.dxf.end_angle) - float(e.dxf.start_angle)) % 360.0)
        if sweep == 0.0:
            sweep = 2 * math.pi
        return arc_piece(center, r, a0, sweep * sign, source, number, tol)
    if kind in ("LWPOLYLINE", "POLYLINE"):
        if kind == "POLYLINE" and not (e.is_2d_polyline or e.is_3d_polyline):
            raise SourceError(file, number, 0, f"{source}: a polygon mesh or polyface is not a contour")
        out: list[Piece] = []
        for ve in e.virtual_entities():
            out.extend(_entity(ve, ve.dxftype(), source, number, scale, options, file, notes))
        return out
    if kind == "SPLINE":
        return _spline(e.construction_tool(), source, number, scale, tol, notes)
    if kind == "ELLIPSE":
        from ezdxf.math import rational_bspline_from_ellipse

        ell = e.construction_tool()
        sweep = (ell.end_param - ell.start_param) % (2 * math.pi) or 2 * math.pi
        bs = rational_bspline_from_ellipse(ell, segments=max(1, int(math.ceil(sweep / (math.pi / 2)))))
        return _spline(bs, source, number, scale, tol, notes)
    raise SourceError(file, number, 0, f"{source}: {kind} entities are not supported (cut: LINE, ARC, CIRCLE, "
                      "LWPOLYLINE, POLYLINE, SPLINE, ELLIPSE, INSERT)")  # fmt: skip


def _spline(bs, source: str, number: int, scale: float, tol: float, notes: list[str]) -> list[Piece]:
    """A piece for an ezdxf ``BSpline``: exact when clamped, else its flattening as a polyline (noted)."""
    poly = np.array([[v.x, v.y] for v in bs.flattening(tol / max(scale, 1e-12))]) * scale
    if poly.shape[0] < 2:
        poly = np.array([[v.x, v.y] for v in bs.approximate(8)]) * scale
    pts = np.array([[v.x, v.y] for v in bs.control_points]) * scale
    w = np.asarray(bs.weights(), np.float64) if bs.is_rational else np.ones(pts.shape[0])
    kn = np.asarray(bs.knots(), np.float64)
    curve = (int(bs.degree), pts, w, kn)
    try:
        if not bs.is_clamped:
            raise ValueError("not clamped")
        make_curve_table([curve])
    except ValueError as exc:
        notes.append(f"{source}: cut as {poly.shape[0] - 1} lines within {tol:g} mm ({exc})")
        return [line_piece(a, b, source, number) for a, b in zip(poly[:-1], poly[1:], strict=True)]
    out: list[Piece] = []
    for c in split_at_breaks(curve):
        if _straight(c[1]):  # the segment between its ends: cut as a line
            out.append(line_piece(c[1][0], c[1][-1], source, number))
            continue
        if c[0] == 1:  # a degree-1 spline is a polyline
            out.extend(line_piece(a, b, source, number) for a, b in zip(c[1][:-1], c[1][1:], strict=True))
            continue
        c = _cubic(c) if c[0] == 2 else c
        out.append(Piece(Kind.CURVE, c[1][0].copy(), c[1][-1].copy(), _flat(c, tol), source, number, curve=c))
    return out


def _straight(pts: np.ndarray, tol_mm: float = 1e-9) -> bool:
    """True when control points ``(m, 2)`` lie on the segment between the first and last, in order (the curve
    is that segment). Such curves are cut as lines: straight NURBS plan in zero time today (a planner defect,
    reported)."""
    d = pts[-1] - pts[0]
    n = float(np.linalg.norm(d))
    if n <= tol_mm:
        return False
    rel = pts - pts[0]
    off = np.abs(rel[:, 0] * d[1] - rel[:, 1] * d[0]) / n
    along = rel @ d / n
    return bool(np.all(off <= tol_mm) and np.all(np.diff(along) >= -tol_mm))


def _cubic(curve):
    """A quadratic (rational) B-spline raised to degree 3, the same curve (ezdxf, The NURBS Book A5.9).

    Quadratic curves plan in zero time today (a planner defect, reported); cubic ones plan correctly.
    """
    from ezdxf.math import BSpline

    p, pts, w, kn = curve
    bs = BSpline(np.c_[pts, np.zeros(len(pts))], order=p + 1, knots=list(kn), weights=list(w)).degree_elevation(1)
    q = np.array([[v.x, v.y] for v in bs.control_points])
    qw = np.asarray(bs.weights(), np.float64) if bs.is_rational else np.ones(q.shape[0])
    return (3, q, qw, np.asarray(bs.knots(), np.float64))


def _flat(curve, tol: float) -> np.ndarray:
    """``(k, 2)`` points along a curve ``(degree, points, weights, knots)`` within ``tol`` mm (ezdxf)."""
    from ezdxf.math import BSpline

    p, pts, w, kn = curve
    bs = BSpline(np.c_[pts, np.zeros(len(pts))], order=p + 1, knots=list(kn), weights=list(w))
    poly = np.array([[v.x, v.y] for v in bs.flattening(tol)])
    return poly if poly.shape[0] >= 2 else np.stack([pts[0], pts[-1]])


def split_at_breaks(curve):
    """A clamped B-spline cut where an interior knot repeats ``degree`` times (a corner in its parameter:
    the ellipse's quarter joints) into pieces without such knots: ``[(degree, points, weights, knots)]``."""
    p, pts, w, kn = curve
    m = pts.shape[0]
    vals, counts = np.unique(kn[p + 1 : m], return_counts=True)
    out = []
    for u in vals[counts >= p]:
        i = int(np.searchsorted(kn, u, side="left"))  # the run of u starts here
        k = i - 1  # the curve passes through control point k at u
        out.append((p, pts[: k + 1], w[: k + 1], np.concatenate([kn[:i], np.full(p + 1, u)])))
        pts, w, kn = pts[k:], w[k:], np.concatenate([np.full(p + 1, u), kn[i + p :]])
    out.append((p, pts, w, kn))
    return out
