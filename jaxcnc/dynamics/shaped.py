"""Input shaping as a planner stage: a planned job's ticks convolved with a shaper, written like any table.

The stage (issue 20; shapers in :mod:`jaxcnc.planners.shaping`):

1. **Before planning** the program is prepared so that shaping keeps to the path
   (:func:`~jaxcnc.planners.shaping.shaping_program`: corners the shaper would round off too far become
   exact stops, arcs get the feed whose shaper sagitta fits the tolerance) and, on request, its feeds are
   kept out of resonant speed bands (:func:`~jaxcnc.planners.shaping.avoid_bands`).
2. The planner plans it at the machine's limits, as any job.
3. **Holds.** Where the planned motion is at rest (every rest point lies on a tick:
   :mod:`jaxcnc.planners.timelaw`), the table waits ``H`` ticks, ``H + 1`` the shaper's last tap on the tick
   grid, so the shaped approach ends before the next move starts: a stop stays a stop (no corner is
   rounded) and the job lasts ``H`` ticks longer per rest point — never more than the shaper's duration.
4. **Shaping.** Every tick ``k`` of the held sequence becomes ``Σ w_i p[k - d_i]``
   (:func:`~jaxcnc.planners.shaping.fir_taps`: positive weights summing to 1), streamed chunk by chunk.
   A convex combination of positions keeps each axis' finite-difference speed, acceleration and jerk
   within the unshaped table's (:mod:`jaxcnc.planners.shaping`); the written table is checked anyway.
5. **Events** move with the motion: events at a rest point to the end of its hold (a laser switched off at
   a corner goes off when the shaped tool arrives), the others by the shaper's mean delay.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxcnc.errors import JaxcncError
from jaxcnc.machine import MachineConfig
from jaxcnc.planners.job import PlannedJob
from jaxcnc.planners.shaping import (
    BandPlan,
    Shaper,
    avoid_bands,
    fir_taps,
    make_shaper,
    repeat_pitches,
    resonant_bands,
    rest_ticks,
    row_peak_speeds,
    shaping_program,
)
from jaxcnc.program import Program
from jaxcnc.ticks.sample import CHUNK_TICKS, TickSampler


class ShapedSampler:
    """The shaped table of ``job``: ``n_rows`` and chunks of machine-axis positions (a
    :class:`~jaxcnc.ticks.sample.Sampler`). ``shapers``: axis name -> :class:`Shaper` (axes not named are
    delayed like the others but not shaped: they hold still or keep their path)."""

    def __init__(self, job: PlannedJob, shapers: dict[str, Shaper], chunk: int = CHUNK_TICKS):
        m = job.machine
        unknown = [a for a in shapers if a not in m.axis_names]
        if unknown:
            raise JaxcncError(f"shaper given for axes {unknown} that machine {m.name!r} lacks")
        if not shapers:
            raise JaxcncError("no shaper given")
        self.job, self.chunk = job, chunk
        self.taps = [fir_taps(shapers[a], m.tick_hz) if a in shapers else (np.zeros(1, np.int64), np.ones(1))
                     for a in m.axis_names]  # fmt: skip
        self.n_delay = int(max(int(d.max()) for d, _ in self.taps))
        # the next move may start once the shaper's last tap reads the rest point: n_delay - 1 held ticks
        self.hold = max(self.n_delay - 1, 0)
        self.shift = int(round(max(s.centroid_s for s in shapers.values()) * m.tick_hz))
        self.rest = rest_ticks(job)
        self._last_copy = self.rest + self.hold * np.arange(1, self.rest.size + 1)  # held index of each rest's end
        need = chunk + self.n_delay + 2
        self.base = TickSampler(job, chunk=max(CHUNK_TICKS, 1 << (need - 1).bit_length()))

    @property
    def n_rows(self) -> int:
        return self.job.plan.n_ticks + 1 + self.hold * int(self.rest.size)

    @property
    def extra_s(self) -> float:
        """How much longer the shaped job lasts (s)."""
        return self.hold * int(self.rest.size) / self.job.machine.tick_hz

    def source_tick(self, j: np.ndarray) -> np.ndarray:
        """The unshaped tick each held index ``j`` ``(m,)`` repeats (clipped to the table)."""
        c = np.searchsorted(self._last_copy, j, side="left")  # rest points whose copies all lie before j
        nxt = np.concatenate([self.rest, [np.iinfo(np.int64).max]])[c]
        k = np.minimum(j - self.hold * c, nxt)
        return np.clip(k, 0, self.job.plan.n_ticks)

    def event_ticks(self, ticks: np.ndarray) -> np.ndarray:
        """Where events of the unshaped ticks ``ticks`` go in the shaped table (module docstring)."""
        ticks = np.asarray(ticks, np.int64)
        i = np.searchsorted(self.rest, ticks, side="left")
        at_rest = (i < self.rest.size) & (self.rest[np.minimum(i, self.rest.size - 1)] == ticks)
        held = ticks + self.hold * i
        limit = np.concatenate([self._last_copy, [self.n_rows - 1]])[i]
        moved = np.where(ticks == 0, 0, np.minimum(held + self.shift, limit))  # the job's start is a rest too
        return np.where(at_rest, self._last_copy[np.minimum(i, self.rest.size - 1)], moved)

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        n_out, d = self.n_rows, self.n_delay
        for j0 in range(0, n_out, self.chunk):
            j1 = min(j0 + self.chunk, n_out)
            k = self.source_tick(np.arange(j0 - d, j1))
            k_lo = int(k.min())
            p, _ = self.base.program_positions(k_lo, int(k.max()) - k_lo + 1)
            held = self.base.machine_positions(p)[k - k_lo]  # (j1 - j0 + d, n_axes)
            out = np.zeros((j1 - j0, held.shape[1]))
            for a, (delays, weights) in enumerate(self.taps):
                for dl, wt in zip(delays, weights, strict=True):  # a few taps, not a loop over ticks
                    out[:, a] += wt * held[d - dl : d - dl + (j1 - j0), a]
            yield j0, out


#: Re-plans of speed-band avoidance on the planned speeds (each lowers the rows a plan left inside a band).
BAND_ITERATIONS = 4


def path_shapers(
    machine: MachineConfig, name: str, f_hz: float | None = None, zeta: float | None = None, per_axis: bool = False
) -> dict[str, Shaper]:
    """The shapers of a job: ``per_axis`` — each axis with modes gets ``name`` for its first mode; otherwise
    (the path) every axis the same shaper, for ``f_hz``/``zeta`` when given, else for the lowest first mode
    of the machine's axes (the same delays on every axis keep straight lines straight)."""
    moded = [a for a in machine.axes if a.modes]
    if per_axis:
        if not moded:
            raise JaxcncError(f"{machine.source}: per-axis shaping needs modes (mode_hz, mode_zeta) in [axes.*]")
        return {a.name: make_shaper(name, *a.modes[0]) for a in moded}
    if f_hz is None or zeta is None:
        if not moded:
            raise JaxcncError(
                f"{machine.source}: no axis has vibration modes (mode_hz, mode_zeta); give the shaper's frequency"
            )
        f0, z0 = min((a.modes[0] for a in moded), key=lambda m: m[0])
        f_hz, zeta = f_hz if f_hz is not None else f0, zeta if zeta is not None else z0
    s = make_shaper(name, f_hz, zeta)
    return {a: s for a in machine.axis_names}


