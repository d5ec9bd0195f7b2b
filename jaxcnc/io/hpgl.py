"""HP-GL plot files (``.plt``, ``.hpgl``) as Programs.

Instructions read: ``IN`` (initialise: pen up, absolute, at the origin), ``SP n`` (select pen; pen 0 puts
the pen away: nothing is drawn until another pen is selected), ``PU`` / ``PD`` (pen up / down, then move
through the coordinate pairs that follow), ``PA`` / ``PR`` (absolute / relative coordinates from now on,
then move through the pairs that follow with the pen as it is). Coordinates are plotter units, 40 per
mm (0.025 mm each). Instructions end at ``;``, a line end or the next instruction's two letters;
parameters are separated by commas or spaces. Any other instruction, an odd number of coordinates, a
number that is not one, or a coordinate beyond ±10⁸ units is an error naming the line.

Every pen-down move is a straight piece numbered by its line; chaining, the shapely checks (closed,
not self-intersecting, not crossing unless open contours are allowed), cut order and the Program are
:mod:`jaxcnc.io.drawing`.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from jaxcnc.errors import SourceError
from jaxcnc.io.drawing import Drawing, DrawingOptions, Piece, assemble, line_piece

HPGL_SUFFIXES = (".plt", ".hpgl")
#: Plotter units per mm.
UNITS_PER_MM = 40.0
#: Coordinates beyond this many plotter units (2.5 km) are refused.
MAX_UNITS = 1e8
_TOKEN = re.compile(r"([A-Za-z]{2})([^A-Za-z;]*);?|(\S)")
_SEP = re.compile(r"[,\s]+")


def parse_hpgl(text: str, file: str = "<hpgl>") -> list[Piece]:
    """The pen-down moves of HP-GL ``text`` as straight pieces (mm). See the module docstring."""
    newlines = np.flatnonzero(np.frombuffer(text.encode("utf-32-le"), dtype=np.uint32) == 10)
    pos = np.zeros(2)
    pen_down, absolute, pen = False, True, 1
    pieces: list[Piece] = []
    for m in _TOKEN.finditer(text):
        line = int(np.searchsorted(newlines, m.start(), side="right")) + 1
        if m.group(3) == ";":
            continue
        if m.group(3) is not None:
            raise SourceError(file, line, 0, f"unexpected {m.group(3)!r} (an instruction is two letters)")
        op, raw = m.group(1).upper(), m.group(2).strip()
        args = [a for a in _SEP.split(raw) if a] if raw else []
        try:
            nums = np.array([float(a) for a in args], dtype=np.float64)
        except ValueError:
            raise SourceError(file, line, 0, f"{op}: parameters must be numbers, got {raw!r}") from None
        if not np.all(np.isfinite(nums)) or np.any(np.abs(nums) > MAX_UNITS):
            raise SourceError(file, line, 0, f"{op}: parameter beyond ±{MAX_UNITS:g} plotter units in {raw!r}")
        if op == "IN":
            pos, pen_down, absolute, pen = np.zeros(2), False, True, 1
            continue
        if op == "SP":
            if nums.size > 1 or (nums.size and nums[0] != int(nums[0])):
                raise SourceError(file, line, 0, f"SP takes one pen number, got {raw!r}")
            pen = int(nums[0]) if nums.size else 0
            continue
        if op not in ("PU", "PD", "PA", "PR"):
            raise SourceError(file, line, 0, f"{op}: instruction not supported (read: IN, SP, PU, PD, PA, PR)")
        if op == "PU":
            pen_down = False
        elif op == "PD":
            pen_down = True
        elif op == "PA":
            absolute = True
        else:
            absolute = False
        if nums.size % 2:
            raise SourceError(file, line, 0, f"{op}: coordinates come in x,y pairs, got {nums.size} numbers")
        pts = nums.reshape(-1, 2) / UNITS_PER_MM
        if not absolute:
            pts = pos + np.cumsum(pts, axis=0)
        for p in pts:
            if pen_down and pen != 0 and np.any(p != pos):
                pieces.append(line_piece(pos, p, f"{op} at line {line}", line))
            pos = p
    return pieces


def read_hpgl(path: str | Path, start: np.ndarray, options: DrawingOptions | None = None) -> Drawing:
    """The HP-GL file at ``path`` as a job (:class:`~jaxcnc.io.drawing.Drawing`), starting at ``start`` ``(3,)``.

    Raises:
        SourceError: unreadable file, a bad instruction (its line), or contours that fail the checks.
    """
    file = str(path)
    try:
        text = Path(path).read_bytes().decode("ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise SourceError(file, 0, 0, f"cannot read the plot file: {exc}") from None
    return assemble(parse_hpgl(text, file), options or DrawingOptions(), start, file)
