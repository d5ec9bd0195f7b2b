"""The jaxcnc stream protocol, version 2: framed rows over TCP or UDP, in sessions, optionally keyed.

For MCU/FPGA boards that play a table from a buffer at their own clock. Every frame::

    u16 magic 0x4A43 | u8 version (2) | u8 type | u8 flags | u8 n_axes | u16 n_events
    | u64 session | u64 seq | i64 tick | u32 count | i64 aux
    | payload | u32 CRC-32 of everything before it
    | [32-byte HMAC-SHA256 of everything before it, when flags has KEYED]

all little-endian; over TCP each frame is preceded by its u32 length, over UDP it is one datagram.
``docs/stream-protocol.md`` gives every type's fields, the handshake and the state machine. In short:

- A session is opened by HELLO (session 0, a random nonce as payload) and answered by WELCOME (the
  session id the receiver drew, the nonce echoed). Every later frame, both ways, carries that session
  id; the receiver takes frames only from the session's owner (the connection or address that opened
  or resumed it). A second player is answered REFUSED (``busy``) and its frames are ignored.
- ``seq`` counts every frame a side sends in a session (from 1); a frame whose ``seq`` was seen
  already, or is older than the last 64, is dropped (replay).
- With a shared key (:func:`load_key`: a file or ``JAXCNC_STREAM_KEY``, never the command line),
  every frame carries an HMAC-SHA256 tag; a frame with a wrong or missing tag is dropped.
- After a lost link the player reconnects and sends HELLO with flag RESUME and its session id;
  WELCOME says which tick the receiver needs next. A receiver that does not hold the session (it
  restarted) answers REFUSED, and the player stops with that error.

NumPy and the standard library only (this is the controller side).
"""

from __future__ import annotations

import hashlib
import hmac
import os
import select
import socket
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxcnc.format import EVENT_DTYPE

MAGIC = 0x4A43
VERSION = 2
HEADER = struct.Struct("<HBBBBHQQqIq")
CRC = struct.Struct("<I")
TAG_SIZE = 32  # HMAC-SHA256
HELLO, WELCOME, DATA, ACK, END, DONE, REFUSED, STOP, STOPPED = 1, 2, 3, 4, 5, 6, 7, 8, 9
TYPE_NAMES = {
    HELLO: "HELLO",
    WELCOME: "WELCOME",
    DATA: "DATA",
    ACK: "ACK",
    END: "END",
    DONE: "DONE",
    REFUSED: "REFUSED",
    STOP: "STOP",
    STOPPED: "STOPPED",
}
KEYED = 1  # flags: an HMAC-SHA256 tag follows the CRC
RESUME = 2  # flags (HELLO): resume the session named in the frame after a lost link
POWER = 4  # flags (DATA): the rows' laser power follows them, one float32 (finite, >= 0) per row
MAX_ROWS = 8192  # rows in one DATA frame (a receiver refuses more)
ROWS_PER_FRAME = 256  # what the player puts in a UDP datagram: a DATA frame stays well below a datagram's limit
TCP_ROWS_PER_FRAME = MAX_ROWS  # ... and in a TCP frame: few frames (and acknowledgements) per second at 100 kHz
MAX_AXES = 32
MAX_EVENTS = 1024  # events in one DATA frame
MAX_TEXT = 512  # bytes of a REFUSED frame's reason
MAX_FRAME = HEADER.size + MAX_ROWS * (MAX_AXES + 1) * 4 + MAX_EVENTS * EVENT_DTYPE.itemsize + CRC.size + TAG_SIZE
NONCE = struct.Struct("<Q")  # HELLO's payload: the player's nonce
STATUS = struct.Struct("<QI")  # WELCOME, ACK, DONE, STOPPED: the nonce echoed (WELCOME) and the underrun count
STATUS_TYPES = (WELCOME, ACK, DONE, STOPPED)
KEY_ENV = "JAXCNC_STREAM_KEY"
MIN_KEY_BYTES = 16


