"""Programs as CAM posts write them: the header and cycle words they emit, accepted with their meaning
or refused with a located reason (docs/gcode.md, "Words")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxcnc.errors import SourceError
from jaxcnc.gcode import parse_gcode
from jaxcnc.program import PROGRAM_COLUMNS, Event, Kind, LaserMode


def parse(text: str, **kw):
    return parse_gcode(text, "post.ngc", **kw)


def err(text: str) -> SourceError:
    with pytest.raises(SourceError) as info:
        parse(text)
    return info.value


def same_program(a, b) -> bool:
    return all(getattr(a, k).tobytes() == getattr(b, k).tobytes() for k in PROGRAM_COLUMNS)


# ---- whole programs in the shapes posts give them ---------------------------------------------------

POSTS = {
    # Autodesk Fusion, LinuxCNC (EMC2) post: the safe-start block, G53 retracts, G54 G0 with no axes
    "fusion-linuxcnc": """%
(1001)
(T1  D=6. CR=0. - ZMIN=-1. - flat end mill)
N10 G90 G94 G40 G17 G91.1
N15 G21
N20 G53 G0 Z0.
(2D CONTOUR1)
N25 G49
N30 M5
N35 T1 M6
N40 S5000 M3
N45 G54 G0
N50 X10. Y5.
N55 M8
N60 G1 Z-1. F1000.
N65 X20.
N70 G2 X25. Y10. I0. J5.
N75 G1 Z15.
N80 M9
N85 G49
N90 G53 G0 Z0.
N95 M5
N100 M30
%
""",
    # FreeCAD's linuxcnc_post: G80 in the preamble and the postamble
    "freecad-linuxcnc": """(Exported by FreeCAD)
(Post Processor: linuxcnc_post)
(begin preamble)
G17 G54 G40 G49 G80 G90
G21
(begin operation: Profile)
G0 Z5.000
G0 X0.000 Y0.000
G1 Z-1.000 F600.000
G1 X10.000 F1200.000
G3 X20.000 Y0.000 I5.000 J0.000
(finish operation: Profile)
(begin postamble)
M05
G17 G54 G90 G80 G40
M2
""",
    # Mach3 / Fanuc style safe-start line: G0 and G80 in one block
    "iso-safe-start": """G0 G17 G40 G49 G80 G90 G21
G0 X0 Y0 S10000 M3
G1 X10 Y0 F800
G3 X10 Y10 R5
G0 X0 Y0
M5
M30
""",
    # LinuxCNC's trajectory-planner tests open with G80 (cancel canned cycle) and arc centre modes
    "linuxcnc-tp-tests": """G21 G80 G90 G91.1
G64 P0.005
G0 X0 Y0 Z1
G1 Z0 F1000
G1 X5
G2 X10 Y0 I2.5 J0
G3 J-1
M2
""",
    # LightBurn, GRBL device profile: ';' comments, compact words, power on G1, M4 dynamic laser
    "lightburn-grbl": """; LightBurn 1.7.04
; GRBL device profile, absolute coords
G00 G17 G40 G21 G54
G90
M4
; Cut @ 12000 mm/min, 10% power
M8
G0 X44.635Y36.862
; Layer C00
G1 X44.631Y37.046S1000F16000
G1 X44.592Y37.467
M9
G1 S0
M5
G90
; return to user-defined finish pos
G0 X0 Y0
M2
""",
    # SheetCam plasma post (as in LinuxCNC's 51MeanderAve): G64 P Q, M01, M03, G04 pierce
    "sheetcam-plasma": """(Post processor: LinuxCNC plasma.scpost)
