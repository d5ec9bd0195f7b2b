"""Test helpers: plan G-code text on a machine and write/verify its table."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jaxcnc.format import TableFile
from jaxcnc.gcode import parse_gcode
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


def at_s(spans, idx: np.ndarray, s: np.ndarray, order: int = 0) -> list[np.ndarray]:
    """Position and derivatives (NumPy) of spans ``idx`` at path parameter ``s`` from their starts."""
    from jaxcnc.geometry.evaluate import evaluate_path, span_arrays

    return list(evaluate_path(span_arrays(spans), np.asarray(idx), np.asarray(s, dtype=np.float64), order))


def random_cubic_nurbs(n_points: int, seed: int = 0) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """A planar cubic NURBS with ``n_points`` control points winding through a 200 mm field."""
    rng = np.random.default_rng(seed)
    ang = np.cumsum(rng.normal(0.0, 0.25, n_points))
    pts = np.cumsum(np.stack([np.cos(ang), np.sin(ang)], axis=1) * rng.uniform(1.0, 3.0, (n_points, 1)), axis=0)
    pts = np.c_[pts - pts.mean(axis=0), np.zeros(n_points)]
    w = rng.uniform(0.5, 2.0, n_points)
    knots = np.concatenate([np.zeros(4), np.linspace(0, 1, n_points - 2)[1:-1], np.ones(4)])
    return 3, pts, w, knots
