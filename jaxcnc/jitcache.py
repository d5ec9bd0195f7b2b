"""Compiled programs that a fresh process loads instead of tracing them again: :func:`cached_jit`.

``jax.jit`` traces a Python function and lowers it to StableHLO in every new process, before its persistent
compile cache can hand back the executable: on a 2000-block program ``jaxcnc plan`` spent ~0.8 s tracing and
~0.5 s lowering its 14 programs, with every executable already on disk. A function made with :func:`cached_jit`
behaves as ``jax.jit`` of it, and where the compile cache is on (:func:`~jaxcnc.jaxconfig.configure_jax`, as the
command line does) it also keeps each traced program, as ``jax.export`` serialises it, next to the executables
(``<cache>/exports``): a later process with the same arguments' shapes deserialises the program and only
compiles it, which the compile cache answers.

A stored program is used only where everything that made it is the same (the key of its file):

* the function (module and qualified name), its static arguments (``repr``) and the tree, shapes, dtypes and
  weak types of the others;
* JAX and jaxlib, float64 on or off, the platform it runs on;
* every jaxcnc source file's bytes, and every jaxcnc module's simple globals (numbers, strings, tuples, arrays)
  and functions' code as they are in this process when the program is made: a constant or a function replaced
  at run time (a test's monkeypatch) makes other programs, never reads a stored one made without it.

Beside each program its executable for this host (``.xla``: :mod:`jax.experimental.serialize_executable`, keyed
also by the compiler options, the device kind and, on a CPU, the processor's model and instruction-set flags) is
stored when the process compiles it, and a later process loads that instead of lowering the program and asking
JAX's compile cache: a warm ``jaxcnc plan`` of a 1.5k-block CAM part loaded its 11 planning programs in 0.24 s
against ~0.7 s through the compile cache (docs/planning.md, "Eighth pass"). The two do not mix: an executable that
JAX's compile cache handed back lacks its functions when serialised again (XLA:CPU: "Function ... not found" in the
process that runs it). So a stored executable is compiled under a name of its own (the file's), which JAX's cache
keys too — it never hands back one compiled for another version of the program — and one it handed back all the
same (its hits are counted per thread) is run but never stored. Executables are read with ``pickle``: only files
and folders no other user may write. ``JAXCNC_EXECUTABLE_CACHE=0``: programs alone, compiled by every process (JAX's
compile cache answers).

Programs from other source versions are removed when a new version writes its first (the newest
``KEEP_VERSIONS`` kept). Set ``JAXCNC_EXPORT_CACHE=0`` to trace as ``jax.jit`` does. Anything ``jax.export``
cannot store (or a damaged file) falls back to ``jax.jit``, with the same results.

A process that lives long (a planning service, a worker of a build, a user's loop over parts) keeps every program
it compiled: :func:`release_when_crowded` hands them back before they reach the kernel's limit on memory mappings
(each XLA:CPU executable maps memory of its own, and past ``vm.max_map_count`` LLVM crashes compiling the next one).
:func:`~jaxcnc.planners.job.plan_job` and every job of :mod:`jaxcnc.jobs` call it first.

A first run compiles its programs where they are first called, one after the other; :func:`compile_ahead` calls one
in a background thread while the caller goes on (XLA compiles outside the GIL), so on two cores two compiles
proceed side by side (docs/planning.md, "First runs").
"""

from __future__ import annotations

import functools
import gc
import hashlib
import inspect
import os
import pickle
import platform as platform_module
import re
import shutil
import sys
import tempfile
import threading
import types
import weakref
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import jax
import numpy as np

#: Source versions whose stored programs are kept in the cache directory.
KEEP_VERSIONS = 3
#: Where stored programs go when set (a test's temporary directory); ``None``: beside the compile cache.
DIRECTORY: Path | None = None
_LOCK = threading.RLock()
#: Share of the kernel's limit on a process's memory mappings (``vm.max_map_count``) above which
#: :func:`release_when_crowded` releases the compiled programs.
CROWDED_SHARE = 0.5
#: ``vm.max_map_count`` where ``/proc`` does not say (Linux's default).
DEFAULT_MAX_MAP_COUNT = 65530
_INSTANCES: weakref.WeakSet = weakref.WeakSet()  # every _CachedJit made, for release_when_crowded


