"""The G-code front end: words with their proper meaning, and a clear error for anything else."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxcnc.errors import SourceError
from jaxcnc.gcode import ARC_RADIUS_TOL_MM, load_gcode, parse_gcode
from jaxcnc.program import Event, Kind, LaserMode
from tests.conftest import corpus_file


def parse(text: str, **kw):
    kw.setdefault("max_lines", 100_000)  # fuzzed text may loop for ever: stop it quickly
    return parse_gcode(text, "t.ngc", **kw)


def err(text: str) -> SourceError:
    with pytest.raises(SourceError) as info:
        parse(text)
    return info.value


def test_lines_feeds_units_and_distance_modes():
    p = parse("G21 G90\nG0 X10 Y5\nG1 X20 F600\nG91 G1 Y-5\nG20 G90 G1 X1 Y1 F60\n")
    assert list(p.kind) == [Kind.LINE] * 4
    np.testing.assert_allclose(p.end, [[10, 5, 0], [20, 5, 0], [20, 0, 0], [25.4, 25.4, 0]])
    np.testing.assert_allclose(p.start[1:], p.end[:-1])
    assert list(p.rapid) == [True, False, False, False]
    assert math.isnan(p.feed[0])
    np.testing.assert_allclose(p.feed[1:], [10.0, 10.0, 60 * 25.4 / 60])  # F in units/min -> mm/s
    assert list(p.line) == [2, 3, 4, 5]


def test_case_spaces_comments_line_numbers_and_percent():
    text = "%\n(header)\nn10 g1 x 1 0 ; comment\nN20 G1 (inline) Y2.5 F1200\n%\nG1 X99\n"
    p = parse(text)
    assert len(p) == 2
    np.testing.assert_allclose(p.end, [[10, 0, 0], [10, 2.5, 0]])


def test_ij_arc_centre_and_direction():
    p = parse("G1 X10 F600\nG3 X0 Y10 I-10 J0\nG2 X10 Y0 I0 J-10\n")
    assert list(p.kind) == [Kind.LINE, Kind.ARC, Kind.ARC]
    np.testing.assert_allclose(p.center[1], [0, 0, 0], atol=1e-12)
    assert p.turn[1] == 1 and p.turn[2] == -1
    np.testing.assert_allclose(p.center[2], [0, 0, 0], atol=1e-12)


@pytest.mark.parametrize(
    ("word", "r_sign", "cw", "center"),
    [
        ("G2", 1, True, (5, -5)),  # short clockwise arc from (0,0) to (10,0) with R 5√2: centre below
        ("G3", 1, False, (5, 5)),
        ("G2", -1, True, (5, 5)),  # negative R: the long way round, centre on the other side
        ("G3", -1, False, (5, -5)),
    ],
)
def test_r_arcs(word, r_sign, cw, center):
    r = r_sign * 5 * math.sqrt(2)
    p = parse(f"G1 X0 Y0 F600\n{word} X10 Y0 R{r:.12f}\n")
    np.testing.assert_allclose(p.center[1, :2], center, atol=1e-9)
    assert p.turn[1] == (-1 if cw else 1)


def test_full_circle_and_radius_tolerance():
    p = parse("G1 X10 F600\nG2 X10 Y0 I5 J0\n")
    assert p.kind[1] == Kind.ARC and np.allclose(p.start[1], p.end[1])
    # within tolerance: accepted, centre moved onto the bisector so both radii are equal
    d = ARC_RADIUS_TOL_MM / 2
    p = parse(f"G1 X0 F600\nG3 X10 Y0 I5 J{d}\n")
    c = p.center[1]
    assert abs(np.hypot(*(p.start[1] - c)[:2]) - np.hypot(*(p.end[1] - c)[:2])) < 1e-12
    e = err("G1 X0 F600\nG3 X10 Y0 I5.1 J0\n")
    assert (e.line, e.column) == (2, 11)  # the I word
    assert "radius to end" in e.reason and "differs" in e.reason


def test_dwell_laser_power_and_stops():
    p = parse("F600 S40\nG0 X1\nM3\nG4 P0.5\nG1 X2\nS80\nG1 X3\nM5\nG1 X4\nM4 G1 X5\n")
    kinds = list(p.kind)
    assert kinds == [Kind.LINE, Kind.DWELL, Kind.LINE, Kind.LINE, Kind.LINE, Kind.LINE]
    assert p.dwell_s[1] == 0.5
    assert list(p.laser) == [0, 3, 3, 3, 0, 4]
    assert list(p.power) == [40, 40, 40, 80, 80, 80]
    # laser switched (M3, M5, M4) or a dwell before: the motion is at rest there; S changes on the fly
    assert list(p.stop_before) == [True, True, True, False, True, True]


def test_tool_change_optional_stop_and_end():
    p = parse("T3 M6\nG1 X1 F60\nM1\nM0\nG1 X2\nM30\nG1 X50\n")
    ev = [(int(k), int(e), int(v)) for k, e, v in zip(p.kind, p.event, p.event_value, strict=False)]
    assert ev == [
        (Kind.EVENT, Event.TOOL_CHANGE, 3),
        (Kind.LINE, 0, 0),
        (Kind.EVENT, Event.OPTIONAL_STOP, 0),
        (Kind.EVENT, Event.PROGRAM_STOP, 0),
        (Kind.LINE, 0, 0),
        (Kind.EVENT, Event.PROGRAM_END, 0),
    ]
    assert p.end[-1, 0] == 2.0  # nothing after M30 runs


def test_path_control_modes():
    p = parse("G64 P0.02 Q0.01\nG1 X1 F60\nG61\nG1 X2\nG64\nG1 X3\nG61.1\nG1 X4\nG1 X5\n")
    assert p.blend_tol[0] == pytest.approx(0.02)
    assert p.blend_tol[1] == 0.0 and math.isinf(p.blend_tol[2])
    # a move programmed under G61.1 ends at rest (the move after it starts there): X4 blends in, X5 starts at rest
    assert list(p.stop_before) == [True, False, False, False, True]


def test_g28_home():
    p = parse("G1 X10 Y10 F60\nG28\n", start=(0, 0, 0), home=(1, 2, 3))
    np.testing.assert_allclose(p.end[-1], [1, 2, 3])
    assert p.rapid[-1]
    p = parse("G1 X10 Y10 F60\nG28 Y20\n", home=(1, 2, 3))
    np.testing.assert_allclose(p.end[-2:], [[10, 20, 0], [10, 2, 0]])  # via Y20, then only Y homes


def test_start_position_and_g40_g17_g94():
    p = parse("G17 G40 G94\nG1 X1 F60\n", start=(5, 6, 7))
    np.testing.assert_allclose(p.start[0], [5, 6, 7])


@pytest.mark.parametrize(
    ("text", "line", "col", "needle"),
    [
        ("G1 X1.2.3 F60", 1, 4, "malformed number"),
        ("G1 X--1 F60", 1, 4, "malformed number"),
        ("G1 X", 1, 4, "has no number"),
        ("\nG43 H1", 2, 5, "has no [tools] table"),
        ("G41 D1", 1, 1, "cutter compensation G41 is not supported yet"),
        ("M62 P1", 1, 1, "M62"),
        ("G1 A10 F60", 1, 4, "unsupported word A10"),
        ("G1 X1e3 F60", 1, 6, "exponent notation is not RS274NGC (X1E3 reads as X1 and E3)"),
        ("G1 X1.5E-3 F60", 1, 8, "exponent notation"),
        ("G1 X1 E3 F60", 1, 7, "E is not an RS274NGC word (3D printer extrusion?)"),
        ("G1 X#<undefined>", 1, 5, "#<undefined> is not set"),
        ("G0 G1 X1", 1, 4, "same modal group"),
        ("G1 X1 X2 F60", 1, 7, "twice"),
        ("G1 X1 (open", 1, 7, "never closed"),
        ("G1 X1 F0", 1, 1, "feed rate is zero"),
        ("G4 P-1", 1, 4, "negative dwell"),
        ("G4", 1, 1, "needs P"),
        ("X1", 1, 1, "no motion mode"),
        ("G1 X1 F60 P2", 1, 11, "no meaning"),
        ("G2 X1 Y1 I1 R1 F60", 1, 13, "both R and I/J"),
        ("G3 X1 Y1 K1 F60", 1, 10, "K has no meaning"),
        ("G2 X1 F60", 1, 1, "needs I/J"),
        ("G2 X10 R2 F60", 1, 8, "smaller than half the chord"),
        ("G18 G2 X1 J1 F60", 1, 11, "J has no meaning for an arc in the ZX plane (G18)"),
        ("G53 G2 X1 F60", 1, 1, "G53 needs G0 or G1"),
        ("G92", 1, 1, "G92 needs axis words"),
        ("G10 L2 P1 X1", 1, 11, "offset other than zero is not supported"),
        ("G81 X1 Y1 Z-1 R1", 1, 1, "canned cycles are not supported"),
        ("G1.5 X1", 1, 1, "unknown or unsupported word G1.5"),
        ("N1.5 G1 X1 F60", 1, 1, "non-negative integer"),
        ("G1 X1 F60 @", 1, 11, "polar coordinates"),
        ("G1 X1 F60 &", 1, 11, "unexpected character"),
        ("O100 sub", 1, 1, "O100 sub is never closed"),
    ],
)
def test_errors_name_file_line_column(text, line, col, needle):
    e = err(text)
    assert (e.file, e.line, e.column) == ("t.ngc", line, col), str(e)
    assert needle in e.reason
    assert str(e).startswith(f"t.ngc:{line}:{col}: ")


def test_binary_and_missing_files(tmp_path):
    f = tmp_path / "bin.ngc"
    f.write_bytes(b"G1 X1 F60\nG1 X\xff\n")
    with pytest.raises(SourceError) as info:
        load_gcode(f)
    assert info.value.line == 2
    f.write_bytes(b"G1 X1 F60\n\x00\x01")
    with pytest.raises(SourceError, match="NUL"):
        load_gcode(f)
    with pytest.raises(SourceError, match="cannot read"):
        load_gcode(tmp_path / "missing.ngc")


@pytest.mark.parametrize(
    ("name", "arcs", "feeds", "rapids"),
    [
        ("51MeanderAve", 329, 373, 18),  # counts from the corpus MANIFEST: 373 G1 + 329 G2/G3
        ("plasmatest", 129, 218, 15),  # 218 G1 + 129 IJ arcs
    ],
)
def test_corpus_programs_parse(name, arcs, feeds, rapids):
    p = load_gcode(corpus_file(name))
    assert int((p.kind == Kind.ARC).sum()) == arcs
    assert int(((p.kind == Kind.LINE) & ~p.rapid).sum()) == feeds
    assert int(((p.kind == Kind.LINE) & p.rapid).sum()) == rapids
    assert p.event[-1] == Event.PROGRAM_END
    assert np.all(p.laser[p.kind == Kind.ARC] == LaserMode.CONSTANT)


def test_corpus_radius_mismatch_is_reported():
    """cncjs' calibration file has an arc whose end radius differs by 1.4 mm: refused, located."""
    f = corpus_file("Circle_Diamond")
    with pytest.raises(SourceError) as info:
        load_gcode(f)
    assert info.value.line == 624 and "differs from radius to start" in info.value.reason


