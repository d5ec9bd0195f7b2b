"""RS274NGC / ISO-7bit interpreter: G-code text into a :class:`~jaxcnc.program.Program`.

The interpreter keeps the modal state (motion mode, plane, units, distance mode, feed, laser,
path-control mode) and executes each block's words in the RS274NGC order of execution. It
turns every supported word into its proper meaning and refuses everything else with a
:class:`~jaxcnc.errors.SourceError` naming ``file:line:column`` and the word — nothing is
silently ignored.

Supported here: G0 G1 G2 G3 (arcs in the G17/G18/G19 planes in IJK or R form, full circles, helices, P turns), G4,
G5 G5.1 G5.2/G5.3 G6.2 splines, G8, G9, G10 L2 (zero values), G17 G18 G19, G20 G21, G28, G40, G43 G43.1 G43.2 G49 (tool
offsets from the machine file's ``[tools]``), G53, G54–G59.3, G61 G61.1 G64 (P, Q), G80, G90 G91, G90.1 G91.1, G92
G92.1 G92.2 G92.3, G94, G97, G98 G99, F, S, T, M0 M1 M2 M30, M3 M4 M5, M6, M7 M8 M9, N, block delete, comments,
``%`` delimiters, and through the preprocessor parameters, expressions and O-word control flow. Codes that name
something jaxcnc cannot honour (canned cycles, spindle-synchronized motion, probing, writing the tool table, rotary
axes, ...) are refused with the reason.

Runs of plain motion blocks go through :mod:`jaxcnc.gcode.fastpath` in bulk, to the same result.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxcnc.blocks import BLOCK_KINDS, BlockCall, BlockKind, chain_error, g_word
from jaxcnc.blocks import Arc as BlockArc
from jaxcnc.blocks import Line as BlockLine
from jaxcnc.errors import SourceError
from jaxcnc.gcode import fastpath
from jaxcnc.gcode.dialect import LINUXCNC, Dialect, load_dialect
from jaxcnc.gcode.fastpath import PlainTable, RunResult, RunState, interpret_run, plain_table
from jaxcnc.gcode.lexer import MAX_COORDINATE, Word, shown_number, tokenize
from jaxcnc.gcode.preprocess import MAX_DEPTH, MAX_LINES, expand
from jaxcnc.gcode.splines import NurbsBlock, bezier_curve
from jaxcnc.program import (
    MIN_FEED_MM_S,
    PROGRAM_COLUMNS,
    Event,
    Kind,
    LaserMode,
    Program,
    make_curve_table,
    program_from_columns,
)

MM_PER_INCH = 25.4
#: Largest allowed difference between the start and end radius of an I/J/K arc, LinuxCNC's values
#: (mm programs; inch programs use the inch value); within it the centre is moved onto the chord's
#: bisector so the arc passes exactly through both end points.
ARC_RADIUS_TOL_MM = 2 * 0.01 * math.sqrt(2)
ARC_RADIUS_TOL_INCH = 2 * 0.001 * math.sqrt(2)
#: Most turns an arc's P word may ask for (each turn is a row of the program; a helix of more is a runaway).
MAX_ARC_TURNS = 10_000
#: Program axes (first, second, normal) of each arc plane; G18 is Z-X so that G3 is
#: counter-clockwise seen from +Y, as RS274NGC defines it.
PLANE_AXES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}

# G codes in tenths (G61.1 -> 611) -> modal group, as in the RS274NGC standard.
_G_GROUP = {
    0: 1,
    10: 1,
    20: 1,
    30: 1,
    40: 0,
    90: 0,  # G9 exact stop, this block only
    280: 0,
    170: 2,
    900: 3,
    910: 3,
    940: 5,
    200: 6,
    210: 6,
    400: 7,
    610: 13,
    611: 13,
    640: 13,
    50: 1,
    51: 1,
    52: 1,
    53: 1,
    62: 1,
    10010: 1,
    180: 2,
    190: 2,
    901: 4,
    911: 4,
    920: 0,
    921: 0,
    922: 0,
    923: 0,
    530: 0,
    430: 8,
    431: 8,
    432: 8,
    490: 8,
    540: 12,
    550: 12,
    560: 12,
    570: 12,
    580: 12,
    590: 12,
    591: 12,
    592: 12,
    593: 12,
    # words of CAM post headers
    80: 15,  # G8 lathe radius mode (the default)
    100: 0,  # G10 L2 (zero values only)
    800: 100,  # G80: its own group (on ISO controls G80 is in the canned-cycle group, apart from G0-G3)
    970: 14,  # G97 spindle speed in RPM (the default)
    980: 10,  # G98 / G99 canned-cycle return level
    990: 10,
}
_M_GROUP = {0: 4, 1: 4, 2: 4, 30: 4, 6: 6, 3: 7, 4: 7, 5: 7, 7: 8, 8: 8, 9: 8, 170: 16, 171: 16}
#: The external motion module (docs/scanner.md): M170 hands motion to the galvo scanner, M171 back to the stage.
EXTERNAL_ON, EXTERNAL_OFF = 170, 171
_CYCLE = "canned cycles are not supported: have the post write the cycle out as G0/G1 moves"
_LATHE_CYCLE = "lathe cycles are not supported"
_SPINDLE = "needs a spindle encoder, which a laser machine lacks"
_PROBE = "probing needs a probe input, which jaxcnc does not have"
_FANUC = "is not a LinuxCNC code and is not supported"
#: Why known G codes (tenths) are refused.
_REFUSED_G = {
    70: "G7 lathe diameter mode is not supported (G8, radius mode, is the only mode)",
    171: "G17.1 selects a plane of the U V W axes; jaxcnc plans X, Y and Z only",
    181: "G18.1 selects a plane of the U V W axes; jaxcnc plans X, Y and Z only",
    191: "G19.1 selects a plane of the U V W axes; jaxcnc plans X, Y and Z only",
    281: "G28.1 stores the home position; jaxcnc takes it from the caller (home=)",
    300: "G30 goes to the second home position, which is not configured (G28 goes home)",
    301: "G30.1 stores the second home position, which is not configured",
    330: f"G33 spindle-synchronized motion {_SPINDLE}",
    331: f"G33.1 rigid tapping {_SPINDLE}",
    382: f"G38.2 {_PROBE}",
    383: f"G38.3 {_PROBE}",
    384: f"G38.4 {_PROBE}",
    385: f"G38.5 {_PROBE}",
    410: "cutter compensation G41 is not supported yet",
    411: "cutter compensation G41.1 is not supported yet",
    420: "cutter compensation G42 is not supported yet",
    421: "cutter compensation G42.1 is not supported yet",
    500: f"G50 (scaling off on Fanuc mills, a spindle limit on lathes) {_FANUC}",
    510: f"G51 (scaling on Fanuc mills) {_FANUC}",
    520: "G52 local coordinate offsets are not supported (G92 is)",
    680: f"G68 (coordinate rotation on Fanuc) {_FANUC}",
    690: f"G69 (coordinate rotation off on Fanuc) {_FANUC}",
    700: f"G70 finishing cycle: {_LATHE_CYCLE}",
    710: f"G71 roughing cycle: {_LATHE_CYCLE}",
    711: f"G71.1 roughing cycle: {_LATHE_CYCLE}",
    720: f"G72 facing cycle: {_LATHE_CYCLE}",
    721: f"G72.1 facing cycle: {_LATHE_CYCLE}",
    730: f"G73 is a drilling cycle: {_CYCLE}",
    740: f"G74 is a tapping cycle: {_CYCLE}",
    760: f"G76 threading cycle {_SPINDLE}",
    **{c: f"G{c // 10} is a drilling or boring cycle: {_CYCLE}" for c in range(810, 900, 10)},
    930: "G93 inverse-time feed is not supported (G94, units per minute, is)",
    950: "G95 feed per revolution needs a spindle; use G94 (units per minute)",
    960: "G96 constant surface speed is a lathe spindle mode; here S is the laser power (G97)",
}
#: Why known M codes are refused.
_REFUSED_M = {
    19: "M19 spindle orientation needs a spindle; a laser machine has none",
    **{c: f"M{c} override control is not supported (a plan runs at 100 %)" for c in (48, 49, 50, 51, 52, 53)},
    60: "M60 pallet change is not supported",
    **{
        c: f"M{c} (Fanuc subprogram {what}) is not supported: have the post write the subprograms out (Fusion: "
        "'Use subroutines' off), or call LinuxCNC O-word subroutines (o100 call)"
        for c, what in ((98, "call"), (99, "return"))
    },
    61: "M61 (set the tool number without a change) is not supported; use T and M6",
    **{c: f"M{c} digital output is not supported: switch the laser with M3/M4/M5" for c in (62, 63, 64, 65)},
    66: "M66 waiting on an input is not supported",
    **{c: f"M{c} analog output is not supported: set the laser power with S" for c in (67, 68)},
    **{c: f"M{c} saving or restoring the modal state is not supported" for c in (70, 71, 72, 73)},
}
#: Why letters outside the supported words are refused.
_LETTER_REASONS = {
    **{a: "jaxcnc plans the X, Y and Z axes only" for a in "ABCUVW"},
    "D": "cutter compensation (G41/G42 with D) is not supported",
    "E": "E is not an RS274NGC word (3D printer extrusion?)",
}
_AXES = ("X", "Y", "Z")
_ALLOWED = set("GMFSTNPQXYZIJKRLH")
_MOTION_GROUP = 1


def _written_against(before: Word, w: Word) -> bool:
    """Word ``w`` follows ``before``'s number with nothing between them (``X1e3``: ``X1`` then ``E3``)."""
    return before.column + 1 + len(before.text) == w.column and before.text[-1:].isdigit()


