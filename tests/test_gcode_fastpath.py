"""The bulk path for plain blocks (jaxcnc/gcode/fastpath.py) against the line-by-line interpreter.

Both paths must give the same Program bit for bit (every column, dtype and byte) and the same errors
(``file:line:column: reason``), whatever mix of plain and complex lines a program holds.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxcnc.errors import SourceError
from jaxcnc.gcode import fastpath, load_gcode, parse_gcode
from jaxcnc.gcode.fastpath import plain_table
from jaxcnc.gcode.interpreter import _Interpreter, _needs_preprocessor
from jaxcnc.gcode.lexer import MAX_COORDINATE
from jaxcnc.program import PROGRAM_COLUMNS, Kind
from tests.conftest import corpus_file


def outcome(text: str, fast: bool, min_run: int = 1, **kw):
    """The Program, or the error's text, from one path."""
    saved = fastpath.MIN_RUN
    fastpath.MIN_RUN = min_run
    try:
        return parse_gcode(text, "f.ngc", fast=fast, max_lines=20_000, **kw)
    except SourceError as exc:
        return f"SourceError: {exc}"
    finally:
        fastpath.MIN_RUN = saved


def assert_identical(a, b) -> None:
    """Two outcomes are the same error, or Programs equal in every column, bit for bit."""
    if isinstance(a, str) or isinstance(b, str):
        assert a == b
        return
    for k in PROGRAM_COLUMNS:
        x, y = getattr(a, k), getattr(b, k)
        assert x.dtype == y.dtype and x.shape == y.shape, k
        assert x.tobytes() == y.tobytes(), f"column {k} differs: {x} vs {y}"
    assert (a.curves is None) == (b.curves is None)
    if a.curves is not None:
        for f in ("degree", "cp", "points", "weights", "kn", "knots"):
            assert getattr(a.curves, f).tobytes() == getattr(b.curves, f).tobytes()


def assert_paths_agree(text: str, **kw) -> None:
    """Both paths give the same outcome; for a refused program also on the lines before the error."""
    slow = outcome(text, fast=False, **kw)
    for min_run in (1, 3):
        assert_identical(outcome(text, fast=True, min_run=min_run, **kw), slow)
    if isinstance(slow, str) and slow.startswith("SourceError: f.ngc:"):
        line = int(slow.split(":")[2])
        if line > 1:
            head = "\n".join(text.splitlines()[: line - 1]) + "\n"
            assert_identical(outcome(head, fast=True, **kw), outcome(head, fast=False, **kw))


# ---- which lines are plain ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("line", "plain"),
    [
        ("G1 X1 Y2 F600", True),
        ("g01x1.y-.5z+3", True),
        ("G0", True),
        ("N10 G2 X1 Y0 I.5 J0 S40", True),
        ("X 1 0 (comment) Y2 ; rest", True),
        ("X1(c)5", True),  # X15, as the lexer reads it
        ("G1.0 X1", True),
        ("", True),
        ("(only a comment)", True),
        ("G17 G1 X1", False),  # another G word
        ("G1.5 X1", False),
        ("G1 X1 X2", False),  # a letter twice
        ("G0 G1 X1", False),
        ("N-1 G1 X1", False),
        ("N1.5 X1", False),
        ("F-1", False),
        ("S-2", False),
        ("G1 X1 T1", False),
        ("M3", False),
        ("G1 X1.2.3", False),
        ("G1 X", False),
        ("G1 X#1", False),
        ("G1 X[1]", False),
        ("/G1 X1", False),
        ("%", False),
        ("G1 X1 (open", False),
        ("G1 X1 E5", False),
        ("G1 X1 @", False),
        ("G1 X" + "9" * 400, False),  # overflows to infinity
        ("G1 X1 \u0131", False),  # dotless i: upper() would make it an I
    ],
)
def test_plain_lines(line, plain):
    t = plain_table(["G1 X0", line, "G1 X0"])
    assert list(t.plain) == [True, plain, True]
    assert list(t.complex_index) == ([3] if plain else [1, 3])


