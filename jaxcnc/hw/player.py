"""The player: streams a verified table file to a sink, keeping its buffer fed.

It never computes motion. It opens the table (which verifies every checksum before anything
moves), then loops: write as many rows as the sink has room for, each with the events that fall
on them, and let the sink's clock run when its buffer is full. Progress is the sink's executed
tick.

Feed hold, resume and override (:meth:`Player.hold`, :meth:`Player.resume`,
:meth:`Player.set_override`, from any thread): from the last row it sent, the player plays the
table re-sampled by :class:`~jaxcnc.hw.timewarp.TimeWarp`, its rate moving to the commanded one
(0 for a hold) as fast as the table's spare acceleration allows. The path is the table's.

Controlled stop (Ctrl-C, or :meth:`Player.request_stop`): a hold that ends the play — the drives
stop on the path, at rest, within the acceleration limits, after the rows already buffered plus
the hold distance.

The laser: sinks whose ``write`` takes a ``power`` argument get each row's power, the table's power channel
(``docs/laser.md``; a version 1 table: its laser events held). On a hold or a stop the laser goes off at
the first re-sampled row, before the drives slow (a ``laser`` off event and power 0), and comes back
(an on event, the table's power; M4 scaled by the rate) when the drives move again.
"""

from __future__ import annotations

import inspect
import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from jaxcnc.format import EVENT_DTYPE, EventKind, TableFile
from jaxcnc.hw.sinks.base import Sink
from jaxcnc.hw.timewarp import TimeWarp


@dataclass(frozen=True)
class PlayResult:
    rows_sent: int
    executed_tick: int
    wall_s: float
    table_time_s: float
    stopped: bool = False  # a controlled stop ended the play before the table's end

    @property
    def real_time_factor(self) -> float:
        """Table duration divided by the wall time it took to play (> 1: faster than real time)."""
        return self.table_time_s / self.wall_s if self.wall_s > 0 else float("inf")