def memory_maps() -> int:
    """The memory mappings of this process (``/proc/self/maps`` lines; 0 where there is no procfs)."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return 0


def max_map_count() -> int:
    """The kernel's limit on a process's memory mappings (``vm.max_map_count``; Linux's default where unknown)."""
    try:
        with open("/proc/sys/vm/max_map_count", "rb") as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return DEFAULT_MAX_MAP_COUNT


def release_when_crowded(limit: int | None = None) -> bool:
    """Release every compiled program of this process (``jax.clear_caches`` and the stored programs' calls) where
    it has more than ``limit`` memory mappings (default: ``CROWDED_SHARE`` of ``vm.max_map_count``); returns
    whether it did. The next call of a program compiles it again (from the compile cache where it is on).

    Each XLA:CPU executable maps memory of its own, and a process that keeps every program it compiled passes the
    kernel's limit: the test suite did (LLVM segfaulted at 93 % of the run, 2026-11-28), and so would a long-lived
    process planning many different jobs (the S-curve stage's cuts make many grid sizes). Counting the mappings
    reads ``/proc/self/maps`` (~0.1 ms per thousand)."""
    limit = int(CROWDED_SHARE * max_map_count()) if limit is None else limit
    if memory_maps() <= limit:
        return False
    with _LOCK:
        for instance in list(_INSTANCES):
            with instance.lock:
                instance.calls.clear()
        jax.clear_caches()
    gc.collect()  # the executables go with the last Python objects that hold them
    return True


def cached_jit(
    fun: Callable | None = None,
    *,
    static_argnames: tuple[str, ...] = (),
    compiler_options: dict[str, str] | None = None,
):
    """``jax.jit(fun, static_argnames=..., compiler_options=...)`` whose traced programs are kept on disk with the
    compile cache (module docstring). Usable as a decorator, with or without arguments."""
    if fun is None:
        return functools.partial(cached_jit, static_argnames=static_argnames, compiler_options=compiler_options)
    return _CachedJit(fun, tuple(static_argnames), compiler_options)


#: The compile-ahead thread, once made (in a list: a module global's value keys the stored programs), and the calls
#: it has been sent (:func:`compile_ahead`).
_AHEAD: list[ThreadPoolExecutor] = []
_SEEN: set = set()


def compile_ahead(fun: Callable, *args, **kwargs) -> Future:
    """Call ``fun(*args, **kwargs)`` (a compiled function, on arguments of the shapes a later call will have) in a
    background thread, under the caller's default device, and return its future: the program is compiled (or
    loaded from the compile cache) while the caller goes on, and the later call finds it ready. Wait on the
    future before that call (else both compile it). XLA compiles outside the GIL: on two cores a first run hides
    one program's compile behind the caller's work. The result is the call's.

    Only a call this process has not made before (the function, the arguments' shapes and dtypes, the other
    arguments' values) goes to the thread; later ones run here and return a finished future: a compiled program
    run beside the caller's only shares the cores (the 100k-block blended contour took 5-10 % more CPU with every
    call sent to the thread)."""
    if not _first_call(fun, args, kwargs):
        done: Future = Future()
        done.set_result(fun(*args, **kwargs))
        return done
    return _submit(fun, args, kwargs)


def warm_ahead(fun: Callable, *args, **kwargs) -> Future | None:
    """:func:`compile_ahead` of a call whose result nobody reads (arguments made up to have a later call's
    shapes): its future where this process has not made the call before, else ``None`` and nothing run — the
    program is compiled already, and running it again on the made-up arguments would only take the cores from
    the caller (the blends' kernel warmed so on 65,536 straight blends took ~70 ms CPU from every 100k-block
    blended plan after a process's first)."""
    return _submit(fun, args, kwargs) if _first_call(fun, args, kwargs) else None


def _first_call(fun: Callable, args: tuple, kwargs: dict) -> bool:
    """Whether this process makes this call (:func:`compile_ahead`'s "made before") for the first time; records
    it."""
    leaves, tree = jax.tree.flatten((args, kwargs))
    seen = (fun, str(tree), tuple(_call_key(x) for x in leaves))
    with _LOCK:
        first = seen not in _SEEN
        if len(_SEEN) > 1 << 14:
            _SEEN.clear()
        _SEEN.add(seen)
        if first and not _AHEAD:
            _AHEAD.append(ThreadPoolExecutor(1, thread_name_prefix="jaxcnc-compile-ahead"))
    return first


def _submit(fun: Callable, args: tuple, kwargs: dict) -> Future:
    """``fun(*args, **kwargs)`` in the compile-ahead thread, under the caller's default device."""
    device = jax.config.jax_default_device  # thread-local: the worker enters the caller's

    def run():
        if device is None:
            return fun(*args, **kwargs)
        with jax.default_device(device):
            return fun(*args, **kwargs)

    return _AHEAD[0].submit(run)


def _call_key(x: Any) -> Any:
    """What of an argument decides :func:`compile_ahead`'s "made before": an array's shape and dtype, a simple
    value itself, another object's type and length (a grid: its intervals)."""
    if hasattr(x, "shape") and hasattr(x, "dtype"):
        return (tuple(np.shape(x)), str(x.dtype))
    if isinstance(x, bool | int | float | str | type(None) | tuple):
        return repr(x)
    return (type(x).__name__, len(x) if hasattr(x, "__len__") else None)


def export_dir() -> Path | None:
    """Where stored programs go: :data:`DIRECTORY` where set, else ``exports`` in the compile cache's directory, or
    ``None`` (no compile cache, or ``JAXCNC_EXPORT_CACHE=0``)."""
    if os.environ.get("JAXCNC_EXPORT_CACHE", "1") == "0":
        return None
    if DIRECTORY is not None:
        return DIRECTORY
    root = jax.config.jax_compilation_cache_dir
    return Path(root) / "exports" if root else None


class _CachedJit:
    """The callable :func:`cached_jit` returns."""

    def __init__(self, fun: Callable, static: tuple[str, ...], compiler_options: dict[str, str] | None) -> None:
        self.fun, self.static, self.options = fun, static, compiler_options
        self.jitted = jax.jit(fun, static_argnames=static or None, compiler_options=compiler_options)
        self.signature = inspect.signature(fun)
        self.names = [k for k in self.signature.parameters if k not in static]  # the traced arguments, in order
        self.calls: dict[tuple, Callable | None] = {}  # key -> the stored program's call (None: jax.jit's)
        # one program's load or export at a time; other functions' go on in other threads (compile_ahead)
        self.lock = threading.RLock()
        functools.update_wrapper(self, fun)
        _INSTANCES.add(self)

    def __call__(self, *args, **kwargs):
        root = export_dir()
        if root is None:
            return self.jitted(*args, **kwargs)
        bound = self.signature.bind(*args, **kwargs)
        bound.apply_defaults()
        static = {k: bound.arguments[k] for k in self.static}
        dynamic = [bound.arguments[k] for k in self.names]
        leaves, tree = jax.tree.flatten(dynamic)
        statics = tuple((k, _static_key(v)) for k, v in sorted(static.items()))
        if any(v is None for _, v in statics):  # a static argument that cannot be named across processes
            return self.jitted(*args, **kwargs)
        key = (repr(statics), str(tree), tuple(_aval_key(x) for x in leaves), _platform())
        with self.lock:
            call = self.calls.get(key, False)
            if call is False:
                call = self.calls[key] = self._load_or_export(root, key, static, dynamic)
        if call is None:
            return self.jitted(*args, **kwargs)
        try:
            return call(*dynamic)
        except Exception:  # (arguments on another device than the program's platform, say): as jax.jit, from now on
            with self.lock:
                self.calls[key] = None
            return self.jitted(*args, **kwargs)

    def _load_or_export(self, root: Path, key: tuple, static: dict, dynamic: list):
        """The stored program's call for ``key``: its executable for this host where one is stored (module
        docstring), else the program read from ``root`` (or traced, exported and written there), compiled, and its
        executable stored; ``None`` where ``jax.export`` cannot store it."""
        from jax import export

        platform = key[-1]
        made = (key, _environment(platform), _globals_fingerprint(self.fun.__module__))
        digest = hashlib.sha256(repr(made).encode()).hexdigest()
        folder = root / _source_fingerprint()
        path = folder / f"{self.fun.__module__}.{self.fun.__qualname__}-{digest[:32]}.exported"
        binary = None
        if executables_on():
            host = hashlib.sha256(repr((digest, self.options, _host_key(platform))).encode()).hexdigest()
            binary = path.with_name(f"{path.stem}-{host[:16]}.xla")
            loaded = _load_executable(binary)
            if loaded is not None:
                return loaded
        exported = None
        try:
            exported = export.deserialize(bytearray(path.read_bytes()))
        except FileNotFoundError:
            pass
        except Exception:  # a damaged or foreign file: made again below
            exported = None
        if exported is None:
            fun, names = self.fun, self.names

            def bound(*values):
                return fun(**dict(zip(names, values, strict=True)), **static)

            try:
                data = export.export(jax.jit(bound), platforms=[platform])(*dynamic).serialize()
                _write(folder, path, data)
                # called as a later process calls it (serialising drops weak types from the results, and the
                # programs after it must see the same arguments either way)
                exported = export.deserialize(bytearray(data))
            except Exception:  # not exportable (or the directory not writable): plain jax.jit
                return None
        if binary is None:
            return jax.jit(exported.call, compiler_options=self.options)
        # compiled under a name of its own (JAX's compile cache keys it by that name too: never an executable of
        # another version of the program, nor one compiled where executables are not stored, comes back from it)
        name = re.sub(r"\W", "_", f"jaxcnc_{self.fun.__qualname__}_{binary.stem[-16:]}")
        call = jax.jit(_named(exported.call, name), compiler_options=self.options)
        return _compile_and_store(call, dynamic, folder, binary)


def _static_key(value: Any) -> str | None:
    """A static argument as it names the program in every process: its ``repr``, or for a jaxcnc module's own
    function (no closure) its module, name and code; ``None`` for other callables (a closure, a plug-in's function:
    what they read is not in the key)."""
    if not callable(value):
        return repr(value)
    code = getattr(value, "__code__", None)
    module = getattr(value, "__module__", "") or ""
    qualname = getattr(value, "__qualname__", "")
    if code is None or value.__closure__ or "<" in qualname or not module.startswith("jaxcnc"):
        return None
    return f"{module}.{qualname}:{hashlib.sha256(_code_bytes(code)).hexdigest()[:16]}"


def _aval_key(x: Any) -> tuple:
    """Shape, dtype and weak type of a leaf (what a traced program depends on)."""
    aval = jax.typeof(x)
    return (tuple(aval.shape), str(aval.dtype), bool(getattr(aval, "weak_type", False)))


def _platform() -> str:
    """The platform the program runs on: the default device's (a planning scope), else the default backend's."""
    device = jax.config.jax_default_device
    if device is None:
        return jax.default_backend()
    return device if isinstance(device, str) else device.platform


def _environment(platform: str) -> tuple:
    import jaxlib

    return (jax.__version__, jaxlib.__version__, bool(jax.config.jax_enable_x64), platform)


@functools.cache
def _source_fingerprint() -> str:
    """A hash of every jaxcnc source file (their bytes, in path order)."""
    package = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:24]


