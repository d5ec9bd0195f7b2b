"""``tcp://HOST:PORT`` and ``udp://HOST:PORT``: the player's side of the stream protocol (version 2).

The sink opens a session (HELLO → WELCOME), keeps every row the receiver has not acknowledged,
spends the receiver's credit (its free buffer rows) and goes back to the receiver's next needed tick
when acknowledgements stop coming (UDP loss) or after resuming the session on a new link.

Every wait is bounded, and a lost link is an error, never a hang or a traceback:

- a send that cannot complete in ``send_timeout`` (the receiver stopped reading), a closed or reset
  connection, or no frame from the receiver for ``link_timeout`` is a lost link;
- the sink then reconnects and resumes the session (HELLO with RESUME) for at most ``link_timeout``
  seconds and ``retries`` attempts, and at most ``max_relinks`` times in a row without the receiver
  advancing; past that, :class:`LinkError` (the receiver's drives ramp down on their own);
- a receiver that no longer holds the session (it restarted) or that is busy with another player
  answers REFUSED: :class:`LinkError` with its reason.

:meth:`StreamSink.abort` (the player's way out on an error or a signal) sends STOP: the receiver
switches the laser off and ramps its drives down on the path within its buffer.

``faults`` injects, for tests, datagram loss, duplication and reordering (UDP) or a disconnection
after some frames (TCP), from a seeded RNG. ``key``: the shared key (every frame signed).
"""

from __future__ import annotations

import os
import socket
import time
from collections import OrderedDict
from dataclasses import dataclass, replace

import numpy as np

from jaxcnc.format import TableHeader
from jaxcnc.hw.stream import (
    ACK,
    DATA,
    DONE,
    END,
    HELLO,
    REFUSED,
    RESUME,
    ROWS_PER_FRAME,
    STOP,
    STOPPED,
    TCP_ROWS_PER_FRAME,
    VERSION,
    WELCOME,
    AuthError,
    Frame,
    FramedTCP,
    ProtocolError,
    VersionError,
    decode,
    parse_address,
)

MAX_EVENTS_PER_FRAME = 1024


class LinkError(ConnectionError):
    """The receiver cannot be reached, stopped answering, or refused the session."""


class Refused(LinkError):
    """The receiver refused the session (busy, unknown session, another version, the shared key).
    ``retry_after_s`` > 0: a transient refusal (another session still opening, nothing moved)."""

    def __init__(self, message: str, retry_after_s: float = 0.0) -> None:
        super().__init__(message)
        self.retry_after_s = retry_after_s


@dataclass(frozen=True)
class Faults:
    drop: float = 0.0  # probability a DATA datagram is lost
    duplicate: float = 0.0  # ... sent twice
    reorder: float = 0.0  # ... held back and sent after the next one
    disconnect_after: int = 0  # TCP: drop the connection after this many DATA frames (0: never)
    seed: int = 0


class _LinkDown(Exception):
    """Internal: the current link failed (resume it)."""


