"""The words of CAM posts (tool offsets, program numbers and names, Sinumerik edges) fuzzed in every dialect:
each program ends in a finite Program or a located one-line :class:`SourceError`, the same on the bulk path as on
the line-by-line interpreter (docs/gcode.md, "Words"; issue 13, Deliver 5)."""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.test_gcode_fastpath import assert_paths_agree
from tests.test_gcode_fuzz import check_outcome, run_counted

#: The machine file's tool table as :func:`parse_gcode` takes it: tool -> (z_mm, x_mm, y_mm).
TOOLS = {1: (2.0, 0.0, 0.0), 2: (5.5, 0.1, -0.2), 99999: (-1.0, 0.0, 0.0)}
DIALECTS = ("linuxcnc", "fanuc", "siemens")

_TOOL = st.sampled_from(["1", "1", "2", "2", "0", "99999", "02", "3", "100000", "-1", "1.5"])  # the last 3 refused
_VALUE = st.sampled_from(["0", "1", "-2.5", "15.", ".5", "1000", "-0", "100000", "3.25"])
#: Header lines each dialect's posts write (a '%' only opens a program), and the others' (mostly refused).
HEADERS = {
    "linuxcnc": ["(PART 7)", "G21 G90 G17 G40 G49 G80", "G64 P0.01", "G61", "G20"],
    "fanuc": ["O1001 (PART)", "O0001", "O12345678", "(PART 7)", "G21 G90 G17 G40 G49 G80"],
    "siemens": ["%_N_PART_MPF", "%_N_DRILL_SPF", ";$PATH=/_N_WKS_DIR/_N_PART_WPD", "G71", "G710", "G70", "G60"],
}


@st.composite
def _line(draw) -> str:
    t, v, w = draw(_TOOL), draw(_VALUE), draw(_VALUE)
    words = [
        f"T{t} M6",
        f"G43 Z{v} H{t}",
        f"G43 H{t}",
        "G43",
        f"G43.1 Z{v}",
        f"G43.2 H{t}",
        f"G43.2 Z{v}",
        "G49",
        f"T{t} D{draw(st.sampled_from(['0', '1', '2']))}",
        f"D{draw(st.sampled_from(['0', '1']))}",
        f"H{t}",
        draw(st.sampled_from(["G91", "G90", f"G92 Z{v}", f"G53 G0 Z{v}", "G28", "M3 S100", "M5", "M98 P10"])),
    ]
    moves = [
        f"G0 X{v} Y{w} Z{v}",
        f"G1 X{v} Y{w} F{draw(st.sampled_from(['100', '600.']))}",
        "G2 I0.5 J0 F100",  # a full circle from wherever the tool is
        f"Z{w}",
    ]
    return draw(st.sampled_from(moves)) if draw(st.booleans()) else draw(st.sampled_from(words))


@st.composite
def _post_programs(draw) -> tuple[str, str]:
    """A program and the dialect it is read in: mostly that dialect's header, sometimes another's."""
    dialect = draw(st.sampled_from(DIALECTS))
    headers = (
        st.sampled_from(HEADERS[dialect]) if draw(st.integers(0, 3)) else st.sampled_from(sum(HEADERS.values(), []))
    )
    lines = draw(st.lists(headers, max_size=2)) + ["G0 X0 Y0 Z0"] + draw(st.lists(_line(), min_size=1, max_size=8))
    opened = draw(st.booleans()) and dialect != "siemens"
    end = draw(st.sampled_from(["", "M2\n", "M30\n"])) if not opened else "%\n"
    return ("%\n" if opened else "") + "\n".join(lines) + "\n" + end, dialect


FIGURES = {"run": 0, "refused": 0, "accepted": 0}


@settings(max_examples=600, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(_post_programs())
def _fuzz(case):
    text, dialect = case
    check_outcome(text, FIGURES, dialect=dialect, tools=TOOLS)
    assert_paths_agree(text, dialect=dialect, tools=TOOLS)


def test_fuzz_post_words_in_every_dialect():
    """Tool offsets (G43 H / G43 / G43.1 / G43.2 / G49, H0, missing and malformed tools), program numbers and
    names, Sinumerik T D edges and header G codes, mixed with motion, G92, G53 and G28, in each dialect: a
    located error or a finite Program, the same on both paths. Prints the figures (cases, refused, accepted)."""
    f = run_counted(_fuzz, FIGURES, "post words fuzz")
    assert f["run"] >= 500
    # both outcomes must be exercised, else the property says little
    assert f["refused"] >= 100 and f["accepted"] >= 100, f