#: Fingerprints by what they were computed from (:func:`_globals_fingerprint`); in a dict: the value of a module
#: global (``None``, a number) would key the stored programs itself.
_FINGERPRINTS: dict[tuple, str] = {}


def _globals_fingerprint(module: str) -> str:
    """A hash of the jaxcnc modules' (and ``module``'s) simple globals and functions' code as they are now (see the
    module docstring).

    Hashing every global's bytes and code took ~60 ms a program (0.8 s of a warm 'jaxcnc plan' of a CAM part); it is
    done once for each state of the modules, recognised by the identity of every global (a monkeypatch replaces
    one) and the bytes of the small arrays among them (which may be written in place)."""
    names = sorted({m for m in list(sys.modules) if m == "jaxcnc" or m.startswith("jaxcnc.")} | {module})
    modules = [(name, sys.modules.get(name)) for name in names]
    state = tuple(
        (name, attr, id(value), value.tobytes() if isinstance(value, np.ndarray) and value.size <= 1 << 16 else None)
        for name, mod in modules
        if mod is not None
        for attr, value in list(vars(mod).items())
    )
    with _LOCK:
        found = _FINGERPRINTS.get(state)
    if found is not None:
        return found
    h = hashlib.sha256()
    for name, mod in modules:
        if mod is None:
            continue
        for attr, value in sorted(vars(mod).items(), key=lambda kv: kv[0]):
            part = _value_key(value)
            if part is not None:
                h.update(f"{name}.{attr}=".encode())
                h.update(part)
    with _LOCK:
        if len(_FINGERPRINTS) > 64:
            _FINGERPRINTS.clear()
        _FINGERPRINTS[state] = found = h.hexdigest()
    return found


