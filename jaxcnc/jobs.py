"""Jobs: any supported input, planned on a machine into a verified table, with its report.

This is what ``jaxcnc plan`` and ``jaxcnc check`` do, as a library: the command line only parses its
arguments and prints. The input's front end comes from its suffix (:mod:`jaxcnc.front_ends`: G-code,
point files for pulsed engraving, plug-ins); a program on a machine whose laser is pulsed is a point
job too (every G1 end point burned by one pulse). A job goes through four stages — parse, plan, ticks,
verify — shown by a progress bar on a terminal; verification is independent of the planner: the
table's limits at every tick (:mod:`jaxcnc.ticks.verify`), every tick's distance from the programmed
path (:mod:`jaxcnc.ticks.deviation`) and, for pulsed jobs, the pulses (:mod:`jaxcnc.ticks.verify_pulses`).

>>> report = plan_file("part.ngc", "machine.toml", "part.ticks")   # doctest: +SKIP
>>> report["total_time_s"], report["violations"]                     # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from jaxcnc.errors import JaxcncError, SourceError
from jaxcnc.front_ends import GCODE_SUFFIXES, POINT_SUFFIXES, front_end_for  # noqa: F401  (part of this API)
from jaxcnc.machine import MachineConfig, load_machine
from jaxcnc.memory import release_free_heap
from jaxcnc.program import PointJob, Program

if TYPE_CHECKING:
    from jaxcnc.format import TableFile

STAGES = ("parse", "plan", "ticks", "verify")


@dataclass(frozen=True)
class JobBounds:
    """How large a job's table may be: a job beyond any bound is refused before anything is planned (on a lower
    bound of its duration, naming the block that crosses it) and again before anything is written (on the plan).

    The defaults let a day-long job at 10 kHz on a three-axis machine through (8.6e8 ticks, ~21 GB) and refuse the
    runaways of a slow feed or a long dwell (``G1 X10 F0.001`` would be 6.9 days, 144 GB; ``G4 P1e7`` 116 days).
    Raise them with ``jaxcnc plan --max-ticks/--max-bytes/--max-duration`` or ``plan_file(bounds=JobBounds(...))``.

    Attributes:
        max_ticks: rows of the table (1e9 by default).
        max_bytes: size of the table file, positions and the fine channel (32 GiB by default).
        max_duration_s: the job's duration in seconds (24 h by default).
    """

    max_ticks: int = 1_000_000_000
    max_bytes: int = 32 * 2**30
    max_duration_s: float = 24 * 3600.0

    def __post_init__(self) -> None:
        for name in ("max_ticks", "max_bytes", "max_duration_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise JaxcncError(f"job bound {name} = {v!r}: must be a positive finite number")


DEFAULT_BOUNDS = JobBounds()


def table_bytes(n_rows: int, n_axes: int) -> int:
    """The size in bytes of a table of ``n_rows`` rows and ``n_axes`` axes (positions and the fine channel, whole
    blocks, the header page), without its events: what :class:`~jaxcnc.format.TableWriter` allocates."""
    from jaxcnc.format.tablefile import DEFAULT_BLOCK_ROWS

    blocks = -(-int(n_rows) // DEFAULT_BLOCK_ROWS)
    return 4096 + blocks * (DEFAULT_BLOCK_ROWS * n_axes * 4 * 2 + 8)


def _fmt_bytes(n: float) -> str:
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n:.0f} B"


def _fmt_s(t: float) -> str:
    if t >= 2 * 86400:
        return f"{t:.4g} s ({t / 86400:.3g} days)"
    if t >= 3600:
        return f"{t:.4g} s ({t / 3600:.3g} h)"
    return f"{t:.4g} s"


def _limits_s(machine: MachineConfig, bounds: JobBounds) -> list[tuple[float, str]]:
    """Each bound as the longest duration (s) it allows on ``machine``, with its option and value."""
    from jaxcnc.format.tablefile import DEFAULT_BLOCK_ROWS

    n_axes = len(machine.axes)
    blocks = max(0, bounds.max_bytes - 4096) // (DEFAULT_BLOCK_ROWS * n_axes * 8 + 8)
    rows_by_bytes = blocks * DEFAULT_BLOCK_ROWS
    hz = machine.tick_hz
    return [
        (bounds.max_duration_s, f"--max-duration {_fmt_s(bounds.max_duration_s)}"),
        (
            (bounds.max_ticks - 1) / hz,
            f"--max-ticks {bounds.max_ticks:,} ({(bounds.max_ticks - 1) / hz:.4g} s at {hz:g} Hz)",
        ),
        (
            max(rows_by_bytes - 1, 0) / hz,
            f"--max-bytes {_fmt_bytes(bounds.max_bytes)} ({max(rows_by_bytes - 1, 0) / hz:.4g} s of {n_axes}-axis "
            f"table at {hz:g} Hz)",
        ),
    ]


def _beyond(total_s: float, machine: MachineConfig, bounds: JobBounds) -> list[str]:
    return [what for limit, what in _limits_s(machine, bounds) if total_s > limit]


def check_program_bounds(program: Program, machine: MachineConfig, bounds: JobBounds = DEFAULT_BOUNDS) -> None:
    """Refuse a program whose table would exceed ``bounds``, before it is planned.

    A lower bound of each row's time: its chord (no path is shorter) at its feed (the programmed one, the
    machine's default, or the rapid cap for G0; the plan never goes faster), or its dwell. When their running sum
    passes the tightest bound, the row where it does is named (``file:line``) with the bounds it breaks.
    """
    from jaxcnc.program import Kind

    if len(program) == 0:
        return
    moving = program.is_motion
    chord = np.linalg.norm(program.end - program.start, axis=1)
    speed = np.where(
        program.rapid, machine.path.rapid, np.where(np.isnan(program.feed), machine.path.feed, program.feed)
    )
    with np.errstate(over="ignore", invalid="ignore"):
        move_s = np.where(moving, chord / speed, 0.0)
        dwell_s = np.where(program.kind == Kind.DWELL, program.dwell_s, 0.0)
        row_s = move_s + dwell_s
        total = np.cumsum(row_s)
    limit = min(lim for lim, _ in _limits_s(machine, bounds))
    if not total[-1] > limit:
        return
    k = int(np.argmax(total > limit))
    if program.kind[k] == Kind.DWELL:
        what = f"a dwell of {_fmt_s(float(dwell_s[k]))}"
    else:
        what = f"{chord[k]:.4g} mm at {speed[k]:.3g} mm/s, at least {_fmt_s(float(move_s[k]))}"
    beyond = _beyond(float(total[-1]) if math.isfinite(total[-1]) else math.inf, machine, bounds)
    raise SourceError(
        program.file,
        int(program.line[k]),
        0,
        f"the job would last at least {_fmt_s(float(total[k]))} up to this block ({what}), beyond "
        f"{'; '.join(beyond)}: refused before anything is planned or written (raise the bound if it is meant)",
    )


def _check_points_bounds(job: PointJob, machine: MachineConfig, bounds: JobBounds) -> None:
    """A point job lasts at least one shortest pulse period per interval between its points: refused before
    planning when that passes a bound (naming the point where it does)."""
    from jaxcnc.planners.pulsed import pulse_window

    period = pulse_window(machine).shortest_period_s
    limit = min(lim for lim, _ in _limits_s(machine, bounds))
    if (len(job) - 1) * period <= limit:
        return
    k = int(limit // period) + 1
    total = (len(job) - 1) * period
    raise SourceError(
        job.file,
        int(job.line[k]),
        0,
        f"{len(job):,} points burn for at least {_fmt_s(total)} ({_fmt_s(period)} per point at the lamp's shortest "
        f"period), beyond {'; '.join(_beyond(total, machine, bounds))}: refused before anything is planned or "
        "written (raise the bound if it is meant)",
    )


def check_planned_bounds(
    file: str, n_rows: int, total_time_s: float, machine: MachineConfig, bounds: JobBounds = DEFAULT_BOUNDS
) -> None:
    """Refuse a planned job whose table (``n_rows`` rows, ``total_time_s`` s) exceeds ``bounds``, before it is
    written."""
    size = table_bytes(n_rows, len(machine.axes))
    broken = []
    if total_time_s > bounds.max_duration_s:
        broken.append(f"--max-duration {_fmt_s(bounds.max_duration_s)}")
    if n_rows > bounds.max_ticks:
        broken.append(f"--max-ticks {bounds.max_ticks:,}")
    if size > bounds.max_bytes:
        broken.append(f"--max-bytes {_fmt_bytes(bounds.max_bytes)}")
    if broken:
        raise JaxcncError(
            f"{file}: the planned job lasts {_fmt_s(total_time_s)} = {n_rows:,} ticks, a table of "
            f"{_fmt_bytes(size)}: beyond {'; '.join(broken)}; nothing was written (raise the bound if it is meant)"
        )


#: Tables of at least this many rows hand the C heap's free pages back between stages
#: (:func:`~jaxcnc.memory.release_free_heap`): the 1 M-block contour's checks started ~200 MB lower.
TRIM_ROWS = 1 << 22


class Stages:
    """Times the stages of a job and shows them as a progress bar (``progress``: ``None`` = on a terminal)."""

    def __init__(self, progress: bool | None, label: str):
        from tqdm.auto import tqdm

        self.seconds: dict[str, float] = {}
        self._bar = tqdm(
            total=len(STAGES), desc=label, unit="stage", leave=False, disable=progress is False if progress is not None
            else None, bar_format="{desc}: {n_fmt}/{total_fmt} stages [{elapsed}] {postfix}",
        )  # fmt: skip

    @contextmanager
    def stage(self, name: str):
        self._bar.set_postfix_str(name)
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = time.perf_counter() - t0
            self._bar.update(1)

    def close(self) -> None:
        self._bar.close()


def _machine(machine: MachineConfig | str | Path) -> MachineConfig:
    return machine if isinstance(machine, MachineConfig) else load_machine(machine)


def source_options(dialect: str | None = None, input_options: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The options a front end reads its input with (``dialect`` is one of them), those set only. Tables record
    them (header ``source_options``) so that ``check`` reads the source again as it was planned."""
    given = {k: v for k, v in (input_options or {}).items() if v is not None}
    if dialect is not None:
        given["dialect"] = dialect
    return given


