"""The laser output of a controller model: power queued beside the rows, played as the drives take them.

A sink (``sim``, the stream receiver, ``halstreamer``'s model) pushes each row's power (the table's power
channel, ``docs/laser.md``) when it pushes the row, and takes as many values as its drive clock took rows.
A row the clock takes while its rate ramps (an underrun, a stop) is played **dark**: the laser goes off
before the drives slow and stays off until they are back at the planned rate
(:attr:`jaxcnc.hw.drives.DriveClock.last_lit`). What was played is recorded: kept in memory, or only hashed
(a running CRC-32 of the float32 bytes, like :class:`~jaxcnc.hw.sinks.record.RowRecorder`). NumPy only.
"""

from __future__ import annotations

import zlib
from collections import deque

import numpy as np


class LaserOutput:
    """Per-row power in a FIFO beside the drives' rows; ``played`` (after :meth:`finish`) holds what fired."""

    def __init__(self, keep: bool = True):
        self.keep = keep
        self._queue: deque[np.ndarray] = deque()
        self.queued = 0
        self.crc = 0  # CRC-32 of every played value's little-endian float32 bytes, in order
        self.n_played = 0
        self.n_dark = 0  # rows played dark (ramps) that the table lit
        self._chunks: list[np.ndarray] = []
        self.played: np.ndarray | None = None
        self.output = 0.0  # the power at the last row taken

    def push(self, power: np.ndarray) -> None:
        """Queue ``(m,)`` values for the next ``m`` rows."""
        p = np.ascontiguousarray(power, dtype="<f4").reshape(-1)
        if p.size:
            self._queue.append(p)
            self.queued += p.size

    def take(self, lit: np.ndarray) -> np.ndarray:
        """Play the next ``len(lit)`` rows: their power where ``lit``, else 0; ``(m,)`` float32."""
        n = int(lit.size)
        parts = []
        while n > 0 and self._queue:
            head = self._queue[0]
            k = min(n, head.size)
            parts.append(head[:k])
            if k == head.size:
                self._queue.popleft()
            else:
                self._queue[0] = head[k:]
            n -= k
        got = np.concatenate(parts) if parts else np.zeros(0, "<f4")
        got = np.concatenate([got, np.zeros(int(lit.size) - got.size, "<f4")])  # rows pushed without power: dark
        self.queued -= min(self.queued, int(lit.size))
        out = np.where(lit, got, np.float32(0)).astype("<f4")
        self.n_dark += int(((got > 0) & ~lit).sum())
        self.crc = zlib.crc32(out.tobytes(), self.crc)
        self.n_played += out.size
        if out.size:
            self.output = float(out[-1])
        if self.keep:
            self._chunks.append(out)
        return out

    def drop(self) -> None:
        """Forget the rows still queued (a stop: they are never played); the output goes dark."""
        self._queue.clear()
        self.queued = 0
        self.output = 0.0

    def finish(self) -> np.ndarray | None:
        """Every played value in order (when kept)."""
        if self.keep:
            self.played = np.concatenate(self._chunks) if self._chunks else np.zeros(0, "<f4")
            self._chunks = [self.played]
        return self.played
