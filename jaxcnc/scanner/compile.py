"""Plans compiled into scanner vector lists, and the delays and sky-writing chosen from the head model.

Two ways from a planned table (``jaxcnc.jobs.plan_file`` on a scanner-only machine, any front end):

- ``exact``: timed vectors that reproduce the table tick for tick (:func:`jaxcnc.format.vectors.encode_rows`):
  the planner's time law runs on the board; pulsed point jobs become timed marks with a pulse at each point.
- ``board``: as boards are driven by hand: each lit run of the table becomes a polyline (its vertices: the run
  simplified within one discrete, shapely) marked at the run's top speed, runs joined by jumps; delays and
  sky-writing from :func:`auto_settings` (or the user's :class:`Settings`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import shapely

from jaxcnc.errors import MachineFileError
from jaxcnc.format import FINE_SCALE, EventKind
from jaxcnc.format.vectors import Op, VectorHeader, encode_rows, execute, make, records
from jaxcnc.machine import MachineConfig
from jaxcnc.scanner.head import HeadModel, simulate


@dataclass(frozen=True)
class Settings:
    """A board's motion settings in board ticks (``None`` in :func:`compile_board`: chosen from the model)."""

    laser_on: int = 0
    laser_off: int = 0
    jump: int = 0
    mark: int = 0
    polygon: int = 0
    variable_polygon: bool = False
    sky_mode: int = 0
    run_in: int = 0
    run_out: int = 0
    sky_limit_deg: float = 20.0

    def commands(self) -> list:
        """The list commands that set these."""
        return [
            make(Op.SET_LASER_DELAYS, ticks=self.laser_on, aux=self.laser_off),
            make(Op.SET_SCANNER_DELAYS, ticks=self.jump, aux=self.mark, pos=(self.polygon, 0, 0)),
            make(Op.SET_POLYGON_MODE, aux=int(self.variable_polygon)),
            make(Op.SET_SKY_WRITING, aux=self.sky_mode, ticks=self.run_in, pos=(self.run_out, 0, 0),
                 value=self.sky_limit_deg),
        ]  # fmt: skip


#: No delays, no sky-writing: what a naive list does.
NO_DELAYS = Settings()


def _deviation(actual: np.ndarray, lit: np.ndarray, path: np.ndarray) -> float:
    """Largest distance (mm) of the lit ``actual`` points from the polyline ``path``."""
    if not lit.any():
        return 0.0
    line = shapely.LineString(path)
    return float(shapely.distance(shapely.points(actual[lit]), line).max())


def _corner_trial(head: HeadModel, s: Settings, speed: float, turn_deg: float, dt: float, disc: float) -> float:
    """Lit deviation (mm) of the model marking a corner turning ``turn_deg`` between two 1 mm lines."""
    a = math.radians(180.0 - turn_deg)
    seg = 1.0 / disc
    p0, p1 = (0, 0), (round(seg), 0)
    p2 = (round(seg + seg * math.cos(math.pi - a)), round(seg * math.sin(math.pi - a)))
    h = VectorHeader(1.0 / dt, disc)
    rec = records(
        [make(Op.LIST_START, pos=(-round(0.5 / disc), 0)), make(Op.SET_JUMP_SPEED, value=speed),
         make(Op.SET_MARK_SPEED, value=speed), make(Op.SET_LASER, value=1.0), *s.commands(),
         make(Op.JUMP_ABS, pos=p0), make(Op.MARK_ABS, pos=p1), make(Op.MARK_ABS, pos=p2),
         make(Op.WAIT, ticks=200), make(Op.LIST_END)]
    )  # fmt: skip
    ex = execute(rec, h)
    act = simulate(ex.positions[:, :2] * disc, head, dt)
    return _deviation(act, ex.power > 0, np.array([p0, p1, p2], float) * disc)


