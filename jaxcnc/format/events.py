"""The table's event records: a fixed 24-byte record and the codes of its ``kind`` field.

Events ride beside the rows of a tick table (block starts, laser power, dwells, stops, pulses);
``docs/table-format.md`` gives their bytes and meaning. NumPy only.
"""

from __future__ import annotations

import numpy as np

#: Event record: tick (int64), kind (uint32), aux (uint32: line, tool, laser mode), value (float64).
EVENT_DTYPE = np.dtype([("tick", "<i8"), ("kind", "<u4"), ("aux", "<u4"), ("value", "<f8")])


class EventKind:
    """Codes of ``EVENT_DTYPE['kind']``."""

    BLOCK = 1  # a program block starts: aux = source line, value = Program row index
    LASER = 2  # laser output changes: value = power (0 = off), aux = mode (0 off, 3 M3, 4 M4)
    PROGRAM_STOP = 3  # M0
    OPTIONAL_STOP = 4  # M1
    TOOL_CHANGE = 5  # M6: aux = tool number
    PROGRAM_END = 6  # M2/M30
    DWELL = 7  # a dwell starts: value = seconds
    COOLANT = 8  # M7/M8/M9 (assist gas): aux = 7, 8 or 9
    WORK_PULSE = 9  # a laser pulse that burns a point: aux = the point's index in its file, value = energy
    IDLE_PULSE = 10  # a pump pulse that burns nothing (keeps the lamp in its window): shutter closed
    SHUTTER = 11  # shutter / strobe state changes: aux = 1 open, 0 closed
    PSO_PULSE = 12  # a position-synchronised pulse: aux = pulse number, value = path length (mm)
    FEED = 13  # (version 2) the programmed feed from here on: value = mm/s (M4 scales power by speed / feed)

    NAMES = {
        1: "block",
        2: "laser",
        3: "program_stop",
        4: "optional_stop",
        5: "tool_change",
        6: "program_end",
        7: "dwell",
        8: "coolant",
        9: "work_pulse",
        10: "idle_pulse",
        11: "shutter",
        12: "pso_pulse",
        13: "feed",
    }
