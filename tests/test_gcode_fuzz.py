"""The G-code numeric grammar never raises anything but a located one-line error (issue 14, Deliver 6 and 7).

Every word (G M N T L P X F ...) and every expression may hold numbers that overflow a double, give NaN or
infinity, or are written with digits that are not ASCII. Each must end in a :class:`SourceError` naming
``file:line`` and the cause — the same one on the bulk path (:mod:`jaxcnc.gcode.fastpath`) as on the line-by-line
interpreter — and never a traceback, a NumPy warning or a NaN taken for true. The command line turns it into
exit status 2 and exactly one line on standard error.
"""

from __future__ import annotations

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxcnc.errors import SourceError
from jaxcnc.gcode import parse_gcode
from jaxcnc.program import PROGRAM_COLUMNS
from tests.conftest import machine_text
from tests.test_gcode_fastpath import assert_paths_agree

BIG = "1" * 400  # float() of it is inf
HUGE = "9" * 308  # finite, 1e308: times 25.4 (G20) it overflows
OVER = "[10**300*10**300]"  # an expression that overflows

#: (program, line, what the error says): each was a traceback, a NumPy warning or an accepted NaN/inf before.
CASES = [
    (f"G{BIG} X1\n", 1, "overflows"),
    (f"M{BIG}\n", 1, "overflows"),
    (f"G1 X1 F100\nN{BIG} G1 X2\n", 2, "overflows"),
    (f"T{BIG} M6\n", 1, "overflows"),
    (f"G10 L{BIG} P1\n", 1, "overflows"),
    (f"G4 P{BIG}\n", 1, "overflows"),
    (f"G1 X{BIG} F100\n", 1, "overflows"),
    (f"G1 X1 F{BIG}\n", 1, "overflows"),
    (f"G2 X1 Y0 I{BIG} F100\n", 1, "overflows"),
    (f"G2 X0 Y0 I1 F100 P{HUGE}\n", 1, "turns"),
    (f"G20 G1 X{HUGE} F100\n", 1, "beyond"),
    ("G20\n" + "G1 X1 F100\n" * 5 + f"G1 X{HUGE}\n", 7, "beyond"),
    (f"G2 X1 Y0 R{HUGE} F100\n", 1, "beyond"),
    (f"G1 X1 F100\nG2 X0 Y0 I1{'0' * 305} J0\n", 2, "beyond"),
    ("G1 X1 F100\n" * 5 + f"G20 G1 X2 F{HUGE}\n", 6, "feed"),
    (f"G1 X{OVER} F100\n", 1, "overflows"),
    (f"G1 X[FIX{OVER}] F100\n", 1, "overflows"),
    (f"G1 X[FUP{OVER}] F100\n", 1, "overflows"),
    (f"G1 X[ROUND{OVER}] F100\n", 1, "overflows"),
    (f"G1 X[COS{OVER}] F100\n", 1, "overflows"),
    (f"G1 X[ATAN{OVER}/[1]] F100\n", 1, "overflows"),
    ("G1 X[[10**300] MOD [10**-300]] F100\n", 1, "MOD"),
    ("G1 X[EXP[708]*EXP[708]] F100\n", 1, "overflows"),
    (f"G1 X[{BIG}] F100\n", 1, "overflows"),
    (f"#1={OVER}\nG1 X#1 F100\n", 1, "overflows"),
    (f"o1 repeat [{OVER}-{OVER}]\nG1 X1 F100\no1 endrepeat\n", 1, "overflows"),
    (f"o1 if [{OVER}-{OVER}]\nG1 X1 F100\no1 endif\n", 1, "overflows"),
    ("G1 X\u0661\u0660 F100\n", 1, "ASCII"),  # Arabic-Indic ١٠
    ("G1 X1 F100\n" * 5 + "G1 X\u0661\u0660\n", 6, "ASCII"),
    ("G1 X\uff11 F100\n", 1, "ASCII"),  # full-width １
    ("G1 X1\u0660 F100\n", 1, "ASCII"),
    ("G1 X[\u0661+1] F100\n", 1, "ASCII"),
    ("N\u0661 G1 X1 F100\n", 1, "ASCII"),
    ("%\nG1 X10 F100\n", 1, "%"),
    ("%\nG1 X10 F100\nG1 X20\nG1 X30\nG1 X40\nG1 X50\n", 1, "%"),
    ("%\n#1=2\nG1 X#1 F100\n", 1, "%"),
    ("G1 X10 F0." + "0" * 300 + "1\n", 1, "feed"),
    ("G1 X1 F100\n" * 5 + "G1 X10 F0." + "0" * 300 + "1\n", 6, "feed"),
]


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize(("text", "line", "needle"), CASES, ids=range(len(CASES)))
def test_numeric_grammar_is_refused_with_a_located_error(text, line, needle):
    """Each input: a SourceError at the line, naming the cause; the bulk path says the same (no warning)."""
    with pytest.raises(SourceError) as info:
        parse_gcode(text, "f.ngc", max_lines=1000)
    e = info.value
    assert e.file == "f.ngc" and e.line == line, str(e)
    assert needle in e.reason, str(e)
    assert "\n" not in str(e)
    assert_paths_agree(text)


