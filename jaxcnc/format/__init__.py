"""The neutral file formats between planning and playing: NumPy and the standard library only.

The planning side (:mod:`jaxcnc.ticks`) writes tick tables with these modules and the player side
(:mod:`jaxcnc.hw`) reads them, so a controller that only plays tables needs neither JAX nor anything
else of the planning stack (``docs/player.md``). Nothing here may import JAX, SciPy, matplotlib or a
planning module; a test checks it.

- :mod:`jaxcnc.format.tablefile` — the tick table file v2 (v1 read): header, streamed writer, memory-mapped,
  checksum-verified reader (``docs/table-format.md`` gives the bytes).
- :mod:`jaxcnc.format.events` — the table's event records and their codes.
"""

from __future__ import annotations

from jaxcnc.format.events import EVENT_DTYPE, EventKind
from jaxcnc.format.tablefile import (
    DEFAULT_BLOCK_ROWS,
    FINE_SCALE,
    TableFile,
    TableHeader,
    TableWriter,
    file_sha256,
    fixed_to_mm,
)

__all__ = [
    "DEFAULT_BLOCK_ROWS",
    "EVENT_DTYPE",
    "FINE_SCALE",
    "EventKind",
    "TableFile",
    "TableHeader",
    "TableWriter",
    "file_sha256",
    "fixed_to_mm",
]
