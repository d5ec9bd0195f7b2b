"""Fuzzing the stream receiver with a hostile client's frames (hypothesis), in process and over TCP.

Between the session owner's valid frames, a hostile client sends random bytes, garbled, truncated and
oversized frames, frames of another session, frames signed with a wrong key or none, replays of the
owner's own frames (also from the owner's address: a spoofed datagram, an injected segment), and
END / STOP / HELLO / resume frames of its own. The receiver must never raise, and the rows it takes
must be exactly the owner's, in order: nothing else is ever accepted. Refusals are one line.

The number of cases run is printed (``pytest -s``) and counted in ``CASES``.
"""

from __future__ import annotations

import json
import os
import random
import socket
import struct
import threading

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxcnc.format import EVENT_DTYPE, EventKind, TableFile, TableWriter
from jaxcnc.hw.player import play
from jaxcnc.hw.receiver import Receiver, spawn
from jaxcnc.hw.sinks.stream import StreamSink
from jaxcnc.hw.stream import (
    DATA,
    END,
    HELLO,
    MAX_FRAME,
    RESUME,
    STOP,
    WELCOME,
    Frame,
    ProtocolError,
    decode,
)

KEY = b"the owner's shared key, 32 bytes"
WRONG = b"a hostile client's guess of it!!"
N_AXES = 3
CASES: dict[str, int] = {"keyed": 0, "unkeyed": 0, "hostile_frames": 0, "tcp_hostile_bytes": 0}


class _Owner:
    """The legitimate player: a session with the receiver, and its valid frames in order."""

    def __init__(self, receiver: Receiver, key: bytes | None, peer="owner"):
        self.r, self.key, self.peer = receiver, key, peer
        self.seq, self.tick = 0, 0
        self.sent: list[bytes] = []  # every valid frame's bytes (for replays)
        self.rows: list[np.ndarray] = []
        self.event_ticks: list[int] = []
        self.rng = np.random.default_rng(0)
        hello = self._frame(Frame(HELLO, N_AXES, count=100, aux=10_000_000, nonce=77))
        welcome = decode(self.r.handle(hello, self.peer, now=0.0).data, key)
        assert welcome.type == WELCOME and welcome.nonce == 77
        self.session = welcome.session

    def _frame(self, f: Frame) -> bytes:
        self.seq += 1
        data = Frame(**{**f.__dict__, "session": getattr(self, "session", 0), "seq": self.seq}).encode(self.key)
        self.sent.append(data)
        return data

    def data(self) -> bytes:
        n = int(self.rng.integers(1, 40))
        rows = self.rng.integers(-1000, 1000, (n, N_AXES)).astype(np.int32)
        ev = np.zeros(1, EVENT_DTYPE)
        ev["tick"], ev["kind"], ev["value"] = self.tick, EventKind.LASER, 100.0
        data = self._frame(Frame(DATA, N_AXES, tick=self.tick, count=n, rows=rows, events=ev))
        self.rows.append(rows)
        self.event_ticks.append(self.tick)
        self.tick += n
        return data

    def resume(self, peer) -> bytes:
        self.peer = peer
        return self._frame(Frame(HELLO, N_AXES, aux=10_000_000, nonce=78, flags=RESUME))