@pytest.mark.filterwarnings("error")
def test_a_program_that_ends_with_m2_needs_no_closing_percent():
    """As in LinuxCNC: the text after M2 is not read, so a program opened by '%' may end with M2 instead."""
    for text in ("%\nG1 X10 F100\nM2\n", "%\nG1 X10 F100\n%\n", "%\n#1=2\nG1 X#1 F100\nM2\n"):
        assert len(parse_gcode(text, "f.ngc")) >= 1


def test_large_but_finite_numbers_still_parse():
    """Refusing overflow does not refuse big numbers: N, S and expressions with large finite values."""
    p = parse_gcode(f"N{'9' * 40} G1 X[10**200 / 10**199] F100 S{'9' * 20}\n", "f.ngc")
    assert p.end[0, 0] == pytest.approx(10.0) and math.isfinite(p.power[0])


# ---- the fuzzer ------------------------------------------------------------------------------------------------

_DIGITS = st.sampled_from(["0", "1", "5", "9", "\u0661", "\u06f5", "\uff11", "\u0969", "\U0001d7d9"])
_ODD_NUMBER = st.one_of(
    st.integers(1, 420).map(lambda n: "9" * n),
    st.integers(1, 330).map(lambda n: "0." + "0" * n + "1"),
    st.lists(_DIGITS, min_size=1, max_size=4).map("".join),
    st.tuples(st.integers(0, 99), st.lists(_DIGITS, max_size=3).map("".join)).map(lambda t: f"{t[0]}.{t[1]}"),
)
_PLAIN_NUMBER = st.one_of(st.integers(1, 200).map(str), st.sampled_from(["0.5", "1.25", "10", "3", "2.0"]))
#: Mostly plain numbers (so that many programs are valid), now and then an odd one.
_NUMBER = st.one_of(_PLAIN_NUMBER, _PLAIN_NUMBER, _PLAIN_NUMBER, _ODD_NUMBER)
_ATOM = st.one_of(_NUMBER, st.sampled_from(["10**300", "10**-300", "[0-1]", "#1", "#<_g>", "2**10", "[1/3]"]))


@st.composite
def _expression(draw, depth: int = 0) -> str:
    if depth >= 3 or draw(st.integers(0, 2)) == 0:
        return draw(_ATOM)
    kind = draw(st.integers(0, 3))
    if kind == 0:
        fn = draw(st.sampled_from(["FIX", "FUP", "ROUND", "ABS", "SQRT", "EXP", "LN", "COS", "SIN", "TAN", "ACOS"]))
        return f"{fn}[{draw(_expression(depth + 1))}]"
    if kind == 1:
        return f"ATAN[{draw(_expression(depth + 1))}]/[{draw(_expression(depth + 1))}]"
    op = draw(st.sampled_from(["+", "-", "*", "/", "**", "MOD", "EQ", "LT", "AND", "XOR"]))
    return f"[{draw(_expression(depth + 1))} {op} {draw(_expression(depth + 1))}]"


