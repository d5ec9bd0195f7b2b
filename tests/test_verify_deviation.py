"""The independent path check: every tick's distance from the programmed geometry against the blend tolerance."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import BSpline

from jaxcnc.cli.main import main
from jaxcnc.errors import JaxcncError
from jaxcnc.format import FINE_SCALE, EventKind, TableFile, TableWriter, file_sha256
from jaxcnc.gcode import parse_gcode
from jaxcnc.jobs import program_for_table
from jaxcnc.program import program_start
from jaxcnc.ticks.deviation import (
    SLACK_MM,
    CurveDistance,
    ProgramPath,
    path_deviation,
    point_arc_distance,
    segment_distance,
)
from jaxcnc.ticks.verify import Violation
from tests.conftest import machine_text, make_machine
from tests.helpers import random_cubic_nurbs, table_of

P = 0.05
CORNERS = f"G21 G90 G64 P{P}\nG1 X10 Y0 F3000\nX10 Y10\nX0 Y10\nX0 Y0\nX20 Y5\nX25 Y-5\nX40 Y-4\nX41 Y6\nX30 Y20 Z1\n"
ARCS_G17 = "G21 G90 {mode}\nG1 X10 Y0 F3000\nG3 X20 Y10 I0 J10\nG2 X30 Y0 I10 J0\nG1 X40 Y5\nG3 X50 Y5 R5\nG1 X50 Y20\n"
ARCS_G18 = (
    "G21 G90 G18 {mode}\nG1 X10 Z0 F3000\nG3 X20 Z10 I0 K10\nG2 X30 Z0 I10 K0\nG1 X40 Z5\nG3 X40 Z5 I0 K5\nG1 X30\n"
)
HELIX = "G21 G90 {mode}\nG1 X10 Y0 F3000\nG3 X10 Y0 Z5 I-10 J0\nG2 X0 Y10 Z3 I-10 J0\nG1 X0 Y20\n"
QUARTER = "G21 G90 {mode}\nG1 X10 Y0 F1200\nG5.2 P1\nX10 Y10 P0.7071067811865476 L3\nX0 Y10 P1\nG5.3\nG1 X-10 Y10\n"
G62 = (
    "G21 G90 {mode}\nG1 X0 Y0 F1200\nG6.2 X0 Y0 R1 K0 P4 Q1\nX10 Y10 R2 K0\nX20 Y-5 R0.5 K0\nX30 Y10 R1 K0\n"
    "X40 Y0 R1 K1\nG6.2 K2\nG6.2 K2\nG6.2 K2\nG6.2 K2\nG1 X50 Y0\n"
)


def _deviation(text: str, tmp_path: Path, **machine_kw):
    machine = make_machine(**machine_kw)
    job, table, _ = table_of(text, machine, tmp_path)
    return job, table, machine, path_deviation(table, machine, job.program)


def _rewrite(table: TableFile, path: Path, p_mm: np.ndarray, meta: dict | None = None) -> TableFile:
    """The table with exact positions ``p_mm`` (same events and header metadata): valid CRCs."""
    h = table.header
    x = p_mm / h.discrete_mm
    pos = np.round(x)
    fine = np.round((x - pos) * FINE_SCALE)
    m = {k: v for k, v in (meta or h.meta).items() if k != "axes"}
    with TableWriter(path, axes=h.axes, tick_hz=h.tick_hz, discrete_mm=h.discrete_mm, n_rows=h.n_rows, meta=m) as w:
        w.write(pos.astype(np.int32), fine.astype(np.int32))
        w.events = table.events.copy()
    return TableFile(path)


def _row_ticks(table: TableFile, row: int) -> tuple[int, int]:
    """First tick of program row ``row`` and the first tick of the next block."""
    ev = table.events[table.events["kind"] == EventKind.BLOCK]
    i = int(np.flatnonzero(ev["value"] == row)[0])
    return int(ev["tick"][i]), int(ev["tick"][i + 1]) if i + 1 < ev.size else table.n_rows


# ----------------------------------------------------------------------------------------------
# Planned tables


def test_blended_corners_stay_within_p(tmp_path: Path) -> None:
    job, table, _, dev = _deviation(CORNERS, tmp_path)
    assert dev.ok and not dev.violations, dev.violations
    assert 0.3 * P < dev.max_mm <= P + SLACK_MM, dev
    assert dev.max_tol_mm == P and dev.allowed_at_worst_mm == P + SLACK_MM
    # away from the corners the table follows the programmed lines
    assert dev.n_away > table.n_rows // 2 and dev.max_away_mm < 1e-9, dev
    assert job.program.line[dev.worst_row] == dev.worst_line


def test_damaged_table_fails_at_the_right_ticks(tmp_path: Path) -> None:
    job, table, machine, dev = _deviation(CORNERS, tmp_path)
    assert dev.ok
    row = 2  # X10 Y10 -> X0 Y10
    t0, t1 = _row_ticks(table, row)
    mid = (t0 + t1) // 2
    p = table.exact_mm()
    p[mid - 5 : mid + 6, 2] += 0.2  # lifted off the XY line by 0.2 mm (> P), CRCs valid
    p[mid + 20, 1] -= 0.04  # moved by 0.04 mm (< P): allowed, as G64 P allows it anywhere on the row
    bad = _rewrite(table, tmp_path / "bad.ticks", p)
    dev = path_deviation(bad, machine, job.program)
    assert not dev.ok and dev.n_over == 11
    line = int(job.program.line[row])
    assert len(dev.violations) == 1
    v = dev.violations[0]
    assert (v.first_tick, v.last_tick, v.axis, v.quantity) == (mid - 5, mid + 5, f"line {line}", "path")
    assert v.value == pytest.approx(0.2, abs=1e-9) and v.limit == P + SLACK_MM
    assert mid - 5 <= dev.worst_tick <= mid + 5 and dev.worst_line == line
    assert (
        str(v) == f"tick {mid - 5} (to {mid + 5}) line {line}: distance from the programmed path 0.2 mm > 0.050001 mm"
    )


@pytest.mark.parametrize(
    "program",
    [CORNERS, ARCS_G17, ARCS_G18, HELIX, QUARTER, G62],
    ids=["corners", "g17", "g18", "helix", "g5.2", "g6.2"],
)
def test_exact_path_follows_the_program(tmp_path: Path, program: str) -> None:
    text = program.replace("G64 P0.05", "G61").format(mode="G61")
    _, table, _, dev = _deviation(text, tmp_path)
    assert dev.ok and dev.max_mm < 1e-6, dev
    assert dev.max_tol_mm == 0.0 and dev.n_away == table.n_rows


@pytest.mark.parametrize(
    "program", [ARCS_G17, ARCS_G18, HELIX, QUARTER, G62], ids=["g17", "g18", "helix", "g5.2", "g6.2"]
)
def test_blended_curved_programs_pass(tmp_path: Path, program: str) -> None:
    _, _, _, dev = _deviation(program.format(mode=f"G64 P{P}"), tmp_path)
    assert dev.ok and dev.max_mm <= P + SLACK_MM, dev
    assert dev.max_away_mm < 1e-6, dev


@pytest.mark.parametrize(
    ("program", "row", "plane"),
    [(ARCS_G17, 1, (0, 1)), (ARCS_G18, 2, (2, 0)), (ARCS_G18, 4, (2, 0)), (QUARTER, 1, (0, 1))],
    ids=["g17-g3", "g18-g2", "g18-full-circle", "g5.2-quarter-circle"],
)
def test_arc_and_nurbs_ticks_moved_radially_are_measured_exactly(tmp_path: Path, program, row, plane) -> None:
    """A tick of an arc (or of the NURBS quarter circle) moved radially by δ in the plane is δ from the path."""
    job, table, machine, dev = _deviation(program.format(mode="G61"), tmp_path)
    pr = job.program
    center = pr.center[row] if pr.center[row][0] == pr.center[row][0] else np.zeros(3)  # the quarter: origin
    t0, t1 = _row_ticks(table, row)
    ticks = np.linspace(t0 + (t1 - t0) // 8, t1 - (t1 - t0) // 8, 7).astype(int)  # clear of the neighbours
    delta = np.array([0.3, -0.2, 0.11, 1.0, -0.5, 0.07, 0.25])
    p = table.exact_mm()
    a, b = plane
    rel = p[ticks][:, [a, b]] - center[[a, b]]
    rho = np.linalg.norm(rel, axis=1, keepdims=True)
    p[np.ix_(ticks, [a, b])] = center[[a, b]] + rel * (1 + delta[:, None] / rho)
    dev = path_deviation(_rewrite(table, tmp_path / "moved.ticks", p), machine, pr)
    assert dev.n_over == 7 and len(dev.violations) == 7
    got = {v.first_tick: v.value for v in dev.violations}
    np.testing.assert_allclose([got[t] for t in ticks], np.abs(delta), atol=1e-9)
    assert dev.worst_tick == ticks[3] and dev.max_mm == pytest.approx(1.0, abs=1e-9)


def test_helix_ticks_moved_radially_are_measured_exactly(tmp_path: Path) -> None:
    job, table, machine, _ = _deviation(HELIX.format(mode="G61"), tmp_path)
    row = 1
    c = job.program.center[row]
    t0, t1 = _row_ticks(table, row)
    ticks = np.linspace(t0 + (t1 - t0) // 8, t1 - (t1 - t0) // 8, 5).astype(int)
    delta = np.array([0.2, -0.3, 0.5, 0.08, -1.5])
    p = table.exact_mm()
    rel = p[ticks, :2] - c[:2]
    p[ticks, :2] = c[:2] + rel * (1 + delta[:, None] / np.linalg.norm(rel, axis=1, keepdims=True))
    dev = path_deviation(_rewrite(table, tmp_path / "moved.ticks", p), machine, job.program)
    got = {v.first_tick: v.value for v in dev.violations}
    # the table's helix is the planner's representation of it (within 1e-6 mm: test_exact_path_follows_the_program)
    np.testing.assert_allclose([got[t] for t in ticks], np.abs(delta), atol=1e-6)


# ----------------------------------------------------------------------------------------------
# Distances against closed forms and brute force


def _dense_arc(start, end, center, turn, plane, n=400_001):
    """Points of an arc/helix by brute force: angles sampled in program coordinates."""
    perm = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}[plane]
    s, e, c = (np.asarray(x, float)[list(perm)] for x in (start, end, center))
    r = np.hypot(*(s[:2] - c[:2]))
    a0 = np.arctan2(s[1] - c[1], s[0] - c[0])
    a1 = np.arctan2(e[1] - c[1], e[0] - c[0])
    full = np.hypot(*(e[:2] - s[:2])) < 1e-9
    sweep = 2 * np.pi if full else np.mod(turn * (a1 - a0), 2 * np.pi)
    t = np.linspace(0.0, 1.0, n)
    ang = a0 + turn * sweep * t
    uvw = np.stack([c[0] + r * np.cos(ang), c[1] + r * np.sin(ang), s[2] + (e[2] - s[2]) * t], axis=1)
    out = np.empty_like(uvw)
    out[:, list(perm)] = uvw
    return out, np.hypot(r * sweep, e[2] - s[2]) / (n - 1)  # points and their spacing


def test_segment_distance_closed_form() -> None:
    a, b = np.array([0.0, 0.0, 0.0]), np.array([10.0, 0.0, 0.0])
    p = np.array([[5.0, 3.0, 4.0], [-3.0, 4.0, 0.0], [13.0, 0.0, 4.0], [2.0, 0.0, 0.0]])
    np.testing.assert_allclose(segment_distance(p, a, b), [5.0, 5.0, 5.0, 0.0])
    np.testing.assert_allclose(segment_distance(p, a, a), np.linalg.norm(p, axis=1))


@pytest.mark.parametrize("plane", [17, 18, 19])
@pytest.mark.parametrize("turn", [1, -1])
def test_point_arc_distance_closed_form(plane: int, turn: int) -> None:
    perm = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}[plane]

    def prog(u, v, w):
        out = np.empty(np.broadcast(u, v, w).shape + (3,))
        out[..., perm[0]], out[..., perm[1]], out[..., perm[2]] = u, v, w
        return out

    c, r = prog(1.0, 2.0, 3.0), 5.0
    start, end = prog(1.0 + r, 2.0, 3.0), prog(1.0, 2.0 + turn * r, 3.0)  # a quarter in the turn's direction
    ang = turn * np.array([0.1, 0.7, 1.5])  # inside the sweep
    rad = np.array([5.3, 4.0, 0.0])
    w = np.array([0.0, 1.0, -2.0])
    p = prog(1.0 + rad * np.cos(ang), 2.0 + rad * np.sin(ang), 3.0 + w)
    np.testing.assert_allclose(point_arc_distance(p, start, end, c, turn, plane), np.hypot(rad - r, w), atol=1e-12)
    # outside the sweep: the nearer end
    q = prog(1.0 + 6.0 * np.cos(-turn * 0.5), 2.0 + 6.0 * np.sin(-turn * 0.5), 3.5)
    want = min(np.linalg.norm(q - start), np.linalg.norm(q - end))
    assert point_arc_distance(q[None], start, end, c, turn, plane)[0] == pytest.approx(want, abs=1e-12)
    # the same end points the other way round: three quarters, so q is on it now
    assert point_arc_distance(q[None], start, end, c, -turn, plane)[0] == pytest.approx(np.hypot(1.0, 0.5), abs=1e-12)
    # a full circle
    assert point_arc_distance(q[None], start, start, c, turn, plane)[0] == pytest.approx(np.hypot(1.0, 0.5), abs=1e-12)


_coord = st.floats(-50, 50, allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(
    cx=_coord,
    cy=_coord,
    r=st.floats(0.05, 40),
    a0=st.floats(-np.pi, np.pi),
    sweep=st.floats(1e-3, 2 * np.pi - 1e-6),
    turn=st.sampled_from([1, -1]),
    plane=st.sampled_from([17, 18, 19]),
    rise=st.sampled_from([0.0, 0.0, 3.0, -0.5]),
    full=st.booleans(),
    px=_coord,
    py=_coord,
    pz=st.floats(-10, 10),
)
def test_point_arc_distance_against_dense_sampling(cx, cy, r, a0, sweep, turn, plane, rise, full, px, py, pz) -> None:
    """Planar arcs are exact, helices an upper bound that equals the distance: both within the sampling's
    resolution of brute force, and never farther than the best sample."""
    perm = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}[plane]
    a1 = a0 if full else a0 + turn * sweep
    uvw_s, uvw_e, uvw_c = (
        (cx + r * np.cos(a0), cy + r * np.sin(a0), 1.0),
        (cx + r * np.cos(a1), cy + r * np.sin(a1), 1.0 + rise),
        (cx, cy, 1.0),
    )
    start, end, center = np.empty(3), np.empty(3), np.empty(3)
    start[list(perm)], end[list(perm)], center[list(perm)] = uvw_s, uvw_e, uvw_c
    if not full and np.hypot(*(end[list(perm)][:2] - start[list(perm)][:2])) < 1e-6:
        return  # end on the start: a full circle by the reader's rule, a different arc
    p = np.array([px, py, pz])
    d = point_arc_distance(p[None], start, end, center, turn, plane)[0]
    pts, h = _dense_arc(start, end, center, turn, plane)
    brute = np.min(np.linalg.norm(pts - p, axis=1))
    assert d <= brute + 1e-9
    assert d >= brute - h / 2 - 1e-9


@pytest.mark.parametrize("rise", [25.0, 2.0, -0.3])
@pytest.mark.parametrize("turn", [1, -1])
def test_helix_far_points_against_dense_sampling(rise: float, turn: int) -> None:
    """Points anywhere (not only near the helix) against a quarter and a full turn of steep and flat helices."""
    rng = np.random.default_rng(7)
    c = np.zeros(3)
    for end in (np.array([0.0, 10.0 * turn, rise]), np.array([10.0, 0.0, rise])):
        start = np.array([10.0, 0.0, 0.0])
        pts, h = _dense_arc(start, end, c, turn, 17, n=100_001)
        p = rng.uniform(-20, 20, (150, 3))
        d = point_arc_distance(p, start, end, c, turn, 17)
        brute = np.array([np.min(np.linalg.norm(pts - q, axis=1)) for q in p])
        assert np.all(d <= brute + 1e-9) and np.all(d >= brute - h / 2 - 1e-9)


def test_curve_distance_on_a_nurbs_circle() -> None:
    """A rational quadratic quarter circle: the distance is |ρ − R| for points at angles inside it."""
    curve = CurveDistance(
        2,
        np.array([[10.0, 0, 0], [10, 10, 0], [0, 10, 0]]),
        np.array([1, np.sqrt(0.5), 1]),
        np.array([0, 0, 0, 1, 1, 1.0]),
    )
    rng = np.random.default_rng(1)
    ang = rng.uniform(0, np.pi / 2, 2000)
    rho = 10 + rng.uniform(-3, 3, ang.size)
    z = rng.uniform(-1, 1, ang.size)
    p = np.stack([rho * np.cos(ang), rho * np.sin(ang), z], axis=1)
    np.testing.assert_allclose(curve.distance(p), np.hypot(rho - 10, z), atol=1e-10)
    t_in, t_out = curve.end_tangents()
    np.testing.assert_allclose([t_in, t_out], [[0, 1, 0], [-1, 0, 0]], atol=1e-12)


def test_curve_distance_against_dense_sampling() -> None:
    deg, pts, w, knots = random_cubic_nurbs(40, seed=3)
    curve = CurveDistance(deg, pts, w, knots)
    spl = BSpline(knots, np.c_[pts * w[:, None], w], deg)
    u = np.linspace(knots[0], knots[-1], 200_001)
    h = spl(u)
    dense = h[:, :3] / h[:, 3:]
    spacing = 1.01 * np.max(np.linalg.norm(np.diff(dense, axis=0), axis=1))  # chord ≈ arc between samples
    rng = np.random.default_rng(5)
    on = dense[rng.integers(0, u.size, 200)]
    p = np.concatenate([on + rng.normal(0, 0.2, on.shape), rng.uniform(dense.min(0) - 5, dense.max(0) + 5, (100, 3))])
    d = curve.distance(p)
    brute = np.array([np.min(np.linalg.norm(dense - q, axis=1)) for q in p])
    assert np.all(d <= brute + 1e-9)
    assert np.all(d >= brute - spacing / 2 - 1e-9)
    np.testing.assert_allclose(curve.distance(on), 0.0, atol=1e-9)


# ----------------------------------------------------------------------------------------------
# What each tick is allowed


def test_junction_tolerances_follow_the_program() -> None:
    """The mode a move is programmed in says how it ends: a junction gets the lower of its two rows' tolerances (the
    second's only where it has one), none after a row programmed under G61."""
    machine = make_machine()
    text = (
        "G21 G90 G64 P0.05\nG1 X10 F600\nX10 Y10\n"  # rows 0, 1: junction 0-1 P0.05
        "G64 P0.2\nX0 Y10\n"  # row 2: junction 1-2 the lower, P0.05
        "G61\nX0 Y0\n"  # row 3: junction 2-3 P0.2 (row 3 has none of its own); 3-4 exact
        "G64\nX5 Y0\n"  # row 4: the machine's corner_tol_mm (0 here)
        "G64 P0.1\nX5 Y5\nX5 Y5\n"  # rows 5, 6: P0.1 (4-5: the lower, 0); row 6 does not move
        "X6 Y6\nG4 P1\nX8 Y6\n"  # row 7; row 8 dwells: no blend across it; row 9
        "M3 S100\nX9 Y9\n"  # row 10: the laser switched: at rest
    )
    pr = parse_gcode(text, "t.ngc", start=program_start(machine), home=program_start(machine))
    geo = ProgramPath(pr, corner_tol_mm=0.0)
    assert list(geo.moving) == [True] * 6 + [False, True, False, True, True]
    np.testing.assert_array_equal(geo.prev, [-1, 0, 1, 2, 3, 4, 5, 5, 7, 7, 9])
    np.testing.assert_array_equal(geo.next, [1, 2, 3, 4, 5, 7, 7, 9, 9, 10, -1])
    np.testing.assert_allclose(geo.tol_in, [0, 0.05, 0.05, 0.2, 0, 0, 0.1, 0.1, 0, 0, 0])
    np.testing.assert_allclose(geo.allowed, [0.05, 0.05, 0.2, 0.2, 0, 0.1, 0.1, 0.1, 0, 0, 0])
    geo = ProgramPath(pr, corner_tol_mm=0.03)
    assert geo.allowed[3] == 0.2 and geo.allowed[4] == 0.03 and geo.tol_in[4] == 0 and geo.tol_in[5] == 0.03


