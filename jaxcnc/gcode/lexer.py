"""Split one ISO-7bit / RS274NGC line into words.

RS274NGC ignores spaces and tabs outside comments and reads letters case-insensitively, so
``g1x 1 0`` is ``G1 X10``. Comments are ``( ... )`` and ``;`` to the end of the line. Each word
keeps the 1-based column where its letter stands in the original line, for error messages.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from jaxcnc.errors import SourceError

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)")


@dataclass(frozen=True)
class Word:
    """One word: an upper-case letter and its number, as written (``text``) and parsed."""

    letter: str
    value: float
    text: str
    column: int


def strip_comments(raw: str, file: str, line_no: int) -> tuple[str, list[int], list[str]]:
    """Remove comments and blanks. Returns (compact text, source column of each char, comments)."""
    chars: list[str] = []
    cols: list[int] = []
    comments: list[str] = []
    i, n = 0, len(raw)
    while i < n:
        c = raw[i]
        if c == "(":
            j = raw.find(")", i + 1)
            if j < 0:
                raise SourceError(file, line_no, i + 1, "comment opened with '(' is never closed")
            comments.append(raw[i + 1 : j])
            i = j + 1
            continue
        if c == ";":
            comments.append(raw[i + 1 :])
            break
        if c in " \t\r\n\f\v":
            i += 1
            continue
        chars.append(c)
        cols.append(i + 1)
        i += 1
    return "".join(chars), cols, comments


def tokenize(raw: str, file: str, line_no: int) -> tuple[list[Word], list[str]]:
    """Words and comments of one line; raises :class:`SourceError` on anything malformed."""
    text, cols, comments = strip_comments(raw, file, line_no)
    words: list[Word] = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        col = cols[i]
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
            shown = c if c.isprintable() else repr(c)
            raise SourceError(file, line_no, col, f"unexpected character {shown!r}: expected a word such as G1 or X10")
        letter = c.upper()
        m = _NUMBER.match(text, i + 1)
        if m is None and i + 1 < n and text[i + 1] in "#[":
            raise SourceError(file, line_no, cols[i + 1], f"unexpected {text[i + 1]!r} after {c.upper()!r}")
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
        words.append(Word(letter, float(m.group(0)), m.group(0), col))
        i = end
    return words, comments
