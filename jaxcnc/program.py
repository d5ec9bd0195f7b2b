"""The Program: one struct-of-arrays record of the blocks a front end read.

A Program is plain data — NumPy arrays of one row per executable block, no Python object per
block — so a million-block job costs tens of MB and pickles cheaply. Front ends
(:mod:`jaxcnc.gcode`, later DXF/STL/point files) produce it; :mod:`jaxcnc.geometry` turns its
motion rows into spans. All lengths are mm, feeds mm/s, whatever units the source used.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import IntEnum

import numpy as np

#: The program's coordinate axes, in column order of ``start``/``end``/``center``.
PROGRAM_AXES = ("x", "y", "z")


class Kind(IntEnum):
    """What a row does."""

    LINE = 1  # straight move, G0 (rapid) or G1
    ARC = 2  # circular arc in the row's plane, G2/G3
    DWELL = 3  # stand still for ``dwell_s`` seconds, G4
    EVENT = 4  # a machine event at rest: see :class:`Event`


class Event(IntEnum):
    """Machine events carried by EVENT rows (the motion is at rest there)."""

    NONE = 0
    PROGRAM_STOP = 1  # M0: pause until the operator resumes
    OPTIONAL_STOP = 2  # M1: pause if the optional-stop switch is on
    TOOL_CHANGE = 3  # M6: change to tool ``event_value``
    PROGRAM_END = 4  # M2 / M30


class LaserMode(IntEnum):
    OFF = 0  # M5
    CONSTANT = 3  # M3: constant power
    DYNAMIC = 4  # M4: power scaled with speed (laser mode of GRBL-like controllers)


@dataclass(frozen=True, eq=False)
class Program:
    """Blocks as arrays; every array has ``n_blocks`` rows.

    Attributes:
        kind: ``(n,)`` int8, a :class:`Kind`.
        start, end: ``(n, 3)`` float64 mm, position before and after the row.
        center: ``(n, 3)`` float64 mm, arc centre (``nan`` unless ARC).
        turn: ``(n,)`` int8, +1 counter-clockwise (G3), -1 clockwise (G2), 0 otherwise.
        plane: ``(n,)`` int8, 17/18/19 for the arc plane (G17 XY, ...).
        feed: ``(n,)`` float64 mm/s programmed feed; ``nan`` = not set (machine default).
        rapid: ``(n,)`` bool, G0 move (machine rapid cap, laser dark).
        laser: ``(n,)`` int8 :class:`LaserMode` in effect during the row.
        power: ``(n,)`` float64, the S word in effect (the laser's power scale).
        dwell_s: ``(n,)`` float64 seconds (DWELL rows).
        stop_before: ``(n,)`` bool, the motion must be at rest when this row starts
            (exact stop mode, laser switched, tool change, pause).
        blend_tol: ``(n,)`` float64 mm, G64 P tolerance (``inf`` = G64 without P,
            0 = G61 exact path).
        event, event_value: ``(n,)`` int8 :class:`Event` and its value (tool number).
        line: ``(n,)`` int32 1-based source line of the block.
        file: the source's name.
    """

    kind: np.ndarray
    start: np.ndarray
    end: np.ndarray
    center: np.ndarray
    turn: np.ndarray
    plane: np.ndarray
    feed: np.ndarray
    rapid: np.ndarray
    laser: np.ndarray
    power: np.ndarray
    dwell_s: np.ndarray
    stop_before: np.ndarray
    blend_tol: np.ndarray
    event: np.ndarray
    event_value: np.ndarray
    line: np.ndarray
    file: str = "<memory>"

    def __len__(self) -> int:
        return int(self.kind.shape[0])

    @property
    def n_blocks(self) -> int:
        return len(self)

    @property
    def is_motion(self) -> np.ndarray:
        """``(n,)`` bool: rows that move the tool."""
        return (self.kind == Kind.LINE) | (self.kind == Kind.ARC)

    def uses_axis(self, axis: int) -> bool:
        """True when some row moves axis ``axis`` (column index) or stands away from the start."""
        col = np.concatenate([self.start[:, axis], self.end[:, axis]])
        return bool(col.size) and bool(np.any(col != col[0]))


# Column dtypes; ``from_columns`` fills defaults for what a front end leaves out.
_DTYPES = {
    "kind": np.int8,
    "start": np.float64,
    "end": np.float64,
    "center": np.float64,
    "turn": np.int8,
    "plane": np.int8,
    "feed": np.float64,
    "rapid": np.bool_,
    "laser": np.int8,
    "power": np.float64,
    "dwell_s": np.float64,
    "stop_before": np.bool_,
    "blend_tol": np.float64,
    "event": np.int8,
    "event_value": np.int32,
    "line": np.int32,
}
_DEFAULTS = {
    "center": np.nan,
    "turn": 0,
    "plane": 17,
    "feed": np.nan,
    "rapid": False,
    "laser": 0,
    "power": 0.0,
    "dwell_s": 0.0,
    "stop_before": False,
    "blend_tol": 0.0,
    "event": 0,
    "event_value": 0,
    "line": 0,
}


def program_from_columns(file: str = "<memory>", **cols: np.ndarray) -> Program:
    """Build a Program from column arrays; omitted columns take their defaults.

    ``kind``, ``start`` and ``end`` are required. This is how synthetic programs (benchmarks,
    tests, point files) are made without writing G-code.
    """
    n = int(np.asarray(cols["kind"]).shape[0])
    out = {}
    for f in fields(Program):
        if f.name == "file":
            continue
        dt = _DTYPES[f.name]
        width = (n, 3) if f.name in ("start", "end", "center") else (n,)
        if f.name in cols:
            a = np.asarray(cols[f.name], dtype=dt)
            if a.shape != width:
                raise ValueError(f"column {f.name}: shape {a.shape}, expected {width}")
        else:
            a = np.full(width, _DEFAULTS[f.name], dtype=dt)
        a.setflags(write=False)
        out[f.name] = a
    return Program(file=file, **out)