class Player:
    """Plays a table into a sink. Thread-safe controls while it plays (they need ``a_max``):
    :meth:`hold`, :meth:`resume`, :meth:`set_override` and :meth:`request_stop`.

    Feed hold and override re-sample the table by time warp (:class:`~jaxcnc.hw.timewarp.TimeWarp`):
    the path is the table's, the rate ramps within the spare acceleration. The laser is switched
    off once a hold has brought the drives to rest and back on before they move again. A command
    acts after the rows already in the sink's buffer (its latency is the buffer's length).
    """

    def __init__(
        self,
        table: TableFile,
        sink: Sink,
        *,
        a_max: np.ndarray | None = None,
        chunk_rows: int = 4096,
        warp_chunk_rows: int = 256,
    ):
        self.table, self.sink, self.a_max, self.chunk_rows = table, sink, a_max, chunk_rows
        self.warp_chunk_rows = warp_chunk_rows
        self._stop = threading.Event()
        self._held = False
        self._override = 1.0
        self.holds = 0  # holds that brought the drives to rest

    # ---- controls (any thread) -------------------------------------------------------------------
    def request_stop(self) -> None:
        self._stop.set()

    def _need_limits(self) -> None:
        if self.a_max is None:
            raise ValueError("feed hold and override need the machine's acceleration limits (a_max)")

    def hold(self) -> None:
        """Feed hold: ramp down along the path to rest and wait there."""
        self._need_limits()
        self._held = True

    def resume(self) -> None:
        """Leave a feed hold: ramp back up to the override rate."""
        self._held = False

    def set_override(self, rate: float) -> None:
        """Feed override: play at ``rate`` (0 < rate ≤ 1) times the planned speed."""
        self._need_limits()
        if not 0.0 < rate <= 1.0:
            raise ValueError("the override is a rate in (0, 1]: the table is already planned at the limits")
        self._override = float(rate)

    @property
    def override(self) -> float:
        """The feed override rate (1 = as planned)."""
        return self._override

    @property
    def held(self) -> bool:
        return self._held

    @property
    def commanded_rate(self) -> float:
        return 0.0 if self._held or self._stop.is_set() else self._override

    # ---- playing ---------------------------------------------------------------------------------
    def _send(
        self,
        first: int,
        rows: np.ndarray,
        events: np.ndarray,
        progress,
        interruptible: bool = False,
        power: np.ndarray | None = None,
    ) -> int:
        """Write ``rows`` for ticks ``first ..`` as the sink makes room, with the events among them.

        Returns the rows written: all of them, or with ``interruptible`` those written before a
        control asked for something other than the plan (the caller then warps from there).
        """
        done = 0
        while done < rows.shape[0]:
            if interruptible and self.commanded_rate != 1.0 and self.a_max is not None:
                break
            room = self.sink.free_rows()
            if room <= 0:
                self.sink.wait()
                if progress:
                    progress(self.sink.executed_tick() + 1)
                continue
            n = min(room, rows.shape[0] - done)
            lo, hi = np.searchsorted(events["tick"], [first + done, first + done + n])
            if self._takes_power:
                self.sink.write(first + done, rows[done : done + n], events[lo:hi], power[done : done + n])
            else:
                self.sink.write(first + done, rows[done : done + n], events[lo:hi])
            done += n
        return done

    def _warped_events(self, taus: np.ndarray, tau0: float, out: int) -> np.ndarray:
        """The table's events in table time ``(tau0, taus[-1]]``, moved to the output ticks that reach them."""
        ev = self.table.events
        lo, hi = np.searchsorted(ev["tick"], [np.floor(tau0) + 1, np.floor(taus[-1]) + 1])
        moved = ev[lo:hi].copy()
        moved["tick"] = out + np.searchsorted(taus, moved["tick"], side="left")
        return moved

    def _warped_power(self, taus: np.ndarray, tau0: float, dark: bool) -> np.ndarray:
        """Power of the re-sampled rows at table times ``taus``: 0 while dark; else the table's power at the
        row each falls in, scaled by the rate (table ticks per output tick) where the table runs M4."""
        if dark or taus.size == 0:
            return np.zeros(taus.size, np.float32)
        h = self.table.header
        idx = np.clip(np.floor(taus).astype(np.int64), 0, h.n_rows - 1)
        lo, hi = int(idx.min()), int(idx.max()) + 1
        base = self.table.read_power(lo, hi)[idx - lo].astype(np.float64)
        las = self.table.events[self.table.events["kind"] == EventKind.LASER]
        mode = np.r_[0, las["aux"].astype(np.int64)][np.searchsorted(las["tick"], idx, side="right")]
        rate = np.clip(np.diff(np.concatenate([[tau0], taus])), 0.0, 1.0)
        return np.where(mode == 4, base * rate, base).astype(np.float32)

    def _laser_event(self, tick: int, power: float, mode: int) -> np.ndarray:
        e = np.zeros(1, EVENT_DTYPE)
        e["tick"], e["kind"], e["aux"], e["value"] = tick, EventKind.LASER, mode, power
        return e

    def run(self, progress=None) -> PlayResult:
        """Play to the end, or until a stop is requested (then ramp down and stop)."""
        table, sink = self.table, self.sink
        h = table.header
        self._takes_power = takes_power(sink)
        t0 = time.perf_counter()
        sink.open(h)
        out = 0  # output ticks sent (the sink's tick numbers)
        row = 0  # table rows played, while not warped
        warp: TimeWarp | None = None
        laser = (0.0, 0)  # the table's laser state at the last row sent: (power, mode)
        parked = False  # a hold brought the drives to rest
        dark = False  # a hold or stop switched the laser off (before the drives slowed)
        stopped = False
        try:
            while True:
                if warp is None:
                    if row >= h.n_rows:
                        break
                    if self.commanded_rate == 1.0 or self.a_max is None:
                        n = min(self.chunk_rows, h.n_rows - row)
                        power = table.read_power(row, row + n) if self._takes_power else None
                        k = self._send(out, table.read_positions(row, row + n), table.events, progress, True, power)
                        lo, hi = np.searchsorted(table.events["tick"], [row, row + k])
                        laser = _laser_state(table.events[lo:hi], laser)
                        row, out = row + k, out + k
                        continue
                    warp = TimeWarp(table, self.a_max)
                    warp.tau = float(max(row - 1, 0))
                if warp.done:
                    break
                if parked and self._stop.is_set():  # a stop while held at rest: done, at once
                    stopped = True
                    break
                target = self.commanded_rate
                sink_ev = np.zeros(0, EVENT_DTYPE)
                if target > 0.0 and dark:  # leaving a hold: the laser back on as the drives move again
                    if laser[0] > 0:
                        sink_ev = self._laser_event(out, *laser)
                    dark = parked = False
                elif target == 0.0 and not dark:  # a hold or stop begins: the laser off before the drives slow
                    if laser[0] > 0:
                        sink_ev = self._laser_event(out, 0.0, 0)
                    dark = True
                warp.command(target)
                tau0 = warp.tau
                rows = warp.rows(self.warp_chunk_rows)
                taus = warp.last_taus
                events = self._warped_events(taus, tau0, out) if rows.shape[0] else np.zeros(0, EVENT_DTYPE)
                laser = _laser_state(events, laser)
                if dark:  # the table's laser events stay in force for later, but nothing fires while dark
                    events = events[events["kind"] != EventKind.LASER]
                if warp.rate == 0.0 and target == 0.0 and not parked and rows.shape[0]:
                    parked = True  # at rest
                    if self._stop.is_set():
                        stopped = True
                    else:
                        self.holds += 1
                events = np.sort(np.concatenate([sink_ev, events]), order="tick", kind="stable")
                power = self._warped_power(taus, tau0, dark) if self._takes_power else None
                k = self._send(out, rows, events, progress, power=power)
                out += k
                if stopped:
                    break
        except BaseException:
            abort_sink(sink)  # the laser off, the drives brought to rest on the path; then the error
            raise
        sink.close()
        if progress:
            progress(sink.executed_tick() + 1)
        return PlayResult(
            rows_sent=out,
            executed_tick=sink.executed_tick(),
            wall_s=time.perf_counter() - t0,
            table_time_s=max(sink.executed_tick(), 0) / h.tick_hz,  # the motion played
            stopped=stopped,
        )