def _hostile(draw, owner: _Owner) -> tuple[bytes, str]:
    """One hostile frame and the peer it comes from (a stranger, or spoofing the owner)."""
    peer = draw(st.sampled_from(["stranger", "stranger2", owner.peer]))
    kind = draw(
        st.sampled_from(
            ["random", "garbled", "truncated", "oversized", "session", "key", "unsigned", "replay", "control"]
        )
    )
    # with a key the session id is no secret (the frames are signed); without one it is the only one
    known = [st.just(owner.session)] if owner.key is not None else []
    sess = draw(st.one_of(*known, st.integers(0, 2**64 - 1).filter(lambda s: s != owner.session)))
    seq = draw(st.one_of(st.integers(0, owner.seq + 5), st.integers(0, 2**64 - 1)))
    tick = draw(st.one_of(st.just(owner.tick), st.integers(-5, owner.tick + 5), st.integers(-(2**63), 2**63 - 1)))
    count = draw(st.integers(1, 40))
    rows = np.full((count, N_AXES), 999_999, np.int32)
    forged = Frame(DATA, N_AXES, session=sess, seq=seq, tick=tick if tick >= 0 else 0, count=count, rows=rows)
    if kind == "random":
        return draw(st.binary(min_size=0, max_size=600)), peer
    if kind in ("garbled", "truncated") and owner.sent:
        data = bytearray(draw(st.sampled_from(owner.sent)))
        if kind == "truncated":
            return bytes(data[: draw(st.integers(0, len(data) - 1))]), peer
        for _ in range(draw(st.integers(1, 4))):
            i = draw(st.integers(0, len(data) - 1))
            data[i] ^= draw(st.integers(1, 255))
        return bytes(data), peer
    if kind == "oversized":
        base = forged.encode(draw(st.sampled_from([None, WRONG])))
        return base + draw(st.binary(min_size=1, max_size=2000)), peer
    if kind == "session":  # signed with the right key but another session: only the owner knows its id
        return Frame(**{**forged.__dict__, "session": sess ^ 1 if sess == owner.session else sess}).encode(
            owner.key
        ), peer
    if kind == "key":
        return forged.encode(WRONG), peer
    if kind == "unsigned":
        return forged.encode(None), peer
    if kind == "replay" and owner.sent:
        return draw(st.sampled_from(owner.sent)), peer
    # control frames of its own: END tick=0, STOP, a HELLO, a resume of the owner's session
    typ = draw(st.sampled_from([END, STOP, HELLO, HELLO]))
    flags = draw(st.sampled_from([0, RESUME]))
    key = draw(st.sampled_from([None, WRONG] + ([owner.key] if owner.key is None else [])))
    f = Frame(typ, N_AXES, session=sess, seq=seq, tick=0, aux=10_000_000, nonce=5, flags=flags if typ == HELLO else 0)
    return f.encode(key), peer


@st.composite
def scenarios(draw, key):
    r = Receiver(capacity=1 << 20, key=key)
    owner = _Owner(r, key)
    steps = []
    for _ in range(draw(st.integers(1, 30))):
        action = draw(st.sampled_from(["owner", "hostile", "hostile", "resume"]))
        if action == "owner":
            steps.append(("owner", owner.data(), owner.peer))
        elif action == "resume" and key is not None:
            peer = f"owner-link-{len(steps)}"
            steps.append(("owner", owner.resume(peer), peer))
        else:
            steps.append(("hostile", *_hostile(draw, owner)))
    return r, owner, steps


def _check(r: Receiver, owner: _Owner, steps) -> None:
    pushed = []
    push = r.clock.push
    r.clock.push = lambda rows: (pushed.append(np.array(rows)), push(rows))
    owner_left = 0
    for i, (who, data, peer) in enumerate(steps):
        if who == "hostile":
            CASES["hostile_frames"] += 1
        # a virtual clock, 1 ms a frame from the owner's HELLO at 0: the whole scenario runs within the
        # handshake's 2 s, however slowly hypothesis and the machine run it (on the wall clock a stranger's
        # HELLO more than 2 s after the owner's would rightly find the unused session lapsed)
        reply = r.handle(data, peer, now=0.001 * (i + 1))  # never raises
        if reply.data is not None:
            f = decode(reply.data, r.key) if r.key and reply.data[4] & 1 else decode(reply.data)
            assert "\n" not in f.text
        if who == "owner":
            owner_left += 1
    got = np.concatenate(pushed) if pushed else np.zeros((0, N_AXES), np.int32)
    want = np.concatenate(owner.rows) if owner.rows else np.zeros((0, N_AXES), np.int32)
    np.testing.assert_array_equal(got, want)  # exactly the owner's rows, in order: nothing else
    assert not r.ended and not r.stopped  # no END or STOP but the owner's (it sent none)
    assert r.session == owner.session
    events = np.concatenate(list(r._events)) if r._events else np.zeros(0, EVENT_DTYPE)
    assert events["tick"].tolist() == owner.event_ticks and np.all(events["value"] == 100.0)


@pytest.mark.slow
@settings(max_examples=1000, deadline=None, suppress_health_check=list(HealthCheck))
@given(scenarios(KEY))
def test_keyed_receiver_accepts_nothing_but_the_owners_frames(scenario):
    """With a shared key every hostile frame, even one sent from the owner's own address, is dropped."""
    CASES["keyed"] += 1
    _check(*scenario)


