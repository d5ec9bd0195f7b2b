"""Stage + scanner split: the tool point S = S1 (main axes x, y) + S2 (scanner axes u, v) at constant speed.

The machine file's ``[scanner]`` names two additional axes (``u``, ``v`` with their own ``[axes.*]`` limits),
their field and the calibration between the frames (:class:`~jaxcnc.machine.ScannerConfig`): the tool point
is ``main + offset + R(rotation) · diag(scale) · (u, v)``. The tool moves along the whole program (cuts with
the laser on, travels between contours with it off) at one constant speed, the feed, sampled at the tick
rate; the split decides where the heavy stage is at every tick, the scanner takes the rest.

Methods (``method``):

* ``"own"`` (default) — **a time-domain low-pass of the tool path for the stage, the residual on the
  scanner, iterated against the field.** The stage follows two centred moving averages of width
  ``T = 2 F / a_stage`` of the tool path (the job planned ahead, so the filter need not be causal). Why:
  the tool's velocity has constant length ``F``, so a moving average of width ``T`` has acceleration
  ``(v(t + T/2) − v(t − T/2)) / T``, at most ``2F / T = a_stage`` — a proof, not a tuning, and it holds
  per axis; the second average keeps the acceleration continuous (jerk at most ``4F/T²``) without raising
  it, so a stage with a jerk limit widens ``T`` to ``2·√(F/j)`` where that is wider (:func:`filter_ticks`); the
  stage speed is at most ``F``. The residual ``S − S1`` is at most ``F·T = 2F²/a_stage`` in length (far
  less on most paths) and is measured at every tick against the field; if it leaves the field the plan is
  refused with the place and the highest contour speed that fits (found by iterating ``F ← F·√(h/r)``,
  the residual scaling as ``F²``). The stage starts ``2T/2`` before the tool moves and ends as long after:
  the job takes ``L/F + 2·(w − 1)`` ticks (``w`` the filter width in ticks), whatever the corners.
* ``"seed"`` — the source documents' DopOs2 (SEEDS.md §4) as a reference: the tool path cut into equal
  chords, every vertex whose interior angle is below ``α_kr`` replaced by the midpoint of its neighbours
  until none is (red-black passes: the paper's "step back and re-check" without its sequential loop),
  that polyline the stage path, the scanner the remainder, the tool at constant speed (the paper's intent;
  its scalar speed split is not self-consistent). ``α_kr = 180° − a_stage·Δl/F²`` in radians (the turn per
  chord at which the stage, running at ``F``, reaches its acceleration: a smaller step needs a larger
  ``α_kr``, as the paper says). The documents' own figures (their time sum, ``Vbig``/``Vsmall``,
  ``Abig``/``Asmall`` per chord) are reported beside.
* ``"none"``: the stage alone (the normal planners; not planned here).

Numerics are vectorised NumPy over ticks (moving averages by cumulative sums, no loop over points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from jaxcnc.errors import PlanningError
from jaxcnc.machine import MachineConfig
from jaxcnc.program import Event, Kind, LaserMode, Program, program_start

SPLIT_METHODS = ("own", "seed", "none")
#: Fraction kept below every limit (as the planners' ``NUMERIC_MARGIN``).
MARGIN = 1e-3
#: Default chord of the documents' method (mm).
SEED_STEP_MM = 0.1


@dataclass(frozen=True, eq=False)
class SplitPlan:
    """A split job sampled at the tick rate (``n`` ticks, mm in the main axes' frame unless said).

    Attributes:
        tool: ``(n, 2)`` the tool point S. main: ``(n, 2)`` the stage S1. scan: ``(n, 2)`` S2 = S − S1.
        cmd: ``(n, 2)`` the scanner axes' positions (its own frame, through the calibration).
        lit: ``(n,)`` laser on. row: ``(n,)`` the program row the tool is on.
        feed_mm_s: the tool's constant speed while moving. stats: figures for the report.
    """

    tick_hz: float
    tool: np.ndarray
    main: np.ndarray
    scan: np.ndarray
    cmd: np.ndarray
    lit: np.ndarray
    row: np.ndarray
    feed_mm_s: float
    method: str
    path_length_mm: float
    stats: dict = field(default_factory=dict)

    @property
    def n_ticks(self) -> int:
        return int(self.tool.shape[0])

    @property
    def total_time_s(self) -> float:
        return (self.n_ticks - 1) / self.tick_hz


def scanner_axes(machine: MachineConfig) -> tuple[str, str]:
    """The two scanner axes of ``machine``; an error when it has no usable ``[scanner]``."""
    sc = machine.scanner
    if sc is None:
        raise PlanningError(f"{machine.source}: the stage + scanner split needs a [scanner] section")
    if len(sc.axes) != 2:
        raise PlanningError(f"{machine.source}: [scanner] axes: the split needs two scanner axes, got {len(sc.axes)}")
    return sc.axes[0], sc.axes[1]


def calibration(machine: MachineConfig) -> tuple[np.ndarray, np.ndarray]:
    """``(M, offset)``: tool = main + offset + M @ (u, v); ``M`` ``(2, 2)`` = R(rotation) · diag(scale)."""
    sc = machine.scanner
    th = math.radians(sc.rotation_deg)
    rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    return rot @ np.diag(np.asarray(sc.scale[:2], np.float64)), np.asarray(sc.offset_mm[:2], np.float64)


def half_field(machine: MachineConfig) -> np.ndarray:
    """``(2,)`` how far each scanner axis may go from 0: half its field, within the axis' travel."""
    sc = machine.scanner
    out = []
    for name, f in zip(sc.axes[:2], sc.field_mm[:2], strict=True):
        ax = machine.axis(name)
        out.append(min(f / 2, -ax.min, ax.max) if ax.min < 0 < ax.max else 0.0)
    return np.asarray(out)


def job_feed(program: Program, machine: MachineConfig) -> float:
    """The contour speed: the program's feed on cut rows (its lowest, if several), else ``[path] feed``."""
    cut = program.is_motion & ~program.rapid
    f = program.feed[cut]
    f = f[np.isfinite(f)]
    return float(f.min()) if f.size else float(machine.path.feed)


def refuse_unsplittable(program: Program) -> None:
    """Raise, naming the first row, for what a split job cannot do: the tool never stops (a dwell, a pause or a
    tool change needs rest) and it moves in the XY plane only (the split has no Z; a Z move would be lost)."""
    pause = (Event.PROGRAM_STOP, Event.OPTIONAL_STOP, Event.TOOL_CHANGE)
    z0 = program.start[0, 2] if len(program) else 0.0
    causes = (
        ((program.kind == Kind.DWELL) & (program.dwell_s > 0), "a dwell cannot be split at constant tool speed"),
        (
            (program.kind == Kind.EVENT) & np.isin(program.event, pause),
            "a pause or tool change stops the tool, which a split job at constant tool speed cannot",
        ),
        (
            program.is_motion & ((program.start[:, 2] != z0) | (program.end[:, 2] != z0)),
            "moves Z; a stage + scanner split is planar (plan Z moves as a separate job)",
        ),
    )
    first = [(int(np.flatnonzero(bad)[0]), why) for bad, why in causes if np.any(bad)]
    if first:
        r, why = min(first)
        raise PlanningError(f"{program.file}:{program.line[r]}: {why}")


def tool_path(program: Program, feed_mm_s: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The tool point at every tick moving at constant speed along the whole program (travels included).

    Returns ``(S (n, 2), row (n,), lit (n,), length_mm)``; the speed is ``L / ((n − 1) dt)``, at most
    ``feed_mm_s`` (the last tick lands on the end).
    """
    from jaxcnc.geometry import SpanKind, build_spans
    from jaxcnc.geometry.evaluate import evaluate_path, span_arrays

    refuse_unsplittable(program)
    spans = build_spans(program, 0.0)
    keep = np.flatnonzero((spans.kind != SpanKind.POINT) & (np.asarray(spans.length) > 0))
    length = np.asarray(spans.length, np.float64)[keep]
    cum = np.concatenate([[0.0], np.cumsum(length)])
    total = float(cum[-1])
    if total <= 0:
        raise PlanningError(f"{program.file}: nothing moves")
    n = int(math.ceil(total / (feed_mm_s * dt)))
    s = np.minimum(np.arange(n + 1) * (total / n), total)
    k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, keep.size - 1)
    (p,) = evaluate_path(span_arrays(spans), keep[k], s - cum[k])
    row = np.asarray(spans.block)[keep[k]]
    lit = (program.laser[row] != LaserMode.OFF) & ~program.rapid[row]
    return np.asarray(p)[:, :2], row, lit, total


def moving_average(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving average of odd width ``w`` over axis 0 of ``x`` ``(n, d)``, the ends held (edge values)."""
    h = w // 2
    xp = np.concatenate([np.repeat(x[:1], h, axis=0), x, np.repeat(x[-1:], h, axis=0)])
    c = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(xp, axis=0)])
    return (c[w:] - c[:-w]) / w


