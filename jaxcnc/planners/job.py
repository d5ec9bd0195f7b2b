"""A planned job: Program → spans → Plan for one machine, with the machine-level checks.

Checks done here, each an error naming the program's file and line: the program moves an axis
the machine lacks; some span leaves the machine's travel.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from jaxcnc.errors import PlanningError, RowPlanningError, SourceError
from jaxcnc.geometry.path import build_spans
from jaxcnc.geometry.spans import SpanKind, Spans
from jaxcnc.jaxconfig import planning_scope
from jaxcnc.jitcache import release_when_crowded
from jaxcnc.machine import AxisConfig, MachineConfig
from jaxcnc.memory import release_free_heap
from jaxcnc.planners.protocol import (
    Planner,
    PlanRequest,
    TimeLaw,
    coordinate_extent_mm,
    machine_limits,
    request_limits,
)
from jaxcnc.planners.registry import DEFAULT_PLANNER, PLANNERS, resolve_planner
from jaxcnc.planners.smoothing import blends_slower_than_stops, jerk_limited
from jaxcnc.program import PROGRAM_AXES, Kind, Program


@dataclass(frozen=True, eq=False)
class PlannedJob:
    """Everything the tick stage needs: the program, its spans, their time law, the machine.

    ``axis_source[i]`` is the program column (0..2 for x, y, z) feeding machine axis ``i``, or -1
    for a machine axis the program does not drive (it stays at its home).
    """

    program: Program
    spans: Spans
    plan: TimeLaw
    machine: MachineConfig
    axis_source: tuple[int, ...]
    plan_wall_s: float
    planner: str = DEFAULT_PLANNER
    #: corners the program would blend that are kept exact under the machine's jerk limits (a blend there would be
    #: passed slower than a stop: :func:`~jaxcnc.planners.smoothing.blends_slower_than_stops`)
    exact_corners: int = 0

    @property
    def path_length_mm(self) -> float:
        return float(np.sum(self.spans.length))


def _check_axes(program: Program, machine: MachineConfig) -> tuple[int, ...]:
    names = machine.axis_names
    for col, axis in enumerate(PROGRAM_AXES):
        if axis not in names and program.uses_axis(col):
            moved = np.flatnonzero(program.end[:, col] != program.start[:, col])
            line = int(program.line[moved[0]]) if moved.size else 0
            raise SourceError(
                program.file,
                line,
                0,
                f"the program moves axis {axis.upper()} but machine {machine.name!r} has no axis {axis!r}",
            )
    return tuple(PROGRAM_AXES.index(a) if a in PROGRAM_AXES else -1 for a in names)


def outside_travel(
    lo: np.ndarray, hi: np.ndarray, machine: MachineConfig, tol_mm: float = 1e-9
) -> tuple[int, str, float, AxisConfig] | None:
    """The first row of extents ``lo``/``hi`` ``(n, 3)`` (x, y, z) that leaves the machine's travel.

    Returns ``(row, axis, value, axis_config)`` for the first offending row (axes in x, y, z
    order), or ``None``; axes the machine lacks are not checked.
    """
    for col, axis in enumerate(PROGRAM_AXES):
        if axis not in machine.axis_names:
            continue
        ax = machine.axis(axis)
        bad = np.flatnonzero((lo[:, col] < ax.min - tol_mm) | (hi[:, col] > ax.max + tol_mm))
        if bad.size:
            k = int(bad[0])
            return k, axis, float(lo[k, col] if lo[k, col] < ax.min else hi[k, col]), ax
    return None


def _check_travel(program: Program, spans: Spans, machine: MachineConfig) -> None:
    out = outside_travel(spans.lo, spans.hi, machine)
    if out is not None:
        k, axis, value, ax = out
        text = f"{value:.6g} mm"
        if text in (f"{ax.min:.6g} mm", f"{ax.max:.6g} mm"):  # (a blend's bulge past an edge: say by how much)
            text = f"{value:.12g} mm ({(value - ax.max if value > ax.max else ax.min - value) * 1e3:.3g} µm beyond)"
        raise SourceError(
            program.file,
            int(program.line[spans.block[k]]),
            0,
            f"{axis.upper()} reaches {text}, outside the travel of machine {machine.name!r} [{ax.min:g}, {ax.max:g}]",
        )


#: Programs of at least this many rows hand the C heap's free pages back before their spans are built
#: (:func:`~jaxcnc.memory.release_free_heap`): a 1 M-block blended plan made after another one peaked
#: ~120 MB higher, in the blends' build, on the pieces the first plan left (docs/planning.md, "Memory").
TRIM_BLOCKS = 1 << 18
#: Rounds of keeping corners exact under jerk limits (:func:`~.smoothing.blends_slower_than_stops`) at most.
EXACT_ROUNDS = 4


def span_feed(program: Program, spans: Spans, machine: MachineConfig) -> np.ndarray:
    """``(n,)`` the programmed speed of each span: its row's feed (the machine's default where none is set), or
    the machine's rapid cap on a rapid."""
    rows = spans.block
    feed = program.feed[rows]
    return np.where(program.rapid[rows], machine.path.rapid, np.where(np.isnan(feed), machine.path.feed, feed))


