"""Dialects: Siemens BSPLINE (the documents' example), Fanuc G06.2, user dialect files, errors."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.errors import JaxcncError, SourceError
from jaxcnc.gcode import parse_gcode
from jaxcnc.gcode.dialect import load_dialect, parse_dialect
from jaxcnc.geometry import SpanKind, build_spans
from tests.helpers import at_s

SEEDS_BSPLINE = """\
G00 X30 Y0 Z0
BSPLINE X30 Y30 PW={w} SD=2 PL=0.25
X0 Y30 PW=1 PL=0.0
X-30 Y30 PW={w} PL=0.25
X-30 Y0 PW=1 PL=0.0
X-30 Y-30 PW={w} PL=0.25
X0 Y-30 PW=1 PL=0.0
X30 Y-30 PW={w} PL=0.25
X30 Y0 PW=1 PL=0.0
G00 X0 Y0
M02
"""


@pytest.mark.parametrize(("w", "tol"), [("0.707", 1e-3), ("0.70710678118654757", 1e-9)])
def test_documents_bspline_circle(w, tol):
    """SEEDS §2: a degree-2 rational B-spline on a square of control points is the radius-30 circle."""
    p = parse_gcode(SEEDS_BSPLINE.format(w=w), "circle.mpf", dialect="siemens")
    deg, pts, weights, knots = p.curves.curve(0)
    assert deg == 2
    np.testing.assert_allclose(knots, [0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1])
    np.testing.assert_allclose(weights[1::2], float(w))
    sp = build_spans(p)
    c = np.flatnonzero(sp.kind == SpanKind.CURVE)
    idx = np.repeat(c, 500)
    (pos,) = at_s(sp, idx, np.tile(np.linspace(0, 1, 500), c.size) * sp.length[idx])
    r = np.hypot(*pos[:, :2].T)
    assert np.max(np.abs(r - 30)) <= tol  # within 1 µm with PW=0.707; 1e-9 mm with the exact weight
    assert p.kind[-1] == 4 and p.end[-2, 0] == 0  # the spline ends at G00; the program at M02


def test_bspline_without_pl_uses_chord_lengths():
    p = parse_gcode("G0 X0 Y0\nBSPLINE X10 Y0 SD=2\nX10 Y10\nX20 Y10\nG1 X30 F600\n", "c.mpf", dialect="siemens")
    _, _, _, knots = p.curves.curve(0)
    np.testing.assert_allclose(knots, [0, 0, 0, 10, 30, 30, 30])


def test_fanuc_nurbs_and_dialect_limits():
    text = "G01 X0 Y0 F600\nG06.2 P3 K0 X0 Y0 R1\nK0 X10 Y10 R1\nK0 X20 Y0 R1\nK1 X30 Y10\nK2\nK2\nK2\nG01 X40\n"
    p = parse_gcode(text, "f.nc", dialect="fanuc")
    deg, _, _, knots = p.curves.curve(0)
    assert deg == 2 and list(knots) == [0, 0, 0, 1, 2, 2, 2]
    with pytest.raises(SourceError, match="G5 is not part of the fanuc dialect"):
        parse_gcode("G5 X1 Y1 I1 J0 P0 Q1 F60\n", "f.nc", dialect="fanuc")
    with pytest.raises(SourceError, match=r"unknown word 'BSPLINE' \(not part of the linuxcnc dialect\)"):
        parse_gcode("BSPLINE X1 Y1\n", "l.ngc")  # not a LinuxCNC word
    # Fanuc has no ';' comments; Siemens no '(' comments
    with pytest.raises(SourceError):
        parse_gcode("G01 X1 F60 ; note\n", "f.nc", dialect="fanuc")
    with pytest.raises(SourceError):
        parse_gcode("G01 X1 F60 (note)\n", "s.mpf", dialect="siemens")


def test_user_dialect_file(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text('[dialect]\nname = "mine"\ncomments = ["paren"]\narc_centers = "absolute"\nsplines = []\n')
    d = load_dialect(str(f))
    assert d.name == "mine" and d.arc_centers_absolute and not d.semicolon_comments
    p = parse_gcode("G0 X10 Y0\nG3 X0 Y10 I0 J0 F600\n", "m.ngc", dialect=d)
    np.testing.assert_allclose(p.center[1], [0, 0, 0], atol=1e-12)  # I J absolute by default here


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[dialect]\ncomments = ['hash']\n", "comments"),
        ("[dialect]\nsplines = ['G7']\n", "splines"),
        ("[dialect]\nfoo = 1\n", "unknown key"),
        ("[keywords]\nBSPLINE = 'nothing'\n", "meanings"),
        ("[addresses]\nP = 'weight'\n", "two letters"),
        ("[dialect\n", "not valid TOML"),
        ("[dialect]\nprogram_numbers = 1\n", "program_numbers must be true or false"),
        ("[dialect]\nedge_offsets = 'yes'\n", "edge_offsets must be true or false"),
        ("[g_codes]\nG71 = 'G81'\n", "one of G20, G21, G61, G61.1, G64"),
        ("[g_codes]\nX71 = 'G21'\n", "a G code of the dialect"),
        ("[g_codes]\nG71 = 21\n", "a G code of the dialect"),
    ],
)
def test_bad_dialect_files(text, needle):
    with pytest.raises(JaxcncError, match=needle):
        parse_dialect(text, "bad.toml")


def test_unknown_dialect_name():
    with pytest.raises(JaxcncError, match="unknown dialect"):
        load_dialect("heidenhain")


def test_fanuc_nurbs_cancelled_before_its_knots_are_complete():
    with pytest.raises(SourceError) as info:
        parse_gcode("G01 X0 Y0 F600\nG06.2 P3 K0 X0 Y0\nK0 X10 Y10\nK0 X20 Y0\nK1\nG01 X40\n", "f.nc", dialect="fanuc")
    assert info.value.line == 6 and "opened at line 2 is incomplete: 4 knots, 6 needed" in info.value.reason


HAAS = """%
O00001 (PART 7)
G00 G17 G40 G49 G80 G90
T2 M06
G00 G90 G54 X0. Y0. S3000 M03
G43 H02 Z1.
G01 Z-0.1 F20.
X1.
G00 Z1.
G91 G28 Z0.
M30
%
O00002 (NOT CALLED)
G01 X5.
M99
"""


def test_fanuc_program_numbers_name_the_program_and_nothing_else():
    """Every Fanuc / Haas post starts with the program number ``O00001 (NAME)``: the fanuc dialect reads it (and
    those of subprograms written after M30, which nothing calls); LinuxCNC's O-words need a keyword and say which
    dialect reads numbers; M98 / M99 calls are refused by name."""
    p = parse_gcode(HAAS, "h.nc", dialect="fanuc", tools={2: (0.0, 0.0, 25.0)})
    without = parse_gcode(HAAS.replace("O00001 (PART 7)\n", ""), "h.nc", dialect="fanuc", tools={2: (0.0, 0.0, 25.0)})
    assert all(getattr(p, k).tobytes() == getattr(without, k).tobytes() for k in ("kind", "end", "feed"))
    assert p.end[3].tolist() == pytest.approx([0.0, 0.0, 24.9])  # G43 H02 applied
    with pytest.raises(SourceError) as info:
        parse_gcode(HAAS, "h.nc", tools={2: (0.0, 0.0, 25.0)})
    assert info.value.line == 2 and "--dialect fanuc" in info.value.reason
    with pytest.raises(SourceError, match="M98 \\(Fanuc subprogram call\\) is not supported"):
        parse_gcode("G0 X1\nM98 P2\nM30\n", "h.nc", dialect="fanuc")
    with pytest.raises(SourceError, match="needs a keyword"):  # an O-word with more than a number stays control flow
        parse_gcode("O100 X1\n", "h.nc", dialect="fanuc")


SINUMERIK = """%_N_PART_7_MPF
;$PATH=/_N_MPF_DIR
N10 G90 G94 G17 G40
N15 G71
N20 T1 D1
N25 M6
N40 G0 X10 Y5
N45 G0 Z15
N50 G1 Z-1 F100
N55 G64
N60 X20 F500
N65 G3 X25 Y10 I0 J5
N70 G1 Y20
N75 G0 Z15
N80 D0
N81 G0 Z15
N82 G70
N83 G0 Z1
N84 G60
N85 G1 X2 F10
N90 M30
"""


def test_sinumerik_program_names_units_and_cutting_edges():
    """What Sinumerik posts write: the ``%_N_NAME_MPF`` line, ``G71`` / ``G70`` (metric / inch), ``T1 D1`` (the tool's
    offsets from the machine file's table; ``D0`` none), ``G60`` (exact stop, modal)."""
    p = parse_gcode(SINUMERIK, "p.mpf", dialect="siemens", tools={1: (0.0, 0.0, 10.0)})
    np.testing.assert_allclose(
        p.end[1:-1],  # (row 0: the tool change; the last: the program's end)
        [[10, 5, 0], [10, 5, 25], [10, 5, 9], [20, 5, 9], [25, 10, 9], [25, 20, 9], [25, 20, 25], [25, 20, 15],
         [25, 20, 25.4], [50.8, 20, 25.4]],
    )  # fmt: skip
    assert np.all(np.isinf(p.blend_tol[1:-2])) and p.blend_tol[-2] == 0.0  # G60: exact corners from there (G61)
    for text, needle in [
        ("N1 T2 D1\n", "D1: tool T2 has no offsets"),
        ("N1 T1 D2\n", "each tool one cutting edge"),
        ("N1 D1\n", "no tool is selected"),
        ("N1 G70 G71\n", "G71 and G70 are in the same modal group"),
    ]:
        with pytest.raises(SourceError, match=needle):
            parse_gcode(text, "p.mpf", dialect="siemens", tools={1: (0.0, 0.0, 10.0)})
    with pytest.raises(SourceError, match="unsupported word D1: cutter compensation"):  # D under LinuxCNC
        parse_gcode("T1 D1\n", "p.ngc", tools={1: (0.0, 0.0, 10.0)})
    with pytest.raises(SourceError, match="G71 roughing cycle"):  # G71 means a lathe cycle there
        parse_gcode("G71\n", "p.ngc")
