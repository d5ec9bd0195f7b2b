"""Corner blending: every junction the program allows, replaced by a G2 quintic within a tolerance.

A junction between two spans (line–line, line–arc, arc–arc, helices; in 3D) that turns by ``θ`` is
cut back by ``ℓ`` of arc length on both sides, at ``A`` on the incoming span (unit tangent ``Ta``,
curvature vector ``Ka``) and ``B`` on the outgoing one (``Tb``, ``Kb``), and joined by the quintic
Bézier of G2 Hermite interpolation with ``λ = 2ℓ``:

    P0 = A,  P1 = A + λ/5 Ta,  P2 = 2 P1 - P0 + λ²/20 Ka,
    P5 = B,  P4 = B - λ/5 Tb,  P3 = 2 P4 - P5 + λ²/20 Kb.

Then ``P'(0) = λ Ta`` and ``P''(0) = λ² Ka`` (no tangential part), so with the timing polynomial of
:mod:`jaxcnc.geometry.poly` the blend leaves ``A`` and joins ``B`` with the spans' own tangents and
curvatures: position, tangent and curvature are continuous (G2), and the planner needs no velocity
step and no acceleration step at the joints.

Between two lines (``Ka = Kb = 0``) the control points lie on the two lines, the quintic is the
degree-elevated quartic ``C - ℓ t1, C - ℓ/2 t1, C, C + ℓ/2 t2, C + ℓ t2`` (``C`` the corner), and by
symmetry it comes closest to ``C`` at its middle, ``B(½) = C + 3ℓ (t2 - t1) / 16``: the path moves
at most ``(3/8) ℓ sin(θ/2)`` from the corner, so ``ℓ = 8 tol / (3 sin(θ/2))`` keeps the deviation
within ``tol``. Where an arc takes part the same ``ℓ`` is a first guess: the distance to the two
replaced pieces is measured at 17 points of the blend (plus a bound of the curvature between
them) and ``ℓ`` shrinks until it is within ``tol``. ``ℓ`` never exceeds half of either span, so
neighbouring blends never overlap (a short line between two blends may be consumed entirely).

Which junctions are blended: consecutive motion spans (lines, arcs; no dwell or event between
them) with a tolerance — ``G64 P`` of the second row, the machine's ``corner_tol_mm`` for ``G64``
without ``P`` (start-up mode), none in exact-path or exact-stop mode (G61, G61.1) — where the motion
need not stop (no programmed stop before the second row: a laser switched on or off, a dwell, a
pause) and the beam does not change: both lit with the same mode and power, or both dark (a rapid
may then blend into a dark feed move). Junctions turning by more than ``MAX_TURN_RAD`` stop: a
blend within the tolerance would be taken at a few mm/s there (its curvature radius falls below a
micrometre), so the stop costs nothing. NURBS pieces keep their exact junctions (they are joined
tangentially by the programs that write them).
"""

from __future__ import annotations

import numpy as np

from jaxcnc.buckets import pad_rows
from jaxcnc.geometry import poly
from jaxcnc.geometry.bezier import homogeneous_power, power_to_bezier, restrict
from jaxcnc.geometry.blend_kernel import blend_kernel, deviation_kernel
from jaxcnc.geometry.evaluate import evaluate_path, junction_curvatures, span_arrays
from jaxcnc.geometry.kinds import SpanKind, kind_in
from jaxcnc.geometry.spans import (
    MIN_LENGTH_MM,
    SPAN_FIELDS,
    ArcTable,
    PolyTable,
    Spans,
    assemble,
    merge_polys,
    row_norm,
)
from jaxcnc.jitcache import warm_ahead
from jaxcnc.program import LaserMode, Program

BLEND_DEGREE = 5
#: Turns below this are rounding (tangent continuity already); above the limit the motion stops.
MIN_TURN_RAD = 1e-9
MAX_TURN_RAD = np.deg2rad(150.0)
#: Rounds of shrinking a blend whose measured deviation exceeds the tolerance.
SHRINK_ROUNDS = 8
#: Rounds of giving up a chain curvature where a blend would leave the tolerance.
CHAIN_ROUNDS = 4
#: A line whose blends leave less than this share of it is consumed by them (see :func:`_consume`).
SNAP = 0.25