def load_program(
    path: str | Path,
    machine: MachineConfig,
    dialect: str | None = None,
    input_options: Mapping[str, Any] | None = None,
) -> Program:
    """The contour program in ``path`` (G-code, or any front end that produces a
    :class:`~jaxcnc.program.Program`), starting where the machine is homed.

    ``input_options``: the front end's options (drawings: :class:`~jaxcnc.io.drawing.DrawingOptions` fields such
    as ``allow_open`` or ``lead_in_mm``); one the front end does not take is an error."""
    path = Path(path)
    fe = front_end_for(path)
    if fe.produces != "program":
        raise JaxcncError(f"{path}: a {fe.name} holds points, not a program; it is planned as a point job")
    return fe.load(path, machine, **source_options(dialect, input_options))


def is_point_job(input_path: str | Path, machine: MachineConfig) -> bool:
    """Point-by-point pulsed engraving: a point file, or a program on a machine whose laser is pulsed."""
    return front_end_for(input_path).produces == "points" or machine.laser.mode == "pulsed"


def load_point_job(
    input_path: str | Path,
    machine: MachineConfig,
    dialect: str | None = None,
    allow_repeats: bool = False,
    input_options: Mapping[str, Any] | None = None,
) -> PointJob:
    """The points of a point job: read from a point file, or the G1 end points of a program.

    ``allow_repeats``: the user asks for repeated burns (a point given twice is burned twice); otherwise such a
    job is refused when planned, naming both lines.
    """
    from jaxcnc.io.points import points_from_program

    input_path = Path(input_path)
    fe = front_end_for(input_path)
    options = source_options(dialect, input_options)
    if fe.produces == "points":
        job = fe.load(input_path, machine, **options)
    else:
        job = points_from_program(fe.load(input_path, machine, **options))
    return dataclasses.replace(job, allow_repeats=True) if allow_repeats else job


