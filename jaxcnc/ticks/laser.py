"""Laser power per tick: M3 constant, M4 scaled with the tool's speed (``docs/laser.md``). NumPy only.

The table's ``laser`` events say when the beam is commanded on (mode 3 or 4, the S value) and off; its
``feed`` events say the programmed feed. The power channel holds, for every tick ``k``, the output during
``[k, k+1)`` (a zero-order hold, as a PWM or DAC output is):

- M3: ``S``;
- M4: ``S · max(floor, curve(v_k / F))`` with ``v_k = |p_{k+1} - p_k| · tick_hz`` the tool's mean speed over that
  tick, ``F`` the programmed feed and ``curve`` the machine's ``[laser] m4_curve_*`` (the identity by default),
  ``v_k / F`` clipped to [0, 1];
- dark otherwise (0).

An M4 tick without a ``feed`` event before it (a table written by a tool that records none) plays as M3.

With the identity curve and no floor the energy a tick deposits, ``S · v_k / F / tick_hz``, is exactly ``S / F``
per millimetre of the distance it covers: M4 burns evenly through corners and accelerations, where constant
power over-burns by ``F / v``. :func:`power_of_rows` is what the writer stores; ``check`` recomputes it from the
table alone (:mod:`jaxcnc.ticks.verify_laser`).
"""

from __future__ import annotations

import numpy as np

from jaxcnc.format import EventKind
from jaxcnc.machine import LaserConfig


