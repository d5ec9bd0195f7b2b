"""Split one ISO-7bit / RS274NGC line into words.

RS274NGC ignores spaces and tabs outside comments and reads letters case-insensitively, so
``g1x 1 0`` is ``G1 X10``. Comments are ``( ... )`` and ``;`` to the end of the line. Each word
keeps the 1-based column where its letter stands in the original line, for error messages.
"""

from __future__ import annotations

import math
import re
import unicodedata
from dataclasses import dataclass

from jaxcnc.errors import SourceError

#: A number as RS274NGC writes it: ASCII digits only (``\d`` would also match Arabic-Indic or full-width digits,
#: which ``float()`` reads; G-code is ISO-7bit, so those are refused).
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)")
#: Largest magnitude of a coordinate word (X Y Z I J K R, program units). No machine travels 1000 km, and below
#: it every product the interpreter forms (radius², inch scaling, offsets) stays far from overflow.
MAX_COORDINATE = 1e9
COORDINATE_LETTERS = frozenset("XYZIJKR")


def shown_number(text: str) -> str:
    """A number's text for a message: long ones shortened (``1111…111, 400 digits``)."""
    return text if len(text) <= 24 else f"{text[:10]}…{text[-4:]} ({len(text)} characters)"


def non_ascii_digit(c: str) -> str | None:
    """The reason to refuse ``c`` when it is a digit other than ASCII 0-9 (else ``None``)."""
    if c.isascii() or not (c.isdigit() or c.isnumeric()):
        return None
    name = unicodedata.name(c, f"U+{ord(c):04X}")
    return f"non-ASCII digit {c!r} ({name}): G-code numbers are written with the ASCII digits 0-9"


def number_value(letter: str, text: str) -> float | str:
    """The value of a word's number ``text``, or the reason to refuse it (it overflows, or a coordinate is
    beyond :data:`MAX_COORDINATE`)."""
    v = float(text)
    if not math.isfinite(v):
        return f"{letter}{shown_number(text)}: the number overflows a double (it is beyond 1.8e308)"
    if letter in COORDINATE_LETTERS and abs(v) > MAX_COORDINATE:
        return (
            f"{letter}{shown_number(text)} is beyond ±{MAX_COORDINATE:g}: farther than any machine travels "
            "(a coordinate, centre or radius)"
        )
    return v


@dataclass(frozen=True)
class Word:
    """One word: an upper-case letter and its number, as written (``text``) and parsed."""

    letter: str
    value: float
    text: str
    column: int


#: Internal G-code numbers of dialect keywords (tenths as the interpreter counts them).
KEYWORD_CODES = {"BSPLINE": 1001.0}


def strip_comments(
    raw: str, file: str, line_no: int, paren: bool = True, semicolon: bool = True
) -> tuple[str, list[int], list[str]]:
    """Remove comments and blanks. Returns (compact text, source column of each char, comments).

    ``paren`` / ``semicolon``: which comment styles the dialect has.
    """
    chars: list[str] = []
    cols: list[int] = []
    comments: list[str] = []
    i, n = 0, len(raw)
    while i < n:
        c = raw[i]
        if c == "(" and paren:
            j = raw.find(")", i + 1)
            if j < 0:
                raise SourceError(file, line_no, i + 1, "comment opened with '(' is never closed")
            comments.append(raw[i + 1 : j])
            i = j + 1
            continue
        if c == ";" and semicolon:
            comments.append(raw[i + 1 :])
            break
        if c in " \t\r\n\f\v":
            i += 1
            continue
        chars.append(c)
        cols.append(i + 1)
        i += 1
    return "".join(chars), cols, comments


