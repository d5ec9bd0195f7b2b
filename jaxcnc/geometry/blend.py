"""Corner blending: the junction of two lines replaced by a G2-continuous curve within a tolerance.

A corner ``C`` between an incoming line (unit direction ``t1``) and an outgoing one (``t2``),
turning by ``θ``, is cut back by ``ℓ`` on both lines and joined by the quartic Bézier

    P0 = C - ℓ t1,  P1 = C - ℓ/2 t1,  P2 = C,  P3 = C + ℓ/2 t2,  P4 = C + ℓ t2.

``P0, P1, P2`` lie on the first line and ``P2, P3, P4`` on the second, so the blend leaves and
joins the lines with their tangents and with zero curvature (its second derivative vanishes at
both ends): position, tangent and curvature are continuous (G2) and the planner needs no
velocity step and no acceleration step at the joints. By symmetry the blend comes closest to
``C`` at ``u = ½``, where ``B(½) = C + 3ℓ (t2 - t1) / 16``: the path moves at most
``(3/8) ℓ sin(θ/2)`` from the corner, so ``ℓ = 8 tol / (3 sin(θ/2))`` keeps the deviation within
``tol`` (and ``ℓ`` is at most half of either line, so neighbouring blends never overlap).

Which junctions are blended: consecutive line rows (no span between them) with a tolerance —
``G64 P`` of the second row, the machine's ``corner_tol_mm`` for ``G64`` without ``P``, none in
exact-stop mode (G61) — that do not stop (no programmed stop before the second row) and keep the
same rapid/feed state, laser mode and power (so laser switching points stay exactly where
programmed). Junctions with arcs and curves keep their exact corners.
"""

from __future__ import annotations

import numpy as np

from jaxcnc.geometry.bezier import homogeneous_power
from jaxcnc.geometry.spans import MIN_LENGTH_MM, line_spans
from jaxcnc.program import Kind, Program

BLEND_DEGREE = 4
#: Turns below this are rounding (tangent continuity already); above the limit the motion stops.
MIN_TURN_RAD = 1e-9
MAX_TURN_RAD = np.deg2rad(179.0)


def blend_tolerances(program: Program, is_line: np.ndarray, corner_tol_mm: float) -> np.ndarray:
    """``(n_rows,)`` blend tolerance (mm) of the junction *before* each row (0: exact corner)."""
    producing = is_line | np.isin(program.kind, (Kind.ARC, Kind.CURVE, Kind.DWELL, Kind.EVENT))
    rows = np.flatnonzero(producing)
    tol = np.zeros(len(program))
    if rows.size < 2:
        return tol
    r1, r2 = rows[:-1], rows[1:]
    prog_tol = program.blend_tol[r2]
    t = np.where(np.isinf(prog_tol), corner_tol_mm, prog_tol)
    ok = (
        is_line[r1]
        & is_line[r2]
        & ~program.stop_before[r2]
        & (program.rapid[r1] == program.rapid[r2])
        & (program.laser[r1] == program.laser[r2])
        & (program.power[r1] == program.power[r2])
    )
    tol[r2] = np.where(ok, np.maximum(t, 0.0), 0.0)
    return tol


def corner_blends(
    program: Program, line_rows: np.ndarray, tol: np.ndarray
) -> tuple[dict[str, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray] | None]:
    """Trimmed line spans and the blends between them.

    Args:
        line_rows: ``(k,)`` rows that are lines, in order; tol: ``(n_rows,)`` from
            :func:`blend_tolerances`.
    Returns:
        the line spans' fields (trimmed, lines trimmed to nothing dropped) and the blends as
        ``(coeffs (b, 5, 4), origin (b, 3), row (b,))`` — each blend owned by the row after its
        corner — or ``None`` when no corner is blended.
    """
    a, b = program.start[line_rows].copy(), program.end[line_rows].copy()
    length = np.linalg.norm(b - a, axis=1)
    t = (b - a) / length[:, None]
    j_tol = tol[line_rows[1:]]  # junction i: between line i and line i+1 (tol 0 unless adjacent)
    cos_turn = np.clip(np.sum(t[:-1] * t[1:], axis=1), -1.0, 1.0)
    turn = np.arccos(cos_turn)
    blend = (j_tol > 0) & (turn > MIN_TURN_RAD) & (turn < MAX_TURN_RAD)
    half = np.sin(turn / 2)
    ell = np.where(blend, 8.0 * j_tol / (3.0 * np.where(blend, half, 1.0)), 0.0)
    ell = np.minimum(ell, 0.5 * np.minimum(length[:-1], length[1:]))
    blend &= ell > MIN_LENGTH_MM
    ell = np.where(blend, ell, 0.0)
    corner = b[:-1].copy()
    a[1:] += ell[:, None] * t[1:]
    b[:-1] -= ell[:, None] * t[:-1]
    keep = np.linalg.norm(b - a, axis=1) > MIN_LENGTH_MM
    lines = line_spans(a[keep], b[keep], line_rows[keep])
    if not blend.any():
        return lines, None
    j = np.flatnonzero(blend)
    c, t1, t2, e = corner[j], t[j], t[j + 1], ell[j][:, None]
    pts = np.stack([c - e * t1, c - 0.5 * e * t1, c, c + 0.5 * e * t2, c + e * t2], axis=1)
    coeffs = homogeneous_power(pts, np.ones(pts.shape[:2]), pts[:, 0])
    return lines, (coeffs, pts[:, 0].copy(), line_rows[j + 1])