def second_difference(x: np.ndarray, dt: float) -> np.ndarray:
    """``(n, d)`` accelerations by central differences (0 at the ends)."""
    a = np.zeros_like(x)
    a[1:-1] = (x[2:] - 2 * x[1:-1] + x[:-2]) / dt**2
    return a


def first_difference(x: np.ndarray, dt: float) -> np.ndarray:
    """``(n, d)`` velocities by backward differences (0 at the first tick)."""
    v = np.zeros_like(x)
    v[1:] = np.diff(x, axis=0) / dt
    return v


def third_difference(x: np.ndarray, dt: float) -> np.ndarray:
    """``(n, d)`` jerks by backward differences over four ticks, as the check measures them (0 before)."""
    j = np.zeros_like(x)
    j[3:] = (x[3:] - 3 * x[2:-1] + 3 * x[1:-2] - x[:-3]) / dt**3
    return j


def _stage_limits(machine: MachineConfig) -> tuple[float, float, float | None]:
    """The stage's speed, acceleration and jerk (``None``: not limited), the slower of x and y, below the margin."""
    x, y = machine.axis("x"), machine.axis("y")
    jerks = [j for j in (x.j_max, y.j_max) if j is not None]
    j_stage = min(jerks) * (1 - MARGIN) if jerks else None
    return min(x.v_max, y.v_max) * (1 - MARGIN), min(x.a_max, y.a_max) * (1 - MARGIN), j_stage


