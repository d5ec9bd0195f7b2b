"""``sim``: in-process virtual drives that execute and record what they receive.

The simulated controller has a FIFO of ``buffer_rows`` rows and a clock at the table's tick
rate. ``wait`` advances the clock: by default virtually (instantly), with ``realtime=True`` in
wall-clock time — then a player that falls behind makes the buffer run low, and the drives ramp down
along the path within ``a_max`` and wait (:class:`~jaxcnc.hw.drives.DriveClock`); ``underruns``
counts those stops and, with ``trace=True``, ``trace`` holds the drives' position at every tick.
Executed rows are recorded (in memory for small tables, into a ``.npy`` file when asked) together
with the events, and always summarised by a running CRC-32, so a table of any
length plays in bounded memory and tests can compare what the drives did with the file.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from jaxcnc.format import EVENT_DTYPE, EventKind, TableHeader
from jaxcnc.hw.drives import DriveClock
from jaxcnc.hw.laser import LaserOutput
from jaxcnc.hw.sinks.record import RowRecorder


class SimSink:
    """Virtual drives. After ``close``, ``recorded`` holds every executed row in order and ``laser.played`` the
    laser output of each (the table's power channel; dark where the drives ramped: an underrun, an abort)."""

    def __init__(
        self,
        buffer_rows: int = 16384,
        record: str | Path | None = None,
        realtime: bool = False,
        keep: bool | None = None,
        a_max: np.ndarray | None = None,
        trace: bool = False,
    ):
        self.buffer_rows, self.realtime, self.keep = buffer_rows, realtime, keep
        self.a_max_mm = None if a_max is None else np.asarray(a_max, dtype=np.float64)
        self.record_path = Path(record) if record else None
        self._expected = 0  # next tick the player must send
        self.recorded: np.ndarray | None = None  # after close: every executed row, in order (if kept)
        self.events: list[np.ndarray] = []
        self.trace: list[np.ndarray] | None = [] if trace else None
        self._servo = 0  # servo ticks run

    @property
    def crc(self) -> int:
        """CRC-32 of every executed row's bytes, in order (verification without storing)."""
        return self._rec.crc

    @property
    def underruns(self) -> int:
        return self.clock.underruns

    def open(self, header: TableHeader) -> None:
        self.header = header
        small = header.n_rows * header.n_axes * 4 <= 256 << 20  # long tables: only the CRC (bounded memory)
        keep = self.keep or (self.keep is None and small)
        self._rec = RowRecorder(header.n_axes, self.record_path, keep=keep)
        self.laser = LaserOutput(keep=keep)
        a_disc = None if self.a_max_mm is None else self.a_max_mm / header.discrete_mm  # mm/s² -> discretes/s²
        self.clock = DriveClock(header.n_axes, header.tick_hz, a_disc, self.buffer_rows // 4, self.buffer_rows // 2)
        self._t0 = time.perf_counter()

    def free_rows(self) -> int:
        return self.buffer_rows - self.clock.queued

    def write(self, first_tick: int, rows: np.ndarray, events: np.ndarray, power: np.ndarray | None = None) -> None:
        if first_tick != self._expected:
            raise RuntimeError(f"sim sink: expected tick {self._expected}, got {first_tick}")
        if rows.shape[0] > self.free_rows():
            raise RuntimeError("sim sink: buffer overflow (the player ignored flow control)")
        self.clock.push(rows)
        self.laser.push(np.zeros(rows.shape[0], np.float32) if power is None else power)
        self._expected += rows.shape[0]
        if events.size:
            self.events.append(np.asarray(events, EVENT_DTYPE))

    def _execute(self, n: int, ended: bool = False) -> None:
        """Run the drives' clock ``n`` servo ticks."""
        taken, pos = self.clock.run(n, ended, positions=self.trace is not None)
        self._servo += n
        self._rec.append(taken)
        self.laser.take(self.clock.last_lit)
        if self.trace is not None:
            self.trace.append(pos)

    def _sleep_until(self, servo_tick: int) -> None:
        if self.realtime:
            time.sleep(max(0.0, self._t0 + servo_tick / self.header.tick_hz - time.perf_counter()))

    def wait(self) -> None:
        if self.realtime:
            # the clock runs by itself: execute the ticks that are due (at least one)
            due = int((time.perf_counter() - self._t0) * self.header.tick_hz) - self._servo
            if due <= 0:
                self._sleep_until(self._servo + 1)
                due = 1
            self._execute(due)
        else:
            # virtual clock: run until half the buffer is free (double buffering)
            self._execute(max(1, self.clock.queued - self.buffer_rows // 2))

    def executed_tick(self) -> int:
        return self.clock.executed

    def abort(self) -> None:
        """Stop now (the player's error or signal): the laser off at the next tick, the drives ramped
        down on the path within the buffered rows (held at once without ``a_max``), the rows left in
        the buffer never executed, the recording finished."""
        if not hasattr(self, "clock"):
            return
        off = self.clock.executed + 1
        self.events = [e[e["tick"] <= off] for e in self.events]  # what was queued after is never played
        stop = np.zeros(1, EVENT_DTYPE)
        stop["tick"], stop["kind"] = off, EventKind.LASER
        self.events.append(stop)
        self.clock.stop()
        taken, pos = self.clock.run_to_rest(positions=self.trace is not None)
        self._rec.append(taken)
        self.laser.take(np.zeros(taken.shape[0], bool))  # the ramp-down is dark
        self.laser.drop()
        self.laser.finish()
        if self.trace is not None:
            self.trace.append(pos)
        self.recorded = self._rec.close()

    def close(self) -> None:
        while self.clock.queued:  # the rest of the buffer (after a ramp-down, ramping up first)
            left = self.clock.queued
            self._sleep_until(self._servo + left)
            self._execute(left, ended=True)
        self.laser.finish()
        self.recorded = self._rec.close()
