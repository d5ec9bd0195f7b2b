"""The machine description: a TOML file loaded into a typed, validated, immutable config.

Every planner reads one :class:`MachineConfig`. Loading checks every key; any mistake raises
:class:`~jaxcnc.errors.MachineFileError` naming the file, the line, the key and the reason.

Units: lengths in mm, speeds in mm/s, accelerations in mm/s², jerks in mm/s³, rates in Hz.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from jaxcnc.errors import MachineFileError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

#: Axis names a machine may declare, in table column order.
AXIS_NAMES = ("x", "y", "z", "a", "b", "c", "u", "v", "w")
#: Axes every machine must have: arcs and contours live in the XY plane.
REQUIRED_AXES = ("x", "y")
#: Positions are stored as int32 discretes in the table file.
_INT32_MAX = 2**31 - 1
#: Travel (and scanner field) may span at most this many discretes from 0: half of int32, so that no
#: position the planner, an overshoot, a scanner offset or the fine channel adds can overflow a table's int32.
INT32_SAFE_DISCRETES = 2**30
#: The range of tick rates (Hz): servo and scanner boards run at 1 kHz to a few hundred kHz; below 10 Hz a
#: table is no motion control, above 1 MHz it is a typo (1e9 would write 24 GB per second of motion).
TICK_HZ_RANGE = (10.0, 1e6)
#: The finest discrete (mm): 0.1 nm, below any encoder.
MIN_DISCRETE_MM = 1e-7


@dataclass(frozen=True)
class AxisConfig:
    """Limits of one axis. ``j_max`` is ``None`` for an acceleration-limited axis."""

    name: str
    v_max: float  # mm/s
    a_max: float  # mm/s²
    j_max: float | None  # mm/s³
    min: float  # mm
    max: float  # mm
    home: float  # mm, where the machine stands when a program starts
    #: Vibration modes ``(f_hz, zeta)`` of the axis (``mode_hz``, ``mode_zeta``): the simulated axis and the
    #: input shapers of issue 20 (docs/vibration.md). Empty: the axis is taken as rigid.
    modes: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True)
class PathConfig:
    """Contour defaults: speeds the program may not exceed, tolerances of the path."""

    feed: float  # mm/s, contour feed when the program sets none
    rapid: float  # mm/s, cap on G0 moves
    chord_tol_mm: float  # max chord error between consecutive ticks
    corner_tol_mm: float  # G64 without P: corners blended within this (0 = exact corners)


@dataclass(frozen=True)
class LaserConfig:
    """How the laser is driven: continuous, point-by-point pulsed, or position-synchronised."""

    mode: str = "cw"  # "cw" | "pulsed" | "pso"
    pulse_hz: float | None = None
    tolerance: float = 0.05
    idle_pulses: bool = True
    pso_mm: float | None = None
    #: M4 (power scaled with speed): the least fraction of S it fires at while lit (0: dark at standstill).
    m4_floor: float = 0.0
    #: M4 user curve: power fraction ``m4_curve_power`` at speed fraction ``m4_curve_speed`` (of the programmed
    #: feed), linear between; ``None``: power fraction = speed fraction (docs/laser.md).
    m4_curve_speed: tuple[float, ...] | None = None
    m4_curve_power: tuple[float, ...] | None = None
    #: Laser latency: the source starts firing ``on_delay_s`` after it is commanded on (and follows level
    #: changes that late) and stops ``off_delay_s`` after it is commanded off; the tick writer commands it that
    #: much earlier so the burn starts and ends where the program says (docs/laser.md).
    on_delay_s: float = 0.0
    off_delay_s: float = 0.0

    def delay_ticks(self, tick_hz: float) -> tuple[int, int]:
        """``(on, off)`` delays in whole ticks at ``tick_hz`` (rounded to the nearest tick)."""
        return round(self.on_delay_s * tick_hz), round(self.off_delay_s * tick_hz)


@dataclass(frozen=True)
class ScannerConfig:
    """Additional fast axes summed with the main axes (galvo or light stage).

    The tool point is ``main + offset_mm + R(rotation_deg) · diag(scale) · (u, v)``: the scanner's
    axes (``axes``, in its own frame) are scaled, rotated and offset into the main axes' frame (the
    calibration). ``field_mm``: the full width of the field per scanner axis, centred on 0.
    """

    axes: tuple[str, ...]
    field_mm: tuple[float, ...]
    scale: tuple[float, ...] = (1.0, 1.0)
    rotation_deg: float = 0.0
    offset_mm: tuple[float, ...] = (0.0, 0.0)


@dataclass(frozen=True)
class GalvoConfig:
    """The scan head of a scanner-only (galvo marking) machine: how the mirrors follow the board's command.

    The machine's x and y axes are the beam at the field, driven by a galvo board that executes vector lists at
    ``[machine] tick_hz`` (the board clock). The head is a second-order tracking loop per axis
    (:class:`jaxcnc.scanner.head.HeadModel`, ``docs/scanner.md``): ``tracking_error_s`` τ (at constant speed the
    mirror is τ behind the command), ``damping`` ζ, ``mirror_a_max_mm_s2`` the mirrors' acceleration limit at the
    field (their inertia against the drive's torque).
    """

    tracking_error_s: float
    mirror_a_max_mm_s2: float
    damping: float = 1.0
    #: ``axes = ["u", "v"]``: a stage + galvo machine (the external motion module, ``docs/scanner.md``): x, y (z)
    #: are the stage, these two the beam's offset in the field (their ``[axes.*]`` limits, min/max the field,
    #: home 0 its centre); a G-code program switches between the two with M170 / M171. Empty: scanner-only.
    axes: tuple[str, ...] = ()
    #: The board's delays and sky-writing (``docs/scanner.md``), each in seconds at the board (ticks =
    #: round(s * tick_hz)); ``None``: chosen from the head model (:func:`jaxcnc.scanner.compile.auto_settings`).
    laser_on_delay_s: float | None = None
    laser_off_delay_s: float | None = None
    jump_delay_s: float | None = None
    mark_delay_s: float | None = None
    polygon_delay_s: float | None = None
    variable_polygon: bool | None = None
    sky_writing: float | None = None  # mode 0 off, 1 chain ends, 2 also corners turning more than sky_limit_deg
    run_in_s: float | None = None
    run_out_s: float | None = None
    sky_limit_deg: float | None = None

    @property
    def stage(self) -> bool:
        """The machine has a stage beside the galvo head (``axes`` given)."""
        return bool(self.axes)


@dataclass(frozen=True)
class ToolConfig:
    """One row of the tool table (``[tools.N]``): the offsets ``G43 H<N>`` applies.

    ``z_mm`` is the tool length offset (a nozzle or lens of another focal length): with it in effect, a programmed
    ``Z`` is reached at machine ``Z + z_mm``; ``x_mm``, ``y_mm`` shift the controlled point likewise (a second head).
    """

    number: int
    z_mm: float
    x_mm: float = 0.0
    y_mm: float = 0.0


@dataclass(frozen=True)
class MachineConfig:
    """A validated, immutable machine description."""

    name: str
    tick_hz: float
    discrete_mm: float
    axes: tuple[AxisConfig, ...]
    path: PathConfig
    laser: LaserConfig = field(default_factory=LaserConfig)
    scanner: ScannerConfig | None = None
    source: str = "<memory>"
    #: The planner's name (``[machine] planner``): a contour planner, or on a pulsed machine a pulse planner;
    #: ``None``: the default. Checked against the registries when planning (see :func:`key_error`).
    planner: str | None = None
    #: ``[galvo]``: a scanner-only machine whose x, y are the beam, with its scan-head model (docs/scanner.md).
    galvo: GalvoConfig | None = None
    #: ``[tools.N]``: the tool table, by tool number (what ``G43 H<N>`` applies), in ascending order.
    tools: tuple[ToolConfig, ...] = ()

    def tool_offsets(self) -> dict[int, tuple[float, float, float]]:
        """The tool table as ``{number: (x_mm, y_mm, z_mm)}``, what :func:`~jaxcnc.gcode.parse_gcode` reads."""
        return {t.number: (t.x_mm, t.y_mm, t.z_mm) for t in self.tools}

    @property
    def axis_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.axes)

    @property
    def dt(self) -> float:
        """The tick period in seconds."""
        return 1.0 / self.tick_hz

    def axis(self, name: str) -> AxisConfig:
        for a in self.axes:
            if a.name == name:
                return a
        raise KeyError(name)

    def limits(self, names: tuple[str, ...]) -> dict[str, np.ndarray]:
        """Per-axis limit arrays for ``names`` (axes the machine lacks get ``nan``).

        Returns a dict of arrays of shape ``(len(names),)``: ``v_max``, ``a_max``, ``j_max``
        (``inf`` where unset), ``min``, ``max``, ``home``.
        """
        out: dict[str, list[float]] = {k: [] for k in ("v_max", "a_max", "j_max", "min", "max", "home")}
        for n in names:
            a = self.axis(n) if n in self.axis_names else None
            for k in out:
                v = getattr(a, k) if a is not None else math.nan
                out[k].append(math.inf if (k == "j_max" and v is None) else v)
        return {k: np.asarray(v, dtype=np.float64) for k, v in out.items()}


# --------------------------------------------------------------------------------------------
# Schema: key -> (kind, required, default, check). Kinds: "number", "string", "bool",
# "string_list", "number_list". Checks return an error text or None.


def _positive(v: float) -> str | None:
    return None if v > 0 and math.isfinite(v) else "must be a positive finite number"


def _nonneg(v: float) -> str | None:
    return None if v >= 0 and math.isfinite(v) else "must be zero or a positive finite number"


def _finite(v: float) -> str | None:
    return None if math.isfinite(v) else "must be a finite number"


def _speed(v: float) -> str | None:
    if (e := _positive(v)) is not None:
        return e
    if v > 1e5:
        return f"{v:g} mm/s is faster than any stage or scanner (100 m/s); was it given in mm/min?"
    return None


def _tick_rate(v: float) -> str | None:
    if (e := _positive(v)) is not None:
        return e
    lo, hi = TICK_HZ_RANGE
    if not lo <= v <= hi:
        return f"{v:g} Hz is outside {lo:g} Hz to {hi:g} Hz (servo and scanner boards tick at 1 kHz to a few 100 kHz)"
    return None


def _discrete(v: float) -> str | None:
    if (e := _positive(v)) is not None:
        return e
    if v < MIN_DISCRETE_MM:
        return f"{v:g} mm per discrete is finer than {MIN_DISCRETE_MM:g} mm (0.1 nm), below any encoder"
    if v > 0.1:
        return f"{v:g} mm per discrete is coarser than 0.1 mm; did you mean {v / 1000:g} (in mm)?"
    return None


def _fraction(v: float) -> str | None:
    return None if 0 <= v < 1 else "must be a fraction in [0, 1)"


def _delay(v: float) -> str | None:
    if not (math.isfinite(v) and v >= 0):
        return "must be zero or a positive finite number of seconds"
    return None if v <= 0.1 else f"{v:g} s is longer than any laser's switching delay (0.1 s); was it given in ms?"


def _m4_curve(speed: tuple[float, ...] | None, power: tuple[float, ...] | None) -> tuple[str, str] | None:
    """``(key, why)`` when the M4 curve is malformed: both lists or neither, equal lengths >= 2, speeds
    rising strictly from 0 to 1, powers in [0, 1]."""
    if speed is None and power is None:
        return None
    if speed is None or power is None:
        key = "m4_curve_speed" if speed is None else "m4_curve_power"
        return (key, "m4_curve_speed and m4_curve_power go together")
    if len(speed) != len(power) or len(speed) < 2:
        return ("m4_curve_power", f"{len(power)} powers for {len(speed)} speeds (need equal lengths, at least 2)")
    if speed[0] != 0 or speed[-1] != 1 or any(b <= a for a, b in zip(speed, speed[1:], strict=False)):
        return ("m4_curve_speed", f"{list(speed)}: speed fractions must rise strictly from 0 to 1")
    if not all(0 <= p <= 1 for p in power):
        return ("m4_curve_power", f"{list(power)}: power fractions must lie in [0, 1]")
    return None


def _tracking_error(v: float) -> str | None:
    if (e := _positive(v)) is not None:
        return e
    return None if v <= 0.01 else f"{v:g} s is slower than any galvo (at most 10 ms); was it given in µs or ms?"


def _damping(v: float) -> str | None:
    ok = math.isfinite(v) and 0.1 <= v <= 2.0
    return None if ok else "must lie in [0.1, 2] (a galvo's tracking loop is tuned near 0.7 to 1)"


def _mirror_accel(v: float) -> str | None:
    if (e := _positive(v)) is not None:
        return e
    return None if v <= 1e10 else f"{v:g} mm/s² is beyond any galvo mirror (1e10 mm/s² at the field)"


def _laser_delay(v: float) -> str | None:
    ok = math.isfinite(v) and -0.01 <= v <= 0.1
    return None if ok else "must lie in [-0.01, 0.1] s (a board's laser delay; was it given in µs?)"


def _board_delay(v: float) -> str | None:
    ok = math.isfinite(v) and 0 <= v <= 0.1
    return None if ok else "must lie in [0, 0.1] s (a board's scanner delay; was it given in µs?)"


def _sky_mode(v: float) -> str | None:
    return None if v in (0, 1, 2) else "sky-writing mode is 0 (off), 1 (chain ends) or 2 (also corners)"


def _sky_limit(v: float) -> str | None:
    return None if math.isfinite(v) and 0 <= v <= 180 else "must lie in [0, 180] degrees"


def _name(v: str) -> str | None:
    return None if v.strip() == v and v else "must be a non-empty name without surrounding spaces"


def _laser_mode(v: str) -> str | None:
    return None if v in ("cw", "pulsed", "pso") else f"unknown laser mode {v!r}; expected cw, pulsed or pso"


#: Corner blending tolerance (mm) for G64 without P when the machine file sets none. RS274's G64
#: without P means "best speed"; an unbounded deviation would let a corner's blend take half of each
#: line. 0.01 mm is below what a laser cut shows (a kerf is 0.1–0.3 mm wide; cutting tables repeat to
#: ±0.02–0.05 mm) and lets the 0.1–5° kinks of CAM polylines and the corners of chord-cut curves pass at
#: speed. ``corner_tol_mm = 0`` in a machine file keeps every corner exact.
DEFAULT_CORNER_TOL_MM = 0.01

Check = Callable[[Any], "str | None"] | None
_SCHEMA: dict[str, dict[str, tuple[str, bool, Any, Check]]] = {
    "machine": {
        "name": ("string", False, "machine", None),
        "tick_hz": ("number", True, None, _tick_rate),
        "discrete_mm": ("number", False, 0.001, _discrete),
        "planner": ("string", False, None, _name),
    },
    "axis": {
        "v_max": ("number", True, None, _speed),
        "a_max": ("number", True, None, _positive),
        "j_max": ("number", False, None, _positive),
        "min": ("number", True, None, _finite),
        "max": ("number", True, None, _finite),
        "home": ("number", False, None, _finite),
        "mode_hz": ("number_list", False, (), None),
        "mode_zeta": ("number_list", False, (), None),
    },
    "path": {
        "feed": ("number", True, None, _speed),
        "rapid": ("number", True, None, _speed),
        "chord_tol_mm": ("number", False, 0.001, _positive),
        "corner_tol_mm": ("number", False, DEFAULT_CORNER_TOL_MM, _nonneg),
    },
    "laser": {
        "mode": ("string", False, "cw", _laser_mode),
        "pulse_hz": ("number", False, None, _positive),
        "tolerance": ("number", False, 0.05, _fraction),
        "idle_pulses": ("bool", False, True, None),
        "pso_mm": ("number", False, None, _positive),
        "m4_floor": ("number", False, 0.0, _fraction),
        "m4_curve_speed": ("number_list", False, None, None),
        "m4_curve_power": ("number_list", False, None, None),
        "on_delay_s": ("number", False, 0.0, _delay),
        "off_delay_s": ("number", False, 0.0, _delay),
    },
    "scanner": {
        "axes": ("string_list", True, None, None),
        "field_mm": ("number_list", True, None, None),
        "scale": ("number_list", False, (1.0, 1.0), None),
        "rotation_deg": ("number", False, 0.0, _finite),
        "offset_mm": ("number_list", False, (0.0, 0.0), None),
    },
    "tool": {
        "z_mm": ("number", True, None, _finite),
        "x_mm": ("number", False, 0.0, _finite),
        "y_mm": ("number", False, 0.0, _finite),
    },
    "galvo": {
        "tracking_error_s": ("number", True, None, _tracking_error),
        "mirror_a_max_mm_s2": ("number", True, None, _mirror_accel),
        "damping": ("number", False, 1.0, _damping),
        "axes": ("string_list", False, (), None),
        "laser_on_delay_s": ("number", False, None, _laser_delay),
        "laser_off_delay_s": ("number", False, None, _laser_delay),
        "jump_delay_s": ("number", False, None, _board_delay),
        "mark_delay_s": ("number", False, None, _board_delay),
        "polygon_delay_s": ("number", False, None, _board_delay),
        "variable_polygon": ("bool", False, None, None),
        "sky_writing": ("number", False, None, _sky_mode),
        "run_in_s": ("number", False, None, _board_delay),
        "run_out_s": ("number", False, None, _board_delay),
        "sky_limit_deg": ("number", False, None, _sky_limit),
    },
}
_TOP_LEVEL = ("machine", "axes", "path", "laser", "scanner", "galvo", "tools")
#: Axes a galvo board drives: the beam at the field (x, y) and a focus shifter (z).
GALVO_AXES = ("x", "y", "z")


class _Loader:
    """Validates a parsed TOML document; knows the text to find line numbers for keys."""

    def __init__(self, file: str, text: str):
        self.file, self.lines = file, text.splitlines()

    def line_of(self, table: str, key: str | None = None) -> int:
        """1-based line where ``key`` is set inside ``[table]`` (or the table header); 0 if unknown."""
        current, header_line = "", 0
        for i, raw in enumerate(self.lines, 1):
            s = raw.split("#", 1)[0].strip()
            m = re.fullmatch(r"\[\s*([^\[\]]+?)\s*\]", s)
            if m:
                current = re.sub(r"\s*\.\s*", ".", m.group(1)).replace('"', "")
                if current == table:
                    header_line = i
                continue
            if key is None:
                continue
            kv = re.match(r"([A-Za-z0-9_.\-\"]+)\s*=", s)
            if not kv:
                continue
            full = (current + "." if current else "") + kv.group(1).replace('"', "")
            if full == f"{table}.{key}" if table else full == key:
                return i
        return header_line

    def fail(self, table: str, key: str | None, reason: str) -> MachineFileError:
        dotted = f"{table}.{key}" if key else table
        return MachineFileError(self.file, dotted, reason, self.line_of(table, key))

    def section(self, table: str, raw: Any, kind: str) -> dict[str, Any]:
        """Check one table against the schema ``kind``; return its values with defaults."""
        if not isinstance(raw, Mapping):
            raise self.fail(table, None, f"must be a table, got {type(raw).__name__}")
        schema = _SCHEMA[kind]
        for key in raw:
            if key not in schema:
                known = ", ".join(schema)
                raise self.fail(table, key, f"unknown key {key!r}; known keys here: {known}")
        out: dict[str, Any] = {}
        for key, (typ, required, default, check) in schema.items():
            if key not in raw:
                if required:
                    raise self.fail(table, None, f"missing required key {key!r}")
                out[key] = default
                continue
            v = self.typed(table, key, raw[key], typ)
            if check is not None and (err := check(v)) is not None:
                raise self.fail(table, key, f"{v!r}: {err}")
            out[key] = v
        return out

    def typed(self, table: str, key: str, v: Any, typ: str) -> Any:
        def is_num(x: Any) -> bool:
            return isinstance(x, (int, float)) and not isinstance(x, bool)

        ok = {
            "number": is_num(v),
            "string": isinstance(v, str),
            "bool": isinstance(v, bool),
            "string_list": isinstance(v, list) and all(isinstance(x, str) for x in v),
            "number_list": isinstance(v, list) and all(is_num(x) for x in v),
        }[typ]
        if not ok:
            want = {
                "number": "a number",
                "string": "a string",
                "bool": "true or false",
                "string_list": "a list of strings",
                "number_list": "a list of numbers",
            }[typ]
            raise self.fail(table, key, f"expected {want}, got {v!r} ({type(v).__name__})")
        if typ == "number":
            return float(v)
        if typ == "number_list":
            return tuple(float(x) for x in v)
        if typ == "string_list":
            return tuple(v)
        return v

    def modes(
        self, axis: str, f_hz: tuple[float, ...], zeta: tuple[float, ...], tick_hz: float
    ) -> tuple[tuple[float, float], ...]:
        """An axis' vibration modes: one damping ratio per frequency, frequencies below half the tick rate."""
        table = f"axes.{axis}"
        if len(f_hz) != len(zeta):
            raise self.fail(table, "mode_zeta", f"{len(zeta)} damping ratios for {len(f_hz)} mode frequencies")
        for f in f_hz:
            if not (math.isfinite(f) and 0 < f < tick_hz / 2):
                raise self.fail(table, "mode_hz", f"{f!r} Hz: a mode must lie in (0, tick_hz / 2 = {tick_hz / 2:g}) Hz")
        for z in zeta:
            if not 0 <= z < 1:
                raise self.fail(table, "mode_zeta", f"{z!r}: a damping ratio must lie in [0, 1) (an oscillating mode)")
        return tuple(zip(f_hz, zeta, strict=True))

    def galvo_axes(self, names: tuple[str, ...], axes: list[AxisConfig]) -> None:
        """``[galvo] axes`` of a stage + galvo machine: two beam axes with their tables, centred on home 0; every
        other axis a stage axis (x, y, z)."""
        have = {a.name: a for a in axes}
        if len(names) != 2 or len(set(names)) != 2:
            raise self.fail("galvo", "axes", f"{list(names)}: names the two beam axes of the field, e.g. ['u', 'v']")
        for n in names:
            if n in GALVO_AXES:
                raise self.fail("galvo", "axes", f"{n!r} is a stage axis; the beam axes are others, e.g. u, v")
            if n not in have:
                raise self.fail("galvo", "axes", f"beam axis {n!r} has no [axes.{n}] table")
            if have[n].home != 0.0 or not have[n].min < 0.0 < have[n].max:
                raise self.fail(f"axes.{n}", "home", "a beam axis spans its field around home 0 (its centre)")
        if extra := [a for a in have if a not in names and a not in GALVO_AXES]:
            raise self.fail(f"axes.{extra[0]}", None, f"a stage + galvo machine's stage moves x, y, z, not {extra[0]}")

    def load(self, doc: Mapping[str, Any]) -> MachineConfig:
        for key in doc:
            if key not in _TOP_LEVEL:
                raise self.fail(key, None, f"unknown table [{key}]; known tables: {', '.join(_TOP_LEVEL)}")
        for key in ("machine", "axes", "path"):
            if key not in doc:
                raise MachineFileError(self.file, key, f"missing required table [{key}]")
        m = self.section("machine", doc["machine"], "machine")
        path = self.section("path", doc["path"], "path")
        laser = self.section("laser", doc.get("laser", {}), "laser")
        axes_raw = doc["axes"]
        if not isinstance(axes_raw, Mapping):
            raise self.fail("axes", None, "must be a table of axis tables such as [axes.x]")
        for name in axes_raw:
            if name not in AXIS_NAMES:
                raise self.fail(f"axes.{name}", None, f"unknown axis {name!r}; axes are {', '.join(AXIS_NAMES)}")
        for name in REQUIRED_AXES:
            if name not in axes_raw:
                raise MachineFileError(
                    self.file,
                    f"axes.{name}",
                    f"missing axis {name!r}: a [axes.{name}] table is required",
                    self.line_of("axes"),
                )
        axes = []
        for name in (n for n in AXIS_NAMES if n in axes_raw):
            a = self.section(f"axes.{name}", axes_raw[name], "axis")
            if a["min"] >= a["max"]:
                raise self.fail(f"axes.{name}", "min", f"min ({a['min']:g}) must be below max ({a['max']:g})")
            if a["home"] is None:
                a["home"] = min(max(0.0, a["min"]), a["max"])
            elif not a["min"] <= a["home"] <= a["max"]:
                raise self.fail(f"axes.{name}", "home", f"home {a['home']:g} is outside [{a['min']:g}, {a['max']:g}]")
            reach = max(abs(a["min"]), abs(a["max"])) / m["discrete_mm"]
            if reach > INT32_SAFE_DISCRETES:
                raise self.fail(
                    "machine",
                    "discrete_mm",
                    f"axis {name} travel reaches {reach:.3g} discretes from 0, beyond 2^30 (half of int32, the "
                    "margin that keeps table positions from overflowing); use a coarser discrete or a smaller travel",
                )
            a["modes"] = self.modes(name, a.pop("mode_hz"), a.pop("mode_zeta"), m["tick_hz"])
            axes.append(AxisConfig(name=name, **a))
        if laser["mode"] == "pulsed" and laser["pulse_hz"] is None:
            raise self.fail("laser", None, "mode 'pulsed' needs pulse_hz")
        if laser["mode"] == "pso" and laser["pso_mm"] is None:
            raise self.fail("laser", None, "mode 'pso' needs pso_mm")
        if (bad := _m4_curve(laser["m4_curve_speed"], laser["m4_curve_power"])) is not None:
            raise self.fail("laser", bad[0], bad[1])
        scanner = None
        if "scanner" in doc:
            sc = self.section("scanner", doc["scanner"], "scanner")
            for n in sc["axes"]:
                if n not in axes_raw:
                    raise self.fail("scanner", "axes", f"scanner axis {n!r} has no [axes.{n}] table")
            if len(sc["field_mm"]) != len(sc["axes"]) or not all(math.isfinite(f) and f > 0 for f in sc["field_mm"]):
                raise self.fail("scanner", "field_mm", "needs one positive, finite field size per scanner axis")
            if max(sc["field_mm"]) / m["discrete_mm"] > INT32_SAFE_DISCRETES:
                raise self.fail(
                    "scanner", "field_mm", f"a field of {max(sc['field_mm']):g} mm spans more than 2^30 discretes"
                )
            if len(sc["scale"]) != len(sc["axes"]) or not all(math.isfinite(f) and f != 0 for f in sc["scale"]):
                raise self.fail("scanner", "scale", "needs one finite, non-zero scale per scanner axis")
            if len(sc["offset_mm"]) != len(sc["axes"]) or not all(math.isfinite(f) for f in sc["offset_mm"]):
                raise self.fail("scanner", "offset_mm", "needs one finite offset per scanner axis")
            scanner = ScannerConfig(
                axes=sc["axes"],
                field_mm=sc["field_mm"],
                scale=sc["scale"],
                rotation_deg=sc["rotation_deg"],
                offset_mm=sc["offset_mm"],
            )
        galvo = None
        if "galvo" in doc:
            g = self.section("galvo", doc["galvo"], "galvo")
            if scanner is not None:
                raise self.fail(
                    "galvo", None, "[galvo] declares a scanner-only machine (x, y are the beam); a stage + scanner "
                    "split ([scanner]) has no scan-head model yet: remove one of the two tables"
                )  # fmt: skip
            if g["axes"]:
                self.galvo_axes(g["axes"], axes)
            elif extra := [a.name for a in axes if a.name not in GALVO_AXES]:
                raise self.fail(
                    f"axes.{extra[0]}", None, f"a galvo machine drives x, y (the beam) and z (focus), not {extra[0]}"
                )
            if g["tracking_error_s"] < 2.0 / m["tick_hz"]:
                raise self.fail(
                    "galvo", "tracking_error_s",
                    f"{g['tracking_error_s']:g} s is shorter than two board ticks (tick_hz {m['tick_hz']:g}): "
                    "the model cannot resolve it",
                )  # fmt: skip
            galvo = GalvoConfig(**g)
        tools = self.tools(doc.get("tools", {}))
        return MachineConfig(
            name=m["name"],
            tick_hz=m["tick_hz"],
            discrete_mm=m["discrete_mm"],
            axes=tuple(axes),
            path=PathConfig(**path),
            laser=LaserConfig(**laser),
            scanner=scanner,
            source=self.file,
            planner=m["planner"],
            galvo=galvo,
            tools=tools,
        )

    def tools(self, raw: Any) -> tuple[ToolConfig, ...]:
        """``[tools.N]`` tables: ``N`` a tool number 1..99999 (``H`` words name them; 0 is "no tool")."""
        if not isinstance(raw, Mapping):
            raise self.fail("tools", None, "must be a table of tool tables such as [tools.1]")
        out = []
        for key, row in raw.items():
            if not re.fullmatch(r"[0-9]{1,5}", key) or int(key) == 0:
                raise self.fail(
                    f"tools.{key}", None, f"{key!r} is not a tool number: tools are [tools.1] to [tools.99999] "
                    "(the number G43 H names; H0 means no offset)",
                )  # fmt: skip
            out.append(ToolConfig(number=int(key), **self.section(f"tools.{key}", row, "tool")))
        return tuple(sorted(out, key=lambda t: t.number))


def parse_machine(text: str, file: str = "<string>") -> MachineConfig:
    """Parse and validate machine TOML ``text``; ``file`` names it in error messages."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = re.search(r"line (\d+)", msg)
        raise MachineFileError(file, "", f"not valid TOML: {msg}", int(m.group(1)) if m else 0) from None
    return _Loader(file, text).load(doc)


def key_error(machine: MachineConfig, table: str, key: str, reason: str) -> MachineFileError:
    """An error about ``[table] key`` of ``machine``'s file, found by a later stage (e.g. an unknown planner).

    Names the file and, when the file is still readable, the line that sets the key.
    """
    try:
        text = Path(machine.source).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        text = ""
    line = _Loader(machine.source, text).line_of(table, key) if text else 0
    return MachineFileError(machine.source, f"{table}.{key}", reason, line)


def load_machine(path: str | Path) -> MachineConfig:
    """Load and validate the machine file at ``path``."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise MachineFileError(str(p), "", f"cannot read machine file: {exc}") from None
    return parse_machine(text, str(p))
