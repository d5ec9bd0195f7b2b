"""From a planned job to a table file: sampled, quantised, streamed to disk with its events.

The table is written chunk by chunk (a long job never holds all its ticks in memory). Events:
one ``BLOCK`` per program block at its first tick, ``LASER`` where the beam's power changes
(rapids are dark), and the machine events (dwell, stops, tool change, end) at their ticks.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

import jaxcnc
from jaxcnc.format import EVENT_DTYPE, EventKind, TableWriter, file_sha256, fixed_to_mm
from jaxcnc.geometry.kinds import SpanKind
from jaxcnc.machine import MachineConfig
from jaxcnc.memory import release_free_heap
from jaxcnc.planners.job import PlannedJob
from jaxcnc.program import Event, Kind, LaserMode
from jaxcnc.ticks.laser import LatencyShift, power_of_rows, shift_laser_events
from jaxcnc.ticks.pso import pso_events
from jaxcnc.ticks.sample import CHUNK_TICKS, Sampler, TickSampler, machine_axes, quantize, sampled_ahead

_EVENT_OF = {
    Event.PROGRAM_STOP: EventKind.PROGRAM_STOP,
    Event.OPTIONAL_STOP: EventKind.OPTIONAL_STOP,
    Event.TOOL_CHANGE: EventKind.TOOL_CHANGE,
    Event.PROGRAM_END: EventKind.PROGRAM_END,
    Event.COOLANT: EventKind.COOLANT,
}


def job_events(job: PlannedJob) -> np.ndarray:
    """The event records of a job, sorted by tick (``EVENT_DTYPE``)."""
    prog, spans, plan = job.program, job.spans, job.plan
    rows = spans.block
    tick = plan.span_start_ticks(len(spans))  # where each span starts
    first_of_block = np.concatenate([[True], rows[1:] != rows[:-1]])
    parts = []

    order = []  # program order of each event, to sort events of one tick as the program wrote them

    def add(ticks, kind, aux=0, value=0.0, seg=None):
        e = np.zeros(np.size(ticks), EVENT_DTYPE)
        e["tick"], e["kind"], e["aux"], e["value"] = ticks, kind, aux, value
        parts.append(e)
        order.append(np.broadcast_to(len(rows) if seg is None else seg, e.shape) * 8 + kind)

    b = np.flatnonzero(first_of_block)
    add(tick[b], EventKind.BLOCK, prog.line[rows[b]], rows[b], seg=b)
    # Laser: the beam burns on feed moves and dwells while M3/M4 is on; rapids and events are dark.
    kind = prog.kind[rows]
    lit = (
        (prog.laser[rows] != LaserMode.OFF)
        & ~prog.rapid[rows]
        & ((kind == Kind.LINE) | (kind == Kind.ARC) | (kind == Kind.CURVE) | (kind == Kind.DWELL))
    )
    power = np.where(lit, prog.power[rows], 0.0)
    mode = np.where(lit, prog.laser[rows], 0)
    changed = np.flatnonzero(np.diff(np.concatenate([[0.0], power])) != 0)
    add(tick[changed], EventKind.LASER, mode[changed], power[changed], seg=changed)
    if power.size and power[-1] != 0:
        add(np.int64(plan.n_ticks), EventKind.LASER, 0, 0.0)
    # Feed: where the programmed feed of the moves changes (M4 scales the power by speed / feed).
    moves = np.flatnonzero(((kind == Kind.LINE) | (kind == Kind.ARC) | (kind == Kind.CURVE)) & ~prog.rapid[rows])
    feed = np.where(np.isnan(prog.feed[rows[moves]]), job.machine.path.feed, prog.feed[rows[moves]])
    fc = moves[np.flatnonzero(np.diff(np.concatenate([[0.0], feed])) != 0)]
    add(tick[fc], EventKind.FEED, 0, feed[np.searchsorted(moves, fc)], seg=fc)
    dw = np.flatnonzero((kind == Kind.DWELL) & first_of_block)
    add(tick[dw], EventKind.DWELL, 0, prog.dwell_s[rows[dw]], seg=dw)
    ev = np.flatnonzero((kind == Kind.EVENT) & (spans.kind == SpanKind.POINT))
    for code, ek in _EVENT_OF.items():
        sel = ev[prog.event[rows[ev]] == code]
        add(tick[sel], ek, prog.event_value[rows[sel]], 0.0, seg=sel)
    if job.machine.laser.mode == "pso":
        moving = lit & (spans.kind != SpanKind.POINT)
        pso = pso_events(plan, moving[plan.span], job.machine.laser.pso_mm)
        parts.append(pso)
        order.append(np.full(pso.shape[0], len(rows) * 8 + EventKind.PSO_PULSE))
    out = np.concatenate(parts)
    return out[np.lexsort((np.concatenate(order), out["tick"]))]


def write_samples(
    path: str | Path,
    machine: MachineConfig,
    sampler: Sampler,
    events: np.ndarray,
    meta: dict,
    progress: bool | None = None,
    power: bool = True,
    power_scale=None,
) -> Path:
    """Write a table file from a sampler's chunks of exact machine-axis positions and the events.

    ``progress``: show a progress bar (``None``: only on a terminal). ``power``: write the laser power channel
    (:func:`jaxcnc.ticks.laser.power_of_rows`: M3 constant, M4 scaled with the speed over each tick).
    ``power_scale``: a function of the positions ``(m+1, n_axes)`` of ticks ``first .. first+m`` giving ``(m,)``
    factors on that power (a raster image's level under each tick, :func:`jaxcnc.ticks.raster.raster_levels`).
    With laser latency (``[laser] on_delay_s``/``off_delay_s``) that power is the output wanted of the laser; the
    channel and the ``laser`` events hold the command, early by the delays (:class:`jaxcnc.ticks.laser.LatencyShift`).
    """
    m = machine
    events_out = events  # the programmed laser: what the burn must be
    d_on, d_off = m.laser.delay_ticks(m.tick_hz) if power else (0, 0)
    shift = None
    if d_on or d_off:  # laser latency: the channel and the laser events commanded early (docs/laser.md)
        shift = LatencyShift(d_on, d_off, sampler.n_rows, events, str(meta.get("source", "")), m.tick_hz)
        meta = {**meta, "laser_delay_ticks": [d_on, d_off]}
        events = shift_laser_events(events, d_on, d_off)
        if events.size and events["tick"][0] < 0:  # switched on (at no power: M4 at rest) before the job starts
            shift.too_early(int(events["tick"][0] + d_on))
        las = events[events["kind"] == EventKind.LASER]
        if (bad := np.flatnonzero(np.diff(las["tick"]) <= 0)).size:
            t = int(las["tick"][bad[0] + 1] + (d_on if las["value"][bad[0] + 1] > 0 else d_off))
            shift._fail(t, "the laser is switched off and on again faster than its delays allow")
    with TableWriter(
        path,
        axes=list(m.axis_names),
        tick_hz=m.tick_hz,
        discrete_mm=m.discrete_mm,
        n_rows=sampler.n_rows,
        meta=meta,
        power=power,
    ) as w:
        bar = tqdm(
            total=sampler.n_rows,
            unit="tick",
            unit_scale=True,
            desc="ticks",
            disable=progress is False if progress is not None else None,
            leave=False,
        )
        held: tuple[int, np.ndarray] | None = None  # one chunk back: its power needs the next chunk's first row
        pending: list[tuple[np.ndarray, np.ndarray]] = []  # rows whose command waits for the output ahead of them
        cmd = np.zeros(0, np.float32)

        def flush(more: np.ndarray) -> None:
            nonlocal cmd
            cmd = np.concatenate([cmd, more])
            while pending and pending[0][0].shape[0] <= cmd.size:
                pos, fine = pending.pop(0)
                w.write(pos, fine, cmd[: pos.shape[0]])
                cmd = cmd[pos.shape[0] :]

        def put(first: int, p: np.ndarray, after: np.ndarray) -> None:
            # the chunk and the row after it quantised in one call, padded to one shape for every chunk of every job
            # (elementwise: the same values as apart; a job's last chunk and that row compiled a shape each)
            rows = p.shape[0]
            both = np.zeros((max(rows, CHUNK_TICKS) + 1, p.shape[1]))
            both[:rows], both[rows] = p, after[0]
            q_pos, q_fine = (np.asarray(a) for a in quantize(both, m.discrete_mm))
            pos, fine = q_pos[:rows], q_fine[:rows]
            lit = None
            if power:
                # the laser from the positions as the table holds them, the ones the check reads: a tick on a raster
                # pixel's edge, or an M4 speed, comes out the same for both to the last bit
                pos_a, fine_a = q_pos[rows : rows + 1], q_fine[rows : rows + 1]
                pa = fixed_to_mm(np.vstack([pos, pos_a]), np.vstack([fine, fine_a]), m.discrete_mm)
                lit = power_of_rows(pa, events_out, first, m.tick_hz, m.laser)
                if power_scale is not None:
                    lit = (lit * power_scale(pa)).astype(np.float32)
            if shift is None:
                w.write(np.asarray(pos), np.asarray(fine), lit)
            else:
                pending.append((np.asarray(pos), np.asarray(fine)))
                flush(shift.push(lit))
            bar.update(p.shape[0])

        for first, p in sampled_ahead(sampler):  # the next chunk sampled while this one is written
            p = np.asarray(p)
            if held is not None:
                put(*held, p[:1])
            held = (first, p)
        if held is not None:
            put(*held, held[1][-1:])  # at rest after the last row
        if shift is not None:
            flush(shift.finish())
        bar.close()
        w.events = events
    return Path(path)


def table_meta(
    machine: MachineConfig,
    source: str,
    planner: str,
    total_time_s: float,
    start_mm: np.ndarray | list[float] | None = None,
    **more,
) -> dict:
    """The header metadata every table carries: machine, source (with checksums), generator, and where the
    job starts (``start_mm``, per machine axis; default: each axis' home, where every job starts) — ``check``
    compares the first row with it (``docs/table-format.md``)."""
    if start_mm is None:
        start_mm = [machine.axis(a).home for a in machine.axis_names]
    return {
        "start_mm": [float(v) for v in start_mm],
        "machine": machine.name,
        "machine_file": machine.source,
        "machine_sha256": file_sha256(machine.source),
        "source": source,
        "source_sha256": file_sha256(source),
        "generator": f"jaxcnc {jaxcnc.__version__}",
        "planner": planner,
        "total_time_s": total_time_s,
        **more,
    }


def write_table(
    job: PlannedJob,
    path: str | Path,
    *,
    progress: bool | None = None,
    planner: str | None = None,
    source_options: dict | None = None,
) -> Path:
    """Sample ``job`` at its tick rate and write the table file at ``path``.

    ``progress``: show a progress bar (``None``: only on a terminal). ``planner``: the name the header
    records (default: the planner that planned ``job``). ``source_options``: the options the source was read
    with (:func:`jaxcnc.jobs.source_options`), recorded so that ``check`` reads it again the same way.
    """
    planner = planner or job.planner
    m = job.machine
    start = None  # where the program starts (its first block), on the machine's axes; else the homes
    if len(job.program):
        home = np.array([m.axis(a).home for a in m.axis_names])
        start = machine_axes(job.program.start[:1], np.asarray(job.axis_source), home)[0]
    more = {"source_options": dict(source_options)} if source_options else {}
    image = getattr(job.program, "raster", None)  # a raster image (jaxcnc.io.image.RasterProgram)
    scale = None
    if image is not None:
        from jaxcnc.ticks.raster import axes_xy, raster_levels

        xy = axes_xy(m.axis_names)
        more.update(raster=image.record(), constant_speed_laser=True)

        def scale(p: np.ndarray) -> np.ndarray:
            return raster_levels(image, p, xy)

    meta = table_meta(
        m, job.program.file, planner, job.plan.total_time_s, start_mm=start, n_blocks=job.program.n_blocks, **more
    )
    events = job_events(job)
    if len(job.spans) >= TRIM_SPANS:
        release_free_heap()  # the events' sort and search temporaries, before the tick windows
    return write_samples(path, job.machine, TickSampler(job), events, meta, progress, power_scale=scale)


#: Jobs of at least this many spans hand the heap's free pages back after making their events (the 1 M-block
#: contour's: ~130 MB of temporaries that would stay resident under the tick windows).
TRIM_SPANS = 1 << 18
