"""Planning in bounded memory (issue 13) gives the same spans and plans, bit for bit.

The memory itself is measured by ``jaxcnc bench plan`` (peak resident per size, fresh process); these
tests pin what the memory work must not change: windows upload their own spans, the segments are
written into arrays allocated once (and grown), spans are assembled field by field.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

from jaxcnc.bench.programs import BENCH_MACHINE, cam_polyline
from jaxcnc.buckets import bucket_size
from jaxcnc.geometry import SpanKind, build_spans
from jaxcnc.geometry.spans import SPAN_FIELDS, pad_tables, slice_spans
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job
from jaxcnc.planners.grid import device_spans, frames_at

PLAN_FIELDS = (
    "length", "v0", "vp", "v1", "a_acc", "a_dec", "t_acc", "t_cru", "t_dec",
    "group_tick", "offset_ticks", "first_tick", "span", "s_start",
)  # fmt: skip


def _same_plan(a, b) -> None:
    assert a.n_ticks == b.n_ticks
    for f in PLAN_FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)


@pytest.mark.parametrize("corner_tol", [0.0, 0.01])
def test_a_window_uploads_its_own_spans_and_evaluates_them_alike(corner_tol):
    spans = build_spans(cam_polyline(400), corner_tol)
    whole = device_spans(spans)
    first, last = 37, 301
    window = device_spans(spans, first, last)
    idx = np.arange(first, last)
    curved = idx[np.isin(spans.kind[idx], (SpanKind.ARC, SpanKind.BLEND))]
    assert curved.size > 3
    s = spans.length[curved] * 0.37
    for a, b in zip(frames_at(whole, curved, s, 2), frames_at(window, curved - first, s, 2), strict=True):
        np.testing.assert_array_equal(a, b)


def test_slice_spans_keeps_rows_and_their_table_rows():
    spans = build_spans(cam_polyline(300), 0.01)
    sub = slice_spans(spans, 20, 180)
    for f in SPAN_FIELDS:
        if f != "item":
            np.testing.assert_array_equal(getattr(sub, f), getattr(spans, f)[20:180])
    arc = np.flatnonzero(sub.kind == SpanKind.ARC)
    poly = np.flatnonzero(sub.kind == SpanKind.BLEND)
    assert arc.size and poly.size
    np.testing.assert_array_equal(sub.arcs.radius[sub.item[arc]], spans.arcs.radius[spans.item[20 + arc]])
    np.testing.assert_array_equal(sub.polys.coeffs[sub.item[poly]], spans.polys.coeffs[spans.item[20 + poly]])
    padded = pad_tables(sub, 64, 512)
    assert len(padded.arcs) == 64 and len(padded.polys) == 512
    np.testing.assert_array_equal(padded.arcs.radius[: len(sub.arcs)], sub.arcs.radius)
    with pytest.raises(ValueError):
        pad_tables(sub, 0, 512)


@pytest.mark.parametrize("corner_tol", [0.0, 0.01])
def test_segments_grown_from_a_small_table_plan_the_same(monkeypatch, corner_tol):
    """The plan's segment arrays start at the grid's size; grown from one row they give the same plan."""
    import jaxcnc.planners.topp as topp

    prog = cam_polyline(1200)
    m = parse_machine(BENCH_MACHINE + f"corner_tol_mm = {corner_tol}\n", "<bench>")
    reference = plan_job(prog, m).plan
    init = topp._SegmentTable.__init__
    monkeypatch.setattr(topp._SegmentTable, "__init__", lambda self, capacity, *a: init(self, 1, *a))
    monkeypatch.setattr(topp, "WINDOW_INTERVALS", 1 << 10)  # several windows, each growing the arrays
    windowed = plan_job(prog, m).plan
    np.testing.assert_allclose(windowed.vp, reference.vp, rtol=0, atol=1e-9)
    monkeypatch.setattr(topp, "WINDOW_INTERVALS", 1 << 17)
    _same_plan(plan_job(prog, m).plan, reference)


def _window(rng, v0: np.ndarray, v1: np.ndarray):
    from types import SimpleNamespace

    import jaxcnc.planners.topp as topp

    m = v0.size
    out = {k: rng.uniform(1e-4, 1e-3, m) for k in topp._SEGMENT_KEYS}
    out.update(v0=v0, v1=v1, x_node=np.r_[v0, v1[-1:]] ** 2)
    return out, SimpleNamespace(delta=rng.uniform(0.1, 1.0, m), span=np.arange(m), s_start=np.zeros(m))


@pytest.mark.parametrize("split", ["shared", "window", "boundary", "signed zero"])
def test_segment_table_shares_v1_with_the_next_v0_only_where_their_bits_agree(split):
    import jaxcnc.planners.topp as topp

    rng = np.random.default_rng(7)
    v = rng.uniform(1.0, 2.0, 12)
    v0a, v1a, v0b, v1b = v[:5].copy(), v[1:6].copy(), v[5:11].copy(), v[6:12].copy()
    if split == "window":
        v1a[1] += 1e-12  # inside the first window: v1[1] is not v0[2]
    elif split == "boundary":
        v0b[0] += 1e-12  # the second window starts elsewhere than the first one ended
    elif split == "signed zero":
        v1a[-1], v0b[0] = -0.0, 0.0
    table = topp._SegmentTable(4)  # grown on the way
    for v0, v1 in ((v0a, v1a), (v0b, v1b)):
        out, grid = _window(rng, v0, v1)
        table.append(out, grid, v0.size)
    plan = table.plan(1000.0)
    assert np.array_equal(plan.v0.view(np.int64), np.r_[v0a, v0b].view(np.int64))
    assert np.array_equal(plan.v1.view(np.int64), np.r_[v1a, v1b].view(np.int64))
    assert np.shares_memory(plan.v0, plan.v1) == (split == "shared")


@pytest.mark.parametrize("corner_tol", [0.0, 0.01])
def test_where_segments_lie_is_derived_from_the_counts_and_equals_the_stored_columns(monkeypatch, corner_tol):
    """The table does not store ``span``, ``s_start``, ``length`` when the windows' grids follow the counts (they
    do, window after window); storing them, as it does from the first window that differs, plans the same."""
    import jaxcnc.planners.topp as topp

    prog = cam_polyline(3000)
    m = parse_machine(BENCH_MACHINE + f"corner_tol_mm = {corner_tol}\n", "<bench>")
    monkeypatch.setattr(topp, "WINDOW_INTERVALS", 1 << 11)  # several windows
    monkeypatch.setattr(topp, "TRIM_SEGMENTS", 1)  # the large plans' way (derived, trimmed) on a small one
    modes = []
    plan = topp._SegmentTable.plan
    monkeypatch.setattr(topp._SegmentTable, "plan", lambda self, hz: modes.append(self.derived) or plan(self, hz))
    derived = plan_job(prog, m).plan
    assert modes == [True]
    derivable = topp._SegmentTable._derivable
    calls = []

    def second_window_differs(self, grid, commit):
        calls.append(commit)
        return len(calls) != 2 and derivable(self, grid, commit)

    monkeypatch.setattr(topp._SegmentTable, "_derivable", second_window_differs)
    stored = plan_job(prog, m).plan
    assert modes == [True, False] and len(calls) == 2  # stored from the second window on
    _same_plan(stored, derived)
    monkeypatch.setattr(topp._SegmentTable, "_derivable", lambda self, grid, commit: False)
    _same_plan(plan_job(prog, m).plan, derived)  # stored from the first window
    # the plan keeps them derived: 2 columns stored, not 14 (v1 with v0 as the nodes' speeds, the ramps' accelerations,
    # where the segments lie, the groups' ticks and the trapezoids from the ramps made where they are read)
    assert sorted(derived.columns) == ["offset_ticks", "v_nodes"] and derived.ramps is not None
    assert derived.cuts is not None and sorted(stored.columns) != sorted(derived.columns)
    n = len(derived)
    for k0, k1 in ((0, 1), (5, 17), (n // 3, n // 2), (n - 3, n), (0, n)):
        rows = derived.rows(k0, k1)
        for f in PLAN_FIELDS:  # any window of rows is the same bits as the whole column's slice
            np.testing.assert_array_equal(rows[f], getattr(stored, f)[k0:k1], err_msg=f"{f} {k0}:{k1}")
    spans = np.arange(int(derived.span[-1]) + 1)
    np.testing.assert_array_equal(derived.span_first_segment(spans.size), stored.span_first_segment(spans.size))
    for tick in (0, derived.n_ticks // 3, derived.n_ticks):  # the tick stage's windows: the same spans and rows
        a, b = derived.device_window(tick, 64), stored.device_window(tick, 64)
        assert (a.span_first, a.span_last, a.tick_end) == (b.span_first, b.span_last, b.tick_end)
        k0 = max(int(np.searchsorted(stored.first_tick, tick, side="right")) - 1, 0)
        assert (a.span_first, a.span_last) == (int(stored.span[k0]), int(stored.span[min(k0 + 64, n) - 1]) + 1)
        for k, v in a.law.arrays.items():
            np.testing.assert_array_equal(np.asarray(v), np.asarray(b.law.arrays[k]), err_msg=f"{k} at {tick}")


def test_grid_rows_are_the_grids_rows_in_any_block_of_spans():
    from jaxcnc.planners.grid import build_grid, interval_counts
    from jaxcnc.planners.topp import _grid_rows

    spans = build_spans(cam_polyline(500), 0.01)
    counts = interval_counts(spans) * np.random.default_rng(3).integers(1, 5, len(spans))
    grid = build_grid(spans, counts)
    parts = [_grid_rows(spans.length, counts, a, b) for a, b in ((0, 17), (17, 18), (18, 260), (260, len(spans)))]
    for whole, piece in zip((grid.span, grid.s_start, grid.delta), zip(*parts, strict=True), strict=True):
        assert np.array_equal(np.concatenate(piece).view(np.int64), whole.view(np.int64))


def test_arena_limit_applies_on_glibc_only_and_leaves_the_users_setting(monkeypatch):
    import os

    from jaxcnc.memory import limit_arenas

    monkeypatch.setenv("MALLOC_ARENA_MAX", "4")
    assert limit_arenas() is False  # the user's choice stands
    monkeypatch.delenv("MALLOC_ARENA_MAX")
    try:
        glibc = (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc")
    except (AttributeError, ValueError):  # no confstr or no such name: not glibc
        glibc = False
    assert limit_arenas() is glibc


def test_heap_thresholds_apply_on_glibc_only_and_leave_the_users_setting(monkeypatch):
    import os

    from jaxcnc.memory import fix_thresholds, tune_heap

    for key in ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES"):
        monkeypatch.setenv(key, "1")
        assert fix_thresholds() is False  # the user's choice stands
        monkeypatch.delenv(key)
    try:
        glibc = (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc")
    except (AttributeError, ValueError):
        glibc = False
    monkeypatch.delenv("MALLOC_ARENA_MAX", raising=False)
    assert fix_thresholds() is glibc
    assert tune_heap() is glibc


@pytest.mark.parametrize("corner_tol", [0.0, 0.01])
def test_ramp_accelerations_are_derived_and_equal_the_stored_columns(monkeypatch, corner_tol):
    """Large plans do not store ``a_acc``, ``a_dec`` while every window's equal :func:`_ramp_accel` of its speeds and
    times (they do); storing them, as the table does from the first window that differs, plans the same."""
    import jaxcnc.planners.topp as topp

    prog = cam_polyline(3000)
    m = parse_machine(BENCH_MACHINE + f"corner_tol_mm = {corner_tol}\n", "<bench>")
    monkeypatch.setattr(topp, "WINDOW_INTERVALS", 1 << 11)  # several windows
    monkeypatch.setattr(topp, "TRIM_SEGMENTS", 1 << 30)
    small = plan_job(prog, m).plan  # stored, as small plans do
    monkeypatch.setattr(topp, "TRIM_SEGMENTS", 1)  # the large plans' way on a small one
    modes = []
    plan = topp._SegmentTable.plan

    def recorded(self, hz):
        modes.append((self.derived_accel, "a_acc" in self.cols))
        return plan(self, hz)

    monkeypatch.setattr(topp._SegmentTable, "plan", recorded)
    derived = plan_job(prog, m).plan
    assert modes == [(True, False)]
    _same_plan(derived, small)
    derivable = topp._SegmentTable._accel_derivable
    calls = []

    def second_window_differs(out, commit):
        calls.append(commit)
        return len(calls) != 2 and derivable(out, commit)

    monkeypatch.setattr(topp._SegmentTable, "_accel_derivable", staticmethod(second_window_differs))
    stored = plan_job(prog, m).plan
    assert modes[1] == (False, True) and len(calls) == 2  # stored from the second window on
    _same_plan(stored, small)


def test_ramp_accel_is_the_trapezoids_division_bit_for_bit():
    from jaxcnc.planners.motion import trapezoids
    from jaxcnc.planners.timelaw import ramp_accel as _ramp_accel

    rng = np.random.default_rng(5)
    n = 5000
    x = rng.uniform(0, 1e4, n + 1) * (rng.random(n + 1) < 0.9)  # some rests
    cap = rng.uniform(0, 2e4, n)
    a = rng.uniform(0, 3e3, n) * (rng.random(n) < 0.95)  # some without acceleration
    length = rng.uniform(0, 0.2, n) * (rng.random(n) < 0.98)
    t = {k: np.asarray(v) for k, v in trapezoids(x, cap, a, length, np.zeros(n)).items()}
    for k, v, dt in (("a_acc", "v0", "t_acc"), ("a_dec", "v1", "t_dec")):
        assert np.array_equal(_ramp_accel(t["vp"], t[v], t[dt]).view(np.int64), t[k].view(np.int64)), k


def _split_program():
    """Large turns, long lines and arcs at a coarse tolerance: blends split into pieces (several rounds)."""
    from jaxcnc.gcode.interpreter import parse_gcode

    rng = np.random.default_rng(0)
    lines, x, y = ["G21 G90", "G1 F3000 X0 Y0"], 0.0, 0.0
    for i in range(200):
        x += rng.uniform(1, 10)
        y += rng.uniform(-10, 10) * (1 if i % 2 else -1)
        lines.append(f"G1 X{x:.4f} Y{y:.4f}")
        if i % 7 == 0:
            lines.append(f"G2 X{x + 5:.4f} Y{y:.4f} I2.5 J0")
            x += 5
    return parse_gcode("\n".join(lines))


def test_blend_trims_and_pieces_made_block_by_block_are_the_same_spans(monkeypatch):
    """:func:`~jaxcnc.geometry.blend._trim` evaluates, :func:`~jaxcnc.geometry.blend._blend_round` makes the blends
    and :func:`~jaxcnc.geometry.blend._blend_fields` places its pieces in blocks (bounded temporaries); blocks of a
    few rows give the same spans, bit for bit."""
    import jaxcnc.geometry.blend as blend

    prog = _split_program()
    pieces = []
    send = blend._send
    monkeypatch.setattr(blend, "_send", lambda pts, corner: pieces.append(len(pts)) or send(pts, corner))
    whole = build_spans(prog, 0.5)
    assert len(pieces) > 3  # blends were split, in several rounds
    monkeypatch.setattr(blend, "TRIM_BLOCK", 5)
    monkeypatch.setattr(blend, "PLACE_BLOCK", 3)
    monkeypatch.setattr(blend, "KERNEL_CHUNK", 16)
    pieces.clear()
    blocks = build_spans(prog, 0.5)
    assert pieces[0] == 16  # the blends were made in chunks
    for f in SPAN_FIELDS:
        assert np.array_equal(getattr(blocks, f), getattr(whole, f)), f
    for f in ("coeffs", "timing", "length_err"):
        assert np.array_equal(getattr(blocks.polys, f), getattr(whole.polys, f)), f
    for f in ("center", "e1", "e2", "sweep"):
        assert np.array_equal(getattr(blocks.arcs, f), getattr(whole.arcs, f)), f


def test_a_large_program_hands_free_heap_back_before_its_spans_are_built(monkeypatch):
    import jaxcnc.planners.job as job

    calls = []
    monkeypatch.setattr(job, "release_free_heap", lambda: calls.append(1))
    prog = cam_polyline(300)
    m = parse_machine(BENCH_MACHINE, "<bench>")
    first = plan_job(prog, m).plan
    assert not calls  # a small program does not
    monkeypatch.setattr(job, "TRIM_BLOCKS", 100)
    _same_plan(plan_job(prog, m).plan, first)
    assert calls == [1]


def test_group_and_first_ticks_derived_from_the_groups_are_the_alignments_own():
    """A plan keeps each group's first tick once (:class:`~jaxcnc.planners.timelaw.GroupTicks`), not
    ``group_tick`` and ``first_tick`` per segment: read whole, in windows of rows or at given segments they are
    :func:`~jaxcnc.planners.timelaw.align_to_ticks`' own columns, bit for bit, and the segment at a tick is the one
    a search of that ``first_tick`` finds."""
    import jaxcnc.planners.topp as topp
    from jaxcnc.planners.timelaw import align_to_ticks

    prog = cam_polyline(2000)
    lines = prog.kind.size
    stop = np.zeros(lines, bool)
    stop[[300, 301, 1200]] = True  # rests inside the program: several groups
    prog = dataclasses.replace(prog, stop_before=stop)
    plan = plan_job(prog, parse_machine(BENCH_MACHINE + "corner_tol_mm = 0.01\n", "<bench>")).plan
    assert plan.groups is not None and "group_tick" not in plan.columns and "first_tick" not in plan.columns
    assert plan.groups.first_segment.size >= 4
    n = len(plan)
    mb = bucket_size(n)  # padded as the planner pads them (the scans' sums in the same order)
    # the durations summed on the host, as the planner aligns them (topp._align_total)
    duration = np.r_[plan.t_acc + plan.t_cru + plan.t_dec, np.zeros(mb - n)]
    times = {"t_acc": duration, "t_cru": np.zeros(mb), "t_dec": np.zeros(mb)}
    ref = jax.jit(align_to_ticks)(times, np.r_[plan.v0 == 0.0, np.ones(mb - n, bool)], plan.tick_hz)  # as planned
    ref = {k: np.asarray(v)[:n] if np.ndim(v) else v for k, v in ref.items()}
    # the offsets: the planner's own program (another program of the same sums may round the scan's adds otherwise:
    # XLA:CPU contracts products into sums as a program's fusions allow)
    own = topp._align_total(duration, np.r_[plan.v0 == 0.0, np.ones(mb - n, bool)], plan.tick_hz)
    np.testing.assert_array_equal(np.asarray(own["offset_ticks"])[:n], plan.offset_ticks)
    for f in ("group_tick", "first_tick"):
        want = np.asarray(ref[f])
        assert plan.column(f).dtype == want.dtype == np.int64
        np.testing.assert_array_equal(plan.column(f), want)
        for k0, k1 in ((0, 1), (7, 300), (n - 5, n)):
            np.testing.assert_array_equal(plan.rows(k0, k1, (f,))[f], want[k0:k1])
    assert int(ref["n_ticks"]) == plan.n_ticks
    first = np.asarray(ref["first_tick"])
    for tick in (0, 1, int(first[n // 2]), int(first[n // 2]) + 1, plan.n_ticks - 1, plan.n_ticks):
        assert plan.segment_at_tick(tick) == max(int(np.searchsorted(first, tick, side="right")) - 1, 0)
    spans = int(plan.span[-1]) + 1
    np.testing.assert_array_equal(plan.span_start_ticks(spans), first[plan.span_first_segment(spans)])


def _bits(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    return a.view(np.int64) if a.dtype == np.float64 else a


@pytest.mark.parametrize("corner_tol", [0.0, 0.01])
def test_ramps_keep_the_trapezoids_bit_for_bit(monkeypatch, corner_tol):
    """Large plans keep their trapezoids as :class:`~jaxcnc.planners.timelaw.Ramps` (a duration and which ramp;
    the segments that are not one ramp or cruise whole): every column, whole or in windows of rows, holds the bits
    of the plan that stores the four columns, and the ticks are the same."""
    import jaxcnc.planners.topp as topp
    from jaxcnc.planners.timelaw import RAMP_GENERAL

    prog = cam_polyline(3000)
    m = parse_machine(BENCH_MACHINE + f"corner_tol_mm = {corner_tol}\n", "<bench>")
    monkeypatch.setattr(topp, "WINDOW_INTERVALS", 1 << 11)  # several windows
    columns = plan_job(prog, m).plan
    assert columns.ramps is None and "t_acc" in columns.columns  # a small plan stores them
    monkeypatch.setattr(topp, "TRIM_SEGMENTS", 1)  # the large plans' way on a small one
    ramps = plan_job(prog, m).plan
    assert ramps.ramps is not None and not {"vp", "t_acc", "t_cru", "t_dec"} & set(ramps.columns)
    phase = ramps.ramps.phase
    assert (phase != RAMP_GENERAL).any() and (phase == RAMP_GENERAL).any()  # both kinds of segment
    assert ramps.n_ticks == columns.n_ticks
    n = len(ramps)
    for f in PLAN_FIELDS:
        np.testing.assert_array_equal(_bits(getattr(ramps, f)), _bits(getattr(columns, f)), err_msg=f)
        for k0, k1 in ((0, 1), (5, 170), (n // 2, n // 2 + 333), (n - 4, n)):
            got = ramps.rows(k0, k1, (f,))[f]
            np.testing.assert_array_equal(_bits(got), _bits(getattr(columns, f)[k0:k1]), err_msg=f"{f} {k0}:{k1}")
    np.testing.assert_array_equal(_bits(ramps.duration_s), _bits(columns.duration_s))


def test_blends_keep_no_weight_column_and_join_rational_tables_whole():
    """The blends' poly table holds ``(q, 6, 3)`` coefficients (their weight is 1); joined with rational pieces it
    becomes homogeneous, the blends' rows with the weight 1; evaluated, either form gives the same bits."""
    from jaxcnc.geometry.evaluate import evaluate_path, span_arrays
    from jaxcnc.geometry.spans import PolyTable, merge_polys

    spans = build_spans(cam_polyline(600), 0.01)
    polys = spans.polys
    assert len(polys) and not polys.rational and polys.coeffs.shape[1:] == (6, 3)
    hom = polys.homogeneous()
    assert hom.shape[1:] == (6, 4)
    np.testing.assert_array_equal(hom[..., :3], polys.coeffs)
    np.testing.assert_array_equal(hom[..., 3], np.broadcast_to(np.eye(6)[0], (len(polys), 6)))
    rational = PolyTable(coeffs=hom[:5] * 2.0, timing=polys.timing[:5], length_err=polys.length_err[:5])  # weight 2
    joined = merge_polys([rational, polys])
    assert joined.rational
    np.testing.assert_array_equal(joined.coeffs[5:], hom)
    whole = dataclasses.replace(spans, polys=PolyTable(hom, polys.timing, polys.length_err))
    blend = np.flatnonzero(spans.kind == SpanKind.BLEND)
    s = spans.length[blend] * 0.61
    got, want = (evaluate_path(span_arrays(sp), blend, s, 2) for sp in (spans, whole))
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(a, b)
