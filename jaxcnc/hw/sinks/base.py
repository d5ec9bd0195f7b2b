"""The sink protocol: where the player puts rows.

A sink models a controller's buffer and clock. The player asks how many rows the sink can take
(``free_rows``: its free buffer, the credits of the stream protocol), writes at most that many,
and lets the sink's clock run (``wait``) when the buffer is full. The sink reports the last tick
its drives executed.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from jaxcnc.format import TableHeader


class Sink(Protocol):
    def open(self, header: TableHeader) -> None:
        """Prepare for a table with this header (axes, tick rate, row count)."""

    def free_rows(self) -> int:
        """Rows the sink's buffer can take now."""

    def write(self, first_tick: int, rows: np.ndarray, events: np.ndarray, power: np.ndarray | None = None) -> None:
        """Queue ``rows`` ``(m, n_axes)`` int32 for ticks ``first_tick ..``, the events among them and (when the
        sink's ``write`` names a ``power`` parameter) each row's laser power ``(m,)`` float32 (docs/laser.md).
        A sink without that parameter gets the events only (the laser held from its ``laser`` events)."""

    def wait(self) -> None:
        """Let the sink's clock run until it has room again (or it is done)."""

    def executed_tick(self) -> int:
        """The last tick the drives executed (-1 before the first)."""

    def close(self) -> None:
        """Run the buffer to its end and release the sink."""

    # Optional: ``abort(self) -> None`` — stop now, on the player's error or a signal: the laser off at
    # once, the drives brought to rest on the path (ramped down within the buffered rows where the sink
    # can, else held), the rows left unexecuted, the recording finished and the sink released; never
    # raises. The player calls it instead of ``close`` on every way out but the normal end; a sink
    # without it is closed.