def junction_tolerances(
    program: Program, spans: Spans, corner_tol_mm: float, exact_before: np.ndarray | None = None
) -> np.ndarray:
    """``(n-1,)`` blend tolerance (mm) of each junction between consecutive spans (0: not blended).

    ``exact_before``: ``(rows,)`` bool, the junctions into these rows are kept exact as well (a planner's choice,
    such as the S-curve stage's where a blend would be passed slower than a stop: :func:`~jaxcnc.planners.
    smoothing.blends_slower_than_stops`)."""
    n = len(spans)
    if n < 2:
        return np.zeros(0)
    k1, k2 = spans.kind[:-1], spans.kind[1:]
    r1, r2 = spans.block[:-1], spans.block[1:]
    blendable = kind_in(k1, (SpanKind.LINE, SpanKind.ARC)) & kind_in(k2, (SpanKind.LINE, SpanKind.ARC))
    lit = (program.laser != LaserMode.OFF) & ~program.rapid
    same_beam = np.where(
        lit[r1] & lit[r2],
        (program.laser[r1] == program.laser[r2]) & (program.power[r1] == program.power[r2]),
        ~lit[r1] & ~lit[r2],
    )
    # The mode a move is programmed in says how it ends (LinuxCNC's termination condition): under G61/G61.1 (or
    # G64 P0) the first move ends on its end point; else the lower tolerance of the two moves (LinuxCNC takes
    # the smaller "in case it dropped between moves"), the second one's only where it has one of its own.
    tol_a, tol_b = program.blend_tol[r1], program.blend_tol[r2]
    own_b = np.where(np.isinf(tol_b), corner_tol_mm, tol_b)
    tol = np.where(np.isinf(tol_a), corner_tol_mm, tol_a)
    tol = np.where(tol_a > 0, np.minimum(tol, np.where(tol_b > 0, own_b, np.inf)), 0.0)
    ok = blendable & (r1 != r2) & ~program.stop_before[r2] & same_beam & (tol > 0)
    if exact_before is not None:
        ok &= ~exact_before[r2]
    return np.where(ok, tol, 0.0)


def _pieces(
    spans: Spans, arrays: dict, idx: np.ndarray, s_lo: np.ndarray, s_hi: np.ndarray, rows: int
) -> dict[str, np.ndarray]:
    """The parts ``[s_lo, s_hi]`` of spans ``idx`` (lines and arcs) as
    :func:`~jaxcnc.geometry.blend_kernel.deviation_kernel` reads them: ends ``a``, ``b`` ``(J, 3)``, ``is_arc``,
    and the arcs' centre, in-plane unit vectors, axis, radius, rise per radian and the part's angles ``lo``,
    ``hi`` (zeros on lines); ``rows`` rows each, those after the parts' zeros (the kernel's padding)."""
    j = idx.size
    out = {f: np.zeros((rows, 3)) for f in ("a", "b")}
    out["a"][:j], out["b"][:j] = evaluate_path(arrays, idx, s_lo)[0], evaluate_path(arrays, idx, s_hi)[0]
    out["is_arc"] = np.zeros(rows, bool)
    out["is_arc"][:j] = spans.kind[idx] == SpanKind.ARC
    for f in ("center", "e1", "e2", "axis"):
        out[f] = np.zeros((rows, 3))
    for f in ("radius", "rise", "lo", "hi"):
        out[f] = np.zeros(rows)
    arc = np.flatnonzero(out["is_arc"])
    t: ArcTable = spans.arcs
    it = spans.item[idx[arc]]
    r, h = t.radius[it], t.rise[it]
    omega = 1.0 / np.sqrt(r * r + h * h)
    out["center"][arc], out["e1"][arc], out["e2"][arc], out["axis"][arc] = t.center[it], t.e1[it], t.e2[it], t.axis[it]
    out["radius"][arc], out["rise"][arc], out["lo"][arc], out["hi"][arc] = r, h, s_lo[arc] * omega, s_hi[arc] * omega
    return out