def filter_ticks(feed_mm_s: float, a_stage: float, j_stage: float | None, dt: float) -> int:
    """The odd width ``w`` (ticks) of the stage's two moving averages.

    One average of width ``T`` over a path run at constant speed ``F`` has acceleration
    ``(v(t + T/2) − v(t − T/2)) / T``, at most ``2F/T``; the second average does not raise it, so
    ``T ≥ 2F/a`` keeps the acceleration. The second average's jerk is ``(a₁(t + T/2) − a₁(t − T/2)) / T``
    with ``|a₁| ≤ 2F/T``: at most ``4F/T²``, so ``T ≥ 2·√(F/j)`` keeps the jerk too.
    """
    t_s = 2 * feed_mm_s / a_stage
    if j_stage is not None:
        t_s = max(t_s, 2 * math.sqrt(feed_mm_s / j_stage))
    w = int(math.ceil(t_s / dt))
    return w + 1 - w % 2


def lowpass_split(
    tool: np.ndarray, feed_mm_s: float, a_stage: float, dt: float, j_stage: float | None = None
) -> tuple[np.ndarray, int]:
    """``(S1 (n + 2(w−1), 2), w)``: the tool path held ``w − 1`` ticks at each end, twice averaged over ``w``
    ticks (:func:`filter_ticks`), widened until the acceleration (and the jerk, when limited) measured at the
    tick rate obey."""
    w = filter_ticks(feed_mm_s, a_stage, j_stage, dt)
    for _ in range(50):
        pad = w - 1
        s = np.concatenate([np.repeat(tool[:1], pad, axis=0), tool, np.repeat(tool[-1:], pad, axis=0)])
        s1 = moving_average(moving_average(s, w), w)
        ok = np.max(np.abs(second_difference(s1, dt))) <= a_stage
        if ok and j_stage is not None:
            ok = np.max(np.abs(third_difference(s1, dt))) <= j_stage
        if ok:
            return s1, w
        w += 2
    raise PlanningError("the low-pass stage path does not converge")  # pragma: no cover


