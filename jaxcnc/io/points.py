"""Point files for point-by-point pulsed engraving: ``.xyz`` / ``.csv``, one point per line.

Format: ``x y z`` in mm, separated by spaces, tabs, commas or semicolons, optionally a fourth
column with the point's pulse energy (any unit the laser takes; carried to the table's work-pulse
events). Blank lines and lines starting with ``#`` are skipped; the first data line may be a
header (``x,y,z[,energy]``). A G-code program serves as a point file too: the end point of every
feed move (G1) is a point (:func:`points_from_program`).

Every mistake is an error naming the file, the line and the cause: a wrong number of columns,
text where a number belongs, a NaN or infinite coordinate, an empty file. A point given twice (anywhere in
the file, within a quarter discrete) would be burned twice: that needs the machine's discrete and is refused
when the job is planned, naming both lines, unless repeated burns are asked for
(:func:`jaxcnc.planners.pulsed.request.check_repeats`).

NumPy only: the table checker reads point files too.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from jaxcnc.errors import SourceError
from jaxcnc.program import Kind, PointJob

POINT_SUFFIXES = (".xyz", ".csv")
_SEP = re.compile(r"[,;\s]+")


def _is_header(fields: list[str]) -> bool:
    return bool(fields) and all(re.fullmatch(r"[A-Za-z_][\w ]*", f) for f in fields)


def parse_points(text: str, file: str = "<string>") -> PointJob:
    """Parse the text of a point file (see the module docstring)."""
    rows: list[list[str]] = []
    lines: list[int] = []
    header_seen = False
    for no, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        fields = [f for f in _SEP.split(s) if f]
        if not rows and not header_seen and _is_header(fields):
            header_seen = True
            continue
        rows.append(fields)
        lines.append(no)
    if not rows:
        raise SourceError(file, 0, 0, "no points in the file")
    counts = np.fromiter((len(r) for r in rows), dtype=np.int64, count=len(rows))
    width = 4 if counts[0] == 4 else 3
    bad = np.flatnonzero(counts != width)
    if bad.size:
        k = int(bad[0])
        raise SourceError(
            file, lines[k], 0, f"expected {width} numbers (x y z{' energy' if width == 4 else ''}), got {counts[k]}"
        )
    flat = [f for r in rows for f in r]
    try:
        values = np.array(flat, dtype=np.float64).reshape(-1, width)
    except ValueError:
        for k, r in enumerate(rows):
            for f in r:
                try:
                    float(f)
                except ValueError:
                    raise SourceError(file, lines[k], 0, f"{f!r} is not a number") from None
        raise  # pragma: no cover  (numpy and float() agree on what a number is)
    line = np.asarray(lines, dtype=np.int64)
    return _validated(values[:, :3], values[:, 3] if width == 4 else None, line, file)


def _validated(points: np.ndarray, energy: np.ndarray | None, line: np.ndarray, file: str) -> PointJob:
    finite = np.all(np.isfinite(points), axis=1)
    if energy is not None:
        finite &= np.isfinite(energy)
    if not np.all(finite):
        k = int(np.flatnonzero(~finite)[0])
        raise SourceError(file, int(line[k]), 0, "coordinate or energy is NaN or infinite")
    if energy is not None and np.any(energy < 0):
        k = int(np.flatnonzero(energy < 0)[0])
        raise SourceError(file, int(line[k]), 0, f"negative pulse energy {energy[k]:g}")
    for a in (points, line) + ((energy,) if energy is not None else ()):
        a.setflags(write=False)
    return PointJob(points=points, energy=energy, line=line, file=file)


def read_points(path: str | Path) -> PointJob:
    """Read a ``.xyz`` / ``.csv`` point file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8", errors="strict")
    except UnicodeDecodeError as exc:
        raise SourceError(str(path), 0, 0, f"not a text file ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise SourceError(str(path), 0, 0, exc.strerror or str(exc)) from None
    return parse_points(text, str(path))


def points_from_program(program) -> PointJob:
    """The points of a G-code program: the end point of every feed move (G1) that moves."""
    moves = (program.kind == Kind.LINE) & ~program.rapid
    moves &= np.any(program.end != program.start, axis=1)
    idx = np.flatnonzero(moves)
    if idx.size == 0:
        raise SourceError(program.file, 0, 0, "the program has no G1 moves whose end points could be burned")
    return _validated(np.array(program.end[idx]), None, np.array(program.line[idx], dtype=np.int64), program.file)
