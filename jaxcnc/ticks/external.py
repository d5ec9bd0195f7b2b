"""The external motion module (issue 18): one G-code program drives a stage and a galvo scanner in turn.

The documents' module (SEEDS §3): on "switch to external control" the interpolator waits, the module feeds the
scanner board from the program and publishes the coordinates back; on "leave external control" the interpolator
resumes. Here, on a machine whose ``[galvo]`` names beam axes (``axes = ["u", "v"]``: the beam's offset in the
field, in the stage's frame and mm at the work; x, y (z) the stage), ``M170`` / ``M171`` split a program into
sections (``Event.EXTERNAL`` rows, :mod:`jaxcnc.gcode.interpreter`):

- a **stage** section is planned on the stage axes (the beam held at the field's centre, 0);
- a **scanner** section is planned on the beam axes with their own limits: the program's X Y stay the tool
  point, so the beam runs ``X − P`` where ``P`` is where the stage waits (the position handed over at M170);
  the stage holds ``P`` exactly; the M171 row brings the beam back (dark) to the centre, so the next stage
  section starts from ``P`` — the position handed back.

Every section starts and ends at rest; their tables are joined into one table with every axis (both groups),
BLOCK events naming the program's rows. :func:`check_external` verifies the tool point (stage + beam) against
the program at every tick, the stage at rest while the scanner runs, the beam at the centre while the stage
runs; :func:`scanner_lists` gives each scanner section's tick-exact vector list (what the board runs while the
stage waits).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxcnc.errors import JaxcncError, SourceError
from jaxcnc.format import EVENT_DTYPE, EventKind, TableFile
from jaxcnc.format.vectors import VectorHeader, encode_rows
from jaxcnc.machine import GalvoConfig, MachineConfig
from jaxcnc.program import Event, Kind, Program, program_start
from jaxcnc.ticks.deviation import tool_point_violations, tool_rows_distance

#: Numeric slack on the tool-point distance (mm) beside the tolerance.
SLACK_MM = 1e-6
_ARRAYS = tuple(f.name for f in dataclasses.fields(Program) if f.name not in ("file", "curves"))


@dataclass
class Section:
    """One section of a program: ``scanner`` or stage, its program ``rows`` (indices into the program), its
    ticks ``first_tick .. last_tick`` in the joined table, and ``stage_mm`` (x, y, z) where the stage stands
    while a scanner section runs (the position handed over)."""

    scanner: bool
    rows: np.ndarray
    first_tick: int = 0
    last_tick: int = 0
    stage_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass
class ExternalPlan:
    """A planned stage + scanner program: ``positions_mm`` ``(n, n_axes)`` in the machine's axis order,
    ``events`` (``EVENT_DTYPE``), the ``sections`` and the job's time."""

    positions_mm: np.ndarray
    events: np.ndarray
    sections: list[Section]
    total_time_s: float
    path_length_mm: float

    @property
    def n_ticks(self) -> int:
        return int(self.positions_mm.shape[0])


def is_stage_galvo(machine: MachineConfig) -> bool:
    """The machine has a stage and a galvo head (``[galvo] axes``): programs may switch with M170 / M171."""
    return machine.galvo is not None and machine.galvo.stage


def sections_of(program: Program) -> list[Section]:
    """The program's stage and scanner sections in order (the EXTERNAL rows themselves belong to none)."""
    ext = np.flatnonzero((program.kind == Kind.EVENT) & (program.event == Event.EXTERNAL))
    bounds = np.concatenate([[-1], ext, [len(program)]])
    out = []
    for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        rows = np.arange(a + 1, b)
        scanner = k > 0 and bool(program.event_value[bounds[k]] == 1)
        if rows.size:
            out.append(Section(scanner, rows))
    return out


def stage_machine(machine: MachineConfig) -> MachineConfig:
    """The stage alone: the machine without its beam axes."""
    beam = machine.galvo.axes
    return dataclasses.replace(machine, axes=tuple(a for a in machine.axes if a.name not in beam), galvo=None)


def beam_machine(machine: MachineConfig) -> MachineConfig:
    """The scanner alone, as a scanner-only galvo machine: its beam axes as x, y (their limits, their field)."""
    u, v = (machine.axis(n) for n in machine.galvo.axes)
    galvo = GalvoConfig(machine.galvo.tracking_error_s, machine.galvo.mirror_a_max_mm_s2, machine.galvo.damping)
    axes = (dataclasses.replace(u, name="x"), dataclasses.replace(v, name="y"))
    return dataclasses.replace(machine, name=f"{machine.name} scanner", axes=axes, galvo=galvo)