def _value_key(value: Any) -> bytes | None:
    """Bytes that change when ``value`` (a module global) does, for the values a trace may read."""
    if isinstance(value, bool | int | float | complex | str | bytes | type(None)):
        return repr(value).encode()
    if isinstance(value, tuple | frozenset) and all(isinstance(v, bool | int | float | str) for v in value):
        return _const_bytes(value)
    if isinstance(value, np.ndarray) and value.size <= 1 << 16:
        return str(value.dtype).encode() + repr(value.shape).encode() + value.tobytes()
    code = getattr(getattr(value, "__wrapped__", value), "__code__", None)
    if code is not None:
        return _code_bytes(code)
    return None


def _code_bytes(code: types.CodeType) -> bytes:
    """A function's bytecode and constants, nested functions' included (no addresses: the same in every process)."""
    return b"\0".join([code.co_code, *(_const_bytes(c) for c in code.co_consts)])


def _const_bytes(const: Any) -> bytes:
    """A code object's constant as bytes that are the same in every process (sets sorted: their order follows the
    process's string hashing; nested code objects by their own bytes)."""
    if isinstance(const, types.CodeType):
        return _code_bytes(const)
    if isinstance(const, frozenset | set):
        return b"{" + b",".join(sorted(_const_bytes(c) for c in const)) + b"}"
    if isinstance(const, tuple):
        return b"(" + b",".join(_const_bytes(c) for c in const) + b")"
    return repr(const).encode()


