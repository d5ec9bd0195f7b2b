"""Operator controls while ``jaxcnc play`` runs: feed hold, resume, override, stop.

On a terminal, single keys: ``space`` hold / resume, ``+`` / ``-`` override up / down by 10 %
(between 10 % and 100 %), ``q`` controlled stop. From a pipe (another program driving the play),
one command per line: ``hold``, ``resume``, ``override 0.5``, ``stop``. Unknown input is reported
on stderr and ignored.
"""

from __future__ import annotations

import os
import sys
import threading
from contextlib import contextmanager

from jaxcnc.hw.player import Player

KEYS_HELP = "keys: space hold/resume, +/- feed override, q stop"


def apply(player: Player, command: str) -> str | None:
    """Carry out one command (a line or a key); what was done, or ``None`` if not understood."""
    word, _, arg = command.strip().lower().partition(" ")
    if word in ("hold", "h") or (command == " " and player.commanded_rate > 0):
        player.hold()
        return "hold"
    if word in ("resume", "r") or command == " ":
        player.resume()
        return "resume"
    if word in ("stop", "q"):
        player.request_stop()
        return "stop"
    if word in ("+", "-"):
        step = 0.1 if word == "+" else -0.1
        player.set_override(min(1.0, max(0.1, round(player.override + step, 2))))
        return f"override {player.override:.0%}"
    if word == "override":
        try:
            player.set_override(float(arg))
        except ValueError as exc:
            print(f"jaxcnc: {exc}", file=sys.stderr)
            return "refused"
        return f"override {player.override:.0%}"
    return None


def _read(player: Player, stream, keys: bool) -> None:
    while True:
        data = stream.read(1) if keys else stream.readline()
        if not data:
            return
        if not data.strip() and data != " ":
            continue
        if apply(player, data) is None:
            print(
                f"jaxcnc: unknown control {data.strip()!r} ({KEYS_HELP if keys else 'hold, resume, override R, stop'})",
                file=sys.stderr,
            )


@contextmanager
def operator_controls(player: Player, stream=None):
    """Read controls from ``stream`` (default stdin) in a background thread while the block runs."""
    stream = stream or sys.stdin
    keys = stream.isatty()
    saved = None
    if keys:
        import termios
        import tty

        fd = stream.fileno()
        saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)  # keys arrive one by one, Ctrl-C still signals
        stream = os.fdopen(os.dup(fd), "r", buffering=1)
    threading.Thread(target=_read, args=(player, stream, keys), daemon=True).start()
    try:
        yield keys
    finally:
        if saved is not None:
            import termios

            termios.tcsetattr(sys.stdin.fileno(), termios.TCSADRAIN, saved)