def test_plain_table_values_and_dialect_comments():
    t = plain_table(["g1 x 1 0 (c) y-.5 ; z9", "F600 S40 N7"])
    row = dict(zip(fastpath.PLAIN_LETTERS, t.values[0], strict=True))
    assert row["G"] == 1 and row["X"] == 10 and row["Y"] == -0.5 and math.isnan(row["Z"])
    assert list(t.present[1]) == [c in "FSN" for c in fastpath.PLAIN_LETTERS]
    # a dialect without ( ) comments leaves '(' in the line; one without ';' leaves ';'
    assert not plain_table(["X1 (c)"], paren_comments=False).plain[0]
    assert not plain_table(["X1 ; c"], semicolon_comments=False).plain[0]


_DIGITS = st.text("0123456789", max_size=20)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(st.sampled_from(["", "+", "-"]), _DIGITS, st.sampled_from(["", "."]), _DIGITS, st.booleans()),
        min_size=1,
        max_size=12,
    )
)
def test_numbers_read_as_float_reads_them(parts):
    """Each word's number is float(text), bit for bit: signs, leading zeros, '1.', '.5', -0, 15 digits
    and more (the exact integer route and the float() route for long numbers)."""
    texts = []
    for sign, whole, point, frac, long in parts:
        body = whole + point + (frac if point else "")
        if not any(c.isdigit() for c in body):
            body = "0" + body
        texts.append(sign + ("9" * 30 + body if long and len(texts) % 3 == 0 else body))
    # X for negative numbers (F may not be negative), F for the others (X may not be beyond ±1e9)
    letters = ["X" if t.startswith("-") else "F" for t in texts]
    table = plain_table([f"{a}{t}" for a, t in zip(letters, texts, strict=True)])
    for k, t in enumerate(texts):
        v = float(t)
        column = fastpath.PLAIN_LETTERS.index(letters[k])
        if math.isfinite(v) and (letters[k] == "F" or abs(v) <= MAX_COORDINATE):
            assert table.plain[k]
            assert np.float64(table.values[k, column]).tobytes() == np.float64(v).tobytes(), t
        else:
            assert not table.plain[k]


@settings(max_examples=500, deadline=None)
@given(st.text(st.sampled_from(["\n", " ", "\t", "/", "o", "O", "G", "1", "\r", "\x0b", "\x0c", "\xa0", "x"])))
def test_preprocessor_detection_is_the_multiline_expression(text):
    """The quick search for O-words finds what ``^\\s*/?\\s*[oO]`` (MULTILINE) finds."""
    old = re.compile(r"[#\[\]]|^\s*/?\s*[oO]", re.MULTILINE)
    assert _needs_preprocessor(text) == (old.search(text) is not None)
    assert _needs_preprocessor(text + "#") and _needs_preprocessor("[" + text)


def test_plain_blocks_never_reach_the_line_by_line_interpreter(monkeypatch):
    text = "G21 G90 F600\n" + "".join(f"G1 X{k} Y{k % 7}\nG2 X{k + 1} Y{k % 7} I0.5 J0\n" for k in range(50))
    reference = parse_gcode(text, fast=False)
    calls = []
    original = _Interpreter.block
    monkeypatch.setattr(_Interpreter, "block", lambda self, b: calls.append(b.line) or original(self, b))
    p = parse_gcode(text)
    assert calls == [1]  # only the header G21 G90: the 100 moves ran in bulk
    assert_identical(p, reference)
    assert int((p.kind == Kind.ARC).sum()) == 50


# ---- errors: the same located message from a plain line inside a run ----------------------------


