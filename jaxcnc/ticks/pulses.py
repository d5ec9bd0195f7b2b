"""Pulsed jobs to table files: the trajectory sampled at the tick rate, and the pulse events.

Events: one ``WORK_PULSE`` per point at the tick its pulse fires (``aux`` = the point's index in
its file, ``value`` = its energy), ``IDLE_PULSE`` for pump pulses that burn nothing, and
``SHUTTER`` half-way between two pulses of different kinds (open before work pulses, closed
before idle ones).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.buckets import bucket_size
from jaxcnc.format import EVENT_DTYPE, EventKind
from jaxcnc.jitcache import cached_jit
from jaxcnc.planners.pulsed import PlannedPoints
from jaxcnc.planners.pulsed.trajectory import Trajectory
from jaxcnc.program import PROGRAM_AXES
from jaxcnc.ticks.sample import CHUNK_TICKS, machine_axes
from jaxcnc.ticks.table import table_meta, write_samples


@cached_jit(static_argnames=("chunk",))
def _trajectory_chunk(first, n_last, start_tick, coeffs, tick_hz, chunk: int):
    """Positions ``(chunk, 3)`` of ticks ``first + i``: piece search, then Horner in local seconds."""
    tick = jnp.minimum(first + jnp.arange(chunk, dtype=jnp.int64), n_last)
    t = tick.astype(jnp.float64)
    k = jnp.clip(jnp.searchsorted(start_tick, t, side="right") - 1, 0, start_tick.shape[0] - 1)
    tau = ((t - start_tick[k]) / tick_hz)[:, None]
    c = coeffs[k]
    return c[:, 0] + tau * (c[:, 1] + tau * (c[:, 2] + tau * c[:, 3]))


class TrajectorySampler:
    """Samples a :class:`~jaxcnc.planners.pulsed.trajectory.Trajectory` chunk by chunk (machine axes)."""

    def __init__(self, traj: Trajectory, machine, chunk: int = CHUNK_TICKS):
        self.traj, self.chunk = traj, chunk
        n = len(traj)
        m = bucket_size(n)
        self._start = jax.device_put(np.concatenate([traj.start_tick, np.full(m - n, np.inf)]))
        self._coeffs = jax.device_put(np.concatenate([traj.coeffs, np.zeros((m - n, 4, 3))]))
        names = machine.axis_names
        self._src = np.array([PROGRAM_AXES.index(a) if a in PROGRAM_AXES else -1 for a in names])
        self._home = np.array([machine.axis(a).home for a in names])

    @property
    def n_rows(self) -> int:
        return self.traj.n_ticks + 1

    def program_positions(self, first: int, count: int) -> np.ndarray:
        """Exact x, y, z ``(count, 3)`` mm of ticks ``first..first+count-1``."""
        p = _trajectory_chunk(
            np.int64(first), np.int64(self.traj.n_ticks), self._start, self._coeffs, self.traj.tick_hz, self.chunk
        )
        return np.asarray(p)[:count]

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        for first in range(0, self.n_rows, self.chunk):
            count = min(self.chunk, self.n_rows - first)
            yield first, machine_axes(self.program_positions(first, count), self._src, self._home)


def pulse_events(planned: PlannedPoints) -> np.ndarray:
    """Work, idle and shutter events of a pulsed plan, sorted by tick (``EVENT_DTYPE``).

    A work pulse's ``aux`` is its point's index in the source file (the burn order may differ
    from the file's after ``--reorder``).
    """
    plan, job = planned.plan, planned.job
    work = np.zeros(plan.work_tick.shape[0], EVENT_DTYPE)
    work["tick"], work["kind"], work["aux"] = plan.work_tick, EventKind.WORK_PULSE, job.index
    if job.energy is not None:
        work["value"] = job.energy
    idle = np.zeros(plan.idle_tick.shape[0], EVENT_DTYPE)
    idle["tick"], idle["kind"] = plan.idle_tick, EventKind.IDLE_PULSE
    pulses = np.concatenate([work, idle])
    pulses = pulses[np.argsort(pulses["tick"], kind="stable")]
    is_work = pulses["kind"] == EventKind.WORK_PULSE
    change = np.flatnonzero(is_work[1:] != is_work[:-1]) + 1
    shutter = np.zeros(change.shape[0] + 1, EVENT_DTYPE)
    shutter["kind"] = EventKind.SHUTTER
    shutter["tick"][0] = max(int(pulses["tick"][0]) - planned.window.n_min // 2, 0)
    shutter["aux"][0] = 1 if is_work[0] else 0
    shutter["tick"][1:] = (pulses["tick"][change - 1] + pulses["tick"][change]) // 2
    shutter["aux"][1:] = is_work[change]
    out = np.concatenate([shutter, pulses])
    return out[np.argsort(out["tick"], kind="stable")]


def write_pulse_table(
    planned: PlannedPoints, path: str | Path, *, progress: bool | None = None, source_options: dict | None = None
) -> Path:
    """Sample a pulsed plan at the tick rate and write its table file with the pulse events (``source_options``
    as :func:`jaxcnc.ticks.table.write_table` records them)."""
    plan = planned.plan
    more = {"source_options": dict(source_options)} if source_options else {}
    meta = table_meta(
        planned.machine,
        planned.job.file,
        plan.planner,
        plan.trajectory.total_time_s,
        n_points=len(planned.job),
        pulse_hz=planned.window.pulse_hz,
        pulse_tolerance=planned.window.tolerance,
        **more,
    )
    sampler = TrajectorySampler(plan.trajectory, planned.machine)
    return write_samples(path, planned.machine, sampler, pulse_events(planned), meta, progress)
