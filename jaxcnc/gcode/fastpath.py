"""The bulk fast path: plain motion blocks tokenised and interpreted with NumPy, a run at a time.

A *plain* block is one whose words are all among

    G0 G1 G2 G3   X Y Z   I J K R   F   S   N

with literal numbers (any spelling the lexer reads: ``G01``, ``g1``, ``G1.0``, ``X-.5``, ``x 1 0``), spaces
and tabs anywhere, and the comments the dialect has (``( ... )`` closed on its line, ``;`` to the end of
the line). A blank or comment-only line is plain too (it holds no block). Every other line — any other
word, parameters, expressions, O-words, block delete, ``%``, anything malformed, a letter given twice, a
negative F or S, an N that is not a non-negative integer, a number that overflows — is *complex* and goes
through the line-by-line interpreter, which stays the reference implementation.

:func:`plain_table` reads the whole program at once: comments and blanks removed with one regular
expression pass each, the plain lines recognised by one more, the digits of every number read as integers
in one NumPy call and divided by an exact power of ten (bit for bit ``float()`` of the text), each word put
in a ``(blocks, 11)`` table of values and one of presence. :func:`interpret_run` then
executes a run of consecutive plain blocks from the modal state the interpreter has at its start: motion
mode, feed and power forward-filled, positions forward-filled per axis (absolute) or summed in sequence
(incremental), arc centres from I/J/K or R with LinuxCNC's radius tolerance and centre correction, full
circles and helices — every value computed with the same floating-point operations, in the same order,
as :class:`~jaxcnc.gcode.interpreter._Interpreter` does, so the rows are bit for bit the same. A run in
which some block would raise an error (or reach a non-finite number) is executed only up to that block;
the interpreter then runs the block itself and raises the located error it always raised.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from jaxcnc.gcode.lexer import MAX_COORDINATE
from jaxcnc.program import MIN_FEED_MM_S, Kind

#: The letters a plain block may hold, in the column order of :attr:`PlainTable.values`.
PLAIN_LETTERS = "GXYZIJKRFSN"
_G, _X, _Y, _Z, _I, _J, _K, _R, _F, _S, _N = range(len(PLAIN_LETTERS))
_MODAL = [_G, _F, _S]  # the modal words of a plain block
_THREE = np.arange(3)
_NAN3 = np.full(3, np.nan)
#: Runs of fewer plain blocks than this are left to the line-by-line interpreter (the vectorised
#: interpretation of a run has a fixed cost of some tens of microseconds).
MIN_RUN = 4

_WORD = r"[GXYZIJKRFSN][+-]?(?:\d+\.?\d*|\.\d+)"  # the lexer's number syntax
_PLAIN_LINE = re.compile(rf"^(?:{_WORD})*$", re.MULTILINE)
_COMMENTS = {
    (True, True): re.compile(r"\([^)\n]*\)|;[^\n]*"),
    (True, False): re.compile(r"\([^)\n]*\)"),
    (False, True): re.compile(r";[^\n]*"),
    (False, False): None,
}
_NON_ASCII = re.compile(r"[^\x00-\x7f]")
_COLUMN = np.full(256, -1, dtype=np.int64)
for _k, _c in enumerate(PLAIN_LETTERS):
    _COLUMN[ord(_c)] = _k
_LETTERS_TO_SPACE = bytes(32 if (65 <= c <= 90 or c == 10) else c for c in range(256))
#: 10**k as exact doubles (float() of the decimal text is exact for these).
_POW10 = np.array([float(f"1e{k}") for k in range(16)])


@dataclass(frozen=True)
class PlainTable:
    """The words of every plain block of a program (rows: blocks; columns: :data:`PLAIN_LETTERS`).

    Attributes:
        plain: ``(n,)`` bool, the block is plain.
        values: ``(n, 11)`` float64, each word's number (NaN where the block lacks the letter).
        present: ``(n, 11)`` bool, the block has the letter.
        complex_index: sorted indices of the blocks that are not plain, then ``n``.
        axes, ijk, words: ``(n,)`` bool, the block has X/Y/Z, I/J/K, any word.
    """

    plain: np.ndarray
    values: np.ndarray
    present: np.ndarray
    complex_index: np.ndarray
    axes: np.ndarray
    ijk: np.ndarray
    words: np.ndarray

    def run_end(self, i: int) -> int:
        """The first block at or after ``i`` that is not plain (``n`` when none is)."""
        return int(self.complex_index[np.searchsorted(self.complex_index, i)])


def plain_table(texts: list[str], paren_comments: bool = True, semicolon_comments: bool = True) -> PlainTable:
    """Recognise and tokenise the plain blocks among ``texts`` (one block per entry, no line breaks).

    ``paren_comments`` / ``semicolon_comments``: the comment styles of the dialect; a comment style it
    lacks leaves its character in the line, which then is not plain.
    """
    n = len(texts)
    body = "\n".join(texts)
    comments = _COMMENTS[(paren_comments, semicolon_comments)]
    if comments is not None and ("(" in body or ";" in body):
        body = comments.sub("", body)  # left to right, as the lexer reads them
    body = body.replace(" ", "").replace("\t", "")  # the only blanks a line can hold
    if not body.isascii():  # upper() could turn a non-ASCII letter into an ASCII one
        body = _NON_ASCII.sub("#", body)
    up = body.upper()
    # What the plain lines leave behind is the text of the other lines: those are complex.
    rest = np.frombuffer(_PLAIN_LINE.sub("", up).encode("ascii"), dtype=np.uint8)
    newline = rest == 10
    complex_lines = np.unique(np.cumsum(newline)[~newline])
    buf = np.frombuffer(up.encode("ascii"), dtype=np.uint8).copy()
    breaks = np.flatnonzero(buf == 10)
    if complex_lines.size:  # blank the complex lines so that only plain words are read below
        first = np.concatenate(([0], breaks + 1))[complex_lines]
        stop = np.concatenate((breaks, [buf.size]))[complex_lines]
        edges = np.zeros(buf.size + 1, dtype=np.int64)
        np.add.at(edges, first, 1)
        np.add.at(edges, stop, -1)
        buf[np.cumsum(edges[:-1]) > 0] = 32
    letters = np.flatnonzero(buf >= 65)  # only word letters are >= 'A' in plain lines
    line = np.searchsorted(breaks, letters)
    numbers = _word_numbers(buf, letters, line, breaks)
    col = _COLUMN[buf[letters]]
    plain = np.ones(n, dtype=bool)
    plain[complex_lines] = False
    # Words the line-by-line interpreter refuses or treats otherwise: the block is complex.
    g = col == _G
    odd = ~np.isfinite(numbers)
    odd |= (col >= _X) & (col <= _R) & (np.abs(numbers) > MAX_COORDINATE)  # the lexer refuses these
    odd |= g & (numbers != 0) & (numbers != 1) & (numbers != 2) & (numbers != 3)
    odd |= (col == _N) & ((numbers < 0) | (numbers != np.trunc(numbers)))
    odd |= ((col == _F) | (col == _S)) & (numbers < 0)
    plain[line[odd]] = False
    key = line * len(PLAIN_LETTERS) + col
    twice = np.bincount(key, minlength=n * len(PLAIN_LETTERS)) > 1
    plain[np.flatnonzero(twice) // len(PLAIN_LETTERS)] = False
    values = np.full((n, len(PLAIN_LETTERS)), np.nan)
    present = np.zeros((n, len(PLAIN_LETTERS)), dtype=bool)
    values[line, col] = numbers
    present[line, col] = True
    values[~plain] = np.nan
    present[~plain] = False
    return PlainTable(
        plain,
        values,
        present,
        np.append(np.flatnonzero(~plain), n),
        axes=present[:, _X : _Z + 1].any(axis=1),
        ijk=present[:, _I : _K + 1].any(axis=1),
        words=present.any(axis=1),
    )


def _word_numbers(buf: np.ndarray, letters: np.ndarray, line: np.ndarray, breaks: np.ndarray) -> np.ndarray:
    """The number of each word (its letter at ``buf[letters[i]]``, on line ``line[i]``), bit for bit
    what ``float()`` makes of its text, as the lexer converts it.

    The digits are read as one integer per word (NumPy reads integers some ten times faster than
    decimals) and divided by the power of ten of the digits after the point. With at most 15 digits
    the integer and the power are exact doubles, so the one rounding of the division gives the
    correctly rounded value of the decimal, which is what ``float()`` returns. Longer numbers go
    through ``float()`` itself.
    """
    n = letters.size
    if n == 0:
        return np.zeros(0)
    # A word runs from its letter to the next letter on its line, or to the line's end (plain lines
    # hold no blanks any more).
    same_line = np.append(line[1:] == line[:-1], False)
    end = np.where(same_line, np.append(letters[1:], buf.size), np.append(breaks, buf.size)[line])
    sign = buf[letters + 1]
    negative = sign == 45  # '-'
    signed = negative | (sign == 43)  # '+'
    dots = np.flatnonzero(buf == 46)  # at most one per word, and only in plain words
    dot_at = np.full(n, -1, dtype=np.int64)
    dot_at[np.searchsorted(letters, dots, side="right") - 1] = dots
    has_dot = dot_at >= 0
    frac = np.where(has_dot, end - dot_at - 1, 0)
    long = np.flatnonzero(end - letters - 1 - signed - has_dot > 15)
    text = buf
    if long.size:  # too many digits for the exact route: zeros here, float() below
        text = buf.copy()
        for i in long:
            text[letters[i] + 1 : end[i]] = 48
    digits = np.fromstring(text.tobytes().translate(_LETTERS_TO_SPACE, b"+-."), dtype=np.int64, sep=" ")
    if digits.size != n:  # pragma: no cover - the plain-line expression guarantees it
        raise AssertionError("plain words and numbers do not pair up")
    values = digits / _POW10[np.minimum(frac, 15)]
    values = np.where(negative, -values, values)  # -0 reads as -0.0, as float("-0") does
    for i in long:
        values[i] = float(buf[letters[i] + 1 : end[i]].tobytes().decode("ascii"))
    return values


@dataclass
class RunState:
    """The modal state a run of plain blocks starts from (read from the interpreter)."""

    pos: np.ndarray  # (3,) mm
    scale: float  # mm per program unit
    absolute: bool
    arc_absolute: bool
    offset: np.ndarray  # (3,) program -> machine (G92), mm
    motion: int | None  # tenths: 0, 10, 20, 30
    feed_raw: float | None
    power: float
    laser: int
    plane: int
    plane_axes: tuple[int, int, int]
    exact_stop: bool
    blend_tol: float
    pending_stop: bool
    arc_tol: float  # radius tolerance, mm


@dataclass
class RunResult:
    """What a run did: ``blocks`` blocks executed (all of the run unless one needs the interpreter)."""

    blocks: int
    nonfinite: bool = False  # the next block reaches a non-finite number (the interpreter takes over)
    columns: dict[str, np.ndarray] | None = None  # the rows, one array per Program column
    pos: np.ndarray | None = None
    motion: int | None = None
    feed_raw: float | None = None
    power: float = 0.0
    any_words: bool = False


def interpret_run(table: PlainTable, a: int, b: int, lines: np.ndarray, st: RunState) -> RunResult:
    """Execute the plain blocks ``a:b`` of ``table`` (source lines ``lines[a:b]``) from state ``st``.

    Returns the rows and the state after the run, or — when a block would raise an error or reach a
    non-finite number — those of the blocks before it, with ``blocks`` the count of blocks executed.
    """
    flagged, nonfinite, result = _run(table, a, b, lines, st)
    if flagged < 0:
        return result
    if flagged == 0:
        return RunResult(0, nonfinite)
    prefix = _run(table, a, a + flagged, lines, st)[2]  # every value is causal: the prefix is unchanged
    prefix.nonfinite = nonfinite
    return prefix


def _run(table: PlainTable, a: int, b: int, lines: np.ndarray, st: RunState) -> tuple[int, bool, RunResult]:
    """(first flagged block or -1, whether it is flagged for a non-finite number, the run's result)."""
    V, P = table.values[a:b], table.present[a:b]
    n = b - a
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        # G (as tenths), F and S forward-filled from the state: column k of `modal`
        have = P[:, _MODAL]
        g0 = -1.0 if st.motion is None else st.motion / 10
        initial = (g0, np.nan if st.feed_raw is None else st.feed_raw, st.power)
        last = np.maximum.accumulate(np.where(have, np.arange(1, n + 1)[:, None], 0), axis=0)
        modal = np.concatenate((np.array([initial]), V[:, _MODAL]))[last, _THREE]
        motion = (modal[:, 0] * 10).astype(np.int64)  # negative: none; 0, 10, 20, 30
        feed_raw = modal[:, 1]
        axes, ijk = table.axes[a:b], table.ijk[a:b]
        # rows: blocks with axis words, and arcs without them (full circles: "G2 I5", "I5 J0" in G2 mode)
        arc_line = (motion >= 20) & (axes | have[:, 0] | ijk)
        row_line = axes | arc_line
        rows = np.flatnonzero(row_line)
        rm = motion[rows]
        # errors the interpreter raises for such blocks
        # (a feed below the floor or beyond a double, as the interpreter computes it, is refused there)
        feed_mm_s = feed_raw * st.scale / 60.0
        slow = ~np.isnan(feed_raw) & ((feed_mm_s < MIN_FEED_MM_S) | ~np.isfinite(feed_mm_s))
        bad = (axes & (motion < 0)) | ((ijk | P[:, _R]) & ~arc_line) | (row_line & (motion >= 10) & slow)
        # end points: absolute values forward-filled, or the increments summed in sequence from the start
        # point (an absent axis adds -0.0, which leaves every number as it is, -0.0 included)
        m = rows.size
        present = P[rows, 1:4]
        if st.absolute:
            given = np.concatenate((st.pos[None, :], V[rows, 1:4] * st.scale + st.offset))
            pick = np.maximum.accumulate(np.where(present, np.arange(1, m + 1)[:, None], 0), axis=0)
            end = given[pick, _THREE]
        else:
            steps = np.where(present, V[rows, 1:4] * st.scale, -0.0)
            end = np.cumsum(np.concatenate((st.pos[None, :], steps)), axis=0)[1:]
        start = np.concatenate((st.pos[None, :], end))[:-1]
        odd = ~np.isfinite(end).all(axis=1)
        arcs = np.flatnonzero(rm >= 20)
        if arcs.size:
            center = np.full((m, 3), np.nan)
            arc_bad, center[arcs] = _arcs(V, P, rows[arcs], start[arcs], end[arcs], rm[arcs] == 20, st)
            bad[rows[arcs[arc_bad]]] = True
            odd[arcs] |= ~np.isfinite(center[arcs]).all(axis=1)
            turn = np.where(rm == 20, -1, np.where(rm == 30, 1, 0)).astype(np.int8)
            kind = np.where(rm >= 20, int(Kind.ARC), int(Kind.LINE)).astype(np.int8)
        else:
            center = np.full((m, 3), np.nan)
            turn = np.full(m, np.int8(0))
            kind = np.full(m, np.int8(Kind.LINE))
        if odd.any():
            bad[rows[odd]] = True
        if bad.any():
            k = int(np.argmax(bad))
            return k, bool(np.isin(k, rows[odd])), RunResult(0)
        fr = feed_raw[rows]
        feed = np.where((rm == 0) | np.isnan(fr), np.nan, fr * st.scale / 60.0)
    stop = np.full(m, st.exact_stop)  # each row after a move programmed under G61.1 starts at rest
    if m:
        stop[0] = st.pending_stop
    columns = {
        "kind": kind,
        "start": start,
        "end": end,
        "center": center,
        "turn": turn,
        "feed": feed,
        "rapid": rm == 0,
        "laser": np.full(m, np.int8(st.laser)),
        "power": modal[rows, 2],
        "dwell_s": np.zeros(m),
        "stop_before": stop,
        "blend_tol": np.full(m, 0.0 if st.exact_stop else st.blend_tol),
        "event": np.full(m, np.int8(0)),
        "event_value": np.full(m, np.int32(0)),
        "line": lines[a:b][rows],
        "curve": np.full(m, np.int32(-1)),
        "plane": np.full(m, np.int8(st.plane)),
    }
    return (
        -1,
        False,
        RunResult(
            blocks=n,
            columns=columns,
            pos=end[-1].copy() if m else st.pos.copy(),
            motion=None if motion[-1] < 0 else int(motion[-1]),
            feed_raw=None if np.isnan(feed_raw[-1]) else float(feed_raw[-1]),
            power=float(modal[-1, 2]),
            any_words=bool(table.words[a:b].any()),
        ),
    )


def _arcs(
    V: np.ndarray, P: np.ndarray, lines: np.ndarray, start: np.ndarray, end: np.ndarray, cw: np.ndarray, st: RunState
) -> tuple[np.ndarray, np.ndarray]:
    """Centres of the arc rows (lines ``lines`` of the run) and which of them the interpreter refuses.

    The operations are those of ``_Interpreter.arc``, element by element.
    """
    a0, a1, a2 = st.plane_axes
    ci, cj, cn = _I + a0, _I + a1, _I + a2  # I/J/K letters of the plane's first, second and normal axis
    has_i, has_j, has_n, has_r = P[lines, ci], P[lines, cj], P[lines, cn], P[lines, _R]
    vi, vj, vr = V[lines, ci], V[lines, cj], V[lines, _R]
    sx, sy, ex, ey = start[:, a0], start[:, a1], end[:, a0], end[:, a1]
    bad = has_n | (has_r & (has_i | has_j))
    chord_x, chord_y = ex - sx, ey - sy
    d = np.hypot(chord_x, chord_y)
    mid_x, mid_y = (sx + ex) / 2, (sy + ey) / 2
    left_x, left_y = -chord_y / d, chord_x / d  # unit normal to the left of the chord
    # R form: the centre on the bisector, on the side the arc turns towards (R < 0: the other side)
    radius = np.abs(vr) * st.scale
    half = d / 2
    h2 = radius * radius - half * half
    h = np.sqrt(np.where(0.0 > h2, 0.0, h2))  # max(h2, 0.0)
    side_h = np.where(cw, -1.0, 1.0) * np.where(vr > 0, 1.0, -1.0) * h
    r_x, r_y = mid_x + side_h * left_x, mid_y + side_h * left_y
    bad |= has_r & ((d < 1e-9) | (radius == 0) | (half > radius + st.arc_tol))
    # I J K form: the centre given, checked against both radii, moved onto the bisector
    if st.arc_absolute:
        c_x = np.where(has_i, vi * st.scale + st.offset[a0], sx)
        c_y = np.where(has_j, vj * st.scale + st.offset[a1], sy)
    else:
        c_x = sx + np.where(has_i, vi, 0.0) * st.scale
        c_y = sy + np.where(has_j, vj, 0.0) * st.scale
    r1 = np.hypot(sx - c_x, sy - c_y)
    r2 = np.hypot(ex - c_x, ey - c_y)
    bad |= ~has_r & (~(has_i | has_j) | (r1 < 1e-9) | (np.abs(r1 - r2) > st.arc_tol))
    t = (c_x - mid_x) * left_x + (c_y - mid_y) * left_y
    moved = d > 1e-9
    c_x = np.where(moved, mid_x + t * left_x, c_x)
    c_y = np.where(moved, mid_y + t * left_y, c_y)
    center = np.empty((lines.size, 3))
    center[:, a0] = np.where(has_r, r_x, c_x)
    center[:, a1] = np.where(has_r, r_y, c_y)
    center[:, a2] = start[:, a2]
    return bad, center