def auto_settings(
    head: HeadModel, mark_speed_mm_s: float, dt_s: float, discrete_mm: float, tol_mm: float = 0.01,
    sky: bool = True, jump_speed_mm_s: float | None = None,
) -> Settings:  # fmt: skip
    """Delays and sky-writing chosen from the head model for marking at ``mark_speed_mm_s`` within ``tol_mm``.

    Jump delay: until the mirrors settle within half ``tol_mm`` after a jump at ``jump_speed_mm_s``.
    Laser on/off delays: the tracking error (the mirrors pass a point ``τ`` after the command). With ``sky``
    (mode 2): the shortest run-in/run-out (tried on the model: doubling, then bisection) for which a 150°, 90°
    and 30° corner stay within half ``tol_mm`` while lit; the limit angle is the largest turn the model rounds by
    less than half the tolerance without sky-writing (a ladder of turns up to 30°, then bisection to 0.05°).
    Without ``sky``: mark, jump and (variable) polygon delays
    long enough for the mirrors to settle within the tolerance at a stop.
    """
    lag = max(0, round(head.tracking_error_s / dt_s))
    half = 0.5 * tol_mm
    jump = settle_ticks(head, jump_speed_mm_s or mark_speed_mm_s, dt_s, half)
    if sky:
        base = Settings(laser_on=lag, laser_off=lag, sky_mode=2, sky_limit_deg=0.0)

        def ok(t: int) -> bool:
            s = replace(base, run_in=t, run_out=t)
            return all(_corner_trial(head, s, mark_speed_mm_s, ang, dt_s, discrete_mm) <= half for ang in (150, 90, 30))

        lo, hi = 0, max(1, lag)
        while not ok(hi):
            lo, hi = hi, 2 * hi
            if hi > 100000:
                raise ValueError("no run-in settles the head model within the tolerance")
        while hi - lo > 1:
            mid = (lo + hi) // 2
            lo, hi = (lo, mid) if ok(mid) else (mid, hi)
        plain = replace(base, sky_mode=1, run_in=hi, run_out=hi)  # the ends sky-written: the corner alone counts

        def rounds_within(ang: float) -> bool:
            return _corner_trial(head, plain, mark_speed_mm_s, ang, dt_s, discrete_mm) <= half

        # the ladder finds the first turn rounded too far (the rounding grows with the turn up to ~90 degrees, not
        # beyond: a reversal retraces the line), bisection then pins the limit between two rungs to 0.05 degrees
        limit, bad = 0.0, None
        for ang in (0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 15.0, 20.0, 30.0):
            if not rounds_within(ang):
                bad = ang
                break
            limit = ang
        while bad is not None and bad - limit > 0.05:
            mid = 0.5 * (limit + bad)
            limit, bad = (mid, bad) if rounds_within(mid) else (limit, mid)
        return replace(base, run_in=hi, run_out=hi, sky_limit_deg=round(limit, 2), jump=jump)
    settle = settle_ticks(head, mark_speed_mm_s, dt_s, half)
    return Settings(laser_on=lag, laser_off=lag, jump=jump, mark=settle, polygon=2 * settle, variable_polygon=True)


def machine_settings(machine: MachineConfig, auto: Settings | None = None) -> Settings:
    """The board settings of a machine file: every ``[galvo]`` delay and sky-writing key given there (seconds at
    the board, rounded to ticks at ``[machine] tick_hz``), the others from ``auto`` (e.g. :func:`auto_settings`;
    ``None``: no delays). Code can still pass any :class:`Settings` of its own."""
    g = machine.galvo
    if g is None:
        raise MachineFileError(machine.source, "galvo", f"machine {machine.name!r} has no [galvo] table")
    s = auto or NO_DELAYS
    hz = machine.tick_hz

    def ticks(v: float | None, default: int) -> int:
        return default if v is None else round(v * hz)

    return Settings(
        laser_on=ticks(g.laser_on_delay_s, s.laser_on),
        laser_off=ticks(g.laser_off_delay_s, s.laser_off),
        jump=ticks(g.jump_delay_s, s.jump),
        mark=ticks(g.mark_delay_s, s.mark),
        polygon=ticks(g.polygon_delay_s, s.polygon),
        variable_polygon=s.variable_polygon if g.variable_polygon is None else g.variable_polygon,
        sky_mode=s.sky_mode if g.sky_writing is None else int(g.sky_writing),
        run_in=ticks(g.run_in_s, s.run_in),
        run_out=ticks(g.run_out_s, s.run_out),
        sky_limit_deg=s.sky_limit_deg if g.sky_limit_deg is None else g.sky_limit_deg,
    )


def settle_ticks(head: HeadModel, speed_mm_s: float, dt_s: float, tol_mm: float) -> int:
    """Ticks after a move at ``speed_mm_s`` ends until the mirrors stay within ``tol_mm`` of the command.

    Tried on the model for moves of 0.05 mm up to 15 ms of travel (short moves end while the mirrors still
    accelerate, long ones at full lag); the longest settling wins.
    """
    n = 8192
    t = np.arange(n) * dt_s
    worst = 0
    for length in np.geomspace(0.05, speed_mm_s * 0.015, 8):  # a few trial moves
        x = np.minimum(t * speed_mm_s, length)
        act = simulate(x[:, None], head, dt_s)[:, 0]
        stop = int(np.ceil(length / speed_mm_s / dt_s))
        bad = np.flatnonzero(np.abs(act[stop:] - x[stop:]) > tol_mm)
        worst = max(worst, int(bad[-1] + 1) if bad.size else 0)
    return worst


@dataclass
class Runs:
    """The lit runs of a table as programmed polylines (mm), with their power and top speed."""

    paths: list[np.ndarray]
    power: list[float]
    speed_mm_s: list[float]