def _block_kind(code: int, dialect: Dialect, block: _Block, w: Word) -> BlockKind | None:
    """The registered block kind of G code ``code`` (tenths), ``None`` when there is none; an error when its
    kind does not belong to ``dialect``."""
    word = g_word(code)
    if word not in BLOCK_KINDS:
        return None
    kind = BLOCK_KINDS.get(word)
    if kind.dialects is not None and dialect.name not in kind.dialects:
        raise block.error(
            w, f"{word} ({kind.name}) is not part of the {dialect.name} dialect (it is of: {', '.join(kind.dialects)})"
        )
    return kind


_SPLINE_CODES = (50, 51, 52, 62, 10010)
_SPLINE_NAMES = {50: "G5", 51: "G5.1", 52: "G5.2", 62: "G6.2", 10010: "BSPLINE"}
# A line that starts (after blanks and a block delete '/') with an O-word. This is what the expression
# ^\s*/?\s*[oO] finds in MULTILINE mode, written with a leading newline so that the search skips
# from line break to line break instead of trying every character.
_O_WORD_LEAD = r"[^\S\n]*/?[^\S\n]*[oO]"
_O_WORD_FIRST = re.compile(_O_WORD_LEAD)
_O_WORD_LINE = re.compile(r"\n" + _O_WORD_LEAD)


#: A Sinumerik program's name line (``%_N_PART_MPF``, ``_SPF`` for a subprogram), for dialects with ``program_names``.
_PROGRAM_NAME = re.compile(r"^[ \t]*%_N_\w+_(?:MPF|SPF)[ \t]*$", re.MULTILINE | re.IGNORECASE)


def _needs_preprocessor(text: str) -> bool:
    """The program has parameters, expressions or O-words (for :mod:`jaxcnc.gcode.preprocess`)."""
    return (
        "#" in text
        or "[" in text
        or "]" in text
        or _O_WORD_FIRST.match(text) is not None
        or _O_WORD_LINE.search(text) is not None
    )


@dataclass
class _State:
    pos: np.ndarray  # current position, mm
    scale: float = 1.0  # mm per program unit
    absolute: bool = True
    motion: int | None = None  # tenths: 0, 10, 20, 30
    feed_raw: float | None = None  # F as written, program units per minute
    power: float = 0.0
    laser: int = LaserMode.OFF
    tool: int = 0  # selected (T)
    loaded_tool: int = 0  # in the spindle (M6)
    exact_stop: bool = False  # G61.1
    blend_tol: float = math.inf  # G64 without P (LinuxCNC's start-up mode)
    pending_stop: bool = True
    plane: int = 17
    arc_absolute: bool = False  # G90.1: I J K are absolute centre coordinates
    g92: np.ndarray = field(default_factory=lambda: np.zeros(3))  # G92 offset (mm)
    g92_saved: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tool_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))  # G43 / G43.1 / G43.2 (mm), G49 zeroes it
    g5_last_pq: np.ndarray | None = None  # P, Q of the previous G5 (for tangent continuation)
    g80_line: int | None = None  # the G80 that left no motion mode (for error messages)
    nurbs: NurbsBlock | None = None  # a G5.2 / G6.2 curve being read
    curves: list = field(default_factory=list)
    rows: dict[str, list] = field(default_factory=lambda: {k: [] for k in PROGRAM_COLUMNS})


class _Block:
    """The words of one block, grouped, with a record of which ones were used."""

    def __init__(self, words: list[Word], file: str, line: int, dialect: Dialect = LINUXCNC):
        self.file, self.line = file, line
        self.g: list[tuple[int, Word]] = []
        self.m: list[tuple[int, Word]] = []
        self.vals: dict[str, Word] = {}
        self.used: set[str] = {"N"}
        self.kinds: dict[int, BlockKind] = {}  # the block's plug-in motion words (jaxcnc.blocks), by code
        g_groups: dict[int, Word] = {}
        m_groups: dict[int, Word] = {}
        for i, w in enumerate(words):
            if (
                w.letter not in _ALLOWED
                and w.letter not in dialect.addresses
                and not (w.letter == "D" and dialect.edge_offsets)
            ):
                why = _LETTER_REASONS.get(w.letter)
                if w.letter == "E" and i and _written_against(words[i - 1], w):
                    number = f"{words[i - 1].letter}{words[i - 1].text}"
                    why = (
                        f"exponent notation is not RS274NGC ({number}E{w.text} reads as {number} and E{w.text}): "
                        "write the number out"
                    )
                raise self.error(w, f"unsupported word {w.letter}{w.text}" + (f": {why}" if why else ""))
            if w.letter in "GM":
                if not abs(w.value) < 1e6:  # no G or M code is this large (and its tenths must stay an int)
                    raise self.error(w, f"unknown or unsupported word {w.letter}{shown_number(w.text)}")
                code = round(w.value * 10) if w.letter == "G" else round(w.value)
                exact = w.value * 10 if w.letter == "G" else w.value
                if w.letter == "G" and abs(exact - code) <= 1e-9 and code in dialect.g_codes:
                    code = dialect.g_codes[code]  # the dialect's word for one of ours (Sinumerik's G71: G21)
                    exact = float(code)
                table, groups = (_G_GROUP, g_groups) if w.letter == "G" else (_M_GROUP, m_groups)
                kind = None
                if w.letter == "G" and abs(exact - code) <= 1e-9 and code not in table:
                    kind = _block_kind(code, dialect, self, w)  # a plug-in's motion word, or None
                    if kind is not None:
                        self.kinds[code] = kind
                if kind is None and (abs(exact - code) > 1e-9 or code not in table):
                    why = None
                    if abs(exact - code) <= 1e-9:
                        why = (_REFUSED_G if w.letter == "G" else _REFUSED_M).get(code)
                        if w.letter == "M" and 100 <= code <= 199:
                            why = f"M{code} runs a user-defined program, which jaxcnc cannot follow"
                    raise self.error(w, why or f"unknown or unsupported word {w.letter}{w.text}")
                if w.letter == "G" and code in _SPLINE_NAMES and _SPLINE_NAMES[code] not in dialect.splines:
                    raise self.error(w, f"{_SPLINE_NAMES[code]} is not part of the {dialect.name} dialect")
                group = _MOTION_GROUP if kind is not None else table[code]
                if group in groups:
                    other = groups[group]
                    raise self.error(
                        w,
                        f"{w.letter}{w.text} and {other.letter}{other.text} are in the same modal group; one per block",
                    )
                groups[group] = w
                (self.g if w.letter == "G" else self.m).append((code, w))
            else:
                if w.letter in self.vals:
                    raise self.error(w, f"word {w.letter} appears twice in the block")
                self.vals[w.letter] = w
        if "N" in self.vals:
            n = self.vals["N"]
            if n.value < 0 or n.value != int(n.value):
                raise self.error(n, f"line number N{n.text} must be a non-negative integer")

    def error(self, w: Word | None, reason: str) -> SourceError:
        return SourceError(self.file, self.line, w.column if w else 0, reason)

    def has_g(self, code: int) -> Word | None:
        return next((w for c, w in self.g if c == code), None)

    def has_m(self, code: int) -> Word | None:
        return next((w for c, w in self.m if c == code), None)

    def take(self, letter: str) -> Word | None:
        w = self.vals.get(letter)
        if w is not None:
            self.used.add(letter)
        return w

    def axis_words(self) -> dict[int, Word]:
        return {i: self.vals[a] for i, a in enumerate(_AXES) if a in self.vals}

    def check_all_used(self) -> None:
        for letter, w in self.vals.items():
            if letter not in self.used:
                raise self.error(w, f"word {letter}{w.text} has no meaning in this block")