def machine_planner(machine: MachineConfig) -> str:
    """The contour planner ``machine`` names (``[machine] planner``), or :data:`DEFAULT_PLANNER`."""
    return machine.planner or DEFAULT_PLANNER


def plan_job(program: Program, machine: MachineConfig, planner: str | Planner | None = None) -> PlannedJob:
    """Plan ``program`` on ``machine`` with ``planner``: a name, a :class:`Planner`, or ``None`` for the
    machine file's ``planner`` (``topp`` when it names none)."""
    t0 = time.perf_counter()
    release_when_crowded()  # a long-lived process: the programs of earlier jobs, before the limit on mappings
    try:
        name, chosen = resolve_planner(machine_planner(machine) if planner is None else planner)
    except PlanningError as exc:
        if planner is None:  # the machine file named it
            from jaxcnc.machine import key_error

            raise key_error(machine, "machine", "planner", str(exc)) from None
        raise
    axis_source = _check_axes(program, machine)
    if len(program) >= TRIM_BLOCKS:
        release_free_heap()  # what earlier work freed (a job planned before): the spans' build starts lean
    # under jerk limits (the S-curve stage) the path is G2 where it is blended: tangent junctions where the
    # curvature steps are blended too, and corners whose blend is passed slower than a stop are kept exact
    limits = machine_limits(machine)
    s_curve = bool(np.any(np.isfinite(limits[2])) and not chosen.handles_jerk)
    with planning_scope():  # the blends' kernels too: the same spans on any machine, none compiled for a GPU
        spans = build_spans(program, machine.path.corner_tol_mm, g2=s_curve)
    if len(spans) == 0 or not np.any(spans.kind != SpanKind.POINT):
        raise PlanningError(f"{program.file}: the program has no motion")
    _check_travel(program, spans, machine)
    exact = np.zeros(len(program), bool)
    if s_curve:
        # a corner kept exact changes its neighbours' blends (one on a short line may take all of it now, or half
        # where it took less): the rule is asked again of the new blends until it keeps no other corner exact
        for _ in range(EXACT_ROUNDS):
            more = blends_slower_than_stops(spans, span_feed(program, spans, machine), *limits, len(program))
            if not np.any(more & ~exact):
                break
            exact |= more
            with planning_scope():
                spans = build_spans(program, machine.path.corner_tol_mm, exact_before=exact, g2=True)
    rows = spans.block
    feed = span_feed(program, spans, machine)
    dwell = np.where(program.kind[rows] == Kind.DWELL, program.dwell_s[rows], 0.0)
    first_of_block = np.concatenate([[True], rows[1:] != rows[:-1]])
    stop = program.stop_before[rows] & first_of_block
    del first_of_block  # (n,): not kept alive through the plan
    # the machine's limits less the margin, applied here once (none on v and a where rounding cannot reach them)
    v_max, a_max, j_max = request_limits(machine, coordinate_extent_mm(spans))
    request = PlanRequest(spans, feed, dwell, stop, v_max, a_max, machine, j_max=j_max)
    try:
        with planning_scope():  # sequential passes: on the host CPU (see jaxconfig)
            if s_curve:
                plan = jerk_limited(request, chosen)  # jerk limits: the planner's time law averaged (an S-curve)
            else:
                plan = chosen.plan(request)
    except RowPlanningError as exc:  # a planner's refusal of one row: located in the program
        line, reason = int(program.line[exc.row]), exc.reason
        if exc.per_row is not None:  # the source line with the most (an arc's P turns are rows of one line)
            lines = program.line[: len(exc.per_row)]
            by_line = np.bincount(lines, weights=exc.per_row)
            line = int(np.argmax(by_line))
            reason = reason.replace("{on_line}", f"{int(by_line[line]):,}")
        raise PlanningError(f"{program.file}:{line}: {reason}") from None
    except Exception as exc:
        one_line = PLANNERS.failed(name, exc)  # a plug-in's failure: one line naming it
        if one_line is None:
            raise
        raise one_line from None
    moving_mm = float(np.sum(spans.length[spans.kind != SpanKind.POINT]))
    if plan.n_ticks <= 0 and moving_mm > 0:
        # a time law that covers a moving program in no time would leave the table at the start while the
        # program ends elsewhere (the table's check sees no motion at all): refuse it loudly
        raise PlanningError(
            f"{program.file}: planner {name!r} planned {moving_mm:.6g} mm of motion in zero time "
            "(a planner bug; please report it, and plan with another --planner meanwhile)"
        )
    return PlannedJob(
        program=program,
        spans=spans,
        plan=plan,
        machine=machine,
        axis_source=axis_source,
        plan_wall_s=time.perf_counter() - t0,
        planner=name,
        exact_corners=int(np.count_nonzero(exact)),
    )