# ---- fuzzing: the parser raises SourceError or nothing, never anything else, never hangs ----

_ALPHABET = st.sampled_from(
    list("GMXYZIJKRFSTNPQ0123456789.-+ ()%;\n\t#[]/aboO@<>=*")
    + [
        "G1 ",
        "G2 ",
        "X1.5",
        "o1 while [1]\n",
        "o1 endwhile\n",
        "o<s> sub\n",
        "o<s> call\n",
        "o<s> endsub\n",
        "#1=",
        "#<a>",
        "[#1+1]",
        "G5.2 ",
        "G6.2 K1 ",
        "SIN[",
        "]",
    ]
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_ALPHABET, max_size=80).map("".join))
def test_fuzz_random_text(text):
    try:
        parse(text)
    except SourceError as e:
        assert e.file == "t.ngc" and e.line >= 1


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=200))
def test_fuzz_random_bytes(tmp_path_factory, data):
    f = tmp_path_factory.mktemp("fz") / "f.ngc"
    f.write_bytes(data)
    try:
        load_gcode(f, max_lines=100_000)
    except SourceError:
        pass


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_fuzz_mutated_corpus(data):
    text = corpus_file("plasmatest").read_text()
    lines = text.splitlines()[:120]
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(lines) - 1))
        line = lines[i]
        j = data.draw(st.integers(0, len(line)))
        op = data.draw(st.sampled_from(["insert", "delete", "replace"]))
        ch = data.draw(st.sampled_from(list("GXYIJ.-0123456789 (A")))
        if op == "insert":
            line = line[:j] + ch + line[j:]
        elif op == "delete":
            line = line[:j] + line[j + 1 :]
        else:
            line = line[:j] + ch + line[j + 1 :]
        lines[i] = line
    try:
        parse("\n".join(lines))
    except SourceError as e:
        assert 1 <= e.line <= len(lines)