def remembered(name: str, probe: Callable[[], bool]) -> bool:
    """``probe()``, a fact about this JAX and jaxlib (whether XLA knows an option, say), answered once per cache
    directory: kept in a file named for it and the versions beside the stored programs, and asked of ``probe``
    where there is no cache directory or no such file. One call at a time in a process (callers cache it)."""
    root = export_dir()
    if root is None:
        return probe()
    path = root / f"{name}-{'-'.join(map(str, _environment(_platform())))}.fact".replace(" ", "")

    def read() -> bool | None:
        try:
            return {b"1": True, b"0": False}.get(path.read_bytes())
        except OSError:
            return None

    with _LOCK:  # (two threads' first calls: one probe, the other reads its answer)
        found = read()
        if found is not None:
            return found
        found = probe()
        try:
            _write_atomic(root, path, b"1" if found else b"0")
        except OSError:  # a read-only cache: asked again next time
            pass
    return found


def executables_on() -> bool:
    """Whether compiled executables are stored and loaded beside the programs (``JAXCNC_EXECUTABLE_CACHE=0``: the
    programs alone, compiled by each process, which the compile cache answers)."""
    return os.environ.get("JAXCNC_EXECUTABLE_CACHE", "1") != "0" and hasattr(os, "getuid")


@functools.cache
def _host_key(platform: str) -> tuple:
    """What an executable depends on beyond its program and JAX's versions: the device kind, and on a CPU the
    processor (architecture, model, instruction-set flags) — XLA:CPU compiles for the features of the host, and
    code made on one processor need not run on another sharing the cache directory."""
    try:
        kind = jax.devices(platform)[0].device_kind
    except RuntimeError:
        kind = platform
    if platform != "cpu":
        return (platform, kind)
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            info = f.read()
    except OSError:
        info = ""
    first = info.split("\n\n", 1)[0]  # the first processor's lines (every core of a host is alike)
    lines = tuple(ln for ln in first.splitlines() if ln.split(":", 1)[0].strip() in _CPU_KEYS)
    return (platform, kind, platform_module.machine(), lines)


