"""Sinks the player streams rows to, by name: ``open_sink("sim")``, ``open_sink("tcp://HOST:PORT")``.

:data:`SINKS` holds a factory ``(spec, **options) -> Sink`` per name: a plain name (``sim``, ``scanner``,
``halstreamer``) or a URL scheme (``tcp``, ``udp``: the whole URL is the spec). Built-ins are imported on
first use; third-party sinks are declared under the ``jaxcnc.sinks`` entry-point group
(:mod:`jaxcnc.plugins`), e.g. ``myboard = "my_board:open_board"`` for ``--sink myboard://10.0.0.7``.
"""

from __future__ import annotations

from jaxcnc.errors import JaxcncError
from jaxcnc.hw.sinks.base import Sink
from jaxcnc.hw.sinks.sim import SimSink
from jaxcnc.plugins import Registry

#: Sink factories ``(spec, **options) -> Sink`` by name or URL scheme (entry-point group ``jaxcnc.sinks``).
SINKS: Registry = Registry("sink", "jaxcnc.sinks", error=JaxcncError)


def _sim(spec: str, **options) -> Sink:
    return SimSink(**options)


def _scanner(spec: str, **options) -> Sink:
    from jaxcnc.hw.sinks.scanner import ScannerSink

    return ScannerSink(**options)


def _halstreamer(spec: str, **options) -> Sink:
    from jaxcnc.hw.sinks.hal import HalStreamerSink

    return HalStreamerSink(**options)


def _stream(spec: str, **options) -> Sink:
    from jaxcnc.hw.sinks.stream import StreamSink

    try:
        return StreamSink(spec, **options)
    except ValueError as exc:
        raise JaxcncError(str(exc)) from None


for _name, _factory in (("sim", _sim), ("scanner", _scanner), ("halstreamer", _halstreamer), ("hal", _halstreamer)):
    SINKS.register(_name, _factory)
SINKS.register("tcp", _stream)
SINKS.register("udp", _stream)


def open_sink(spec: str, **options) -> Sink:
    """The sink named by ``spec`` (``sim``, ``scanner``, ``halstreamer``, ``tcp://HOST:PORT``, ``udp://HOST:PORT``,
    or a plug-in's name or ``scheme://...``)."""
    name = spec.split("://", 1)[0] if "://" in spec else spec
    if name not in SINKS:
        known = ", ".join(n + "://..." if n in ("tcp", "udp") else n for n in SINKS.names())
        raise JaxcncError(f"unknown sink {spec!r}; available: {known}")
    return SINKS.get(name)(spec, **options)


__all__ = ["SINKS", "SimSink", "Sink", "open_sink"]