class _Interpreter:
    def __init__(
        self,
        file: str,
        start: np.ndarray,
        home: np.ndarray,
        dialect: Dialect = LINUXCNC,
        external: bool = False,
        tools: Mapping[int, Sequence[float]] | None = None,
    ):
        self.file, self.dialect = file, dialect
        self.tools = {int(k): np.asarray(v, dtype=np.float64) for k, v in (tools or {}).items()}
        self.external = external  # M170/M171 have a meaning: the machine has a stage and a galvo head
        self.external_at: tuple[np.ndarray, int] | None = None  # the stage's position and the M170 line, inside
        self.address = {meaning: name for name, meaning in dialect.addresses.items()}
        self.home = np.asarray(home, dtype=np.float64)
        self.s = _State(pos=np.asarray(start, dtype=np.float64).copy(), arc_absolute=dialect.arc_centers_absolute)
        self.ended = False
        self.machine_coords = False  # G53 in the current block
        self.chunks: list[dict[str, np.ndarray]] = []  # finished rows, as column arrays, in order

    # -- rows -------------------------------------------------------------------------------
    def emit(
        self,
        kind: Kind,
        line: int,
        end: np.ndarray | None = None,
        *,
        center=None,
        turn: int = 0,
        feed: float = math.nan,
        rapid: bool = False,
        dwell_s: float = 0.0,
        event: int = 0,
        event_value: int = 0,
        curve: int = -1,
        plane: int | None = None,
    ) -> None:
        s, r = self.s, self.s.rows
        end = s.pos if end is None else end
        r["kind"].append(int(kind))
        r["start"].append(s.pos.copy())
        r["end"].append(np.asarray(end, dtype=np.float64).copy())
        r["center"].append(np.full(3, np.nan) if center is None else np.asarray(center, dtype=np.float64))
        r["turn"].append(turn)
        r["feed"].append(feed)
        r["rapid"].append(rapid)
        r["laser"].append(s.laser)
        r["power"].append(s.power)
        r["dwell_s"].append(dwell_s)
        r["stop_before"].append(s.pending_stop or kind in (Kind.DWELL, Kind.EVENT))
        r["blend_tol"].append(0.0 if s.exact_stop else s.blend_tol)
        r["event"].append(event)
        r["event_value"].append(event_value)
        r["line"].append(line)
        r["curve"].append(curve)
        r["plane"].append(s.plane if plane is None else plane)
        s.pos = np.asarray(end, dtype=np.float64).copy()
        # Rows that stand still (dwell, events) leave the machine at rest for the next one, and so does a move
        # programmed under G61.1: the mode a move is programmed in says how it ends (LinuxCNC's termination
        # condition), not how the next one starts.
        s.pending_stop = kind in (Kind.DWELL, Kind.EVENT) or s.exact_stop

    # -- one block --------------------------------------------------------------------------
    def block(self, b: _Block) -> None:
        s = self.s
        if s.nurbs is not None and s.nurbs.kind == "BSPLINE":
            continues = not b.m and all(code == 10010 for code, _ in b.g) and bool(b.axis_words())
            if not continues or b.has_g(10010) is not None:
                self.finish_nurbs(b)
                if b.has_g(10010) is None and s.motion == 10010:
                    s.motion, s.g80_line = None, None
        # F, S, T
        if (w := b.take("F")) is not None:
            if w.value < 0:
                raise b.error(w, f"negative feed F{w.text}")
            s.feed_raw = w.value
        if (w := b.take("S")) is not None:
            if w.value < 0:
                raise b.error(w, f"negative power S{w.text}")
            s.power = w.value
        if (w := b.take("T")) is not None:
            if w.value < 0 or w.value != int(w.value):
                raise b.error(w, f"tool number T{w.text} must be a non-negative integer")
            s.tool = int(w.value)
        # M6 tool change: the motion stops, the tool is changed, the program goes on.
        if b.has_m(6) is not None:
            self.emit(Kind.EVENT, b.line, event=Event.TOOL_CHANGE, event_value=s.tool)
            s.loaded_tool = s.tool
        # M3/M4/M5: the laser is switched at rest (like a spindle, motion waits for it).
        for code, mode in ((3, LaserMode.CONSTANT), (4, LaserMode.DYNAMIC), (5, LaserMode.OFF)):
            if b.has_m(code) is not None and s.laser != mode:
                s.laser = mode
                s.pending_stop = True
        for code in (EXTERNAL_ON, EXTERNAL_OFF):
            if (w := b.has_m(code)) is not None:
                self.external_switch(b, w, code == EXTERNAL_ON)
        # G4 dwell
        if (g4 := b.has_g(40)) is not None:
            p = b.take("P")
            if p is None:
                raise b.error(g4, "G4 needs P (dwell time in seconds)")
            if p.value < 0:
                raise b.error(p, f"negative dwell time P{p.text}")
            self.emit(Kind.DWELL, b.line, dwell_s=p.value)
        # coolant (assist gas on a laser): an event at rest
        for code in (7, 8, 9):
            if b.has_m(code) is not None:
                self.emit(Kind.EVENT, b.line, event=Event.COOLANT, event_value=code)
        # planes, units, G40 (no compensation is ever active: nothing to do)
        for code, plane in ((170, 17), (180, 18), (190, 19)):
            if b.has_g(code) is not None:
                s.plane = plane
        if b.has_g(200) is not None:
            s.scale = MM_PER_INCH
        if b.has_g(210) is not None:
            s.scale = 1.0
        # path control
        if b.has_g(610) is not None:
            s.exact_stop, s.blend_tol = False, 0.0
        if b.has_g(611) is not None:
            s.exact_stop, s.blend_tol = True, 0.0
        if b.has_g(640) is not None:
            s.exact_stop = False
            p, q = b.take("P"), b.take("Q")
            for w in (p, q):
                if w is not None and w.value < 0:
                    raise b.error(w, f"negative tolerance {w.letter}{w.text}")
            s.blend_tol = p.value * s.scale if p is not None else math.inf
        # tool offsets (G43 H, G43.2 H; G43.1 and G43.2 with axis words take them below, with the axis words)
        if (g43 := b.has_g(430)) is not None:
            s.tool_offset = self.tool_row(b, b.take("H"), g43)
        if b.has_g(490) is not None:
            s.tool_offset = np.zeros(3)
        if (d := b.take("D")) is not None:  # (only where the dialect has D select a cutting edge's offsets)
            s.tool_offset = self.edge_row(b, d)
        # arc centre mode
        if b.has_g(901) is not None:
            s.arc_absolute = True
        if b.has_g(911) is not None:
            s.arc_absolute = False
        # distance mode
        if b.has_g(900) is not None:
            s.absolute = True
        if b.has_g(910) is not None:
            s.absolute = False
        # G8 (lathe radius mode), G97 (spindle RPM mode) and G98/G99 (canned-cycle return level) name
        # the only modes there are: accepted, they change nothing. So does G40 (no compensation is
        # ever active) and selecting a work coordinate system G54-G59.3: no offsets can be set
        # (G10 L2 only to zero), so each is the machine system.
        # motion mode; G80 (cancel canned cycle: none ever runs) also cancels the motion mode, as in
        # LinuxCNC, unless the block names one (the "G0 G17 G40 G49 G80 G90" of ISO post headers).
        motion_word = None
        for code in (0, 10, 20, 30, *_SPLINE_CODES, *b.kinds, 800):
            if (w := b.has_g(code)) is not None and (code != 800 or motion_word is None):
                if s.nurbs is not None and s.nurbs.kind == "G5.2" and code != 52:
                    raise b.error(w, f"G5.2 NURBS opened at line {s.nurbs.line} is not closed with G5.3")
                if s.nurbs is not None and s.nurbs.kind == "G6.2" and not s.nurbs.complete and code != 62:
                    nb = s.nurbs
                    raise b.error(
                        w,
                        f"G6.2 NURBS opened at line {nb.line} is incomplete: {len(nb.knots)} knots, "
                        f"{len(nb.points) + nb.order} needed",
                    )
                if code == 800:
                    s.motion, s.g80_line = None, b.line
                else:
                    s.motion, motion_word = code, w
        axes = b.axis_words()
        for letter in _AXES:
            b.take(letter)
        # G10, G92, G43.1 and G43.2 take the block's axis words for themselves (none moves); then the M words
        # below still act ("G92 X0 M2")
        if (g10 := b.has_g(100)) is not None:
            self.g10(b, g10, axes, motion_word)
        elif (g431 := b.has_g(431)) is not None:
            self.g43_axes(b, g431, axes, motion_word, dynamic=True)
        elif (g432 := b.has_g(432)) is not None:
            self.g43_axes(b, g432, axes, motion_word, dynamic=False)
        elif (g92 := b.has_g(920)) is not None:
            if not axes:
                raise b.error(g92, "G92 needs axis words")
            if motion_word is not None:
                raise b.error(g92, "G92 and a motion G code in one block both claim the axis words")
            for k, w in axes.items():  # the current position now reads as the given value (under the tool offset)
                s.g92[k] = s.pos[k] - w.value * s.scale - s.tool_offset[k]
        else:
            rows = len(s.rows["kind"])
            self.move(b, axes, motion_word)
            if b.has_g(90) is not None and len(s.rows["kind"]) > rows:
                # G9: this block's motion ends at rest and its end is not blended — as a move programmed under
                # G61.1, for this block alone (its last row: an arc's P turns run on into one another)
                s.rows["blend_tol"][-1] = 0.0
                s.pending_stop = True
        # stops and end
        for code, ev in (
            (0, Event.PROGRAM_STOP),
            (1, Event.OPTIONAL_STOP),
            (2, Event.PROGRAM_END),
            (30, Event.PROGRAM_END),
        ):
            if b.has_m(code) is not None:
                self.emit(Kind.EVENT, b.line, event=ev)
                if ev == Event.PROGRAM_END:
                    self.ended = True
        b.check_all_used()

    def external_switch(self, b: _Block, w: Word, enter: bool) -> None:
        """M170: motion goes to the galvo scanner (the stage waits where it is; the program's X Y Z stay the tool
        point, the beam starts at the field's centre); M171: back to the stage, the beam returning (dark) to
        the field's centre, so the program continues from where the stage waited. A row EXTERNAL marks each."""
        s = self.s
        if not self.external:
            raise b.error(
                w, f"M{w.text} switches motion to a galvo scanner (the external motion module): only on a machine "
                "with a stage and a [galvo] head with beam axes (docs/scanner.md)",
            )  # fmt: skip
        if b.axis_words() or b.has_g(0) or b.has_g(10) or b.has_g(20) or b.has_g(30):
            raise b.error(w, f"M{w.text} stands in a block without motion (the switch happens at rest)")
        if enter and self.external_at is not None:
            raise b.error(w, f"M170: motion is on the scanner already (since line {self.external_at[1]})")
        if not enter and self.external_at is None:
            raise b.error(w, "M171 without M170: motion is on the stage")
        if enter:
            self.external_at = (s.pos.copy(), b.line)
        else:
            if not np.array_equal(s.pos, self.external_at[0]):
                self.emit(Kind.LINE, b.line, self.external_at[0], rapid=True)  # the beam back to the centre
            self.external_at = None
        self.emit(Kind.EVENT, b.line, event=Event.EXTERNAL, event_value=int(enter))

    def move(self, b: _Block, axes: dict[int, Word], motion_word: Word | None) -> None:
        """The block's G92.1-G92.3, then what moves: G53, G5.3, a spline point, G28, a line or an arc."""
        s = self.s
        for code in (921, 922):
            if b.has_g(code) is not None:
                if code == 922:
                    s.g92_saved = s.g92.copy()
                s.g92 = np.zeros(3)
        if b.has_g(923) is not None:
            s.g92 = s.g92_saved.copy()
        self.machine_coords = (g53w := b.has_g(530)) is not None
        if self.machine_coords and (s.motion not in (0, 10) or not axes):
            raise b.error(g53w, "G53 needs G0 or G1 and axis words")
        if (g53 := b.has_g(53)) is not None:
            if s.nurbs is None or s.nurbs.kind != "G5.2":
                raise b.error(g53, "G5.3 without an open G5.2 NURBS")
            if axes:
                raise b.error(next(iter(axes.values())), "G5.3 takes no axis words")
            self.finish_nurbs(b)
            s.motion, s.g80_line = None, None
        elif s.motion in _SPLINE_CODES and (
            axes or motion_word is not None or (s.motion == 62 and s.nurbs is not None and "K" in b.vals)
        ):
            self.spline(b, axes, motion_word)
        elif (g28 := b.has_g(280)) is not None:
            if motion_word is not None and axes:
                raise b.error(g28, "G28 and a motion G code in one block both claim the axis words")
            self.home_move(b, axes)
        elif axes:
            if s.motion is None:
                w = next(iter(axes.values()))
                if b.has_g(800) is not None:
                    raise b.error(w, "G80 cancels the motion mode: axis words need G0/G1/G2/G3 in the block")
                after = f" (G80 at line {s.g80_line} cancelled it)" if s.g80_line is not None else ""
                raise b.error(w, f"axis words with no motion mode (G0/G1/G2/G3) in effect{after}")
            self.motion(b, axes, motion_word)
        elif s.motion in (20, 30) and (motion_word is not None or any(c in b.vals for c in "IJK")):
            # an arc without end point words ends where it starts: a full circle ("G2 I5", as LinuxCNC)
            self.motion(b, axes, motion_word)

    @property
    def offset(self) -> np.ndarray:
        """Program → machine coordinates: the G92 offset plus the tool offset (work offsets G54–G59.3 are zero).

        As in LinuxCNC, a new tool offset moves nothing by itself: the position reads differently, the next
        absolute coordinate of an axis is reached at its new machine position, an incremental one from where the
        axis is."""
        return self.s.g92 + self.s.tool_offset

    def tool_row(self, b: _Block, h: Word | None, g: Word) -> np.ndarray:
        """The tool table's offsets ``(3,)`` (mm) of tool ``H`` (without ``H``: the tool M6 loaded; 0: none)."""
        if h is not None and (h.value != int(h.value) or h.value < 0):
            raise b.error(h, f"H{h.text}: a tool number is a non-negative integer")
        number = int(h.value) if h is not None else self.s.loaded_tool
        if number == 0:
            return np.zeros(3)
        what = f"H{h.text}" if h is not None else f"G{g.text} without H (the loaded tool T{number})"
        return self.table_row(b, h if h is not None else g, number, f"{what}: tool {number}", "H0 or G49")

    def table_row(self, b: _Block, word: Word, number: int, who: str, cancel: str) -> np.ndarray:
        """Tool ``number``'s offsets ``(3,)`` from the tool table, or the error at ``word``: ``who`` has no offsets
        (what the table has; ``cancel``: the words for no offset)."""
        if number not in self.tools:
            have = ", ".join(str(k) for k in sorted(self.tools)[:8]) + ("..." if len(self.tools) > 8 else "")
            where = f"the machine file's [tools] has {have}" if self.tools else "the machine file has no [tools] table"
            raise b.error(word, f"{who} has no offsets ({where}; {cancel}: no offset)")
        return self.tools[number].copy()

    def edge_row(self, b: _Block, d: Word) -> np.ndarray:
        """Sinumerik's ``D<n>``: the offsets ``(3,)`` of cutting edge ``n`` of the selected tool ``T`` (the machine
        file's tool table has one edge a tool, ``D1``); ``D0`` none."""
        if d.value == 0:
            return np.zeros(3)
        if d.value != 1:
            raise b.error(d, f"D{d.text}: the machine file's [tools] gives each tool one cutting edge (D1; D0: none)")
        if self.s.tool == 0:
            raise b.error(d, "D1 selects a cutting edge of the selected tool, and no tool is selected (T)")
        return self.table_row(b, d, self.s.tool, f"D1: tool T{self.s.tool}", "D0")

    def g43_axes(self, b: _Block, g: Word, axes: dict[int, Word], motion_word: Word | None, dynamic: bool) -> None:
        """G43.1 (the axis words are the tool offsets, in program units) and G43.2 (adds tool ``H``'s offsets, or
        the axis words, to those in effect), as LinuxCNC 2.9."""
        s = self.s
        if motion_word is not None and axes:
            raise b.error(g, f"G{g.text} and a motion G code in one block both claim the axis words")
        h = b.take("H")
        if dynamic:
            if h is not None:
                raise b.error(h, "G43.1 takes axis words, not H (G43 H applies the tool table)")
            if not axes:
                raise b.error(g, "G43.1 needs axis words: the tool offsets (e.g. G43.1 Z2.5)")
            for k, w in axes.items():
                s.tool_offset[k] = w.value * s.scale
            return
        if h is None and not axes:
            raise b.error(g, "G43.2 adds the offsets of a tool (H) or those given as axis words: it needs one")
        if h is not None:
            s.tool_offset = s.tool_offset + self.tool_row(b, h, g)
        for k, w in axes.items():
            s.tool_offset[k] += w.value * s.scale

    def g10(self, b: _Block, g10: Word, axes: dict[int, Word], motion_word: Word | None) -> None:
        """G10 L2: set a coordinate system's offsets and rotation — only to the zero they have.

        Work offsets are not kept (G54-G59.3 all equal the machine system), so a G10 L2 that sets
        zeros, as post headers and LinuxCNC's tests write it ("G10 L2 P0 R0"), changes nothing and
        is accepted; any other value, L20 (offsets from the current point) and the tool-table forms
        L1/L10/L11 are refused.
        """
        if motion_word is not None and axes:
            raise b.error(g10, "G10 and a motion G code in one block both claim the axis words")
        l_word, p, r = b.take("L"), b.take("P"), b.take("R")
        if l_word is None:
            raise b.error(g10, "G10 needs L (L2: coordinate system offsets)")
        if l_word.value in (1, 10, 11):
            raise b.error(
                l_word, f"G10 L{l_word.text} writes the tool table, which is the machine file's [tools] (read-only)"
            )
        if l_word.value == 20:
            raise b.error(l_word, "G10 L20 sets a work offset from the current point; work offsets are not supported")
        if l_word.value != 2:
            raise b.error(l_word, f"G10 L{l_word.text} is not a G10 form (L2 sets coordinate system offsets)")
        if p is None:
            raise b.error(g10, "G10 L2 needs P (0: the active system, 1-9: G54-G59.3)")
        if p.value != int(p.value) or not 0 <= p.value <= 9:
            raise b.error(p, f"G10 L2 P{p.text}: P is 0 (the active system) or 1-9 (G54-G59.3)")
        for w in (*axes.values(), r):
            if w is not None and w.value != 0:
                what = "rotation" if w.letter == "R" else "offset"
                raise b.error(
                    w,
                    f"G10 L2 {w.letter}{w.text}: a coordinate system {what} other than zero is not supported "
                    "(G54-G59.3 all equal the machine system)",
                )

    def target(self, axes: dict[int, Word]) -> np.ndarray:
        s = self.s
        t = s.pos.copy()
        for i, w in axes.items():
            if self.machine_coords:  # G53: machine coordinates, absolute
                t[i] = w.value * s.scale
            elif s.absolute:
                t[i] = w.value * s.scale + self.offset[i]
            else:
                t[i] = s.pos[i] + w.value * s.scale
        return t

    def feed_mm_s(self, b: _Block, w: Word) -> float:
        if self.s.feed_raw is None:
            return math.nan  # the machine file's default contour feed applies
        if self.s.feed_raw == 0:
            raise b.error(w, "feed rate is zero (set F before feed moves)")
        feed = self.s.feed_raw * self.s.scale / 60.0
        if not math.isfinite(feed):
            raise b.error(w, f"feed rate F{self.s.feed_raw:g} overflows a double in mm/s")
        if feed < MIN_FEED_MM_S:
            raise b.error(
                w,
                f"feed rate F{self.s.feed_raw:.3g} ({feed:.3g} mm/s) is below physical sense: the slowest feed is "
                f"{MIN_FEED_MM_S:g} mm/s, one micrometre in 1000 s",
            )
        return feed

    def home_move(self, b: _Block, axes: dict[int, Word]) -> None:
        """G28: rapid to the optional intermediate point, then the named axes (all if none) home."""
        if axes:
            mid = self.target(axes)
            self.emit(Kind.LINE, b.line, mid, rapid=True)
            dest = self.s.pos.copy()
            for i in axes:
                dest[i] = self.home[i]
        else:
            dest = self.home.copy()
        self.emit(Kind.LINE, b.line, dest, rapid=True)

    def motion(self, b: _Block, axes: dict[int, Word], motion_word: Word | None) -> None:
        s = self.s
        end = self.target(axes)
        first = motion_word or next(iter(axes.values()), None) or next(b.vals[c] for c in "IJK" if c in b.vals)
        if s.motion == 0:
            self.emit(Kind.LINE, b.line, end, rapid=True)
        elif s.motion == 10:
            self.emit(Kind.LINE, b.line, end, feed=self.feed_mm_s(b, first))
        elif s.motion in (20, 30):
            self.arc(b, end, first, cw=s.motion == 20)
        else:
            self.kind_block(b, end, first)

    def kind_block(self, b: _Block, end: np.ndarray, first: Word) -> None:
        """A block of a registered kind (:mod:`jaxcnc.blocks`): its pieces emitted as the block's rows."""
        s = self.s
        word = g_word(s.motion)
        kind = BLOCK_KINDS.get(word)
        params = {}
        for letter in kind.letters:
            if (p := b.take(letter)) is not None:
                params[letter] = p.value * (s.scale if letter in kind.lengths else 1.0)
        call = BlockCall(word, s.pos.copy(), end.copy(), params, s.plane, self.dialect.name)
        try:
            pieces = kind.lower(call)
        except ValueError as exc:
            raise b.error(first, f"{word}: {exc}") from None
        except Exception as exc:  # a plug-in's own failure: one line naming it
            if (err := BLOCK_KINDS.failed(word, exc)) is None:
                raise
            raise err from None
        gap = chain_error(pieces, call.start_mm, end) if pieces else float(np.linalg.norm(end - call.start_mm))
        if gap > 1e-9:
            raise b.error(
                first,
                f"{word} ({kind.name}): its pieces do not join the block's start to its end "
                f"(gap {gap:.3g} mm; a fault of the block kind)",
            )
        feed = self.feed_mm_s(b, first)
        for p in pieces:
            if isinstance(p, BlockLine):
                self.emit(Kind.LINE, b.line, p.end_mm, feed=feed)
            elif isinstance(p, BlockArc):
                self.emit(Kind.ARC, b.line, p.end_mm, center=p.center_mm, turn=p.turn, feed=feed, plane=p.plane)
            else:
                curve = (p.degree, p.points_mm, p.weights, p.knots)
                try:
                    make_curve_table([curve])
                except ValueError as exc:
                    raise b.error(first, f"{word} ({kind.name}): {str(exc).removeprefix('curve 0: ')}") from None
                s.curves.append(curve)
                self.emit(Kind.CURVE, b.line, p.end_mm, feed=feed, curve=len(s.curves) - 1)

    def arc(self, b: _Block, end_prog: np.ndarray, first: Word, cw: bool) -> None:
        """G2/G3 in the active plane; motion along the plane's normal makes a helix."""
        s = self.s
        perm = PLANE_AXES[s.plane]  # (first, second, normal) program axes of the plane
        names = "".join("XYZ"[a] for a in perm[:2])
        offs = "".join("IJK"[a] for a in perm[:2])
        start = s.pos[list(perm)]
        end = end_prog[list(perm)]
        words = {letter: b.take(letter) for letter in "IJK"}
        r = b.take("R")
        # P: the number of turns (a P of G4 or G64 in the same block is theirs)
        p = b.take("P") if b.has_g(40) is None and b.has_g(640) is None else None
        if p is not None and (p.value != int(p.value) or not 1 <= p.value <= MAX_ARC_TURNS):
            raise b.error(p, f"arc turns P{shown_number(p.text)} must be a positive integer of at most {MAX_ARC_TURNS}")
        turns = 1 if p is None else int(p.value)
        normal_offset = words["IJK"[perm[2]]]
        if normal_offset is not None:
            raise b.error(
                normal_offset, f"{normal_offset.letter} has no meaning for an arc in the {names} plane (G{s.plane})"
            )
        i, j = words[offs[0]], words[offs[1]]
        if r is not None and (i is not None or j is not None):
            raise b.error(r, f"arc given both R and {offs[0]}/{offs[1]}; use one form")
        chord = end[:2] - start[:2]
        d = float(np.hypot(*chord))
        tol = ARC_RADIUS_TOL_MM if s.scale == 1.0 else ARC_RADIUS_TOL_INCH * MM_PER_INCH
        if r is not None:
            radius = abs(r.value) * s.scale
            if d < 1e-9:
                raise b.error(r, f"R-form arc with end point equal to start: a full circle needs {offs[0]}/{offs[1]}")
            if radius == 0:
                raise b.error(r, "arc radius R is zero")
            half = d / 2
            if half > radius + tol:
                raise b.error(r, f"arc radius {radius:g} mm is smaller than half the chord {half:g} mm")
            h = math.sqrt(max(radius * radius - half * half, 0.0))
            n_left = np.array([-chord[1], chord[0]]) / d  # left of the travel direction
            # Short arcs (R > 0) have the centre on the side they turn towards; long ones opposite.
            side = (-1.0 if cw else 1.0) * (1.0 if r.value > 0 else -1.0)
            c2 = (start[:2] + end[:2]) / 2 + side * h * n_left
        else:
            if i is None and j is None:
                raise b.error(first, f"arc needs {offs[0]}/{offs[1]} (centre) or R (radius)")
            if s.arc_absolute:  # G90.1: I J K are the centre's coordinates
                c2 = np.array(
                    [
                        i.value * s.scale + self.offset[perm[0]] if i else start[0],
                        j.value * s.scale + self.offset[perm[1]] if j else start[1],
                    ]
                )
            else:
                c2 = start[:2] + np.array([i.value if i else 0.0, j.value if j else 0.0]) * s.scale
            r1 = float(np.hypot(*(start[:2] - c2)))
            r2 = float(np.hypot(*(end[:2] - c2)))
            if r1 < 1e-9:
                raise b.error(i or j, "arc centre coincides with its start point (radius zero)")
            if abs(r1 - r2) > tol:
                raise b.error(
                    i or j,
                    f"radius to end {r2:.6g} mm differs from radius to start {r1:.6g} mm by "
                    f"{abs(r1 - r2):.3g} mm (tolerance {tol:.4g} mm)",
                )
            if d > 1e-9:
                # Move the centre onto the chord's perpendicular bisector: the arc then passes
                # exactly through both programmed points (a shift of at most the tolerance).
                # (Written out rather than np.dot, whose BLAS kernel may fuse the multiply-add: the bulk
                # path in fastpath.py computes the same expression element by element, bit for bit.)
                mid = (start[:2] + end[:2]) / 2
                n = np.array([-chord[1], chord[0]]) / d
                off = c2 - mid
                c2 = mid + float(off[0] * n[0] + off[1] * n[1]) * n
        feed, turn = self.feed_mm_s(b, first), -1 if cw else 1
        if turns > 1:
            # P turns: P - 1 full circles, then the arc, the motion along the normal shared out in
            # proportion to the angle turned (LinuxCNC's helix of P turns)
            a_s = math.atan2(start[1] - c2[1], start[0] - c2[0])
            a_e = math.atan2(end[1] - c2[1], end[0] - c2[0])
            sweep = 2 * math.pi if d < 1e-9 else ((a_s - a_e) if cw else (a_e - a_s)) % (2 * math.pi)
            total = sweep + 2 * math.pi * (turns - 1)
            z0, rise = start[2], end[2] - start[2]
            for k in range(1, turns):
                circle_end = s.pos.copy()
                circle_end[perm[2]] = z0 + rise * (2 * math.pi * k / total)
                center = np.empty(3)
                center[list(perm)] = [c2[0], c2[1], s.pos[perm[2]]]
                self.emit(Kind.ARC, b.line, circle_end, center=center, turn=turn, feed=feed)
        center = np.empty(3)
        center[list(perm)] = [c2[0], c2[1], s.pos[perm[2]]]
        self.emit(Kind.ARC, b.line, end_prog, center=center, turn=turn, feed=feed)

    # -- splines -------------------------------------------------------------------------------
    def spline(self, b: _Block, axes: dict[int, Word], motion_word: Word | None) -> None:
        s = self.s
        first = motion_word or next(iter(axes.values()), None) or b.vals["K"]
        if 2 in axes:
            raise b.error(axes[2], "spline blocks move X and Y only (Z is not allowed)")
        if s.motion in (50, 51):
            self.bezier(b, axes, first, cubic=s.motion == 50)
        elif s.motion == 10010:
            self.bspline(b, axes, motion_word, first)
        elif s.motion == 52:
            self.g52(b, axes, motion_word, first)
        else:
            self.g62(b, axes, motion_word, first)

    def _xy(self, b: _Block, letters: str) -> np.ndarray | None:
        """The offset ``(I, J)`` or ``(P, Q)`` in mm (None when both are absent)."""
        w1, w2 = b.take(letters[0]), b.take(letters[1])
        if w1 is None and w2 is None:
            return None
        if w1 is None or w2 is None:
            w = w1 or w2
            raise b.error(w, f"{letters[0]} and {letters[1]} go together; only {w.letter} is given")
        for w in (w1, w2):
            if abs(w.value) > MAX_COORDINATE:
                raise b.error(w, f"{w.letter}{shown_number(w.text)} is beyond ±{MAX_COORDINATE:g}: farther than any "
                              "machine travels (a control point offset)")  # fmt: skip
        return np.array([w1.value, w2.value, 0.0]) * self.s.scale

    def bezier(self, b: _Block, axes: dict[int, Word], first: Word, cubic: bool) -> None:
        s = self.s
        if not axes:
            raise b.error(first, "spline needs its end point (X and/or Y)")
        end = self.target(axes)
        p0 = s.pos.copy()
        ij = self._xy(b, "IJ")
        if cubic:
            pq = self._xy(b, "PQ")
            if pq is None:
                raise b.error(first, "G5 needs P and Q (second control point relative to the end)")
            if ij is None:
                if s.g5_last_pq is None:
                    raise b.error(first, "the first G5 of a series needs I and J")
                ij = -s.g5_last_pq
            pts = np.stack([p0, p0 + ij, end + pq, end])
            s.g5_last_pq = pq
        else:
            if ij is None or not np.any(ij):
                raise b.error(first, "G5.1 needs a non-zero I, J (control point relative to the start)")
            pts = np.stack([p0, p0 + ij, end])
        self.add_curve(b, first, bezier_curve(pts), end)

    def g52(self, b: _Block, axes: dict[int, Word], motion_word: Word | None, first: Word) -> None:
        s = self.s
        p, order = b.take("P"), b.take("L")
        if p is not None and p.value <= 0:
            raise b.error(p, f"NURBS weight P{p.text} must be positive")
        if s.nurbs is None:
            if motion_word is None:
                raise b.error(first, "control point outside a G5.2 NURBS block")
            k = 3 if order is None else order.value
            if k != int(k) or not 2 <= k <= 8:
                raise b.error(order, f"NURBS order L{order.text} must be an integer from 2 to 8")
            s.nurbs = NurbsBlock("G5.2", b.line, motion_word.column, int(k), [s.pos.copy()], [1.0])
            if not axes:  # "G5.2 P-": the weight of the first control point (the current position)
                if p is not None:
                    s.nurbs.weights[0] = p.value
                return
        elif order is not None:
            if len(s.nurbs.points) > 1:
                raise b.error(order, "the order L is given before the second control point only")
            if order.value != int(order.value) or not 2 <= order.value <= 8:
                raise b.error(order, f"NURBS order L{order.text} must be an integer from 2 to 8")
            s.nurbs.order = int(order.value)
        if not axes:
            raise b.error(first, "G5.2 block without a control point")
        s.nurbs.points.append(self.target(axes))
        s.nurbs.weights.append(1.0 if p is None else p.value)
        s.pos = s.nurbs.points[-1].copy()  # incremental coordinates continue from the last point

    def bspline(self, b: _Block, axes: dict[int, Word], motion_word: Word | None, first: Word) -> None:
        """Siemens BSPLINE: one control point per block (see :mod:`jaxcnc.gcode.splines`)."""
        s = self.s
        pw, sd, pl = (
            b.take(self.address[m]) if m in self.address else None for m in ("weight", "degree", "knot_interval")
        )
        if s.nurbs is None:
            degree = 3 if sd is None else sd.value
            if degree != int(degree) or not 1 <= degree <= 7:
                raise b.error(sd, f"spline degree {sd.letter}={sd.text} must be an integer from 1 to 7")
            s.nurbs = NurbsBlock("BSPLINE", b.line, first.column, int(degree) + 1, [s.pos.copy()], [1.0])
        elif sd is not None:
            raise b.error(sd, f"the degree {sd.letter}= is given on the first BSPLINE block only")
        if not axes:
            raise b.error(first, "BSPLINE block without a point")
        if pw is not None and pw.value <= 0:
            raise b.error(pw, f"point weight {pw.letter}={pw.text} must be positive")
        if pl is not None and pl.value < 0:
            raise b.error(pl, f"knot interval {pl.letter}={pl.text} must not be negative")
        given = [v is not None for v in s.nurbs.knots]
        if given and given[0] != (pl is not None):
            raise b.error(pl or first, "give the knot interval on every BSPLINE block or on none")
        s.nurbs.points.append(self.target(axes))
        s.nurbs.weights.append(1.0 if pw is None else pw.value)
        s.nurbs.knots.append(None if pl is None else pl.value)
        s.pos = s.nurbs.points[-1].copy()

    def g62(self, b: _Block, axes: dict[int, Word], motion_word: Word | None, first: Word) -> None:
        s = self.s
        p, k, r, q = b.take("P"), b.take("K"), b.take("R"), b.take("Q")
        if s.nurbs is None or s.nurbs.complete:
            if p is None:
                raise b.error(first, "G6.2 starts a NURBS with P (order)")
            if p.value != int(p.value) or not 2 <= p.value <= 8:
                raise b.error(p, f"NURBS order P{p.text} must be an integer from 2 to 8")
            if q is not None and q.value != 1:
                raise b.error(q, f"G6.2 Q{q.text} is not supported (only Q1)")
            s.nurbs = NurbsBlock("G6.2", b.line, first.column, int(p.value), start=s.pos.copy())
        elif p is not None or q is not None:
            raise b.error(p or q, "P and Q are given on the first G6.2 block only")
        if k is None:
            raise b.error(first, "each G6.2 block needs its knot K")
        if s.nurbs.knots and k.value < s.nurbs.knots[-1]:
            raise b.error(k, f"knot K{k.text} is smaller than the previous knot {s.nurbs.knots[-1]:g}")
        s.nurbs.knots.append(k.value)
        if axes:
            if len(s.nurbs.knots) > len(s.nurbs.points) + 1:
                raise b.error(first, "control point after the trailing knot-only G6.2 blocks")
            if r is not None and r.value <= 0:
                raise b.error(r, f"NURBS weight R{r.text} must be positive")
            s.nurbs.points.append(self.target(axes))
            s.nurbs.weights.append(1.0 if r is None else r.value)
            if len(s.nurbs.points) == 1 and np.linalg.norm(s.nurbs.points[0] - s.nurbs.start) > 1e-6:
                raise b.error(
                    first, "a G6.2 NURBS starts at its first control point: program it at the current position"
                )
            s.pos = s.nurbs.points[-1].copy()
        elif r is not None:
            raise b.error(r, "weight R without a control point")
        if s.nurbs.complete:
            s.pos = s.nurbs.start
            self.finish_nurbs(b)

    def finish_nurbs(self, b: _Block) -> None:
        s = self.s
        nb = s.nurbs
        s.nurbs = None
        if nb.kind in ("G5.2", "BSPLINE"):
            s.pos = nb.points[0].copy()
        if len(nb.points) < nb.order:
            raise SourceError(
                self.file,
                nb.line,
                nb.column,
                f"{nb.kind} NURBS of order {nb.order} needs at least {nb.order} control points, got {len(nb.points)}",
            )
        self.add_curve(b, None, nb.curve(), nb.points[-1], line=nb.line, column=nb.column)

    def add_curve(
        self,
        b: _Block,
        word: Word | None,
        curve: tuple,
        end: np.ndarray,
        line: int | None = None,
        column: int | None = None,
    ) -> None:
        try:
            make_curve_table([curve])
        except ValueError as exc:
            msg = str(exc).removeprefix("curve 0: ")
            raise SourceError(self.file, line or b.line, column or (word.column if word else 0), msg) from None
        s = self.s
        s.curves.append(curve)
        feed = self.feed_mm_s(b, word) if b is not None else math.nan
        self.emit(Kind.CURVE, line or b.line, end, feed=feed, curve=len(s.curves) - 1)

    def close(self, b: _Block | None) -> None:
        """End of the program text: a BSPLINE ends here; nothing else may be left open."""
        if self.external_at is not None:
            raise SourceError(self.file, self.external_at[1], 0, "M170 hands motion to the scanner; no M171 follows")
        nb = self.s.nurbs
        if nb is not None and nb.kind == "BSPLINE":
            self.finish_nurbs(b)
            return
        if nb is not None and not (nb.kind == "G6.2" and nb.complete):
            what = (
                "is not closed with G5.3"
                if nb.kind == "G5.2"
                else (
                    f"has {len(nb.knots)} knots; {len(nb.points)} control points of order {nb.order} need "
                    f"{len(nb.points) + nb.order}"
                )
            )
            raise SourceError(self.file, nb.line, nb.column, f"{nb.kind} NURBS {what}")

    def flush_rows(self) -> None:
        """Move the rows emitted one by one into :attr:`chunks` (before a run's rows follow them)."""
        r = self.s.rows
        if not r["kind"]:
            return
        out = {k: np.asarray(v) for k, v in r.items()}
        for k in ("start", "end", "center"):
            out[k] = np.asarray(r[k], dtype=np.float64).reshape(-1, 3)
        self.chunks.append(out)
        self.s.rows = {k: [] for k in PROGRAM_COLUMNS}

    # -- runs of plain blocks (fastpath.py) ---------------------------------------------------
    def fast_ready(self) -> bool:
        """Plain blocks can be executed in bulk from here (no spline is open or modal)."""
        s = self.s
        return s.nurbs is None and s.motion in (None, 0, 10, 20, 30)

    def run_state(self) -> RunState:
        s = self.s
        return RunState(
            pos=s.pos.copy(),
            scale=s.scale,
            absolute=s.absolute,
            arc_absolute=s.arc_absolute,
            offset=self.offset.copy(),
            motion=s.motion,
            feed_raw=s.feed_raw,
            power=s.power,
            laser=s.laser,
            plane=s.plane,
            plane_axes=PLANE_AXES[s.plane],
            exact_stop=s.exact_stop,
            blend_tol=s.blend_tol,
            pending_stop=s.pending_stop,
            arc_tol=ARC_RADIUS_TOL_MM if s.scale == 1.0 else ARC_RADIUS_TOL_INCH * MM_PER_INCH,
        )

    def run_plain(self, table: PlainTable, a: int, b: int, lines: np.ndarray) -> RunResult:
        """Execute plain blocks ``a:b`` in bulk; see :func:`~jaxcnc.gcode.fastpath.interpret_run`."""
        res = interpret_run(table, a, b, lines, self.run_state())
        if res.blocks == 0:
            return res
        s = self.s
        if res.columns is not None and res.columns["kind"].size:
            self.flush_rows()
            self.chunks.append(res.columns)
            s.pending_stop = s.exact_stop  # (as after a row of its own)
        s.pos = res.pos
        s.motion, s.feed_raw, s.power = res.motion, res.feed_raw, res.power
        if res.any_words:
            self.machine_coords = False
        return res

    def program(self) -> dict[str, np.ndarray]:
        self.flush_rows()
        if not self.chunks:
            out = {k: np.asarray([]) for k in PROGRAM_COLUMNS}
            for k in ("start", "end", "center"):
                out[k] = out[k].reshape(-1, 3)
            return out
        return {k: np.concatenate([c[k] for c in self.chunks]) for k in PROGRAM_COLUMNS}


