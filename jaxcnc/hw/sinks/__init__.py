"""Sinks the player streams rows to. ``open_sink("sim")`` builds one from its command-line name."""

from __future__ import annotations

from jaxcnc.errors import JaxcncError
from jaxcnc.hw.sinks.base import Sink
from jaxcnc.hw.sinks.sim import SimSink


def open_sink(spec: str, **options) -> Sink:
    """The sink named by ``spec`` (``sim``, ``scanner``, ``halstreamer``, ``tcp://HOST:PORT``, ``udp://HOST:PORT``)."""
    if spec == "sim":
        return SimSink(**options)
    if spec == "scanner":
        from jaxcnc.hw.sinks.scanner import ScannerSink

        return ScannerSink(**options)
    if spec in ("halstreamer", "hal"):
        from jaxcnc.hw.sinks.hal import HalStreamerSink

        return HalStreamerSink(**options)
    if spec.startswith(("tcp://", "udp://")):
        from jaxcnc.hw.sinks.stream import StreamSink

        try:
            return StreamSink(spec, **options)
        except ValueError as exc:
            raise JaxcncError(str(exc)) from None
    raise JaxcncError(
        f"unknown or not yet supported sink {spec!r}; available: sim, scanner, halstreamer, tcp://HOST:PORT, udp://HOST:PORT"
    )


__all__ = ["SimSink", "Sink", "open_sink"]