@dataclass(frozen=True)
class DynamicPlan:
    """A job planned for vibration: the planned job, the sampler that writes its table and what was done."""

    job: PlannedJob
    sampler: object  # ShapedSampler or TickSampler
    shapers: dict[str, Shaper]
    bands: BandPlan | None
    n_stops_added: int
    n_feed_caps: int
    tol_mm: float | None
    plan_wall_s: float


def plan_dynamic(
    program: Program,
    machine: MachineConfig,
    shaper: str | None = None,
    *,
    f_hz: float | None = None,
    zeta: float | None = None,
    per_axis: bool = False,
    tol_mm: float | None = None,
    bands: np.ndarray | str | None = None,
    band_width: float = 0.2,
    planner: str | None = None,
) -> DynamicPlan:
    """Plan ``program`` with input shaping (``shaper``: a name of
    :data:`~jaxcnc.planners.shaping.SHAPER_NAMES`, or ``None``) and/or speed-band avoidance (``bands``:
    ``(k, 2)`` mm/s, or ``"auto"``: the machine's modes times the part's repeat lengths, ``± band_width``).
    ``tol_mm``: the contour error allowed to shaping (default the machine's ``corner_tol_mm``)."""
    from jaxcnc.planners import plan_job

    t0 = time.perf_counter()
    band_plan = None
    if isinstance(bands, str):
        if bands != "auto":
            raise JaxcncError(f"speed bands {bands!r}: give 'auto' or LOW-HIGH ranges in mm/s")
        modes = [f for a in machine.axes for f, _ in a.modes]
        if not modes:
            raise JaxcncError(f"{machine.source}: --avoid-bands auto needs modes (mode_hz, mode_zeta) in [axes.*]")
        bands = resonant_bands(modes, repeat_pitches(program), band_width)
    if bands is not None:
        band_plan = avoid_bands(program, machine, np.asarray(bands, np.float64))
        program = band_plan.program
    shapers: dict[str, Shaper] = {}
    stops = caps = 0
    tol = None
    if shaper is not None:
        shapers = path_shapers(machine, shaper, f_hz, zeta, per_axis)
        longest = max(shapers.values(), key=lambda s: s.duration_s)
        prep = shaping_program(program, machine, longest, tol_mm)
        program, stops, caps, tol = prep.program, prep.n_stops_added, prep.n_feed_caps, prep.tol_mm
    job = plan_job(program, machine, planner=planner)
    for _ in range(BAND_ITERATIONS if band_plan is not None else 0):
        peak = row_peak_speeds(job)  # corners and short rows may cruise below the feed, inside a band
        if peak is None:
            break
        again = avoid_bands(program, machine, band_plan.bands, peak)
        if again.n_rows_slowed == 0:
            break
        program = again.program
        band_plan = BandPlan(program, band_plan.bands, band_plan.n_rows_slowed + again.n_rows_slowed)
        job = plan_job(program, machine, planner=planner)
    sampler = ShapedSampler(job, shapers) if shapers else TickSampler(job)
    return DynamicPlan(job, sampler, shapers, band_plan, stops, caps, tol, time.perf_counter() - t0)