def lit_runs(positions: np.ndarray, power: np.ndarray, discrete_mm: float, dt_s: float) -> Runs:
    """Split a table into its lit runs; each simplified to a polyline within one discrete (shapely)."""
    lit = np.asarray(power) > 0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], lit.astype(np.int8), [0]])))
    paths, pw, sp = [], [], []
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # one step per lit run
        a0 = max(a - 1, 0)  # the run starts where its first lit row was reached from
        p = positions[a0:b, :2].astype(np.float64)
        keep = np.concatenate([[True], np.any(np.diff(p, axis=0) != 0, axis=1)])
        p = p[keep]
        if p.shape[0] < 2:
            continue
        simple = np.asarray(shapely.LineString(p).simplify(1.0, preserve_topology=False).coords)
        v = np.hypot(*np.diff(p, axis=0).T).max() * discrete_mm / dt_s
        paths.append(simple * discrete_mm)
        pw.append(float(np.max(power[a:b])))
        sp.append(float(v))
    return Runs(paths, pw, sp)


def compile_board(
    runs: Runs, header: VectorHeader, settings: Settings, jump_speed_mm_s: float, start_mm=(0.0, 0.0),
    mark_speed_mm_s: float | None = None,
) -> np.ndarray:  # fmt: skip
    """A board list for ``runs``: per run a jump and a polyline at its speed (or ``mark_speed_mm_s``)."""
    d = header.discrete_mm
    start = np.round(np.asarray(start_mm) / d).astype(np.int64)
    items = [make(Op.LIST_START, pos=start), make(Op.SET_JUMP_SPEED, value=jump_speed_mm_s), *settings.commands()]
    speed = power = None
    for path, pw, v in zip(runs.paths, runs.power, runs.speed_mm_s, strict=True):
        v = mark_speed_mm_s or v
        if v != speed:
            items.append(make(Op.SET_MARK_SPEED, value=v))
            speed = v
        if pw != power:
            items.append(make(Op.SET_LASER, value=pw))
            power = pw
        q = np.round(path / d).astype(np.int64)
        items.append(make(Op.JUMP_ABS, pos=q[0]))
        items.append(make(Op.POLYLINE, aux=q.shape[0] - 1))
        items.extend(make(Op.VERTEX, pos=p) for p in q[1:])
    items.append(make(Op.LIST_END))
    return records(items)


def compile_exact(positions: np.ndarray, power: np.ndarray, events: np.ndarray | None = None) -> np.ndarray:
    """Timed vectors reproducing a table tick for tick (work and idle pulses included from ``events``)."""
    pulses = None
    if events is not None and len(events):
        pulses = events[np.isin(events["kind"], (9, 10))]
    return encode_rows(positions, power, pulses)


def compile_pulsed(
    positions: np.ndarray, fine: np.ndarray | None, events: np.ndarray, head: HeadModel | None, header: VectorHeader,
    subdiv: int = 16,
) -> tuple[np.ndarray, VectorHeader]:  # fmt: skip
    """A pulsed point job as timed marks with a ``laser_pulse`` at each of the table's pulses.

    ``positions`` ``(n, k)`` int discretes and ``fine`` ``(n, k)`` (the table's fine channel, ``None``: none) of
    a pulsed table at the board tick; ``events`` its events (work and idle pulses travel with their ticks, so every
    pulse interval is the table's). The list's discrete is ``header.discrete_mm / subdiv`` (boards resolve far below
    a table's discrete): the commanded beam is the table's unquantised path within ``1 / (2 subdiv)`` discrete.
    With a ``head``, the x and y commands are **pre-compensated** for the mirrors' lag so that the actual beam, not
    the command, is on each point at its pulse: the inverse of the tracking model,
    ``c = x + τ x' + x'' / ω²`` (derivatives of the table's path by central differences; the path starts and ends
    at rest, so ``c = x`` there). Returns the records and the list's header.
    """
    d = header.discrete_mm
    x = np.asarray(positions, np.float64)
    if fine is not None:
        x = x + np.asarray(fine, np.float64) / FINE_SCALE
    x = x * d
    if head is not None and x.shape[0] > 2:
        v = np.gradient(x[:, :2], header.dt, axis=0)
        a = np.gradient(v, header.dt, axis=0)
        x[:, :2] += head.tracking_error_s * v + a / head.omega**2
    q = np.rint(x / d * subdiv).astype(np.int64)
    lh = VectorHeader(header.tick_hz, d / subdiv, header.axes, dict(header.meta, subdiv=subdiv))
    pulses = events[np.isin(events["kind"], (EventKind.WORK_PULSE, EventKind.IDLE_PULSE))]
    return encode_rows(q, np.zeros(q.shape[0]), pulses), lh