class ProtocolError(Exception):
    """A frame that is damaged, malformed or not of this protocol (the frame is dropped)."""


class VersionError(ProtocolError):
    """A frame of another version of the protocol."""

    def __init__(self, version: int):
        self.version = version
        super().__init__(f"the peer speaks stream protocol version {version}; this side speaks {VERSION}")


class AuthError(ProtocolError):
    """A frame whose shared-key tag is wrong or missing (or present where no key is set)."""


class FramingError(ProtocolError):
    """The TCP byte stream lost its framing (a length out of range): the connection must be closed."""


@dataclass(frozen=True)
class Frame:
    type: int
    n_axes: int = 0
    session: int = 0
    seq: int = 0
    tick: int = 0
    count: int = 0
    aux: int = 0
    rows: np.ndarray | None = None  # DATA: (count, n_axes) int32
    power: np.ndarray | None = None  # DATA: (count,) float32 laser power per row (sets the POWER flag)
    events: np.ndarray | None = None  # DATA: EVENT_DTYPE records among the rows' ticks
    nonce: int = 0  # HELLO, WELCOME: the player's nonce
    underruns: int = 0  # WELCOME, ACK, DONE, STOPPED: the board's ramp-downs for want of rows
    text: str = ""  # REFUSED: why
    flags: int = 0  # RESUME (KEYED is set by encode)

    def payload(self) -> bytes:
        if self.type == DATA:
            rows = np.ascontiguousarray(self.rows, dtype="<i4").tobytes()
            power = b"" if self.power is None else np.ascontiguousarray(self.power, dtype="<f4").tobytes()
            ev = b"" if self.events is None else np.ascontiguousarray(self.events, dtype=EVENT_DTYPE).tobytes()
            return rows + power + ev
        if self.type == HELLO:
            return NONCE.pack(self.nonce)
        if self.type in STATUS_TYPES:
            return STATUS.pack(self.nonce, self.underruns & 0xFFFFFFFF)
        if self.type == REFUSED:
            return self.text.encode("utf-8", "replace")[:MAX_TEXT]
        return b""

    def encode(self, key: bytes | None = None) -> bytes:
        payload = self.payload()
        n_events = 0 if self.events is None or self.type != DATA else len(self.events)
        count = len(payload) if self.type == REFUSED else self.count
        flags = (self.flags & ~(KEYED | POWER)) | (KEYED if key else 0)
        if self.type == DATA and self.power is not None:
            flags |= POWER
        head = HEADER.pack(
            MAGIC,
            VERSION,
            self.type,
            flags,
            self.n_axes,
            n_events,
            self.session & 0xFFFFFFFFFFFFFFFF,
            self.seq & 0xFFFFFFFFFFFFFFFF,
            self.tick,
            count & 0xFFFFFFFF,
            self.aux,
        )
        body = head + payload
        body += CRC.pack(zlib.crc32(body))
        if key:
            body += hmac.new(key, body, hashlib.sha256).digest()
        return body


def _crc_ok(data: bytes) -> bool:
    return len(data) >= 4 and zlib.crc32(data[:-4]) == CRC.unpack_from(data, len(data) - 4)[0]


