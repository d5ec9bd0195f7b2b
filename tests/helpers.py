"""Test helpers: plan G-code text on a machine and write/verify its table."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jaxcnc.gcode import parse_gcode
from jaxcnc.hw.tablefile import TableFile
from jaxcnc.machine import MachineConfig
from jaxcnc.planners import PlannedJob, plan_job, program_start
from jaxcnc.planners.registry import DEFAULT_PLANNER
from jaxcnc.ticks.table import write_table
from jaxcnc.ticks.verify import Measurement, measure_table


def plan_text(text: str, machine: MachineConfig, planner: str = DEFAULT_PLANNER) -> PlannedJob:
    start = program_start(machine)
    return plan_job(parse_gcode(text, "test.ngc", start=start, home=start), machine, planner)


def span_segments(job: PlannedJob, kind: int) -> np.ndarray:
    """Indices of the plan's segments that lie on spans of ``kind``."""
    return np.flatnonzero(job.spans.kind[job.plan.span] == kind)


def table_of(
    text: str, machine: MachineConfig, folder: Path, name: str = "t.ticks", planner: str = DEFAULT_PLANNER
) -> tuple[PlannedJob, TableFile, Measurement]:
    job = plan_text(text, machine, planner)
    path = write_table(job, folder / name, progress=False)
    table = TableFile(path)
    return job, table, measure_table(table, machine)
