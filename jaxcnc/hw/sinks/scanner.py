"""``scanner``: a galvo board's command lists, double-buffered (docs/scanner.md).

Galvo boards (RTC-style) execute **lists** of vector commands at their own 10 µs-class clock: the host loads one
list while the board executes the other, and a list is started only when it is complete (or the job's last one).
This sink does that with lists of ``list_rows`` table rows each:

1. the player fills the loading list (rows, each row's laser power, the pulse events among them);
2. when it is full (or at the end) the rows are **encoded** into timed vectors
   (:func:`jaxcnc.format.vectors.encode_rows`: ``timed_mark`` lit, ``timed_jump`` dark, ``set_laser`` at every
   power change, ``laser_pulse`` at every pulse), the list after the first starting where the previous one ended;
3. the list goes over the "wire" as list-file bytes (checked records, CRC-32) and is read back as the board
   reads it (:func:`~jaxcnc.format.vectors.parse_vectors`);
4. the board **executes** it (:func:`~jaxcnc.format.vectors.execute`, the board's integer interpolation at its
   tick): commanded positions, laser output and pulses per tick. A list whose execution does not reproduce its
   rows tick for tick is refused before it runs (``RuntimeError``: a defect, never a silent deviation).

The emulation's board clock is instant: ``underruns`` counts the waits the player asks for with no complete list
ready. What the board played is recorded: ``recorded`` (positions, int32), ``recorded_power`` (float32) and
``recorded_pulses`` for small tables, and running CRC-32s of both channels (``crc``, ``power_crc``).

The laser: the player's per-row ``power`` when it passes one (``write(..., power=...)``); otherwise the table's
``laser`` events held from row to row (an M4 table's speed scaling is then not in the lists). NumPy only.
"""

from __future__ import annotations

import zlib

import numpy as np

from jaxcnc.errors import JaxcncError
from jaxcnc.format import EventKind, TableHeader
from jaxcnc.format.vectors import PULSE_DTYPE, VectorHeader, encode_rows, execute, parse_vectors, vector_bytes
from jaxcnc.hw.sinks.record import RowRecorder

#: Event kinds that travel in the lists as ``laser_pulse`` records.
_PULSE_KINDS = (EventKind.WORK_PULSE, EventKind.IDLE_PULSE)
#: Keep the played rows in memory up to this many bytes (else only their CRC).
_KEEP_BYTES = 256 << 20


