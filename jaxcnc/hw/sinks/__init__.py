"""Sinks the player streams rows to. ``open_sink("sim")`` builds one from its command-line name."""

from __future__ import annotations

from jaxcnc.errors import JaxcncError
from jaxcnc.hw.sinks.base import Sink
from jaxcnc.hw.sinks.sim import SimSink


def open_sink(spec: str, **options) -> Sink:
    """The sink named by ``spec`` (``sim``); options go to its constructor."""
    if spec == "sim":
        return SimSink(**options)
    raise JaxcncError(f"unknown or not yet supported sink {spec!r}; available: sim")


__all__ = ["SimSink", "Sink", "open_sink"]
