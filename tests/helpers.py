"""Test helpers: plan G-code text on a machine and write/verify its table."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jaxcnc.format import TableFile
from jaxcnc.gcode import parse_gcode
from jaxcnc.machine import MachineConfig
from jaxcnc.planners import PlannedJob, plan_job, program_start
from jaxcnc.planners.registry import DEFAULT_PLANNER, Planner
from jaxcnc.ticks.table import write_table
from jaxcnc.ticks.verify import Measurement, measure_table


def plan_text(text: str, machine: MachineConfig, planner: str | Planner = DEFAULT_PLANNER) -> PlannedJob:
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


def bang_sweeps(pts: np.ndarray):
    """``bang``'s plan of ``pts`` on the documents' glass engraver before the polish (the sweeps), and the
    arguments :func:`~jaxcnc.planners.pulsed.polish.polish` gets:
    ``(D, ticks, v, cruise, capm, capk, shortest, A, tick_hz, window)``."""
    from jaxcnc.bench.pulsed import glass_engraver
    from jaxcnc.planners.pulsed import bang
    from jaxcnc.planners.pulsed.windows import pulse_window

    w = pulse_window(glass_engraver())
    D = np.diff(pts, axis=0)
    f = w.tick_hz
    A = np.full(3, 300.0)
    capm = bang.path_caps(D, 50.0, np.full(3, 50.0))
    capk = np.full((len(pts), 3), 30.0 / np.sqrt(3))
    cruise = np.any(np.abs(D) >= capm * capm / A, axis=1)
    lo = np.maximum(np.ceil(np.max(np.abs(D) / capm, axis=1) * f), w.n_min)
    cand = bang.candidates(lo, w)
    fwd, bwd = (bang._Gaps(D, cruise, capm, capk, bang.bucket_size(len(D)), reverse=r) for r in (False, True))
    first = bang._sweep(fwd, bwd, cand, None, A, f, w, lookahead=bang.LOOKAHEAD)[0]
    ticks, v, _ = bang._improve(fwd, bwd, cand, [first], A, f, w, bang.PASSES)
    return D, ticks, v, cruise, capm, capk, cand[:, 0], A, f, w


def window_optimum_at_rest(pts: np.ndarray, ticks: np.ndarray, max_seconds: float = 120.0) -> tuple[int, object]:
    """The glass engraver's certified per-gap bounds summed, and the optimum at rest of the window ``pts``
    (:func:`~jaxcnc.planners.pulsed.optimum.optimum_window` at the request's limits and path caps, started from
    ``ticks``): ``(bound ticks, OptimumWindow)``."""
    from jaxcnc.bench.pulsed import glass_engraver
    from jaxcnc.planners.protocol import machine_limits, request_limits, with_margin
    from jaxcnc.planners.pulsed.bound import lower_bound_travel
    from jaxcnc.planners.pulsed.optimum import optimum_window
    from jaxcnc.planners.pulsed.windows import pulse_window

    machine = glass_engraver()
    win = pulse_window(machine)
    V, A, _ = machine_limits(machine)
    Vr, Ar, _ = request_limits(machine)
    lb = lower_bound_travel(pts, win, V, A, feed_mm_s=machine.path.feed, rapid_mm_s=machine.path.rapid)
    caps = {"feed_mm_s": with_margin(machine.path.feed), "rapid_mm_s": with_margin(machine.path.rapid)}
    opt = optimum_window(
        pts, win, Vr, Ar, lb.gap_ticks, start_ticks=ticks, rest_ends=True, max_seconds=max_seconds, **caps
    )
    return int(lb.gap_ticks.sum()), opt