@st.composite
def _numeric_programs(draw) -> str:
    lines = [draw(st.sampled_from(["", "", "G20", "G91", "#1=1", "#<_g>=2", "%"]))]
    for _ in range(draw(st.integers(1, 5))):
        value = draw(_NUMBER) if draw(st.booleans()) else f"[{draw(_expression())}]"
        form = draw(st.integers(0, 6))
        if form == 0:
            lines.append(f"G1 {draw(st.sampled_from(list('XYZFSN')))}{value} F100")
        elif form == 1:
            lines.append(f"G2 X1 Y0 {draw(st.sampled_from(['I', 'J', 'R', 'P']))}{value} F100")
        elif form == 2:
            lines.append(f"G4 P{value}")
        elif form == 3:
            lines.append(f"o1 if [{draw(_expression())}]\nG1 X2 F100\no1 endif")
        elif form == 4:
            lines.append(f"o2 repeat [{draw(_expression())}]\nG1 X3 F100\no2 endrepeat")
        elif form == 5:
            lines.append(f"#1={draw(_expression())}\nG1 X#1 F100")
        else:
            lines.append(f"{draw(st.sampled_from(list('GMNTLPXYZIJKRFSQ')))}{value}")
    return "\n".join(lines) + "\n"


FIGURES = {"run": 0, "refused": 0, "accepted": 0}


def check_outcome(text: str, figures: dict = FIGURES, **kw) -> None:
    """``text`` (as ``f.ngc``, ``parse_gcode`` options ``kw``) ends in a located one-line error or a Program whose
    values are finite; counted in ``figures`` (run, refused, accepted)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            p = parse_gcode(text, "f.ngc", max_lines=2000, **kw)
        except SourceError as e:
            assert e.file == "f.ngc" and 1 <= e.line <= text.count("\n") + 1, str(e)
            assert "\n" not in str(e) and e.reason
            figures["refused"] += 1
        else:
            for k in PROGRAM_COLUMNS:
                col = getattr(p, k)
                if col.dtype.kind == "f" and k not in ("feed", "center", "blend_tol"):
                    assert np.all(np.isfinite(col)), (k, col)
            assert not np.any(np.isinf(p.feed)) and np.all(np.isnan(p.feed) | (p.feed > 0))
            assert not np.any(np.isnan(p.blend_tol))
            figures["accepted"] += 1
    figures["run"] += 1


@settings(max_examples=1000, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(_numeric_programs())
def _fuzz(text):
    check_outcome(text)
    assert_paths_agree(text)


def test_fuzz_numeric_grammar():
    """Huge, NaN-, inf-giving and non-ASCII numbers in words and expressions: a located error or a finite Program,
    the same on both paths. Prints the figures (cases run, refused, accepted)."""
    f = run_counted(_fuzz, FIGURES, "numeric grammar fuzz")
    assert f["run"] >= 900
    # the generator must exercise both outcomes, else the property says little
    assert f["refused"] >= 100 and f["accepted"] >= 50, f


def run_counted(fuzz, figures: dict, name: str) -> dict:
    """Run the hypothesis test ``fuzz`` with ``figures`` zeroed; print and return them."""
    for k in figures:
        figures[k] = 0
    fuzz()
    print(f"\n{name}: {figures['run']} cases, {figures['refused']} refused, {figures['accepted']} accepted")
    return figures


# ---- the command line -------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("program", "where"),
    [
        (f"G1 X10 F600\nG{BIG} X1\n", ":2:"),
        (f"G1 X{OVER} F600\n", ":1:"),
        ("G1 X10 F600\nG1 X\u0661\u0660\n", ":2:"),
        ("%\nG1 X10 F600\n", ":1"),
        (f"o1 if [{OVER}-{OVER}]\nG1 X1 F100\no1 endif\n", ":1:"),
        (f"G1 X10 F600\nG2 X0 Y0 I1 P{HUGE}\n", ":2:"),
    ],
)
def test_plan_exits_2_with_one_line(tmp_path, program, where):
    prog = tmp_path / "p.ngc"
    prog.write_text(program, encoding="utf-8")
    m = tmp_path / "m.toml"
    m.write_text(machine_text())
    out = tmp_path / "o.ticks"
    r = subprocess.run(
        [sys.executable, "-W", "default", "-m", "jaxcnc", "plan", str(prog), "-m", str(m), "-o", str(out), "-q"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"jaxcnc: error: {prog}{where}"), r.stderr
    assert not out.exists()
