"""Independent verification of a tick table against a machine's limits (NumPy only).

Speed, acceleration and jerk are measured at the tick rate by finite differences of the
*unquantised* positions (integer discretes plus the fine residual). Differences are taken in
exact int64 arithmetic on the 2^-32-discrete fixed-point values, then scaled, so the
measurement noise is ~1e-13 mm per tick. The machine is taken to stand still before the first
row and after the last, so a table that starts or ends moving fails. Nothing here reads the
plan: the table and the machine file are the only inputs.

The table is streamed: ``chunk_rows`` rows at a time are read with ``pread`` (:class:`TableRows`), never
through the memory map, so checking a job of any length stays in bounded memory (tens of MB).
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from jaxcnc.errors import TableFileError
from jaxcnc.format import FINE_SCALE, TableFile, fixed_to_mm
from jaxcnc.machine import MachineConfig

#: Relative slack for floating-point rounding when comparing with a limit.
REL_SLACK = 1e-9
_QUANTITIES = ("v", "a", "j")
_UNITS = {"v": "mm/s", "a": "mm/s^2", "j": "mm/s^3", "pos": "mm"}
#: Threads of the table checks at most (:func:`check_threads`).
MAX_CHECK_THREADS = 4
T = TypeVar("T")


@dataclass(frozen=True)
class Violation:
    """A run of consecutive ticks where one quantity of one axis exceeds its limit."""

    first_tick: int
    last_tick: int
    axis: str
    #: "v", "a", "j", "pos", "start", "path", "table", "pulse" or "laser" (the last three: ``axis`` holds the text)
    quantity: str
    value: float  # the worst value in the run
    limit: float

    def __str__(self) -> str:
        if self.quantity == "table":
            return f"table: {self.axis}"
        if self.quantity == "pulse":
            return f"tick {self.first_tick}: {self.axis}"
        if self.quantity == "laser":  # ``axis`` holds the text (jaxcnc.ticks.verify_laser)
            span = f"tick {self.first_tick}" + (f" (to {self.last_tick})" if self.last_tick != self.first_tick else "")
            return f"{span} laser: {self.axis}"
        if self.quantity == "start":
            return (
                f"tick 0 axis {self.axis}: the first row is at {self.value:.6g} mm but the job starts at "
                f"{self.limit:.6g} mm (a jump into the first row)"
            )
        span = f"tick {self.first_tick}" + (f" (to {self.last_tick})" if self.last_tick != self.first_tick else "")
        if self.quantity == "path":  # ``axis`` names the program line (jaxcnc.ticks.deviation)
            return f"{span} {self.axis}: distance from the programmed path {self.value:.6g} mm > {self.limit:.6g} mm"
        name = {"v": "|v|", "a": "|a|", "j": "|j|", "pos": "position"}[self.quantity]
        rel = ">" if self.quantity != "pos" or self.value > self.limit else "<"
        return (
            f"{span} axis {self.axis}: {name} = {self.value:.6g} {_UNITS[self.quantity]} {rel} limit {self.limit:.6g}"
        )


@dataclass
class Measurement:
    """Per-axis maxima measured on a table, and the limit violations found."""

    axes: list[str]
    max_abs_v: dict[str, float] = field(default_factory=dict)
    max_abs_a: dict[str, float] = field(default_factory=dict)
    max_abs_j: dict[str, float] = field(default_factory=dict)
    min_pos: dict[str, float] = field(default_factory=dict)
    max_pos: dict[str, float] = field(default_factory=dict)
    violations: list[Violation] = field(default_factory=list)
    n_rows: int = 0
    pulses: Any = None  # a pulsed table's PulseCheck (jaxcnc.ticks.verify_pulses), when checked
    path: Any = None  # the PathDeviation (jaxcnc.ticks.deviation), when the program was compared
    path_note: str = ""  # why the path was not compared, when it was not
    path_summary: str = ""  # the path compared by a machine's own check (stage + scanner, stage + galvo): its result
    laser: Any = None  # the LaserCheck (jaxcnc.ticks.verify_laser), when the table has a power channel

    @property
    def ok(self) -> bool:
        return not self.violations


class TableRows:
    """Rows of a table read on demand with ``pread``, so a table of any length is checked in bounded memory.

    Slices of :attr:`TableFile.positions` are memory-mapped: every page touched stays resident in the
    process (a 1 h table at 10 kHz maps ~0.9 GB). Here positions come from :meth:`TableFile.read_positions`
    and the fine residuals from the same layout at ``header.fine_offset`` (``docs/table-format.md``: rows are
    contiguous across blocks), each call into fresh arrays of only the rows asked for. The blocks' CRCs were
    checked when the :class:`TableFile` was opened. Use as a context manager (it holds a file descriptor).
    """

    def __init__(self, table: TableFile):
        self.table = table
        self.header = table.header
        self._fd: int | None = None

    def __enter__(self) -> TableRows:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Release the file descriptor of the fine channel."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def read(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Rows ``start:stop`` (clipped to the table): ``(positions, fine)``, ``(m, n_axes)`` int32 each;
        ``fine`` is ``None`` when the table has no fine channel."""
        h = self.header
        start, stop = max(0, start), min(stop, h.n_rows)
        pos = self.table.read_positions(start, stop)
        if not h.has_fine:
            return pos, None
        if stop <= start:
            return pos, np.zeros((0, h.n_axes), np.int32)
        if self._fd is None:
            self._fd = os.open(self.table.path, os.O_RDONLY)
        row = h.n_axes * 4
        data = os.pread(self._fd, (stop - start) * row, h.fine_offset + start * row)
        if len(data) != (stop - start) * row:
            raise TableFileError(f"{self.table.path}: short read of fine rows {start}-{stop - 1} (file changed?)")
        return pos, np.frombuffer(data, dtype="<i4").reshape(stop - start, h.n_axes).astype(np.int32)

    def exact_mm(self, start: int, stop: int) -> np.ndarray:
        """Unquantised positions (discretes + fine residual) of rows ``start:stop`` in mm, ``(m, n_axes)``
        float64 — the same values as :meth:`TableFile.exact_mm`."""
        pos, fine = self.read(start, stop)
        return fixed_to_mm(pos, fine, self.header.discrete_mm)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive index ranges of the True runs of a 1-D mask."""
    if not mask.any():
        return []
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1, strict=False))


def check_threads() -> int:
    """Threads the table checks measure chunks on by default: the CPUs this process may run on, at most
    :data:`MAX_CHECK_THREADS`."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(cpus, MAX_CHECK_THREADS))


