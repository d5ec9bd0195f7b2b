"""The next window's grid built in a worker thread while a window is solved (issue 13): the same Plan, bit for bit.

``topp._GridAhead`` joins a window's grid from the rows the window before built from its commit point on and the
rows the worker built ahead (``grid.join_pieces``); these tests plan programs of several windows with and without
it and compare every array of the plans, check that the joins happened (else the comparison proves nothing), and
that the worker's failures surface from ``plan_job`` as the main thread's do.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxcnc.planners.grid as grid_module
import jaxcnc.planners.topp as topp
from jaxcnc.bench.programs import BENCH_MACHINE, cam_polyline
from jaxcnc.buckets import bucket_size
from jaxcnc.gcode import load_gcode, parse_gcode
from jaxcnc.geometry import build_spans
from jaxcnc.machine import load_machine, parse_machine
from jaxcnc.planners import plan_job, program_start
from jaxcnc.planners.grid import AXIS_FIELDS, GridPiece, build_grid, interval_counts, join_pieces
from jaxcnc.planners.timelaw import PLAN_COLUMNS

PEERS = Path(__file__).resolve().parents[1] / ".." / "shared" / "peers"
GRID_FIELDS = ("span", "s_start", "delta", "curved", "boxed", *AXIS_FIELDS)


def _plan_arrays(plan) -> dict[str, bytes]:
    """Every array of a Plan, as bytes (bit for bit: ``-0.0`` is not ``0.0``, NaN is itself)."""
    out = {k: np.ascontiguousarray(getattr(plan, k)) for k in PLAN_COLUMNS}
    return {k: v.tobytes() + str(v.shape).encode() for k, v in out.items()}


def _count_joins(monkeypatch) -> list[int]:
    """Record the interval count of every grid ``_GridAhead`` joins (``None``: not joined)."""
    joined: list[int] = []
    join = topp.join_pieces

    def counting(*args, **kwargs):
        grid = join(*args, **kwargs)
        joined.append(None if grid is None else len(grid))
        return grid

    monkeypatch.setattr(topp, "join_pieces", counting)
    return joined


def _with_and_without(monkeypatch, program, machine, window: int) -> tuple[dict, dict, list]:
    monkeypatch.setattr(topp, "WINDOW_INTERVALS", window)
    monkeypatch.setattr(topp, "_cpus", lambda: 2)  # (a machine of one CPU plans without the worker)
    monkeypatch.setattr(topp, "OVERLAP_WINDOWS", False)
    alone = _plan_arrays(plan_job(program, machine).plan)
    monkeypatch.setattr(topp, "OVERLAP_WINDOWS", True)
    joined = _count_joins(monkeypatch)
    overlapped = _plan_arrays(plan_job(program, machine).plan)
    return alone, overlapped, joined


def test_blended_contour_in_windows_plans_the_same_with_the_worker(monkeypatch):
    machine = parse_machine(BENCH_MACHINE + "corner_tol_mm = 0.01\n", "<bench>")
    alone, overlapped, joined = _with_and_without(monkeypatch, cam_polyline(3000), machine, 1 << 9)
    assert sum(g is not None for g in joined) >= 4  # several windows joined from the worker's rows
    assert alone.keys() == overlapped.keys()
    for k in alone:
        assert alone[k] == overlapped[k], k


def test_small_windows_that_grow_and_refine_plan_the_same(monkeypatch):
    """Windows of 64 intervals: some settle no node and grow (their grid is built as before), and the arcs among
    the blends of every third span are cut finer once (the interior check made to fail there): the same plan with
    the worker, whose rows of spans cut finer since are not used."""
    moves = "".join(
        f"G1 X{10 + i % 7} Y{i * 0.5:.2f}\nG2 X{10 + (i + 1) % 7} Y{i * 0.5 + 0.25:.2f} R4\n" for i in range(60)
    )
    machine = parse_machine(BENCH_MACHINE + "corner_tol_mm = 0.01\n", "<bench>")
    start = program_start(machine)
    program = parse_gcode("G21 G90\nG0 X0 Y0\nF6000\nG64 P0.01\n" + moves + "M2\n", "<arcs>", start=start, home=start)
    spans = build_spans(program, 0.01)
    step = spans.length / interval_counts(spans)  # before any refinement
    check, refined = topp.grid_excess, []

    def failing_once(arrays, grid, *args, **kwargs):
        bad = check(arrays, grid, *args, **kwargs)
        once = grid.curved & ~grid.boxed & (grid.span % 3 == 0) & (grid.delta > 0.5 * step[grid.span])
        refined.append(int(once.sum()))
        return bad | once

    monkeypatch.setattr(topp, "grid_excess", failing_once)
    alone, overlapped, joined = _with_and_without(monkeypatch, program, machine, 64)
    assert any(g is None for g in joined) and sum(g is not None for g in joined) > 10  # grown windows, joined ones
    assert sum(refined) > 20
    for k in alone:
        assert alone[k] == overlapped[k], k


@pytest.mark.skipif(not PEERS.is_dir(), reason="../shared/peers absent")
@pytest.mark.parametrize("name", ["meander520", "plasmatest"])
def test_peer_programs_in_windows_plan_the_same(monkeypatch, name):
    path = PEERS / "programs" / f"{name}.ngc"
    machine_file = PEERS / "machines" / "m1000_t0.01.toml"
    if not (path.is_file() and machine_file.is_file()):
        pytest.skip(f"{path} absent")
    machine = load_machine(machine_file)
    program = load_gcode(path, start=program_start(machine), home=program_start(machine))
    alone, overlapped, joined = _with_and_without(monkeypatch, program, machine, 1 << 10)
    assert any(g is not None for g in joined)
    for k in alone:
        assert alone[k] == overlapped[k], k


def test_a_failure_in_the_worker_surfaces_from_plan_job(monkeypatch):
    monkeypatch.setattr(topp, "OVERLAP_WINDOWS", True)
    monkeypatch.setattr(topp, "WINDOW_INTERVALS", 1 << 9)
    monkeypatch.setattr(topp, "_cpus", lambda: 2)
    build = topp.build_grid

    def failing(*args, **kwargs):
        if threading.current_thread() is not threading.main_thread():
            raise MemoryError("worker out of memory")
        return build(*args, **kwargs)

    monkeypatch.setattr(topp, "build_grid", failing)
    machine = parse_machine(BENCH_MACHINE + "corner_tol_mm = 0.01\n", "<bench>")
    with pytest.raises(MemoryError, match="worker out of memory"):
        plan_job(cam_polyline(400), machine)


@pytest.fixture(scope="module")
def blended_spans():
    spans = build_spans(cam_polyline(120), 0.01)
    return spans, interval_counts(spans)


def _same_grid(a, b) -> None:
    for f in GRID_FIELDS:
        assert getattr(a, f).tobytes() == getattr(b, f).tobytes(), f
    for f in AXIS_FIELDS:
        assert a.axis_major[f].shape == b.axis_major[f].shape
        assert a.axis_major[f].tobytes() == b.axis_major[f].tobytes(), f  # the zero padding too


@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_join_pieces_is_build_grid(blended_spans, data):
    """A window joined from a previous window's tail and a piece built ahead is the grid built for it."""
    spans, counts = blended_spans
    n = len(spans)
    first = data.draw(st.integers(0, n - 3))
    split = data.draw(st.integers(first + 1, n - 2))
    last = data.draw(st.integers(split + 1, n))
    end = data.draw(st.integers(last, n))
    prev_first = data.draw(st.integers(0, first))
    prev = build_grid(spans, counts, None, prev_first, split)
    row = int(counts[prev_first:first].sum())
    pieces = [
        GridPiece.of(prev, counts, row),
        GridPiece(split, end, counts[split:end].copy(), build_grid(spans, counts, None, split, end)),
    ]
    pad_to = bucket_size(int(counts[first:last].sum()))
    _same_grid(join_pieces(pieces, counts, first, last, pad_to), build_grid(spans, counts, None, first, last, pad_to))


def test_join_pieces_refuses_gaps_and_changed_counts(blended_spans):
    spans, counts = blended_spans
    counts = counts.copy()
    a = GridPiece.of(build_grid(spans, counts, None, 0, 40), counts)
    b = GridPiece(50, 90, counts[50:90].copy(), build_grid(spans, counts, None, 50, 90))
    assert join_pieces([a, b], counts, 10, 60, 512) is None  # spans 40..49 are missing
    c = GridPiece(40, 90, counts[40:90].copy(), build_grid(spans, counts, None, 40, 90))
    assert join_pieces([a, c], counts, 10, 60, 512) is not None
    counts[45] *= 4  # cut finer since the piece was built
    assert join_pieces([a, c], counts, 10, 60, 512) is None
    assert grid_module.join_pieces is join_pieces
