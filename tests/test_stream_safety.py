"""The stream receiver against hostile and careless peers, and the player's ways out (issue 14).

Each test reproduces a bug found on the receiver and the player: a foreign client injecting rows, an
``END tick=0`` from anyone, a player or receiver restarted mid-job, two players at once, a stalled
socket, the receiver's idle timeout, stop during a feed hold. Real processes over loopback sockets;
every wait is on an event (a recording that grows, a callback) with a generous deadline.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from jaxcnc.hw.player import Player, play
from jaxcnc.hw.receiver import spawn
from jaxcnc.hw.sinks.sim import SimSink
from jaxcnc.hw.sinks.stream import StreamSink
from jaxcnc.hw.stream import DATA, END, HELLO, RESUME, Frame, FramedTCP
from tests.conftest import machine_text, make_machine
from tests.helpers import table_of

pytestmark = pytest.mark.realtime

PROGRAM = "G1 X150 F3000 M3 S800\nM5\nM2\n"  # 3 s at 50 mm/s with the laser on (30k ticks at 10 kHz)


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    folder = tmp_path_factory.mktemp("safety")
    m = make_machine()
    _, table, _ = table_of(PROGRAM, m, folder, "line.ticks")
    (folder / "m.toml").write_text(machine_text())
    a_max = np.array([m.axis(a).a_max for a in table.axes])
    return m, table, a_max, folder / "m.toml"


def _a_max_option(m, a_max) -> str:
    return ",".join(str(x) for x in a_max / m.discrete_mm)


def _rows_recorded(path: Path, n_axes: int) -> int:
    """Rows written so far to a recording in progress (its raw ``.part`` file)."""
    part = path.with_name(path.name + ".part")
    try:
        return part.stat().st_size // (4 * n_axes)
    except FileNotFoundError:
        return 0


def _wait_until(cond, timeout: float = 60.0, what: str = "") -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def _play_cli(table_path, addr, *extra, **kw) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "jaxcnc", "play", str(table_path), "--sink", addr, "-q", *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def _one_line_error(err: str) -> None:
    assert "Traceback" not in err, err
    assert err.count("\n") == 1 and err.startswith("jaxcnc: error: "), err


def _receiver_last_line(err: str) -> str:
    """The receiver's stderr: one-line messages only (refusals, then why it ended); the last one."""
    assert "Traceback" not in err, err
    lines = err.splitlines()
    assert lines and all(ln.startswith("receiver: ") for ln in lines), err
    return lines[-1]


def _summary(out: str) -> dict:
    return json.loads(out.strip().splitlines()[-1])


def _kill(*procs) -> None:
    for p in procs:
        if p is not None and p.poll() is None:
            p.kill()
            p.wait()


class _Intruder:
    """A foreign TCP client of the receiver: it opens its own session attempt and sends frames."""

    def __init__(self, addr: str):
        host, port = addr.split("://")[1].rsplit(":", 1)
        self.link = FramedTCP(socket.create_connection((host, int(port)), timeout=5))

    def hello(self, n_axes: int) -> Frame | None:
        self.link.send(_hello(n_axes))
        return self._reply()

    def _reply(self) -> Frame | None:
        try:
            return self.link.recv(2.0)
        except (ConnectionError, OSError):
            return None

    def send(self, frame: Frame) -> None:
        try:
            self.link.send(frame)
        except OSError:
            pass

    def send_all(self, frames: list[Frame]) -> None:
        """Every frame in one write (the receiver reads them back to back)."""
        data = b"".join(len(b).to_bytes(4, "little") + b for b in (f.encode() for f in frames))
        try:
            self.link.sock.sendall(data)
        except OSError:
            pass

    def close(self) -> None:
        self.link.sock.close()


# The intruder's frames: well formed, with guessed session ids and sequence numbers.
def _hello(n_axes: int) -> Frame:
    return Frame(HELLO, n_axes, seq=1, count=10**6, aux=10_000_000, nonce=1)


def _data(n_axes: int, tick: int, rows: np.ndarray) -> Frame:
    return Frame(DATA, n_axes, session=tick % 7, seq=tick + 2, tick=tick, count=rows.shape[0], rows=rows)