@pytest.mark.parametrize(
    ("bad", "needle"),
    [
        ("G2 X20 Y0 I5.1 J0", "radius to end"),
        ("G2 X20 Y0 R2", "smaller than half the chord"),
        ("G2 X20 Y0 R0", "R is zero"),
        ("G2 X10 Y0 R5", "a full circle needs I/J"),
        ("G2 X10 Y0 I0 J0", "radius zero"),
        ("G2 X20 Y0", "needs I/J"),
        ("G2 X20 Y0 I5 R5", "both R and I/J"),
        ("G2 X20 Y0 I5 K1", "K has no meaning"),
        ("G2 F100", "arc needs I/J (centre) or R"),
        ("G2 R5", "a full circle needs I/J"),
        ("G1 X20 I5", "no meaning"),
        ("G0 X20 R5", "no meaning"),
        ("I5", "no meaning"),
        ("F0 X20", "feed rate is zero"),
        ("G1 X1 X2", "twice"),
        ("G1 X1.2.3", "malformed number"),
        ("N-1 G1 X1", "non-negative integer"),
        ("G1 X20 F-5", "negative feed"),
        ("S-1", "negative power"),
    ],
)
def test_errors_in_runs_are_the_interpreters(bad, needle):
    run = "".join(f"G1 X{k} Y0\n" for k in range(10))
    text = f"F600\n{run}G1 X10 Y0\n{bad}\n{run}"
    slow = outcome(text, fast=False)
    assert isinstance(slow, str) and needle in slow and slow.startswith("SourceError: f.ngc:13:")
    for min_run in (1, 4):
        assert outcome(text, fast=True, min_run=min_run) == slow


def test_axis_words_before_any_motion_mode():
    assert_paths_agree("X1\nX2\nX3\nX4\n")
    assert outcome("X1\nX2\nX3\nX4\n", fast=True).startswith("SourceError: f.ngc:1:1: axis words")


def test_overflowing_coordinates_go_line_by_line():
    big = "1" + "0" * 307  # 1e307: finite, but 25.4 times it is not
    assert_paths_agree(f"G20 G1 F60\nX{big}\nX1\nX2\nX3\nX4\n")
    assert_paths_agree(f"G1 F60\nG91\nX{big}\nX{big}\nX{big}\nX1\nG2 X1 Y1 I1\n")


def test_modal_state_enters_and_leaves_runs():
    """Each modal setting changed by a complex line is seen by the next run, and a run's state by the
    next complex line."""
    text = """G21 G90 G17 F600 S10
G1 X1 Y1
G1 X2
G91 G1 X1 Y1
X1
G20 X1 Y1
F30 X1
G90 G1 X1 Y2 S20
G18 G2 X2 Z1 I0.5 K0.5
G3 X1 Z0 R0.8
G19 G2 Y3 Z1 J0.5 K0.5
G17 G90.1 G2 X1 Y4 I1 J3
G2 X1 Y2 I1 J3 Z-1
G91.1 G92 X0 Y0
G1 X1 Y1
G92.1
G1 X1 Y1
M3
G1 X5
M5 G4 P1
G1 X6
G64 P0.01
G1 X7
G61.1
G1 X8
G1 X9
G61
G1 X10
G53 G0 X1
G1 X2
G28
G0 X1
T2 M6
G1 X2
G5 X3 Y3 I1 J0 P-1 Q0
G1 X4
M2
"""
    assert_paths_agree(text, start=(1.0, -2.0, 0.5), home=(0.0, 0.0, 5.0))


@pytest.mark.parametrize(
    "text",
    [
        "G2 Y0 J5 F60\nG2 Y0 J-5\nG3 X0 Y0 I0 J2\nG91 G2 X0 Y0 J1\nG1 X-0 Y-0 Z-0\n",
        "G90.1 G2 Y0 J5 F60\nG2 Y0 I0 J1\nG1 X-0\nG91 G1 X-0 Y0\nG0 Z-0\n",
        "G18 G2 Z0 I2 F60\nG19 G3 Y0 K-1\nG17 G2 X-0 Y-0 R1\n",
    ],
)
def test_signed_zeros(text):
    """A start point of -0.0 (and -0 words) keep their sign exactly where the interpreter keeps it."""
    assert_paths_agree(text, start=(-0.0, -0.0, -0.0))
    assert_paths_agree(text)


@pytest.mark.parametrize(
    "name",
    ["LHchips4", "51MeanderAve", "plasmatest", "arcspiral", "butterfly-xy", "Curva_Farfalla", "Circle_Diamond"],
)
def test_corpus_programs_identical(name):
    f = corpus_file(name)
    text = f.read_text()
    assert_paths_agree(text)

    def loaded(fast: bool):  # load_gcode goes through the bulk path too
        try:
            return load_gcode(f, fast=fast)
        except SourceError as exc:
            return f"SourceError: {exc}"

    assert_identical(loaded(True), loaded(False))


