"""RS274NGC expressions and parameters: a recursive-descent parser and evaluator.

Grammar (precedence from low to high, all binary operators left-associative)::

    expr    := logic
    logic   := compare  (("AND" | "OR" | "XOR") compare)*
    compare := additive (("EQ" | "NE" | "GT" | "GE" | "LT" | "LE") additive)*
    additive:= multiplicative (("+" | "-") multiplicative)*
    multiplicative := power (("*" | "/" | "MOD") power)*
    power   := unary ("**" unary)*
    unary   := ("-" | "+") unary | primary
    primary := number | parameter | "[" expr "]" | FUNC "[" expr "]" | "ATAN" "[" expr "]" "/" "[" expr "]"
               | "EXISTS" "[" parameter "]"
    parameter := "#" (integer | "<" name ">" | primary)

Trigonometric functions work in degrees, as in RS274NGC. Names are case-insensitive and spaces
are not significant (the caller removes them). Errors are raised as ``ExpressionError`` with the
offset into the text, which the preprocessor turns into ``file:line:column``. Every value is a finite double:
a number, an operation or a function whose result overflows (or would be NaN) is such an error, so a
condition is never NaN and a word never gets an infinite value. Digits are ASCII (``0-9``) only.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from jaxcnc.gcode.lexer import non_ascii_digit

_NUMBER_CHARS = "0123456789."


class ExpressionError(Exception):
    def __init__(self, offset: int, reason: str):
        super().__init__(reason)
        self.offset, self.reason = offset, reason


def _deg(f: Callable[[float], float]) -> Callable[[float], float]:
    return lambda x: f(math.radians(x))


def _checked(name: str, f: Callable[[float], float], ok: Callable[[float], bool]) -> Callable[[float], float]:
    def g(x: float) -> float:
        if not ok(x):
            raise ValueError(f"{name}[{x:g}] is outside its domain")
        return f(x)

    return g


FUNCTIONS: dict[str, Callable[[float], float]] = {
    "ABS": abs,
    "ACOS": _checked("ACOS", lambda x: math.degrees(math.acos(x)), lambda x: -1 <= x <= 1),
    "ASIN": _checked("ASIN", lambda x: math.degrees(math.asin(x)), lambda x: -1 <= x <= 1),
    "COS": _deg(math.cos),
    "SIN": _deg(math.sin),
    "TAN": _deg(math.tan),
    "EXP": _checked("EXP", math.exp, lambda x: x < 709),
    "LN": _checked("LN", math.log, lambda x: x > 0),
    "SQRT": _checked("SQRT", math.sqrt, lambda x: x >= 0),
    "FIX": lambda x: float(math.floor(x)),
    "FUP": lambda x: float(math.ceil(x)),
    "ROUND": lambda x: float(math.floor(x + 0.5)) if x >= 0 else -float(math.floor(-x + 0.5)),
}
_BINARY_LEVELS = (
    ("AND", "OR", "XOR"),
    ("EQ", "NE", "GT", "GE", "LT", "LE"),
    ("+", "-"),
    ("*", "/", "MOD"),
)


def _finite(v: float, offset: int, what: str) -> float:
    """``v`` when it is a finite number; otherwise the located error (an overflow, or NaN from one)."""
    if not math.isfinite(v):
        raise ExpressionError(offset, f"{what} overflows a double" if math.isinf(v) else f"{what} is not a number")
    return v


def _apply(op: str, a: float, b: float, offset: int) -> float:
    """``a op b``, finite, or an :class:`ExpressionError` at ``offset``."""
    try:
        return _finite(_apply_raw(op, a, b, offset), offset, f"{a:g} {op} {b:g}")
    except OverflowError:
        raise ExpressionError(offset, f"{a:g} {op} {b:g} overflows a double") from None


def _apply_raw(op: str, a: float, b: float, offset: int) -> float:
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    if op == "/":
        if b == 0:
            raise ExpressionError(offset, "division by zero")
        return a / b
    if op == "MOD":
        if b == 0:
            raise ExpressionError(offset, "MOD by zero")
        return a - b * math.floor(a / b)
    if op == "**":
        try:
            r = a**b
        except (OverflowError, ZeroDivisionError):
            raise ExpressionError(offset, f"{a:g} ** {b:g} is undefined") from None
        if isinstance(r, complex):
            raise ExpressionError(offset, f"{a:g} ** {b:g} is not a real number")
        return float(r)
    cmp = {"EQ": a == b, "NE": a != b, "GT": a > b, "GE": a >= b, "LT": a < b, "LE": a <= b}
    if op in cmp:
        return 1.0 if cmp[op] else 0.0
    x, y = a != 0, b != 0
    return 1.0 if {"AND": x and y, "OR": x or y, "XOR": x != y}[op] else 0.0


class Parser:
    """Parses and evaluates one expression or parameter reference in ``text`` from ``pos``.

    ``read(name_or_number)`` returns a parameter's value (raising ``KeyError`` if unset);
    ``exists(name)`` tells whether a named parameter is set.
    """

    def __init__(self, text: str, pos: int, read: Callable[[object], float], exists: Callable[[object], bool]):
        self.text, self.pos, self.read, self.exists = text, pos, read, exists

    # -- helpers -----------------------------------------------------------------------------
    def peek_word(self, word: str) -> bool:
        return self.text[self.pos : self.pos + len(word)].upper() == word

    def expect(self, ch: str) -> None:
        if self.pos >= len(self.text) or self.text[self.pos] != ch:
            got = repr(self.text[self.pos]) if self.pos < len(self.text) else "the end of the line"
            raise ExpressionError(self.pos, f"expected {ch!r}, found {got}")
        self.pos += 1

    def number(self) -> float:
        start = self.pos
        while self.pos < len(self.text) and self.text[self.pos] in _NUMBER_CHARS:
            self.pos += 1
        s = self.text[start : self.pos]
        if not s or s == "." or s.count(".") > 1:
            raise ExpressionError(start, f"malformed number {s!r}" if s else "expected a number")
        if self.pos < len(self.text) and (why := non_ascii_digit(self.text[self.pos])):
            raise ExpressionError(self.pos, why)
        shown = s if len(s) <= 24 else f"{s[:10]}…{s[-4:]} ({len(s)} characters)"
        return _finite(float(s), start, f"the number {shown}")

    # -- grammar -----------------------------------------------------------------------------
    def bracketed(self) -> float:
        self.expect("[")
        v = self.expr()
        self.expect("]")
        return v

    def expr(self, level: int = 0) -> float:
        if level == len(_BINARY_LEVELS):
            return self.power()
        v = self.expr(level + 1)
        while True:
            op = next((o for o in _BINARY_LEVELS[level] if self.peek_word(o)), None)
            if op is None:
                return v
            at = self.pos
            self.pos += len(op)
            v = _apply(op, v, self.expr(level + 1), at)

    def power(self) -> float:
        v = self.unary()
        while self.peek_word("**"):
            at = self.pos
            self.pos += 2
            v = _apply("**", v, self.unary(), at)
        return v

    def unary(self) -> float:
        if self.pos < len(self.text) and self.text[self.pos] in "+-":
            sign = -1.0 if self.text[self.pos] == "-" else 1.0
            self.pos += 1
            return sign * self.unary()  # (the operand is finite: so is its negative)
        return self.primary()

    def primary(self) -> float:
        if self.pos >= len(self.text):
            raise ExpressionError(self.pos, "expression ends early")
        c = self.text[self.pos]
        if c == "[":
            return self.bracketed()
        if c == "#":
            return self.parameter_value()
        if c in _NUMBER_CHARS:
            return self.number()
        if why := non_ascii_digit(c):
            raise ExpressionError(self.pos, why)
        if c.isalpha():
            return self.function()
        raise ExpressionError(self.pos, f"unexpected {c!r} in expression")

    def function(self) -> float:
        start = self.pos
        while self.pos < len(self.text) and self.text[self.pos].isalpha():
            self.pos += 1
        name = self.text[start : self.pos].upper()
        if name == "ATAN":
            y = self.bracketed()
            self.expect("/")
            x = self.bracketed()
            return _finite(math.degrees(math.atan2(y, x)), start, f"ATAN[{y:g}]/[{x:g}]")
        if name == "EXISTS":
            self.expect("[")
            key = self.parameter_key()
            self.expect("]")
            return 1.0 if self.exists(key) else 0.0
        if name not in FUNCTIONS:
            raise ExpressionError(start, f"unknown function or operator {name!r}")
        arg = self.bracketed()
        try:
            v = float(FUNCTIONS[name](arg))
        except ValueError as exc:
            raise ExpressionError(start, str(exc)) from None
        except OverflowError:
            raise ExpressionError(start, f"{name}[{arg:g}] overflows a double") from None
        return _finite(v, start, f"{name}[{arg:g}]")

    def parameter_key(self) -> object:
        """After '#': an integer, a ``<name>`` (lower-cased) or a bracketed/indirect number."""
        at = self.pos
        self.expect("#")
        if self.pos < len(self.text) and self.text[self.pos] == "<":
            end = self.text.find(">", self.pos)
            if end < 0:
                raise ExpressionError(self.pos, "parameter name '<' is never closed with '>'")
            name = self.text[self.pos + 1 : end].lower()
            if not name:
                raise ExpressionError(self.pos, "empty parameter name")
            self.pos = end + 1
            return name
        v = self.primary() if self.pos < len(self.text) and self.text[self.pos] in "[#" else self.number()
        if v != int(v) or not 1 <= v <= 5602:
            raise ExpressionError(at, f"parameter number {v:g} must be an integer from 1 to 5602")
        return int(v)

    def parameter_value(self) -> float:
        at = self.pos
        key = self.parameter_key()
        try:
            return self.read(key)
        except KeyError:
            shown = f"#<{key}>" if isinstance(key, str) else f"#{key}"
            raise ExpressionError(at, f"parameter {shown} is not set") from None