def seed_smooth(points: np.ndarray, alpha_kr_rad: float, max_passes: int = 20000) -> tuple[np.ndarray, int, int]:
    """The documents' smoothing of a chord polyline ``(m, 2)``: vertices whose interior angle (between the
    vectors to their neighbours; π on a straight run) is below ``alpha_kr_rad`` move to their neighbours'
    midpoint, in red-black passes until none is. ``(smoothed, passes, sharp vertices left)``."""
    p = points.copy()
    left = 0
    for it in range(max_passes):
        left = 0
        for parity in (1, 2):
            a, b, c = p[parity - 1 : -2 : 2], p[parity:-1:2], p[parity + 1 :: 2]
            m = min(len(a), len(b), len(c))
            a, b, c = a[:m], b[:m], c[:m]
            u, v = a - b, c - b
            nu, nv = np.linalg.norm(u, axis=1), np.linalg.norm(v, axis=1)
            ok = (nu > 0) & (nv > 0)
            cos = np.where(ok, np.sum(u * v, axis=1) / np.where(ok, nu * nv, 1.0), -1.0)
            sharp = np.arccos(np.clip(cos, -1.0, 1.0)) < alpha_kr_rad
            left += int(np.sum(sharp))
            idx = parity + 2 * np.flatnonzero(sharp)
            p[idx] = 0.5 * (p[idx - 1] + p[idx + 1])
        if left == 0:
            return p, it + 1, 0
    return p, max_passes, left