# ---- property: random programs mixing plain and complex lines ------------------------------------

_PLANES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}
_COMPLEX = [
    "G90",
    "G91",
    "G20",
    "G21",
    "G17",
    "G18",
    "G19",
    "G90.1",
    "G91.1",
    "G92 X1 Y-2",
    "G92.1",
    "G92.2",
    "G92.3",
    "M3 S50",
    "M4",
    "M5",
    "G4 P0.25",
    "G64 P0.02 Q0.01",
    "G64",
    "G61",
    "G61.1",
    "T3 M6",
    "M0",
    "M1",
    "M8",
    "M9",
    "G28",
    "G53 G0 X1 Y1",
    "G40 G49 G94",
    "G54",
    "G5 X1 Y1 I1 J0 P-1 Q0",
    "G5.1 X2 Y0 I1 J1",
    "/G1 X5 Y5",
    "#1 = 2.5",
    "G1 X[1 + #1] F[600]",
    "M2",
]
_BROKEN = [
    "G1 X1.2.3",
    "G1 X1 X2",
    "G2 X1",
    "G1 X1 I2",
    "N-1 G1 X1",
    "G4",
    "G1 X1 (open",
    "F-5",
    "F0",
    "Q1",
    "G2 F100",
    "G17 G2 X1 Y1 K1",
    "G0 G1 X1",
    "I1",
]


def _rare(n: int) -> st.SearchStrategy[bool]:
    """True about once in ``n`` draws (hypothesis favours small integers, so not integers(0, n) == 0)."""
    return st.sampled_from([False] * (n - 1) + [True])


def _num(draw, lo: float = -30.0, hi: float = 30.0) -> str:
    v = draw(st.one_of(st.integers(int(lo), int(hi)).map(float), st.floats(lo, hi, allow_nan=False)))
    text = f"{v:.4f}".rstrip("0")
    return draw(st.sampled_from([text, text.rstrip("."), text if text.startswith("-") else "+" + text]))


def _decorate(draw, words: list[str], paren: bool, semicolon: bool) -> str:
    """Write words as posts and people do: case, blanks, blanks and comments inside words, N, comments."""
    out = []
    for w in words:
        if draw(st.integers(0, 9)) == 0:  # a blank or a comment inside the word: the same word
            cut = draw(st.integers(1, len(w)))
            w = w[:cut] + draw(st.sampled_from([" ", "\t"] + (["(c)"] if paren else []))) + w[cut:]
        out.append(w)
    sep = draw(st.sampled_from([" ", "", "  ", "\t"]))
    line = sep.join(out)
    if draw(st.booleans()):
        line = line.lower()
    if draw(st.integers(0, 4)) == 0:
        line = f"N{draw(st.integers(0, 99999))} {line}"
    if paren and draw(st.integers(0, 5)) == 0:
        line = f"{line} (note)"
    if semicolon and draw(st.integers(0, 5)) == 0:
        line = f"{line} ; end (of line"
    return line


