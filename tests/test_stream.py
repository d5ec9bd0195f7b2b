"""The stream protocol over real loopback sockets to a receiver in another process, with faults."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from jaxcnc.format import TableFile, TableWriter
from jaxcnc.hw.player import play
from jaxcnc.hw.receiver import Receiver, spawn
from jaxcnc.hw.sinks.stream import Faults, StreamSink
from jaxcnc.hw.stream import ACK, DATA, HELLO, WELCOME, Frame, ProtocolError, decode


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    n = 30_000
    rng = np.random.default_rng(0)
    pos = np.cumsum(rng.integers(-3, 4, (n, 3)), axis=0).astype(np.int32)
    path = tmp_path_factory.mktemp("s") / "s.ticks"
    with TableWriter(path, axes=["x", "y", "z"], tick_hz=10_000, discrete_mm=0.001, n_rows=n) as w:
        w.write(pos, np.zeros_like(pos))
    return TableFile(path)


def test_frames_round_trip_and_damage_is_detected():
    rows = np.arange(12, dtype=np.int32).reshape(4, 3)
    f = Frame(DATA, 3, session=9, seq=7, tick=100, count=4, rows=rows)
    g = decode(f.encode())
    assert (g.type, g.session, g.seq, g.tick, g.count) == (DATA, 9, 7, 100, 4)
    np.testing.assert_array_equal(g.rows, rows)
    data = bytearray(f.encode())
    for spot in (0, 10, 30, 50, len(data) - 1):
        bad = bytearray(data)
        bad[spot] ^= 0x40
        with pytest.raises(ProtocolError):
            decode(bytes(bad))
    with pytest.raises(ProtocolError):
        decode(bytes(data[:20]))


def _hello(r: Receiver, n_axes: int = 2) -> Frame:
    w = decode(r.handle(Frame(HELLO, n_axes, seq=1, count=10, aux=1_000_000, nonce=5).encode(), "p").data)
    assert (w.type, w.nonce) == (WELCOME, 5) and w.session != 0
    return w


def test_receiver_takes_each_tick_once_in_order():
    r = Receiver(capacity=100)
    s = _hello(r).session
    rows = np.arange(20, dtype=np.int32).reshape(10, 2)

    def data(seq, tick, part):
        return decode(r.handle(Frame(DATA, 2, s, seq, tick, len(part), rows=part).encode(), "p").data)

    assert data(2, 4, rows[4:8]).tick == 0  # a gap: dropped, still needs 0
    ack = data(3, 0, rows[:4])
    assert (ack.type, ack.tick, ack.count) == (ACK, 4, 96)
    assert data(4, 0, rows[:4]).tick == 4  # duplicate: ignored
    assert data(5, 4, rows[4:]).tick == 10
    assert r.stats["gaps"] == 1 and r.stats["duplicates"] == 1


def _run(table, scheme: str, faults: Faults, tmp_path, capacity: int = 4096) -> tuple[dict, dict, np.ndarray]:
    rec = tmp_path / f"rec_{scheme}.npy"
    opts = ("--record", str(rec), "--speed", "20", "--capacity", str(capacity), "--idle-timeout", "20")
    proc, addr = spawn(f"{scheme}://127.0.0.1:0", *opts)
    try:
        sink = StreamSink(addr, faults=faults)
        result = play(table, sink)
        out, _ = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert result.executed_tick == table.n_rows - 1
    return sink.stats, json.loads(out.strip().splitlines()[-1]), np.load(rec)


@pytest.mark.realtime
def test_tcp_with_a_disconnection_mid_job(table, tmp_path):
    sent, got, rec = _run(table, "tcp", Faults(disconnect_after=40), tmp_path)
    assert sent["reconnects"] == 1 and got["reconnects"] == 1
    assert got["executed"] == table.n_rows
    np.testing.assert_array_equal(rec, table.positions)  # every tick executed once, in order


@pytest.mark.realtime
def test_udp_with_loss_duplication_and_reordering(table, tmp_path):
    sent, got, rec = _run(table, "udp", Faults(drop=0.05, duplicate=0.05, reorder=0.05, seed=3), tmp_path)
    assert sent["dropped"] > 0 and sent["duplicated"] > 0 and sent["reordered"] > 0
    assert got["gaps"] > 0  # the faults reached the receiver ...
    assert got["executed"] == table.n_rows
    np.testing.assert_array_equal(rec, table.positions)  # ... and every tick was still executed exactly once


@pytest.mark.realtime
def test_cli_plays_over_tcp(table, tmp_path):
    proc, addr = spawn("tcp://127.0.0.1:0", "--speed", "50")
    try:
        r = subprocess.run(
            [sys.executable, "-m", "jaxcnc", "play", str(table.path), "--sink", addr, "--quiet"],
            capture_output=True,
            text=True,
            timeout=60,
        )
        out, _ = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert r.returncode == 0, r.stderr
    assert json.loads(out.strip().splitlines()[-1])["executed"] == table.n_rows


def test_unreachable_receiver_is_a_clean_error(table):
    from jaxcnc.hw.sinks.stream import LinkError

    sink = StreamSink("tcp://127.0.0.1:9", retries=3, timeout=0.01)
    with pytest.raises(LinkError, match="cannot reach"):
        sink.open(table.header)


def test_scanner_lists_double_buffered(table):
    from jaxcnc.hw.sinks.scanner import ScannerSink

    sink = ScannerSink(list_rows=4096)
    result = play(table, sink, chunk_rows=1000)
    assert result.executed_tick == table.n_rows - 1
    np.testing.assert_array_equal(sink.recorded, table.positions)
    assert sink.lists_run == -(-table.n_rows // 4096)  # only complete lists ran; the last one partial