G21 (Units: Metric)
G40 G90
F1 S1
G64 P0.01 q00.01
G00
X21.000 Y20.000
M01
M03
G04 P0.6
G01 F5000
S1 (On start)
X18.000
G03 X18.919 Y18.317 I2.000 J0.000
M05
G00
X0 Y0
M30
""",
}


@pytest.mark.parametrize("name", sorted(POSTS))
def test_post_programs_plan(name):
    p = parse(POSTS[name])
    assert len(p) > 0 and np.all(np.isfinite(p.end))
    assert np.all(p.start[1:] == p.end[:-1])
    assert same_program(p, parse(POSTS[name], fast=False))


def test_fusion_post_rows():
    p = parse(POSTS["fusion-linuxcnc"])
    moves = p.kind != Kind.EVENT
    np.testing.assert_allclose(p.end[moves][-2], [25, 10, 15])  # G1 Z15. after the arc
    assert int((p.kind == Kind.ARC).sum()) == 1
    assert list(p.event[p.kind == Kind.EVENT]) == [
        Event.TOOL_CHANGE,
        Event.COOLANT,
        Event.COOLANT,
        Event.PROGRAM_END,
    ]


def test_lightburn_post_rows():
    p = parse(POSTS["lightburn-grbl"])
    cut = (p.kind == Kind.LINE) & ~p.rapid
    assert list(p.power[cut]) == [1000, 1000]
    assert np.all(p.laser[cut] == LaserMode.DYNAMIC)
    assert p.power[-2] == 0 and p.rapid[-2]  # "G1 S0" moves nowhere but sets the power of what follows


# ---- G80 -------------------------------------------------------------------------------------------


def test_g80_in_a_header_changes_nothing():
    body = "G1 X5 F600\nG2 X10 Y0 I2.5 J0\n"
    assert same_program(parse("G80 G90 G94\n" + body), parse("G90 G94\n" + body))
    assert same_program(parse("G0 G17 G40 G49 G80 G90\n" + body), parse("G0 G17 G40 G49 G90\n" + body))


def test_g80_with_a_motion_code_takes_that_mode():
    p = parse("G1 G80 X5 F600\nX6\n")  # the block's G1 is the motion mode; G80 cancels no cycle
    np.testing.assert_allclose(p.end[:, 0], [5, 6])
    assert not p.rapid.any()


def test_g80_cancels_the_motion_mode_as_linuxcnc():
    e = err("G1 X1 F60\nG80\nX2\n")
    assert (e.line, e.column) == (3, 1)
    assert "no motion mode" in e.reason and "G80 at line 2 cancelled it" in e.reason
    e = err("G1 X1 F60\nG80 X2\n")
    assert (e.line, e.column) == (2, 5) and "G80 cancels the motion mode" in e.reason
    # axis words claimed by G92 / G28 in a G80 block are theirs
    p = parse("G0 X1\nG80 G92 X0\nG0 X1\nG80 G28\n", home=(0, 0, 0))
    np.testing.assert_allclose(p.end[:, 0], [1, 2, 0])


# ---- no-op modal words: G8, G97, G98, G99 -----------------------------------------------------------


@pytest.mark.parametrize("word", ["G8", "G97", "G98", "G99", "G97 G98", "G8 G97 G99"])
def test_default_mode_words_change_nothing(word):
    body = "G1 X5 F600 S40\nM3\nG2 X10 Y0 I2.5 J0\n"
    assert same_program(parse(f"{word}\n{body}"), parse(f"(nothing)\n{body}"))
    assert same_program(parse(f"G1 {word} X1 F60\n"), parse("G1 X1 F60\n"))


# ---- G10 L2 ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("block", ["G10 L2 P0 R0", "G10 L2 P1 X0 Y0 Z0", "G10 L2 P9 X0 R0.0", "G10 P0 L2"])
def test_g10_l2_to_zero_changes_nothing(block):
    body = "G1 X5 Y1 F600\nG54 G1 X6\n"
    assert same_program(parse(f"{block}\n{body}"), parse(f"(nothing)\n{body}"))


def test_m_words_act_in_g10_and_g92_blocks():
    p = parse("G0 X1\nG10 L2 P0 R0 M0\nG92 X0 M2\nG1 X5 F60\n")
    assert list(p.event) == [0, Event.PROGRAM_STOP, Event.PROGRAM_END]  # nothing after the M2 runs


@pytest.mark.parametrize(
    ("block", "col", "needle"),
    [
        ("G10 L2 P0 X-2 Y1 R60", 11, "offset other than zero is not supported"),
        ("G10 L2 P1 R60", 11, "rotation other than zero is not supported"),
        ("G10 L20 P1 X0", 5, "L20 sets a work offset from the current point"),
        ("G10 L1 P1 Z0.5", 5, "writes the tool table"),
        ("G10 L10 P1 Z0.5", 5, "writes the tool table"),
        ("G10 L3 P1", 5, "not a G10 form"),
        ("G10 P1 X0", 1, "G10 needs L"),
        ("G10 L2 X0", 1, "G10 L2 needs P"),
        ("G10 L2 P10", 8, "P is 0 (the active system) or 1-9"),
        ("G10 L2 P1 X0 G0", 1, "both claim the axis words"),
        ("G10 L2 P1 Q2", 11, "no meaning"),
    ],
)
def test_g10_refusals(block, col, needle):
    e = err(f"G0 X1\n{block}\n")
    assert (e.file, e.line, e.column) == ("post.ngc", 2, col), str(e)
    assert needle in e.reason


# ---- arcs: P turns, no end point words --------------------------------------------------------------


def test_arc_turns_p_make_full_circles_then_the_arc():
    p = parse("G1 X0 Y0 Z0 F600\nG3 X-5 Y5 Z3 I-5 J0 P2\n")
    assert list(p.kind) == [Kind.LINE, Kind.ARC, Kind.ARC] and list(p.line) == [1, 2, 2]
    # a quarter turn plus one full turn: the helix rises 3 mm over 5/4 turns, 2.4 mm in the full one
    np.testing.assert_allclose(p.end[1], [0, 0, 2.4], atol=1e-12)
    np.testing.assert_allclose(p.center[1], [-5, 0, 0], atol=1e-12)
    np.testing.assert_allclose(p.center[2], [-5, 0, 2.4], atol=1e-12)
    np.testing.assert_allclose(p.end[2], [-5, 5, 3])
    assert list(p.turn[1:]) == [1, 1]
    p = parse("G1 X0 Y0 F600\nG2 X0 Y0 I5 P3\n")  # a full circle three times
    assert len(p) == 4 and np.all(p.end[1:] == p.start[1:]) and np.all(p.turn[1:] == -1)
    p = parse("G19 G1 X0 Y2 Z0 F600\nG2 Y-2 X5 J-2 K-10 P2\n")  # LinuxCNC's arc_time.ngc, in G19
    assert len(p) == 3 and p.end[-1][0] == 5 and p.plane[-1] == 19


@pytest.mark.parametrize(("block", "needle"), [("G2 X10 I5 P0", "positive integer"), ("G2 X10 I5 P1.5", "integer")])
def test_arc_turns_must_be_positive_integers(block, needle):
    e = err(f"G1 X0 F60\n{block}\n")
    assert (e.line, e.column) == (2, 11) and needle in e.reason


def test_p_of_g4_or_g64_in_an_arc_block_is_theirs():
    p = parse("G1 X0 F60\nG64 P0.05 G2 X10 I5\n")
    assert len(p) == 2 and p.blend_tol[1] == pytest.approx(0.05)


def test_arc_without_end_point_words_is_a_full_circle():
    p = parse("G1 X10 F600\nG2 I-5\nJ2\nG3 I-1 J0 Z-1\n")
    assert list(p.kind) == [Kind.LINE, Kind.ARC, Kind.ARC, Kind.ARC]
    assert np.all(p.end[1:3] == p.start[1:3])
    np.testing.assert_allclose(p.center[1:3, :2], [[5, 0], [10, 2]])
    np.testing.assert_allclose(p.end[3], [10, 0, -1])  # a helix turn
    assert err("G1 X1 F60\nG2 F100\n").reason == "arc needs I/J (centre) or R (radius)"
    assert "a full circle needs I/J" in err("G1 X1 F60\nG2 R5\n").reason


# ---- G43 -------------------------------------------------------------------------------------------


def test_g43_needs_a_tool_table_except_for_no_offset():
    e = err("T1 M6\nG43 Z15. H1\n")
    assert (e.line, e.column) == (2, 10) and "no tool table is configured" in e.reason
    e = err("T1 M6\nG43 Z15.\n")
    assert (e.line, e.column) == (2, 1) and "loaded tool T1" in e.reason
    assert len(parse("T1\nG43 G0 Z15.\nG43 H0\nG49\n")) == 1  # T1 selected, not loaded: no offset


# ---- refusals with their reasons --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("block", "col", "needle"),
    [
        ("G81 X1 Y1 Z-1 R1 F100", 1, "G81 is a drilling or boring cycle: canned cycles are not supported"),
        ("G98 G83 X1 Y1 Z-1 R1 Q0.5", 5, "G83 is a drilling or boring cycle"),
        ("G73 X1 Z-1 R1 Q1", 1, "G73 is a drilling cycle"),
        ("G76 P0.05 Z-1 I-0.1 J0.1 K0.1", 1, "G76 threading cycle needs a spindle encoder"),
        ("G33 Z-2 K0.025", 1, "G33 spindle-synchronized motion needs a spindle encoder"),
        ("G33.1 Z-0.75 K0.05", 1, "G33.1 rigid tapping needs a spindle encoder"),
        ("G38.2 Z-10 F100", 1, "probing needs a probe input"),
        ("G41.1 D0.5", 1, "cutter compensation G41.1 is not supported yet"),
        ("G42 D1", 1, "cutter compensation G42 is not supported yet"),
        ("G43.1 Z0.5", 1, "dynamic tool length offset"),
        ("G7", 1, "lathe diameter mode"),
        ("G17.1", 1, "U V W axes"),
        ("G28.1", 1, "home="),
        ("G30", 1, "second home position"),
        ("G50", 1, "not a LinuxCNC code"),
        ("G52 X1", 1, "G92 is"),
        ("G69", 1, "not a LinuxCNC code"),
        ("G70 Q100", 1, "lathe cycles are not supported"),
        ("G93", 1, "inverse-time feed"),
        ("G95", 1, "feed per revolution needs a spindle"),
        ("G96 S200 M3", 1, "constant surface speed"),
        ("M19", 1, "spindle orientation"),
        ("M48", 1, "override control"),
        ("M60", 1, "pallet change"),
        ("M61 Q1", 1, "use T and M6"),
        ("M62 P0", 1, "switch the laser with M3/M4/M5"),
        ("M66 P0 L0", 1, "waiting on an input"),
        ("M67 E0 Q50", 1, "set the laser power with S"),
        ("M70", 1, "modal state"),
        ("M111", 1, "user-defined program"),
        ("G0 X0 Y0 A90.", 10, "unsupported word A90.: jaxcnc plans the X, Y and Z axes only"),
        ("G0 W1", 4, "X, Y and Z axes only"),
        ("G1 X1 D3", 7, "cutter compensation"),
        ("G1 X1 E0.5", 7, "not an RS274NGC word"),
        ("G1 @1 ^90", 4, "polar coordinates"),
        ("G10.5", 1, "unknown or unsupported word G10.5"),
    ],
)
def test_refused_words_name_the_reason(block, col, needle):
    e = err(f"G0 X0\n{block}\n")
    assert (e.file, e.line, e.column) == ("post.ngc", 2, col), str(e)
    assert needle in e.reason, e.reason


def test_refusals_are_the_same_in_every_dialect():
    for dialect in ("linuxcnc", "siemens", "fanuc"):
        with pytest.raises(SourceError, match="canned cycles are not supported"):
            parse_gcode("G81 X1 Y1 Z-1 R1 F100\n", dialect=dialect)
        assert math.isnan(parse_gcode("G80 G0 X1\n", dialect=dialect).feed[0])