def parse_gcode(
    text: str,
    file: str = "<string>",
    *,
    start: tuple[float, ...] | np.ndarray = (0.0, 0.0, 0.0),
    home: tuple[float, ...] | np.ndarray | None = None,
    block_delete: bool = False,
    max_depth: int = MAX_DEPTH,
    max_lines: int = MAX_LINES,
    dialect: str | Dialect | None = None,
    fast: bool = True,
    external: bool = False,
    tools: Mapping[int, Sequence[float]] | None = None,
) -> Program:
    """Interpret G-code ``text`` into a Program.

    Parametric programs (parameters, expressions, O-words) are flattened first by
    :mod:`jaxcnc.gcode.preprocess`. Runs of plain motion blocks (G0-G3 with X Y Z I J K R F S N
    and comments; see :mod:`jaxcnc.gcode.fastpath`) are tokenised and executed in bulk with NumPy;
    every other block goes through the line-by-line interpreter. Both give the same Program, bit for
    bit, and the same errors.

    Args:
        text: the program.
        file: its name, used in error messages and kept in the Program.
        start: machine position (x, y, z) in mm when the program starts.
        home: G28 home position (x, y, z) in mm; defaults to ``start``.
        block_delete: the block delete switch: when on, blocks starting with ``/`` are skipped.
        max_depth, max_lines: limits on subroutine nesting and executed lines.
        dialect: ``"linuxcnc"`` (default), ``"siemens"``, ``"fanuc"``, a dialect TOML file or a
            :class:`~jaxcnc.gcode.dialect.Dialect`.
        fast: use the bulk path for plain blocks (``False``: every block line by line, the reference).
        external: M170 / M171 switch motion to a galvo scanner and back (a stage + galvo machine); else errors.
        tools: the tool table, ``{number: (x_mm, y_mm, z_mm)}`` (a machine file's
            :meth:`~jaxcnc.machine.MachineConfig.tool_offsets`): the offsets ``G43 H<number>`` and ``G43.2`` apply.
            Without it only ``H0`` (no offset), ``G43.1`` and ``G49`` have a meaning.

    Raises:
        SourceError: naming ``file:line:column``, the word and the reason.
    """
    dia = load_dialect(dialect)
    if dia.program_names and "%_N_" in text.upper():  # (blanked: the lines keep their numbers)
        text = _PROGRAM_NAME.sub("", text)
    home_arr = np.asarray(start if home is None else home, dtype=np.float64)
    it = _Interpreter(file, np.asarray(start, dtype=np.float64), home_arr, dia, external, tools)
    open_percent: list[int] = []  # the line of a '%' that opens the program when no second '%' closes it
    if _needs_preprocessor(text):
        expanded = expand(text, file, max_depth=max_depth, max_lines=max_lines, dialect=dia, percent=open_percent)
        texts = [e.text for e in expanded]
        lines = np.fromiter((e.line for e in expanded), dtype=np.int64, count=len(expanded))
    else:
        texts = text.splitlines()
        if "%" in text:
            marks = [i for i, raw in enumerate(texts) if "%" in raw and raw.strip() == "%"]
            if len(marks) > 1:
                del texts[marks[1] :]  # the second '%' ends the program
            elif marks:
                open_percent.append(marks[0] + 1)
            if marks:
                texts[marks[0]] = ""  # the first opens it
        lines = np.arange(1, len(texts) + 1, dtype=np.int64)
    # A one-letter keyword of a dialect would read as a word letter: such dialects go line by line.
    fast = fast and bool(texts) and all(len(k) > 1 for k in dia.keywords)
    table = plain_table(texts, dia.paren_comments, dia.semicolon_comments) if fast else None
    last = None
    i, n = 0, len(texts)
    slow_until = 0  # blocks before this index go line by line (a run reached a non-finite number)
    while i < n:
        if table is not None and i >= slow_until and table.plain[i] and it.fast_ready():
            end = table.run_end(i)
            if end - i >= fastpath.MIN_RUN:
                res = it.run_plain(table, i, end, lines)
                i += res.blocks
                if res.nonfinite:
                    slow_until = end
                if i == end:
                    continue
                # block i would raise an error (or overflow): the interpreter executes it below
        raw, line_no = texts[i], int(lines[i])
        i += 1
        stripped = raw.lstrip()
        if stripped.startswith("/"):
            if block_delete:
                continue  # block delete switch on: the block is skipped
            raw = raw.replace("/", " ", 1)
        words, _comments = tokenize(raw, file, line_no, dia)
        if not words:
            continue
        last = _Block(words, file, line_no, dia)
        it.block(last)
        if it.ended:
            break
    if open_percent and not it.ended:  # as in LinuxCNC: a program opened by '%' ends at a '%' (or at M2/M30)
        raise SourceError(
            file, open_percent[0], 1, "'%' opens the program but no closing '%' line follows (nor M2/M30)"
        )
    it.close(last)  # (a run of plain blocks never leaves a spline open: ``last`` is only read then)
    curves = make_curve_table(it.s.curves) if it.s.curves else None
    return program_from_columns(file=file, curves=curves, **it.program())


def load_gcode(path: str | Path, **kwargs) -> Program:
    """Read and interpret a G-code file (ISO-7bit/ASCII or UTF-8); see :func:`parse_gcode`."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise SourceError(str(p), 0, 0, f"cannot read program: {exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise SourceError(str(p), line, 0, f"byte 0x{data[exc.start]:02x} is not ISO-7bit/UTF-8 text") from None
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise SourceError(str(p), line, 0, "NUL byte: this is not a text program")
    return parse_gcode(text, str(p), **kwargs)
