"""What a sink's drives executed, row by row: kept in memory, streamed to a ``.npy`` file, or only hashed.

The number of executed rows is not known in advance: a feed hold or an override plays more servo
ticks than the table has rows. Rows are appended; a file recording is written raw while playing
(bounded memory) and given its ``.npy`` header at :meth:`RowRecorder.close`.
"""

from __future__ import annotations

import os
import zlib
from pathlib import Path

import numpy as np


class RowRecorder:
    """Executed rows ``(m, n_axes)`` int32. ``keep``: in memory (small jobs); ``path``: a ``.npy`` file.

    ``crc`` is the running CRC-32 of every row's little-endian bytes, whatever is kept.
    """

    def __init__(self, n_axes: int, path: str | Path | None = None, keep: bool = False):
        self.n_axes, self.path, self.keep = n_axes, Path(path) if path else None, keep
        self.rows = 0
        self.crc = 0
        self._chunks: list[np.ndarray] = []
        self._raw = open(self._raw_path, "wb") if self.path is not None else None  # noqa: SIM115
        self.array: np.ndarray | None = None

    @property
    def _raw_path(self) -> Path:
        return self.path.with_name(self.path.name + ".part")

    def append(self, rows: np.ndarray) -> None:
        data = np.ascontiguousarray(rows, dtype="<i4")
        self.crc = zlib.crc32(data.tobytes(), self.crc)
        self.rows += data.shape[0]
        if self._raw is not None:
            self._raw.write(data.tobytes())
        elif self.keep:
            self._chunks.append(data)

    def close(self) -> np.ndarray | None:
        """Finish the recording; the executed rows (memory-mapped for a file), or ``None`` if only hashed."""
        if self._raw is not None:
            self._raw.close()
            self._raw = None
            out = np.lib.format.open_memmap(self.path, mode="w+", dtype=np.int32, shape=(self.rows, self.n_axes))
            if self.rows:
                raw = np.memmap(self._raw_path, dtype="<i4", mode="r", shape=(self.rows, self.n_axes))
                step = 1 << 20
                for i in range(0, self.rows, step):  # block by block: bounded memory
                    out[i : i + step] = raw[i : i + step]
                del raw
            out.flush()
            os.unlink(self._raw_path)
            self.array = out
        elif self.keep:
            self.array = np.concatenate(self._chunks) if self._chunks else np.zeros((0, self.n_axes), np.int32)
            self._chunks = []
        return self.array
