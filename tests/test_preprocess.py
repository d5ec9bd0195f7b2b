"""The parametric preprocessor: expressions, parameters, O-word control flow, limits, round trips."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.errors import SourceError
from jaxcnc.gcode import parse_gcode
from jaxcnc.gcode.preprocess import expand_text, format_number
from tests.conftest import REPO


def xs(text: str) -> list[float]:
    """X values of the flattened program's G1 moves."""
    p = parse_gcode(text, "p.ngc", max_lines=100_000)
    return [float(v) for v in p.end[:, 0]]


@pytest.mark.parametrize(
    ("expr", "value"),
    [
        ("1 + 2 * 3", 7),
        ("[1 + 2] * 3", 9),
        ("2 ** 3 ** 2", 64),
        ("-2 ** 2", 4),
        ("7 MOD 3", 1),
        ("-7 MOD 3", 2),
        ("10 / 4", 2.5),
        ("1 + 2 EQ 3", 1),
        ("2 GT 3", 0),
        ("2 GE 2", 1),
        ("1 LT 2 AND 2 LT 1", 0),
        ("1 LT 2 OR 2 LT 1", 1),
        ("1 XOR 1", 0),
        ("SIN[30]", 0.5),
        ("COS[60]", 0.5),
        ("TAN[45]", 1),
        ("ASIN[1]", 90),
        ("ACOS[0]", 90),
        ("ATAN[1]/[1]", 45),
        ("ATAN[1]/[-1]", 135),
        ("SQRT[16]", 4),
        ("ABS[-3]", 3),
        ("FIX[-2.5]", -3),
        ("FUP[2.1]", 3),
        ("ROUND[2.5]", 3),
        ("ROUND[-2.5]", -3),
        ("EXP[0]", 1),
        ("LN[1]", 0),
        ("exists[#<nope>]", 0),
        ("2*[3+4]-1", 13),
    ],
)
def test_expressions(expr, value):
    assert xs(f"G1 X[{expr}] F60\n")[0] == pytest.approx(value, abs=1e-12)


def test_parameters_numbered_named_global_and_same_line_rule():
    text = "#1 = 5\n#<a> = 2\n#<_g> = 3\n#1 = 7 #2 = #1\nG1 X#2 F60\nG1 X[#<a> + #<_g>]\nG1 X-#1\nG1 X##3\n"
    # #2 reads the old #1 (5); #3 is 0 (unset numbered parameters read 0), so ##3 is #0 -> error
    with pytest.raises(SourceError, match="parameter number 0"):
        parse_gcode(text, "p.ngc")
    assert xs(text.replace("G1 X##3\n", "#3 = 1\nG1 X##3\n")) == [5, 5, -7, 7]


def test_subroutines_arguments_locals_and_return():
    text = """
o<f> sub
  #<t> = [#1 * 2]
  o10 if [#2 GT 0]
    o<f> return
  o10 endif
  G1 X[#<t> + #2] F60
o<f> endsub
#<t> = 100
o<f> call [3] [0]
o<f> call [3] [1]
o<f> call [4] [-1]
G1 X#<t>
"""
    assert xs(text) == [6, 7, 100]  # the subroutine's #<t> is its own; return leaves early


def test_recursion_factorial():
    text = """
o<fact> sub
  o1 if [#1 LE 1]
    #<_r> = 1
  o1 else
    o<fact> call [#1 - 1]
    #<_r> = [#<_r> * #1]
  o1 endif
o<fact> endsub
o<fact> call [6]
G1 X#<_r> F60
"""
    assert xs(text) == [720]


def test_if_elseif_else():
    template = "#1 = {}\no1 if [#1 LT 0]\nG1 X-1 F60\no1 elseif [#1 EQ 0]\nG1 X0.5 F60\no1 else\nG1 X1 F60\no1 endif\n"
    assert xs(template.format(-5)) == [-1]
    assert xs(template.format(0)) == [0.5]
    assert xs(template.format(3)) == [1]


def test_loops_break_continue():
    text = """
#1 = 0
o1 while [#1 LT 10]
  #1 = [#1 + 1]
  o1 if [#1 EQ 3]
    o1 continue
  o1 endif
  o2 if [#1 EQ 6]
    o1 break
  o2 endif
  G1 X#1 F60
o1 endwhile
#2 = 0
o3 do
  #2 = [#2 + 10]
  G1 X#2
o3 while [#2 LT 30]
o4 repeat [2]
  G1 X99
o4 endrepeat
o5 repeat [0]
  G1 X-99
o5 endrepeat
"""
    assert xs(text) == [1, 2, 4, 5, 10, 20, 30, 99, 99]