# ----------------------------------------------------------------------------------------------
# Loading the program, the command line


def test_wrong_program_is_refused(tmp_path: Path) -> None:
    job, table, machine, _ = _deviation(CORNERS, tmp_path)
    other = parse_gcode("G21 G90\nG1 X1 F60\nX2\n", "other.ngc")
    with pytest.raises(JaxcncError, match="not the program of this table"):
        path_deviation(table, machine, other)


def test_program_for_table_skips_and_errors(tmp_path: Path) -> None:
    machine = make_machine()
    _, table, _ = table_of(CORNERS, machine, tmp_path)
    program = tmp_path / "corners.ngc"
    program.write_text(CORNERS)

    def with_meta(**meta) -> TableFile:
        return _rewrite(table, tmp_path / "m.ticks", table.exact_mm(), {**table.header.meta, **meta})

    prog, note = program_for_table(table, machine)  # source "test.ngc": not here
    assert prog is None and "not here" in note
    prog, note = program_for_table(with_meta(source=str(program)), machine)
    assert prog is not None and note == "" and len(prog) == table.header.meta["n_blocks"]
    prog, note = program_for_table(with_meta(source=str(program), source_sha256="0" * 64), machine)
    assert prog is None and "changed since" in note
    prog, note = program_for_table(with_meta(source=str(tmp_path / "pts.xyz")), machine)
    assert prog is None and "is not a program" in note
    prog, note = program_for_table(table, machine, program=program)  # explicit: no checksum
    assert prog is not None
    with pytest.raises(JaxcncError, match="no such program"):
        program_for_table(table, machine, program=tmp_path / "missing.ngc")
    with TableWriter(tmp_path / "nb.ticks", axes=["x", "y", "z"], tick_hz=1e4, discrete_mm=1e-3, n_rows=2) as w:
        w.write(np.zeros((2, 3), np.int32), np.zeros((2, 3), np.int32))
    no_blocks = TableFile(tmp_path / "nb.ticks")
    prog, note = program_for_table(no_blocks, machine, program=program)
    assert prog is None and "no block events" in note