def map_chunks(rows: TableRows, fn: Callable[[TableRows, int], T], starts: Sequence[int], threads: int) -> Iterator[T]:
    """``fn(rows, start)`` for each of ``starts``, yielded in their order, computed on ``threads`` threads.

    NumPy releases the GIL inside its array loops, so chunks measured on two threads take ~0.55-0.6 of the time
    on a 2-core machine. At most ``2 × threads`` chunks are in flight (the working memory stays bounded). The
    reader's file descriptors are opened here, before any thread reads (``pread`` on a shared descriptor is
    safe from any thread). Results are combined by the caller in chunk order, so they are the same, bit for bit,
    whatever the number of threads.
    """
    if threads <= 1 or len(starts) <= 1:
        yield from (fn(rows, s) for s in starts)
        return
    rows.read(0, 1)  # both descriptors open before the threads share them
    with ThreadPoolExecutor(threads, thread_name_prefix="jaxcnc-check") as pool:
        ahead: deque = deque()
        for s in starts:
            ahead.append(pool.submit(fn, rows, s))
            if len(ahead) >= 2 * threads:
                yield ahead.popleft().result()
        while ahead:
            yield ahead.popleft().result()


def require_machine_axes(table: TableFile, machine: MachineConfig) -> None:
    """Refuse (:class:`~jaxcnc.errors.TableFileError`) a table whose axes are not the machine's, in order
    (:meth:`TableFile.require_axes`: sinks send columns by position)."""
    table.require_axes(machine.axis_names, f"machine {machine.name!r}")


def job_start_mm(table: TableFile, machine: MachineConfig | None) -> np.ndarray | None:
    """Where the job starts, per column (mm): the header's ``start_mm`` when it records one, otherwise the
    machine's home of each axis (where every job starts, :func:`jaxcnc.planners.program_start`); ``None``
    without either."""
    start = table.header.meta.get("start_mm")
    if start is not None:
        return np.asarray(start, np.float64)
    if machine is None:
        return None
    return np.array([machine.axis(a).home for a in table.header.axes], np.float64)


