"""docs/table-format.md is exact: parse a real table with struct and zlib by the documented offsets."""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np

from jaxcnc.format import TableFile
from tests.conftest import make_machine
from tests.helpers import table_of

DOC = Path(__file__).resolve().parents[1] / "docs" / "table-format.md"


def test_documented_layout(tmp_path):
    _, table, _ = table_of("M3 S50\nG1 X5 Y3 F600\nG2 X10 Y3 R2.5\nM5\n", make_machine(), tmp_path)
    blob = table.path.read_bytes()
    assert blob[:8] == b"JXCNCTBL"
    (version, n_axes, block_rows, flags) = struct.unpack_from("<HHII", blob, 8)
    tick_hz, discrete = struct.unpack_from("<dd", blob, 20)
    n_rows, n_blocks = struct.unpack_from("<QQ", blob, 36)
    (json_bytes,) = struct.unpack_from("<I", blob, 52)
    (n_events,) = struct.unpack_from("<Q", blob, 56)
    (events_crc,) = struct.unpack_from("<I", blob, 64)
    data_offset, events_offset = struct.unpack_from("<QQ", blob, 68)
    (header_crc,) = struct.unpack_from("<I", blob, 124)
    assert blob[84:124] == bytes(40)
    meta = blob[128 : 128 + json_bytes]
    assert zlib.crc32(blob[:124] + meta) == header_crc
    assert json.loads(meta)["axes"] == ["x", "y", "z"]
    assert (version, n_axes, flags) == (2, 3, 3)  # fine and power channels
    assert (tick_hz, discrete) == (10000.0, 0.001)
    assert n_blocks == -(-n_rows // block_rows) and data_offset % 4096 == 0
    assert len(blob) == events_offset + 24 * n_events
    crc = np.frombuffer(blob, "<u4", 3 * n_blocks, data_offset - 12 * n_blocks).reshape(3, n_blocks)
    block_bytes = block_rows * n_axes * 4
    fine_offset = data_offset + n_blocks * block_bytes
    power_offset = fine_offset + n_blocks * block_bytes
    for b in range(n_blocks):
        assert zlib.crc32(blob[data_offset + b * block_bytes : data_offset + (b + 1) * block_bytes]) == crc[0, b]
        assert zlib.crc32(blob[fine_offset + b * block_bytes : fine_offset + (b + 1) * block_bytes]) == crc[1, b]
        at = power_offset + b * block_rows * 4
        assert zlib.crc32(blob[at : at + block_rows * 4]) == crc[2, b]
    assert events_offset == power_offset + n_blocks * block_rows * 4
    pos = np.frombuffer(blob, "<i4", n_rows * n_axes, data_offset).reshape(n_rows, n_axes)
    np.testing.assert_array_equal(pos, table.positions)
    power = np.frombuffer(blob, "<f4", n_rows, power_offset)
    assert set(np.unique(power)) == {0.0, 50.0}  # M3 S50: constant while lit
    np.testing.assert_array_equal(power, table.power)
    ev = blob[events_offset:]
    assert zlib.crc32(ev) == events_crc
    tick, kind, aux, value = struct.unpack_from("<qIId", ev, 24 * 1)
    assert (kind, aux, value) == (2, 3, 50.0)  # laser on, M3, S50 (record 0 is the first block)
    assert TableFile(table.path).events[1]["tick"] == tick


def test_doc_snippet_reads_positions(tmp_path):
    _, table, _ = table_of("G1 X5 F600\n", make_machine(), tmp_path)
    code = DOC.read_text().split("```python")[1].split("```")[0].replace("job.ticks", str(table.path))
    scope: dict = {}
    exec(code, scope)  # noqa: S102 - the documented snippet, run as a firmware writer would
    np.testing.assert_array_equal(scope["pos"], table.positions)
    np.testing.assert_array_equal(scope["power"], table.power)


def test_documented_bounds_are_the_readers_and_plans_record_their_start(tmp_path):
    """The validation table states the reader's bounds; a planned table records where its job starts."""
    from jaxcnc.format import tablefile as tf

    doc = DOC.read_text()
    assert f"| `n_axes` | 1 to {tf.MAX_AXES} |" in doc
    assert f"| `block_rows` | 1 to {tf.MAX_BLOCK_ROWS:,} (2²⁰) |" in doc
    assert tf.TICK_HZ_RANGE == (1.0, 1e6) and "| `tick_hz` | finite, 1 Hz to 1 MHz |" in doc
    assert tf.DISCRETE_MM_RANGE == (1e-9, 0.1) and "| `discrete_mm` | finite, 1e-9 to 0.1 mm |" in doc
    assert tf.MAX_JSON_BYTES == 1 << 20 and "at most 1 MiB" in doc
    machine = make_machine()
    _, table, meas = table_of("G1 X5 Y3 F600\n", machine, tmp_path)
    assert table.header.meta["start_mm"] == [machine.axis(a).home for a in machine.axis_names]
    assert meas.ok and table.exact_mm(0, 1)[0].tolist() == table.header.meta["start_mm"]
