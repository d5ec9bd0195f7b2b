"""The parametric preprocessor: structured RS274NGC programs flattened to plain ISO-7bit.

Parameters (``#1``–``#5602`` numbered, ``#<name>`` local to a subroutine call, ``#<_name>``
global), expressions in ``[ ]`` (:mod:`jaxcnc.gcode.expressions`) and O-word control flow
(``sub/endsub/call/return``, ``if/elseif/else/endif``, ``while/endwhile``, ``do/while``,
``repeat/endrepeat``, ``break/continue``) are executed by a recursive-descent interpreter; what it
emits is plain ISO-7bit, one line per executed block, with every value a literal number. A line
without any of these passes through unchanged. ``jaxcnc expand FILE`` prints the result, which
parses to the same program as the original.

As in RS274NGC, parameter assignments on a line take effect after the whole line is read (so
``#1=2 #2=#1`` reads the old ``#1``); call arguments become ``#1``… of the subroutine; a
subroutine's ``#<name>`` parameters are its own. Runaway recursion and endless loops stop with an
error after ``max_depth`` calls and ``max_lines`` executed lines.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from jaxcnc.errors import SourceError
from jaxcnc.gcode.expressions import ExpressionError, Parser
from jaxcnc.gcode.lexer import strip_comments

MAX_DEPTH = 64
MAX_LINES = 10_000_000
_OWORD = re.compile(r"[oO](\d+|<[^>]*>)(.*)$")
_KEYWORDS = (
    "endsub",
    "sub",
    "call",
    "return",
    "elseif",
    "else",
    "endif",
    "if",
    "endwhile",
    "while",
    "do",
    "endrepeat",
    "repeat",
    "break",
    "continue",
)
_PLAIN = re.compile(r"[#\[\]]")


@dataclass(frozen=True)
class ExpandedLine:
    """One flattened block and the source line it came from."""

    text: str
    line: int


def format_number(v: float) -> str:
    """The shortest decimal that reads back as ``v``, never in exponent form."""
    if not np.isfinite(v):
        raise ValueError(f"{v} is not a finite number")
    return np.format_float_positional(v, unique=True, trim="-")


@dataclass
class _OLine:
    index: int  # source line index
    label: str
    keyword: str
    arg: str  # compact text after the keyword
    arg_col: list[int]


@dataclass
class _Frame:
    ret: int  # source index to continue at after return
    local: dict = field(default_factory=dict)  # named locals and #1..#30
    loops: list = field(default_factory=list)  # (label, start index, counter)


class Preprocessor:
    def __init__(self, text: str, file: str, max_depth: int = MAX_DEPTH, max_lines: int = MAX_LINES, dialect=None):
        self.file, self.max_depth, self.max_lines = file, max_depth, max_lines
        self.comment_styles = (dialect.paren_comments, dialect.semicolon_comments) if dialect else (True, True)
        self.program_numbers = bool(dialect and dialect.program_numbers)
        self.numbers: set[int] = set()  # lines that name the program ("O1001"): read, and nothing else
        self.lines = text.splitlines()
        self.globals: dict[object, float] = {}
        self.compact: dict[int, tuple[str, list[int]]] = {}
        self.olines: dict[int, _OLine] = {}
        self._scan()

    def err(self, index: int, col: int, reason: str) -> SourceError:
        return SourceError(self.file, index + 1, col, reason)

    # -- structure -------------------------------------------------------------------------
    def _scan(self) -> None:
        """Find O-word lines and match their blocks (if/elseif/else/endif, loops, subs)."""
        self.match: dict[int, dict] = {}
        stack: list[tuple[str, str, int, int]] = []  # (label, kind, index, column)
        self.subs: dict[str, int] = {}
        for i, raw in enumerate(self.lines):
            if raw.strip() == "%":
                continue
            body = raw.lstrip()
            if body[:1] not in ("o", "O", "/"):
                continue
            text, cols, _ = strip_comments(raw, self.file, i + 1, *self.comment_styles)
            if text.startswith("/"):
                text, cols = text[1:], cols[1:]
            m = _OWORD.match(text)
            if not m:
                continue
            label = m.group(1).lower()
            rest = m.group(2)
            kw = next((k for k in _KEYWORDS if rest.lower().startswith(k)), None)
            number = kw is None and not rest.strip() and m.group(1).isdigit()  # "O1001" alone: a program number
            if number and self.program_numbers:
                self.numbers.add(i)  # the program's number (the dialect's): it names the program, nothing else
                continue
            if kw is None:
                hint = " (a Fanuc / Haas program number? read the program with the fanuc dialect, --dialect fanuc)"
                hint = hint if number else ""
                raise self.err(i, cols[0], f"O-word O{m.group(1)} needs a keyword such as sub, call, if, while{hint}")
            off = m.start(2) + len(kw)
            ol = _OLine(i, label, kw, rest[len(kw) :], cols[off:])
            self.olines[i] = ol
            if kw in ("sub", "if", "repeat", "do") or (
                kw == "while" and not (stack and stack[-1][0] == label and stack[-1][1] == "do")
            ):
                if kw == "sub":
                    if stack:
                        raise self.err(i, cols[0], f"subroutine O{label} defined inside another block")
                    if label in self.subs:
                        raise self.err(i, cols[0], f"subroutine O{label} is defined twice")
                    self.subs[label] = i
                stack.append((label, kw, i, cols[0]))
                self.match[i] = {"kind": kw, "branches": []}
            elif kw in ("endsub", "endif", "endwhile", "endrepeat", "while"):
                opener = {"endsub": "sub", "endif": "if", "endwhile": "while", "endrepeat": "repeat", "while": "do"}[kw]
                if not stack or stack[-1][0] != label or stack[-1][1] != opener:
                    raise self.err(i, cols[0], f"O{label} {kw} does not close an open O{label} {opener}")
                _, _, start, _ = stack.pop()
                self.match[start]["end"] = i
                self.match[i] = {"kind": "enddo" if kw == "while" else kw, "start": start}
            elif kw in ("elseif", "else"):
                if not stack or stack[-1][0] != label or stack[-1][1] != "if":
                    raise self.err(i, cols[0], f"O{label} {kw} outside an open O{label} if")
                start = stack[-1][2]
                self.match[start]["branches"].append(i)
                self.match[i] = {"kind": kw, "start": start}
        if stack:
            label, kw, i, col = stack[-1]
            raise self.err(i, col, f"O{label} {kw} is never closed")

    # -- parameters ------------------------------------------------------------------------
    def read(self, frame: _Frame, key: object) -> float:
        if isinstance(key, str) and not key.startswith("_"):
            return frame.local[key]
        if isinstance(key, int) and key <= 30 and key in frame.local:
            return frame.local[key]
        if isinstance(key, int):
            return self.globals.get(key, 0.0)  # numbered parameters default to 0
        return self.globals[key]

    def exists(self, frame: _Frame, key: object) -> bool:
        try:
            self.read(frame, key)
        except KeyError:
            return False
        return True

    def write(self, frame: _Frame, key: object, value: float) -> None:
        if (isinstance(key, str) and not key.startswith("_")) or (
            isinstance(key, int) and key <= 30 and frame is not self.main
        ):
            frame.local[key] = value
        else:
            self.globals[key] = value

    def parser(self, frame: _Frame, text: str, pos: int) -> Parser:
        return Parser(text, pos, lambda k: self.read(frame, k), lambda k: self.exists(frame, k))

    def evaluate(self, frame: _Frame, i: int, text: str, cols: list[int], pos: int = 0) -> tuple[float, int]:
        p = self.parser(frame, text, pos)
        try:
            v = p.expr()
        except ExpressionError as exc:
            raise self.err(i, cols[min(exc.offset, len(cols) - 1)] if cols else 0, exc.reason) from None
        except RecursionError:
            raise self.err(i, cols[pos] if cols else 0, "expression nested too deeply") from None
        return v, p.pos

    def condition(self, frame: _Frame, ol: _OLine) -> float:
        if not ol.arg.startswith("["):
            raise self.err(ol.index, ol.arg_col[0] if ol.arg_col else 0, f"O{ol.label} {ol.keyword} needs [condition]")
        v, end = self.evaluate(frame, ol.index, ol.arg, ol.arg_col)
        if end != len(ol.arg):
            raise self.err(ol.index, ol.arg_col[end], f"unexpected text after the condition: {ol.arg[end:]!r}")
        if not np.isfinite(v):  # pragma: no cover - the parser never yields one; a NaN must never read as true
            raise self.err(ol.index, ol.arg_col[0], f"condition is {v}")
        return v

    # -- blocks ----------------------------------------------------------------------------
    def flatten(self, frame: _Frame, i: int, raw: str) -> str | None:
        """A block with parameters/expressions evaluated; assignments applied. None if empty."""
        text, cols, _ = strip_comments(raw, self.file, i + 1, *self.comment_styles)
        out: list[str] = []
        assigns: list[tuple[object, float]] = []
        pos = 0
        while pos < len(text):
            c = text[pos]
            if c == "#":
                p = self.parser(frame, text, pos)
                try:
                    key = p.parameter_key()
                except ExpressionError as exc:
                    raise self.err(i, cols[min(exc.offset, len(cols) - 1)], exc.reason) from None
                if p.pos >= len(text) or text[p.pos] != "=":
                    raise self.err(i, cols[pos], "a parameter outside a word must be assigned: #n=value")
                value, pos = self.evaluate(frame, i, text, cols, p.pos + 1)
                assigns.append((key, value))
                continue
            if c.isalpha():
                letter = c.upper()
                value_start = pos + 1
                if value_start < len(text) and (
                    text[value_start] in "#["
                    or text[value_start].isalpha()
                    or (
                        text[value_start] in "+-"
                        and value_start + 1 < len(text)
                        and (text[value_start + 1] in "#[" or text[value_start + 1].isalpha())
                    )
                ):
                    value, pos = self.evaluate(frame, i, text, cols, value_start)
                    out.append(letter + format_number(value))  # (finite: the parser refuses anything else)
                    continue
                end = value_start
                while end < len(text) and text[end] in "+-.0123456789":
                    end += 1
                out.append(letter + text[value_start:end])
                pos = end
                continue
            if c == "/" and pos == 0:
                out.append("/")
                pos += 1
                continue
            out.append(c)  # anything else is left for the interpreter to report
            pos += 1
        for key, value in assigns:
            self.write(frame, key, value)
        return " ".join(out) if out else None

    def has_expressions(self, i: int, raw: str) -> bool:
        """The block holds parameters or expressions (outside its comments)."""
        if _PLAIN.search(raw) is None:
            return False
        compact = strip_comments(raw, self.file, i + 1, *self.comment_styles)[0]
        return any(c in compact for c in "#[]")

    def run(self) -> list[ExpandedLine]:
        out: list[ExpandedLine] = []
        self.main = _Frame(ret=-1)
        stack = [self.main]
        executed = 0
        i = 0
        n = len(self.lines)
        percent = False
        self.open_percent: int | None = None  # the source line of a '%' that opened the program, until closed
        while i < n:
            executed += 1
            if executed > self.max_lines:
                raise self.err(i, 0, f"more than {self.max_lines} lines executed: an endless loop?")
            frame = stack[-1]
            raw = self.lines[i]
            if raw.strip() == "%":
                if percent and len(stack) == 1:
                    self.open_percent = None
                    break
                if not percent:
                    self.open_percent = i + 1
                percent = True
                i += 1
                continue
            ol = self.olines.get(i)
            if i in self.numbers:
                i += 1
                continue
            if ol is None:
                if not self.has_expressions(i, raw):
                    if raw.strip():
                        out.append(ExpandedLine(raw.strip(), i + 1))
                else:
                    text = self.flatten(frame, i, raw)
                    if text is not None:
                        out.append(ExpandedLine(text, i + 1))
                i += 1
                continue
            i = self.control(stack, ol)
        if len(stack) > 1:
            raise self.err(n - 1, 0, "the program ends inside a subroutine")
        return out

    def control(self, stack: list[_Frame], ol: _OLine) -> int:
        """Execute an O-word line; return the next source index."""
        frame = stack[-1]
        i, kw, m = ol.index, ol.keyword, self.match.get(ol.index, {})
        if kw == "sub":
            return m["end"] + 1  # definitions are skipped where they stand
        if kw in ("endsub", "return"):
            if len(stack) == 1:
                raise self.err(i, 0, f"O{ol.label} {kw} outside a subroutine call")
            stack.pop()
            return frame.ret
        if kw == "call":
            if ol.label not in self.subs:
                raise self.err(i, 0, f"call of undefined subroutine O{ol.label}")
            if len(stack) > self.max_depth:
                raise self.err(i, 0, f"subroutine calls nested deeper than {self.max_depth}: runaway recursion?")
            args, pos = [], 0
            while pos < len(ol.arg):
                if ol.arg[pos] != "[":
                    raise self.err(i, ol.arg_col[pos], "call arguments are bracketed expressions: [1] [2]")
                v, pos = self.evaluate(frame, i, ol.arg, ol.arg_col, pos)
                args.append(v)
            if len(args) > 30:
                raise self.err(i, 0, "more than 30 call arguments")
            stack.append(_Frame(ret=i + 1, local={k + 1: v for k, v in enumerate(args)}))
            return self.subs[ol.label] + 1
        if kw == "if":
            for branch in [i, *m["branches"]]:
                b = self.olines[branch]
                if b.keyword == "else" or self.condition(frame, b):
                    return branch + 1
            return m["end"] + 1
        if kw in ("elseif", "else"):  # reached by falling out of the taken branch
            return self.match[m["start"]]["end"] + 1
        if kw == "endif":
            return i + 1
        if kw == "while" and m.get("kind") == "while":
            if self.condition(frame, ol):
                frame.loops.append((ol.label, i))
                return i + 1
            return m["end"] + 1
        if kw == "endwhile":
            self._pop_loop(frame, ol.label)
            return m["start"]
        if kw == "do":
            frame.loops.append((ol.label, i))
            return i + 1
        if kw == "while" and m.get("kind") == "enddo":  # the end of a do/while
            self._pop_loop(frame, ol.label)
            if self.condition(frame, ol):
                frame.loops.append((ol.label, m["start"]))
                return m["start"] + 1
            return i + 1
        if kw == "repeat":
            key = ("repeat", i)
            if key not in frame.local:
                count, _ = self.evaluate(frame, i, ol.arg, ol.arg_col) if ol.arg else (0.0, 0)
                if not np.isfinite(count) or count != int(count) or count < 0:
                    raise self.err(i, 0, f"repeat count {count:g} must be a non-negative integer")
                frame.local[key] = int(count)
            if frame.local[key] <= 0:
                del frame.local[key]
                return m["end"] + 1
            frame.local[key] -= 1
            frame.loops.append((ol.label, i))
            return i + 1
        if kw == "endrepeat":
            self._pop_loop(frame, ol.label)
            return m["start"]
        if kw in ("break", "continue"):
            while frame.loops:
                label, start = frame.loops.pop()
                if label == ol.label:
                    sm = self.match[start]
                    if kw == "continue":
                        kind = sm["kind"]
                        if kind == "do":  # re-test the closing while
                            return sm["end"]
                        return start
                    frame.local.pop(("repeat", start), None)
                    return sm["end"] + 1
            raise self.err(i, 0, f"O{ol.label} {kw} outside an O{ol.label} loop")
        raise self.err(i, 0, f"O{ol.label} {kw} here is not allowed")

    def _pop_loop(self, frame: _Frame, label: str) -> None:
        if frame.loops and frame.loops[-1][0] == label:
            frame.loops.pop()


def expand(
    text: str,
    file: str = "<string>",
    *,
    max_depth: int = MAX_DEPTH,
    max_lines: int = MAX_LINES,
    dialect=None,
    percent: list[int] | None = None,
) -> list[ExpandedLine]:
    """Flatten a parametric program; see the module docstring. ``dialect`` sets the comment styles.

    ``percent``: when given, the source line of a ``%`` that opened the program and was never closed is appended
    to it (the interpreter refuses that unless the program ends with M2/M30 first, as LinuxCNC does).
    """
    pre = Preprocessor(text, file, max_depth, max_lines, dialect)
    out = pre.run()
    if percent is not None and pre.open_percent is not None:
        percent.append(pre.open_percent)
    return out


def expand_text(text: str, file: str = "<string>", **kwargs) -> str:
    """The flattened program as text (what ``jaxcnc expand`` prints)."""
    return "\n".join(e.text for e in expand(text, file, **kwargs)) + "\n"
