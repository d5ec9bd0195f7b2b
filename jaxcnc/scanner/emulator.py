"""The board emulator: lists executed at the board tick with two list buffers, and the mirrors' response.

The host loads list ``i + 1`` into the free buffer while the board executes list ``i``; a buffer is free again
when the list in it has been executed. A list whose loading is not complete when the previous one ends is an
**underrun**: the board holds the beam where it is with the laser **off** until it has the list (safe), then goes
on. Loading takes ``load_s(records)`` (default: 40-byte records over a 100 Mbit/s link, the source documents'
link). The result is a table like any other: commanded and actual beam per tick, laser output, pulses.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxcnc.format import EVENT_DTYPE, EventKind, TableWriter
from jaxcnc.format.vectors import VECTOR_DTYPE, Op, VectorHeader, execute
from jaxcnc.scanner.head import HeadModel, simulate


def link_load_s(n_records: int, bits_per_s: float = 100e6) -> float:
    """Seconds to send ``n_records`` records over a link of ``bits_per_s``."""
    return n_records * VECTOR_DTYPE.itemsize * 8 / bits_per_s


@dataclass
class Emulation:
    """Per tick: ``commanded`` and ``actual`` ``(n, 2)`` mm, ``power`` ``(n,)``; ``pulses`` (tick, kind, aux,
    value); ``underrun`` ``(n,)`` True where the board waited for a list; ``list_start_tick`` per list."""

    commanded: np.ndarray
    actual: np.ndarray
    power: np.ndarray
    positions: np.ndarray  # commanded, int discretes (n, 3)
    pulses: np.ndarray
    underrun: np.ndarray
    list_start_tick: np.ndarray
    vectors: int


def emulate(
    rec: np.ndarray,
    header: VectorHeader,
    head: HeadModel | None = None,
    load_s: Callable[[int], float] | None = link_load_s,
) -> Emulation:
    """Execute ``rec`` (one or more lists) as the board does; ``load_s=None``: every list loaded in time."""
    ex = execute(rec, header)
    starts = np.flatnonzero(rec["op"] == Op.LIST_START)
    sizes = np.diff(np.concatenate([starts, [rec.shape[0]]]))
    n_lists = starts.size
    rows = ex.positions.shape[0]
    seg_rows = np.diff(np.concatenate([ex.list_rows, [rows]]))
    seg_rows[0] -= 0  # row 0 belongs to the first list
    dt = header.dt
    gap = np.zeros(n_lists, np.int64)
    if load_s is not None and n_lists:
        load = np.array([np.ceil(load_s(int(k)) / dt) for k in sizes], np.int64)
        # list i loads into the buffer list i-2 used: it starts when list i-1 is loaded and list i-2 is done
        load_end = np.zeros(n_lists, np.int64)
        run_start = np.zeros(n_lists, np.int64)
        run_end = np.zeros(n_lists, np.int64)
        for i in range(n_lists):  # one step per list
            begin = load_end[i - 1] if i else 0
            if i >= 2:
                begin = max(begin, run_end[i - 2])
            load_end[i] = begin + load[i]
            ready = load_end[i]
            run_start[i] = ready if i == 0 else max(run_end[i - 1], ready)
            gap[i] = 0 if i == 0 else run_start[i] - run_end[i - 1]
            run_end[i] = run_start[i] + seg_rows[i]
    # insert the waits: the beam held, the laser off
    insert_at = ex.list_rows[1:] if n_lists > 1 else np.zeros(0, np.int64)
    reps = np.ones(rows, np.int64)
    held = insert_at - 1
    np.add.at(reps, held, gap[1:])
    idx = np.repeat(np.arange(rows), reps)
    underrun = np.zeros(idx.size, bool)
    first_of = np.concatenate([[0], np.cumsum(reps)[:-1]])
    for r, g in zip(held.tolist(), gap[1:].tolist(), strict=True):  # one step per list
        underrun[first_of[r] + 1 : first_of[r] + 1 + g] = True
    positions = ex.positions[idx]
    power = np.where(underrun, 0.0, ex.power[idx])
    new_tick = first_of + (reps - 1) * 0
    pulses = ex.pulses.copy()
    if pulses.size:
        pulses["tick"] = new_tick[pulses["tick"]]
    cmd = positions[:, :2] * header.discrete_mm
    act = simulate(cmd, head or HeadModel(), dt)
    return Emulation(cmd, act, power, positions, pulses, underrun, new_tick[ex.list_rows], ex.vectors)


def write_table(em: Emulation, header: VectorHeader, path: str | Path) -> None:
    """The emulation as a table (version 2): axes x, y (commanded) and xa, ya (actual, rounded), power, pulses."""
    d = header.discrete_mm
    rows = np.concatenate([em.positions[:, :2], np.rint(em.actual / d)], axis=1).astype(np.int32)
    with TableWriter(path, axes=["x", "y", "xa", "ya"], tick_hz=header.tick_hz, discrete_mm=d, n_rows=rows.shape[0],
                     meta={"source": "jaxcnc scanner emulation"}, fine=False, power=True) as w:  # fmt: skip
        w.write(rows, power=em.power.astype(np.float32))
        ev = np.zeros(em.pulses.size, EVENT_DTYPE)
        ev["tick"], ev["kind"], ev["value"] = em.pulses["tick"], em.pulses["kind"], em.pulses["value"]
        ev["aux"] = np.maximum(em.pulses["aux"], 0)
        ch = np.flatnonzero(np.diff(np.concatenate([[0.0], em.power])) != 0)
        las = np.zeros(ch.size, EVENT_DTYPE)
        las["tick"], las["kind"], las["value"] = ch, EventKind.LASER, em.power[ch]
        las["aux"] = np.where(em.power[ch] > 0, 3, 0)
        allev = np.concatenate([ev, las])
        w.events = allev[np.argsort(allev["tick"], kind="stable")]