class ScannerSink:
    """Rows encoded into vector lists of ``list_rows`` rows, verified, and executed by an emulated board."""

    def __init__(self, list_rows: int = 8192):
        if list_rows < 2:
            raise JaxcncError(f"scanner sink: list_rows {list_rows} must be at least 2")
        self.list_rows = list_rows
        self._loading: list[tuple[np.ndarray, np.ndarray]] = []
        self._pulses: list[np.ndarray] = []
        self.loaded = 0
        self.ready: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None  # list waiting for the board
        self.executed = -1
        self.lists_run = 0
        self.records_sent = 0  # vector records sent to the board
        self.bytes_sent = 0  # list-file bytes (header, records, CRC)
        self.vectors = 0  # motion commands the board executed
        self.underruns = 0
        self.power_crc = 0  # CRC-32 of every played power value (little-endian float32)
        self._laser = 0.0  # the laser from the events, held between writes
        self._prev: tuple[np.ndarray, float] | None = None  # the last encoded row and its power
        self.recorded: np.ndarray | None = None  # after close, for small tables: every executed row
        self.recorded_power: np.ndarray | None = None
        self.recorded_pulses: np.ndarray | None = None

    @property
    def crc(self) -> int:
        """CRC-32 of every executed row (little-endian int32), like the other sinks' recorders."""
        return self._rec.crc

    def open(self, header: TableHeader) -> None:
        """Prepare for a table: at most 3 axes (a list's ``pos`` fields), the board ticking at the table's rate."""
        if header.n_axes > 3:
            raise JaxcncError(
                f"scanner sink: a galvo board drives at most 3 axes (the beam and focus), the table has "
                f"{header.n_axes}: {', '.join(header.axes)}"
            )
        self.header = header
        self.vh = VectorHeader(float(header.tick_hz), float(header.discrete_mm), tuple(header.axes))
        self.keep = header.n_rows * (header.n_axes * 4 + 4) <= _KEEP_BYTES
        self._rec = RowRecorder(header.n_axes, keep=self.keep)
        self._power_chunks: list[np.ndarray] = []
        self._pulse_chunks: list[np.ndarray] = []

    def free_rows(self) -> int:
        """Room in the list being loaded (none while a complete list waits for the board)."""
        return 0 if self.ready is not None else self.list_rows - self.loaded

    def _power_from_events(self, first_tick: int, n: int, events: np.ndarray) -> np.ndarray:
        """Each row's power from the ``laser`` events among the rows (held from the last one before)."""
        las = events[events["kind"] == EventKind.LASER] if len(events) else events
        out = np.full(n, self._laser, np.float32)
        if len(las):
            at = np.clip(np.asarray(las["tick"], np.int64) - first_tick, 0, n)
            val = np.where(np.asarray(las["aux"]) > 0, np.asarray(las["value"], np.float64), 0.0)
            idx = np.searchsorted(at, np.arange(n), side="right") - 1  # the last event at or before each row
            out = np.where(idx >= 0, val[np.maximum(idx, 0)], self._laser).astype(np.float32)
            self._laser = float(val[-1])
        return out

    def write(self, first_tick: int, rows: np.ndarray, events: np.ndarray, power: np.ndarray | None = None) -> None:
        """Queue ``rows`` for ticks ``first_tick ..`` with their power (or the held ``laser`` events) and pulses."""
        n = rows.shape[0]
        if n > self.free_rows():
            raise RuntimeError("scanner sink: list overflow (the player ignored flow control)")
        pw = self._power_from_events(first_tick, n, events) if power is None else np.asarray(power, np.float32)
        self._loading.append((np.array(rows, dtype=np.int32), pw))
        if len(events):
            pul = events[np.isin(events["kind"], _PULSE_KINDS)]
            if len(pul):
                rel = np.zeros(len(pul), PULSE_DTYPE)
                rel["tick"] = np.asarray(pul["tick"], np.int64) - first_tick + self.loaded  # row in this list
                rel["kind"], rel["aux"], rel["value"] = pul["kind"], pul["aux"], pul["value"]
                self._pulses.append(rel)
        self.loaded += n
        if self.loaded == self.list_rows:
            self._close_list()

    def _close_list(self) -> None:
        """Encode the loaded rows into a list, send it (bytes, CRC) and check that it reproduces them."""
        if not self._loading:
            return
        rows = np.concatenate([r for r, _ in self._loading])
        power = np.concatenate([p for _, p in self._loading]).astype(np.float64)
        pulses = np.concatenate(self._pulses) if self._pulses else np.zeros(0, PULSE_DTYPE)
        self._loading, self._pulses, self.loaded = [], [], 0
        lead = 0
        if self._prev is not None:  # a later list starts where the previous one left the beam
            lead = 1
            rows_e = np.concatenate([self._prev[0][None], rows])
            power_e = np.concatenate([[self._prev[1]], power])
            pulses = pulses.copy()
            pulses["tick"] += 1
        else:
            rows_e, power_e = rows, power
        self._prev = (rows[-1].copy(), float(power[-1]))
        rec = encode_rows(rows_e, power_e, pulses)
        where = f"scanner list {self.lists_run + (self.ready is not None) + 1}"
        data = vector_bytes(rec, self.vh, where)
        _, got = parse_vectors(data, where)  # what the board received
        ex = execute(got, self.vh, where)
        pos = ex.positions[lead:, : rows.shape[1]]
        pw = ex.power[lead:]
        if not (np.array_equal(pos, rows) and np.array_equal(pw, power)):
            m = min(pos.shape[0], rows.shape[0])
            diff = np.flatnonzero(np.any(pos[:m] != rows[:m], axis=1) | (pw[:m] != power[:m]))
            bad = int(diff[0]) if diff.size else m  # else: the execution is longer or shorter than the rows
            raise RuntimeError(f"{where}: the encoded list does not reproduce row {bad} (a defect in the encoder)")
        out_pulses = ex.pulses.copy()
        out_pulses["tick"] -= lead
        self.ready = (pos.astype(np.int32), pw.astype(np.float32), out_pulses, np.array([len(got), len(data)]))
        self.vectors += int(ex.vectors)

    def _run_list(self) -> None:
        """The board executes the ready list (its own clock; instant in the emulation)."""
        (pos, pw, pulses, sizes), self.ready = self.ready, None
        self._rec.append(pos)
        self.power_crc = zlib.crc32(np.ascontiguousarray(pw, "<f4").tobytes(), self.power_crc)
        if self.keep:
            self._power_chunks.append(pw)
            pulses = pulses.copy()
            pulses["tick"] += self.executed + 1
            self._pulse_chunks.append(pulses)
        self.records_sent += int(sizes[0])
        self.bytes_sent += int(sizes[1])
        self.executed += pos.shape[0]
        self.lists_run += 1

    def wait(self) -> None:
        """Let the board run the complete list, if one is ready."""
        if self.ready is not None:
            self._run_list()
        else:
            self.underruns += 1  # the board finished and no complete list was ready

    def executed_tick(self) -> int:
        """The last tick the board executed."""
        return self.executed

    def _finish(self) -> None:
        self.recorded = self._rec.close()
        if self.keep:
            self.recorded_power = np.concatenate(self._power_chunks) if self._power_chunks else np.zeros(0, np.float32)
            self.recorded_pulses = np.concatenate(self._pulse_chunks) if self._pulse_chunks else None

    def abort(self) -> None:
        """Stop now: lists not yet started are discarded (a board stops at the end of the list it runs)."""
        if hasattr(self, "_rec"):
            self._loading, self._pulses, self.loaded, self.ready = [], [], 0, None
            self._finish()

    def close(self) -> None:
        """Send the last (partial) list and run everything to the end."""
        if self.ready is not None:
            self._run_list()
        self._close_list()
        if self.ready is not None:
            self._run_list()
        self._finish()
