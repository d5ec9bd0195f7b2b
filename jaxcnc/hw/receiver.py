"""The reference receiver of the stream protocol: a controller's buffer and clock, in its own process.

    python -m jaxcnc.hw.receiver tcp://127.0.0.1:0 --record executed.npy [--capacity 8192] [--speed 20]

It prints ``listening tcp://HOST:PORT`` once bound, takes frames as :mod:`jaxcnc.hw.stream` defines,
executes rows at the table's tick rate (``--speed`` times faster for tests), records each executed
row at its tick, and when the job is done prints one JSON line of statistics and exits. Every tick
is executed exactly once and in order: a row is taken only when it is the next one needed.

Clock: execution starts when the buffer is half full (double buffering) or the job's last row has
arrived. If the buffer runs low before the end (a slow player or a lost link) the drives ramp down
along the path within ``--a-max`` and wait at rest until the buffer is half full again, then ramp
back up (:class:`~jaxcnc.hw.drives.DriveClock`); without ``--a-max`` they can only hold the last row.
The summary counts ``underruns`` (ramp-downs), ``hard_stops`` (stops the reserve could not ramp)
and ``held_ticks``.
"""

from __future__ import annotations

import argparse
import json
import select
import socket
import sys
import time

import numpy as np

from jaxcnc.hw.drives import DriveClock
from jaxcnc.hw.sinks.record import RowRecorder
from jaxcnc.hw.stream import (
    ACK,
    DATA,
    DONE,
    END,
    HELLO,
    WELCOME,
    Frame,
    FramedTCP,
    ProtocolError,
    decode,
    parse_address,
)