#: The ``/proc/cpuinfo`` lines that name a processor and what code it runs.
_CPU_KEYS = ("vendor_id", "cpu family", "model", "model name", "flags", "Features", "CPU implementer", "CPU part")


def _private(path: Path) -> bool:
    """Whether ``path`` and its folder belong to this user and no one else may write them: an executable is loaded
    with ``pickle`` (how :mod:`jax.experimental.serialize_executable` stores one), which runs what the file says,
    so only a file no other user could have written is read."""
    uid = os.getuid()
    for p in (path, path.parent):
        st = p.stat()
        if st.st_uid != uid or st.st_mode & 0o022:
            return False
    return True


def _load_executable(path: Path):
    """The executable stored at ``path`` (:func:`_compile_and_store`), loaded and ready to call; ``None`` where there
    is none, it is not :func:`_private`, or it does not load (damaged, or from another jaxlib)."""
    from jax.experimental import serialize_executable

    try:
        if not _private(path):
            return None
        payload, in_tree, out_tree = pickle.loads(path.read_bytes())
        return serialize_executable.deserialize_and_load(payload, in_tree, out_tree)
    except Exception:  # none yet, or a damaged or foreign file: compiled again, and written
        return None


def _compile_and_store(call: Callable, dynamic: list, folder: Path, path: Path):
    """``call`` (a jitted program) compiled for ``dynamic``, its executable written to ``path`` for later processes
    (unless JAX's compile cache answered the compile); the compiled executable, called as ``call`` is. Where it
    cannot be compiled ahead, ``call`` as it is (compiled on its first call)."""
    from jax.experimental import serialize_executable

    _listen()
    _HITS.n = 0
    try:
        compiled = call.lower(*dynamic).compile()
    except Exception:
        return call
    if _HITS.n:  # loaded from JAX's compile cache: serialised again, such an executable lacks its functions
        return compiled
    try:
        _write(folder, path, pickle.dumps(serialize_executable.serialize(compiled)))
    except Exception:  # (a full disk, a read-only directory): this process runs it all the same
        pass
    return compiled


def _named(fn: Callable, name: str) -> Callable:
    """``fn`` under the name ``name`` (which names the program that ``jax.jit`` of it lowers)."""

    def call(*args):
        return fn(*args)

    call.__name__ = call.__qualname__ = name
    return call


#: JAX's persistent compile cache hits in this thread (:func:`_compile_and_store`'s guard).
_HITS = threading.local()


def _count_hit(event: str, **kwargs: Any) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _HITS.n = getattr(_HITS, "n", 0) + 1


@functools.cache
def _listen() -> None:
    """Count JAX's compile-cache hits per thread from now on (its listeners are called in the compiling thread)."""
    jax.monitoring.register_event_listener(_count_hit)


def _write(folder: Path, path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically; the first write of a source version removes the oldest others."""
    fresh = not folder.exists()
    _write_atomic(folder, path, data)
    if fresh:
        others = sorted((p for p in folder.parent.iterdir() if p.is_dir() and p != folder), key=_mtime, reverse=True)
        for old in others[KEEP_VERSIONS - 1 :]:
            shutil.rmtree(old, ignore_errors=True)


def _write_atomic(folder: Path, path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` in ``folder`` (made where missing) through a temporary file and a rename."""
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)  # this user's alone (:func:`_private`), whatever the umask
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def _mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:
        return 0.0
