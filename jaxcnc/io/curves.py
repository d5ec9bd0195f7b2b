"""B-spline / NURBS curves as programs: from arrays, or from JSON curve files.

A JSON curve file holds one curve — ``{"degree": p, "control_points": [[x, y(, z)], ...],
"weights": [...], "knots": [...]}`` (weights optional, default 1) — or several under
``"blocks": [...]`` (the form of ``shared/corpus/nurbs``). The program rapids to the first curve's
start and cuts the curves in order at the given feed, with rapids between curves that do not join.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from jaxcnc.errors import SourceError
from jaxcnc.program import Kind, LaserMode, Program, make_curve_table, program_from_rows

Curve = tuple[int, np.ndarray, np.ndarray, np.ndarray]


def curves_program(
    curves: Sequence[Curve],
    feed_mm_s: float,
    *,
    start: Sequence[float] = (0.0, 0.0, 0.0),
    laser_power: float = 0.0,
    file: str = "<curves>",
) -> Program:
    """A program cutting ``curves`` (``(degree, points, weights, knots)``) at ``feed_mm_s``.

    Raises:
        ValueError: a curve's data is inconsistent (see :func:`~jaxcnc.program.make_curve_table`).
    """
    table = make_curve_table(list(curves))
    rows: dict[str, list] = {k: [] for k in ("kind", "start", "end", "rapid", "feed", "curve", "laser", "power")}
    pos = np.asarray(start, dtype=np.float64)

    def add(kind, end, rapid=False, feed=np.nan, curve=-1):
        nonlocal pos
        rows["kind"].append(kind)
        rows["start"].append(pos.copy())
        rows["end"].append(end)
        rows["rapid"].append(rapid)
        rows["feed"].append(feed)
        rows["curve"].append(curve)
        lit = laser_power > 0 and not rapid
        rows["laser"].append(LaserMode.CONSTANT if lit else LaserMode.OFF)
        rows["power"].append(laser_power if lit else 0.0)
        pos = np.asarray(end, dtype=np.float64)

    for i in range(len(table)):
        _, pts, _, _ = table.curve(i)
        if np.any(pts[0] != pos):
            add(Kind.LINE, pts[0].copy(), rapid=True)
        add(Kind.CURVE, pts[-1].copy(), feed=feed_mm_s, curve=i)
    return program_from_rows(file, rows, table, line=np.arange(1, len(rows["kind"]) + 1))


def read_curves_json(path: str | Path) -> list[Curve]:
    """The curves in a JSON curve file (see the module docstring)."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise SourceError(str(p), 0, 0, f"cannot read curve file: {exc}") from None
    blocks = doc.get("blocks", [doc]) if isinstance(doc, dict) else None
    if not isinstance(blocks, list):
        raise SourceError(str(p), 0, 0, "expected an object with degree/control_points/knots or a 'blocks' list")
    out = []
    for i, b in enumerate(blocks):
        try:
            degree = int(b["degree"])
            pts = np.asarray(b["control_points"], dtype=np.float64)
            weights = np.asarray(b.get("weights", np.ones(len(pts))), dtype=np.float64)
            knots = np.asarray(b["knots"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as exc:
            raise SourceError(str(p), 0, 0, f"curve {i}: missing or malformed field ({exc})") from None
        out.append((degree, pts, weights, knots))
    try:
        make_curve_table(out)
    except ValueError as exc:
        raise SourceError(str(p), 0, 0, str(exc)) from None
    return out
