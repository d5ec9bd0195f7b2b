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


def test_g9_stops_at_the_end_of_its_block_alone():
    """G9 (non-modal exact stop): the block's last row ends unblended and the next row starts at rest, as after a
    move programmed under G61.1; an arc's P turns run on; without motion it does nothing (posts emit it; it was
    refused until the red-team pass of 2026-12-08)."""
    p = parse("G64 P0.1\nG1 X10 F600\nG9 G1 X10 Y10\nG1 X20 Y10\nG9 G2 X20 Y10 I1 P3\nG1 X30\nG9\nG1 X40 Y5\n")
    assert list(p.line) == [2, 3, 4, 5, 5, 5, 6, 8]
    assert list(p.blend_tol) == [0.1, 0.0, 0.1, 0.1, 0.1, 0.0, 0.1, 0.1]
    assert list(p.stop_before) == [True, False, True, False, False, False, True, False]
    same = parse("G64 P0.1\nG1 X10 F600\nG61.1\nG1 X10 Y10\nG64 P0.1\nG1 X20 Y10\n")
    for k in ("blend_tol", "stop_before", "end"):
        np.testing.assert_array_equal(getattr(same, k), getattr(p, k)[:3])


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


TOOLS = {1: (0.0, 0.0, 12.5), 2: (1.5, -2.0, -3.0)}


def test_g43_needs_the_tool_in_the_table_except_for_no_offset():
    e = err("T1 M6\nG43 Z15. H1\n")
    assert (e.line, e.column) == (2, 10) and "the machine file has no [tools] table" in e.reason
    e = err("T1 M6\nG43 Z15.\n")
    assert (e.line, e.column) == (2, 1) and "loaded tool T1" in e.reason
    assert len(parse("T1\nG43 G0 Z15.\nG43 H0\nG49\n")) == 1  # T1 selected, not loaded: no offset
    with pytest.raises(SourceError) as info:
        parse("G0 X1\nG43 Z15. H3\n", tools=TOOLS)
    assert (info.value.line, info.value.column) == (2, 10)
    assert "tool 3 has no offsets (the machine file's [tools] has 1, 2" in info.value.reason
    with pytest.raises(SourceError, match="a tool number is a non-negative integer"):
        parse("G43 H1.5\n", tools=TOOLS)


def test_g43_h_applies_the_tool_length_offset_as_linuxcnc():
    """LinuxCNC's meaning: a programmed Z is reached at machine Z + the tool's offset; the offset moves nothing
    itself (an axis not named stays where it is), absolute coordinates take it, incremental ones go on from where
    the axis is; G49 (and H0) cancel it; G92 reads the position under it."""
    p = parse(
        "G21 G90 G0 X1 Y2 Z3\n"  # start
        "T1 M6\n"
        "G43 Z15. H1\n"  # Fusion's form: the offset and a move in the motion mode in effect
        "X4\n"  # Z not named: stays at 27.5
        "G91 Z1\n"  # incremental: 28.5
        "G90 G1 Z0 F600\n"  # the part's top: machine 12.5
        "G49 G0 Z10\n"  # cancelled: machine 10
        "G43 G0 X0\n"  # without H: the loaded tool T1; Z not named stays at 10
        "Z0\n"  # 12.5
        "G43 H0 G0 Z0\n"  # no offset
        "M2\n",
        tools=TOOLS,
    )
    np.testing.assert_allclose(
        p.end[[0, 2, 3, 4, 5, 6, 7, 8, 9]],
        [[1, 2, 3], [1, 2, 27.5], [4, 2, 27.5], [4, 2, 28.5], [4, 2, 12.5], [4, 2, 10], [0, 2, 10], [0, 2, 12.5],
         [0, 2, 0]],
    )  # fmt: skip
    assert p.event[1] == Event.TOOL_CHANGE
    q = parse("G0 X0 Y0 Z0\nG43 H1\nG92 Z0\nG0 Z1\nG49\nZ1\n", tools=TOOLS)  # G92 under the offset
    np.testing.assert_allclose(q.end[-2:, 2], [1.0, 1.0 - 12.5])
    g53 = parse("G0 X0 Y0 Z0\nG43 H1\nG53 G0 Z0\nG28\nG28 Z5\n", tools=TOOLS, home=(0.0, 0.0, 50.0))
    np.testing.assert_allclose(g53.end[1:, 2], [0.0, 50.0, 17.5, 50.0])  # machine positions; G28's via point shifted
    arc = parse("G0 X0 Y0 Z0\nG43.2 H2\nX0 Y0\nG90.1 G2 X10 Y0 I5 J0 F600\n", tools=TOOLS)  # absolute centres too
    np.testing.assert_allclose(arc.end[-1], [11.5, -2.0, 0.0])
    np.testing.assert_allclose(arc.center[-1][:2], [6.5, -2.0])