def _sub_program(program: Program, rows: np.ndarray, shift: np.ndarray) -> Program:
    cols = {k: getattr(program, k)[rows] for k in _ARRAYS}
    for k in ("start", "end", "center"):
        cols[k] = cols[k] + shift
    return Program(**cols, file=program.file, curves=program.curves)


def _scanner_rows(program: Program, sec: Section) -> None:
    """Refuse what a scanner section cannot run, naming the line: focus (Z) moves and splines."""
    pr, rows = program, sec.rows
    z_moves = (pr.start[rows, 2] != sec.stage_mm[2]) | (pr.end[rows, 2] != sec.stage_mm[2])
    curve = pr.kind[rows] == Kind.CURVE
    for bad, why in ((z_moves, "moves Z: a scanner section marks in the plane the stage holds"),
                     (curve, "a spline in a scanner section is not supported (lines and arcs are)")):  # fmt: skip
        if bad.any():
            raise SourceError(pr.file, int(pr.line[rows[np.flatnonzero(bad)[0]]]), 0, why)


def plan_external(program: Program, machine: MachineConfig, planner: str | None = None) -> ExternalPlan:
    """Plan a program with M170 / M171 sections on a stage + galvo machine (see the module's text)."""
    from jaxcnc.planners import plan_job
    from jaxcnc.ticks.sample import TickSampler
    from jaxcnc.ticks.table import job_events

    if not is_stage_galvo(machine):
        raise JaxcncError(f"machine {machine.name!r} has no stage + galvo head ([galvo] axes): no external motion")
    names = machine.axis_names
    stage_m, beam_m = stage_machine(machine), beam_machine(machine)
    stage_cols = [names.index(a) for a in stage_m.axis_names]
    beam_cols = [names.index(a) for a in machine.galvo.axes]
    home = np.array([machine.axis(a).home for a in names])
    chunks: list[np.ndarray] = []
    prev_row = home.copy()
    events: list[np.ndarray] = []
    sections = []
    tick, total_s, length = 0, 0.0, 0.0
    stage_at = program_start(machine)  # program x, y, z where the stage stands
    for sec in sections_of(program):
        moving = (program.kind[sec.rows] == Kind.LINE) | (program.kind[sec.rows] == Kind.ARC)
        moving |= program.kind[sec.rows] == Kind.CURVE
        if not moving.any():
            continue  # a section of events only (the program's end after the last switch): no motion to plan
        sec.stage_mm = stage_at.copy()
        if sec.scanner:
            _scanner_rows(program, sec)
            job = plan_job(_sub_program(program, sec.rows, -stage_at), beam_m, planner=planner)
        else:
            job = plan_job(_sub_program(program, sec.rows, np.zeros(3)), stage_m, planner=planner)
        n = job.plan.n_ticks + 1
        p = np.empty((n, len(names)))
        p[:] = prev_row  # the other group holds where it stands
        cols = beam_cols if sec.scanner else stage_cols
        for first, c in TickSampler(job):
            p[first : first + c.shape[0], cols] = np.asarray(c)
        if not sec.scanner:
            p[:, beam_cols] = 0.0
            stage_at = np.asarray(job.program.end[-1], np.float64).copy()
        ev = job_events(job)
        ev["tick"] += tick
        blk = ev["kind"] == EventKind.BLOCK
        ev["value"][blk] = sec.rows[ev["value"][blk].astype(np.int64)]
        events.append(ev)
        chunks.append(p[1:] if chunks else p)  # a section's first row is the last of the one before
        prev_row = p[-1].copy()
        sec.first_tick, sec.last_tick = tick, tick + n - 1
        tick += n - 1
        total_s += job.plan.total_time_s
        length += job.path_length_mm
        sections.append(sec)
    if not sections:
        raise JaxcncError(f"{program.file}: the program has no motion")
    pos = np.concatenate(chunks)
    ev = np.concatenate(events) if events else np.zeros(0, EVENT_DTYPE)
    ev = ev[np.argsort(ev["tick"], kind="stable")]
    return ExternalPlan(pos, ev, sections, total_s, length)