def seed_figures(tool: np.ndarray, feed_mm_s: float, a_stage: float, step_mm: float) -> dict:
    """The documents' method on chords of ``step_mm``: their figures and what the stage and scanner would need."""
    seg = np.linalg.norm(np.diff(tool, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    m = max(3, int(math.ceil(s[-1] / step_mm)) + 1)
    q = np.linspace(0.0, s[-1], m)
    pts = np.stack([np.interp(q, s, tool[:, 0]), np.interp(q, s, tool[:, 1])], axis=1)
    dl = s[-1] / (m - 1)
    alpha_kr = math.pi - a_stage * dl / feed_mm_s**2
    s1, passes, left = seed_smooth(pts, alpha_kr)
    s2 = pts - s1
    h1 = np.linalg.norm(np.diff(s1, axis=0), axis=1)
    h2 = np.linalg.norm(np.diff(s2, axis=0), axis=1)
    hs = np.where(h1 + h2 > 0, h1 + h2, 1.0)
    v1, v2 = feed_mm_s * h1 / hs, feed_mm_s * h2 / hs  # the paper's scalar split (Vbig + Vsmall = Vc)
    t_paper = np.concatenate([[0.0], np.cumsum(hs / feed_mm_s)])
    dtp = np.diff(t_paper)[1:]
    a1p = np.abs(np.diff(v1)) / np.where(dtp > 0, dtp, np.inf)
    a2p = np.abs(np.diff(v2)) / np.where(dtp > 0, dtp, np.inf)
    dt_int = dl / feed_mm_s  # the intent: the tool at constant speed, one chord per dl / F
    a_stage_meas = np.linalg.norm(second_difference(s1, dt_int), axis=1)
    return {
        "step_mm": dl,
        "alpha_kr_deg": math.degrees(alpha_kr),
        "passes": passes,
        "sharp_left": left,
        "paper_time_s": float(t_paper[-1]),
        "paper_max_abig_mm_s2": float(a1p.max(initial=0.0)),
        "paper_max_asmall_mm_s2": float(a2p.max(initial=0.0)),
        "intent_time_s": float((m - 1) * dt_int),
        "intent_max_stage_accel_mm_s2": float(a_stage_meas.max()),
        "max_scanner_reach_mm": float(np.abs(s2).max()),
        "main": s1,
        "chords": pts,
    }


def plan_split(
    program: Program,
    machine: MachineConfig,
    method: str = "own",
    feed_mm_s: float | None = None,
    seed_step_mm: float = SEED_STEP_MM,
) -> SplitPlan:
    """Split ``program`` between the stage and the scanner (module docstring).

    Raises:
        PlanningError: no usable ``[scanner]``; the feed is above the stage's speed; the scanner would leave
            its field or limits (the place and the highest contour speed that fits are named).
    """
    if method not in ("own", "seed"):
        raise PlanningError(f"unknown split method {method!r}; methods: own, seed (none: the stage alone)")
    u_name, v_name = scanner_axes(machine)
    dt = machine.dt
    feed = float(feed_mm_s if feed_mm_s is not None else job_feed(program, machine))
    v_stage, a_stage, j_stage = _stage_limits(machine)
    if feed > v_stage:
        raise PlanningError(f"{program.file}: contour speed {feed:g} mm/s is above the stage's {v_stage:g} mm/s")
    m_cal, offset = calibration(machine)
    m_inv = np.linalg.inv(m_cal)
    half = half_field(machine)
    uv_home = np.array([machine.axis(n).home for n in (u_name, v_name)])
    c0 = offset + m_cal @ uv_home  # tool minus stage with the scanner at home
    tool_home = program_start(machine)[:2] + c0
    requested, lowered = feed, False
    for _ in range(40):
        tool, row, lit, length = tool_path(program, feed, dt)
        speed = length / ((tool.shape[0] - 1) * dt)
        if np.linalg.norm(tool[0] - tool_home) > 1e-12:  # the tool starts where stage and scanner stand
            n_in = int(math.ceil(np.linalg.norm(tool[0] - tool_home) / (speed * dt)))
            lead = tool_home + np.linspace(0.0, 1.0, n_in + 1)[:-1, None] * (tool[0] - tool_home)
            tool = np.concatenate([lead, tool])
            row, lit = (
                np.concatenate([np.full(n_in, -1), row]),
                np.concatenate([np.zeros(n_in, bool), lit]),
            )  # -1: no row yet
            length += float(np.linalg.norm(tool[n_in] - tool_home))
        stats: dict = {}
        if method == "own":
            main, w = lowpass_split(tool - c0, speed, a_stage, dt, j_stage)
            pad = w - 1
            stats["filter_ticks"] = w
        else:
            fig = seed_figures(tool, speed, a_stage, seed_step_mm)
            from scipy.interpolate import CubicSpline

            t_chord = np.linspace(0.0, (tool.shape[0] - 1) * dt, fig["main"].shape[0])
            t_tick = np.arange(tool.shape[0]) * dt
            main = CubicSpline(t_chord, fig["main"], bc_type="clamped")(t_tick) - c0
            pad = 0
            stats["seed"] = {k: v for k, v in fig.items() if k not in ("main", "chords")}
        full_tool = np.concatenate([np.repeat(tool[:1], pad, axis=0), tool, np.repeat(tool[-1:], pad, axis=0)])
        full_row = np.concatenate([np.repeat(row[:1], pad), row, np.repeat(row[-1:], pad)])
        full_lit = np.concatenate([np.zeros(pad, bool), lit, np.zeros(pad, bool)])
        scan = full_tool - main
        cmd = (scan - offset) @ m_inv.T
        reach = np.max(np.abs(cmd) / np.where(half > 0, half, 1e-300), axis=1)
        worst = int(np.argmax(reach))
        if reach[worst] <= 1.0 or method == "seed":
            break
        feed, lowered = speed * math.sqrt(1.0 / reach[worst]) * 0.98, True
    if method == "own" and reach[worst] > 1.0:  # pragma: no cover - the iteration converges
        raise PlanningError(f"{program.file}: no contour speed keeps the scanner in its field")
    if lowered:
        t0 = _first_over(program, machine, requested, m_inv, offset, half, a_stage, dt)
        raise PlanningError(t0 + f"; the highest contour speed that fits is {speed:.4g} mm/s ({speed * 60:.0f} mm/min)")
    stats.update(_scanner_checks(program, machine, cmd, full_tool, full_row, dt, speed))
    stats.update(
        requested_feed_mm_s=requested,
        max_scanner_reach_mm=float(np.abs(scan).max()),
        field_use=float(reach.max()),
        max_stage_accel_mm_s2=float(np.abs(second_difference(main, dt)).max()),
        max_stage_jerk_mm_s3=float(np.abs(third_difference(main, dt)).max()),
    )
    return SplitPlan(
        tick_hz=machine.tick_hz,
        tool=full_tool,
        main=main,
        scan=scan,
        cmd=cmd,
        lit=full_lit,
        row=full_row,
        feed_mm_s=speed,
        method=method,
        path_length_mm=length,
        stats=stats,
    )


def _where(program: Program, row: int, p: np.ndarray) -> str:
    return f"{program.file}:{program.line[max(row, 0)]}: at ({p[0]:.4g}, {p[1]:.4g})"


def _first_over(program, machine, feed, m_inv, offset, half, a_stage, dt) -> str:
    tool, row, _, _ = tool_path(program, feed, dt)
    main, w = lowpass_split(tool, feed, a_stage, dt)
    main = main - offset
    pad = w - 1
    full = np.concatenate([np.repeat(tool[:1], pad, axis=0), tool, np.repeat(tool[-1:], pad, axis=0)])
    rows = np.concatenate([np.repeat(row[:1], pad), row, np.repeat(row[-1:], pad)])
    cmd = ((full - main) - offset) @ m_inv.T
    reach = np.max(np.abs(cmd) / np.where(half > 0, half, 1e-300), axis=1)
    k = int(np.argmax(reach))
    sc = machine.scanner
    return (
        f"{_where(program, int(rows[k]), full[k])}: at {feed:.4g} mm/s ({feed * 60:.0f} mm/min) the scanner would "
        f"reach {np.abs(cmd[k]).max():.4g} mm, outside its {sc.field_mm[0]:g} x {sc.field_mm[1]:g} mm field"
    )


def _scanner_checks(program, machine, cmd, tool, row, dt, speed) -> dict:
    """The scanner axes' speed, acceleration (and jerk, when limited) against their limits; an error naming the
    place otherwise."""
    out = {}
    for j, name in enumerate(machine.scanner.axes[:2]):
        ax = machine.axis(name)
        v = np.abs(first_difference(cmd[:, j : j + 1], dt))[:, 0]
        a = np.abs(second_difference(cmd[:, j : j + 1], dt))[:, 0]
        measured = [("speed", v, ax.v_max), ("acceleration", a, ax.a_max)]
        if ax.j_max is not None:
            measured.append(("jerk", np.abs(third_difference(cmd[:, j : j + 1], dt))[:, 0], ax.j_max))
        for what, x, lim in measured:
            k = int(np.argmax(x))
            if x[k] > lim * (1 - MARGIN / 2):
                ok = speed * lim / x[k] * 0.98
                raise PlanningError(
                    f"{_where(program, int(row[k]), tool[k])}: scanner axis {name} needs {what} {x[k]:.4g} "
                    f"(limit {lim:g}) at {speed:.4g} mm/s; try a contour speed of {ok:.4g} mm/s or less"
                )
        out[f"max_{name}_speed_mm_s"], out[f"max_{name}_accel_mm_s2"] = float(v.max()), float(a.max())
    return out
