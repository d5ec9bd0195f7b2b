"""The player: streams a verified table file to a sink, keeping its buffer fed.

It never computes motion. It opens the table (which verifies every checksum before anything
moves), then loops: write as many rows as the sink has room for, each with the events that fall
on them, and let the sink's clock run when its buffer is full. Progress is the sink's executed
tick.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from jaxcnc.hw.sinks.base import Sink
from jaxcnc.hw.tablefile import TableFile


@dataclass(frozen=True)
class PlayResult:
    rows_sent: int
    executed_tick: int
    wall_s: float
    table_time_s: float

    @property
    def real_time_factor(self) -> float:
        """Table duration divided by the wall time it took to play (> 1: faster than real time)."""
        return self.table_time_s / self.wall_s if self.wall_s > 0 else float("inf")


def play(table: TableFile, sink: Sink, *, chunk_rows: int = 4096, progress=None) -> PlayResult:
    """Play ``table`` into ``sink``; ``progress`` is an optional callable taking executed rows."""
    h = table.header
    events = table.events
    ev_ticks = events["tick"]
    t0 = time.perf_counter()
    sink.open(h)
    sent = 0
    try:
        while sent < h.n_rows:
            room = sink.free_rows()
            if room <= 0:
                sink.wait()
                if progress:
                    progress(sink.executed_tick() + 1)
                continue
            n = min(room, chunk_rows, h.n_rows - sent)
            lo, hi = np.searchsorted(ev_ticks, [sent, sent + n])
            sink.write(sent, table.read_positions(sent, sent + n), events[lo:hi])
            sent += n
    finally:
        sink.close()
    if progress:
        progress(sink.executed_tick() + 1)
    return PlayResult(
        rows_sent=sent,
        executed_tick=sink.executed_tick(),
        wall_s=time.perf_counter() - t0,
        table_time_s=(h.n_rows - 1) / h.tick_hz,
    )