def decode(data: bytes, key: bytes | None = None) -> Frame:
    """Parse and check one frame.

    Raises :class:`VersionError` (another protocol version), :class:`AuthError` (the shared-key tag
    is wrong, missing, or present where ``key`` is None) or :class:`ProtocolError` (damaged or
    malformed: bad magic, CRC, length, type or field).
    """
    if len(data) < 4:
        raise ProtocolError("short frame")
    magic, version = struct.unpack_from("<HB", data)
    if magic != MAGIC:
        raise ProtocolError("not a frame of the jaxcnc stream protocol (bad magic)")
    if version != VERSION:
        if _crc_ok(data):
            raise VersionError(version)
        raise ProtocolError("damaged frame (CRC mismatch)")
    if len(data) < HEADER.size + CRC.size:
        raise ProtocolError("short frame")
    if len(data) > MAX_FRAME:
        raise ProtocolError("frame too long")
    flags = data[4]
    if flags & KEYED:
        if len(data) < HEADER.size + CRC.size + TAG_SIZE:
            raise ProtocolError("short frame")
        body, tag = data[:-TAG_SIZE], data[-TAG_SIZE:]
        if not _crc_ok(body):
            raise ProtocolError("damaged frame (CRC mismatch)")
        if key is None:
            raise AuthError("the peer signs its frames with a shared key; this side has none")
        if not hmac.compare_digest(tag, hmac.new(key, body, hashlib.sha256).digest()):
            raise AuthError("bad tag: a wrong shared key or a forged frame")
    else:
        body = data
        if not _crc_ok(body):
            raise ProtocolError("damaged frame (CRC mismatch)")
        if key is not None:
            raise AuthError("a frame without the shared key's tag")
    _, _, typ, flags, n_axes, n_events, session, seq, tick, count, aux = HEADER.unpack_from(body)
    payload = body[HEADER.size : -CRC.size]
    if typ not in TYPE_NAMES:
        raise ProtocolError(f"unknown frame type {typ}")
    rows = events = power = None
    nonce, underruns, text = 0, 0, ""
    if typ == DATA:
        if not 1 <= n_axes <= MAX_AXES or not 1 <= count <= MAX_ROWS or n_events > MAX_EVENTS:
            raise ProtocolError("DATA frame out of range (axes, rows or events)")
        if tick < 0:
            raise ProtocolError("DATA frame for a negative tick")
        n_power = count if flags & POWER else 0
        need = (count * n_axes + n_power) * 4 + n_events * EVENT_DTYPE.itemsize
        if len(payload) != need:
            raise ProtocolError("DATA length does not match its row and event counts")
        rows = np.frombuffer(payload, dtype="<i4", count=count * n_axes).reshape(count, n_axes)
        if n_power:
            power = np.frombuffer(payload, dtype="<f4", count=count, offset=count * n_axes * 4)
            if not np.all(np.isfinite(power) & (power >= 0)):
                raise ProtocolError("DATA frame with a laser power that is not finite and >= 0")
        events = np.frombuffer(payload, dtype=EVENT_DTYPE, count=n_events, offset=(count * n_axes + n_power) * 4)
        if n_events and (np.any(events["tick"] < tick) or np.any(events["tick"] >= tick + count)):
            raise ProtocolError("DATA frame with an event outside its ticks")
    elif n_events:
        raise ProtocolError(f"{TYPE_NAMES[typ]} frame with events")
    elif flags & POWER:
        raise ProtocolError(f"{TYPE_NAMES[typ]} frame with the POWER flag")
    elif typ == HELLO:
        if len(payload) != NONCE.size:
            raise ProtocolError("HELLO frame of the wrong length")
        (nonce,) = NONCE.unpack(payload)
    elif typ in STATUS_TYPES:
        if len(payload) != STATUS.size:
            raise ProtocolError(f"{TYPE_NAMES[typ]} frame of the wrong length")
        nonce, underruns = STATUS.unpack(payload)
    elif typ == REFUSED:
        if len(payload) != count or count > MAX_TEXT:
            raise ProtocolError("REFUSED frame of the wrong length")
        text = payload.decode("utf-8", "replace").splitlines()[0] if payload else ""
    elif payload:
        raise ProtocolError(f"{TYPE_NAMES[typ]} frame with a payload")
    return Frame(
        typ,
        n_axes,
        session,
        seq,
        tick,
        count,
        aux,
        rows,
        power,
        events,
        nonce,
        underruns,
        text,
        flags & ~(KEYED | POWER),
    )


