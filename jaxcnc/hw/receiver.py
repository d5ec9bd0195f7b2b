"""The reference receiver of the stream protocol: a controller's buffer and clock, in its own process.

    python -m jaxcnc.hw.receiver tcp://127.0.0.1:0 --record executed.npy [--capacity 8192] [--speed 20]

It prints ``listening tcp://HOST:PORT`` once bound, serves one job of one player as
:mod:`jaxcnc.hw.stream` defines (a session opened by a handshake; other clients are refused and
their frames ignored), executes rows at the table's tick rate (``--speed`` times faster for tests),
records each executed row at its tick, and when the job ends prints one JSON line of statistics.
Every tick is executed exactly once and in order: a row is taken only when it is the next one needed.

It listens on loopback unless ``--allow-network`` is given. With a shared key (``--key-file`` or
``$JAXCNC_STREAM_KEY``; never on the command line) every frame must carry its HMAC-SHA256 tag.

Clock: execution starts when the buffer is half full (double buffering) or the job's last row has
arrived. If the buffer runs low before the end (a slow player or a lost link) the drives ramp down
along the path within ``--a-max-disc`` and wait at rest until the buffer is half full again, then ramp
back up (:class:`~jaxcnc.hw.drives.DriveClock`); without ``--a-max-disc`` they can only hold the last row.
The laser (the LASER events the DATA frames carry) is off whenever the drives wait at rest.

Exit status: 0 the job was done; 1 it ended early — the player stopped it (STOP), or no frame came
from the player for ``--idle-timeout`` seconds (the drives ramp down on the path, the laser off);
2 a usage error (bad address, key, options); 128 + N on signal N (the same safe stop). On every way
out the ``--record`` file is written completely and closed, and one line on stderr says why.
"""

from __future__ import annotations

import argparse
import ipaddress
import json
import os
import select
import signal
import socket
import sys
import time
import zlib
from collections import deque
from dataclasses import dataclass

import numpy as np

from jaxcnc.format import EVENT_DTYPE, EventKind
from jaxcnc.hw.drives import DriveClock
from jaxcnc.hw.laser import LaserOutput
from jaxcnc.hw.sinks.record import RowRecorder
from jaxcnc.hw.stream import (
    ACK,
    DATA,
    DONE,
    END,
    HELLO,
    MAX_AXES,
    REFUSED,
    RESUME,
    STOP,
    STOPPED,
    VERSION,
    WELCOME,
    AuthError,
    Frame,
    FramedTCP,
    FramingError,
    ProtocolError,
    ReplayWindow,
    VersionError,
    decode,
    load_key,
    parse_address,
)

HANDSHAKE_S = 2.0  # a session opened but not yet used, and a connection that has not said HELLO, expire
MAX_CONNECTIONS = 8  # connections held at once (the owner's and those still to say who they are)
KEEPALIVE_S = 0.05  # an ACK to the owner after this much silence, or when room has grown by 1/8
MAX_LOG_LINES = 20  # refusals reported on stderr (then only counted)


@dataclass
class Reply:
    """What the transport does after a frame: send ``data`` back, make the peer the owner, close it."""

    data: bytes | None = None
    owner: bool = False
    close: bool = False