def plan_file(
    input_path: str | Path,
    machine: MachineConfig | str | Path,
    out: str | Path,
    planner: str | None = None,
    progress: bool | None = None,
    dialect: str | None = None,
    reorder: bool = False,
    split: str | None = None,
    kinematics: str | Path | None = None,
    split_plot: str | Path | None = None,
    bounds: JobBounds = DEFAULT_BOUNDS,
    allow_repeats: bool = False,
    input_options: Mapping[str, Any] | None = None,
    shaping: Mapping[str, Any] | None = None,
) -> dict:
    """Plan ``input_path`` on the machine, write and verify the table at ``out``; the report dict.

    ``input_options``: the front end's options (:func:`load_program`), recorded in the table's header.
    ``shaping``: input shaping and/or speed-band avoidance of a contour job (:func:`plan_dynamic_file`: ``shaper``
    and the options of :func:`jaxcnc.dynamics.shaped.plan_dynamic`).

    On a machine with a ``[scanner]`` a contour job is split between stage and scanner (``split``: ``own``
    by default, ``seed``, or ``none`` for the stage alone; :func:`plan_split_file`). ``bounds``: how large the
    table may be (:class:`JobBounds`; a job beyond them is refused before anything is written).
    ``allow_repeats``: point jobs burn a point given twice twice instead of refusing it.
    """
    machine = _machine(machine)
    if is_point_job(input_path, machine):
        if shaping is not None:
            raise JaxcncError("shaping and speed bands apply to contour jobs, not point-by-point pulsed ones")
        if split not in (None, "none"):
            raise JaxcncError("--split applies to contour jobs, not point-by-point pulsed ones")
        return plan_points_file(
            input_path,
            machine,
            out,
            planner,
            progress,
            dialect,
            reorder,
            bounds=bounds,
            allow_repeats=allow_repeats,
            input_options=input_options,
        )
    if allow_repeats:
        raise JaxcncError("--allow-repeats applies to point-by-point jobs (point files or pulsed machines)")
    if shaping is not None:
        if (machine.scanner is not None and split != "none") or kinematics or split_plot:
            raise JaxcncError(
                "shaping and speed bands plan the stage alone: not a stage + scanner split (pass --split none on a "
                "machine with a [scanner]; no --kinematics or --split-plot)"
            )
        rest = dict(shaping)
        return plan_dynamic_file(
            input_path,
            machine,
            out,
            rest.pop("shaper", None),
            progress=progress,
            dialect=dialect,
            input_options=input_options,
            bounds=bounds,
            planner=planner,
            **rest,
        )
    if reorder:
        raise JaxcncError("--reorder applies to point-by-point jobs (point files or pulsed machines)")
    if machine.galvo is not None and machine.galvo.stage:
        if split not in (None, "none") or kinematics or split_plot:
            raise JaxcncError("a stage + galvo machine ([galvo] axes) runs M170/M171 sections, not a split")
        return plan_external_file(
            input_path, machine, out, planner, progress, dialect, bounds=bounds, input_options=input_options
        )
    if split not in (None, "none"):
        if machine.scanner is None:
            raise JaxcncError(f"--split {split}: machine {machine.name!r} has no [scanner] section")
    if machine.scanner is not None and split != "none":
        return plan_split_file(
            input_path,
            machine,
            out,
            split or "own",
            progress,
            dialect,
            kinematics,
            split_plot,
            bounds=bounds,
            input_options=input_options,
        )
    if kinematics or split_plot:
        raise JaxcncError("--kinematics and --split-plot belong to stage + scanner split jobs")
    return plan_program_file(
        input_path, machine, out, planner, progress, dialect, bounds=bounds, input_options=input_options
    )


