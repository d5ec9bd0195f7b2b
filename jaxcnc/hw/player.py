"""The player: streams a verified table file to a sink, keeping its buffer fed.

It never computes motion. It opens the table (which verifies every checksum before anything
moves), then loops: write as many rows as the sink has room for, each with the events that fall
on them, and let the sink's clock run when its buffer is full. Progress is the sink's executed
tick.

Controlled stop (Ctrl-C, or :meth:`Player.request_stop` from another thread): the player stops
reading the table and sends instead a ramp-down along the path from the last row it sent — the
table re-sampled by :class:`~jaxcnc.hw.timewarp.TimeWarp` with its rate going to 0 as fast as the
table's spare acceleration allows — then lets the buffer run out. The drives stop on the path, at
rest, within the acceleration limits, after the rows already buffered plus the hold distance.
"""

from __future__ import annotations

import signal
import threading
import time
from dataclasses import dataclass

import numpy as np

from jaxcnc.hw.sinks.base import Sink
from jaxcnc.hw.tablefile import TableFile
from jaxcnc.hw.timewarp import TimeWarp


@dataclass(frozen=True)
class PlayResult:
    rows_sent: int
    executed_tick: int
    wall_s: float
    table_time_s: float
    stopped: bool = False  # a controlled stop ended the play before the table's end

    @property
    def real_time_factor(self) -> float:
        """Table duration divided by the wall time it took to play (> 1: faster than real time)."""
        return self.table_time_s / self.wall_s if self.wall_s > 0 else float("inf")


def stop_ramp(table: TableFile, a_max: np.ndarray, sent: int) -> np.ndarray:
    """Rows (int32) that bring the motion after table row ``sent - 1`` to rest along the path.

    The table is re-sampled from that row with a rate ramping from 1 to 0 at the spare
    acceleration of every axis (:class:`~jaxcnc.hw.timewarp.TimeWarp`). If the table ends (at
    rest) sooner, its remaining rows are the ramp.
    """
    n = table.n_rows
    warp = TimeWarp(table, a_max)
    warp.tau = float(max(sent - 1, 0))
    warp.command(0.0)
    out = []
    while warp.rate > 0.0 and not warp.done:
        out.append(warp.step())
    rows = np.round(np.asarray(out) / table.header.discrete_mm).astype(np.int32) if out else None
    if warp.done or rows is None or sent + rows.shape[0] > n:
        return table.read_positions(sent, n)
    return rows


class Player:
    """Plays a table into a sink; :meth:`request_stop` asks for a controlled stop (thread-safe)."""

    def __init__(self, table: TableFile, sink: Sink, *, a_max: np.ndarray | None = None, chunk_rows: int = 4096):
        self.table, self.sink, self.a_max, self.chunk_rows = table, sink, a_max, chunk_rows
        self._stop = threading.Event()

    def request_stop(self) -> None:
        self._stop.set()

    def _send(self, first: int, rows: np.ndarray, events: np.ndarray, progress, stoppable: bool = False) -> int:
        """Write ``rows`` for ticks ``first ..`` as the sink makes room, with the events among them.

        Returns the rows written: all of them, or with ``stoppable`` those written before a stop
        was requested (a controlled stop then ramps down from there).
        """
        done = 0
        while done < rows.shape[0]:
            if stoppable and self._stop.is_set() and self.a_max is not None:
                break
            room = self.sink.free_rows()
            if room <= 0:
                self.sink.wait()
                if progress:
                    progress(self.sink.executed_tick() + 1)
                continue
            n = min(room, rows.shape[0] - done)
            lo, hi = np.searchsorted(events["tick"], [first + done, first + done + n])
            self.sink.write(first + done, rows[done : done + n], events[lo:hi])
            done += n
        return done

    def run(self, progress=None) -> PlayResult:
        """Play to the end, or until a stop is requested (then ramp down and stop)."""
        table, sink = self.table, self.sink
        h = table.header
        t0 = time.perf_counter()
        sink.open(h)
        sent = 0
        stopped = False
        try:
            while sent < h.n_rows:
                if self._stop.is_set() and self.a_max is not None:
                    ramp = stop_ramp(table, self.a_max, sent)
                    sent += self._send(sent, ramp, table.events[:0], progress)  # the program's events are not reached
                    stopped = sent < h.n_rows
                    break
                n = min(self.chunk_rows, h.n_rows - sent)
                sent += self._send(sent, table.read_positions(sent, sent + n), table.events, progress, stoppable=True)
        finally:
            sink.close()
        if progress:
            progress(sink.executed_tick() + 1)
        return PlayResult(
            rows_sent=sent,
            executed_tick=sink.executed_tick(),
            wall_s=time.perf_counter() - t0,
            table_time_s=(h.n_rows - 1) / h.tick_hz,
            stopped=stopped,
        )


def play(
    table: TableFile,
    sink: Sink,
    *,
    chunk_rows: int = 4096,
    progress=None,
    a_max: np.ndarray | None = None,
    stop_on_sigint: bool = False,
) -> PlayResult:
    """Play ``table`` into ``sink``; ``progress`` is an optional callable taking executed rows.

    With ``a_max`` (the machine's per-axis limits, table axis order) and ``stop_on_sigint``, Ctrl-C
    makes a controlled stop instead of raising :class:`KeyboardInterrupt`.
    """
    player = Player(table, sink, a_max=a_max, chunk_rows=chunk_rows)
    if not (stop_on_sigint and a_max is not None and threading.current_thread() is threading.main_thread()):
        return player.run(progress)
    previous = signal.signal(signal.SIGINT, lambda *_: player.request_stop())
    try:
        return player.run(progress)
    finally:
        signal.signal(signal.SIGINT, previous)