def tokenize(raw: str, file: str, line_no: int, dialect=None) -> tuple[list[Word], list[str]]:
    """Words and comments of one line; raises :class:`SourceError` on anything malformed.

    ``dialect`` (a :class:`~jaxcnc.gcode.dialect.Dialect`) adds its comment styles, keywords
    (``BSPLINE`` becomes an internal G word) and ``NAME=value`` addresses (words named ``NAME``).
    """
    paren = dialect.paren_comments if dialect is not None else True
    semi = dialect.semicolon_comments if dialect is not None else True
    text, cols, comments = strip_comments(raw, file, line_no, paren, semi)
    keywords = dialect.keywords if dialect is not None else {}
    addresses = dialect.addresses if dialect is not None else {}
    words: list[Word] = []
    i, n = 0, len(text)
    upper = text.upper()
    while i < n:
        matched = False
        for name, meaning in keywords.items():
            if upper.startswith(name, i):
                words.append(Word("G", KEYWORD_CODES[meaning], name, cols[i]))
                i += len(name)
                matched = True
                break
        if matched:
            continue
        for name in addresses:
            if upper.startswith(name + "=", i):
                at = i + len(name) + 1
                m = _NUMBER.match(text, at)
                while at < n and text[at] in "+-.0123456789":
                    at += 1
                if at < n and (why := non_ascii_digit(text[at])):
                    raise SourceError(file, line_no, cols[i], why)
                if m is None:
                    raise SourceError(file, line_no, cols[i], f"{name}= needs a number")
                value = number_value(name, m.group(0))
                if isinstance(value, str):
                    raise SourceError(file, line_no, cols[i], value)
                words.append(Word(name, value, m.group(0), cols[i]))
                i = m.end()
                matched = True
                break
        if matched:
            continue
        c = text[i]
        col = cols[i]
        if why := non_ascii_digit(c):
            raise SourceError(file, line_no, col, why)
        if not c.isascii() or not c.isalpha():
            if c in "#[]":
                raise SourceError(
                    file,
                    line_no,
                    col,
                    f"unexpected {c!r}: parameters and [expressions] are values "
                    "of words (X[#1 + 2]) or assignments (#1 = 2)",
                )
            if c == "/":
                raise SourceError(file, line_no, col, "block delete '/' must start the block")
            if c in "@^":
                raise SourceError(
                    file, line_no, col, f"polar coordinates ('@' distance, '^' angle) are not supported: {c!r}"
                )
            shown = c if c.isprintable() else repr(c)
            raise SourceError(file, line_no, col, f"unexpected character {shown!r}: expected a word such as G1 or X10")
        letter = c.upper()
        m = _NUMBER.match(text, i + 1)
        after = i + 1
        while after < n and text[after] in "+-.0123456789":
            after += 1
        if after < n and (why := non_ascii_digit(text[after])):
            raise SourceError(file, line_no, col, why)
        if m is None and i + 1 < n and text[i + 1] in "#[":
            raise SourceError(file, line_no, cols[i + 1], f"unexpected {text[i + 1]!r} after {c.upper()!r}")
        if m is None and i + 1 < n and text[i + 1].isalpha():
            j = col - 1  # the word as written (spaces end it there)
            while j < len(raw) and raw[j].isalpha():
                j += 1
            dialect_name = dialect.name if dialect is not None else "linuxcnc"
            raise SourceError(
                file,
                line_no,
                col,
                f"unknown word {raw[col - 1 : j].upper()!r} (not part of the {dialect_name} dialect)",
            )
        if m is None:
            rest = text[i + 1 : i + 9]
            raise SourceError(
                file,
                line_no,
                col,
                f"malformed number after {letter!r}: {rest!r}" if rest else f"word {letter!r} has no number",
            )
        end = m.end()
        if end < n and (text[end] == "." or text[end].isdigit()):
            raise SourceError(file, line_no, col, f"malformed number {text[i + 1 : end + 1]!r} after {letter!r}")
        if letter == "O":
            raise SourceError(file, line_no, col, "an O-word must start its line (O100 sub, O100 if [...], ...)")
        value = number_value(letter, m.group(0))
        if isinstance(value, str):
            raise SourceError(file, line_no, col, value)
        words.append(Word(letter, value, m.group(0), col))
        i = end
    return words, comments