# ---- spline blocks (LinuxCNC dialect) -------------------------------------------------------


def test_g5_cubic_and_tangent_continuation():
    p = parse("G1 X0 Y0 F600\nG5 I0 J3 P0 Q-3 X1 Y1\nG5 P0 Q-3 X2 Y2\n")
    assert list(p.kind[1:]) == [Kind.CURVE, Kind.CURVE]
    deg, pts, w, knots = p.curves.curve(0)
    assert deg == 3 and list(knots) == [0, 0, 0, 0, 1, 1, 1, 1]
    np.testing.assert_allclose(pts[:, :2], [[0, 0], [0, 3], [1, -2], [1, 1]])
    _, pts2, _, _ = p.curves.curve(1)
    np.testing.assert_allclose(pts2[:, :2], [[1, 1], [1, 4], [2, -1], [2, 2]])  # I J = -(previous P Q)
    np.testing.assert_allclose(p.end[-1], [2, 2, 0])


def test_g5_1_quadratic():
    p = parse("G0 X-2 Y4\nG5.1 X2 I2 J-8 F600\n")
    deg, pts, _, _ = p.curves.curve(0)
    assert deg == 2
    np.testing.assert_allclose(pts[:, :2], [[-2, 4], [0, -4], [2, 4]])


def test_g5_2_nurbs_block():
    p = parse("G1 X0 Y0 F600\nG5.2 P2\nX1 Y1 P3 L4\nX2 Y0\nX3 Y1\nX4 Y0\nG5.3\nG1 X5\n")
    deg, pts, w, knots = p.curves.curve(0)
    assert deg == 3
    np.testing.assert_allclose(pts[:, :2], [[0, 0], [1, 1], [2, 0], [3, 1], [4, 0]])
    np.testing.assert_allclose(w, [2, 3, 1, 1, 1])
    np.testing.assert_allclose(knots, [0, 0, 0, 0, 1, 2, 2, 2, 2])
    assert p.kind[-1] == Kind.LINE and p.start[-1][0] == 4