@dataclass
class _Run:
    """What :func:`_run_stages` did: the program read, what the planner made, the written table, what the
    verification found, and the seconds of each stage."""

    program: Program
    planned: Any
    table: TableFile
    checked: Any
    seconds: dict[str, float]

    @property
    def plan_wall_s(self) -> float:
        """Parse, plan and ticks: what a user waits for before the table exists."""
        return self.seconds["parse"] + self.seconds["plan"] + self.seconds["ticks"]


def _run_stages(
    input_path: str | Path,
    machine: MachineConfig,
    out: str | Path,
    label: str,
    progress: bool | None,
    options: dict[str, Any],
    bounds: JobBounds,
    plan: Callable[[Program], Any],
    size: Callable[[Any], tuple[int, float]],
    write: Callable[[Any, Program], Any],
    verify: Callable[[TableFile, Program], Any],
    keep: Callable[[Any], Any] | None = None,
) -> _Run:
    """The way every contour job goes — parse, plan, ticks, verify — as timed stages under one progress bar:
    the source read with ``options``; ``plan(program)``; the table's size (``size(planned)``: rows, seconds)
    held to ``bounds`` before anything is written; ``write(planned, program)`` writes ``out``;
    ``verify(table, program)`` checks it. ``keep(planned)``: what the caller needs of the plan once the table is
    written (:attr:`_Run.planned`), made before the checks so that the plan is freed under them (they read the
    table and the program alone: a 1 M-block contour's spans and time law, ~1 GB, are not held twice as long)."""
    from jaxcnc.format import TableFile
    from jaxcnc.jitcache import release_when_crowded

    release_when_crowded()  # a long-lived process: the programs of earlier jobs, before the limit on mappings
    st = Stages(progress, label)
    try:
        with st.stage("parse"):
            program = load_program(input_path, machine, input_options=options)
            check_program_bounds(program, machine, bounds)
        with st.stage("plan"):
            planned = plan(program)
            n_rows, total_s = size(planned)
            check_planned_bounds(str(input_path), n_rows, total_s, machine, bounds)
        if n_rows >= TRIM_ROWS:
            release_free_heap()  # what planning freed, before the tick stage's windows
        with st.stage("ticks"):
            write(planned, program)
        if keep is not None:
            planned = keep(planned)
        if n_rows >= TRIM_ROWS:
            release_free_heap()  # the tick stage's windows, before the checks build theirs
        with st.stage("verify"):
            table = TableFile(out)
            checked = verify(table, program)
    finally:
        st.close()
    return _Run(program, planned, table, checked, dict(st.seconds))


def plan_split_file(
    input_path: str | Path,
    machine: MachineConfig,
    out: str | Path,
    method: str = "own",
    progress: bool | None = None,
    dialect: str | None = None,
    kinematics: str | Path | None = None,
    split_plot: str | Path | None = None,
    bounds: JobBounds = DEFAULT_BOUNDS,
    input_options: Mapping[str, Any] | None = None,
) -> dict:
    """Split a contour job between stage and scanner (:mod:`jaxcnc.planners.split`), write and check its
    table (every axis' limits, the field, the tool point); the per-tick CSV and the picture on request."""
    from jaxcnc.planners.split import plan_split
    from jaxcnc.ticks.split import check_split, kinematic_csv, plot_split, write_split_table
    from jaxcnc.ticks.verify import measure_table

    options = source_options(dialect, input_options)
    run = _run_stages(
        input_path, machine, out, f"splitting {Path(input_path).name}", progress, options, bounds,
        plan=lambda program: plan_split(program, machine, method),
        size=lambda plan: (plan.n_ticks, plan.total_time_s),
        write=lambda plan, program: write_split_table(plan, program, machine, out, source_options=options),
        verify=lambda table, program: (measure_table(table, machine), check_split(table, machine, program)),
    )  # fmt: skip
    plan, program, table, (meas, chk) = run.planned, run.program, run.table, run.checked
    if kinematics:
        kinematic_csv(plan, kinematics)
    if split_plot:
        plot_split(plan, machine, split_plot)
    return {
        "input": str(input_path),
        "machine": machine.name,
        "table": str(out),
        "planner": f"split-{method}",
        "split": method,
        "total_time_s": plan.total_time_s,
        "n_blocks": program.n_blocks,
        "n_ticks": plan.n_ticks,
        "tick_hz": machine.tick_hz,
        "path_length_mm": plan.path_length_mm,
        "feed_mm_s": plan.feed_mm_s,
        "plan_wall_s": run.plan_wall_s,
        "timings_s": run.seconds,
        **measured(meas),
        "max_path_deviation_mm": chk.max_tool_deviation_mm,
        "path_tolerance_mm": table.header.discrete_mm,
        "field_use": chk.max_field_use,
        "split_stats": {k: v for k, v in plan.stats.items() if not isinstance(v, dict)},
        "seed_figures": plan.stats.get("seed"),
        "limits": limits(machine),
        "violations": [str(v) for v in meas.violations] + chk.violations,
    }