def write_dynamic_table(
    dp: DynamicPlan,
    original: Program,
    out: str | Path,
    progress: bool | None = None,
    source_options: dict | None = None,
) -> Path:
    """Write the table of ``dp`` (shaped or not) with its events; the header names ``original``'s file (read
    with ``source_options``, recorded as :func:`jaxcnc.ticks.table.write_table` does) and, for a shaped table,
    the contour error shaping was allowed (``shaping_tol_mm``: the path check allows it at every tick)."""
    from jaxcnc.ticks.sample import machine_axes
    from jaxcnc.ticks.table import job_events, table_meta, write_samples

    job, m = dp.job, dp.job.machine
    events = job_events(job)
    if isinstance(dp.sampler, ShapedSampler):
        events = events.copy()
        events["tick"] = dp.sampler.event_ticks(events["tick"])
        events = events[np.argsort(events["tick"], kind="stable")]
    home = np.array([m.axis(a).home for a in m.axis_names])
    start = machine_axes(job.program.start[:1], np.asarray(job.axis_source), home)[0] if len(job.program) else None
    n_rows = dp.sampler.n_rows
    extra = {}
    if dp.shapers:
        s = next(iter(dp.shapers.values()))
        extra["shaper"] = {
            a: {"name": v.name, "f_hz": v.f_hz, "zeta": v.zeta, "duration_s": v.duration_s}
            for a, v in dp.shapers.items()
        }
        extra["shaper_hold_ticks"] = int(dp.sampler.hold)
        extra["shaping_tol_mm"] = float(dp.tol_mm)
        del s
    if dp.bands is not None:
        extra["speed_bands_mm_s"] = dp.bands.bands.tolist()
    if source_options:
        extra["source_options"] = dict(source_options)
    name = job.planner + ("+" + "/".join(sorted({v.name for v in dp.shapers.values()})) if dp.shapers else "")
    meta = table_meta(
        m, original.file, name, (n_rows - 1) / m.tick_hz, start_mm=start, n_blocks=original.n_blocks, **extra
    )
    return write_samples(out, m, dp.sampler, events, meta, progress)
