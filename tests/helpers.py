"""Test helpers: plan G-code text on a machine and write/verify its table."""

from __future__ import annotations

from pathlib import Path

from jaxcnc.gcode import parse_gcode
from jaxcnc.hw.tablefile import TableFile
from jaxcnc.machine import MachineConfig
from jaxcnc.planners import PlannedJob, plan_job, program_start
from jaxcnc.ticks.table import write_table
from jaxcnc.ticks.verify import Measurement, measure_table


def plan_text(text: str, machine: MachineConfig) -> PlannedJob:
    start = program_start(machine)
    return plan_job(parse_gcode(text, "test.ngc", start=start, home=start), machine)


def table_of(
    text: str, machine: MachineConfig, folder: Path, name: str = "t.ticks"
) -> tuple[PlannedJob, TableFile, Measurement]:
    job = plan_text(text, machine)
    path = write_table(job, folder / name, progress=False)
    table = TableFile(path)
    return job, table, measure_table(table, machine)