def plan_external_file(
    input_path: str | Path,
    machine: MachineConfig,
    out: str | Path,
    planner: str | None = None,
    progress: bool | None = None,
    dialect: str | None = None,
    bounds: JobBounds = DEFAULT_BOUNDS,
    input_options: Mapping[str, Any] | None = None,
) -> dict:
    """Plan a program on a stage + galvo machine: stage and scanner sections switched by M170 / M171 (the
    external motion module, :mod:`jaxcnc.ticks.external`); write the joined table and verify it (every axis'
    limits, the tool point, the stage at rest while the scanner runs)."""
    from jaxcnc.jaxconfig import configure_jax

    configure_jax()
    from jaxcnc.ticks.external import check_external, plan_external, write_external_table
    from jaxcnc.ticks.verify import measure_table

    options = source_options(dialect, input_options)
    run = _run_stages(
        input_path, machine, out, f"planning {Path(input_path).name}", progress, options, bounds,
        plan=lambda program: plan_external(program, machine, planner),
        size=lambda plan: (plan.n_ticks, plan.total_time_s),
        write=lambda plan, program: write_external_table(plan, program, machine, out, source_options=options),
        verify=lambda table, program: (measure_table(table, machine), check_external(table, machine, program)),
    )  # fmt: skip
    plan, program, table, (meas, chk) = run.planned, run.program, run.table, run.checked
    return {
        "input": str(input_path),
        "machine": machine.name,
        "table": str(out),
        "planner": "external",
        "total_time_s": plan.total_time_s,
        "n_blocks": program.n_blocks,
        "n_ticks": plan.n_ticks,
        "tick_hz": machine.tick_hz,
        "path_length_mm": plan.path_length_mm,
        "sections": [[int(s.scanner), s.first_tick, s.last_tick] for s in plan.sections],
        "plan_wall_s": run.plan_wall_s,
        "timings_s": run.seconds,
        **measured(meas),
        "max_path_deviation_mm": chk.max_tool_deviation_mm,
        "path_tolerance_mm": machine.path.corner_tol_mm + table.header.discrete_mm,
        "limits": limits(machine),
        "violations": [str(v) for v in meas.violations] + chk.violations,
    }


def measured(meas) -> dict:
    """Per-axis maxima measured on a table, for a report."""
    return {"max_abs_v": meas.max_abs_v, "max_abs_a": meas.max_abs_a, "max_abs_j": meas.max_abs_j}


def limits(machine: MachineConfig) -> dict:
    """The machine's per-axis limits, for a report."""
    return {a.name: {"v_max": a.v_max, "a_max": a.a_max, "j_max": a.j_max} for a in machine.axes}


def plan_program_file(
    input_path: str | Path,
    machine: MachineConfig,
    out: str | Path,
    planner: str | None = None,
    progress: bool | None = None,
    dialect: str | None = None,
    bounds: JobBounds = DEFAULT_BOUNDS,
    input_options: Mapping[str, Any] | None = None,
) -> dict:
    """Plan a contour program (G-code, a drawing), write its table and verify it (limits, the path); the report.

    ``bounds``: refused before anything is planned or written when the table would exceed them."""
    from jaxcnc.jaxconfig import configure_jax

    configure_jax()  # float64 and the persistent compile cache
    from jaxcnc.planners import plan_job
    from jaxcnc.planners.job import machine_planner
    from jaxcnc.ticks.deviation import path_deviation
    from jaxcnc.ticks.table import write_table
    from jaxcnc.ticks.verify import measure_table

    planner = planner or machine_planner(machine)
    options = source_options(dialect, input_options)
    run = _run_stages(
        input_path, machine, out, f"planning {Path(input_path).name}", progress, options, bounds,
        plan=lambda program: plan_job(program, machine, planner=planner),
        size=lambda job: (job.plan.n_ticks + 1, job.plan.total_time_s),
        write=lambda job, _: write_table(job, out, progress=progress, planner=planner, source_options=options),
        verify=lambda table, program: (measure_table(table, machine), path_deviation(table, machine, program)),
        keep=lambda job: {  # what the report needs of the job: the job itself is freed before the checks
            "total_time_s": job.plan.total_time_s,
            "n_spans": len(job.spans),
            "n_ticks": job.plan.n_ticks + 1,
            "path_length_mm": job.path_length_mm,
            "exact_corners": job.exact_corners,
        },
    )  # fmt: skip
    job, program, table, (meas, path) = run.planned, run.program, run.table, run.checked
    return {
        "input": str(input_path),
        "machine": machine.name,
        "table": str(out),
        "planner": planner,
        "total_time_s": job["total_time_s"],
        "n_blocks": program.n_blocks,
        "n_spans": job["n_spans"],
        "n_ticks": job["n_ticks"],
        "tick_hz": machine.tick_hz,
        "path_length_mm": job["path_length_mm"],
        "corners_kept_exact": job["exact_corners"],
        "plan_wall_s": run.plan_wall_s,
        "timings_s": run.seconds,
        **measured(meas),
        "max_path_deviation_mm": path.max_mm,
        "path_tolerance_mm": path.max_tol_mm,
        "limits": limits(machine),
        "violations": [str(v) for v in meas.violations + path.violations],
        **_dynamics_entry(table, machine),
    }