def write_external_table(
    plan: ExternalPlan, program: Program, machine: MachineConfig, path: str | Path, source_options: dict | None = None
) -> Path:
    """Write the joined table (every axis, the events, ``external`` sections in the header: per section
    ``[scanner 0/1, first tick, last tick]``)."""
    from jaxcnc.ticks.sample import ArraySampler
    from jaxcnc.ticks.table import table_meta, write_samples

    more = {"source_options": dict(source_options)} if source_options else {}
    secs = [[int(s.scanner), s.first_tick, s.last_tick] for s in plan.sections]
    meta = table_meta(
        machine, program.file, "external", plan.total_time_s, n_blocks=program.n_blocks, external=secs, **more
    )
    return write_samples(path, machine, ArraySampler(plan.positions_mm), plan.events, meta)


@dataclass
class ExternalCheck:
    """What :func:`check_external` found."""

    max_tool_deviation_mm: float
    max_stage_motion_in_scanner_mm: float
    max_beam_off_centre_in_stage_mm: float
    violations: list[str] = field(default_factory=list)


def table_sections(table: TableFile) -> list[tuple[bool, int, int]]:
    """``(scanner, first tick, last tick)`` of each section recorded in a table's header."""
    secs = table.header.meta.get("external")
    if not isinstance(secs, list):
        raise JaxcncError("the table records no stage / scanner sections (header 'external')")
    return [(bool(s[0]), int(s[1]), int(s[2])) for s in secs]


def check_external(table: TableFile, machine: MachineConfig, program: Program) -> ExternalCheck:
    """The tool point (stage + beam) within the corner tolerance plus one discrete of the program at every tick;
    the stage still (bit for bit) during every scanner section, the beam at the field's centre during every
    stage section."""
    axes = list(table.axes)
    u, v = machine.galvo.axes
    pos = np.asarray(table.exact_mm(0, table.n_rows))
    stage = pos[:, [axes.index(a) for a in axes if a not in (u, v)]]
    beam = pos[:, [axes.index(u), axes.index(v)]]
    tool = np.c_[pos[:, axes.index("x")] + beam[:, 0], pos[:, axes.index("y")] + beam[:, 1]]
    z = pos[:, axes.index("z")] if "z" in axes else np.full(tool.shape[0], program.start[0, 2])
    still, centre = 0.0, 0.0
    out = ExternalCheck(0.0, 0.0, 0.0)
    for scanner, a, b in table_sections(table):
        if scanner:
            still = max(still, float(np.abs(stage[a : b + 1] - stage[a]).max()))
        else:
            centre = max(centre, float(np.abs(beam[a : b + 1]).max()))
    out.max_stage_motion_in_scanner_mm, out.max_beam_off_centre_in_stage_mm = still, centre
    if still > 0:
        out.violations.append(f"the stage moves {still:.3g} mm while the scanner runs")
    if centre > 0:
        out.violations.append(f"the beam leaves the field's centre by {centre:.3g} mm while the stage runs")
    found = tool_rows_distance(table, program, np.c_[tool, z])
    if found is None:
        out.violations.append("the table's block events do not match the program")
        return out
    row, d, first_tick = found
    lead = np.arange(table.n_rows) < first_tick
    d[lead] = 0.0  # before the first row the machine stands at home, where the program starts
    out.max_tool_deviation_mm = float(d.max())
    tol = machine.path.corner_tol_mm + table.header.discrete_mm + SLACK_MM
    out.violations += tool_point_violations(tool, d, row, program, tol)
    return out


def scanner_lists(table: TableFile, machine: MachineConfig) -> list[tuple[int, int, np.ndarray, VectorHeader]]:
    """Each scanner section's vector list, tick-exact (:func:`~jaxcnc.format.vectors.encode_rows`), what the
    board runs while the stage waits: ``(first tick, last tick, records, header)`` per scanner section."""
    axes = list(table.axes)
    cols = [axes.index(a) for a in machine.galvo.axes]
    h = VectorHeader(table.header.tick_hz, table.header.discrete_mm, ("x", "y"), {"axes": list(machine.galvo.axes)})
    out = []
    for scanner, a, b in table_sections(table):
        if scanner:
            pos = np.asarray(table.positions[a : b + 1])[:, cols]
            pw = np.asarray(table.power[a : b + 1], np.float64)
            out.append((a, b, encode_rows(pos, pw), h))
    return out