class Receiver:
    """The controller model and its session. ``a_max_disc_s2``: per-axis limits in discretes/s² (enables
    ramp-downs); ``key``: the shared key (frames must carry its tag)."""

    def __init__(
        self,
        capacity: int = 8192,
        speed: float = 1.0,
        record: str | None = None,
        a_max_disc_s2: np.ndarray | None = None,
        key: bytes | None = None,
        log=None,
    ):
        self.capacity, self.speed, self.record_path, self.a_max_disc_s2 = capacity, speed, record, a_max_disc_s2
        self.key = key
        self.log = log if log is not None else (lambda line: None)
        self.session: int | None = None
        self.state = "idle"  # idle -> pending (WELCOME sent) -> active (the owner's first frame) -> ended
        self.owner = None  # the transport's handle of the owner (a connection, an address)
        self.nonce = 0
        self.opened_at = 0.0
        self.window = ReplayWindow()
        self.seq = 0  # frames sent in the session
        self.next_tick = 0
        self.n_rows: int | None = None
        self.n_axes = 0
        self.tick_hz = 1.0
        self.ended = False
        self.stopped = False  # the player's STOP (or the receiver's own stop): ramped down for good
        self.running = False
        self.t0 = 0.0
        self.servo0 = 0  # servo ticks run before the clock (re)started
        self.servo = 0  # servo ticks run
        self.clock: DriveClock | None = None
        self.recorder: RowRecorder | None = None
        self._events: deque[np.ndarray] = deque()
        self.laser_cmd = 0.0  # the laser power the table commands at the executed tick
        self.power = LaserOutput(keep=False)  # the power channel: queued beside the rows, played, hashed
        self.power_seen = False  # the player sends the power channel (DATA frames with POWER)
        self.events_crc = 0  # CRC-32 of every executed event record, in order
        self.events_run = 0
        self._power_chunks: list[np.ndarray] | None = [] if record else None
        self._event_chunks: list[np.ndarray] | None = [] if record else None
        self.last_owner_frame = time.monotonic()
        self.stats = {
            "frames": 0,
            "duplicates": 0,
            "gaps": 0,
            "bad_frames": 0,
            "bad_auth": 0,
            "replayed": 0,
            "foreign": 0,
            "refused": 0,
            "reconnects": 0,
            "laser_events": 0,
        }
        self._logged = 0

    # ---- state --------------------------------------------------------------------------------
    @property
    def executed(self) -> int:
        return self.clock.executed if self.clock is not None else -1

    @property
    def queued(self) -> int:
        return self.clock.queued if self.clock is not None else 0

    @property
    def done(self) -> bool:
        return self.ended and self.n_rows is not None and self.executed == self.n_rows - 1

    @property
    def at_rest(self) -> bool:
        return self.clock is None or self.clock.at_rest

    @property
    def laser(self) -> float:
        """The laser output: the power channel as played (dark while the drives ramp or wait); for a player that
        sends no power, the table's command — off while the drives wait at rest and after a stop."""
        if self.stopped or (self.clock is not None and self.clock.rate == 0.0 and not self.done):
            return 0.0
        if self.power_seen:
            return 0.0 if self.done else self.power.output
        return self.laser_cmd

    def free(self) -> int:
        return self.capacity - self.queued

    def _say(self, line: str) -> None:
        if self._logged < MAX_LOG_LINES:
            self.log(line)
        self._logged += 1

    # ---- frames -------------------------------------------------------------------------------
    def reply(self, typ: int, **kw) -> bytes:
        """A frame of the session (WELCOME, ACK, DONE, STOPPED), signed with the key if there is one:
        the next tick needed, the free rows (the player's credit), the last executed tick, the underruns."""
        self.seq += 1
        fields = {
            "n_axes": self.n_axes,
            "session": self.session or 0,
            "seq": self.seq,
            "tick": self.next_tick,
            "count": self.free(),
            "aux": self.executed,
            "underruns": self.clock.underruns if self.clock is not None else 0,
        }
        fields.update(kw)
        return Frame(typ, **fields).encode(self.key)

    def refuse(self, text: str, signed: bool, retry_ms: int = 0) -> Reply:
        """A REFUSED frame; ``retry_ms`` > 0 says the refusal is transient (a session still opening that
        has moved nothing): the player may try again after that long."""
        self.stats["refused"] += 1
        frame = Frame(REFUSED, session=0, seq=0, aux=retry_ms, text=text)
        return Reply(frame.encode(self.key if signed else None), close=True)

    def handle(self, data: bytes, peer, now: float | None = None) -> Reply:
        """Take one frame's bytes from ``peer``; what to answer. Never raises for any input."""
        now = time.monotonic() if now is None else now
        self.stats["frames"] += 1
        try:
            f = decode(data, self.key)
        except VersionError as exc:
            self.stats["bad_frames"] += 1
            self._say(f"receiver: refused a player of stream protocol version {exc.version} (this receiver: {VERSION})")
            return self.refuse(f"this receiver speaks stream protocol version {VERSION}, not {exc.version}", False)
        except AuthError as exc:
            self.stats["bad_auth"] += 1
            if len(data) > 3 and data[3] == HELLO and peer != self.owner:
                self._say(f"receiver: refused a player: {exc}")
                return self.refuse(f"shared key: {exc}", False)
            return Reply(close=peer != self.owner)
        except ProtocolError:
            self.stats["bad_frames"] += 1
            return Reply(close=peer != self.owner)
        if f.type == HELLO:
            return self._hello(f, peer, now)
        if self.session is None or f.session != self.session or peer != self.owner:
            self.stats["foreign"] += 1  # not the session's owner: ignored
            return Reply(close=peer != self.owner)
        if not self.window.fresh(f.seq):
            self.stats["replayed"] += 1
            return Reply()
        self.last_owner_frame = now
        if self.state == "pending":
            self.state = "active"
        if f.type == DATA:
            self._data(f)
            self.run_clock(now)  # the ticks due now take these rows too: the credit sent back counts them
            return Reply(self.reply(ACK))
        if f.type == END:
            if not self.ended and f.tick == self.next_tick:  # every row in: the job's true length
                self.ended, self.n_rows = True, f.tick
            elif not self.ended:
                self.stats["bad_frames"] += 1  # an END that does not follow the rows: ignored
            return Reply(self.reply(DONE if self.done else ACK))
        if f.type == STOP:
            self.stop(now)
            return Reply(self.reply(STOPPED))
        self.stats["bad_frames"] += 1  # a board's frame type from the player
        return Reply()

    def _hello(self, f: Frame, peer, now: float) -> Reply:
        if f.flags & RESUME:
            if self.session is None or f.session != self.session or self.state == "idle":
                self._say("receiver: refused a player resuming a session this receiver does not hold")
                return self.refuse(
                    "this receiver does not hold that session (it restarted?): the job cannot resume", True
                )
            if not self.window.fresh(f.seq):
                self.stats["replayed"] += 1
                return Reply(close=peer != self.owner)
            self.stats["reconnects"] += peer != self.owner
            self.owner, self.last_owner_frame = peer, now
            return Reply(self.reply(WELCOME, nonce=f.nonce), owner=True)
        if self.state == "pending" and now - self.opened_at > HANDSHAKE_S and self.n_rows is None:
            self._lapse()  # a WELCOME nobody answered
        if self.state == "pending" and peer == self.owner and f.nonce == self.nonce:
            return Reply(self.reply(WELCOME, nonce=f.nonce), owner=True)  # the same HELLO again (UDP)
        if self.state == "pending":
            # another client opened a session and has not used it yet: nothing moved, it lapses soon
            left_ms = max(1, round((HANDSHAKE_S - (now - self.opened_at)) * 1000))
            self._say("receiver: refused a second player (another session is opening)")
            return self.refuse("busy: another player's session is opening; try again", True, retry_ms=left_ms)
        if self.state != "idle":
            self._say(f"receiver: refused a second player (busy with a job, {self.executed + 1} ticks executed)")
            return self.refuse(
                f"busy: this receiver is playing another player's job ({self.executed + 1} ticks executed); "
                "one job at a time",
                True,
            )
        if not 1 <= f.n_axes <= MAX_AXES or f.aux <= 0:
            self.stats["bad_frames"] += 1
            return self.refuse("HELLO out of range (axes 1-32, a positive tick rate)", True)
        self.session = int.from_bytes(os.urandom(8), "little") or 1
        self.state, self.owner, self.nonce, self.opened_at = "pending", peer, f.nonce, now
        self.window = ReplayWindow()
        self.window.fresh(f.seq)
        self.last_owner_frame = now
        # a new session starts from scratch (an earlier one that lapsed never took a row)
        if self.recorder is not None:
            self.recorder.close()
        self.n_axes, self.tick_hz = f.n_axes, f.aux / 1000.0
        reserve = self.capacity // 4
        self.clock = DriveClock(self.n_axes, self.tick_hz, self.a_max_disc_s2, reserve, self.capacity // 2)
        self.recorder = RowRecorder(self.n_axes, self.record_path)
        self.power, self.power_seen, self.events_crc, self.events_run = LaserOutput(keep=False), False, 0, 0
        if self.record_path:
            self._power_chunks, self._event_chunks = [], []
        return Reply(self.reply(WELCOME, nonce=f.nonce), owner=True)

    def owner_gone(self, peer) -> None:
        """``peer``'s connection closed. If it owns a session it opened but never used, the session
        lapses at once (nothing moved, nothing is lost); a used one stays, for the player to resume."""
        if peer == self.owner and self.state == "pending":  # pending: no frame of the owner since WELCOME
            self._lapse()

    def _lapse(self) -> None:
        """The session ends before anything of it was taken: the receiver is idle again."""
        self.session, self.state, self.owner = None, "idle", None

    def _data(self, f: Frame) -> None:
        if self.ended or self.stopped or f.n_axes != self.n_axes:
            self.stats["bad_frames"] += 1
        elif f.tick == self.next_tick and f.count <= self.free():
            self.clock.push(np.array(f.rows))
            if f.power is not None:
                self.power_seen = True
            self.power.push(np.zeros(f.count, np.float32) if f.power is None else f.power)
            if f.events is not None and len(f.events):
                self._events.append(np.array(f.events))
            self.next_tick += f.count
        elif f.tick < self.next_tick:
            self.stats["duplicates"] += 1
        else:
            self.stats["gaps"] += 1

    # ---- the clock ----------------------------------------------------------------------------
    def _apply_events(self) -> None:
        while self._events and self._events[0]["tick"][0] <= self.executed:
            ev = self._events[0]
            k = int(np.searchsorted(ev["tick"], self.executed, side="right"))
            run = ev[:k]
            self.events_crc = zlib.crc32(np.ascontiguousarray(run).tobytes(), self.events_crc)
            self.events_run += k
            if self._event_chunks is not None:
                self._event_chunks.append(np.array(run))
            laser = ev[:k][ev["kind"][:k] == EventKind.LASER]
            if laser.size:
                self.laser_cmd = float(laser["value"][-1])
                self.stats["laser_events"] += laser.size
            if k == len(ev):
                self._events.popleft()
            else:
                self._events[0] = ev[k:]
                break

    def run_clock(self, now: float) -> None:
        """Run the servo ticks that are due: rows are taken (or ramped down on) by the drive clock."""
        if self.clock is None or self.done or self.stopped:
            return
        all_in = self.ended and self.next_tick >= self.n_rows  # END told the job's length: every row is in
        if not self.running:
            if self.queued >= self.capacity // 2 or (all_in and self.queued):
                self.running, self.t0, self.servo0 = True, now, self.servo
            return
        due = self.servo0 + int((now - self.t0) * self.tick_hz * self.speed) - self.servo
        if due <= 0:
            return
        taken, _ = self.clock.run(due, all_in, positions=False)
        self.servo += due
        self.recorder.append(taken)
        self._play_power(self.clock.last_lit)
        self._apply_events()

    def _play_power(self, lit: np.ndarray) -> None:
        played = self.power.take(lit)
        if self._power_chunks is not None:
            self._power_chunks.append(played)

    def stop(self, now: float | None = None) -> None:
        """Stop for good: the laser off at once, the drives ramped down on the path within the buffer."""
        if self.stopped or self.clock is None:
            self.stopped = True
            return
        if now is not None:
            self.run_clock(now)
        self.stopped = True
        if not self.running:
            self.clock.rate = 0.0  # the clock never started: the drives stand at the first row
        if not self.done:
            self.clock.stop()
            taken, _ = self.clock.run_to_rest()
            self.recorder.append(taken)
            self._play_power(np.zeros(taken.shape[0], bool))  # the ramp-down is dark
        self.power.drop()
        self._apply_events()

    def summary(self) -> dict:
        """Statistics; finishes the recording (call once, on every way out)."""
        if self.recorder is not None:
            self.recorder.close()
            self.recorder = None
            if self._power_chunks is not None:  # beside the rows: NAME.power.npy and NAME.events.npy
                base = str(self.record_path).removesuffix(".npy")
                np.save(base + ".power.npy", np.concatenate(self._power_chunks or [np.zeros(0, "<f4")]))
                np.save(base + ".events.npy", np.concatenate(self._event_chunks or [np.zeros(0, EVENT_DTYPE)]))
                self._power_chunks = self._event_chunks = None
        c = self.clock
        drives = {"underruns": c.underruns, "hard_stops": c.hard_stops, "held_ticks": c.held_ticks} if c else {}
        return {
            "executed": self.executed + 1,
            "n_rows": self.n_rows,
            "done": self.done,
            "at_rest": self.at_rest,
            "laser": self.laser,
            "power_crc": self.power.crc,
            "power_played": self.power.n_played,
            "dark_rows": self.power.n_dark,
            "events_crc": self.events_crc,
            "events_run": self.events_run,
            **self.stats,
            **drives,
        }


class Stopped(Exception):
    """The receiver ended before the job was done (idle timeout, the player's STOP, a signal)."""

    def __init__(self, message: str, status: int):
        super().__init__(message)
        self.status = status


def _bind(scheme: str, host: str, port: int, allow_network: bool) -> socket.socket:
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM if scheme == "tcp" else socket.SOCK_DGRAM)
    except socket.gaierror as exc:
        raise ValueError(f"cannot resolve {host!r}: {exc.strerror}") from None
    family, kind, _, _, addr = infos[0]
    ip = ipaddress.ip_address(addr[0].split("%")[0])
    if not ip.is_loopback and not allow_network:
        raise ValueError(
            f"{host} is not a loopback address: the receiver listens on loopback unless --allow-network is "
            "given (then set a shared key: --key-file or $JAXCNC_STREAM_KEY)"
        )
    srv = socket.socket(family, kind)
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        srv.bind(addr)
    except OSError as exc:
        srv.close()
        raise ValueError(f"cannot listen on {scheme}://{host}:{port}: {exc.strerror or exc}") from None
    if scheme == "tcp":
        srv.listen(MAX_CONNECTIONS)
    return srv


