"""The powder-bed build-parameters file: a TOML file with a ``[pbf]`` table (docs/pbf.md).

It is a file of its own, not a table of the motion machine file (docs/machine-file.md): a powder-bed machine is a
galvo scanner over a recoated bed and shares no key with the axes, ticks and feeds that file describes. Its rules
are that file's: every key has a unit suffix, a value of the wrong type or range is an error, and so is an unknown
key or table — ``FILE:LINE: [pbf.key] reason`` (:class:`~jaxcnc.errors.MachineFileError`, exit status 2).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from jaxcnc.errors import MachineFileError

try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

#: Zones, in the order of their ids (the ``zone`` field of a vector list, the CLI label id - 1).
ZONES = ("core", "contour", "thin_wall", "downskin", "upskin")
ZONE_ID = {name: i for i, name in enumerate(ZONES)}
HATCH_PATTERNS = ("lines", "meander", "stripes", "islands")
PLACEMENTS = ("plate", "keep")
SCAN_ORDERS = ("greedy", "raster")


@dataclass(frozen=True)
class ZoneParams:
    """Laser parameters of one zone: the mark speed and the power."""

    mark_speed_mm_s: float
    power_w: float


@dataclass(frozen=True)
class ScannerParams:
    """The scanner's jump speed and delays (seconds), sky-writing and the recoater's time per layer."""

    jump_speed_mm_s: float = 7000.0
    jump_delay_s: float = 200e-6
    mark_delay_s: float = 100e-6
    polygon_delay_s: float = 50e-6
    laser_on_delay_s: float = 20e-6
    laser_off_delay_s: float = 30e-6
    skywriting: bool = False
    skywriting_s: float = 150e-6
    recoat_s: float = 8.0


@dataclass(frozen=True)
class BuildParams:
    """Everything a build needs besides the mesh; see docs/pbf.md for each key."""

    layer_thickness_mm: float
    hatch_spacing_mm: float
    spot_diameter_mm: float
    placement: str = "plate"
    plate_center_mm: tuple[float, float] = (0.0, 0.0)
    merge_tol_mm: float = 1e-5
    repair: bool = False
    contour_count: int = 1
    contour_spacing_mm: float = 0.08
    hatch_offset_mm: float = 0.0
    hatch_pattern: str = "meander"
    hatch_angle_deg: float = 0.0
    layer_rotation_deg: float = 67.0
    stripe_width_mm: float = 5.0
    island_size_mm: float = 5.0
    scan_order: str = "greedy"
    thin_wall_mm: float = 0.0
    skin_layers: int = 1
    min_hatch_mm: float = 1e-4
    cli_units_mm: float = 1.0
    scanner: ScannerParams = field(default_factory=ScannerParams)
    zones: tuple[ZoneParams, ...] = ()

    def zone(self, name: str) -> ZoneParams:
        """The laser parameters of zone ``name`` (one of :data:`ZONES`)."""
        return self.zones[ZONE_ID[name]]

    def layer_angle_deg(self, k: int) -> float:
        """Hatch angle of layer ``k``: the base angle turned by ``layer_rotation_deg`` per layer, in [0, 180)."""
        return math.fmod(self.hatch_angle_deg + k * self.layer_rotation_deg, 180.0) % 180.0

    def as_dict(self) -> dict:
        """Plain-data form (JSON), for the manifest."""
        return asdict(self)

    def digest(self) -> str:
        """SHA-256 of the parameters (the manifest keys a build by it and the mesh's digest)."""
        return hashlib.sha256(json.dumps(self.as_dict(), sort_keys=True).encode()).hexdigest()


def _pos(v: Any) -> str | None:
    return None if v > 0 and math.isfinite(v) else "must be positive and finite"


def _nonneg(v: Any) -> str | None:
    return None if v >= 0 and math.isfinite(v) else "must be >= 0 and finite"


def _finite(v: Any) -> str | None:
    return None if math.isfinite(v) else "must be finite"


def _choice(options: tuple[str, ...]) -> Callable[[Any], str | None]:
    return lambda v: None if v in options else f"expected one of {', '.join(options)}"


def _pair(v: Any) -> str | None:
    return None if all(math.isfinite(x) for x in v) else "must be finite"


# key -> (type, required, check)
_PBF: dict[str, tuple[str, bool, Callable[[Any], str | None] | None]] = {
    "layer_thickness_mm": ("float", True, _pos),
    "hatch_spacing_mm": ("float", True, _pos),
    "spot_diameter_mm": ("float", True, _nonneg),
    "placement": ("str", False, _choice(PLACEMENTS)),
    "plate_center_mm": ("pair", False, _pair),
    "merge_tol_mm": ("float", False, _pos),
    "repair": ("bool", False, None),
    "contour_count": ("int", False, lambda v: None if v >= 0 else "must be >= 0"),
    "contour_spacing_mm": ("float", False, _pos),
    "hatch_offset_mm": ("float", False, _finite),
    "hatch_pattern": ("str", False, _choice(HATCH_PATTERNS)),
    "hatch_angle_deg": ("float", False, _finite),
    "layer_rotation_deg": ("float", False, _finite),
    "stripe_width_mm": ("float", False, _pos),
    "island_size_mm": ("float", False, _pos),
    "scan_order": ("str", False, _choice(SCAN_ORDERS)),
    "thin_wall_mm": ("float", False, _nonneg),
    "skin_layers": ("int", False, lambda v: None if 0 <= v <= 20 else "must be in 0..20"),
    "min_hatch_mm": ("float", False, _nonneg),
    "cli_units_mm": ("float", False, _pos),
}
_SCANNER: dict[str, tuple[str, bool, Callable[[Any], str | None] | None]] = {
    "jump_speed_mm_s": ("float", False, _pos),
    "jump_delay_s": ("float", False, _nonneg),
    "mark_delay_s": ("float", False, _nonneg),
    "polygon_delay_s": ("float", False, _nonneg),
    "laser_on_delay_s": ("float", False, _nonneg),
    "laser_off_delay_s": ("float", False, _nonneg),
    "skywriting": ("bool", False, None),
    "skywriting_s": ("float", False, _nonneg),
    "recoat_s": ("float", False, _nonneg),
}
_ZONE: dict[str, tuple[str, bool, Callable[[Any], str | None] | None]] = {
    "mark_speed_mm_s": ("float", False, _pos),
    "power_w": ("float", False, _nonneg),
}
#: Zone defaults where the file gives none (a 200 W-class machine); a zone without speed takes the core's.
_ZONE_DEFAULTS = {
    "core": ZoneParams(1000.0, 200.0),
    "contour": ZoneParams(800.0, 150.0),
    "thin_wall": ZoneParams(900.0, 120.0),
    "downskin": ZoneParams(1500.0, 100.0),
    "upskin": ZoneParams(800.0, 180.0),
}


class _Checker:
    """Validates the parsed document; finds the line of a key in the text for the error message."""

    def __init__(self, file: str, text: str):
        self.file, self.lines = file, text.splitlines()

    def line_of(self, table: str, key: str | None) -> int:
        current, header = "", 0
        for i, raw in enumerate(self.lines, 1):
            s = raw.split("#", 1)[0].strip()
            m = re.fullmatch(r"\[\s*([^\[\]]+?)\s*\]", s)
            if m:
                current = re.sub(r"\s*\.\s*", ".", m.group(1)).replace('"', "")
                header = i if current == table else header
                continue
            kv = re.match(r"([A-Za-z0-9_\-]+)\s*=", s)
            if key is not None and kv and current == table and kv.group(1) == key:
                return i
        return header

    def fail(self, table: str, key: str | None, reason: str) -> MachineFileError:
        return MachineFileError(self.file, f"{table}.{key}" if key else table, reason, self.line_of(table, key))

    def section(self, table: str, raw: Any, schema: Mapping[str, tuple]) -> dict[str, Any]:
        if not isinstance(raw, Mapping):
            raise self.fail(table, None, f"must be a table, got {type(raw).__name__}")
        out: dict[str, Any] = {}
        for key, value in raw.items():
            if key not in schema:
                raise self.fail(table, key, f"unknown key {key!r}; known keys here: {', '.join(schema)}")
            typ, _, check = schema[key]
            v = self.typed(table, key, value, typ)
            if check is not None and (err := check(v)) is not None:
                raise self.fail(table, key, f"{value!r}: {err}")
            out[key] = v
        for key, (_, required, _) in schema.items():
            if required and key not in out:
                raise self.fail(table, None, f"missing required key {key!r}")
        return out

    def typed(self, table: str, key: str, v: Any, typ: str) -> Any:
        def num(x: Any) -> bool:
            return isinstance(x, (int, float)) and not isinstance(x, bool)

        if typ == "float" and num(v):
            return float(v)
        if typ == "int" and isinstance(v, int) and not isinstance(v, bool):
            return v
        if typ == "bool" and isinstance(v, bool):
            return v
        if typ == "str" and isinstance(v, str):
            return v
        if typ == "pair" and isinstance(v, list) and len(v) == 2 and all(num(x) for x in v):
            return (float(v[0]), float(v[1]))
        want = {"float": "a number", "int": "an integer", "bool": "true or false", "str": "a string"}
        raise self.fail(table, key, f"{v!r}: expected {want.get(typ, 'a pair of numbers [x, y]')}")


def parse_params(text: str, file: str = "<string>") -> BuildParams:
    """Parse and validate a build-parameters document. Raises :class:`MachineFileError` naming file, line, key."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MachineFileError(file, "", f"not valid TOML: {exc}") from None
    chk = _Checker(file, text)
    for key in doc:
        if key != "pbf":
            raise chk.fail(key, None, "unknown table; a powder-bed build file has one table, [pbf] (docs/pbf.md)")
    if "pbf" not in doc:
        raise MachineFileError(file, "pbf", "missing: a powder-bed build file needs a [pbf] table (docs/pbf.md)")
    raw = dict(doc["pbf"]) if isinstance(doc["pbf"], Mapping) else doc["pbf"]
    sub = {k: raw.pop(k) for k in ("scanner", "zone") if isinstance(raw, dict) and k in raw}
    top = chk.section("pbf", raw, _PBF)
    scanner = ScannerParams(**chk.section("pbf.scanner", sub.get("scanner", {}), _SCANNER))
    zone_raw = sub.get("zone", {})
    if not isinstance(zone_raw, Mapping):
        raise chk.fail("pbf.zone", None, "must be a table of zone tables")
    for name in zone_raw:
        if name not in ZONES:
            raise chk.fail(f"pbf.zone.{name}", None, f"unknown zone {name!r}; zones are {', '.join(ZONES)}")
    zones = []
    for name in ZONES:
        given = chk.section(f"pbf.zone.{name}", zone_raw.get(name, {}), _ZONE)
        zones.append(ZoneParams(**{**asdict(_ZONE_DEFAULTS[name]), **given}))
    return BuildParams(**top, scanner=scanner, zones=tuple(zones))


def load_params(path: str | Path) -> BuildParams:
    """Read and validate a build-parameters TOML file (``[pbf]``)."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise MachineFileError(str(p), "", f"cannot read: {exc.strerror or exc}") from None
    return parse_params(text, str(p))


def default_params(**overrides: Any) -> BuildParams:
    """Parameters with the documented defaults (layer 30 µm, hatch 0.1 mm, spot 80 µm), ``overrides`` applied."""
    base: dict[str, Any] = dict(layer_thickness_mm=0.03, hatch_spacing_mm=0.1, spot_diameter_mm=0.08)
    base.update(overrides)
    base.setdefault("zones", tuple(_ZONE_DEFAULTS[z] for z in ZONES))
    return BuildParams(**base)