def held(events: np.ndarray, kind: int, first: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``aux`` and ``value`` of the latest ``kind`` event at or before each tick ``first .. first+count-1``
    (``(count,)`` each; 0 before the first such event). ``events``: sorted ``EVENT_DTYPE`` records."""
    ev = events[events["kind"] == kind]
    i = np.searchsorted(ev["tick"], np.arange(first, first + count, dtype=np.int64), side="right") - 1
    aux = np.concatenate([[0], ev["aux"].astype(np.int64)])[i + 1]
    value = np.concatenate([[0.0], ev["value"]])[i + 1]
    return aux, value


def m4_fraction(speed_ratio: np.ndarray, laser: LaserConfig) -> np.ndarray:
    """The M4 power fraction at ``speed_ratio = v / F`` (any shape, clipped to [0, 1]): the machine's curve
    (linear between its points; the identity without one), never below ``m4_floor``."""
    r = np.clip(speed_ratio, 0.0, 1.0)
    if laser.m4_curve_speed is not None and laser.m4_curve_power is not None:
        r = np.interp(r, laser.m4_curve_speed, laser.m4_curve_power)
    return np.maximum(r, laser.m4_floor)


def tick_speed_mm_s(p_mm: np.ndarray, tick_hz: float) -> np.ndarray:
    """Mean tool speed over each tick: ``p_mm`` ``(m+1, n_axes)`` positions of ticks ``k .. k+m`` → ``(m,)`` mm/s."""
    return np.linalg.norm(np.diff(p_mm, axis=0), axis=1) * tick_hz


def power_of_rows(p_mm: np.ndarray, events: np.ndarray, first: int, tick_hz: float, laser: LaserConfig) -> np.ndarray:
    """Laser output of ticks ``first .. first+m-1`` from exact positions ``p_mm`` ``(m+1, n_axes)`` of ticks
    ``first .. first+m`` (the last row: the tick after, for the speed over the last tick) and the table's
    events; ``(m,)`` float32 in the S scale."""
    m = p_mm.shape[0] - 1
    mode, s = held(events, EventKind.LASER, first, m)
    _, feed = held(events, EventKind.FEED, first, m)
    v = tick_speed_mm_s(p_mm, tick_hz)
    ratio = np.divide(v, feed, out=np.zeros_like(v), where=feed > 0)
    scale = np.where((mode == 4) & (feed > 0), m4_fraction(ratio, laser), 1.0)
    return np.where(mode != 0, s * scale, 0.0).astype(np.float32)


# --- Laser latency (machine file ``[laser] on_delay_s``, ``off_delay_s``; docs/laser.md "Latency") -------------
#
# The model, in ticks d_on and d_off: the laser's output y follows its command c d_on ticks late (switching on, and
# every level change while lit: M4 modulation, a raster pixel's level), except that the end of a lit run reaches the
# output d_off ticks after the command went dark. A commanded lit run [a, b) (c > 0 on a .. b-1, dark at a-1 and b)
# burns [a + d_on, b + d_off), at y[k] = c[min(k - d_on, b - 1)]: when d_off > d_on the output holds the run's last
# commanded level over its final d_off - d_on ticks (the laser cannot change level once its command is dark); when
# d_on > d_off the command's last d_on - d_off ticks never reach the output. In closed form, with counts of dark
# ticks and the last lit tick at or before each tick (no window is ever materialised: O(ticks)):
#
#   delivered (command -> output)          commanded (wanted output O -> command)
#   d_off >= d_on: y[k] = c[i], i the last lit tick     c[j] = O[j + d_on] if O is lit all over [j + d_on, j + d_off]
#                  in [k - d_off, k - d_on], else 0
#   d_on > d_off:  y[k] = c[k - d_on] if c is lit all   c[j] = O[i], i the last lit tick in [j + d_off, j + d_on]
#                  over [k - d_on, k - d_off], else 0
#
# commanded() inverts delivered() exactly when every lit run of O is longer than d_off - d_on ticks and every dark
# gap between runs longer than d_on - d_off ticks (and no run starts before tick d_on); delivered(commanded(O)) is
# then reachable(O): O with each run's last d_off - d_on ticks held at the level before them.


def _lit_all(x: np.ndarray, a: int, b: int, m: int) -> np.ndarray:
    """``(m,)``: whether ``x[i + a .. i + b]`` (inclusive, ``0 <= a <= b``) is lit (> 0) throughout, ``i < m``."""
    dark = np.concatenate([[0], np.cumsum(x <= 0)])
    i = np.arange(m)
    return dark[i + b + 1] - dark[i + a] == 0


def _last_lit(x: np.ndarray, a: int, b: int, m: int) -> np.ndarray:
    """``(m,)``: the value of the last lit tick of ``x[i + a .. i + b]`` (inclusive), 0 when none is lit."""
    idx = np.maximum.accumulate(np.where(x > 0, np.arange(x.size), -1))
    i = np.arange(m)
    last = idx[i + b]
    return np.where(last >= i + a, x[np.maximum(last, 0)], 0.0)


def delivered_power(cmd: np.ndarray, d_on: int, d_off: int) -> np.ndarray:
    """The laser's output from its command (the model above). ``cmd[i]`` is the command of tick ``k0 - hi + i``
    (``hi = max(d_on, d_off)``, ``lo = min``; ticks before 0 dark); returns the output of ticks
    ``k0 .. k0 + m - 1``, ``(m,)`` with ``m = cmd.size - (hi - lo)``."""
    hi, lo = max(d_on, d_off), min(d_on, d_off)
    m = cmd.size - (hi - lo)
    if d_off >= d_on:  # x[i + (hi - d_off) .. i + (hi - d_on)] = c[k - d_off .. k - d_on]
        return _last_lit(cmd, hi - d_off, hi - d_on, m).astype(np.float32)
    return np.where(_lit_all(cmd, hi - d_on, hi - d_off, m), cmd[hi - d_on : hi - d_on + m], 0.0).astype(np.float32)


def commanded_power(out: np.ndarray, d_on: int, d_off: int) -> np.ndarray:
    """The command that makes the laser output ``out`` (the model above). ``out[i]`` is the wanted output of tick
    ``j0 + lo + i`` (``lo = min(d_on, d_off)``, ``hi = max``); returns the command of ticks ``j0 .. j0 + m - 1``,
    ``(m,)`` with ``m = out.size - (hi - lo)``."""
    hi, lo = max(d_on, d_off), min(d_on, d_off)
    m = out.size - (hi - lo)
    if d_off >= d_on:  # x[i + (d_on - lo) .. i + (d_off - lo)] = O[j + d_on .. j + d_off]
        lit = _lit_all(out, d_on - lo, d_off - lo, m)
        return np.where(lit, out[d_on - lo : d_on - lo + m], 0.0).astype(np.float32)
    return _last_lit(out, d_off - lo, d_on - lo, m).astype(np.float32)


def reachable_power(out: np.ndarray, d_on: int, d_off: int) -> np.ndarray:
    """The output the delayed laser can produce for a wanted output: ``out`` with each lit run's last
    ``h = d_off - d_on`` ticks held at the level of the tick before them (unchanged when ``h <= 0``). ``out[i]``
    is tick ``k0 - h - 1 + i``; returns ticks ``k0 .. k0 + m - 1``, ``m = out.size - 2h - 1`` (``out`` itself when
    ``h <= 0``)."""
    h = d_off - d_on
    if h <= 0:
        return np.asarray(out, np.float32)
    m = out.size - 2 * h - 1
    n = out.size
    # next dark tick at or after each tick (n when none)
    nxt = np.minimum.accumulate(np.where(out <= 0, np.arange(n), n)[::-1])[::-1]
    k = np.arange(m) + h + 1
    end = nxt[k]  # the run's end B (first dark tick) for lit ticks
    tail = (out[k] > 0) & (end - k <= h)
    src = np.where(tail, np.maximum(end - h - 1, 0), k)
    return np.where(out[k] > 0, out[src], 0.0).astype(np.float32)


def shift_laser_events(events: np.ndarray, d_on: int, d_off: int, sign: int = -1) -> np.ndarray:
    """``events`` with every ``laser`` event moved by ``sign · d_on`` ticks (switching on, or a new level) or
    ``sign · d_off`` (switching off, value 0): ``sign = -1`` commands the table's events early (the writer),
    ``+1`` recovers the programmed ticks (the check). Of several laser events on one tick only the last (the one
    in force) is kept, so the order survives the shift; sorted by tick, stably."""
    ev = np.array(events, copy=True)
    las = np.flatnonzero(ev["kind"] == EventKind.LASER)
    if las.size:
        t = ev["tick"][las]
        drop = las[:-1][t[:-1] == t[1:]]
        ev = np.delete(ev, drop)
        las = np.flatnonzero(ev["kind"] == EventKind.LASER)
        on = ev["value"][las] > 0
        ev["tick"][las] += sign * np.where(on, d_on, d_off)
    return ev[np.argsort(ev["tick"], kind="stable")]


class LatencyShift:
    """Streams a wanted output into the commanded power channel: :meth:`push` the output of consecutive ticks from
    tick 0 (any chunk sizes), get back the command of the ticks it now determines (it looks ``max(d_on, d_off)``
    ticks ahead, across chunks); :meth:`finish` returns the rest up to ``n_rows``. Raises a one-line
    :class:`jaxcnc.errors.SourceError` naming the program line (from the ``block`` events) where the output cannot
    be reached: a run that would have to be commanded before tick 0, a run shorter than ``d_off - d_on`` ticks or a
    dark gap shorter than ``d_on - d_off`` ticks."""

    def __init__(self, d_on: int, d_off: int, n_rows: int, events: np.ndarray, source: str, tick_hz: float):
        self.d_on, self.d_off, self.n_rows, self.source, self.tick_hz = d_on, d_off, n_rows, source, tick_hz
        self.lo, self.hi = min(d_on, d_off), max(d_on, d_off)
        self._blocks = events[events["kind"] == EventKind.BLOCK]
        self._buf = np.zeros(0, np.float32)  # wanted output of ticks b0 .. b0 + len - 1
        self._b0 = 0
        self._done = 0  # command returned for ticks < done
        self._lit = False  # the last pushed tick is lit
        self._edge = None  # tick of the last rising edge (while lit) or falling edge (while dark); None: none yet

    def _fail(self, tick: int, why: str) -> None:
        from jaxcnc.errors import SourceError

        i = int(np.searchsorted(self._blocks["tick"], tick, side="right")) - 1
        line = int(self._blocks["aux"][i]) if i >= 0 else 0
        raise SourceError(self.source, line, 0, f"laser latency: {why} (tick {tick})")

    def too_early(self, tick: int) -> None:
        """Raise: a burn at ``tick`` would have to be commanded before the job starts."""
        us = 1e6 / self.tick_hz
        why = (
            f"the burn starts {tick * us:g} µs into the job, but the laser must be switched on "
            f"{self.d_on * us:g} µs ([laser] on_delay_s) before it: start the job with a move before it"
        )
        self._fail(tick, why)

    def _edges(self, t0: int, o: np.ndarray) -> None:
        lit = o > 0
        prev = np.concatenate([[self._lit], lit[:-1]])
        ticks = t0 + np.arange(o.size)
        rise, fall = ticks[lit & ~prev], ticks[~lit & prev]
        us = 1e6 / self.tick_hz
        if rise.size and rise[0] < self.d_on:
            self.too_early(int(rise[0]))
        h = self.d_off - self.d_on
        # the edges alternate: pair each fall with the rise before it, each rise with the fall before it
        if h > 0 and fall.size:
            s = np.concatenate([[self._edge], rise])[: fall.size] if self._lit else rise[: fall.size]
            length = fall - s
            if (bad := np.flatnonzero(length <= h)).size:
                i = int(bad[0])
                self._fail(int(s[i]), f"a burn of {length[i] * us:g} µs is shorter than off_delay_s - on_delay_s "
                           f"= {h * us:g} µs: the laser cannot stop in time")  # fmt: skip
        if h < 0 and rise.size:
            if self._lit:
                r, e = rise, fall[: rise.size]
            elif self._edge is None:  # dark since tick 0: the first rise follows no burn
                r, e = rise[1:], fall[: rise.size - 1]
            else:
                r, e = rise, np.concatenate([[self._edge], fall])[: rise.size]
            gap = r - e
            if (bad := np.flatnonzero(gap <= -h)).size:
                i = int(bad[0])
                self._fail(int(r[i]), f"a dark gap of {gap[i] * us:g} µs is shorter than on_delay_s - off_delay_s "
                           f"= {-h * us:g} µs: the laser cannot switch off and on again in time")  # fmt: skip
        if o.size:
            self._lit = bool(lit[-1])
            last = rise if self._lit else fall
            if last.size:
                self._edge = int(last[-1])

    def push(self, out: np.ndarray) -> np.ndarray:
        """Append the wanted output of the next ticks; the command of the ticks now determined (maybe none)."""
        out = np.asarray(out, np.float32)
        end = self._b0 + self._buf.size
        self._edges(end, out)
        self._buf = np.concatenate([self._buf, out])
        return self._emit(min(self._b0 + self._buf.size - self.hi, self.n_rows))

    def finish(self) -> np.ndarray:
        """The command of every tick not returned yet, up to ``n_rows`` (the output is dark after the table)."""
        end = self._b0 + self._buf.size
        if end < self.n_rows:
            raise ValueError(f"wanted output of {end} ticks pushed, {self.n_rows} announced")
        self._edges(end, np.zeros(1, np.float32))
        self._buf = np.concatenate([self._buf, np.zeros(self.hi + 1, np.float32)])
        return self._emit(self.n_rows)

    def _emit(self, upto: int) -> np.ndarray:
        if upto <= self._done:
            return np.zeros(0, np.float32)
        a = self._done + self.lo - self._b0  # the wanted output of ticks done + lo .. upto - 1 + hi
        cmd = commanded_power(self._buf[a : upto + self.hi - self._b0], self.d_on, self.d_off)
        self._done = upto
        keep = self._done + self.lo - self._b0
        self._buf, self._b0 = self._buf[keep:], self._b0 + keep
        return cmd