@pytest.mark.parametrize(
    ("text", "line", "needle"),
    [
        ("G1 X0 F60\nG5 X1 Y1 P0 Q1\n", 2, "first G5 of a series needs I and J"),
        ("G1 X0 F60\nG5 X1 Y1 I1 P0 Q1\n", 2, "I and J go together"),
        ("G1 X0 F60\nG5 X1 Y1 I1 J1\n", 2, "G5 needs P and Q"),
        ("G1 X0 F60\nG5.1 X1 Y1\n", 2, "needs a non-zero I, J"),
        ("G1 X0 F60\nG5.2 X1 Y1\nX2 Y0\nX3 Y3\n", 2, "not closed with G5.3"),
        ("G1 X0 F60\nG5.2 X1 Y1\nG1 X3\n", 3, "not closed with G5.3"),
        ("G1 X0 F60\nG5.3\n", 2, "G5.3 without an open G5.2"),
        ("G1 X0 F60\nG5.2 X1 Y1\nG5.3\n", 2, "needs at least 3 control points"),
        ("G1 X0 F60\nG5.2 X1 Y1 Z2\nG5.3\n", 2, "X and Y only"),
        ("G1 X0 F60\nG6.2 X0 Y0 R1 K0 P3\nX1 Y1 K0\nX2 Y0 K0\nG6.2 K1\n", 2, "need 6"),
        ("G1 X0 F60\nG6.2 X0 Y0 R1 K0 P3 Q2\n", 2, "Q2 is not supported"),
        ("G1 X0 F60\nG6.2 X5 Y0 R1 K0 P3\n", 2, "starts at its first control point"),
        ("G1 X0 F60\nG6.2 X0 Y0 R1 K1 P3\nX1 Y1 K0\n", 3, "smaller than the previous knot"),
        ("G1 X0 F60\nG6.2 X0 Y0 K0 P3\nX1 Y1 K0\nX2 Y0 K1\nG6.2 K1\nG6.2 K1\nG6.2 K1\n", 2, "clamped"),
    ],
)
def test_spline_errors(text, line, needle):
    e = err(text)
    assert e.line == line and needle in e.reason, str(e)