def _dynamics_entry(table: TableFile, machine: MachineConfig) -> dict:
    """``{"dynamics": ...}``: the simulated axes' figures when the machine has modes (issue 20), else nothing."""
    if not any(a.modes for a in machine.axes):
        return {}
    from jaxcnc.dynamics.simulate import simulate_table

    return {"dynamics": simulate_table(table, machine).summary()}


def plan_dynamic_file(
    input_path: str | Path,
    machine: MachineConfig | str | Path,
    out: str | Path,
    shaper: str | None = None,
    *,
    progress: bool | None = None,
    dialect: str | None = None,
    simulate: bool = True,
    input_options: Mapping[str, Any] | None = None,
    bounds: JobBounds = DEFAULT_BOUNDS,
    **options: Any,
) -> dict:
    """Plan a contour file with input shaping and/or speed-band avoidance (issue 20; ``shaper`` and ``options``
    as :func:`jaxcnc.dynamics.shaped.plan_dynamic` takes them), write the table, check it (limits at every tick,
    the path against the *given* program within the contour error shaping is allowed) and, when the machine has
    modes, simulate it (:func:`jaxcnc.dynamics.simulate.simulate_table`); the report. The source is read with
    ``input_options`` and ``bounds`` hold as for :func:`plan_file`."""
    from jaxcnc.dynamics.shaped import plan_dynamic, write_dynamic_table
    from jaxcnc.jaxconfig import configure_jax
    from jaxcnc.ticks.deviation import path_deviation
    from jaxcnc.ticks.verify import measure_table

    configure_jax()
    machine = _machine(machine)
    input_path = Path(input_path)
    if front_end_for(input_path).produces != "program":
        name = front_end_for(input_path).name
        raise JaxcncError(f"{input_path}: shaping and speed bands apply to contour programs, not {name} points")
    opts = source_options(dialect, input_options)

    def size(dp) -> tuple[int, float]:
        return dp.sampler.n_rows, (dp.sampler.n_rows - 1) / machine.tick_hz

    run = _run_stages(
        input_path, machine, out, f"planning {input_path.name} (shaped)", progress, opts, bounds,
        plan=lambda program: plan_dynamic(program, machine, shaper, **options),
        size=size,
        write=lambda dp, program: write_dynamic_table(dp, program, out, progress, source_options=opts),
        verify=lambda table, program: (measure_table(table, machine), path_deviation(table, machine, program)),
    )  # fmt: skip
    dp, program, table, (meas, path) = run.planned, run.program, run.table, run.checked
    wall = run.plan_wall_s
    report = {
        "input": str(input_path),
        "machine": machine.name,
        "table": str(out),
        "planner": table.header.meta.get("planner"),
        "total_time_s": (table.header.n_rows - 1) / machine.tick_hz,
        "unshaped_time_s": dp.job.plan.total_time_s,
        "n_blocks": program.n_blocks,
        "n_ticks": table.header.n_rows,
        "tick_hz": machine.tick_hz,
        "path_length_mm": dp.job.path_length_mm,
        "plan_wall_s": wall,
        "max_abs_v": meas.max_abs_v,
        "max_abs_a": meas.max_abs_a,
        "max_abs_j": meas.max_abs_j,
        "max_path_deviation_mm": path.max_mm,
        "path_tolerance_mm": path.max_tol_mm,
        "violations": [str(v) for v in meas.violations + path.violations],
    }
    if dp.shapers:
        sh = next(iter(dp.shapers.values()))
        report["shaping"] = {
            "shapers": {a: [s.name, s.f_hz, s.zeta] for a, s in dp.shapers.items()},
            "duration_s": max(s.duration_s for s in dp.shapers.values()),
            "hold_ticks": int(dp.sampler.hold),
            "rest_points": int(dp.sampler.rest.size),
            "extra_s": dp.sampler.extra_s,
            "stops_added": dp.n_stops_added,
            "arc_feed_caps": dp.n_feed_caps,
            "contour_tol_mm": dp.tol_mm,
            "vibration_at_design": float(sh.vibration(sh.f_hz, sh.zeta)),
        }
    if dp.bands is not None:
        report["speed_bands"] = {"bands_mm_s": dp.bands.bands.tolist(), "rows_slowed": dp.bands.n_rows_slowed}
    if simulate:
        report.update(_dynamics_entry(table, machine))
    return report