class StreamSink:
    def __init__(
        self,
        spec: str,
        timeout: float = 0.02,
        retries: int = 500,
        faults: Faults | None = None,
        key: bytes | None = None,
        link_timeout: float = 5.0,
        send_timeout: float = 2.0,
        max_relinks: int = 3,
    ):
        self.spec = spec
        self.scheme, self.host, self.port = parse_address(spec)
        self.timeout, self.retries, self.key = timeout, retries, key
        self.link_timeout, self.send_timeout, self.max_relinks = link_timeout, send_timeout, max_relinks
        self.faults = faults or Faults()
        self.rng = np.random.default_rng(self.faults.seed)
        self.tcp: FramedTCP | None = None
        self.udp: socket.socket | None = None
        self.retained: OrderedDict[int, Frame] = OrderedDict()  # first tick -> DATA frame not yet acknowledged
        self.session = 0
        self.seq = 0  # frames sent in the session
        self.reply_seq = 0  # the newest reply taken
        self.acked = 0  # the receiver's next needed tick
        self.credit = 0
        self.executed = -1
        self.underruns = 0
        self.rows_sent = 0  # the job's rows (more than the table's after a hold or an override)
        self.data_sent = 0
        self.held: bytes | None = None
        self.done = False
        self.stopped = False
        self.last_progress = time.monotonic()
        self.last_reply = time.monotonic()
        self.relinks_without_progress = 0
        self.stats = {"resent_frames": 0, "reconnects": 0, "dropped": 0, "duplicated": 0, "reordered": 0}

    @property
    def where(self) -> str:
        return f"{self.scheme}://{self.host}:{self.port}"

    # -- transport -------------------------------------------------------------------------
    def _close_link(self) -> None:
        if self.tcp is not None:
            self.tcp.close()
            self.tcp = None

    def _connect(self, deadline: float) -> None:
        """A new link (TCP: a connection) before ``deadline``; raises LinkError."""
        if self.scheme == "udp":
            if self.udp is None:
                family = socket.getaddrinfo(self.host, self.port, type=socket.SOCK_DGRAM)[0][0]
                self.udp = socket.socket(family, socket.SOCK_DGRAM)
            return
        self._close_link()
        last: Exception | None = None
        for _ in range(max(1, self.retries)):
            try:
                left = max(0.05, deadline - time.monotonic())
                s = socket.create_connection((self.host, self.port), timeout=min(1.0, left))
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self.tcp = FramedTCP(s, send_timeout=self.send_timeout)
                return
            except OSError as exc:
                last = exc
            if time.monotonic() >= deadline:
                break
            time.sleep(min(max(self.timeout, 0.01), 0.1))
        reason = getattr(last, "strerror", None) or last
        raise LinkError(f"cannot reach the receiver at {self.where}: {reason}")

    def _raw_send(self, frame: Frame) -> None:
        """Send one frame (numbered now); raises _LinkDown when the link fails."""
        self._send_bytes(self._numbered(frame))

    def _numbered(self, frame: Frame) -> bytes:
        self.seq += 1
        return replace(frame, session=self.session, seq=self.seq).encode(self.key)

    def _send_bytes(self, data: bytes) -> None:
        try:
            if self.scheme == "udp":
                self.udp.sendto(data, (self.host, self.port))
            elif self.tcp is None:
                raise _LinkDown("not connected")
            else:
                self.tcp.send_bytes(data)
        except OSError as exc:  # TimeoutError (a stalled receiver), a reset, a closed socket
            self._close_link()
            raise _LinkDown(str(exc) or type(exc).__name__) from None

    def _send(self, frame: Frame) -> None:
        """Send, with the injected faults on DATA frames."""
        f = self.faults
        if frame.type == DATA:
            self.data_sent += 1
            if self.scheme == "tcp" and f.disconnect_after and self.data_sent == f.disconnect_after:
                self._close_link()  # the link drops here
                raise _LinkDown("injected disconnection")
            if self.scheme == "udp" and (f.drop or f.duplicate or f.reorder):
                r = self.rng.random(3)
                data = self._numbered(frame)
                if r[0] < f.drop:
                    self.stats["dropped"] += 1
                    return
                if r[2] < f.reorder and self.held is None:
                    self.held = data
                    self.stats["reordered"] += 1
                    return
                self._send_bytes(data)
                if r[1] < f.duplicate:
                    self._send_bytes(data)  # the same bytes twice: the receiver takes them once
                    self.stats["duplicated"] += 1
                if self.held is not None:
                    data, self.held = self.held, None
                    self._send_bytes(data)
                return
        self._raw_send(frame)

    def _recv_frame(self, timeout: float) -> Frame | None:
        """The next frame of this session from the receiver, or None; raises _LinkDown, LinkError (REFUSED)."""
        try:
            if self.scheme == "udp":
                self.udp.settimeout(max(timeout, 1e-4))
                try:
                    data, _ = self.udp.recvfrom(1 << 16)
                except TimeoutError:
                    return None
            else:
                if self.tcp is None:
                    raise _LinkDown("not connected")
                data = self.tcp.recv_bytes(timeout)
                if data is None:
                    return None
        except ProtocolError as exc:  # framing lost
            self._close_link()
            raise _LinkDown(str(exc)) from None
        except OSError as exc:  # ConnectionError included
            self._close_link()
            raise _LinkDown(str(exc) or type(exc).__name__) from None
        try:
            f = decode(data, self.key)
        except VersionError as exc:
            raise Refused(
                f"the receiver speaks stream protocol version {exc.version}; this player speaks {VERSION}"
            ) from None
        except AuthError as exc:
            f = self._unsigned_refusal(data)
            if f is None:
                if self.session == 0:
                    raise Refused(f"shared key: {exc}") from None
                return None  # a forged or damaged frame: ignored
        except ProtocolError:
            return None
        if f.type == REFUSED:
            if self.session == 0 or f.session in (0, self.session):
                raise Refused(f"the receiver refused: {f.text}", retry_after_s=f.aux / 1000.0)
            return None
        if self.session and f.session != self.session:
            return None
        if f.seq <= self.reply_seq and self.session:
            return None  # an older reply (UDP reordering) or a replay
        self.last_reply = time.monotonic()
        return f

    def _unsigned_refusal(self, data: bytes) -> Frame | None:
        """A receiver without our key (or with another) can still refuse in the clear: read why."""
        for key in (None, self.key):
            try:
                f = decode(data, key)
            except ProtocolError:
                continue
            if f.type == REFUSED and self.session == 0:
                return f
        return None

    # -- session -------------------------------------------------------------------------------
    def _handshake(self, deadline: float, resume: bool) -> None:
        """HELLO (new, or RESUME) until WELCOME; raises LinkError (refused, no answer) or _LinkDown."""
        nonce = int.from_bytes(os.urandom(8), "little")
        hello = Frame(
            HELLO,
            self.header.n_axes,
            count=self.header.n_rows,
            aux=max(1, round(self.header.tick_hz * 1000)),
            nonce=nonce,
            flags=RESUME if resume else 0,
        )
        if not resume:
            self.session, self.seq, self.reply_seq = 0, 0, 0
        resend_every = max(self.timeout, 0.2) if self.scheme == "udp" else self.link_timeout
        for _ in range(max(1, self.retries)):
            self._raw_send(hello)
            until = min(deadline, time.monotonic() + resend_every)
            while time.monotonic() < until:
                f = self._recv_frame(min(0.05, max(0.0, until - time.monotonic())))
                if f is not None and f.type == WELCOME and f.nonce == nonce:
                    self.session = f.session
                    self.reply_seq = f.seq
                    self._take_ack(f, welcome=True)
                    return
            if time.monotonic() >= deadline:
                break
        raise LinkError(f"no answer from the receiver for {self.link_timeout:g} s")

    def _relink(self, why: str) -> None:
        """Reconnect and resume the session, at most ``max_relinks`` times in a row without the receiver
        advancing, each within ``link_timeout``; raises LinkError past that or on a refusal."""
        while True:
            if self.session == 0:
                raise LinkError(f"link lost to the receiver: {why}")
            self.relinks_without_progress += 1
            if self.relinks_without_progress > self.max_relinks:
                raise LinkError(
                    f"link lost to the receiver: {why} ({self.max_relinks} reconnections without progress; "
                    f"the drives had executed tick {self.executed})"
                )
            self.stats["reconnects"] += 1
            deadline = time.monotonic() + self.link_timeout
            try:
                while True:
                    try:
                        self._connect(deadline)
                        self._handshake(deadline, resume=True)
                        break
                    except _LinkDown as exc:  # broke during the handshake: again, while time is left
                        why = str(exc)
                        if time.monotonic() >= deadline:
                            raise
                self._resend()
                return
            except _LinkDown as exc:
                why = str(exc)
            except Refused as exc:
                raise Refused(f"{exc} (the drives had executed tick {self.executed})") from None
            except LinkError as exc:
                raise LinkError(
                    f"link lost to the receiver: {exc} (the drives had executed tick {self.executed})"
                ) from None

    def _guard(self, fn, *args):
        """Run a link operation; when the link fails, resume the session (bounded) instead."""
        try:
            return fn(*args)
        except _LinkDown as exc:
            self._relink(str(exc))
            return None

    def _take_ack(self, f: Frame, welcome: bool = False) -> None:
        if f.type not in (ACK, WELCOME, DONE, STOPPED):
            return
        self.reply_seq = max(self.reply_seq, f.seq)
        if f.tick > self.acked or f.aux > self.executed:
            self.last_progress = time.monotonic()
            self.relinks_without_progress = 0
        if welcome and f.tick < self.acked:
            raise LinkError(
                f"{self.where}: the receiver needs tick {f.tick}, but it acknowledged up to {self.acked} "
                "(it lost rows): stopped"
            )
        if f.tick >= self.acked:
            self.acked, self.credit = f.tick, f.count
        self.executed = max(self.executed, f.aux)
        self.underruns = max(self.underruns, f.underruns)
        self.done = self.done or f.type == DONE
        self.stopped = self.stopped or f.type == STOPPED
        while self.retained:
            first, frame = next(iter(self.retained.items()))
            if first + frame.count > self.acked:
                break
            self.retained.popitem(last=False)

    def _resend(self) -> None:
        """Go back to the receiver's next needed tick and send what it has room for."""
        room = self.credit
        for first, frame in list(self.retained.items()):
            if first + frame.count <= self.acked:
                continue
            if frame.count > room:
                break
            self._raw_send(frame)
            room -= frame.count
            self.stats["resent_frames"] += 1

    def _poll(self, timeout: float) -> None:
        """Take the replies that come within ``timeout``; a silent receiver is a lost link."""
        f = self._recv_frame(timeout)
        while f is not None:
            self._take_ack(f)
            f = self._recv_frame(0.0)
        if time.monotonic() - self.last_reply > self.link_timeout:
            self._close_link()
            raise _LinkDown(f"no frame from the receiver for {self.link_timeout:g} s")

    # -- Sink protocol ---------------------------------------------------------------------
    def open(self, header: TableHeader) -> None:
        self.header = header
        deadline = time.monotonic() + self.link_timeout
        while True:
            self._connect(deadline)
            try:
                self._handshake(deadline, resume=False)
                break
            except _LinkDown as exc:
                raise LinkError(f"link lost to the receiver during the handshake: {exc}") from None
            except Refused as exc:
                # another client's session is still opening (nothing moved): wait for it to lapse
                wait = min(exc.retry_after_s, 1.0) + 0.01
                if exc.retry_after_s <= 0 or time.monotonic() + wait >= deadline:
                    raise
                time.sleep(wait)
        self.last_progress = self.last_reply = time.monotonic()

    def free_rows(self) -> int:
        in_flight = sum(f.count for t, f in self.retained.items() if t + f.count > self.acked)
        return max(0, self.credit - in_flight)

    def _frames(self, first_tick: int, rows: np.ndarray, events: np.ndarray, power: np.ndarray | None = None):
        step = TCP_ROWS_PER_FRAME if self.scheme == "tcp" else ROWS_PER_FRAME
        for i in range(0, rows.shape[0], step):
            part = rows[i : i + step]
            lit = None if power is None else power[i : i + step]
            lo, hi = np.searchsorted(events["tick"], [first_tick + i, first_tick + i + part.shape[0]])
            if hi - lo > MAX_EVENTS_PER_FRAME and part.shape[0] > 1:
                half = part.shape[0] // 2
                yield from self._frames(first_tick + i, part[:half], events, None if lit is None else lit[:half])
                yield from self._frames(first_tick + i + half, part[half:], events, None if lit is None else lit[half:])
                continue
            if hi - lo > MAX_EVENTS_PER_FRAME:
                raise ValueError(f"more than {MAX_EVENTS_PER_FRAME} events on tick {first_tick + i}")
            ev = np.ascontiguousarray(events[lo:hi]) if hi > lo else None
            yield Frame(
                DATA, self.header.n_axes, tick=first_tick + i, count=part.shape[0], rows=part, power=lit, events=ev
            )

    def write(self, first_tick: int, rows: np.ndarray, events: np.ndarray, power: np.ndarray | None = None) -> None:
        """Frame the rows (8192 a TCP frame, 256 a UDP datagram) with their power (the POWER flag) and events;
        send, keep until acked."""
        for frame in self._frames(first_tick, rows, events, power):
            self.retained[frame.tick] = frame
            self._guard(self._send, frame)
        self.rows_sent = max(self.rows_sent, first_tick + rows.shape[0])

    def wait(self) -> None:
        """Take acknowledgements; if the receiver's next tick has not advanced for a timeout while
        rows are unacknowledged (lost or reordered datagrams), go back N."""
        self._guard(self._poll, self.timeout)
        stale = time.monotonic() - self.last_progress > max(self.timeout, 0.05 if self.scheme == "udp" else 0.5)
        if self.retained and stale and self.scheme == "udp":
            self._guard(self._resend)
            self.last_progress = time.monotonic()

    def executed_tick(self) -> int:
        return self.executed

    def close(self) -> None:
        """Send END until the receiver reports every row executed; raises LinkError if it stops progressing."""
        try:
            end = Frame(END, self.header.n_axes, tick=self.rows_sent)
            stall_s = max(2.0, self.link_timeout)  # give up only when the board stops progressing
            deadline, seen = time.monotonic() + stall_s, (self.executed, self.acked)
            last_end = 0.0
            while not self.done and time.monotonic() < deadline:
                if not self.retained and time.monotonic() - last_end > max(self.timeout, 0.1):
                    self._guard(self._send, end)  # (while rows are unacknowledged, their acknowledgements come first)
                    last_end = time.monotonic()
                self.wait()
                if (self.executed, self.acked) != seen:
                    deadline, seen = time.monotonic() + stall_s, (self.executed, self.acked)
            if not self.done:
                raise LinkError("the receiver did not confirm the end of the job")
        finally:
            self._release()

    def abort(self) -> None:
        """Stop now (the player's error or signal): STOP — the receiver switches the laser off and ramps
        its drives down on the path within its buffer — then release the link. Never raises."""
        try:
            if self.session and (self.tcp is not None or self.udp is not None):
                deadline = time.monotonic() + 1.0
                while not self.stopped and time.monotonic() < deadline:
                    self._raw_send(Frame(STOP, self.header.n_axes))
                    self._poll(0.1)
        except Exception:  # noqa: BLE001 - the link is gone: the receiver stops on its own (idle timeout)
            pass
        finally:
            self._release()

    def _release(self) -> None:
        self._close_link()
        if self.udp is not None:
            self.udp.close()
            self.udp = None