def takes_power(sink: Sink) -> bool:
    """Whether ``sink.write`` takes the rows' ``power`` (the laser channel); older sinks get events only."""
    try:
        return "power" in inspect.signature(sink.write).parameters
    except (TypeError, ValueError):
        return False


def abort_sink(sink: Sink) -> None:
    """The way out on an error or a signal: the sink's ``abort`` (laser off at once, drives ramped down
    on the path within the buffered rows, the recording finished), else its ``close``. Never raises:
    the error that brought the player here is the one reported."""
    try:
        abort = getattr(sink, "abort", None)
        if abort is not None:
            abort()
        else:
            sink.close()
    except Exception:  # noqa: BLE001 - the original error is the one to report
        pass


def _laser_state(events: np.ndarray, state: tuple[float, int]) -> tuple[float, int]:
    """The laser (power, mode) after ``events``, given ``state`` before them."""
    laser = events[events["kind"] == EventKind.LASER]
    return (float(laser["value"][-1]), int(laser["aux"][-1])) if laser.size else state


STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


@contextmanager
def sigint_stops(player: Player):
    """While the block runs (main thread), Ctrl-C, SIGTERM and SIGHUP ask ``player`` for a controlled
    stop when it has limits; without limits they interrupt the play (the sink is aborted: the laser
    off, the drives stopped on the path). A second signal during a controlled stop aborts at once."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_signal(*_) -> None:
        if player.a_max is None or player._stop.is_set():
            raise KeyboardInterrupt
        player.request_stop()

    previous = {s: signal.signal(s, on_signal) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def play(
    table: TableFile,
    sink: Sink,
    *,
    chunk_rows: int = 4096,
    progress=None,
    a_max: np.ndarray | None = None,
    stop_on_sigint: bool = False,
) -> PlayResult:
    """Play ``table`` into ``sink``; ``progress`` is an optional callable taking executed rows.

    With ``a_max`` (the machine's per-axis limits, table axis order) and ``stop_on_sigint``, Ctrl-C
    makes a controlled stop instead of raising :class:`KeyboardInterrupt`.
    """
    player = Player(table, sink, a_max=a_max, chunk_rows=chunk_rows)
    if not stop_on_sigint:
        return player.run(progress)
    with sigint_stops(player):
        return player.run(progress)
