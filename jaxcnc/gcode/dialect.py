"""G-code dialects: which comment styles, spline syntaxes, keywords and ``NAME=value`` addresses a
program may use, described in TOML (``jaxcnc/gcode/dialects/*.toml``; users can pass their own file).

One interpreter and one preprocessor serve every dialect, as the source documents' configurable
preprocessor did: a dialect only switches syntax on and off and names what its words mean.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from jaxcnc.errors import JaxcncError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

SPLINE_SYNTAXES = ("G5", "G5.1", "G5.2", "G6.2", "BSPLINE")
KEYWORD_MEANINGS = ("BSPLINE",)
ADDRESS_MEANINGS = ("weight", "degree", "knot_interval")
#: What a dialect's G code may be declared to mean (``[g_codes]``): the units and the path-control modes.
G_ALIAS_MEANINGS = frozenset({200, 210, 610, 611, 640})
BUILTIN = ("linuxcnc", "siemens", "fanuc")


@dataclass(frozen=True)
class Dialect:
    name: str
    paren_comments: bool = True
    semicolon_comments: bool = True
    arc_centers_absolute: bool = False
    splines: tuple[str, ...] = ("G5", "G5.1", "G5.2", "G6.2")
    keywords: dict[str, str] = field(default_factory=dict)  # upper-case word -> meaning
    addresses: dict[str, str] = field(default_factory=dict)  # upper-case NAME -> meaning
    #: A line of an ``O`` number alone (beside comments) names the program (Fanuc, Haas: ``O1001 (PART)``); else an
    #: O-word needs a keyword (LinuxCNC's O-word control flow).
    program_numbers: bool = False
    #: A line ``%_N_<NAME>_MPF`` (or ``_SPF``) names the program (Sinumerik): read, and nothing else.
    program_names: bool = False
    #: ``D<n>`` applies the selected tool's offsets (Sinumerik's cutting edge: ``T1 D1``; ``D0`` none), as
    #: ``G43 H<T>`` does; else ``D`` is a cutter-compensation word, which is refused.
    edge_offsets: bool = False
    #: G codes of the dialect that mean another code (tenths: Sinumerik's ``G71`` is ``G21``, 710 -> 210).
    g_codes: dict[int, int] = field(default_factory=dict)


#: The dialect's switches (``[dialect]`` keys, true or false).
_FLAGS = ("program_numbers", "program_names", "edge_offsets")


def _fail(src: str, reason: str) -> JaxcncError:
    return JaxcncError(f"{src}: dialect: {reason}")


def parse_dialect(text: str, src: str = "<dialect>") -> Dialect:
    """A dialect from TOML text (see the built-in files for the keys)."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _fail(src, f"not valid TOML: {exc}") from None
    unknown = set(doc) - {"dialect", "keywords", "addresses", "g_codes"}
    if unknown:
        raise _fail(src, f"unknown table(s) {sorted(unknown)}")
    d = doc.get("dialect", {})
    unknown = set(d) - {"name", "comments", "arc_centers", "splines", *_FLAGS}
    if unknown:
        raise _fail(src, f"unknown key(s) {sorted(unknown)} in [dialect]")
    comments = d.get("comments", ["paren", "semicolon"])
    if not isinstance(comments, list) or any(c not in ("paren", "semicolon") for c in comments):
        raise _fail(src, "[dialect] comments must list 'paren' and/or 'semicolon'")
    centers = d.get("arc_centers", "incremental")
    if centers not in ("incremental", "absolute"):
        raise _fail(src, "[dialect] arc_centers must be 'incremental' or 'absolute'")
    splines = d.get("splines", [])
    if not isinstance(splines, list) or any(s not in SPLINE_SYNTAXES for s in splines):
        raise _fail(src, f"[dialect] splines must be a list of {', '.join(SPLINE_SYNTAXES)}")
    flags = {k: d.get(k, False) for k in _FLAGS}
    for k, v in flags.items():
        if not isinstance(v, bool):
            raise _fail(src, f"[dialect] {k} must be true or false")
    g_codes = {}
    for k, v in doc.get("g_codes", {}).items():
        code, meaning = _g_tenths(k), _g_tenths(v) if isinstance(v, str) else None
        if code is None or meaning is None or meaning not in G_ALIAS_MEANINGS:
            raise _fail(
                src, f"[g_codes] {k} = {v!r}: a G code of the dialect and the one it means, one of "
                f"{', '.join(f'G{c / 10:g}' for c in sorted(G_ALIAS_MEANINGS))}",
            )  # fmt: skip
        g_codes[code] = meaning
    keywords = {str(k).upper(): v for k, v in doc.get("keywords", {}).items()}
    for k, v in keywords.items():
        if v not in KEYWORD_MEANINGS or not k.isalpha():
            raise _fail(src, f"[keywords] {k} = {v!r}: meanings are {', '.join(KEYWORD_MEANINGS)}")
    addresses = {str(k).upper(): v for k, v in doc.get("addresses", {}).items()}
    for k, v in addresses.items():
        if v not in ADDRESS_MEANINGS or not k.isalpha() or len(k) < 2:
            raise _fail(
                src,
                f"[addresses] {k} = {v!r}: names of two letters or more; meanings are {', '.join(ADDRESS_MEANINGS)}",
            )
    return Dialect(
        name=str(d.get("name", Path(src).stem)),
        paren_comments="paren" in comments,
        semicolon_comments="semicolon" in comments,
        arc_centers_absolute=centers == "absolute",
        splines=tuple(splines),
        keywords=keywords,
        addresses=addresses,
        g_codes=g_codes,
        **flags,
    )


def _g_tenths(word: str) -> int | None:
    """``"G71"`` -> 710, ``"G64.1"`` -> 641; ``None`` if not a G word."""
    m = re.fullmatch(r"[Gg](\d{1,4})(?:\.(\d))?", word.strip())
    return None if m is None else int(m.group(1)) * 10 + int(m.group(2) or 0)


def load_dialect(name_or_path: str | Dialect | None) -> Dialect:
    """A built-in dialect by name (linuxcnc, siemens, fanuc) or a dialect TOML file."""
    if isinstance(name_or_path, Dialect):
        return name_or_path
    if name_or_path is None:
        name_or_path = "linuxcnc"
    if name_or_path in BUILTIN:
        text = resources.files("jaxcnc.gcode.dialects").joinpath(f"{name_or_path}.toml").read_text()
        return parse_dialect(text, f"{name_or_path}.toml")
    p = Path(name_or_path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise JaxcncError(
            f"{p}: unknown dialect (built in: {', '.join(BUILTIN)}) and not a readable file: {exc}"
        ) from None
    return parse_dialect(text, str(p))


LINUXCNC = Dialect("linuxcnc")