def _end(n_axes: int, tick: int) -> Frame:
    return Frame(END, n_axes, session=1, seq=3, tick=tick)


def _threaded_play(table, sink, progress=None, **kw):
    """Play in a thread; ``(thread, box)`` where ``box`` gets the result or the exception."""
    box: dict = {}

    def run():
        try:
            box["result"] = play(table, sink, progress=progress, **kw)
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            box["error"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t, box


# ---- a foreign client ------------------------------------------------------------------------


def test_a_foreign_client_cannot_inject_rows_or_end_the_job(job, tmp_path):
    """Mid-job, a second TCP client sends HELLO and then, in one burst, a row 1 m off the path for each
    tick from the one the receiver said it needs, and END tick=0 (fifty times over): the receiver
    executes exactly the owner's table."""
    m, table, a_max, _ = job
    n_axes = table.header.n_axes
    rec = tmp_path / "rec.npy"
    proc, addr = spawn("tcp://127.0.0.1:0", "--record", str(rec), "--speed", "2", "--idle-timeout", "20")
    try:
        started = threading.Event()
        sink = StreamSink(addr)
        t, box = _threaded_play(table, sink, progress=lambda done: done > 3000 and started.set())
        assert started.wait(60), box
        bad = np.full((1, n_axes), 1_000_000, np.int32)  # 1 m away
        for i in range(50):  # each time: HELLO, then one row at each tick from the one the receiver needs
            intruder = _Intruder(addr)
            reply = intruder.hello(n_axes)  # (refused, busy: it cannot learn the tick; it guesses)
            base = reply.tick if reply is not None and reply.tick else 2000 + 400 * i
            resume = Frame(HELLO, n_axes, session=i + 1, seq=10**6, aux=10_000_000, nonce=2, flags=RESUME)
            burst = [resume] + [_data(n_axes, tick, bad) for tick in range(base, base + 400)] + [_end(n_axes, 0)]
            intruder.send_all(burst)
            intruder.close()
        t.join(60)
        assert not t.is_alive() and "error" not in box, box
        out, err = proc.communicate(timeout=60)
    finally:
        _kill(proc)
    assert box["result"].executed_tick == table.n_rows - 1
    got = _summary(out)
    assert got["executed"] == table.n_rows
    np.testing.assert_array_equal(np.load(rec), table.positions)  # not one foreign row


def test_a_stranger_that_says_hello_first_does_not_lock_the_player_out(job, tmp_path):
    """Before the player connects, strangers open sessions and never use them: one closes its
    connection at once (its session lapses with it), one keeps it open and silent (its session lapses
    after the handshake time; the player is told to try again and does). The job plays, whole."""
    m, table, a_max, _ = job
    n_axes = table.header.n_axes
    rec = tmp_path / "rec.npy"
    proc, addr = spawn("tcp://127.0.0.1:0", "--record", str(rec), "--speed", "4", "--idle-timeout", "20")
    try:
        quitter = _Intruder(addr)
        welcome = quitter.hello(n_axes)
        assert welcome is not None and welcome.session  # the receiver took it for a player
        quitter.close()
        squatter = _Intruder(addr)
        _wait_until(lambda: squatter.hello(n_axes) is not None, 10, "a WELCOME for the squatter")
        t0 = time.monotonic()
        result = play(table, StreamSink(addr))
        waited = time.monotonic() - t0
        squatter.close()
        out, err = proc.communicate(timeout=60)
    finally:
        _kill(proc)
    assert result.executed_tick == table.n_rows - 1
    assert waited > 0.5  # it did wait for the squatter's session to lapse
    assert "Traceback" not in err and "refused a second player (another session is opening)" in err, err
    got = _summary(out)
    assert got["executed"] == table.n_rows
    np.testing.assert_array_equal(np.load(rec), table.positions)


def test_a_busy_refusal_with_rows_executed_is_final():
    """Unit: a session that has taken its first frame refuses others for good (no retry hint); one
    still opening refuses with the time left to its lapse; one whose connection closed unused lapses."""
    from jaxcnc.hw.receiver import Receiver
    from jaxcnc.hw.stream import decode

    r = Receiver(capacity=4096, a_max_disc_s2=np.full(2, 1e9))
    hello = Frame(HELLO, 2, seq=1, count=10, aux=1_000_000, nonce=5)
    w = decode(r.handle(hello.encode(), "a", now=0.0).data)
    refusal = decode(r.handle(Frame(HELLO, 2, seq=1, count=10, aux=1_000_000, nonce=6).encode(), "b", now=0.5).data)
    assert refusal.text.startswith("busy") and 1000 <= refusal.aux <= 1600
    r.owner_gone("b")  # not the owner: nothing happens
    assert decode(r.handle(Frame(HELLO, 2, seq=1, count=10, aux=1_000_000, nonce=9).encode(), "c", now=0.55).data).aux
    r.owner_gone("a")  # "a" closed its connection without a frame after WELCOME
    w2 = decode(r.handle(Frame(HELLO, 2, seq=1, count=10, aux=1_000_000, nonce=7).encode(), "b", now=0.6).data)
    assert w2.session and w2.session != w.session
    rows = np.zeros((4, 2), np.int32)
    r.handle(Frame(DATA, 2, session=w2.session, seq=2, tick=0, count=4, rows=rows).encode(), "b", now=0.7)
    r.owner_gone("b")  # used: it stays for the player to resume
    final = decode(r.handle(Frame(HELLO, 2, seq=1, count=10, aux=1_000_000, nonce=8).encode(), "c", now=0.8).data)
    assert final.text.startswith("busy") and final.aux == 0


def test_end_from_a_stranger_does_not_end_the_job(job, tmp_path):
    """One frame, ``END tick=0``, from a client of its own before the player connects: the job is
    still played, whole."""
    m, table, a_max, _ = job
    rec = tmp_path / "rec.npy"
    proc, addr = spawn("tcp://127.0.0.1:0", "--record", str(rec), "--speed", "5", "--idle-timeout", "20")
    try:
        intruder = _Intruder(addr)
        intruder.send(_end(table.header.n_axes, 0))
        intruder._reply()
        intruder.close()
        result = play(table, StreamSink(addr))
        out, _ = proc.communicate(timeout=60)
    finally:
        _kill(proc)
    assert result.executed_tick == table.n_rows - 1
    assert _summary(out)["executed"] == table.n_rows
    np.testing.assert_array_equal(np.load(rec), table.positions)


# ---- restarts and a second player ----------------------------------------------------------------


def test_player_restart_mid_job_is_refused_and_the_receiver_stops_safely(job, tmp_path):
    """The player is killed mid-job and started again: the new player is told the receiver is busy
    with another session (exit 2, one line, at once: no livelock); the receiver's drives ramp down on
    the path, its idle timeout ends the job in one line and the recording is complete."""
    m, table, a_max, _ = job
    rec = tmp_path / "rec.npy"
    opts = ("--record", str(rec), "--speed", "1", "--a-max-disc", _a_max_option(m, a_max), "--idle-timeout", "3")
    proc, addr = spawn("tcp://127.0.0.1:0", *opts)
    first = second = None
    try:
        first = _play_cli(table.path, addr)
        _wait_until(lambda: _rows_recorded(rec, 3) > 4000, what="the first player's rows")
        first.send_signal(signal.SIGKILL)
        first.wait()
        second = _play_cli(table.path, addr)
        _, err = second.communicate(timeout=30)
        assert second.returncode == 2, err
        _one_line_error(err)
        assert "busy" in err
        out, rerr = proc.communicate(timeout=30)
    finally:
        _kill(proc, first, second)
    assert proc.returncode == 1 and "no frame from the player" in _receiver_last_line(rerr), rerr
    got = _summary(out)
    assert got["hard_stops"] == 0 and got["at_rest"] and got["laser"] == 0.0
    played = np.load(rec)
    assert 4000 < played.shape[0] < table.n_rows
    np.testing.assert_array_equal(played, table.positions[: played.shape[0]])  # on the path, once, in order


def test_two_players_at_once_the_second_is_refused_cleanly(job, tmp_path):
    m, table, a_max, _ = job
    rec = tmp_path / "rec.npy"
    proc, addr = spawn("tcp://127.0.0.1:0", "--record", str(rec), "--speed", "2", "--idle-timeout", "20")
    first = second = None
    try:
        first = _play_cli(table.path, addr)
        _wait_until(lambda: _rows_recorded(rec, 3) > 2000, what="the first player's rows")
        second = _play_cli(table.path, addr)
        _, err2 = second.communicate(timeout=30)
        _, err1 = first.communicate(timeout=60)
        out, _ = proc.communicate(timeout=30)
    finally:
        _kill(proc, first, second)
    assert second.returncode == 2, err2
    _one_line_error(err2)
    assert "busy" in err2
    assert first.returncode == 0, err1
    assert _summary(out)["executed"] == table.n_rows
    np.testing.assert_array_equal(np.load(rec), table.positions)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_receiver_restart_mid_job_stops_the_player_with_a_clear_error(job, tmp_path):
    m, table, a_max, _ = job
    rec = tmp_path / "rec.npy"
    port = _free_port()
    opts = ("--speed", "1", "--idle-timeout", "5")
    proc, addr = spawn(f"tcp://127.0.0.1:{port}", "--record", str(rec), *opts)
    player = proc2 = None
    try:
        player = _play_cli(table.path, addr)
        _wait_until(lambda: _rows_recorded(rec, 3) > 4000, what="rows executed")
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc2, _ = spawn(f"tcp://127.0.0.1:{port}", *opts)
        t0 = time.monotonic()
        _, err = player.communicate(timeout=30)
        assert time.monotonic() - t0 < 20
    finally:
        _kill(proc, proc2, player)
    assert player.returncode == 2, err
    _one_line_error(err)
    assert "restarted" in err


def test_receiver_gone_mid_job_is_link_loss_with_a_clear_error(job, tmp_path):
    m, table, a_max, _ = job
    rec = tmp_path / "rec.npy"
    proc, addr = spawn("tcp://127.0.0.1:0", "--record", str(rec), "--speed", "1", "--idle-timeout", "5")
    player = None
    try:
        player = _play_cli(table.path, addr)
        _wait_until(lambda: _rows_recorded(rec, 3) > 4000, what="rows executed")
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        _, err = player.communicate(timeout=30)
    finally:
        _kill(proc, player)
    assert player.returncode == 2, err
    _one_line_error(err)
    assert "link lost" in err


# ---- a stalled socket ------------------------------------------------------------------------


def _stalling_receiver(n_axes: int):
    """A receiver that welcomes the player with a huge credit and then never reads: ``(address, stop)``."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    stop = threading.Event()
    conns = []

    def serve():
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                c, _ = srv.accept()
            except OSError:
                continue
            c.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            conns.append(c)
            link = FramedTCP(c)
            try:
                hello = link.recv(5.0)
                link.send(_welcome(hello, n_axes))
            except (OSError, ConnectionError):
                pass  # then read nothing more

    threading.Thread(target=serve, daemon=True).start()

    def close():
        stop.set()
        for c in conns:
            c.close()
        srv.close()

    return f"tcp://127.0.0.1:{srv.getsockname()[1]}", close


def _welcome(hello: Frame, n_axes: int) -> Frame:
    from jaxcnc.hw.stream import WELCOME

    return Frame(WELCOME, n_axes, session=7, seq=1, tick=0, count=10**9, aux=-1, nonce=hello.nonce)


def test_a_stalled_socket_is_link_loss_not_a_traceback(job):
    m, table, a_max, _ = job
    addr, close = _stalling_receiver(table.header.n_axes)
    player = None
    try:
        player = _play_cli(table.path, addr)
        _, err = player.communicate(timeout=60)
    finally:
        _kill(player)
        close()
    assert player.returncode == 2, err
    _one_line_error(err)
    assert "link lost" in err


# ---- the receiver's own ways out -------------------------------------------------------------


def test_receiver_idle_timeout_is_one_line_and_the_recording_is_complete(job, tmp_path):
    m, table, a_max, _ = job
    rec = tmp_path / "rec.npy"
    opts = ("--record", str(rec), "--speed", "10", "--capacity", "8192", "--idle-timeout", "1")
    proc, addr = spawn("tcp://127.0.0.1:0", *opts, "--a-max-disc", _a_max_option(m, a_max))
    try:
        sink = StreamSink(addr)
        sink.open(table.header)
        sink.write(0, table.read_positions(0, 6000), table.events[:0])
        _wait_until(lambda: sink.wait() or sink.acked == 6000, what="the rows acknowledged")
        sink.tcp.sock.close()  # the player vanishes
        out, err = proc.communicate(timeout=30)
    finally:
        _kill(proc)
    assert proc.returncode == 1, err
    assert "no frame" in _receiver_last_line(err), err
    played = np.load(rec)
    assert 0 < played.shape[0] <= 6000
    np.testing.assert_array_equal(played, table.positions[: played.shape[0]])
    got = _summary(out)
    assert got["executed"] == played.shape[0] and got["at_rest"] and got["hard_stops"] == 0


def test_receiver_terminated_by_a_signal_finalises_its_recording(job, tmp_path):
    m, table, a_max, _ = job
    rec = tmp_path / "rec.npy"
    proc, addr = spawn("tcp://127.0.0.1:0", "--record", str(rec), "--speed", "1", "--idle-timeout", "20")
    player = None
    try:
        player = _play_cli(table.path, addr)
        _wait_until(lambda: _rows_recorded(rec, 3) > 3000, what="rows executed")
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
        player.communicate(timeout=30)
    finally:
        _kill(proc, player)
    assert proc.returncode == 143 and "SIGTERM" in _receiver_last_line(err), err
    played = np.load(rec)
    assert played.shape[0] > 3000
    np.testing.assert_array_equal(played, table.positions[: played.shape[0]])


# ---- stop during a feed hold -----------------------------------------------------------------


def test_stop_during_a_hold_ends_at_once(job):
    m, table, a_max, _ = job
    sink = SimSink(buffer_rows=2000, keep=True)
    player = Player(table, sink, a_max=a_max)

    def progress(done: int) -> None:
        if done > 8000 and not player.held:
            player.hold()
        if player.holds and not player._stop.is_set():
            player.request_stop()  # at rest in the hold: stop

    box: dict = {}
    t = threading.Thread(target=lambda: box.setdefault("r", player.run(progress)), daemon=True)
    t.start()
    t.join(30)
    assert not t.is_alive(), "stop during a hold never ended"
    result = box["r"]
    assert result.stopped and result.executed_tick < table.n_rows
    rec = sink.recorded
    assert np.all(rec[-1] == rec[-2])  # at rest
    np.testing.assert_array_equal(rec[:, 1:], np.broadcast_to(table.positions[0, 1:], rec[:, 1:].shape))


def test_stop_during_a_hold_from_the_command_line_exits_130(job, tmp_path):
    m, table, a_max, mfile = job
    rec = tmp_path / "rec.npy"
    cmd = [sys.executable, "-m", "jaxcnc", "play", str(table.path), "--sink", "sim", "--realtime"]
    cmd += ["--record", str(rec), "-m", str(mfile), "-q"]
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_until(lambda: _rows_recorded(rec, 3) > 2000, what="motion")
        proc.stdin.write("hold\n")
        proc.stdin.flush()
        held_at = _rows_recorded(rec, 3)
        _wait_until(lambda: _rows_recorded(rec, 3) > held_at + 20_000, what="the hold")  # the buffer, the ramp
        proc.stdin.write("stop\n")
        proc.stdin.flush()
        _, err = proc.communicate(timeout=30)
    finally:
        _kill(proc)
    assert proc.returncode == 130, err
    assert "controlled stop" in err and "Traceback" not in err
    rows = np.load(rec)
    assert np.all(rows[-1] == rows[-2]) and np.all(np.diff(rows[:, 0]) >= 0)


# ---- the shared key, the version, the address --------------------------------------------------


@pytest.fixture(autouse=True)
def _no_stray_env(monkeypatch):
    monkeypatch.delenv("JAXCNC_STREAM_KEY", raising=False)
    yield


@pytest.mark.parametrize("scheme", ["tcp", "udp"])
def test_a_keyed_session_plays_and_a_wrong_or_missing_key_is_refused(job, tmp_path, scheme):
    """The receiver takes its key from $JAXCNC_STREAM_KEY, the player from --key-file: the job plays
    whole. A player with another key, or none, is refused in one line (exit 2) and moves nothing."""
    m, table, a_max, _ = job
    key = tmp_path / "key"
    key.write_text("correct horse battery staple\n")
    wrong = tmp_path / "wrong"
    wrong.write_text("incorrect horse battery staple")
    rec = tmp_path / "rec.npy"
    env = {**os.environ, "JAXCNC_STREAM_KEY": "correct horse battery staple"}
    proc, addr = spawn(
        f"{scheme}://127.0.0.1:0", "--record", str(rec), "--speed", "10", "--idle-timeout", "20", env=env
    )
    try:
        for extra, what in ((("--key-file", str(wrong)), "shared key"), ((), "shared key")):
            bad = _play_cli(table.path, addr, *extra)
            _, err = bad.communicate(timeout=60)
            assert bad.returncode == 2, err
            _one_line_error(err)
            assert what in err, err
        good = _play_cli(table.path, addr, "--key-file", str(key))
        _, err = good.communicate(timeout=60)
        assert good.returncode == 0, err
        out, rerr = proc.communicate(timeout=30)
    finally:
        _kill(proc)
    got = _summary(out)
    assert got["executed"] == table.n_rows and got["bad_auth"] >= 2
    np.testing.assert_array_equal(np.load(rec), table.positions)


def test_a_short_key_is_refused_in_one_line(job, tmp_path):
    m, table, a_max, _ = job
    key = tmp_path / "key"
    key.write_text("short")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "jaxcnc",
            "play",
            str(table.path),
            "--sink",
            "tcp://127.0.0.1:9",
            "--key-file",
            str(key),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2
    _one_line_error(r.stderr)
    assert "at least 16" in r.stderr


def test_another_protocol_version_is_a_one_line_error_on_both_sides(job):
    """A v1 player's HELLO is refused by the receiver (one line on its stderr); a player talking to a
    board of version 3 says so in one line."""
    import struct
    import zlib

    m, table, a_max, _ = job
    proc, addr = spawn("tcp://127.0.0.1:0", "--idle-timeout", "2")
    try:
        old = struct.pack("<HBBIqIq", 0x4A43, HELLO, 3, 0, 0, 10, 10_000_000)  # the version 1 HELLO
        old += struct.pack("<I", zlib.crc32(old))
        intruder = _Intruder(addr)
        intruder.link.send_bytes(old)
        reply = intruder._reply()
        intruder.close()
        _, err = proc.communicate(timeout=30)
    finally:
        _kill(proc)
    assert reply is not None and reply.type == 7 and "version 2, not 1" in reply.text
    assert "version 1" in err.splitlines()[0] and "Traceback" not in err

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)

    def board_v3():
        c, _ = srv.accept()
        link = FramedTCP(c)
        hello = link.recv(5.0)
        data = bytearray(_welcome(hello, 3).encode())
        data[2] = 3
        data[-4:] = struct.pack("<I", zlib.crc32(bytes(data[:-4])))
        link.send_bytes(bytes(data))
        time.sleep(1.0)
        c.close()

    threading.Thread(target=board_v3, daemon=True).start()
    player = _play_cli(table.path, f"tcp://127.0.0.1:{srv.getsockname()[1]}")
    try:
        _, err = player.communicate(timeout=60)
    finally:
        _kill(player)
        srv.close()
    assert player.returncode == 2
    _one_line_error(err)
    assert "version 3" in err


def test_the_receiver_listens_on_loopback_unless_told_otherwise():
    r = subprocess.run(
        [sys.executable, "-m", "jaxcnc.hw.receiver", "tcp://0.0.0.0:0"], capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "not a loopback address" in r.stderr, r.stderr
    proc, addr = spawn("tcp://0.0.0.0:0", "--allow-network", "--idle-timeout", "0.5")
    out, err = proc.communicate(timeout=30)
    assert addr.startswith("tcp://0.0.0.0:") and proc.returncode == 1 and "no frame from any player" in err