def test_g6_2_nurbs_with_knots_plans_and_checks(tmp_path):
    from tests.conftest import make_machine
    from tests.helpers import table_of

    text = (
        "G1 X0 Y0 F600\nG6.2 X0 Y0 R1 K0 P3 Q1\nX10 Y10 R2 K0\nX20 Y0 R1 K0\nX30 Y10 R1 K1\n"
        "G6.2 K2\nG6.2 K2\nG6.2 K2\nG1 X40\n"
    )
    p = parse(text)
    deg, pts, w, knots = p.curves.curve(0)
    assert deg == 2 and list(knots) == [0, 0, 0, 1, 2, 2, 2] and list(w) == [1, 2, 1, 1]
    _, _, meas = table_of(text, make_machine(), tmp_path)
    assert meas.ok, meas.violations


@pytest.mark.parametrize(
    ("name", "json_name"),
    [
        ("butterfly-xy", "lcnc_g52_butterfly_xy.json"),
        ("Curva_Farfalla", "lcnc_g62_Curva_Farfalla_1_1.json"),
    ],
)
def test_corpus_nurbs_equal_their_json(name, json_name):
    import json

    from tests.conftest import CORPUS

    p = load_gcode(corpus_file(name))
    blocks = json.loads((CORPUS / "nurbs" / json_name).read_text())["blocks"]
    assert len(p.curves) == len(blocks)
    for i, blk in enumerate(blocks):
        deg, pts, w, knots = p.curves.curve(i)
        assert deg == blk["degree"]
        np.testing.assert_allclose(pts[:, :2], blk["control_points"], atol=1e-12)
        np.testing.assert_allclose(w, blk["weights"])
        np.testing.assert_allclose(knots, blk["knots"])


def test_corpus_nurbs_programs_plan_and_check(tmp_path):
    from tests.conftest import make_machine
    from tests.helpers import table_of

    for name in ("butterfly-xy", "Curva_Farfalla"):
        _, table, meas = table_of(corpus_file(name).read_text(), make_machine(), tmp_path, name + ".ticks")
        assert meas.ok, meas.violations


# ---- planes, centre modes, offsets, corpus --------------------------------------------------