def plan_points_file(
    input_path: str | Path,
    machine: MachineConfig,
    out: str | Path,
    planner: str | None = None,
    progress: bool | None = None,
    dialect: str | None = None,
    reorder: bool = False,
    bounds: JobBounds = DEFAULT_BOUNDS,
    allow_repeats: bool = False,
    input_options: Mapping[str, Any] | None = None,
) -> dict:
    """Plan a point-by-point pulsed job, write its table and verify it; the report (with the comparisons).

    ``bounds``: refused before anything is planned or written when the table would exceed them;
    ``allow_repeats``: burn a point given twice twice (else refused, naming both lines)."""
    from jaxcnc.jaxconfig import configure_jax

    configure_jax()  # float64 and the persistent compile cache
    from jaxcnc.format import TableFile
    from jaxcnc.planners.pulsed import DEFAULT_PULSE_PLANNER, plan_points
    from jaxcnc.planners.pulsed.reorder import serpentine_order
    from jaxcnc.ticks.pulses import write_pulse_table
    from jaxcnc.ticks.verify import measure_table
    from jaxcnc.ticks.verify_pulses import check_pulses

    planner = planner or machine.planner or DEFAULT_PULSE_PLANNER
    st = Stages(progress, f"planning {Path(input_path).name}")
    try:
        with st.stage("parse"):
            options = source_options(dialect, input_options)
            given = load_point_job(input_path, machine, allow_repeats=allow_repeats, input_options=options)
            _check_points_bounds(given, machine, bounds)
        with st.stage("plan"):
            job = given.take(serpentine_order(given.points)) if reorder else given
            planned = plan_points(job, machine, planner)
            traj = planned.plan.trajectory
            check_planned_bounds(str(input_path), traj.n_ticks + 1, traj.total_time_s, machine, bounds)
        with st.stage("ticks"):
            write_pulse_table(planned, out, progress=progress, source_options=options)
        with st.stage("verify"):
            table = TableFile(out)
            meas = measure_table(table, machine)
            pulses = check_pulses(table, machine, given)
    finally:
        st.close()
    t = st.seconds
    plan = planned.plan
    old = plan_points(job, machine, "stop-and-go").plan if planner != "stop-and-go" else plan
    report = {
        "input": str(input_path),
        "machine": machine.name,
        "table": str(out),
        "planner": planner,
        "n_points": len(job),
        "n_pulses": plan.n_pulses,
        "n_idle_pulses": int(plan.idle_tick.shape[0]),
        "total_time_s": plan.trajectory.total_time_s,
        "burn_time_s": plan.burn_time_s,
        "lower_bound_s": planned.lower_bound_s,
        "lower_bound_travel_s": planned.lower_bound_travel_s,
        "stop_and_go_s": old.burn_time_s,
        "ratio_to_lower_bound": plan.burn_time_s / planned.lower_bound_s if planned.lower_bound_s > 0 else None,
        "reduction_vs_stop_and_go": 1.0 - plan.burn_time_s / old.burn_time_s if old.burn_time_s > 0 else 0.0,
        "n_ticks": plan.trajectory.n_ticks + 1,
        "tick_hz": machine.tick_hz,
        "pulse_hz": planned.window.pulse_hz,
        "pulse_window_ticks": [planned.window.n_min, planned.window.n_max],
        "path_length_mm": float(np.sum(np.linalg.norm(np.diff(job.points, axis=0), axis=1))),
        "plan_wall_s": t["parse"] + t["plan"] + t["ticks"],
        "timings_s": {**t, "plan": planned.plan_wall_s},
        "planner_stats": plan.stats,
        **measured(meas),
        "max_miss_mm": pulses.max_miss_mm,
        "limits": limits(machine),
        "violations": [str(v) for v in meas.violations + pulses.violations],
    }
    if reorder:
        report["as_given_burn_time_s"] = plan_points(given, machine, planner).plan.burn_time_s
    return report


def check_table(
    table_path: str | Path,
    machine: MachineConfig | str | Path,
    points: str | Path | None = None,
    program: str | Path | None = None,
    dialect: str | None = None,
):
    """Verify a table: checksums, limits, travel, the path and, for pulsed tables, pulses. ``(table, measurement)``.

    The measurement's violations include the pulse and path problems; its ``pulses`` attribute holds the
    pulse check (``None`` for tables without work pulses), ``path`` the distances from the programmed
    path (``None`` when not compared; ``path_note`` says why: no G-code source, or it is not here).
    """
    from jaxcnc.format import EventKind, TableFile
    from jaxcnc.ticks.deviation import path_deviation
    from jaxcnc.ticks.verify import measure_table

    machine = _machine(machine)
    table = TableFile(table_path)  # verifies every checksum
    meas = measure_table(table, machine)
    from jaxcnc.ticks.verify_laser import check_laser

    meas.laser = check_laser(table, machine)  # the power channel, tick by tick
    if meas.laser is not None:
        meas.violations.extend(meas.laser.violations)
    if np.any(table.events["kind"] == EventKind.WORK_PULSE):
        from jaxcnc.ticks.verify_pulses import check_pulses

        job = points_of_table(table, machine, points)
        meas.pulses = check_pulses(table, machine, job)
        meas.violations.extend(meas.pulses.violations)
    prog, meas.path_note = program_for_table(table, machine, Path(program) if program else None, dialect)
    if prog is not None and table.header.meta.get("split") and machine.scanner is not None:
        from jaxcnc.ticks.split import check_split  # stage + scanner: the tool point is main + scanner

        chk = check_split(table, machine, prog)
        meas.path_summary = (
            f"stage + scanner: tool point within {chk.max_tool_deviation_mm:.3g} mm of the program at every tick "
            f"(allowed one discrete), scanner at most {100 * chk.max_field_use:.1f} % of its field"
        )
        meas.violations.extend(chk.violations)
    elif prog is not None and table.header.meta.get("external") and machine.galvo is not None:
        from jaxcnc.ticks.external import check_external  # stage + galvo: the tool point is stage + beam

        ext = check_external(table, machine, prog)
        meas.path_summary = (
            f"stage + galvo: tool point within {ext.max_tool_deviation_mm:.3g} mm of the program at every tick, "
            f"stage still while the scanner runs (moved {ext.max_stage_motion_in_scanner_mm:.3g} mm)"
        )
        meas.violations.extend(ext.violations)
    elif prog is not None:
        meas.path = path_deviation(table, machine, prog)
        meas.violations.extend(meas.path.violations)
    return table, meas


