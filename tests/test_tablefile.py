"""The table file: round trip, streaming in any chunk size, every kind of damage refused."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.errors import TableFileError
from jaxcnc.format import EVENT_DTYPE, FINE_SCALE, TableFile, TableWriter


def _write(path, pos, fine, events=None, block_rows=64, chunks=(7, 100, 1)):
    with TableWriter(
        path,
        axes=["x", "y", "z"],
        tick_hz=1000.0,
        discrete_mm=0.001,
        n_rows=pos.shape[0],
        meta={"machine": "m"},
        block_rows=block_rows,
    ) as w:
        i, k = 0, 0
        while i < pos.shape[0]:
            n = chunks[k % len(chunks)]
            w.write(pos[i : i + n], fine[i : i + n])
            i += n
            k += 1
        if events is not None:
            w.events = events
    return path


@pytest.fixture
def data():
    rng = np.random.default_rng(1)
    pos = np.cumsum(rng.integers(-50, 50, (1000, 3)), axis=0).astype(np.int32)
    fine = rng.integers(-(2**31), 2**31 - 1, (1000, 3)).astype(np.int32)
    ev = np.zeros(3, EVENT_DTYPE)
    ev["tick"] = [0, 10, 999]
    ev["kind"] = [1, 2, 6]
    ev["value"] = [0, 55.5, 0]
    return pos, fine, ev


def test_round_trip(tmp_path, data):
    pos, fine, ev = data
    t = TableFile(_write(tmp_path / "a.ticks", pos, fine, ev))
    assert t.n_rows == 1000 and t.axes == ["x", "y", "z"]
    assert t.header.tick_hz == 1000.0 and t.header.meta["machine"] == "m"
    np.testing.assert_array_equal(t.positions, pos)
    np.testing.assert_array_equal(t.fine, fine)
    np.testing.assert_array_equal(t.events, ev)
    np.testing.assert_allclose(t.exact_mm(), (pos + fine / FINE_SCALE) * 0.001)
    assert not (tmp_path / "a.ticks.part").exists()
    # padding of the last block repeats the final row
    raw = np.memmap(tmp_path / "a.ticks", dtype="<i4", mode="r", offset=t.header.data_offset, shape=(1024, 3))
    np.testing.assert_array_equal(raw[1000:], np.repeat(pos[-1:], 24, axis=0))


def test_chunk_sizes_do_not_matter(tmp_path, data):
    pos, fine, ev = data
    a = _write(tmp_path / "a.ticks", pos, fine, ev, chunks=(1000,)).read_bytes()
    b = _write(tmp_path / "b.ticks", pos, fine, ev, chunks=(1, 63, 64, 65)).read_bytes()
    assert a == b


def test_every_damaged_byte_is_refused(tmp_path, data):
    pos, fine, ev = data
    good = _write(tmp_path / "a.ticks", pos, fine, ev).read_bytes()
    t = TableFile(tmp_path / "a.ticks")
    h = t.header
    # a byte in: the fixed header, the JSON metadata, the CRC table, position data, fine data, events
    spots = [9, 130, h.crc_offset + 5, h.data_offset + 700, h.fine_offset + 4000, h.events_offset + 17]
    for spot in spots:
        bad = bytearray(good)
        bad[spot] ^= 0x10
        p = tmp_path / f"bad{spot}.ticks"
        p.write_bytes(bytes(bad))
        with pytest.raises(TableFileError) as info:
            TableFile(p)
        assert str(p) in str(info.value)


def test_damaged_block_is_named(tmp_path, data):
    pos, fine, ev = data
    p = _write(tmp_path / "a.ticks", pos, fine, ev)
    h = TableFile(p).header
    raw = bytearray(p.read_bytes())
    raw[h.data_offset + 3 * h.block_bytes + 1] ^= 1
    p.write_bytes(bytes(raw))
    with pytest.raises(TableFileError, match=r"position block 3 \(ticks 192-255\)"):
        TableFile(p)


def test_truncated_extended_and_foreign_files(tmp_path, data):
    pos, fine, ev = data
    good = _write(tmp_path / "a.ticks", pos, fine, ev).read_bytes()
    for name, blob, needle in [
        ("trunc", good[:-100], "truncated"),
        ("ext", good + b"\0", "truncated or extended"),
        ("foreign", b"G1 X10\n" * 100, "bad magic"),
        ("empty", b"", "bad magic"),
    ]:
        p = tmp_path / f"{name}.ticks"
        p.write_bytes(blob)
        with pytest.raises(TableFileError, match=needle):
            TableFile(p)
    bad = bytearray(good)
    bad[8] = 9  # version 9
    (tmp_path / "v9.ticks").write_bytes(bytes(bad))
    with pytest.raises(TableFileError, match="version 9"):
        TableFile(tmp_path / "v9.ticks")
    with pytest.raises(TableFileError, match="cannot read"):
        TableFile(tmp_path / "missing.ticks")


def test_writer_refuses_wrong_row_counts(tmp_path, data):
    pos, fine, _ = data
    w = TableWriter(tmp_path / "w.ticks", axes=["x", "y", "z"], tick_hz=1e3, discrete_mm=1e-3, n_rows=10)
    with pytest.raises(ValueError):
        w.write(pos[:11], fine[:11])
    w.write(pos[:5], fine[:5])
    with pytest.raises(ValueError, match="announced 10 rows"):
        w.close()
    assert not (tmp_path / "w.ticks").exists() and not (tmp_path / "w.ticks.part").exists()


def test_no_jax_on_the_player_side():
    """hw may not import JAX: a controller that plays tables has only NumPy."""
    import subprocess
    import sys

    code = (
        "import sys; import jaxcnc.format, jaxcnc.hw.player, jaxcnc.hw.sinks, jaxcnc.hw.sinks.stream, "
        "jaxcnc.hw.receiver, jaxcnc.hw.timewarp, jaxcnc.ticks.verify; "
        "print('jax' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
