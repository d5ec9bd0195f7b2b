"""A table played through the simulated axes: actual positions, residual vibration at stops, contour error.

Inputs are the table and the machine file alone (the axis modes of :mod:`jaxcnc.machine`); nothing from
the plan. The table is streamed ``chunk_rows`` rows at a time (:class:`~jaxcnc.ticks.verify.TableRows`);
per-tick arrays are kept only when asked (``keep=True``, for pictures).

* **Stops.** The command is *quiet* over a tick interval when its speed there is at most ``a·dt`` (``a``
  the smallest ``a_max`` of the axes: a motion that starts from rest cannot go faster in its first tick).
  A stop is a run of quiet intervals after motion; the table's end is one too (the command then holds).
* **Residual vibration after a stop**: the free-vibration amplitude (:func:`~jaxcnc.dynamics.axis.amplitude`)
  the modes carry at the stop's first tick, summed over an axis' modes and combined over the axes as a
  Euclidean norm (mm): the ringing that follows the stop if nothing else moves.
* **Contour error**: the component of the tool's error (simulated minus commanded, over the axes) across the
  commanded direction of travel (the last moving interval's direction) — the part of the error that leaves
  the path; the tracking error along the path only delays the tool.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxcnc.dynamics.axis import Mode, ModeFilter, amplitude
from jaxcnc.errors import JaxcncError
from jaxcnc.format import TableFile
from jaxcnc.machine import MachineConfig
from jaxcnc.ticks.verify import TableRows


def machine_modes(machine: MachineConfig) -> dict[str, list[Mode]]:
    """The modes of each machine axis (only axes that have some)."""
    return {a.name: [Mode(f, z) for f, z in a.modes] for a in machine.axes if a.modes}


@dataclass
class Simulation:
    """What the simulated axes did with a table.

    Attributes:
        axes: the table's axes; ``modes`` the modes simulated per axis.
        stop_ticks: ``(n_stops,)`` first tick of each stop; ``residual_mm`` ``(n_stops,)`` the residual
            vibration there (module docstring).
        max_contour_mm, rms_contour_mm: contour error over the ticks where the command moves.
        max_tracking_mm: largest distance between simulated and commanded position.
        settle_s: how long after the end the tail was simulated (and kept).
        commanded, error: ``(n, n_axes)`` mm, when kept (``error`` = simulated - commanded), ``n`` = table
            rows plus the settle tail.
    """

    axes: list[str]
    modes: dict[str, list[Mode]]
    tick_hz: float
    stop_ticks: np.ndarray
    residual_mm: np.ndarray
    max_contour_mm: float
    rms_contour_mm: float
    max_tracking_mm: float
    settle_s: float
    commanded: np.ndarray | None = None
    error: np.ndarray | None = field(default=None, repr=False)

    @property
    def max_residual_mm(self) -> float:
        return float(self.residual_mm.max(initial=0.0))

    @property
    def mean_residual_mm(self) -> float:
        return float(self.residual_mm.mean()) if self.residual_mm.size else 0.0

    def modes_text(self) -> str:
        """The modes simulated, e.g. ``x: 40 Hz ζ=0.05; y: 40 Hz ζ=0.05``."""
        return "; ".join(
            f"{a}: " + ", ".join(f"{m.f_hz:g} Hz ζ={m.zeta:g}" for m in ms) for a, ms in self.modes.items()
        )

    def summary(self) -> dict:
        """The figures as a dict (a report's ``dynamics`` entry)."""
        return {
            "modes": {a: [[m.f_hz, m.zeta] for m in ms] for a, ms in self.modes.items()},
            "n_stops": int(self.stop_ticks.size),
            "max_residual_mm": self.max_residual_mm,
            "mean_residual_mm": self.mean_residual_mm,
            "max_contour_mm": self.max_contour_mm,
            "rms_contour_mm": self.rms_contour_mm,
            "max_tracking_mm": self.max_tracking_mm,
        }


def simulate_table(
    table: TableFile,
    machine: MachineConfig,
    modes: dict[str, list[Mode]] | None = None,
    settle_s: float = 0.2,
    keep: bool = False,
    chunk_rows: int = 1 << 16,
) -> Simulation:
    """Play ``table`` through the modes of ``machine``'s axes (or ``modes``, axis name -> modes).

    ``settle_s``: the command holds its last row this long after the table (the final ringing, kept for
    pictures). ``keep``: keep the per-tick commanded positions and errors. The figures do not depend on
    ``chunk_rows``. Raises :class:`~jaxcnc.errors.JaxcncError` when no axis of the table has a mode.
    """
    h = table.header
    axes = list(h.axes)
    modes = machine_modes(machine) if modes is None else {a: list(ms) for a, ms in modes.items() if ms}
    unknown = [a for a in modes if a not in axes]
    if unknown:
        raise JaxcncError(f"{table.path}: modes given for axes {unknown} the table lacks (axes {axes})")
    if not modes:
        raise JaxcncError(
            f"{machine.source}: no axis has vibration modes (mode_hz, mode_zeta in [axes.*]); nothing to simulate"
        )
    f = h.tick_hz
    filters = {a: [ModeFilter(m, f) for m in ms] for a, ms in modes.items()}
    col = {a: axes.index(a) for a in modes}
    quiet_v = min(machine.axis(a).a_max for a in axes if a in machine.axis_names) / f
    n = h.n_rows
    tail = int(round(settle_s * f))
    stops: list[int] = []
    residual: list[float] = []
    max_contour = max_track = 0.0
    sum_sq, n_moving = 0.0, 0
    direction = np.zeros(len(axes))
    was_moving = False
    kept_u: list[np.ndarray] = []
    kept_e: list[np.ndarray] = []
    with TableRows(table) as rows:
        for start in range(0, n + tail, chunk_rows):
            stop = min(start + chunk_rows, n + tail)
            # commanded positions of ticks start..stop (one more row for the last interval), held after the end
            idx = np.minimum(np.arange(start, stop + 1), n - 1)
            lo, hi = int(idx[0]), int(idx[-1]) + 1
            u = rows.exact_mm(lo, hi)[idx - lo]
            w = np.diff(u, axis=0) * f  # (m, n_axes): held velocity of intervals start..stop-1
            # state at ticks start+1..stop; prepend the state at tick `start` (carried)
            err = np.zeros((stop - start, len(axes)))
            amp = np.zeros((stop - start, len(axes)))
            for a, fl in filters.items():
                i = col[a]
                for flt in fl:
                    before = flt.x
                    x = flt.step(w[:, i])
                    states = np.vstack([before[None, :], x[:-1]])  # states at ticks start..stop-1
                    err[:, i] += states[:, 0]
                    amp[:, i] += amplitude(flt.mode, states[:, 0], states[:, 1])
            speed = np.linalg.norm(w, axis=1)
            quiet = speed <= quiet_v * (1 + 1e-9)
            # stops: first tick of each quiet run after motion (tick start+j begins quiet interval j)
            prev_moving = np.concatenate([[was_moving], ~quiet[:-1]])
            first = np.flatnonzero(quiet & prev_moving)
            stops += list(start + first)
            residual += list(np.linalg.norm(amp[first], axis=1))
            was_moving = bool(~quiet[-1])
            # contour error: error across the direction of the last moving interval at or before each tick
            moving = ~quiet
            dirs = np.where(moving[:, None], w / np.maximum(speed, 1e-300)[:, None], np.nan)
            dirs = np.vstack([direction[None, :], dirs])
            last = np.maximum.accumulate(np.where(~np.isnan(dirs[:, 0]), np.arange(dirs.shape[0]), 0))
            d = dirs[last][:-1]  # direction in force at ticks start..stop-1 (before each interval)
            direction = dirs[last[-1]]
            along = np.sum(err * d, axis=1)
            across = np.linalg.norm(err - along[:, None] * d, axis=1)
            in_job = np.arange(start, stop) < n
            max_contour = max(max_contour, float(across[in_job].max(initial=0.0)))
            sel = in_job & moving
            sum_sq += float(np.sum(across[sel] ** 2))
            n_moving += int(np.count_nonzero(sel))
            max_track = max(max_track, float(np.linalg.norm(err, axis=1).max(initial=0.0)))
            if keep:
                kept_u.append(u[:-1])
                kept_e.append(err)
    return Simulation(
        axes=axes,
        modes=modes,
        tick_hz=f,
        stop_ticks=np.asarray(stops, np.int64),
        residual_mm=np.asarray(residual, np.float64),
        max_contour_mm=max_contour,
        rms_contour_mm=float(np.sqrt(sum_sq / n_moving)) if n_moving else 0.0,
        max_tracking_mm=max_track,
        settle_s=tail / f,
        commanded=np.vstack(kept_u) if keep else None,
        error=np.vstack(kept_e) if keep else None,
    )


def table_dynamics(table_path: str | Path, machine: MachineConfig | str | Path) -> dict | None:
    """The simulated figures (:meth:`Simulation.summary`) of the table at ``table_path`` on ``machine``, or
    ``None`` when no axis of the machine has modes (a report's ``dynamics`` entry)."""
    from jaxcnc.machine import load_machine

    m = machine if isinstance(machine, MachineConfig) else load_machine(machine)
    if not any(a.modes for a in m.axes):
        return None
    return simulate_table(TableFile(table_path), m).summary()
