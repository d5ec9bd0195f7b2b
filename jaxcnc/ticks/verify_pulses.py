"""Independent verification of a pulsed table: pulse windows and the beam on every point.

Inputs are the table, the machine file and the points (NumPy only, nothing of the planner):

- every interval between consecutive pulses (work or idle) lies in ``[T(1-tol), T(1+tol)]``,
  ``T = 1/pulse_hz``, measured in ticks — no idle pulses at all where the machine forbids them;
- every point is burned by exactly one work pulse (the pulse's ``aux`` names the point);
- at each work pulse's tick the unquantised table position (integer plus fine residual) is on
  the point within :data:`HIT_TOL_DISCRETES` of a discrete on every axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from jaxcnc.format import FINE_SCALE, EventKind, TableFile
from jaxcnc.machine import MachineConfig
from jaxcnc.program import PointJob
from jaxcnc.ticks.verify import Violation

#: A work pulse hits its point when the beam is within this many discretes of it (each axis).
HIT_TOL_DISCRETES = 0.25
_PROGRAM_AXES = ("x", "y", "z")


@dataclass
class PulseCheck:
    """What :func:`check_pulses` measured, and the problems it found."""

    n_work: int = 0
    n_idle: int = 0
    min_interval_ticks: int = 0
    max_interval_ticks: int = 0
    max_miss_mm: float = 0.0
    violations: list[Violation] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.violations


def _problem(tick: int, text: str) -> Violation:
    return Violation(int(tick), int(tick), text, "pulse", 0.0, 0.0)


def check_pulses(table: TableFile, machine: MachineConfig, job: PointJob, max_reports: int = 100) -> PulseCheck:
    """Check a pulsed table's pulses against ``machine``'s pulse window and the points of ``job``."""
    out = PulseCheck()
    laser = machine.laser
    h = table.header
    if laser.pulse_hz is None:
        out.violations.append(_problem(0, f"machine {machine.name!r} has no pulse_hz to check the pulses against"))
        return out
    ev = table.events
    pulses = ev[(ev["kind"] == EventKind.WORK_PULSE) | (ev["kind"] == EventKind.IDLE_PULSE)]
    pulses = pulses[np.argsort(pulses["tick"], kind="stable")]
    work = pulses[pulses["kind"] == EventKind.WORK_PULSE]
    out.n_work, out.n_idle = int(work.shape[0]), int(pulses.shape[0] - work.shape[0])
    if out.n_idle and not laser.idle_pulses:
        first = int(pulses["tick"][pulses["kind"] == EventKind.IDLE_PULSE][0])
        out.violations.append(_problem(first, f"{out.n_idle} idle pulses, but the machine allows none"))
    # windows, in ticks, exactly as the machine file states them
    nominal = h.tick_hz / laser.pulse_hz
    lo, hi = nominal * (1.0 - laser.tolerance), nominal * (1.0 + laser.tolerance)
    gaps = np.diff(pulses["tick"])
    if gaps.size:
        out.min_interval_ticks, out.max_interval_ticks = int(gaps.min()), int(gaps.max())
    bad = np.flatnonzero((gaps < lo - 1e-9) | (gaps > hi + 1e-9))
    for i in bad[:max_reports]:
        out.violations.append(
            _problem(
                pulses["tick"][i + 1],
                f"pulse interval {gaps[i]} ticks ({gaps[i] / h.tick_hz * 1e3:.3f} ms) outside the window "
                f"[{lo / h.tick_hz * 1e3:.3f}, {hi / h.tick_hz * 1e3:.3f}] ms",
            )
        )
    if bad.size > max_reports:
        out.violations.append(_problem(pulses["tick"][bad[-1] + 1], f"... {bad.size - max_reports} more intervals"))
    # one work pulse per point
    n = len(job)
    idx = work["aux"].astype(np.int64)
    counts = np.bincount(np.clip(idx, 0, n), minlength=n + 1)
    if np.any(idx >= n):
        out.violations.append(_problem(work["tick"][np.argmax(idx >= n)], f"work pulse for point {idx.max()} of {n}"))
    for k in np.flatnonzero(counts[:n] != 1)[:max_reports]:
        out.violations.append(
            _problem(0, f"point {k} ({job.file}:{int(job.line[k])}) is burned {counts[k]} times, not once")
        )
    # the beam on the point at its pulse
    ok = idx < n
    ticks = work["tick"][ok]
    if ticks.size and (ticks.min() < 0 or ticks.max() >= h.n_rows):
        out.violations.append(_problem(int(ticks.max()), "work pulse outside the table"))
        return out
    pos = table.positions[ticks].astype(np.float64)
    if table.fine is not None:
        pos += table.fine[ticks].astype(np.float64) / FINE_SCALE
    pos *= h.discrete_mm
    target = np.empty_like(pos)
    for i, a in enumerate(h.axes):
        if a in _PROGRAM_AXES:
            target[:, i] = job.points[idx[ok], _PROGRAM_AXES.index(a)]
        else:
            target[:, i] = pos[:, i]  # an axis the points do not name: nothing to hit
    miss = np.abs(pos - target).max(axis=1) if pos.size else np.zeros(0)
    out.max_miss_mm = float(miss.max(initial=0.0))
    tol = HIT_TOL_DISCRETES * h.discrete_mm
    for i in np.flatnonzero(miss > tol)[:max_reports]:
        k = int(idx[ok][i])
        out.violations.append(
            _problem(
                ticks[i],
                f"work pulse misses point {k} ({job.file}:{int(job.line[k])}) by {miss[i] * 1e3:.3f} µm "
                f"(tolerance {tol * 1e3:.3f} µm)",
            )
        )
    return out
