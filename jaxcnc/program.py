"""The Program: one struct-of-arrays record of the blocks a front end read.

A Program is plain data — NumPy arrays of one row per executable block, no Python object per
block — so a million-block job costs tens of MB and pickles cheaply. Front ends
(:mod:`jaxcnc.gcode`, later DXF/STL/point files) produce it; :mod:`jaxcnc.geometry` turns its
motion rows into spans. All lengths are mm, feeds mm/s, whatever units the source used.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import IntEnum
from typing import TYPE_CHECKING

import numpy as np

from jaxcnc.errors import SourceError

if TYPE_CHECKING:
    from jaxcnc.machine import MachineConfig

#: The program's coordinate axes, in column order of ``start``/``end``/``center``.
PROGRAM_AXES = ("x", "y", "z")
#: The slowest feed a program may set, mm/s: one micrometre in 1000 s (6e-5 mm/min). Slower is below physical
#: sense for a laser machine — and a feed that underflows (``F0.000…1``) made a move's time infinite or zero.
#: Slow feeds above it are limited by the job's bounds instead (:class:`jaxcnc.jobs.JobBounds`: a move that
#: would take longer than the job may last is refused, naming its line, before anything is planned).
MIN_FEED_MM_S = 1e-6
#: An arc's radius below this (mm) is no arc: its centre is its start point.
MIN_ARC_RADIUS_MM = 1e-9
#: A line shorter than this (mm) moves nothing: it makes no span, and the check treats it as a row that stands (as
#: G91 round-off leaves one: 0.1 + 0.1 + 0.1 then G90 X0.3 is a move of 5.5e-17 mm, backwards).
MIN_MOVE_MM = 1e-9
#: The arc planes and their (first, second) axes (G17 XY, G18 ZX, G19 YZ).
_PLANE_AXES = {17: (0, 1), 18: (2, 0), 19: (1, 2)}


def program_start(machine: MachineConfig) -> np.ndarray:
    """``(3,)`` program position (x, y, z) mm where every job starts: each axis' home, 0 for axes the
    machine lacks. Front ends start programs here, planners plan from here, ``check`` compares with it."""
    names = machine.axis_names
    return np.array([machine.axis(a).home if a in names else 0.0 for a in PROGRAM_AXES])


class Kind(IntEnum):
    """What a row does."""

    LINE = 1  # straight move, G0 (rapid) or G1
    ARC = 2  # circular arc in the row's plane, G2/G3
    DWELL = 3  # stand still for ``dwell_s`` seconds, G4
    EVENT = 4  # a machine event at rest: see :class:`Event`
    CURVE = 5  # a (rational) B-spline: row ``curve`` of :attr:`Program.curves` (G5, G5.1, NURBS)


class Event(IntEnum):
    """Machine events carried by EVENT rows (the motion is at rest there)."""

    NONE = 0
    PROGRAM_STOP = 1  # M0: pause until the operator resumes
    OPTIONAL_STOP = 2  # M1: pause if the optional-stop switch is on
    TOOL_CHANGE = 3  # M6: change to tool ``event_value``
    PROGRAM_END = 4  # M2 / M30
    COOLANT = 5  # M7 / M8 / M9 (assist gas on a laser): ``event_value`` is 7, 8 or 9
    EXTERNAL = 6  # M170 / M171: motion goes to the galvo scanner (``event_value`` 1) or back to the stage (0)


class LaserMode(IntEnum):
    OFF = 0  # M5
    CONSTANT = 3  # M3: constant power
    DYNAMIC = 4  # M4: power scaled with speed (laser mode of GRBL-like controllers)


@dataclass(frozen=True, eq=False)
class CurveTable:
    """The (rational) B-spline curves of a program, as ragged arrays.

    Curve ``i`` has degree ``degree[i]``, control points ``points[cp[i]:cp[i+1]]`` (``(m, 3)`` mm)
    with weights ``weights[cp[i]:cp[i+1]]`` and knots ``knots[kn[i]:kn[i+1]]`` (``m + degree + 1`` of
    them, clamped: the curve starts at its first control point and ends at its last). Splines of
    every dialect (G5 cubics, G5.1 quadratics, G5.2/G6.2/BSPLINE NURBS) are stored this way.
    """

    degree: np.ndarray
    cp: np.ndarray
    points: np.ndarray
    weights: np.ndarray
    kn: np.ndarray
    knots: np.ndarray

    def __len__(self) -> int:
        return int(self.degree.shape[0])

    def curve(self, i: int) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        """``(degree, points, weights, knots)`` of curve ``i``."""
        a, b = self.cp[i], self.cp[i + 1]
        return int(self.degree[i]), self.points[a:b], self.weights[a:b], self.knots[self.kn[i] : self.kn[i + 1]]


def make_curve_table(curves: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]) -> CurveTable:
    """Pack ``(degree, points (m, 2 or 3), weights (m,), knots (m+degree+1,))`` tuples, checking them.

    Raises ``ValueError`` naming the curve and what is wrong (the front ends turn it into a located
    error).
    """
    deg, pts, wts, kns = [], [], [], []
    for i, (p, points, weights, knots) in enumerate(curves):
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] not in (2, 3):
            raise ValueError(f"curve {i}: control points must be (m, 2) or (m, 3)")
        if points.shape[1] == 2:
            points = np.concatenate([points, np.zeros((points.shape[0], 1))], axis=1)
        weights = np.asarray(weights, dtype=np.float64)
        knots = np.asarray(knots, dtype=np.float64)
        m = points.shape[0]
        if not 1 <= p <= 7:
            raise ValueError(f"curve {i}: degree {p} is outside 1..7")
        if m < p + 1:
            raise ValueError(f"curve {i}: degree {p} needs at least {p + 1} control points, got {m}")
        if weights.shape != (m,) or not np.all(weights > 0) or not np.all(np.isfinite(weights)):
            raise ValueError(f"curve {i}: needs {m} positive finite weights")
        if knots.shape != (m + p + 1,):
            raise ValueError(
                f"curve {i}: needs {m + p + 1} knots for {m} control points of degree {p}, got {knots.size}"
            )
        if not np.all(np.isfinite(points)) or not np.all(np.isfinite(knots)):
            raise ValueError(f"curve {i}: control points and knots must be finite")
        if np.any(np.diff(knots) < 0):
            raise ValueError(f"curve {i}: knots must not decrease")
        if np.any(knots[: p + 1] != knots[0]) or np.any(knots[-p - 1 :] != knots[-1]) or knots[-1] <= knots[0]:
            raise ValueError(f"curve {i}: knots must be clamped (first and last repeated {p + 1} times)")
        inner = knots[p + 1 : m]
        if inner.size and np.max(np.unique(inner, return_counts=True)[1]) > p:
            raise ValueError(f"curve {i}: an interior knot repeats more than the degree {p} (the curve breaks)")
        deg.append(p)
        pts.append(points)
        wts.append(weights)
        kns.append(knots)
    offsets = np.concatenate([[0], np.cumsum([len(w) for w in wts])]).astype(np.int64)
    k_offsets = np.concatenate([[0], np.cumsum([len(k) for k in kns])]).astype(np.int64)
    return CurveTable(
        degree=np.asarray(deg, np.int8),
        cp=offsets,
        points=np.concatenate(pts) if pts else np.zeros((0, 3)),
        weights=np.concatenate(wts) if wts else np.zeros(0),
        kn=k_offsets,
        knots=np.concatenate(kns) if kns else np.zeros(0),
    )


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
            (the row before it programmed under G61.1 exact stop, laser switched, tool change, pause).
        blend_tol: ``(n,)`` float64 mm, the G64 P tolerance the row is programmed under (``inf`` = G64 without P,
            0 = G61 exact path, G61.1): how the row *ends* — the junction after it is blended within the lower
            of its and the next row's tolerance (the next row's only where it has one), not at all where it is 0.
        event, event_value: ``(n,)`` int8 :class:`Event` and its value (tool number).
        line: ``(n,)`` int32 1-based source line of the block.
        curve: ``(n,)`` int32 row of :attr:`curves` for CURVE rows, -1 otherwise.
        file: the source's name.
        curves: the program's spline curves, or ``None``.
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
    curve: np.ndarray
    file: str = "<memory>"
    curves: CurveTable | None = None

    def __post_init__(self) -> None:
        check_program(self)

    def __len__(self) -> int:
        return int(self.kind.shape[0])

    @property
    def n_blocks(self) -> int:
        return len(self)

    @property
    def is_motion(self) -> np.ndarray:
        """``(n,)`` bool: rows that move the tool."""
        return (self.kind == Kind.LINE) | (self.kind == Kind.ARC) | (self.kind == Kind.CURVE)

    def uses_axis(self, axis: int) -> bool:
        """True when some row moves axis ``axis`` (column index) or stands away from the start."""
        col = np.concatenate([self.start[:, axis], self.end[:, axis]])
        return bool(col.size) and bool(np.any(col != col[0]))


def check_program(p: Program) -> None:
    """Refuse rows below physical sense, whichever front end (or API caller) made them.

    Raises :class:`SourceError` naming the program's file and the row's line, for the first row (in row order)
    that has: an unknown kind; a start or end that is not finite; a feed that is not NaN (the machine's default)
    and not a finite number of at least :data:`MIN_FEED_MM_S`; a dwell that is negative or not finite; a power
    that is negative or not finite; a blend tolerance that is negative or NaN; an arc whose centre is not
    finite, whose radius is below :data:`MIN_ARC_RADIUS_MM`, whose turn is not -1 or +1 or whose plane is not
    17, 18 or 19; a curve row without its curve. Shapes: every column ``(n,)`` or ``(n, 3)``.
    """
    n = len(p)
    if n == 0:
        return
    kind = p.kind
    arc = kind == Kind.ARC
    problems: list[tuple[np.ndarray, str]] = []

    def add(bad: np.ndarray, why: str) -> None:
        if bad.any():
            problems.append((bad, why))

    add(~np.isin(kind, [int(k) for k in Kind]), "unknown row kind (expected 1 line, 2 arc, 3 dwell, 4 event, 5 curve)")
    add(~np.isfinite(p.start).all(axis=1) | ~np.isfinite(p.end).all(axis=1), "start or end is not a finite position")
    feed = p.feed
    add(
        ~np.isnan(feed) & ~((feed >= MIN_FEED_MM_S) & np.isfinite(feed)),
        f"feed is below physical sense or not finite (it must be at least {MIN_FEED_MM_S:g} mm/s, one micrometre "
        "in 1000 s; or NaN for the machine's feed)",
    )
    add(~(p.dwell_s >= 0) | ~np.isfinite(p.dwell_s), "dwell time is negative or not finite")
    add(~(p.power >= 0) | ~np.isfinite(p.power), "laser power is negative or not finite")
    add(~(p.blend_tol >= 0), "blend tolerance is negative or NaN")
    if arc.any():
        a = np.flatnonzero(arc)
        add_at = np.zeros(n, dtype=bool)
        centre_bad = add_at.copy()
        centre_bad[a] = ~np.isfinite(p.center[a]).all(axis=1)
        add(centre_bad, "arc centre is not a finite position")
        plane_bad = add_at.copy()
        plane_bad[a] = ~np.isin(p.plane[a], list(_PLANE_AXES))
        add(plane_bad, "arc plane must be 17 (XY), 18 (ZX) or 19 (YZ)")
        turn_bad = add_at.copy()
        turn_bad[a] = (p.turn[a] != 1) & (p.turn[a] != -1)
        add(turn_bad, "arc turn must be +1 (counter-clockwise, G3) or -1 (clockwise, G2)")
        first = np.where(p.plane[a] == 18, 2, np.where(p.plane[a] == 19, 1, 0))
        second = np.where(p.plane[a] == 18, 0, np.where(p.plane[a] == 19, 2, 1))
        with np.errstate(invalid="ignore"):
            d = p.start[a] - p.center[a]
            r = np.hypot(d[np.arange(a.size), first], d[np.arange(a.size), second])
        radius_bad = add_at.copy()
        radius_bad[a] = r < MIN_ARC_RADIUS_MM
        add(radius_bad, f"arc radius is below {MIN_ARC_RADIUS_MM:g} mm: its centre is its start point")
    curve = kind == Kind.CURVE
    if curve.any():
        count = 0 if p.curves is None else len(p.curves)
        add(curve & ((p.curve < 0) | (p.curve >= count)), "curve row without its curve")
    if not problems:
        return
    first_row = min(int(np.argmax(bad)) for bad, _ in problems)
    why = next(why for bad, why in problems if bad[first_row])
    line = int(p.line[first_row])
    raise SourceError(p.file, line, 0, why if line else f"row {first_row}: {why}")


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
    "curve": np.int32,
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
    "curve": -1,
}


def program_from_columns(file: str = "<memory>", curves: CurveTable | None = None, **cols: np.ndarray) -> Program:
    """Build a Program from column arrays; omitted columns take their defaults.

    ``kind``, ``start`` and ``end`` are required. This is how synthetic programs (benchmarks,
    tests, point files) are made without writing G-code.
    """
    n = int(np.asarray(cols["kind"]).shape[0])
    out = {}
    for f in fields(Program):
        if f.name in ("file", "curves"):
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
    return Program(file=file, curves=curves, **out)


def program_from_rows(
    file: str, rows: dict[str, list], curves: CurveTable | None = None, **cols: np.ndarray
) -> Program:
    """A Program from a front end's per-row lists (``rows``: column name -> one entry per row; ``start``,
    ``end`` and ``center`` entries are 3-vectors) plus whole ``cols``; the motion stops wherever the laser
    is switched (it is switched at rest)."""
    n = len(rows["kind"])
    arrays = {
        k: np.asarray(v).reshape(n, 3) if k in ("start", "end", "center") else np.asarray(v) for k, v in rows.items()
    }
    arrays.update(cols)
    lit = np.asarray(arrays["laser"]) != LaserMode.OFF
    stop = np.zeros(n, bool)
    stop[1:] = lit[1:] != lit[:-1]
    return program_from_columns(file=file, curves=curves, stop_before=stop, **arrays)


#: The per-row columns of a :class:`Program`, in field order.
PROGRAM_COLUMNS = tuple(f.name for f in fields(Program) if f.name not in ("file", "curves"))


@dataclass(frozen=True, eq=False)
class PointJob:
    """Points to burn, in the order given.

    Attributes:
        points: ``(n, 3)`` x, y, z in mm.
        energy: ``(n,)`` per-point pulse energy, or ``None`` when the file gives none.
        line: ``(n,)`` source line of each point (1-based).
        file: where the points came from.
        index: ``(n,)`` each point's position in its file (0-based); differs from ``arange(n)``
            once the points are re-ordered.
        allow_repeats: the user asked for repeated burns (``--allow-repeats``): a point given twice is burned
            twice. Otherwise two points within a quarter discrete of each other, anywhere in the job, are
            refused when it is planned (:func:`jaxcnc.planners.pulsed.request.check_repeats`).
    """

    points: np.ndarray
    energy: np.ndarray | None
    line: np.ndarray
    file: str
    index: np.ndarray | None = None
    allow_repeats: bool = False

    def __post_init__(self) -> None:
        if self.index is None:
            object.__setattr__(self, "index", np.arange(self.points.shape[0], dtype=np.int64))

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def take(self, order: np.ndarray) -> PointJob:
        """The same points in another order (``order`` indexes the current one)."""
        return PointJob(
            points=self.points[order],
            energy=None if self.energy is None else self.energy[order],
            line=self.line[order],
            file=self.file,
            index=self.index[order],
            allow_repeats=self.allow_repeats,
        )