class Receiver:
    """The controller model. ``a_max``: per-axis limits in discretes/s² (enables ramp-downs)."""

    def __init__(
        self, capacity: int = 8192, speed: float = 1.0, record: str | None = None, a_max: np.ndarray | None = None
    ):
        self.capacity, self.speed, self.record_path, self.a_max = capacity, speed, record, a_max
        self.next_tick = 0
        self.n_rows: int | None = None
        self.n_axes = 0
        self.tick_hz = 1.0
        self.ended = False
        self.running = False
        self.t0 = 0.0
        self.servo0 = 0  # servo ticks run before the clock (re)started
        self.servo = 0  # servo ticks run
        self.clock: DriveClock | None = None
        self.stats = {"frames": 0, "duplicates": 0, "gaps": 0, "bad_frames": 0, "reconnects": 0}
        self.recorder: RowRecorder | None = None

    @property
    def executed(self) -> int:
        return self.clock.executed if self.clock is not None else -1

    @property
    def queued(self) -> int:
        return self.clock.queued if self.clock is not None else 0

    @property
    def done(self) -> bool:
        return self.ended and self.executed == self.n_rows - 1

    def free(self) -> int:
        return self.capacity - self.queued

    def reply(self, typ: int) -> Frame:
        underruns = self.clock.underruns if self.clock is not None else 0
        return Frame(typ, self.n_axes, underruns, self.next_tick, self.free(), self.executed)

    def on_frame(self, f: Frame) -> Frame:
        self.stats["frames"] += 1
        if f.type == HELLO:
            if self.n_rows is None:
                self.n_rows, self.n_axes, self.tick_hz = f.count, f.n_axes, f.aux / 1000.0
                reserve = self.capacity // 4
                self.clock = DriveClock(self.n_axes, self.tick_hz, self.a_max, reserve, self.capacity // 2)
                self.recorder = RowRecorder(self.n_axes, self.record_path)
            else:
                self.stats["reconnects"] += 1
            return self.reply(WELCOME)
        if f.type == DATA:
            if f.tick == self.next_tick and f.count <= self.free() and f.n_axes == self.n_axes:
                self.clock.push(np.array(f.rows))
                self.next_tick += f.count
            elif f.tick < self.next_tick:
                self.stats["duplicates"] += 1
            else:
                self.stats["gaps"] += 1
            return self.reply(ACK)
        if f.type == END:
            self.ended = True
            self.n_rows = f.tick  # the job's true length (a hold or an override plays more rows than HELLO said)
        return self.reply(DONE if self.done else ACK)

    def run_clock(self, now: float) -> None:
        """Run the servo ticks that are due: rows are taken (or ramped down on) by the drive clock."""
        if self.clock is None or self.done:
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

    def summary(self) -> dict:
        if self.recorder is not None:
            self.recorder.close()
        c = self.clock
        drives = {"underruns": c.underruns, "hard_stops": c.hard_stops, "held_ticks": c.held_ticks} if c else {}
        return {"executed": self.executed + 1, "n_rows": self.n_rows, **self.stats, **drives}


def serve(spec: str, receiver: Receiver, idle_timeout: float = 30.0, out=sys.stdout) -> dict:
    """Run the receiver on ``tcp://HOST:PORT`` or ``udp://HOST:PORT`` until the job is done."""
    scheme, host, port = parse_address(spec)
    kind = socket.SOCK_STREAM if scheme == "tcp" else socket.SOCK_DGRAM
    srv = socket.socket(socket.AF_INET, kind)
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind((host, port))
    if scheme == "tcp":
        srv.listen(1)
    print(f"listening {scheme}://{host}:{srv.getsockname()[1]}", file=out, flush=True)
    conn: FramedTCP | None = None
    last_seen = time.monotonic()
    done_at = None  # when DONE was last sent: linger a little for late END retries, then exit
    try:
        while True:
            now = time.monotonic()
            receiver.run_clock(now)
            if done_at is not None and now - done_at > 0.5:
                break
            if now - last_seen > idle_timeout:
                raise TimeoutError(f"no frame for {idle_timeout} s")
            socks = [srv] + ([conn.sock] if conn else [])
            ready, _, _ = select.select(socks, [], [], 0.0005)
            for s in ready:
                if scheme == "tcp" and s is srv:
                    c, _ = srv.accept()
                    c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    if conn is not None:
                        conn.sock.close()
                    conn = FramedTCP(c)
                    continue
                try:
                    if scheme == "tcp":
                        f = conn.recv(0.05)
                        if f is None:
                            continue
                        reply_to = None
                    else:
                        data, reply_to = srv.recvfrom(1 << 16)
                        f = decode(data)
                except ProtocolError:
                    receiver.stats["bad_frames"] += 1
                    continue
                except (ConnectionError, OSError):
                    conn = None  # link lost: keep the buffer running and wait for a reconnection
                    continue
                last_seen = time.monotonic()
                receiver.run_clock(last_seen)
                r = receiver.on_frame(f)
                if r.type == DONE or (receiver.done and f.type == END):
                    r = receiver.reply(DONE)
                    done_at = time.monotonic()
                try:
                    if scheme == "tcp":
                        conn.send(r)
                    else:
                        srv.sendto(r.encode(), reply_to)
                except OSError:
                    conn = None
    finally:
        if conn is not None:
            conn.sock.close()
        srv.close()
    return receiver.summary()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m jaxcnc.hw.receiver", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("listen", help="tcp://HOST:PORT or udp://HOST:PORT (port 0: any free port)")
    ap.add_argument("--record", help="write the executed rows to this .npy file")
    ap.add_argument("--capacity", type=int, default=8192, help="buffer rows (default: %(default)s)")
    ap.add_argument("--speed", type=float, default=1.0, help="clock speed-up over the table's tick rate")
    ap.add_argument("--idle-timeout", type=float, default=30.0, help="give up after this many silent seconds")
    ap.add_argument(
        "--a-max",
        help="the drives' acceleration limits, discretes/s² per axis in table order (comma-separated): on "
        "underrun the drives ramp down along the path within them; without, they hold the last row",
    )
    args = ap.parse_args(argv)
    a_max = np.array([float(x) for x in args.a_max.split(",")]) if args.a_max else None
    stats = serve(args.listen, Receiver(args.capacity, args.speed, args.record, a_max), args.idle_timeout)
    print(json.dumps(stats), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())


def spawn(listen: str = "tcp://127.0.0.1:0", *options: str) -> tuple:
    """Start a receiver process; return ``(process, address it listens on)``.

    ``options`` are command-line options (``"--speed", "20"``, ...). The caller waits for the
    process (its last stdout line is the JSON summary) and kills it in any case.
    """
    import subprocess

    proc = subprocess.Popen(
        [sys.executable, "-m", "jaxcnc.hw.receiver", listen, *options], stdout=subprocess.PIPE, text=True
    )
    line = proc.stdout.readline().split()
    if len(line) != 2 or line[0] != "listening":
        proc.kill()
        raise RuntimeError(f"receiver did not start: {' '.join(line)!r}")
    return proc, line[1]
