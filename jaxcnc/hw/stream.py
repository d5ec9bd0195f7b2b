"""The jaxcnc stream protocol: framed blocks of rows over TCP or UDP, with credits and acknowledgements.

For MCU/FPGA boards that play a table from a buffer at their own clock. Every frame::

    u16 magic 0x4A43 | u8 type | u8 n_axes | u32 seq | i64 tick | u32 count | i64 aux
    | payload (count rows × n_axes int32, DATA only) | u32 CRC-32 of everything before it

all little-endian; over TCP each frame is preceded by its u32 length, over UDP it is one datagram.

Types and meaning of (tick, count, aux):

- HELLO (player → receiver): table start tick 0, count = rows in the table, aux = tick rate in mHz.
- WELCOME (receiver → player): tick = the next tick it needs (0 for a new job; later after a link
  loss), count = free buffer rows, aux = last executed tick.
- DATA: rows for ticks ``tick .. tick+count-1``. The receiver takes a frame only if it starts exactly
  at the next tick it needs and fits its buffer; earlier frames (duplicates) and later ones (a gap:
  lost or reordered) are dropped — so every tick is executed once, in order.
- ACK (receiver → player, after every frame): tick = next tick needed, count = free rows (the
  player's credit), aux = last executed tick.
- END (player): no rows after the last DATA. DONE (receiver): all rows executed; aux = last tick.

The player keeps every row the receiver has not yet acknowledged and resends from the receiver's
next tick after a timeout (UDP loss) or a reconnection (link loss): go-back-N.
"""

from __future__ import annotations

import socket
import struct
import zlib
from dataclasses import dataclass

import numpy as np

MAGIC = 0x4A43
HEADER = struct.Struct("<HBBIqIq")
CRC = struct.Struct("<I")
HELLO, WELCOME, DATA, ACK, END, DONE = 1, 2, 3, 4, 5, 6
ROWS_PER_FRAME = 256  # a DATA frame stays well below a UDP datagram's limit


class ProtocolError(Exception):
    """A frame that is damaged or not of this protocol."""


@dataclass(frozen=True)
class Frame:
    type: int
    n_axes: int
    seq: int
    tick: int
    count: int
    aux: int
    rows: np.ndarray | None = None

    def encode(self) -> bytes:
        payload = b"" if self.rows is None else np.ascontiguousarray(self.rows, dtype="<i4").tobytes()
        head = HEADER.pack(MAGIC, self.type, self.n_axes, self.seq & 0xFFFFFFFF, self.tick, self.count, self.aux)
        body = head + payload
        return body + CRC.pack(zlib.crc32(body))


def decode(data: bytes) -> Frame:
    """Parse one frame; raises :class:`ProtocolError` on a bad magic, length or CRC."""
    if len(data) < HEADER.size + CRC.size:
        raise ProtocolError("short frame")
    (crc,) = CRC.unpack_from(data, len(data) - CRC.size)
    if zlib.crc32(data[: -CRC.size]) != crc:
        raise ProtocolError("CRC mismatch")
    magic, typ, n_axes, seq, tick, count, aux = HEADER.unpack_from(data)
    if magic != MAGIC:
        raise ProtocolError("bad magic")
    rows = None
    if typ == DATA:
        need = HEADER.size + count * n_axes * 4 + CRC.size
        if len(data) != need or n_axes == 0:
            raise ProtocolError("DATA length does not match its row count")
        rows = np.frombuffer(data, dtype="<i4", count=count * n_axes, offset=HEADER.size).reshape(count, n_axes)
    return Frame(typ, n_axes, seq, tick, count, aux, rows)


def parse_address(spec: str) -> tuple[str, str, int]:
    """``tcp://HOST:PORT`` or ``udp://HOST:PORT`` → (scheme, host, port)."""
    scheme, _, rest = spec.partition("://")
    host, _, port = rest.rpartition(":")
    if scheme not in ("tcp", "udp") or not host or not port.isdigit():
        raise ValueError(f"expected tcp://HOST:PORT or udp://HOST:PORT, got {spec!r}")
    return scheme, host.strip("[]"), int(port)


class FramedTCP:
    """Length-prefixed frames over a connected TCP socket."""

    def __init__(self, sock: socket.socket):
        self.sock, self.buf = sock, b""

    def send(self, frame: Frame) -> None:
        data = frame.encode()
        self.sock.sendall(struct.pack("<I", len(data)) + data)

    def recv(self, timeout: float) -> Frame | None:
        """The next frame, or None after ``timeout`` seconds; raises ConnectionError when closed."""
        self.sock.settimeout(timeout)
        while True:
            if len(self.buf) >= 4:
                (n,) = struct.unpack_from("<I", self.buf)
                if n > 1 << 24:
                    raise ProtocolError("frame length out of range")
                if len(self.buf) >= 4 + n:
                    data, self.buf = self.buf[4 : 4 + n], self.buf[4 + n :]
                    return decode(data)
            try:
                chunk = self.sock.recv(1 << 16)
            except TimeoutError:
                return None
            if not chunk:
                raise ConnectionError("peer closed the connection")
            self.buf += chunk