@pytest.mark.parametrize(
    ("setup", "arc", "center", "through"),
    [
        ("G17 G0 X10 Y0 Z0", "G3 X0 Y10 I-10 J0", (0, 0, 0), (7.0710678, 7.0710678, 0)),
        # G18 arcs are in Z-X: G2 is clockwise seen from +Y, so +X to +Z the short way is G2
        ("G18 G0 X10 Y0 Z0", "G2 X0 Z10 I-10 K0", (0, 0, 0), (7.0710678, 0, 7.0710678)),
        ("G19 G0 X0 Y10 Z0", "G3 Y0 Z10 J-10 K0", (0, 0, 0), (0, 7.0710678, 7.0710678)),
    ],
)
def test_arcs_in_each_plane(setup, arc, center, through):
    from jaxcnc.geometry import build_spans
    from tests.helpers import at_s

    p = parse(f"{setup}\n{arc} F600\n")
    np.testing.assert_allclose(p.center[1], center, atol=1e-12)
    sp = build_spans(p)
    k = np.flatnonzero(sp.kind == 2)
    assert k.size == 1 and sp.length[k[0]] == pytest.approx(np.pi * 5, rel=1e-12)  # a quarter of r = 10
    (mid,) = at_s(sp, k, sp.length[k] / 2)
    np.testing.assert_allclose(mid[0], through, atol=1e-6)  # the arc's middle


def test_helix_in_g18():
    from jaxcnc.geometry import build_spans

    sp = build_spans(parse("G18 G0 X10 Y0 Z0\nG2 X0 Z10 Y4 I-10 K0 F600\n"))
    assert list(sp.kind) == [1, 2]  # the rapid, then an exact helix rising along Y (the normal of ZX)
    np.testing.assert_allclose(sp.end[-1], [0, 4, 10], atol=1e-12)


def test_absolute_arc_centres_g90_1():
    a = parse("G0 X10 Y5\nG90.1 G3 X0 Y15 I0 J5 F600\n")
    b = parse("G0 X10 Y5\nG91.1 G3 X0 Y15 I-10 J0 F600\n")
    np.testing.assert_allclose(a.center[1], [0, 5, 0], atol=1e-12)
    np.testing.assert_allclose(a.center, b.center, equal_nan=True, atol=1e-12)


def test_g92_offsets_and_g53():
    p = parse("G0 X10 Y10\nG92 X0 Y0\nG1 X5 F600\nG53 G0 X1 Y1\nG92.2\nG1 X5\nG92.3\nG1 X5\nG92.1\nG1 X2\n")
    # after G92 the point (10, 10) reads (0, 0): X5 is machine 15; G53 moves in machine coordinates
    np.testing.assert_allclose(p.end[:, :2], [[10, 10], [15, 10], [1, 1], [5, 1], [15, 1], [2, 1]])


def test_coolant_events_and_tool_length_h0():
    p = parse("G43 H0\nM8\nG1 X1 F60\nM9\nG49\n")
    ev = [(int(k), int(e), int(v)) for k, e, v in zip(p.kind, p.event, p.event_value, strict=True)]
    assert ev == [(Kind.EVENT, Event.COOLANT, 8), (Kind.LINE, 0, 0), (Kind.EVENT, Event.COOLANT, 9)]


def test_every_corpus_program_parses():
    """All corpus G-code parses, except cncjs' calibration file, whose arc at N624 ends 1.4 mm off its
    circle — LinuxCNC refuses it too; the error names it (see test_corpus_radius_mismatch_is_reported)."""
    folder = corpus_file("plasmatest").parent
    counts = {}
    for f in sorted(folder.glob("*")):
        if f.suffix not in (".ngc", ".gcode") or "Circle_Diamond" in f.name:
            continue
        p = load_gcode(f)
        counts[f.name.split("__")[-1]] = (len(p), int((p.kind == Kind.ARC).sum()), int((p.kind == Kind.CURVE).sum()))
    assert counts["LHchips4.ngc"][1] == 225  # the MANIFEST: 9.6k G1 + 225 arcs (G18 among them)
    assert counts["arcspiral.ngc"][1] == 999
    assert counts["butterfly-xy.ngc"][2] == 6 and counts["Curva_Farfalla_1-1.ngc"][2] == 1
    assert len(counts) == 6
