"""measure_table streams the table in bounded memory and measures exactly what the mapped version did."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from jaxcnc.format import FINE_SCALE, TableFile, TableWriter
from jaxcnc.machine import MachineConfig
from jaxcnc.ticks.verify import REL_SLACK, Measurement, TableRows, Violation, _runs, measure_table
from tests.conftest import machine_text, make_machine

_QUANTITIES = ("v", "a", "j")


def _previous_measure(table: TableFile, machine: MachineConfig, chunk_rows: int = 1 << 18) -> Measurement:
    """measure_table as it was before streaming (memory-mapped slices, argmin/argmax over the whole column),
    kept verbatim as the reference; the machine-consistency checks (axes, rate) are left out."""
    h = table.header
    axes = h.axes
    meas = Measurement(axes=axes, n_rows=h.n_rows)
    f, q = h.tick_hz, h.discrete_mm
    limits = {}
    for a in axes:
        if a in machine.axis_names:
            ax = machine.axis(a)
            limits[a] = {"v": ax.v_max, "a": ax.a_max, "j": ax.j_max}
    scale = {name: q / FINE_SCALE * f ** (i + 1) for i, name in enumerate(_QUANTITIES)}
    noise = {name: 2 ** (i + 1) * 0.5 * scale[name] for i, name in enumerate(_QUANTITIES)}
    maxima = {name: np.zeros(len(axes)) for name in _QUANTITIES}
    pmin = np.full(len(axes), np.inf)
    pmax = np.full(len(axes), -np.inf)
    n = h.n_rows
    pending: dict[tuple[str, str], list[tuple[int, int, float]]] = {}
    for start in range(0, n + 3, chunk_rows):
        stop = min(start + chunk_rows, n + 3)
        idx = np.clip(np.arange(start - 3, stop), 0, n - 1)
        pos = np.asarray(table.positions[idx[0] : idx[-1] + 1], dtype=np.int64)[idx - idx[0]]
        fine = (
            np.asarray(table.fine[idx[0] : idx[-1] + 1], dtype=np.int64)[idx - idx[0]]
            if h.has_fine
            else np.zeros_like(pos)
        )
        pmin = np.minimum(pmin, pos.min(axis=0) * q)
        pmax = np.maximum(pmax, pos.max(axis=0) * q)
        d = np.diff(pos, axis=0) * np.int64(2**32) + np.diff(fine, axis=0)
        diffs = {"v": d[2:], "a": np.diff(d, axis=0)[1:], "j": np.diff(d, n=2, axis=0)}
        for name, dd in diffs.items():
            val = np.abs(dd).astype(np.float64) * scale[name]
            maxima[name] = np.maximum(maxima[name], val.max(axis=0, initial=0.0))
            for i, a in enumerate(axes):
                lim = limits.get(a, {}).get(name)
                if lim is None:
                    continue
                bad = val[:, i] > lim * (1 + REL_SLACK) + noise[name]
                for r0, r1 in _runs(bad):
                    pending.setdefault((a, name), []).append((start + r0, start + r1, float(val[r0 : r1 + 1, i].max())))
    for (a, name), runs in pending.items():
        merged: list[list] = []
        for r0, r1, v in runs:
            if merged and r0 == merged[-1][1] + 1:
                merged[-1][1], merged[-1][2] = r1, max(merged[-1][2], v)
            else:
                merged.append([r0, r1, v])
        for r0, r1, v in merged:
            meas.violations.append(Violation(min(r0, n - 1), min(r1, n - 1), a, name, v, limits[a][name]))
    for i, a in enumerate(axes):
        if a not in machine.axis_names:
            continue
        ax = machine.axis(a)
        if pmin[i] < ax.min - q / 2:
            meas.violations.append(Violation(int(np.argmin(table.positions[:, i])), 0, a, "pos", pmin[i], ax.min))
        if pmax[i] > ax.max + q / 2:
            meas.violations.append(Violation(int(np.argmax(table.positions[:, i])), 0, a, "pos", pmax[i], ax.max))
    for i, a in enumerate(axes):
        meas.max_abs_v[a] = float(maxima["v"][i])
        meas.max_abs_a[a] = float(maxima["a"][i])
        meas.max_abs_j[a] = float(maxima["j"][i])
        meas.min_pos[a], meas.max_pos[a] = float(pmin[i]), float(pmax[i])
    meas.violations.sort(key=lambda v: (v.first_tick, v.axis, v.quantity))
    return meas


def _write(path: Path, p_mm: np.ndarray, fine: bool = True, block_rows: int = 64, q: float = 0.001) -> TableFile:
    """A table of exact positions ``p_mm`` ``(n, 3)`` (x, y, z) at 10 kHz, written in uneven pieces; its header
    declares the first row as the job's start (``start_mm``), so the machine rests there before row 0 as the
    reference assumes."""
    x = p_mm / q
    pos = np.round(x)
    res = np.clip(np.round((x - pos) * FINE_SCALE), -(2.0**31), 2.0**31 - 1)
    with TableWriter(
        path,
        axes=["x", "y", "z"],
        tick_hz=10000,
        discrete_mm=q,
        n_rows=len(p_mm),
        fine=fine,
        block_rows=block_rows,
        meta={"start_mm": [float(v) for v in p_mm[0]]},
    ) as w:
        for a, b in ((0, len(p_mm) // 3), (len(p_mm) // 3, len(p_mm))):
            w.write(pos[a:b].astype(np.int32), res[a:b].astype(np.int32) if fine else None)
    return TableFile(path)


def _violating_path(n: int, seed: int) -> np.ndarray:
    """A random path that breaks speed, acceleration, jerk and travel limits here and there, with its
    travel extremes repeated (so the first tick holding them matters)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 10000.0
    p = np.stack([480 * np.sin(40 * t), 20 * np.cos(9 * t), 2 * np.sin(3 * t)], axis=1)
    kicks = rng.integers(0, n, 6)
    p[kicks] += rng.normal(0, 0.05, (6, 3))  # a and j spikes
    p[n // 3 : n // 3 + 50, 0] = 505.25  # beyond max x, held for 50 ticks
    p[2 * n // 3, 0] = 505.25  # and again later: the first tick is reported
    p[n // 2 : n // 2 + 3, 1] = -512.5  # beyond min y
    return p


def _assert_same(new: Measurement, old: Measurement) -> None:
    for name in ("max_abs_v", "max_abs_a", "max_abs_j", "min_pos", "max_pos"):
        assert getattr(new, name) == getattr(old, name), name
    assert len(new.violations) == len(old.violations)
    for a, b in zip(new.violations, old.violations, strict=True):
        if b.quantity == "pos":  # the old one wrote last_tick = 0; a travel violation names one tick
            assert (a.first_tick, a.last_tick, a.axis, a.value, a.limit) == (
                b.first_tick,
                b.first_tick,
                b.axis,
                b.value,
                b.limit,
            )
        else:
            assert a == b


@pytest.mark.parametrize("n", [1, 2, 3, 5, 100, 1000, 4099])
@pytest.mark.parametrize("chunk_rows", [1, 4, 37, 1 << 16])
def test_streamed_equals_previous(tmp_path: Path, n: int, chunk_rows: int) -> None:
    machine = make_machine(j=2e5)
    table = _write(tmp_path / "t.ticks", _violating_path(n, seed=n))
    new = measure_table(table, machine, chunk_rows=chunk_rows)
    _assert_same(new, _previous_measure(table, machine, chunk_rows=chunk_rows))
    _assert_same(new, measure_table(table, machine))  # independent of the chunking
    for threads in (1, 2, 3):  # and of the threads the chunks are measured on (in chunk order)
        _assert_same(new, measure_table(table, machine, chunk_rows=chunk_rows, threads=threads))
    if n >= 1000:
        kinds = {(v.axis, v.quantity) for v in new.violations}
        assert {("x", "v"), ("x", "a"), ("x", "j"), ("x", "pos"), ("y", "pos")} <= kinds, kinds


def test_travel_violation_names_first_extreme_tick(tmp_path: Path) -> None:
    n = 1000
    p = np.zeros((n, 3))
    p[:, 0] = np.linspace(0, 1, n)
    p[[137, 138, 600], 0] = 501.0  # x max at 137 first (and at chunk boundaries below)
    p[[64, 900], 1] = -502.0
    table = _write(tmp_path / "t.ticks", p)
    for chunk in (1, 64, 137, 138, 1 << 16):
        pos = [
            v
            for v in measure_table(table, make_machine(v=1e5, a=1e9), chunk_rows=chunk).violations
            if v.quantity == "pos"
        ]
        assert [(v.axis, v.first_tick, v.last_tick, v.value) for v in pos] == [
            ("y", 64, 64, -502.0),
            ("x", 137, 137, 501.0),
        ]


def test_without_fine_channel(tmp_path: Path) -> None:
    machine = make_machine()
    table = _write(tmp_path / "t.ticks", _violating_path(777, seed=3), fine=False)
    new = measure_table(table, machine, chunk_rows=50)
    assert any(v.quantity == "table" and "fine" in v.axis for v in new.violations)
    new.violations = [v for v in new.violations if v.quantity != "table"]
    _assert_same(new, _previous_measure(table, machine, chunk_rows=50))


def test_table_rows_match_the_map(tmp_path: Path) -> None:
    table = _write(tmp_path / "t.ticks", _violating_path(300, seed=1), block_rows=16)
    with TableRows(table) as rows:
        for a, b in ((0, 300), (15, 17), (290, 400), (-5, 3), (299, 300), (10, 10)):
            pos, fine = rows.read(a, b)
            lo, hi = max(a, 0), min(b, 300)
            np.testing.assert_array_equal(pos, table.positions[lo:hi])
            np.testing.assert_array_equal(fine, table.fine[lo:hi])
            np.testing.assert_array_equal(rows.exact_mm(a, b), table.exact_mm(lo, hi))


_PEAK = """
import sys
from jaxcnc.cli.main import main

def status(key):
    return int(next(ln for ln in open("/proc/self/status") if ln.startswith(key)).split()[1]) // 1024

base = status("VmRSS")
rc = main(["check", sys.argv[1], "--machine", sys.argv[2]])
print("PEAK", rc, base, status("VmHWM"))
"""


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc (Linux)")
def test_check_of_long_table_in_bounded_memory(tmp_path: Path) -> None:
    """`jaxcnc check` of a 10-minute 10 kHz table (6 M rows, 144 MB of positions and residuals) grows the
    process by far less than the table: the mapped version grew by at least the table's size."""
    n = 6_000_001
    path = tmp_path / "long.ticks"
    q = 0.001
    with TableWriter(path, axes=["x", "y", "z"], tick_hz=10000, discrete_mm=q, n_rows=n) as w:
        for s in range(0, n, 1 << 20):
            t = np.arange(s, min(s + (1 << 20), n)) / 10000.0
            ramp = np.sin(np.pi * t / 600.0) ** 2  # at rest at both ends
            x = np.stack([40 * np.sin(t) * ramp, 30 * np.cos(0.7 * t) * ramp, 5 * np.sin(0.3 * t) * ramp], 1) / q
            pos = np.round(x)
            w.write(pos.astype(np.int32), np.round((x - pos) * FINE_SCALE).astype(np.int32))
    mfile = tmp_path / "machine.toml"
    mfile.write_text(machine_text())
    r = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(_PEAK), str(path), str(mfile)],
        capture_output=True,
        text=True,
        check=False,
    )
    line = next((ln for ln in r.stdout.splitlines() if ln.startswith("PEAK")), None)
    assert line is not None, r.stdout + r.stderr
    _, rc, base, peak = line.split()
    assert int(rc) == 0, r.stdout + r.stderr
    table_mb = path.stat().st_size / 2**20
    assert int(peak) - int(base) < 48, (base, peak, table_mb)  # MiB: the chunk buffers, not the table
    assert int(peak) < 300
