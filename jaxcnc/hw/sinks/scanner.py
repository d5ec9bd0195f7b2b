"""``scanner``: emulation of a scanner board's command lists (double buffering).

Galvo scanner boards (RTC-style) execute *lists* of commands at their own 10 µs-class clock: the PC
loads one list while the board executes the other, and a list is started only when it is complete
(or the job's last one). This sink does that with lists of ``list_rows`` rows: the player fills the
loading list; when it is full (or at the end) it is handed to the board; the board executes a list
in one go at its clock and then takes the next one (the emulation's board clock is instant, so
``underruns`` only counts waits the player asks for with nothing loaded). Executed rows are
checked by a running CRC and, for small tables, kept.
"""

from __future__ import annotations

import numpy as np

from jaxcnc.format import TableHeader
from jaxcnc.hw.sinks.record import RowRecorder


class ScannerSink:
    def __init__(self, list_rows: int = 8192):
        self.list_rows = list_rows
        self.loading: list[np.ndarray] = []
        self.loaded = 0
        self.ready: np.ndarray | None = None  # the complete list waiting for the board
        self.executed = -1
        self.lists_run = 0
        self.underruns = 0
        self.recorded: np.ndarray | None = None  # after close, for small tables: every executed row

    @property
    def crc(self) -> int:
        return self._rec.crc

    def open(self, header: TableHeader) -> None:
        self.header = header
        self._rec = RowRecorder(header.n_axes, keep=header.n_rows * header.n_axes * 4 <= 256 << 20)

    def free_rows(self) -> int:
        """Room in the list being loaded (none while a complete list waits for the board)."""
        return 0 if self.ready is not None else self.list_rows - self.loaded

    def write(self, first_tick: int, rows: np.ndarray, events: np.ndarray) -> None:
        if rows.shape[0] > self.free_rows():
            raise RuntimeError("scanner sink: list overflow (the player ignored flow control)")
        self.loading.append(np.array(rows, dtype=np.int32))
        self.loaded += rows.shape[0]
        if self.loaded == self.list_rows:
            self._close_list()

    def _close_list(self) -> None:
        if self.loading:
            self.ready = np.concatenate(self.loading)
            self.loading, self.loaded = [], 0

    def _run_list(self) -> None:
        """The board executes the ready list (its own clock; instant in the emulation)."""
        rows, self.ready = self.ready, None
        self._rec.append(rows)
        self.executed += rows.shape[0]
        self.lists_run += 1

    def wait(self) -> None:
        if self.ready is not None:
            self._run_list()
        else:
            self.underruns += 1  # the board finished and no complete list was ready

    def executed_tick(self) -> int:
        return self.executed

    def abort(self) -> None:
        """Stop now: lists not yet started are discarded (a board stops at the end of the list it runs)."""
        if hasattr(self, "_rec"):
            self.loading, self.loaded, self.ready = [], 0, None
            self.recorded = self._rec.close()

    def close(self) -> None:
        self._close_list()
        if self.ready is not None:
            self._run_list()
        self.recorded = self._rec.close()