def recorded_options(table: TableFile, dialect: str | None = None) -> dict[str, Any]:
    """The options the table's source was read with (header ``source_options``), ``dialect`` (given on the
    command line) in place of the recorded one. A header whose record is not a table of options is refused."""
    recorded = table.header.meta.get("source_options", {})

    def plain(v: Any) -> bool:  # what an option recorded by jaxcnc can be: a word, a flag, a number, names
        if isinstance(v, (str, bool)):
            return True
        if isinstance(v, (int, float)):
            return math.isfinite(v)
        return isinstance(v, list) and all(isinstance(x, str) for x in v)

    if (
        not isinstance(recorded, dict)
        or not all(isinstance(k, str) and plain(v) for k, v in recorded.items())
        or not isinstance(recorded.get("dialect", ""), str)
    ):
        raise JaxcncError(f"{table.path}: header source_options = {recorded!r}: must be a table of named options")
    return source_options(dialect, recorded)


def program_for_table(
    table: TableFile,
    machine: MachineConfig,
    program: Path | None = None,
    dialect: str | None = None,
) -> tuple[Program | None, str]:
    """The Program to compare ``table`` with, or ``(None, why not)``.

    With ``program`` that file is read (it must exist: a missing one raises
    :class:`~jaxcnc.errors.JaxcncError`, as does one that cannot be parsed). Without it the table's
    header names the source (a relative name is looked for from the working directory, then from the
    table's folder); it is compared only when a front end reads it as a program, and it is present and
    unchanged (its SHA-256 equals the header's ``source_sha256``) and parses — otherwise the
    reason is returned and the check is skipped, which is neither a pass nor a failure.
    """
    from jaxcnc.errors import SourceError
    from jaxcnc.format import EventKind, file_sha256

    if not np.any(table.events["kind"] == EventKind.BLOCK):
        return None, "the table has no block events (a point job?): nothing ties its ticks to program rows"
    options = recorded_options(table, dialect)
    if program is not None:
        if not Path(program).is_file():
            raise JaxcncError(f"{program}: no such program file")
        return load_program(program, machine, input_options=options), ""
    meta = table.header.meta
    source = str(meta.get("source", ""))
    if not source:
        return None, "the table names no source program; pass --program FILE"
    src = Path(source)
    try:
        fe = front_end_for(src)
    except JaxcncError:  # no front end reads it
        fe = None
    if fe is None or fe.produces != "program":
        return None, f"its source {source!r} is not a program (G-code or a drawing)"
    if not src.is_file() and not src.is_absolute() and (table.path.parent / src).is_file():
        src = table.path.parent / src  # planned from the table's folder
    if not src.is_file():
        return None, f"its source program {source!r} is not here; pass --program FILE"
    want = meta.get("source_sha256")
    if want and file_sha256(src) != want:
        return None, f"{source} changed since the table was planned (checksum differs); pass --program FILE"
    try:
        return fe.load(src, machine, **options), ""
    except SourceError as exc:
        return None, f"its source cannot be read ({exc}); pass --dialect or --program"


def points_of_table(table, machine: MachineConfig, points: str | Path | None):
    """The point job a pulsed table burns: ``points`` or the table's source, checked unchanged."""
    from jaxcnc.format import file_sha256

    meta = table.header.meta
    source = Path(points) if points else Path(str(meta.get("source", "")))
    if not source.is_file():
        raise JaxcncError(
            f"{table.path}: the table burns points from {str(source)!r}, which is not here; pass --points FILE"
        )
    if points is None and meta.get("source_sha256"):
        if file_sha256(source) != meta["source_sha256"]:
            raise JaxcncError(f"{source}: changed since the table was planned (checksum differs); pass --points FILE")
    # the check verifies what was planned: repeats as planned, the source read as it was
    return load_point_job(source, machine, allow_repeats=True, input_options=recorded_options(table))