@pytest.mark.slow
@settings(max_examples=500, deadline=None, suppress_health_check=list(HealthCheck))
@given(scenarios(None))
def test_unkeyed_receiver_accepts_nothing_from_strangers(scenario):
    """Without a key a frame counts only on the owner's link and with its session id: strangers'
    frames (another connection or address) are all dropped, whatever they hold."""
    CASES["unkeyed"] += 1
    r, owner, steps = scenario
    _check(r, owner, [s for s in steps if s[0] == "owner" or s[2] != owner.peer])


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    print(f"\nstream fuzz cases: {json.dumps(CASES)}")


def test_decode_never_raises_anything_but_a_protocol_error():
    rng = random.Random(1)
    base = Frame(DATA, 2, session=1, seq=1, tick=0, count=2, rows=np.zeros((2, 2), np.int32)).encode(KEY)
    for i in range(20_000):
        data = bytearray(base)
        for _ in range(rng.randint(1, 6)):
            data[rng.randrange(len(data))] = rng.randrange(256)
        if i % 3 == 0:
            data = data[: rng.randrange(len(data))]
        for key in (None, KEY):
            try:
                decode(bytes(data), key)
            except ProtocolError as exc:
                assert "\n" not in str(exc)


@pytest.mark.realtime
def test_hostile_tcp_clients_beside_a_real_job(tmp_path):
    """A real receiver process plays a real player's job while hostile clients connect over and over
    with random byte streams: bad length prefixes (0, huge), truncated frames, garbage, half frames
    left hanging, HELLOs and floods of forged frames. The recording equals the table; no traceback."""
    n = 20_000
    rng = np.random.default_rng(5)
    pos = np.cumsum(rng.integers(-3, 4, (n, 3)), axis=0).astype(np.int32)
    path = tmp_path / "j.ticks"
    with TableWriter(path, axes=["x", "y", "z"], tick_hz=10_000, discrete_mm=0.001, n_rows=n) as w:
        w.write(pos, np.zeros_like(pos))
    table = TableFile(path)
    rec = tmp_path / "rec.npy"
    proc, addr = spawn("tcp://127.0.0.1:0", "--record", str(rec), "--speed", "1", "--idle-timeout", "20")
    host, port = addr[6:].rsplit(":", 1)
    stop = threading.Event()
    sent = [0]

    def attack():
        r = random.Random(7)
        while not stop.is_set():
            try:
                s = socket.create_connection((host, int(port)), timeout=2)
            except OSError:
                continue
            try:
                for _ in range(r.randint(1, 20)):
                    choice = r.random()
                    if choice < 0.2:
                        blob = struct.pack("<I", r.choice([0, 1, 3, MAX_FRAME + 1, 2**32 - 1]))
                    elif choice < 0.5:
                        blob = os.urandom(r.randint(0, 300))
                    else:
                        f = Frame(
                            r.choice([HELLO, DATA, END, STOP]),
                            3,
                            session=r.getrandbits(64),
                            seq=r.getrandbits(32),
                            tick=r.randrange(n),
                            count=1,
                            aux=10_000_000,
                            rows=np.full((1, 3), 10**6, np.int32),
                        ).encode()
                        cut = r.choice([len(f), len(f), r.randrange(1, len(f))])
                        blob = struct.pack("<I", len(f)) + f[:cut]
                    s.sendall(blob)
                    sent[0] += len(blob)
            except OSError:
                pass
            finally:
                s.close()

    attacker = threading.Thread(target=attack, daemon=True)
    try:
        attacker.start()
        result = play(table, StreamSink(addr))
        stop.set()
        attacker.join(5)
        out, err = proc.communicate(timeout=60)
    finally:
        stop.set()
        proc.kill()
    CASES["tcp_hostile_bytes"] += sent[0]
    assert result.executed_tick == n - 1
    assert "Traceback" not in err and all(ln.startswith("receiver: ") for ln in err.splitlines()), err
    got = json.loads(out.strip().splitlines()[-1])
    assert got["executed"] == n and got["done"]
    np.testing.assert_array_equal(np.load(rec), table.positions)
    assert sent[0] > 5_000
