"""A controller's row buffer and servo clock, with a ramp-down along the path when the buffer runs low.

Rows (int32 discretes, one per table tick) arrive in table order; every servo tick the drives take
the next one. A PC feeding the buffer is only soft real-time: when it (or the link) is late, the
buffer runs dry. Holding the last row would be a velocity step — an unbounded acceleration. This
clock instead watches its level: when fewer than ``reserve`` rows are left and the job's end has
not arrived, it plays the buffered rows at a rate ``r`` that falls to 0 as fast as the spare
acceleration allows, so the drives stop *on the path*, at rest, before the buffer ends. When the
buffer is refilled to ``resume`` rows (or the end has arrived), ``r`` ramps back to 1.

The rate law is the time warp's (:mod:`jaxcnc.hw.timewarp`): played at rate ``r``, a row interval
with velocity ``v`` and acceleration ``a`` (per axis, table time) moves at ``v r`` with acceleration
``a r² + v ṙ``; so ``|ṙ| ≤ SAFETY · min_i (A_i − |a_i| r²) / |v_i|`` keeps every axis within ``A_i``.
Positions between rows are interpolated linearly; after a ramp the drives stay a fraction of a tick
behind the table, within one discrete of its path. Each row is *taken* (reported executed) once,
in order, when the played table time passes it.

NumPy only (this is the controller side).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from jaxcnc.hw.timewarp import SAFETY


class DriveClock:
    """Buffer and clock of ``n_axes`` drives at ``tick_hz``; ``a_max_disc_s2`` per axis in discretes/s².

    Without ``a_max_disc_s2`` the clock cannot ramp: on underrun the drives hold the last row (counted in
    ``hard_stops``). ``reserve``: rows kept for a ramp-down; ``resume``: rows needed to restart.
    """

    def __init__(
        self,
        n_axes: int,
        tick_hz: float,
        a_max_disc_s2: np.ndarray | None = None,
        reserve: int = 2048,
        resume: int = 4096,
    ):
        self.n_axes, self.f = n_axes, float(tick_hz)
        self.a_max_disc_s2 = None if a_max_disc_s2 is None else np.asarray(a_max_disc_s2, dtype=np.float64)
        self.reserve = reserve if a_max_disc_s2 is not None else 0
        self.resume = max(resume, self.reserve)
        self._chunks: deque[np.ndarray] = deque()
        self.queued = 0  # rows buffered, not yet taken
        self.executed = -1  # index of the last row taken
        self.frac = 0.0  # played table time beyond the last row taken, in [0, 1)
        self.rate = 1.0
        self.last = np.zeros(n_axes, np.int64)  # rows executed and executed - 1
        self.last2 = np.zeros(n_axes, np.int64)
        self.underruns = 0  # ramp-downs (or hard stops) for want of rows
        self.hard_stops = 0  # the buffer ended before the ramp reached rest (or no a_max_disc_s2)
        self.held_ticks = 0  # servo ticks spent at rest waiting for rows
        self._down = False  # ramping down (or at rest) for want of rows
        self.stopping = False  # stop(): ramping down for good
        #: For the rows the last :meth:`run` / :meth:`run_to_rest` took: True where taken at the planned rate.
        #: A row taken while the rate ramps (underrun, stop) is played dark: the laser goes off before the
        #: drives slow, and comes back with the planned rate.
        self.last_lit = np.zeros(0, bool)

    def stop(self) -> None:
        """Stop for good (an abort, a lost player): from now the rate ramps to 0 within the buffered
        rows and stays there; rows left in the buffer are never taken. Without ``a_max_disc_s2`` the drives
        stop at once (a hard stop)."""
        if not self.stopping and self.rate > 0 and self.a_max_disc_s2 is None:
            self.hard_stops += 1
        self.stopping = True

    @property
    def at_rest(self) -> bool:
        """The drives stand still: rate 0, or every row taken."""
        return self.rate == 0.0 or (self.queued == 0 and self.frac == 0.0)

    def run_to_rest(self, positions: bool = False, chunk: int = 4096) -> tuple[np.ndarray, np.ndarray]:
        """After :meth:`stop`: run the servo ticks of the ramp-down (virtually); rows taken and positions."""
        taken, pos, lit = [], [], []
        while not self.at_rest:
            t, p = self.run(chunk, False, positions)
            taken.append(t)
            pos.append(p)
            lit.append(self.last_lit)
        self.last_lit = np.concatenate(lit) if lit else np.zeros(0, bool)
        empty = np.zeros((0, self.n_axes))
        return (
            np.concatenate(taken) if taken else empty.astype(np.int32),
            np.concatenate(pos) if pos else empty,
        )

    def push(self, rows: np.ndarray) -> None:
        """Append rows (the next table ticks) to the buffer."""
        if rows.shape[0] and self.executed == -1 and self.queued == 0:
            self.last = self.last2 = np.asarray(rows[0], dtype=np.int64)  # the job starts at rest there
        if rows.shape[0]:
            self._chunks.append(np.asarray(rows, dtype=np.int32))
            self.queued += rows.shape[0]

    def _peek(self, k: int) -> np.ndarray:
        """The next ``min(k, queued)`` buffered rows (merging chunks at the head as needed)."""
        while len(self._chunks) > 1 and self._chunks[0].shape[0] < k:
            self._chunks.appendleft(np.concatenate([self._chunks.popleft(), self._chunks.popleft()]))
        return self._chunks[0][:k] if self._chunks else np.zeros((0, self.n_axes), np.int32)

    def _take(self, k: int) -> np.ndarray:
        """Remove the next ``k`` rows from the buffer (``k <= queued``)."""
        out = []
        while k > 0:
            head = self._chunks[0]
            n = min(k, head.shape[0])
            out.append(head[:n])
            if n == head.shape[0]:
                self._chunks.popleft()
            else:
                self._chunks[0] = head[n:]
            k -= n
        rows = np.concatenate(out) if len(out) > 1 else out[0]
        self.queued -= rows.shape[0]
        self.executed += rows.shape[0]
        if rows.shape[0] >= 2:
            self.last2 = rows[-2].astype(np.int64)
        else:
            self.last2 = self.last
        self.last = rows[-1].astype(np.int64)
        return rows

    def _position(self) -> np.ndarray:
        if self.frac == 0.0 or self.queued == 0:
            return self.last.astype(np.float64)
        return self.last + self.frac * (self._peek(1)[0] - self.last)

    def run(self, ticks: int, ended: bool, positions: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Advance ``ticks`` servo ticks; ``ended``: every row of the job is in the buffer.

        Returns ``(taken, positions)``: the rows taken in these ticks (table rows
        ``executed - len(taken) + 1 .. executed``) and, if asked, the drives' positions at each
        tick ``(ticks, n_axes)`` float discretes (fewer rows once the job is done).
        """
        taken: list[np.ndarray] = []
        pos: list[np.ndarray] = []
        lit: list[np.ndarray] = []
        left = ticks
        while left > 0:
            keep = (0 if ended else self.reserve) + (self.frac > 0.0)  # an interpolation needs the next row
            if self.rate == 1.0 and self.queued > keep and not self.stopping:
                k = min(left, self.queued - keep)  # as planned: one row per tick, vectorised
                rows = self._take(k)
                taken.append(rows)
                lit.append(np.ones(k, bool))
                if positions:
                    p = rows.astype(np.float64)
                    if self.frac > 0.0:
                        after = np.vstack([rows[1:], self._peek(1)]).astype(np.float64)
                        p += self.frac * (after - p)
                    pos.append(p)
                left -= k
                continue
            if self.queued == 0 and ended:
                break  # the job is done
            if self.stopping:
                target = 0.0
                ended = False  # the rows left are not the job's end: the ramp must fit them
            elif ended or self.queued >= self.resume:
                target, self._down = 1.0, False
            elif self.queued < max(self.reserve, 1):
                if not self._down:
                    self.underruns += 1
                    self.hard_stops += self.a_max_disc_s2 is None
                target, self._down = 0.0, True
            else:
                target = self.rate  # between reserve and resume: carry on as we are
            if target == 0.0 and self.rate == 0.0:
                self.held_ticks += left  # at rest on the path, waiting for rows
                if positions:
                    pos.append(np.repeat(self._position()[None, :], left, axis=0))
                break
            planned = target == 1.0 and self.rate == 1.0
            rows, p = self._step(target, ended)
            if rows is not None:
                taken.append(rows)
                lit.append(np.full(rows.shape[0], planned))
            if positions:
                pos.append(p[None, :])
            left -= 1
        self.last_lit = np.concatenate(lit) if lit else np.zeros(0, bool)
        empty = np.zeros((0, self.n_axes))
        return (
            np.concatenate(taken) if taken else empty.astype(np.int32),
            np.concatenate(pos) if pos else empty,
        )

    def _r_dot(self) -> float:
        """The fastest rate change the next row interval's spare acceleration allows (1/s)."""
        if self.a_max_disc_s2 is None:
            return np.inf  # no limits known: the rate jumps (a hard stop)
        r1 = self._peek(1)[0].astype(np.int64)
        v = (r1 - self.last) * self.f  # discretes/s, table time
        a = (r1 - 2 * self.last + self.last2) * self.f**2
        moving = np.abs(v) > 0
        if not moving.any():
            return np.inf
        spare = np.maximum(self.a_max_disc_s2 - np.abs(a) * self.rate**2, 0.0)
        return SAFETY * float(np.min(spare[moving] / np.abs(v[moving])))

    def _step(self, target: float, ended: bool) -> tuple[np.ndarray | None, np.ndarray]:
        """One servo tick with the rate moving toward ``target`` at the spare acceleration."""
        if self.queued == 0:
            self.rate = target
            return None, self._position()
        step = self._r_dot() / self.f
        new = self.rate + float(np.clip(target - self.rate, -step, step))
        # table ticks played in this servo tick (the mean rate; without limits the rate jumps)
        dt = new if self.a_max_disc_s2 is None else 0.5 * (self.rate + new)
        room = self.queued - self.frac  # table time left in the buffer
        if dt >= room and not ended:
            dt, new = room, 0.0  # the ramp did not fit the buffer: stop at its last row
            self.hard_stops += 1
        self.rate = new
        self.frac += dt
        k = min(int(self.frac), self.queued)
        rows = None
        if k:
            rows = self._take(k)
            self.frac -= k
        if self.queued == 0:
            self.frac = 0.0
        return rows, self._position()