class ReplayWindow:
    """Sequence numbers seen from a peer: a frame is fresh once, if newer than the last ``size`` seen."""

    def __init__(self, size: int = 64):
        self.size, self.top, self.mask = size, 0, 0

    def fresh(self, seq: int) -> bool:
        """True (and remembered) the first time ``seq`` comes within the window; False for a replay."""
        if seq <= 0:
            return False
        if seq > self.top:
            shift = seq - self.top
            self.mask = ((self.mask << shift) | 1) & ((1 << self.size) - 1) if shift < self.size else 1
            self.top = seq
            return True
        back = self.top - seq
        if back >= self.size or self.mask >> back & 1:
            return False
        self.mask |= 1 << back
        return True


def load_key(path: str | os.PathLike | None = None, env: dict | None = None) -> bytes | None:
    """The shared key: the contents of ``path`` if given, else ``$JAXCNC_STREAM_KEY``, else None.

    Surrounding whitespace is stripped; a key shorter than 16 bytes is refused (ValueError). The key
    is never taken from the command line, where other users of the machine could read it.
    """
    env = os.environ if env is None else env
    if path is not None:
        try:
            key = Path(path).read_bytes().strip()
        except OSError as exc:
            raise ValueError(f"cannot read the key file {path}: {exc.strerror or exc}") from None
        where = f"the key file {path}"
    elif env.get(KEY_ENV):
        key, where = env[KEY_ENV].strip().encode(), f"${KEY_ENV}"
    else:
        return None
    if len(key) < MIN_KEY_BYTES:
        raise ValueError(f"{where} holds {len(key)} bytes; a shared key needs at least {MIN_KEY_BYTES}")
    return key


def parse_address(spec: str) -> tuple[str, str, int]:
    """``tcp://HOST:PORT`` or ``udp://HOST:PORT`` → (scheme, host, port)."""
    scheme, _, rest = spec.partition("://")
    host, _, port = rest.rpartition(":")
    if scheme not in ("tcp", "udp") or not host or not port.isdigit() or int(port) > 65535:
        raise ValueError(f"expected tcp://HOST:PORT or udp://HOST:PORT, got {spec!r}")
    return scheme, host.strip("[]"), int(port)


@dataclass
class FramedTCP:
    """Length-prefixed frames over a connected TCP socket.

    ``send_timeout``: a send that cannot complete in this time (the peer stopped reading) raises
    :class:`TimeoutError`; the frame may be half sent, so the caller must treat it as a lost link.
    """

    sock: socket.socket
    send_timeout: float = 2.0
    buf: bytearray = field(default_factory=bytearray)

    def send_bytes(self, data: bytes) -> None:
        self.sock.settimeout(self.send_timeout)
        self.sock.sendall(struct.pack("<I", len(data)) + data)

    def send(self, frame: Frame, key: bytes | None = None) -> None:
        self.send_bytes(frame.encode(key))

    def _pop(self) -> bytes | None:
        if len(self.buf) < 4:
            return None
        (n,) = struct.unpack_from("<I", self.buf)
        if not 4 <= n <= MAX_FRAME:
            raise FramingError(f"frame length {n} out of range")
        if len(self.buf) < 4 + n:
            return None
        data = bytes(self.buf[4 : 4 + n])
        del self.buf[: 4 + n]
        return data

    def recv_bytes(self, timeout: float) -> bytes | None:
        """The next frame's bytes, or None after ``timeout`` s; ConnectionError when the peer closed."""
        data = self._pop()
        if data is not None:
            return data
        ready, _, _ = select.select([self.sock], [], [], max(timeout, 0.0))
        if not ready:
            return None
        self.sock.settimeout(self.send_timeout)
        chunk = self.sock.recv(1 << 20)
        if not chunk:
            raise ConnectionError("peer closed the connection")
        self.buf += chunk
        return self._pop()

    def pending(self) -> list[bytes]:
        """Every complete frame already buffered (after :meth:`recv_bytes` returned one)."""
        out = []
        while (data := self._pop()) is not None:
            out.append(data)
        return out

    def recv(self, timeout: float, key: bytes | None = None) -> Frame | None:
        data = self.recv_bytes(timeout)
        return None if data is None else decode(data, key)

    def close(self) -> None:
        try:
            self.sock.close()
        except OSError:
            pass