def _arc_words(draw, pos: list, absolute: bool, plane: int, arc_abs: bool) -> tuple[list[str], dict[int, float]]:
    """Words of an arc that lies on its circle (within the rounding of 4 decimals) where the generator
    knows the start point or the coordinates are incremental; its axis values (program units)."""
    a0, a1, a2 = _PLANES[plane]
    ci, cj = float(_num(draw, -10, 10)), float(_num(draw, -10, 10))
    if math.hypot(ci, cj) < 0.5:
        ci = 2.5
    th = draw(st.floats(-6.3, 6.3))
    ei = ci - ci * math.cos(th) + cj * math.sin(th)  # the start point turned by th round the centre
    ej = cj - ci * math.sin(th) - cj * math.cos(th)
    ei += draw(st.sampled_from([0.0] * 30 + [0.015] * 3 + [-0.05]))  # off the circle: within the tolerance, or not
    known = pos[a0] is not None and pos[a1] is not None
    if not absolute:
        e = (ei, ej)
    elif known:
        e = (pos[a0] + ei, pos[a1] + ej)
    else:
        e = (float(_num(draw)), float(_num(draw)))  # most likely refused: the radii differ
    if draw(_rare(10)):  # no end point: a full circle ("G2 I5")
        words = [f"{'IJK'[a0]}{ci:.4f}", f"{'IJK'[a1]}{cj:.4f}"]
        return (words if ci and cj else [words[0] if ci else words[1]]), {}
    moved = {a0: round(e[0], 4), a1: round(e[1], 4)}
    words = [f"{'XYZ'[a0]}{e[0]:.4f}", f"{'XYZ'[a1]}{e[1]:.4f}"]
    if draw(st.integers(0, 3)) == 0:  # a helix
        moved[a2] = float(_num(draw, -3, 3))
        words.append(f"{'XYZ'[a2]}{moved[a2]}")
    if abs(math.remainder(th, 2 * math.pi)) > 0.2 and draw(st.integers(0, 3)) == 0:
        r, half = math.hypot(ci, cj), math.hypot(ei, ej) / 2
        # the radius, the long way round, too short (refused), shorter than half the chord within the
        # tolerance (the centre on the chord) and beyond it (refused)
        r = draw(st.sampled_from([r, r, r, -r, -r, 0.3 * r, half - 0.01, half - 0.04]))
        words.append(f"R{r:.4f}")
    elif arc_abs and known:
        words += [f"{'IJK'[a0]}{pos[a0] + ci:.4f}", f"{'IJK'[a1]}{pos[a1] + cj:.4f}"]
    else:
        words += [f"{'IJK'[a0]}{ci:.4f}", f"{'IJK'[a1]}{cj:.4f}"]
    return words, moved


@st.composite
def _programs(draw) -> tuple[str, dict]:
    """A program of plain moves (lines, arcs on their circles, helices, feeds, powers, N words,
    comments, odd spellings) and complex lines, in any dialect, sometimes with a broken line."""
    dialect = draw(st.sampled_from(["linuxcnc", "linuxcnc", "siemens", "fanuc"]))
    paren, semicolon = dialect != "siemens", dialect != "fanuc"
    start = draw(st.sampled_from([(0.0, 0.0, 0.0), (1.5, -2.25, 3.0), (-0.0, 0.0, -0.0)]))
    pos: list[float | None] = list(start)  # program units; None where the generator lost track
    absolute, plane, arc_abs = True, 17, False
    motion = draw(st.sampled_from([None, 0, 10, 10, 10]))
    lines = [{None: "", 0: "G0", 10: "G1 F600"}[motion]]
    complex_lines = [c for c in _COMPLEX if dialect == "linuxcnc" or not c.startswith("G5")]
    for _ in range(draw(st.integers(1, 60))):
        what = draw(st.sampled_from(["move"] * 12 + ["complex"] * 3 + ["blank"]))
        if what == "blank":
            lines.append(draw(st.sampled_from(["", "   ", "(comment)" if paren else ";comment"])))
        elif what == "complex":
            line = draw(st.sampled_from(complex_lines))
            lines.append(line)
            absolute = {"G90": True, "G91": False}.get(line, absolute)
            plane = {"G17": 17, "G18": 18, "G19": 19}.get(line, plane)
            arc_abs = {"G90.1": True, "G91.1": False}.get(line, arc_abs)
            if line in ("G20", "G21", "G92.1", "G92.2", "G92.3", "G28") or "X" in line:
                pos = [None, None, None]
            if line == "G92 X1 Y-2":
                pos = [1.0, -2.0, pos[2]]
            if line.startswith(("G5", "/G1", "G1 X[")):
                motion = {"G5 ": 50, "G5.": 51, "G53": 0}.get(line[:3], 10)
        else:
            g = draw(st.sampled_from(["", "", "", "G0", "G1", "G2", "G3", "G00", "G01", "G02", "G03", "G1.0"]))
            if not g and motion not in (0, 10, 20, 30):
                g = "G1"
            if absolute and None in pos and not draw(_rare(30)):
                g = draw(st.sampled_from(["G0", "G1"]))  # a move to a known point: arcs can follow
            if g:
                motion = round(float(g[1:]) * 10)
            words = [g] if g else []
            if draw(st.integers(0, 3)) == 0:
                words.append(f"F{draw(st.sampled_from(['600', '1200.5', '30']))}")
            if draw(st.integers(0, 5)) == 0:
                words.append(f"S{draw(st.sampled_from(['0', '40', '100.5']))}")
            if motion in (20, 30) and not draw(_rare(200)):
                more, moved = _arc_words(draw, pos, absolute, plane, arc_abs)
                words += more
            else:
                moved = {}
                for axis in range(3):
                    if draw(st.integers(0, 2)) or (absolute and pos[axis] is None):
                        moved[axis] = float(_num(draw))
                        words.append(f"{'XYZ'[axis]}{moved[axis]}")
            for axis, v in moved.items():
                pos[axis] = v if absolute else (None if pos[axis] is None else pos[axis] + v)
            words = draw(st.permutations(words))
            lines.append(_decorate(draw, words, paren, semicolon) if words else "")
    for _ in range(draw(st.sampled_from([0, 0, 0, 0, 1, 2]))):
        lines.insert(draw(st.integers(0, len(lines))), draw(st.sampled_from(_BROKEN)))
    if draw(st.integers(0, 5)) == 0:
        lines.insert(draw(st.integers(0, len(lines))), "%")
    kw = {"dialect": dialect, "start": start, "block_delete": draw(st.booleans())}
    return "\n".join(lines) + draw(st.sampled_from(["\n", "", "\r\n"])), kw


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_programs())
def test_random_programs_both_paths_identical(program):
    text, kw = program
    assert_paths_agree(text, **kw)