def _blend_points(
    spans: Spans,
    i: np.ndarray,
    ell_a: np.ndarray,
    ell_b: np.ndarray,
    k_mid: np.ndarray | None = None,
    arrays: dict | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic G2 blends of the junctions after spans ``i``, which are cut back by ``ell_a`` and the spans
    after them by ``ell_b``: control points ``(J, 6, 3)``, Ta, Tb.

    ``k_mid``: ``(n, 3)`` curvature vectors at the middles of consumed lines (:func:`_chain_curvature`),
    used where a blend starts or ends there. ``arrays``: ``span_arrays(spans)``, where made already.
    """
    arrays = span_arrays(spans) if arrays is None else arrays
    qa, ta, ka = evaluate_path(arrays, i, spans.length[i] - ell_a, 2)
    qb, tb, kb = evaluate_path(arrays, i + 1, ell_b, 2)
    if k_mid is not None:
        ka, kb = ka + k_mid[i], kb + k_mid[i + 1]  # a line's own curvature is 0
    lam = (ell_a + ell_b)[:, None]
    p1 = qa + lam / 5 * ta
    p2 = 2 * p1 - qa + lam**2 / 20 * ka
    p4 = qb - lam / 5 * tb
    p3 = 2 * p4 - qb + lam**2 / 20 * kb
    return np.stack([qa, p1, p2, p3, p4, qb], axis=1), ta, tb


def _coeffs(pts: np.ndarray) -> np.ndarray:
    """Homogeneous power-basis coefficients of Bézier control points ``(J, 6, 3)``, relative to ``P0``."""
    return homogeneous_power(pts, np.ones(pts.shape[:2]), pts[:, 0])


def _kernel(pts: np.ndarray, corner: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`~jaxcnc.geometry.blend_kernel.blend_kernel` on NumPy arrays (:func:`_send`, then :func:`_take`; one
    call: its arrays as they are)."""
    calls = _send(pts, corner)
    if len(calls) == 1:
        return {k: np.asarray(v)[: pts.shape[0]] for k, v in calls[0][2].items()}
    return _take(calls, {}, 0, pts.shape[0])


def _send(pts: np.ndarray, corner: np.ndarray) -> list[tuple[int, int, dict]]:
    """The calls of :func:`~jaxcnc.geometry.blend_kernel.blend_kernel` for blends ``pts`` at ``corner``, sent and not
    waited for (XLA computes them in order on its own thread): ``(lo, hi, outputs)`` of rows ``lo:hi`` each.

    ``KERNEL_ROWS`` blends a call (the last padded): one shape, so a process compiles the kernel once whatever the
    program, and a compile cache made by one program serves every other. A call's working set stays in the CPU's
    caches: the 100k-block contour's first 65,536 blends took ~1.3x the time in one call of their size as in 16
    calls of 4,096 (the same values bit for bit: the kernel is elementwise over blends)."""
    n = pts.shape[0]
    calls = []
    for lo in range(0, max(n, 1), KERNEL_ROWS):
        hi = min(n, lo + KERNEL_ROWS)
        if hi - lo < KERNEL_ROWS:  # the last call's padding rows: harmless blends
            pad = KERNEL_ROWS - (hi - lo)
            args = (
                np.concatenate([pts[lo:hi], np.broadcast_to(_UNIT_BLEND, (pad, 6, 3))]),
                np.concatenate([corner[lo:hi], np.zeros((pad, 3))]),
            )
        else:
            args = (pts[lo:hi], corner[lo:hi])
        calls.append((lo, hi, blend_kernel(*args)))
    return calls


def _take(
    calls: list[tuple[int, int, dict]], out: dict[str, np.ndarray], at: int, size: int, skip: tuple[str, ...] = ()
) -> dict[str, np.ndarray]:
    """The outputs of :func:`_send`'s ``calls`` into rows ``at + lo:at + hi`` of ``out``'s arrays (arrays of ``size``
    rows made for those it has not), call by call as each is done: no list of parts to join. The outputs named in
    ``skip`` are left out (:func:`_blend_round` puts the spans' own end tangents in ``t0`` and ``t1``)."""
    for lo, hi, part in calls:
        for k, v in part.items():
            if k in skip:
                continue
            v = np.asarray(v)
            if k not in out:
                out[k] = np.empty((size,) + v.shape[1:], v.dtype)
            out[k][at + lo : at + hi] = v[: hi - lo]
    return out


def _blend_round(
    spans: Spans,
    arrays: dict,
    j: np.ndarray,
    ell_a: np.ndarray,
    ell_b: np.ndarray,
    k_mid: np.ndarray | None,
    corner: np.ndarray,
    need: np.ndarray,
) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """:func:`_blend_points` and :func:`_kernel` of the junctions after spans ``j`` (``arrays``: their
    ``span_arrays``), ``KERNEL_CHUNK`` junctions at a time: the points of all blends (144 MB at 1 M) and their
    evaluation's temporaries never exist at once. The values are those of the two calls over all junctions, bit for
    bit. A chunk's kernel calls are read once the next chunk's are sent: XLA computes them on its own thread while
    the next chunk's points are made here.

    Returns the kernel's outputs for every blend, with the start points ``origin`` ``(J, 3)`` and the end
    tangents ``t0``, ``t1`` replaced by the spans' ``Ta``, ``Tb`` (which :func:`_blend_fields` puts at a whole
    blend's ends in any case); the rows ``kept`` ``(k,)`` (sorted) whose control points ``(k, 6, 3)`` are kept:
    those ``need`` ``(J,)`` marks, those :func:`_blend_fields` will split (their path parameter strays more than
    ``BLEND_SPEED_TOL`` from arc length) and those whose distance the kernel left to
    :func:`~jaxcnc.geometry.blend_kernel.deviation_kernel` (``dev`` infinite).
    """
    n = j.size
    if n <= min(KERNEL_CHUNK, KERNEL_ROWS):  # one call of the kernel: its arrays as they are (origin: not a view)
        pts, ta, tb = _blend_points(spans, j, ell_a, ell_b, k_mid, arrays)
        out = dict(_kernel(pts, corner), origin=np.ascontiguousarray(pts[:, 0]), t0=ta, t1=tb)
        rows = np.flatnonzero(need | ~(out["err"] <= poly.BLEND_SPEED_TOL) | ~np.isfinite(out["dev"]))
        return out, rows, pts[rows]
    out = {k: np.empty((n, 3)) for k in ("origin", "t0", "t1")}
    kept, kept_pts = [], []
    sent = []
    for lo in range(0, n, KERNEL_CHUNK):
        hi = min(n, lo + KERNEL_CHUNK)
        pts, ta, tb = _blend_points(spans, j[lo:hi], ell_a[lo:hi], ell_b[lo:hi], k_mid, arrays)
        out["origin"][lo:hi], out["t0"][lo:hi], out["t1"][lo:hi] = pts[:, 0], ta, tb
        del ta, tb
        sent.append((lo, pts, _send(pts, corner[lo:hi])))
        del pts
        if len(sent) == 2:
            kept.append(_take_chunk(sent.pop(0), out, n, need, kept_pts))
    for chunk in sent:
        kept.append(_take_chunk(chunk, out, n, need, kept_pts))
    return out, np.concatenate(kept), np.concatenate(kept_pts)


def _take_chunk(
    chunk: tuple[int, np.ndarray, list], out: dict[str, np.ndarray], size: int, need: np.ndarray, kept_pts: list
) -> np.ndarray:
    """:func:`_blend_round`'s chunk ``(lo, pts, calls)``: the kernel's outputs into ``out`` (arrays of ``size``
    rows), the control points of the rows kept appended to ``kept_pts``; returns those rows."""
    lo, pts, calls = chunk
    _take(calls, out, lo, size, skip=("t0", "t1"))
    hi = lo + pts.shape[0]
    err, dev = out["err"][lo:hi], out["dev"][lo:hi]
    rows = np.flatnonzero(need[lo:hi] | ~(err <= poly.BLEND_SPEED_TOL) | ~np.isfinite(dev))
    kept_pts.append(pts[rows])
    return lo + rows


#: Junctions whose blends :func:`_blend_round` makes at a time (their points and the evaluation's temporaries), and
#: blends measured by one call of the kernel (its one shape; :func:`_send`).
KERNEL_CHUNK = 1 << 14
KERNEL_ROWS = 1 << 12


#: A harmless blend (a straight quintic) for the padding rows of :func:`_kernel`.
_UNIT_BLEND = np.stack([np.linspace(0.0, 1.0, 6), np.zeros(6), np.zeros(6)], axis=1)


def _deviation(
    spans: Spans, arrays: dict, i: np.ndarray, ell_a: np.ndarray, ell_b: np.ndarray, coeffs: np.ndarray
) -> np.ndarray:
    """``(J,)`` distance from each blend to the two pieces it replaces (an upper bound):
    :func:`~jaxcnc.geometry.blend_kernel.deviation_kernel`, ``DEVIATION_CHUNK`` blends a call, the last padded: one
    shape, so the kernel (the longest of the planner's to compile: 3.2-3.4 s, and ~0.4-0.7 s to load from the
    compile cache on the development machine) compiles once per process and its cache serves every program (the
    shrink rounds measure fewer blends each time; sizes padded to buckets compiled it twice in a 2000-block
    program). Its working memory is bounded too: the 1 M-block contour's 40k arc junctions in one call held ~100 MB
    more. ``arrays``: ``span_arrays(spans)``."""
    n = i.size
    length = spans.length[i]
    dev = np.empty(n)
    helix = bool(np.any(spans.arcs.rise != 0))  # one program for the whole path (deviation_kernel)
    # each call is read once the next one is sent: XLA computes it on its own thread while the next one's inputs are
    # made here (100k-block contour: ~1/3 of the time is making them)
    sent = []
    for lo in range(0, n, DEVIATION_CHUNK):
        c = slice(lo, min(n, lo + DEVIATION_CHUNK))
        m = DEVIATION_CHUNK  # padding rows: a blend at rest at the origin, parts of zeros
        piece_in = _pieces(spans, arrays, i[c], length[c] - ell_a[c], length[c], m)
        piece_out = _pieces(spans, arrays, i[c] + 1, np.zeros(c.stop - lo), ell_b[c], m)
        start = piece_in["a"]  # the blend starts where the part it replaces does
        sent.append((c, deviation_kernel(pad_rows(coeffs[c], m, 0), start, piece_in, piece_out, helix)))
        if len(sent) == 2:
            _read_deviation(dev, *sent.pop(0))
    for c, part in sent:
        _read_deviation(dev, c, part)
    return dev


def _read_deviation(dev: np.ndarray, rows: slice, part) -> None:
    """The deviation kernel's output ``part`` (padded) into ``dev[rows]`` (waits for it)."""
    dev[rows] = np.asarray(part)[: rows.stop - rows.start]


#: Rows :func:`_deviation` measures in one call (its one compiled shape).
DEVIATION_CHUNK = 1 << 11


def _trims(n: int, j: np.ndarray, ell_a: np.ndarray, ell_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(trim_start, trim_end)`` ``(n,)``: how much of each span the blends at its ends take."""
    trim_start, trim_end = np.zeros(n), np.zeros(n)
    trim_end[j], trim_start[j + 1] = ell_a, ell_b
    return trim_start, trim_end


def _consume(spans: Spans, j: np.ndarray, ell_a: np.ndarray, ell_b: np.ndarray, frozen: np.ndarray) -> None:
    """Where the blends at both ends of a line leave less than ``SNAP`` of it, they take all of it.

    A curve cut into chords of slightly different lengths (coordinates rounded by the post) would
    otherwise keep a sliver of every chord but the shortest, and the blends could not meet with a
    common curvature there (:func:`_chain_curvature`). The junctions at its ends become a little
    asymmetric (``ℓ_a ≠ ℓ_b``); every blend's deviation is measured afterwards. Spans marked ``frozen``
    are left as they are. In place.
    """
    n = len(spans)
    trim_start, trim_end = _trims(n, j, ell_a, ell_b)
    both = (spans.kind == SpanKind.LINE) & (trim_start > 0) & (trim_end > 0)
    left = spans.length - trim_start - trim_end
    snap = np.flatnonzero(both & ~frozen & (left > 0) & (left < SNAP * spans.length))
    if snap.size == 0:
        return
    scale = np.ones(n)
    scale[snap] = spans.length[snap] / (trim_start[snap] + trim_end[snap])
    ell_a *= scale[j]  # span j's end
    ell_b *= scale[j + 1]  # span j+1's start


def _chain_curvature(spans: Spans, j: np.ndarray, ell_a: np.ndarray, ell_b: np.ndarray) -> np.ndarray:
    """``(n, 3)`` curvature vectors at the middles of lines the blends on both sides consume (0 elsewhere).

    Two blends that meet in the middle of a line may meet there with any common curvature; with the
    line's own (0) a chain of short lines — a curve cut into chords — would curve in pulses, twice the
    mean curvature at every vertex and straight between them. Instead they meet with the mean of the
    two blends' average curvatures ``(t_out - t_in) / (2 ℓ)``, projected normal to the line: on a
    circle cut into chords every blend is then close to an arc of the circle.
    """
    n = len(spans)
    trim_start, trim_end = _trims(n, j, ell_a, ell_b)
    k_mid = np.zeros((n, 3))
    consumed = (
        (spans.kind == SpanKind.LINE)
        & (trim_start > 0)
        & (trim_end > 0)
        & (trim_start + trim_end >= spans.length * (1 - 1e-12))
    )
    i = np.flatnonzero(consumed)
    if i.size == 0:
        return k_mid
    # coordinate by coordinate, on (k,) columns: rows of 3 against a (k, 1) column run NumPy's inner loops 3 values
    # at a time (the 100k-block contour's 76k consumed lines: ~2x the time); the same operations value for value
    # (NumPy sums a row of 3 as (x + y) + z)
    w_in, w_out = 2 * trim_start[i], 2 * trim_end[i]
    t = [spans.tangent_in[i, c] for c in range(3)]
    k = [
        ((t[c] - spans.tangent_out[i - 1, c]) / w_in + (spans.tangent_in[i + 1, c] - t[c]) / w_out) / 2
        for c in range(3)
    ]
    along = t[0] * k[0] + t[1] * k[1] + t[2] * k[2]
    for c in range(3):
        k_mid[i, c] = k[c] - t[c] * along
    return k_mid


def curvature_steps(spans: Spans, arrays: dict | None = None) -> np.ndarray:
    """``(n-1,)`` bool: the junctions where an arc takes part and the curvature vector steps (by more than
    ``1e-9`` of the larger one): tangent there or not, the path is G1 at most (an acceleration step at speed)."""
    n = len(spans)
    out = np.zeros(max(n - 1, 0), bool)
    arc = spans.kind == SpanKind.ARC
    j = np.flatnonzero(arc[:-1] | arc[1:])
    if j.size == 0:
        return out
    ka, kb = junction_curvatures(spans, j, arrays)
    big = np.maximum(np.linalg.norm(ka, axis=1), np.linalg.norm(kb, axis=1))
    out[j] = np.linalg.norm(ka - kb, axis=1) > 1e-9 * big
    return out


def blend_path(
    program: Program,
    spans: Spans,
    corner_tol_mm: float,
    exact_before: np.ndarray | None = None,
    g2: bool = False,
) -> Spans:
    """``spans`` with every junction that :func:`junction_tolerances` allows blended (module docstring).

    ``g2``: tangent junctions whose curvature steps (:func:`curvature_steps`: a line into an arc, arcs of other
    radii) are blended as well, so that the path is G2 wherever it may leave the program — what a jerk limit needs
    (at speed ``v`` a curvature step ``ΔK`` is an acceleration step ``ΔK v²``: a jerk of ``ΔK v² f`` at tick rate
    ``f``, which only a lower speed at a higher tick rate keeps within ``J``)."""
    if corner_tol_mm <= 0 and not np.any((program.blend_tol > 0) & np.isfinite(program.blend_tol)):
        return spans  # exact corners throughout (no G64 P > 0; G64 without P means the machine's 0): nothing to blend
    tol = junction_tolerances(program, spans, corner_tol_mm, exact_before)
    t1, t2 = spans.tangent_out[:-1], spans.tangent_in[1:]
    # the turns' cosines column by column: np.sum over rows of 3 adds in the same order, (x + y) + z, ~5x slower
    cos = t1[:, 0] * t2[:, 0] + t1[:, 1] * t2[:, 1] + t1[:, 2] * t2[:, 2]
    turn = np.arccos(np.clip(cos, -1.0, 1.0)) if len(spans) > 1 else np.zeros(0)
    joins = turn > MIN_TURN_RAD
    if g2 and np.any((tol > 0) & ~joins):
        joins |= (tol > 0) & curvature_steps(spans)
    j = np.flatnonzero((tol > 0) & joins & (turn <= MAX_TURN_RAD))
    if j.size == 0:
        return spans
    half = 0.5 * spans.length
    with np.errstate(divide="ignore"):  # (a tangent junction: no reach from the turn; half of either span at most)
        reach = 8.0 * tol[j] / (3.0 * np.sin(turn[j] / 2))
    ell = np.minimum(reach, np.minimum(half[j], half[j + 1]))
    lines = (spans.kind[j] == SpanKind.LINE) & (spans.kind[j + 1] == SpanKind.LINE)
    # line–line: the deviation is (3/8) ℓ sin(θ/2) exactly; elsewhere measure and shrink
    check = np.flatnonzero(~lines)
    keep = np.ones(j.size, bool)
    # what the blends' points and deviations evaluate, made once (dropped before the fields)
    arrays = span_arrays(spans)
    # the blends' kernel compiles (or loads) in the background while the shrink rounds measure with the deviation
    # kernel: the two longest compiles of a first run, side by side on two cores
    kernel_ahead = (
        warm_ahead(blend_kernel, np.broadcast_to(_UNIT_BLEND, (KERNEL_ROWS, 6, 3)), np.zeros((KERNEL_ROWS, 3)))
        if check.size
        else None
    )
    for _ in range(SHRINK_ROUNDS):
        if check.size == 0:
            break
        pts, _, _ = _blend_points(spans, j[check], ell[check], ell[check], arrays=arrays)
        dev = _deviation(spans, arrays, j[check], ell[check], ell[check], _coeffs(pts))
        bad = dev > tol[j[check]]
        ell[check[bad]] *= np.clip(0.95 * tol[j[check[bad]]] / dev[bad], 0.05, 0.95)
        check = check[bad]
    if kernel_ahead is not None:
        kernel_ahead.result()
    keep[check] = False  # still too far after the rounds: an exact corner
    keep &= ell > MIN_LENGTH_MM
    j, ell, lines = j[keep], ell[keep], lines[keep]
    if j.size == 0:
        return spans
    # chords of a curve: consume them whole, and let the blends meet with a common curvature, where
    # that keeps them within tol (else back to symmetric cuts and the line's own curvature, 0)
    corner = spans.origin[j + 1]  # the vertex: where the second span begins (before it is trimmed)
    frozen = np.zeros(len(spans), bool)  # spans left as they are: no snap, their own curvature
    for _ in range(CHAIN_ROUNDS + 1):
        found = kept = kept_pts = None  # the last round's kernel outputs: dead before the new ones
        ell_a, ell_b = ell.copy(), ell.copy()
        _consume(spans, j, ell_a, ell_b, frozen)
        k_mid = _chain_curvature(spans, j, ell_a, ell_b)
        k_mid[frozen] = 0.0
        # (a span's curvature not 0 from its columns: np.any over rows of 3, gathered twice, took ~5 % of the build)
        curved = (k_mid[:, 0] != 0) | (k_mid[:, 1] != 0) | (k_mid[:, 2] != 0)
        changed = (ell_a != ell) | (ell_b != ell) | curved[j] | curved[j + 1]
        del curved
        with_arc = changed & ~lines  # arcs take part: measure against the arc itself
        found, kept, kept_pts = _blend_round(spans, arrays, j, ell_a, ell_b, k_mid, corner, with_arc)
        dev = found["dev"].copy()
        other = np.flatnonzero(with_arc | (changed & ~np.isfinite(dev)))  # (and where the kernel could not tell)
        if other.size:
            pts = kept_pts[np.searchsorted(kept, other)]
            dev[other] = _deviation(spans, arrays, j[other], ell_a[other], ell_b[other], _coeffs(pts))
            del pts
        # the corner kernel's bound is at most ~1.25x the distance, now and then more: where it says a blend leaves
        # tol, the deviation kernel's bound (also an upper bound; often tighter there) decides with it (the rows
        # measured just above have it already)
        over = np.flatnonzero(changed & ~with_arc & np.isfinite(found["dev"]) & (dev > tol[j]))
        if over.size:
            pts, _, _ = _blend_points(spans, j[over], ell_a[over], ell_b[over], k_mid, arrays)
            dev[over] = np.minimum(
                dev[over], _deviation(spans, arrays, j[over], ell_a[over], ell_b[over], _coeffs(pts))
            )
            del pts
        bad = np.flatnonzero(changed & (dev > tol[j]))
        if bad.size == 0:
            break
        frozen[j[bad]] = frozen[j[bad] + 1] = True  # give up the snap and the chain curvature there
    else:  # still too far: plain symmetric blends everywhere (within tol by construction or measurement)
        found = kept = kept_pts = None
        ell_a, ell_b = ell.copy(), ell.copy()
        found, kept, kept_pts = _blend_round(spans, arrays, j, ell_a, ell_b, None, corner, np.zeros(j.size, bool))
    del k_mid, corner, frozen, dev, changed, arrays
    fields_, table, owner = _blend_fields(spans, j, found, kept, kept_pts)
    del found, kept, kept_pts  # the blends' fields hold what is kept of them
    trim_start, trim_end = _trims(len(spans), j, ell_a, ell_b)
    trimmed, alive, arcs = _trim(spans, trim_start, trim_end)
    del trim_start, trim_end
    # a blend's pieces before its second span, in order
    key = np.concatenate(
        [np.flatnonzero(alive).astype(np.float64), j[owner] + 0.5 * (1 + np.arange(owner.size) / (owner.size + 1))]
    )
    return assemble([(trimmed, None), (fields_, None)], key, arcs, merge_polys([spans.polys, table]))


def _blend_fields(
    spans: Spans, j: np.ndarray, found: dict, kept_rows: np.ndarray, kept_pts: np.ndarray
) -> tuple[dict[str, np.ndarray], PolyTable, np.ndarray]:
    """Blend spans (span fields, poly table rows, owning junction of each piece), each blend split in
    halves until its path parameter is within ``BLEND_SPEED_TOL`` of arc length.

    ``found``: :func:`_blend_round`'s outputs for the blends (``t0``, ``t1`` their ends' tangents; its ``origin`` is
    taken out of it); ``kept_rows``, ``kept_pts``: the rows whose control points it kept (every blend to split among
    them)."""
    ta, tb = found["t0"], found["t1"]
    parts, owner = [], np.arange(j.size)
    key = owner.astype(np.float64)
    width = 1.0
    pts = None  # the control points of this round's pieces (the first round's: kept_pts)
    for rnd in range(poly.MAX_SPLITS + 1):
        ok = (found["err"] <= poly.BLEND_SPEED_TOL) | (rnd == poly.MAX_SPLITS)
        parts.append((found, found.pop("origin"), ok, owner, key))
        bad = ~ok
        if not bad.any():
            break
        split = kept_pts[np.searchsorted(kept_rows, np.flatnonzero(bad))] if pts is None else pts[bad]
        coeffs = _coeffs(split)
        n_bad = int(bad.sum())
        half = np.full(n_bad, 0.5)
        halves = [restrict(coeffs, split[:, 0], a, b) for a, b in ((np.zeros(n_bad), half), (half, np.ones(n_bad)))]
        pts = np.concatenate([power_to_bezier(c) + o[:, None] for c, o in halves])
        owner = np.concatenate([owner[bad], owner[bad]])
        width /= 2
        key = np.concatenate([key[bad], key[bad] + width])
        found = dict(_kernel(pts, pts[:, 0]), origin=pts[:, 0])
    if len(parts) == 1 and parts[0][2].all():  # no blend split: the kernel's arrays, in order already
        out = dict(parts[0][0], origin=parts[0][1], owner=parts[0][3])
    else:  # the pieces of every round, ordered by key; one field at a time, placed block by block into its rows
        order = np.argsort(np.concatenate([p[4][p[2]] for p in parts]), kind="stable")
        row = np.empty_like(order)
        row[order] = np.arange(order.size)  # the row of the i-th piece kept (rounds in order)
        kept = [np.flatnonzero(p[2]) for p in parts]
        del order
        out = {}
        for f in list(parts[0][0]):  # each field's pieces freed once placed (the caller's dict of the first round's
            out[f] = _placed(parts, kept, row, lambda p, f=f: p[0][f])  # too): one field at a time is held twice
            for p in parts:
                p[0].pop(f)
        out["origin"] = _placed(parts, kept, row, lambda p: p[1])
        out["owner"] = _placed(parts, kept, row, lambda p: p[3])
        del row, kept
    del parts
    owner = out["owner"]
    n = owner.size
    # a blend's ends have exactly its neighbours' tangents (the first round's t0, t1: a whole blend's pieces start
    # and end where their blend does)
    if n == j.size:  # no blend split: each piece is a whole blend
        t_in, t_out = out["t0"], out["t1"]
    else:
        first = np.concatenate([[True], owner[1:] != owner[:-1]])
        last = np.concatenate([owner[1:] != owner[:-1], [True]])
        t_in, t_out = out["t0"].copy(), out["t1"].copy()
        t_in[first], t_out[last] = ta[owner[first]], tb[owner[last]]
    fields_ = dict(
        kind=np.full(n, SpanKind.BLEND),
        block=spans.block[j + 1][owner],
        length=out["length"],
        origin=out["origin"],
        tangent_in=t_in,
        tangent_out=t_out,
        kappa_max=out["kappa_max"],
        d1_max=out["d1_max"],
        d2_max=out["d2_max"],
        lo=out["lo"],
        hi=out["hi"],
        item=len(spans.polys) + np.arange(n),
    )
    return fields_, PolyTable(coeffs=out["coeffs"], timing=out["timing"], length_err=np.zeros(n)), owner


def _placed(parts: list, kept: list[np.ndarray], row: np.ndarray, field) -> np.ndarray:
    """``field(part)`` (an array over a round's pieces) of every kept piece (``kept``: each round's, in order) in
    its row ``row`` (over the kept pieces of all rounds, in order), copied :data:`PLACE_BLOCK` pieces at a time."""
    first = field(parts[0])
    dst = np.empty((row.size,) + first.shape[1:], first.dtype)
    at = 0
    for p, k in zip(parts, kept, strict=True):
        src = field(p)
        for a in range(0, k.size, PLACE_BLOCK):
            kb = k[a : a + PLACE_BLOCK]
            dst[row[at + a : at + a + kb.size]] = src[kb]
        at += k.size
    return dst


#: Spans per block of :func:`_trim`'s evaluations (elementwise: the same values as one call over all of them).
TRIM_BLOCK = 1 << 16
#: Pieces per block that :func:`_blend_fields` places into their rows (the copies' temporaries stay small).
PLACE_BLOCK = 1 << 16


def _trim(
    spans: Spans, trim_start: np.ndarray, trim_end: np.ndarray
) -> tuple[dict[str, np.ndarray], np.ndarray, ArcTable]:
    """The spans that remain once lines and arcs are cut back at their ends (``trim_start``/``trim_end`` mm): their
    fields (copies of those rows alone: the spans the blends consume are not copied), the mask ``alive`` ``(n,)``
    of the spans they are, and the arcs."""
    cut = (trim_start > 0) | (trim_end > 0)
    length = np.where(cut, spans.length - trim_start - trim_end, spans.length)
    alive = (length > MIN_LENGTH_MM) | (spans.kind == SpanKind.POINT)
    rows = np.flatnonzero(alive)
    out = {k: getattr(spans, k)[rows] for k in SPAN_FIELDS if k != "length"}
    out["length"] = length[rows]
    if not cut.any():
        return out, alive, spans.arcs
    left = np.flatnonzero(cut[rows])  # rows of out (spans rows[left]) cut and not consumed: their new ends
    arrays = span_arrays(spans)
    for a in range(0, left.size, TRIM_BLOCK):  # the evaluations' temporaries: a block's, not every span's
        lb = left[a : a + TRIM_BLOCK]
        cb = rows[lb]
        q0, t0 = evaluate_path(arrays, cb, trim_start[cb], 1)
        _, t1 = evaluate_path(arrays, cb, spans.length[cb] - trim_end[cb], 1)
        out["origin"][lb] = q0
        t0 /= row_norm(t0)[:, None]  # (in place: the same quotients, faster than into new arrays)
        t1 /= row_norm(t1)[:, None]
        out["tangent_in"][lb], out["tangent_out"][lb] = t0, t1
    del arrays
    line = left[out["kind"][left] == SpanKind.LINE]
    if line.size:
        end = out["origin"][line] + out["length"][line, None] * out["tangent_in"][line]
        out["lo"][line] = np.minimum(out["origin"][line], end)
        out["hi"][line] = np.maximum(out["origin"][line], end)
    arcs = spans.arcs
    c = np.flatnonzero(cut)
    arc = c[spans.kind[c] == SpanKind.ARC]
    if arc.size:
        t = {f: np.array(getattr(arcs, f)) for f in ("center", "e1", "e2", "axis", "radius", "rise", "sweep")}
        it = spans.item[arc]
        omega = 1.0 / np.sqrt(t["radius"][it] ** 2 + t["rise"][it] ** 2)
        psi0 = (trim_start[arc] * omega)[:, None]
        e1, e2 = t["e1"][it], t["e2"][it]
        t["e1"][it] = np.cos(psi0) * e1 + np.sin(psi0) * e2
        t["e2"][it] = -np.sin(psi0) * e1 + np.cos(psi0) * e2
        t["center"][it] = t["center"][it] + (t["rise"][it] * psi0[:, 0])[:, None] * t["axis"][it]
        t["sweep"][it] = length[arc] * omega
        arcs = ArcTable(**t)
    return out, alive, arcs
