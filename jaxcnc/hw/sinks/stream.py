"""``tcp://HOST:PORT`` and ``udp://HOST:PORT``: the player's side of the stream protocol.

The sink keeps every row the receiver has not acknowledged, spends the receiver's credit (its free
buffer rows) and goes back to the receiver's next needed tick when acknowledgements stop coming
(UDP loss) or after reconnecting (link loss). ``faults`` injects, for tests, datagram loss,
duplication and reordering (UDP) or a disconnection after some frames (TCP), from a seeded RNG.
"""

from __future__ import annotations

import socket
import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from jaxcnc.format import TableHeader
from jaxcnc.hw.stream import (
    ACK,
    DATA,
    DONE,
    END,
    HELLO,
    ROWS_PER_FRAME,
    WELCOME,
    Frame,
    FramedTCP,
    ProtocolError,
    decode,
    parse_address,
)


class LinkError(ConnectionError):
    """The receiver cannot be reached (after the retries)."""


@dataclass(frozen=True)
class Faults:
    drop: float = 0.0  # probability a DATA datagram is lost
    duplicate: float = 0.0  # ... sent twice
    reorder: float = 0.0  # ... held back and sent after the next one
    disconnect_after: int = 0  # TCP: drop the connection after this many DATA frames (0: never)
    seed: int = 0