_TEXT = st.sampled_from(
    list("GXYZIJKRFSNMTP0123456789.-+ \t()%;/#[]@eE\u0131")
    + ["\n"] * 6
    + ["G1 ", "G2 ", "G3 ", "G0 ", "X1.5", "Y-2", "I1", "J1", "R2", "F600", "S5", "N10", "G17", "G91", "M3", "(c)"]
)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_TEXT, max_size=120).map("".join))
def test_random_text_both_paths_identical(text):
    """Whatever the text, the bulk path classifies, reads and refuses it as the interpreter does."""
    assert_paths_agree(text)


@settings(max_examples=100, deadline=None)
@given(st.data())
def test_mutated_corpus_both_paths_identical(data):
    lines = corpus_file("plasmatest").read_text().splitlines()[:150]
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(lines) - 1))
        j = data.draw(st.integers(0, len(lines[i])))
        ch = data.draw(st.sampled_from(list("GXYIJRF.-0123456789 (;A") + [""]))
        cut = data.draw(st.integers(0, 1))
        lines[i] = lines[i][:j] + ch + lines[i][j + cut :]
    assert_paths_agree("\n".join(lines))


def test_random_programs_exercise_valid_runs():
    """The generator above yields mostly valid programs with arcs (else the property says little)."""
    seen = {"ok": 0, "arcs": 0}

    @settings(
        max_examples=200, deadline=None, database=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
    )
    @given(_programs())
    def count(program):
        text, kw = program
        p = outcome(text, fast=True, **kw)
        if not isinstance(p, str):
            seen["ok"] += 1
            seen["arcs"] += int((p.kind == Kind.ARC).sum())

    count()
    # a fair share valid (runs of 41-66 of 200 seen: the draws are not the same in every process), and arcs in
    # them: at least one per valid program on average (2.2 to 9.9 seen; a full CI run drew 53 and 117 arcs)
    assert seen["ok"] >= 30 and seen["arcs"] >= seen["ok"], seen


def test_bit_identity_is_checked_bytewise():
    """-0.0 and 0.0 compare equal but are different bytes: the comparison above tells them apart."""
    a = parse_gcode("G1 X0 F60\n")
    b = parse_gcode("G1 X0 F60\n", start=(-0.0, 0.0, 0.0))
    assert np.array_equal(a.start, b.start)
    with pytest.raises(AssertionError):
        assert_identical(a, b)