def test_g43_1_and_g43_2_set_and_add_offsets():
    p = parse(
        "G20 G0 X0 Y0 Z0\n"  # inches: the axis words of G43.1 are program units
        "G43.1 Z0.5\nZ0\n"  # 12.7 mm
        "G43.2 Z0.1\nZ0\n"  # + 2.54
        "G43.2 H1\nZ0\n"  # + 12.5 mm from the table
        "G43.1 X1\nZ0 X0\n"  # X replaced, Z kept
        "G49\nZ0\n",
        tools=TOOLS,
    )
    np.testing.assert_allclose(
        p.end[1:], [[0, 0, 12.7], [0, 0, 15.24], [0, 0, 27.74], [25.4, 0, 27.74], [25.4, 0, 0]], atol=1e-12
    )
    for text, col, needle in [
        ("G43.1 H1\n", 7, "G43.1 takes axis words, not H"),
        ("G43.1\n", 1, "G43.1 needs axis words"),
        ("G43.2\n", 1, "G43.2 adds the offsets of a tool (H) or those given as axis words"),
        ("G0 G43.1 Z1\n", 4, "G43.1 and a motion G code in one block both claim the axis words"),
        ("G43 G43.1 Z1\n", 5, "modal group"),
    ]:
        with pytest.raises(SourceError) as info:
            parse(text, tools=TOOLS)
        assert info.value.column == col and needle in info.value.reason, (text, info.value)


def test_a_machine_file_tool_table_reaches_the_program(tmp_path):
    from jaxcnc.front_ends import FRONT_ENDS
    from jaxcnc.machine import MachineFileError, parse_machine

    base = (
        '[machine]\ntick_hz = 1000\n[axes.x]\nv_max = 100\na_max = 1000\nmin = -100\nmax = 100\n'
        '[axes.y]\nv_max = 100\na_max = 1000\nmin = -100\nmax = 100\n'
        '[axes.z]\nv_max = 100\na_max = 1000\nmin = -100\nmax = 100\n'
        '[path]\nfeed = 10\nrapid = 50\n'
    )  # fmt: skip
    m = parse_machine(base + "[tools.2]\nz_mm = -3.0\nx_mm = 1.5\n[tools.1]\nz_mm = 12.5\n", "m.toml")
    assert m.tool_offsets() == {1: (0.0, 0.0, 12.5), 2: (1.5, 0.0, -3.0)}
    prog = tmp_path / "p.ngc"
    prog.write_text("G0 X0 Y0 Z0\nG43 H2 Z1\nM2\n")
    p = FRONT_ENDS.get("ngc").load(prog, m)
    np.testing.assert_allclose(p.end[-1], [0.0, 0.0, -2.0])  # X not named: no move on X
    for extra, needle in [
        ("[tools.0]\nz_mm = 1\n", "'0' is not a tool number"),
        ("[tools.T1]\nz_mm = 1\n", "'T1' is not a tool number"),
        ("[tools.1]\nx_mm = 1\n", "missing required key 'z_mm'"),
        ("[tools.1]\nz_mm = 1\nd_mm = 3\n", "unknown key 'd_mm'"),
        ("[tools.1]\nz_mm = inf\n", "tools.1.z_mm"),
        ("tools = 3\n", "must be a table of tool tables"),
    ]:
        text = (extra + base) if extra.startswith("tools =") else base + extra
        with pytest.raises(MachineFileError, match=needle.replace("[", r"\[").replace(".", r"\.")):
            parse_machine(text, "m.toml")


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


def test_tool_offsets_reach_the_bulk_path_as_the_line_by_line_one():
    body = "".join(f"G1 X{i * 0.1:.3f} Y{(i % 7) * 0.05:.3f} Z{(i % 3) * 0.01:.3f} F600\n" for i in range(200))
    inc = "".join(f"G1 X0.1 Y{(-1) ** i * 0.05:.3f}\n" for i in range(100))
    arcs = "".join(f"G2 X{i * 0.1 + 0.1:.3f} Y0 I0.05 J0\n" for i in range(200, 260))
    text = f"G0 X0 Y0 Z0\nT1 M6\nG43 H2\n{body}G91\n{inc}G90 G43.1 Z2\nG0 X20 Y0\n{arcs}G49\n{body}M2\n"
    fast, slow = parse(text, tools=TOOLS), parse(text, tools=TOOLS, fast=False)
    assert same_program(fast, slow)
    np.testing.assert_allclose(fast.end[2], [1.5, -2.0, -3.0])  # G1 X0 Y0 Z0 under tool 2
