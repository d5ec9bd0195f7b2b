"""``sim``: in-process virtual drives that execute and record what they receive.

The simulated controller has a FIFO of ``buffer_rows`` rows and a clock at the table's tick
rate. ``wait`` advances the clock: by default virtually (instantly), with ``realtime=True`` in
wall-clock time. Executed rows are recorded (in memory for small tables, into a ``.npy`` file when
asked) together with the events, and always summarised by a running CRC-32, so a table of any
length plays in bounded memory and tests can compare what the drives did with the file.
"""

from __future__ import annotations

import time
import zlib
from collections import deque
from pathlib import Path

import numpy as np

from jaxcnc.hw.tablefile import EVENT_DTYPE, TableHeader


class SimSink:
    """Virtual drives. After ``close``, ``recorded`` holds every executed row in order."""

    def __init__(
        self,
        buffer_rows: int = 16384,
        record: str | Path | None = None,
        realtime: bool = False,
        keep: bool | None = None,
    ):
        self.buffer_rows, self.realtime, self.keep = buffer_rows, realtime, keep
        self.record_path = Path(record) if record else None
        self._fifo: deque[np.ndarray] = deque()
        self._queued = 0
        self._next_tick = 0  # next tick the drives will execute
        self._expected = 0  # next tick the player must send
        self.recorded: np.ndarray | None = None
        self.events: list[np.ndarray] = []
        self.underruns = 0
        self.crc = 0  # CRC-32 of every executed row's bytes, in order (verification without storing)

    def open(self, header: TableHeader) -> None:
        self.header = header
        shape = (header.n_rows, header.n_axes)
        if self.record_path is not None:
            self.recorded = np.lib.format.open_memmap(self.record_path, mode="w+", dtype=np.int32, shape=shape)
        elif self.keep or (self.keep is None and header.n_rows * header.n_axes * 4 <= 256 << 20):
            self.recorded = np.empty(shape, np.int32)  # small tables are kept in memory
        else:
            self.recorded = None  # long tables: only the CRC of what was executed (bounded memory)
        self._t0 = time.perf_counter()

    def free_rows(self) -> int:
        return self.buffer_rows - self._queued

    def write(self, first_tick: int, rows: np.ndarray, events: np.ndarray) -> None:
        if first_tick != self._expected:
            raise RuntimeError(f"sim sink: expected tick {self._expected}, got {first_tick}")
        if rows.shape[0] > self.free_rows():
            raise RuntimeError("sim sink: buffer overflow (the player ignored flow control)")
        self._fifo.append(np.array(rows, dtype=np.int32))
        self._queued += rows.shape[0]
        self._expected += rows.shape[0]
        if events.size:
            self.events.append(np.asarray(events, EVENT_DTYPE))

    def _execute(self, n: int) -> None:
        """The drives take ``n`` rows from the FIFO (one per tick)."""
        while n > 0 and self._fifo:
            head = self._fifo[0]
            take = min(n, head.shape[0])
            if self.recorded is not None:
                self.recorded[self._next_tick : self._next_tick + take] = head[:take]
            self.crc = zlib.crc32(np.ascontiguousarray(head[:take], dtype="<i4").tobytes(), self.crc)
            self._next_tick += take
            self._queued -= take
            n -= take
            if take == head.shape[0]:
                self._fifo.popleft()
            else:
                self._fifo[0] = head[take:]
        if n > 0 and self._next_tick < self.header.n_rows:
            self.underruns += 1

    def wait(self) -> None:
        # Run the clock until half the buffer is free (double buffering).
        n = max(1, self._queued - self.buffer_rows // 2)
        if self.realtime:
            due = self._t0 + (self._next_tick + n) / self.header.tick_hz
            time.sleep(max(0.0, due - time.perf_counter()))
        self._execute(n)

    def executed_tick(self) -> int:
        return self._next_tick - 1

    def close(self) -> None:
        if self.realtime:
            due = self._t0 + (self._next_tick + self._queued) / self.header.tick_hz
            time.sleep(max(0.0, due - time.perf_counter()))
        self._execute(self._queued)
        if self.record_path is not None and self.recorded is not None:
            self.recorded.flush()