def _fixed_point(x_mm: np.ndarray, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions in mm as (discretes, fine residual in 2^-32 discretes), int64 each, discretes clipped to int32."""
    u = np.clip(np.asarray(x_mm, np.float64) / q, -(2.0**31), 2.0**31 - 1)
    pos = np.round(u)
    return pos.astype(np.int64), np.round((u - pos) * FINE_SCALE).astype(np.int64)


def measure_table(
    table: TableFile, machine: MachineConfig | None = None, chunk_rows: int = 1 << 16, threads: int | None = None
) -> Measurement:
    """Measure a table's per-axis |v|, |a|, |j| and travel; check them against ``machine``.

    Differences at row ``k`` use rows ``k-3..k`` (jerk), ``k-2..k`` (acceleration) and
    ``k-1..k`` (speed). The machine stands at rest at the job's start before the table (:func:`job_start_mm`:
    the header's ``start_mm`` or the machine's home; without either, at the first row) and at rest at the last
    row after it, so a table that starts or ends moving, or whose first row is not the start (a jump into the
    first row), fails like any other motion — and a first row more than half a discrete from the start is a
    ``start`` violation of its own. With a machine the table's axes must be the machine's, in order
    (:func:`require_machine_axes`, else :class:`~jaxcnc.errors.TableFileError`).
    The table is read ``chunk_rows`` rows at a time (plus a 3-row overlap), measured on ``threads`` threads
    (:func:`check_threads` by default; :func:`map_chunks`); the results depend on neither. A travel violation
    names the first tick holding the axis' extreme.
    """
    h = table.header
    axes = h.axes
    meas = Measurement(axes=axes, n_rows=h.n_rows)
    f, q = h.tick_hz, h.discrete_mm
    limits = {}
    if machine is not None:
        require_machine_axes(table, machine)
        if not h.has_fine:
            meas.violations.append(
                Violation(
                    0, 0, "no fine channel: speed and acceleration cannot be verified at the tick rate", "table", 0, 0
                )
            )
        if abs(h.tick_hz - machine.tick_hz) > 1e-9 * machine.tick_hz:
            meas.violations.append(
                Violation(
                    0, 0, f"tick rate {h.tick_hz:g} Hz differs from the machine's {machine.tick_hz:g} Hz", "table", 0, 0
                )
            )
        if abs(h.discrete_mm - machine.discrete_mm) > 1e-12:
            meas.violations.append(
                Violation(
                    0,
                    0,
                    f"discrete {h.discrete_mm:g} mm differs from the machine's {machine.discrete_mm:g} mm",
                    "table",
                    0,
                    0,
                )
            )
        for a in axes:
            ax = machine.axis(a)
            limits[a] = {"v": ax.v_max, "a": ax.a_max, "j": ax.j_max}
    start_mm = job_start_mm(table, machine)
    with TableRows(table) as rows:
        row0 = rows.exact_mm(0, 1)[0]
    if start_mm is None:
        start_mm = row0
    for i, a in enumerate(axes):
        if abs(row0[i] - start_mm[i]) > 0.5 * q * (1 + 1e-9):
            meas.violations.append(Violation(0, 0, a, "start", float(row0[i]), float(start_mm[i])))
    start_pos, start_fine = _fixed_point(start_mm, q)
    if not h.has_fine:  # the table's rows are whole discretes: so is the start it rests at
        start_fine = np.zeros_like(start_fine)
    # Scale from k-th integer difference (in 2^-32 discretes) to mm/s^k.
    scale = {name: q / FINE_SCALE * f ** (i + 1) for i, name in enumerate(_QUANTITIES)}
    # Noise of the fine channel's rounding (half a unit per row) in the k-th difference.
    noise = {name: 2 ** (i + 1) * 0.5 * scale[name] for i, name in enumerate(_QUANTITIES)}
    maxima = {name: np.zeros(len(axes)) for name in _QUANTITIES}
    n = h.n_rows
    # travel: the extreme discretes of each axis and the first tick holding them, from the same pass
    lo_val = np.full(len(axes), np.iinfo(np.int64).max)
    hi_val = np.full(len(axes), np.iinfo(np.int64).min)
    lo_tick = np.zeros(len(axes), np.int64)
    hi_tick = np.zeros(len(axes), np.int64)
    pending: dict[tuple[str, str], list[tuple[int, int, float]]] = {}

    def chunk(rows: TableRows, start: int) -> tuple:
        """Rows ``start-3 .. stop-1`` of the table extended by 3 copies of its first and last rows: their
        extremes (value, first tick), the maxima of |v|, |a|, |j| and the runs over the limits."""
        stop = min(start + chunk_rows, n + 3)
        idx = np.clip(np.arange(start - 3, stop), 0, n - 1)
        first = int(idx[0])
        raw, raw_fine = rows.read(first, int(idx[-1]) + 1)
        pos = raw.astype(np.int64)[idx - first]
        fine = raw_fine.astype(np.int64)[idx - first] if raw_fine is not None else np.zeros_like(pos)
        before = np.arange(start - 3, stop) < 0  # the machine at rest at the job's start before row 0
        pos[before], fine[before] = start_pos, start_fine
        extremes = (raw.min(axis=0), raw.max(axis=0), first + raw.argmin(axis=0), first + raw.argmax(axis=0))
        # exact int64; a step of more than 2^28 discretes in a tick (absurd) is clipped so nothing overflows
        d = np.clip(np.diff(pos, axis=0), -(2**28), 2**28) * np.int64(2**32) + np.diff(fine, axis=0)
        diffs = {"v": d[2:], "a": np.diff(d, axis=0)[1:], "j": np.diff(d, n=2, axis=0)}
        peaks, runs = {}, []
        for name, dd in diffs.items():
            val = np.abs(dd).astype(np.float64) * scale[name]  # row k = start + i
            peaks[name] = val.max(axis=0, initial=0.0)
            for i, a in enumerate(axes):
                lim = limits.get(a, {}).get(name)
                if lim is None:
                    continue
                bad = val[:, i] > lim * (1 + REL_SLACK) + noise[name]
                runs += [((a, name), start + r0, start + r1, float(val[r0 : r1 + 1, i].max())) for r0, r1 in _runs(bad)]
        return extremes, peaks, runs

    with TableRows(table) as rows:
        for (c_lo, c_hi, c_lo_tick, c_hi_tick), peaks, runs in map_chunks(
            rows, chunk, range(0, n + 3, chunk_rows), check_threads() if threads is None else threads
        ):
            # in chunk order: rows seen again (the 3-row overlap) hold no new extreme, so the strict test keeps
            # the first tick
            lower, higher = c_lo < lo_val, c_hi > hi_val
            lo_tick, hi_tick = np.where(lower, c_lo_tick, lo_tick), np.where(higher, c_hi_tick, hi_tick)
            lo_val, hi_val = np.where(lower, c_lo, lo_val), np.where(higher, c_hi, hi_val)
            for name, peak in peaks.items():
                maxima[name] = np.maximum(maxima[name], peak)
            for key, r0, r1, v in runs:
                pending.setdefault(key, []).append((r0, r1, v))
    pmin, pmax = lo_val * q, hi_val * q
    for (a, name), runs in pending.items():
        merged: list[list] = []
        for r0, r1, v in runs:  # join runs split by chunk boundaries
            if merged and r0 == merged[-1][1] + 1:
                merged[-1][1], merged[-1][2] = r1, max(merged[-1][2], v)
            else:
                merged.append([r0, r1, v])
        for r0, r1, v in merged:
            meas.violations.append(Violation(min(r0, n - 1), min(r1, n - 1), a, name, v, limits[a][name]))
    if machine is not None:
        for i, a in enumerate(axes):
            ax = machine.axis(a)
            if pmin[i] < ax.min - q / 2:
                t = int(lo_tick[i])
                meas.violations.append(Violation(t, t, a, "pos", float(pmin[i]), ax.min))
            if pmax[i] > ax.max + q / 2:
                t = int(hi_tick[i])
                meas.violations.append(Violation(t, t, a, "pos", float(pmax[i]), ax.max))
    for i, a in enumerate(axes):
        meas.max_abs_v[a] = float(maxima["v"][i])
        meas.max_abs_a[a] = float(maxima["a"][i])
        meas.max_abs_j[a] = float(maxima["j"][i])
        meas.min_pos[a], meas.max_pos[a] = float(pmin[i]), float(pmax[i])
    meas.violations.sort(key=lambda v: (v.first_tick, v.axis, v.quantity))
    return meas