class StreamSink:
    def __init__(self, spec: str, timeout: float = 0.02, retries: int = 500, faults: Faults | None = None):
        self.scheme, self.host, self.port = parse_address(spec)
        self.timeout, self.retries = timeout, retries
        self.faults = faults or Faults()
        self.rng = np.random.default_rng(self.faults.seed)
        self.tcp: FramedTCP | None = None
        self.udp: socket.socket | None = None
        self.retained: OrderedDict[int, Frame] = OrderedDict()  # first tick -> DATA frame not yet acknowledged
        self.acked = 0  # the receiver's next needed tick
        self.credit = 0
        self.executed = -1
        self.seq = 0
        self.underruns = 0
        self.rows_sent = 0  # the job's rows (more than the table's after a hold or an override)
        self.data_sent = 0
        self.held: Frame | None = None
        self.done = False
        self.last_progress = time.monotonic()
        self.stats = {"resent_frames": 0, "reconnects": 0, "dropped": 0, "duplicated": 0, "reordered": 0}

    # -- transport -------------------------------------------------------------------------
    def _connect(self) -> None:
        if self.scheme == "udp":
            if self.udp is None:
                self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            return
        last = None
        for _ in range(self.retries):
            try:
                s = socket.create_connection((self.host, self.port), timeout=1.0)
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self.tcp = FramedTCP(s)
                return
            except OSError as exc:
                last = exc
                time.sleep(self.timeout)
        raise LinkError(f"cannot reach {self.scheme}://{self.host}:{self.port}: {last}")

    def _raw_send(self, frame: Frame) -> None:
        if self.scheme == "udp":
            self.udp.sendto(frame.encode(), (self.host, self.port))
        else:
            self.tcp.send(frame)

    def _send(self, frame: Frame) -> None:
        """Send, with the injected faults on DATA frames."""
        try:
            if frame.type == DATA:
                self.data_sent += 1
                f = self.faults
                if self.scheme == "tcp" and f.disconnect_after and self.data_sent == f.disconnect_after:
                    self.tcp.sock.close()  # the link drops here
                    raise ConnectionError("injected disconnection")
                if self.scheme == "udp":
                    r = self.rng.random(3)
                    if r[0] < f.drop:
                        self.stats["dropped"] += 1
                        return
                    if r[2] < f.reorder and self.held is None:
                        self.held = frame
                        self.stats["reordered"] += 1
                        return
                    self._raw_send(frame)
                    if r[1] < f.duplicate:
                        self._raw_send(frame)
                        self.stats["duplicated"] += 1
                    if self.held is not None:
                        held, self.held = self.held, None
                        self._raw_send(held)
                    return
            self._raw_send(frame)
        except (ConnectionError, OSError):
            if self.scheme == "tcp":
                self._reconnect()
            else:
                raise

    def _recv(self) -> Frame | None:
        try:
            if self.scheme == "udp":
                self.udp.settimeout(self.timeout)
                try:
                    data, _ = self.udp.recvfrom(1 << 16)
                except TimeoutError:
                    return None
                return decode(data)
            return self.tcp.recv(self.timeout)
        except ProtocolError:
            return None
        except (ConnectionError, OSError):
            if self.scheme == "tcp":
                self._reconnect()
                return None
            raise

    def _handshake(self) -> None:
        hello = Frame(HELLO, self.header.n_axes, 0, 0, self.header.n_rows, round(self.header.tick_hz * 1000))
        for _ in range(self.retries):
            self._raw_send(hello)
            f = self._recv()
            if f is not None and f.type in (WELCOME, DONE):
                self._take_ack(f)
                return
        raise LinkError(f"no answer from {self.scheme}://{self.host}:{self.port}")

    def _reconnect(self) -> None:
        self.stats["reconnects"] += 1
        self._connect()
        self._handshake()
        self._resend()

    def _take_ack(self, f: Frame) -> None:
        if f.tick > self.acked:
            self.last_progress = time.monotonic()
        if f.tick >= self.acked:
            self.acked, self.credit = f.tick, f.count
        self.executed = max(self.executed, f.aux)
        self.underruns = max(self.underruns, f.seq)  # the board's ramp-downs for want of rows
        self.done = self.done or f.type == DONE
        while self.retained:
            first, frame = next(iter(self.retained.items()))
            if first + frame.count > self.acked:
                break
            self.retained.popitem(last=False)

    def _resend(self) -> None:
        """Go back to the receiver's next needed tick and send what it has room for."""
        room = self.credit
        for first, frame in self.retained.items():
            if first + frame.count <= self.acked:
                continue
            if frame.count > room:
                break
            self._raw_send(frame)
            room -= frame.count
            self.stats["resent_frames"] += 1

    # -- Sink protocol ---------------------------------------------------------------------
    def open(self, header: TableHeader) -> None:
        self.header = header
        self._connect()
        self._handshake()

    def free_rows(self) -> int:
        in_flight = sum(f.count for t, f in self.retained.items() if t + f.count > self.acked)
        return max(0, self.credit - in_flight)

    def write(self, first_tick: int, rows: np.ndarray, events: np.ndarray) -> None:
        for i in range(0, rows.shape[0], ROWS_PER_FRAME):
            part = rows[i : i + ROWS_PER_FRAME]
            frame = Frame(DATA, self.header.n_axes, self.seq, first_tick + i, part.shape[0], 0, part)
            self.seq += 1
            self.retained[first_tick + i] = frame
            self._send(frame)
        self.rows_sent = max(self.rows_sent, first_tick + rows.shape[0])

    def wait(self) -> None:
        """Take acknowledgements; if the receiver's next tick has not advanced for a timeout while
        rows are unacknowledged (lost or reordered frames), go back N."""
        for _ in range(64):
            f = self._recv()
            if f is None:
                break
            if f.type in (ACK, WELCOME, DONE):
                self._take_ack(f)
            if self.free_rows() > 0:
                break
        if self.retained and time.monotonic() - self.last_progress > self.timeout:
            self._resend()
            self.last_progress = time.monotonic()

    def executed_tick(self) -> int:
        return self.executed

    def close(self) -> None:
        """Send END until the receiver reports every row executed."""
        end = Frame(END, self.header.n_axes, self.seq, self.rows_sent, 0, 0)
        stall_s = max(2.0, self.retries * self.timeout)  # give up only when the board stops progressing
        deadline, seen = time.monotonic() + stall_s, (self.executed, self.acked)
        while not self.done and time.monotonic() < deadline:
            if not self.retained:
                self._send(end)  # (while rows are unacknowledged, their acknowledgements come first)
            self.wait()
            if (self.executed, self.acked) != seen:
                deadline, seen = time.monotonic() + stall_s, (self.executed, self.acked)
            elif not self.done:
                time.sleep(self.timeout / 4)  # the board is draining its buffer: do not flood the link
        if self.tcp is not None:
            self.tcp.sock.close()
        if self.udp is not None:
            self.udp.close()
        if not self.done:
            raise LinkError("the receiver did not confirm the end of the job")