class _Signals:
    """SIGTERM, SIGINT and SIGHUP set a flag the loop reads (nothing is interrupted half-done)."""

    def __init__(self):
        self.got: int | None = None
        self.previous = {}

    def __enter__(self):
        for s in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
            try:
                self.previous[s] = signal.signal(s, self._on)
            except ValueError:  # not the main thread
                pass
        return self

    def _on(self, signum, _frame) -> None:
        self.got = signum

    def __exit__(self, *exc):
        for s, h in self.previous.items():
            signal.signal(s, h)


def serve(
    spec: str,
    receiver: Receiver,
    idle_timeout: float = 30.0,
    out=sys.stdout,
    allow_network: bool = False,
) -> dict:
    """Run the receiver on ``tcp://HOST:PORT`` or ``udp://HOST:PORT`` until the job ends.

    Returns the summary when the job is done; raises :class:`Stopped` (the summary in ``.summary``)
    when it ends otherwise. The recording is finished on every way out.
    """
    scheme, host, port = parse_address(spec)
    srv = _bind(scheme, host, port, allow_network)
    bound = srv.getsockname()
    shown = f"[{bound[0]}]" if ":" in bound[0] else bound[0]
    print(f"listening {scheme}://{shown}:{bound[1]}", file=out, flush=True)
    conns: dict[socket.socket, tuple[FramedTCP, float]] = {}  # connection -> (link, accepted at)
    owner_sock: socket.socket | None = None
    udp_owner = None
    started = time.monotonic()
    done_at = None  # when DONE (or STOPPED) was last sent: linger a little for late retries, then exit
    last_reply = 0.0
    free_at_reply = 0
    stop: Stopped | None = None

    def drop(sock: socket.socket) -> None:
        nonlocal owner_sock
        link, _ = conns.pop(sock, (None, 0))
        if link is not None:
            link.close()
        if sock is owner_sock:
            owner_sock = None  # link lost: the buffer keeps running; the player may resume
            receiver.owner_gone(sock)

    def send(sock_or_addr, data: bytes) -> bool:
        try:
            if scheme == "tcp":
                conns[sock_or_addr][0].send_bytes(data)
            else:
                srv.sendto(data, sock_or_addr)
            return True
        except (OSError, KeyError):
            if scheme == "tcp":
                drop(sock_or_addr)
            return False

    def take(data: bytes, peer, sock) -> None:
        nonlocal owner_sock, udp_owner, done_at, last_reply, free_at_reply, stop
        now = time.monotonic()
        receiver.run_clock(now)
        r = receiver.handle(data, peer, now)
        if r.owner:
            if scheme == "tcp" and owner_sock is not None and owner_sock is not sock:
                drop(owner_sock)
            if scheme == "tcp":
                owner_sock = sock
            else:
                udp_owner = peer
        if r.data is not None:
            send(sock if scheme == "tcp" else peer, r.data)
            if peer == receiver.owner:
                last_reply, free_at_reply = now, receiver.free()
        if r.close and scheme == "tcp" and sock is not owner_sock:
            drop(sock)
        if receiver.done or receiver.stopped:
            done_at = done_at or now

    with _Signals() as sig:
        try:
            while True:
                now = time.monotonic()
                receiver.run_clock(now)
                if sig.got is not None:
                    name = signal.Signals(sig.got).name
                    stop = Stopped(f"receiver: {name}", 128 + sig.got)
                    break
                if done_at is not None and now - done_at > 0.5:
                    break
                if receiver.done and done_at is None:
                    done_at = now
                    owner_peer = owner_sock if scheme == "tcp" else udp_owner
                    if owner_peer is not None:  # the last row ran: say so now, not at the player's next END
                        send(owner_peer, receiver.reply(DONE))
                silent = now - (receiver.last_owner_frame if receiver.session is not None else started)
                if done_at is None and silent > idle_timeout:
                    who = "the player" if receiver.session is not None else "any player"
                    stop = Stopped(f"receiver: no frame from {who} for {idle_timeout:g} s", 1)
                    break
                # keep the owner informed: room freed, or a keepalive
                owner_peer = owner_sock if scheme == "tcp" else udp_owner
                if receiver.state == "active" and owner_peer is not None and done_at is None:
                    if now - last_reply > KEEPALIVE_S or receiver.free() - free_at_reply >= receiver.capacity // 8:
                        send(owner_peer, receiver.reply(ACK))
                        last_reply, free_at_reply = now, receiver.free()
                if scheme == "tcp":
                    for s, (_, since) in list(conns.items()):
                        if s is not owner_sock and now - since > HANDSHAKE_S:
                            drop(s)  # a client that did not open or resume the session in time
                socks = [srv] + (list(conns) if scheme == "tcp" else [])
                ready, _, _ = select.select(socks, [], [], 0.002)
                for s in ready:
                    if scheme == "udp":
                        try:
                            data, addr = srv.recvfrom(1 << 16)
                        except OSError:
                            continue
                        take(data, addr, None)
                        continue
                    if s is srv:
                        try:
                            c, _ = srv.accept()
                        except OSError:
                            continue
                        c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                        if len(conns) >= MAX_CONNECTIONS:  # the oldest stranger makes room
                            strangers = [k for k in conns if k is not owner_sock]
                            if strangers:
                                drop(min(strangers, key=lambda k: conns[k][1]))
                        conns[c] = (FramedTCP(c, send_timeout=1.0), time.monotonic())
                        continue
                    if s not in conns:
                        continue
                    link = conns[s][0]
                    try:
                        data = link.recv_bytes(0.0)
                        frames = ([data] if data is not None else []) + link.pending()
                    except FramingError:
                        receiver.stats["bad_frames"] += 1
                        drop(s)
                        continue
                    except (ConnectionError, OSError):
                        drop(s)
                        continue
                    for data in frames:
                        if s not in conns:
                            break
                        take(data, s, s)
        except BaseException as exc:
            stop = Stopped(f"receiver: {type(exc).__name__}: {exc}".splitlines()[0], 1)
            if not isinstance(exc, Exception):
                stop.status = 130
        finally:
            for link, _ in conns.values():
                link.close()
            srv.close()
            if stop is not None or not receiver.done:
                receiver.stop()  # the laser off, the drives ramped down on the path
            summary = receiver.summary()  # the recording is finished here, whatever happened
    if stop is not None or not summary["done"]:
        if stop is None:
            stop = Stopped("receiver: the player stopped the job", 1)
        where = f"{summary['executed']} ticks executed" + (f" of {summary['n_rows']}" if summary["n_rows"] else "")
        rest = "the drives at rest on the path" if summary["at_rest"] else "the drives NOT at rest"
        stop.args = (f"{stop.args[0]}: the job stopped ({where}; {rest}, the laser off)",)
        stop.summary = summary
        raise stop
    return summary


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m jaxcnc.hw.receiver", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("listen", help="tcp://HOST:PORT or udp://HOST:PORT (port 0: any free port; HOST loopback)")
    ap.add_argument("--record", help="write the executed rows to this .npy file")
    ap.add_argument("--capacity", type=int, default=8192, help="buffer rows (default: %(default)s)")
    ap.add_argument("--speed", type=float, default=1.0, help="clock speed-up over the table's tick rate")
    ap.add_argument("--idle-timeout", type=float, default=30.0, help="give up after this many silent seconds")
    ap.add_argument(
        "--allow-network",
        action="store_true",
        help="listen on an address that is not loopback (other machines can then connect: set a shared key)",
    )
    ap.add_argument(
        "--key-file",
        help="a file holding the shared key (at least 16 bytes) that signs every frame; else $JAXCNC_STREAM_KEY if set",
    )
    ap.add_argument(
        "--a-max-disc",
        "--a-max",  # the older name, kept for scripts
        dest="a_max_disc",
        metavar="A,B,...",
        help="the drives' acceleration limits in DISCRETES/s² (not mm/s²), per axis in table order "
        "(comma-separated): on underrun the drives ramp down along the path within them; without, they hold the "
        "last row",
    )
    args = ap.parse_args(argv)
    try:
        a_disc = np.array([float(x) for x in args.a_max_disc.split(",")]) if args.a_max_disc else None
        if a_disc is not None and not (np.all(np.isfinite(a_disc)) and np.all(a_disc > 0)):
            raise ValueError("--a-max-disc: limits must be positive numbers")
        if args.capacity < 4 or not (np.isfinite(args.speed) and args.speed > 0) or not args.idle_timeout > 0:
            raise ValueError("--capacity must be at least 4, --speed and --idle-timeout positive")
        key = load_key(args.key_file)
        receiver = Receiver(args.capacity, args.speed, args.record, a_disc, key, log=_log)
        stats = serve(args.listen, receiver, args.idle_timeout, allow_network=args.allow_network)
    except ValueError as exc:
        print(f"receiver: error: {exc}", file=sys.stderr)
        return 2
    except Stopped as stop:
        print(json.dumps(stop.summary), flush=True)
        print(stop.args[0], file=sys.stderr, flush=True)
        return stop.status
    print(json.dumps(stats), flush=True)
    return 0


def _log(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def spawn(listen: str = "tcp://127.0.0.1:0", *options: str, env: dict | None = None) -> tuple:
    """Start a receiver process; return ``(process, address it listens on)``.

    ``options`` are command-line options (``"--speed", "20"``, ...). The caller waits for the
    process (its last stdout line is the JSON summary; stderr is a pipe too) and kills it in any case.
    """
    import subprocess

    proc = subprocess.Popen(
        [sys.executable, "-m", "jaxcnc.hw.receiver", listen, *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    line = proc.stdout.readline().split()
    if len(line) != 2 or line[0] != "listening":
        proc.kill()
        _, err = proc.communicate()
        raise RuntimeError(f"receiver did not start: {' '.join(line) or err.strip()!r}")
    return proc, line[1]


if __name__ == "__main__":
    sys.exit(main())