@pytest.mark.parametrize(
    ("text", "line", "needle"),
    [
        ("o1 while [1]\no1 endwhile\n", 1, "endless loop"),
        ("o<r> sub\no<r> call\no<r> endsub\no<r> call\n", 2, "runaway recursion"),
        ("o1 if [1]\nG1 X1 F60\n", 1, "never closed"),
        ("o1 endif\n", 1, "does not close"),
        ("o9 call\n", 1, "undefined subroutine"),
        ("G1 X#<nope> F60\n", 1, "#<nope> is not set"),
        ("G1 X[1/0] F60\n", 1, "division by zero"),
        ("G1 X[SQRT[-1]] F60\n", 1, "outside its domain"),
        ("G1 X[1 + ] F60\n", 1, "unexpected ']'"),
        ("G1 X[1 + F60\n", 1, "unknown function or operator 'F'"),
        ("G1 X[FOO[1]] F60\n", 1, "unknown function"),
        ("#1 5\n", 1, "must be assigned"),
        ("o1 bogus\n", 1, "needs a keyword"),
        ("\n\no1 else\n", 3, "outside an open"),
        ("o1 break\n", 1, "outside an O1 loop"),
        ("o1 return\n", 1, "outside a subroutine"),
    ],
)
def test_errors_are_located(text, line, needle):
    with pytest.raises(SourceError) as info:
        parse_gcode(text, "p.ngc", max_lines=10_000)
    assert info.value.file == "p.ngc" and info.value.line == line, str(info.value)
    assert needle in info.value.reason


def test_block_delete_switch():
    text = "G1 X1 F60\n/G1 X2\nG1 X3\n"
    assert [float(v) for v in parse_gcode(text, "p.ngc").end[:, 0]] == [1, 2, 3]
    assert [float(v) for v in parse_gcode(text, "p.ngc", block_delete=True).end[:, 0]] == [1, 3]


def _same_program(a, b):
    from jaxcnc.program import PROGRAM_COLUMNS

    for name in PROGRAM_COLUMNS:
        if name != "line":  # the flattened text has its own line numbers
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_example_expands_to_its_hand_written_equivalent():
    src = (REPO / "examples" / "engraving-grid.ngc").read_text()
    flat = (REPO / "examples" / "engraving-grid-flat.ngc").read_text()
    a = parse_gcode(src, "grid.ngc")
    _same_program(a, parse_gcode(flat, "flat.ngc"))
    _same_program(a, parse_gcode(expand_text(src, "grid.ngc"), "expanded.ngc"))
    assert len(a) == 12 * 6 + 2  # per square: G0, G4, four G1 (M3/M5 are states); then G0 and M30


_VALUE = st.one_of(
    st.floats(-500, 500, allow_nan=False).map(lambda v: format_number(round(v, 4))),
    st.tuples(st.floats(-100, 100), st.floats(-100, 100), st.sampled_from(["+", "-", "*"])).map(
        lambda t: f"[{format_number(round(t[0], 3))} {t[2]} {format_number(round(t[1], 3))}]"
    ),
    st.floats(-180, 180).map(lambda a: f"[10 * COS[{format_number(round(a, 3))}]]"),
)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["G0", "G1"]), _VALUE, _VALUE), min_size=1, max_size=15), st.booleans())
def test_generated_programs_round_trip_through_expand(moves, with_sub):
    body = [f"{g} X{x} Y{y}" for g, x, y in moves]
    if with_sub:
        text = "F600\no<m> sub\n" + "\n".join(body) + "\no<m> endsub\no<m> call\n"
    else:
        text = "F600\n#<_k> = 1\n" + "\n".join(b.replace(" X", " X[#<_k> * ").replace(" Y", "] Y") for b in body) + "\n"
    original = parse_gcode(text, "gen.ngc")
    flat = expand_text(text, "gen.ngc")
    assert "#" not in flat and "[" not in flat and "o<" not in flat.lower()
    _same_program(original, parse_gcode(flat, "flat.ngc"))


def test_format_number_is_exact_and_plain():
    for v in (0.1, 1e-20, 123456789.123, -0.0, 1 / 3, math.pi * 1e10):
        s = format_number(v)
        assert "e" not in s.lower() and float(s) == v


def test_deeply_nested_expression_is_a_clean_error():
    with pytest.raises(SourceError, match="nested too deeply"):
        parse_gcode("G1 X" + "[" * 3000 + "1" + "]" * 3000 + " F60\n", "p.ngc")