def test_check_command_compares_the_path(tmp_path: Path, capsys) -> None:
    machine = tmp_path / "machine.toml"
    machine.write_text(machine_text())
    program = tmp_path / "corners.ngc"
    program.write_text(CORNERS)
    table = tmp_path / "corners.ticks"
    assert main(["plan", str(program), "-m", str(machine), "-o", str(table), "-q"]) == 0
    assert TableFile(table).header.meta["source_sha256"] == file_sha256(program)
    capsys.readouterr()
    assert main(["check", str(table), "-m", str(machine)]) == 0
    out = capsys.readouterr().out
    assert "travel, limits and path hold" in out and "path: max deviation" in out and "away from corners" in out
    # moved off the path (CRCs valid): exit 1, one line naming the ticks and the program line
    t = TableFile(table)
    p = t.exact_mm()
    p[1000:1010, 2] += 0.3
    bad = _rewrite(t, tmp_path / "bad.ticks", p)
    assert main(["check", str(bad.path), "-m", str(machine)]) == 1
    out = capsys.readouterr().out
    assert "tick 1000 (to 1009) line" in out and "distance from the programmed path 0.3 mm > 0.050001 mm" in out
    # the program gone: not compared, said so, exit 0; an explicit program that is missing: exit 2
    program.rename(tmp_path / "elsewhere.ngc")
    assert main(["check", str(table), "-m", str(machine)]) == 0
    out = capsys.readouterr().out
    assert "checksums, travel and limits hold" in out and "path: not compared" in out and "--program" in out
    assert main(["check", str(table), "-m", str(machine), "--program", str(tmp_path / "elsewhere.ngc")]) == 0
    assert "path: max deviation" in capsys.readouterr().out
    assert main(["check", str(table), "-m", str(machine), "--program", str(program)]) == 2
    assert "no such program file" in capsys.readouterr().err


def test_independent_of_geometry_and_planners() -> None:
    code = (
        "import sys, jaxcnc.ticks.deviation\n"
        "bad = [m for m in sys.modules if m.startswith(('jaxcnc.geometry', 'jaxcnc.planners')) or m == 'jax']\n"
        "print(bad)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "[]", r.stdout


def test_violations_join_across_chunks(tmp_path: Path) -> None:
    job, table, machine, _ = _deviation(CORNERS, tmp_path)
    p = table.exact_mm()
    p[500:700, 2] += 0.1
    bad = _rewrite(table, tmp_path / "bad.ticks", p)
    first = None
    for chunk in (7, 64, 1 << 16):
        for threads in (1, 2, 3):
            dev = path_deviation(bad, machine, job.program, chunk_rows=chunk, threads=threads)
            assert [(v.first_tick, v.last_tick) for v in dev.violations] == [(500, 699)], (chunk, threads)
            assert isinstance(dev.violations[0], Violation) and dev.n_over == 200
            first = first or dev
            assert dev == first, (chunk, threads)  # every figure, whatever the chunks and threads
