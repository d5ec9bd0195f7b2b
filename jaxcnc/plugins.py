"""Plug-ins by name: one registry mechanism for every extension point, fed by built-ins and entry points.

Each extension point owns one :class:`Registry`, kept beside the protocol its items implement:

=====================================  ==========================  ==============================================
registry                               entry-point group           an item is (looked up by)
=====================================  ==========================  ==============================================
``jaxcnc.planners.registry.PLANNERS``  ``jaxcnc.planners``         a :class:`~jaxcnc.planners.protocol.Planner`
                                                                   subclass or instance (``--planner NAME``,
                                                                   ``[machine] planner``, ``plan_job(planner=)``)
``jaxcnc.planners.pulsed.request.``    ``jaxcnc.pulse_planners``   a callable ``(PulseRequest) -> PulsePlan``
``PULSE_PLANNERS``                                                 (``--planner NAME`` on point jobs)
``jaxcnc.front_ends.FRONT_ENDS``       ``jaxcnc.front_ends``       a :class:`~jaxcnc.front_ends.FrontEnd` subclass
                                                                   or instance (the input's suffix, no dot)
``jaxcnc.hw.sinks.SINKS``              ``jaxcnc.sinks``            a callable ``(spec, **options) -> Sink``
                                                                   (``--sink NAME``, or ``NAME://...``)
=====================================  ==========================  ==============================================

Built-ins register when their module is imported (``register`` used as a decorator), or are named by
``"module:attribute"`` and imported on first use (:meth:`Registry.register_lazy`). A third-party
distribution adds items by declaring entry points, e.g. in its ``pyproject.toml``::

    [project.entry-points."jaxcnc.planners"]
    gentle = "slow_planner:GentlePlanner"

An entry point is loaded on the first lookup of its name only (importing a plug-in costs nothing until
it is used, and a broken plug-in does not break the others); a plug-in that fails to load is reported
in one line naming it, its distribution and the cause. Built-in names win over entry points of the
same name. An unknown name is an error listing the known ones.

This module imports the standard library alone: the player side (``jaxcnc.hw``, NumPy only) uses it.
"""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Generic, TypeVar

from jaxcnc.errors import JaxcncError

T = TypeVar("T")

#: The entry-point groups jaxcnc reads, and what an entry point of each names.
GROUPS = {
    "jaxcnc.planners": "a Planner subclass or instance (contour velocity planner)",
    "jaxcnc.pulse_planners": "a callable (PulseRequest) -> PulsePlan (pulsed point jobs)",
    "jaxcnc.front_ends": "a FrontEnd subclass or instance; the entry point's name is the file suffix",
    "jaxcnc.sinks": "a callable (spec, **options) -> Sink; the name is the sink's name or URL scheme",
}


class PluginError(JaxcncError):
    """A plug-in that cannot be found or loaded (reported in one line, exit status 2)."""


class Registry(Generic[T]):
    """Named items of one kind: registered in code or found through the entry-point ``group``.

    Args:
        what: what an item is, for messages (``"planner"``).
        group: the entry-point group third-party distributions declare items in.
        adapt: turns what was registered or loaded into an item (e.g. a class into an instance); it may
            raise ``TypeError`` for an object of the wrong kind, reported naming the plug-in.
        error: the error class raised for unknown names and broken plug-ins.
    """

    def __init__(
        self,
        what: str,
        group: str,
        adapt: Callable[[Any], T] | None = None,
        error: type[JaxcncError] = PluginError,
    ):
        self.what, self.group, self.error = what, group, error
        self._adapt = adapt or (lambda obj: obj)
        self._items: dict[str, T] = {}
        self._lazy: dict[str, str] = {}  # built-ins by "module:attribute", imported on first lookup
        self._origins: dict[str, str] = {}  # loaded plug-ins: where each came from
        self._entry_points: dict[str, EntryPoint] | None = None  # found on first need

    def register(self, name: str, item: Any = None):
        """Make ``item`` available under ``name``; without ``item``, a decorator returning what it decorates."""
        if item is None:

            def deco(obj):
                self._items[name] = self._adapt(obj)
                return obj

            return deco
        self._items[name] = self._adapt(item)
        return item

    def register_lazy(self, name: str, target: str) -> None:
        """A built-in item at ``target`` (``"package.module:attribute"``), imported on its first lookup:
        listing names costs no import (the player side never imports the planning stack this way)."""
        self._lazy[name] = target

    def get(self, name: str) -> T:
        """The item named ``name``: registered, or loaded from its entry point on this first lookup."""
        if name in self._items:
            return self._items[name]
        if name in self._lazy:
            module, _, attr = self._lazy[name].partition(":")
            obj = getattr(import_module(module), attr)
            if name not in self._items:  # importing may have registered it already
                self._items[name] = self._adapt(obj)
            return self._items[name]
        ep = self.entry_points().get(name)
        if ep is None:
            raise self.error(f"unknown {self.what} {name!r}; known: {', '.join(self.names())}")
        self._items[name] = self._load(ep)
        self._origins[name] = _where(ep)
        return self._items[name]

    def origin(self, name: str) -> str | None:
        """Where the plug-in ``name`` came from (its entry point and distribution), ``None`` for a built-in
        or one registered in code. Callers name it when third-party code fails at run time."""
        return self._origins.get(name)

    def failed(self, name: str, exc: BaseException) -> JaxcncError | None:
        """The one-line error for plug-in ``name`` having raised ``exc`` while it ran, or ``None`` when
        ``name`` is not an entry-point plug-in (a built-in's failure is a bug to report with its traceback)."""
        where = self.origin(name)
        if where is None or isinstance(exc, JaxcncError):
            return None
        return self.error(f"{self.what} plug-in {name!r} ({where}) failed: {_cause(exc)}")

    def names(self) -> list[str]:
        """Every name that :meth:`get` knows, built-in or from an entry point (none is loaded)."""
        return sorted(set(self._items) | set(self._lazy) | set(self.entry_points()))

    def __contains__(self, name: object) -> bool:
        return name in self._items or name in self._lazy or name in self.entry_points()

    def entry_points(self) -> dict[str, EntryPoint]:
        """The group's entry points by name (read once; built-in names shadow them)."""
        if self._entry_points is None:
            found: dict[str, EntryPoint] = {}
            for ep in entry_points(group=self.group):
                if ep.name not in found:  # the first on sys.path wins, as for imports
                    found[ep.name] = ep
            self._entry_points = found
        return {k: v for k, v in self._entry_points.items() if k not in self._items and k not in self._lazy}

    def forget_entry_points(self) -> None:
        """Read the entry points again on the next lookup (after installing a distribution at run time)."""
        self._entry_points = None

    def _load(self, ep: EntryPoint) -> T:
        try:
            return self._adapt(ep.load())
        except Exception as exc:  # any failure of third-party code: one line naming the plug-in
            raise self.error(
                f"{self.what} plug-in {ep.name!r} ({_where(ep)}, entry-point group {self.group}) failed to load: "
                f"{_cause(exc)}"
            ) from None


def _where(ep: EntryPoint) -> str:
    dist = getattr(getattr(ep, "dist", None), "name", None)
    return f"{ep.value}" + (f" from distribution {dist!r}" if dist else "")


def _cause(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}".splitlines()[0] if str(exc) else type(exc).__name__
