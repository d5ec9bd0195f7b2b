"""``jaxcnc.jitcache.cached_jit``: the results of ``jax.jit``, programs stored and read back by a later process,
and never a stored program where something that made it has changed."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc import jitcache
from jaxcnc.jitcache import cached_jit

SCALE = 2.0


@cached_jit(static_argnames=("power",))
def _poly(x: jnp.ndarray, c: dict, power: int) -> dict:
    """A program with a static argument, a dict argument and a dict result, reading a module constant."""
    return {"y": SCALE * x**power + c["a"], "n": jnp.sum(x)}


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    """Stored programs in a temporary directory, for this test alone."""
    monkeypatch.setattr(jitcache, "DIRECTORY", tmp_path / "exports")
    monkeypatch.delenv("JAXCNC_EXPORT_CACHE", raising=False)
    _poly.calls.clear()
    yield tmp_path
    _poly.calls.clear()


def _stored(root: Path) -> list[Path]:
    return sorted((root / "exports").rglob("*.exported"))


def test_without_a_cache_directory_it_is_jax_jit(monkeypatch):
    monkeypatch.setattr(jitcache, "DIRECTORY", None)
    monkeypatch.setattr(jitcache, "export_dir", lambda: None)
    _poly.calls.clear()
    x = np.linspace(0.0, 1.0, 7)
    out = _poly(x, {"a": 1.0}, power=3)
    np.testing.assert_array_equal(np.asarray(out["y"]), np.asarray(_poly.jitted(x, {"a": 1.0}, power=3)["y"]))
    assert not _poly.calls  # nothing stored nor looked up


def test_stored_programs_give_the_same_bits_and_are_read_back(cache_dir):
    x = np.linspace(-1.0, 2.0, 11)
    expected = _poly.jitted(x, {"a": 0.5}, power=3)
    got = _poly(x, {"a": 0.5}, power=3)
    for k in expected:
        np.testing.assert_array_equal(np.asarray(got[k]), np.asarray(expected[k]))
    files = _stored(cache_dir)
    assert len(files) == 1 and "_poly" in files[0].name
    _poly(x + 1.0, {"a": 0.25}, power=3)  # the same shapes: no new program
    assert _stored(cache_dir) == files
    _poly(x[:5], {"a": 0.25}, power=3)  # another shape
    _poly(x, {"a": 0.25}, power=2)  # another static argument
    assert len(_stored(cache_dir)) == 3
    _poly.calls.clear()  # as a new process: read from the files
    mtimes = {p: p.stat().st_mtime_ns for p in _stored(cache_dir)}
    again = _poly(x, {"a": 0.5}, power=3)
    np.testing.assert_array_equal(np.asarray(again["y"]), np.asarray(expected["y"]))
    assert {p: p.stat().st_mtime_ns for p in _stored(cache_dir)} == mtimes


def test_a_changed_constant_makes_another_program(cache_dir, monkeypatch):
    x = np.arange(4.0)
    _poly(x, {"a": 0.0}, power=1)
    _poly.calls.clear()
    monkeypatch.setattr(sys.modules[__name__], "SCALE", 3.0)
    out = _poly(x, {"a": 0.0}, power=1)
    np.testing.assert_array_equal(np.asarray(out["y"]), 3.0 * x)  # not the stored 2 x
    assert len(_stored(cache_dir)) == 2


def test_a_damaged_file_is_made_again(cache_dir):
    """A damaged program, read where its executable is not there (the executable is read first, where it is)."""
    x = np.arange(3.0)
    _poly(x, {"a": 1.0}, power=2)
    (path,) = _stored(cache_dir)
    path.write_bytes(b"not a program")
    for binary in (cache_dir / "exports").rglob("*.xla"):
        binary.unlink()
    _poly.calls.clear()
    np.testing.assert_array_equal(np.asarray(_poly(x, {"a": 1.0}, power=2)["y"]), SCALE * x**2 + 1.0)
    assert path.read_bytes() != b"not a program"


def test_switched_off_by_the_environment(cache_dir, monkeypatch):
    monkeypatch.setenv("JAXCNC_EXPORT_CACHE", "0")
    assert jitcache.export_dir() is None
    _poly(np.arange(3.0), {"a": 1.0}, power=2)
    assert _stored(cache_dir) == []


def test_static_closures_are_not_stored(cache_dir):
    offset = 5.0

    @cached_jit(static_argnames=("fn",))
    def apply(x, fn):
        return fn(x)

    out = apply(np.arange(3.0), fn=lambda v: v + offset)
    np.testing.assert_array_equal(np.asarray(out), np.arange(3.0) + 5.0)
    assert _stored(cache_dir) == []


def test_a_later_process_plans_from_the_stored_programs(tmp_path):
    """Two processes plan the same program with one cache directory: the second reads the stored programs (no new
    file) and writes the same table bytes."""
    script = textwrap.dedent(
        """
        import sys
        from jaxcnc.jaxconfig import configure_jax
        configure_jax(sys.argv[1])
        from jaxcnc.bench.plan import bench_machine
        from jaxcnc.bench.programs import cam_polyline
        from jaxcnc.machine import parse_machine
        from jaxcnc.planners import plan_job
        job = plan_job(cam_polyline(300), parse_machine(bench_machine(0.01), "<bench>"))
        import hashlib, numpy as np
        h = hashlib.sha256()
        for k in sorted(job.plan.columns):
            h.update(np.ascontiguousarray(job.plan.column(k)).tobytes())
        print(h.hexdigest())
        """
    )
    env = dict(os.environ, JAXCNC_EXPORT_CACHE="1")
    cache = tmp_path / "cache"
    runs = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", script, str(cache)], capture_output=True, text=True, env=env)
        assert out.returncode == 0, out.stderr[-2000:]
        runs.append((out.stdout.split()[-1], sorted(p.name for p in (cache / "exports").rglob("*.exported"))))
    assert runs[0][1] and runs[0] == runs[1]
    env["JAXCNC_EXPORT_CACHE"] = "0"
    out = subprocess.run(
        [sys.executable, "-c", script, str(tmp_path / "plain")], capture_output=True, text=True, env=env
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[-1] == runs[0][0]  # the same plan as jax.jit's, bit for bit


_COUNTING_SCRIPT = textwrap.dedent(
    """
    import sys
    import jax
    compiles = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda event, duration, **kw: compiles.append(event) if event.endswith("backend_compile_duration") else None
    )
    from jaxcnc.jaxconfig import configure_jax
    configure_jax(sys.argv[1])
    from jaxcnc.bench.plan import bench_machine
    from jaxcnc.bench.programs import cam_polyline
    from jaxcnc.machine import parse_machine
    from jaxcnc.planners import plan_job
    job = plan_job(cam_polyline(300), parse_machine(bench_machine(0.01), "<bench>"))
    import hashlib, numpy as np
    h = hashlib.sha256()
    for k in sorted(job.plan.columns):
        h.update(np.ascontiguousarray(job.plan.column(k)).tobytes())
    print(len(compiles), h.hexdigest())
    """
)


def _counted_plan(cache: Path, env: dict) -> tuple[int, str]:
    """:data:`_COUNTING_SCRIPT` in a fresh process: (XLA compiles, the plan's hash)."""
    out = subprocess.run([sys.executable, "-c", _COUNTING_SCRIPT, str(cache)], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    n, digest = out.stdout.split()[-2:]
    return int(n), digest


def test_later_processes_load_the_stored_executables(tmp_path):
    """Four processes plan one program with one cache directory, each the same plan bit for bit:

    1. executables off: JAX's compile cache is filled, the programs alone are stored;
    2. executables on: compiled afresh under the executables' names (JAX's cache keys the name too, and an executable
       it hands back lacks its functions once serialised again: XLA:CPU's "Function ... not found" in the process
       that runs it) and stored;
    3. loaded: none of the planner's programs is compiled;
    4. the executables removed: JAX's cache answers under their names now, and such executables are run, never
       stored.
    """
    env = dict(os.environ, JAXCNC_EXPORT_CACHE="1", JAXCNC_EXECUTABLE_CACHE="0")
    cache = tmp_path / "cache"
    reference = _counted_plan(cache, env)
    assert not any(cache.rglob("*.xla"))
    env["JAXCNC_EXECUTABLE_CACHE"] = "1"
    stored = _counted_plan(cache, env)
    binaries = sorted(cache.rglob("*.xla"))
    assert stored[1] == reference[1] and stored[0] > 5 and len(binaries) > 5
    loaded = _counted_plan(cache, env)
    assert loaded[1] == reference[1]
    assert loaded[0] <= 2  # (eager operations outside the stored programs: a scalar conversion or two)
    assert sorted(cache.rglob("*.xla")) == binaries
    for binary in binaries:
        binary.unlink()
    assert _counted_plan(cache, env)[1] == reference[1]
    assert not any(cache.rglob("*.xla"))


def test_an_executable_others_may_write_or_a_damaged_one_is_not_loaded(cache_dir):
    """Executables are read with pickle: one that another user could have written (group- or world-writable, or in
    such a folder) is not loaded, nor is a damaged one; the program is compiled again, with the same results."""
    x = np.linspace(0.0, 1.0, 10_000 + int.from_bytes(os.urandom(2), "little"))  # a shape JAX's cache cannot know
    want = np.asarray(_poly.jitted(x, {"a": 3.0}, power=2)["y"])
    np.testing.assert_array_equal(np.asarray(_poly(x, {"a": 3.0}, power=2)["y"]), want)
    (binary,) = (cache_dir / "exports").rglob("*.xla")
    assert jitcache._load_executable(binary) is not None
    binary.chmod(0o666)
    assert jitcache._load_executable(binary) is None
    binary.chmod(0o600)
    binary.parent.chmod(0o777)
    assert jitcache._load_executable(binary) is None
    binary.parent.chmod(0o700)
    binary.write_bytes(b"not an executable")
    assert jitcache._load_executable(binary) is None
    _poly.calls.clear()
    np.testing.assert_array_equal(np.asarray(_poly(x, {"a": 3.0}, power=2)["y"]), want)
    assert jitcache._load_executable(binary) is not None  # compiled again and written over


def test_the_command_line_writes_the_same_table_from_stored_programs(tmp_path):
    """``jaxcnc plan`` twice with one cache (programs stored, then read), and once without stored programs: the
    same table bytes."""
    from jaxcnc.bench.plan import bench_machine
    from jaxcnc.bench.programs import cam_gcode

    program = tmp_path / "cam.ngc"
    program.write_text(cam_gcode(400))
    machine = tmp_path / "machine.toml"
    machine.write_text(bench_machine(0.01))
    tables = []
    for i, export in enumerate(("1", "1", "0")):
        env = dict(os.environ, JAXCNC_EXPORT_CACHE=export, JAXCNC_CACHE_DIR=str(tmp_path / f"cache{export}"))
        out_file = tmp_path / f"t{i}.ticks"
        cmd = [sys.executable, "-m", "jaxcnc.cli.main", "plan", str(program), "-m", str(machine), "-o", str(out_file)]
        out = subprocess.run(cmd, capture_output=True, text=True, env=env)
        assert out.returncode == 0, out.stderr[-2000:]
        tables.append(out_file.read_bytes())
    assert any((tmp_path / "cache1" / "exports").rglob("*.exported"))
    assert not (tmp_path / "cache0" / "exports").exists()
    assert tables[0] == tables[1] == tables[2]


def test_a_stored_program_that_fails_falls_back_to_jax_jit(cache_dir, monkeypatch):
    """A stored program whose call raises (arguments on another platform's device, say) is dropped: the call is
    jax.jit's, with its result (or its error)."""
    x = np.arange(5.0)
    _poly(x, {"a": 1.0}, power=2)
    (key,) = _poly.calls

    def broken(*args):
        raise RuntimeError("not on this device")

    _poly.calls[key] = broken
    np.testing.assert_array_equal(np.asarray(_poly(x, {"a": 1.0}, power=2)["y"]), SCALE * x**2 + 1.0)
    assert _poly.calls[key] is None


def test_programs_of_old_source_versions_are_removed(tmp_path):
    """The first program a new source version writes removes all but the newest ``KEEP_VERSIONS - 1`` others."""
    root = tmp_path / "exports"
    for i, name in enumerate(("v0", "v1", "v2", "v3")):
        folder = root / name
        folder.mkdir(parents=True)
        (folder / "p.exported").write_bytes(b"x")
        os.utime(folder, (1_000_000 + i, 1_000_000 + i))
    jitcache._write(root / "new", root / "new" / "q.exported", b"program")
    kept = sorted(p.name for p in root.iterdir())
    assert kept == ["new", "v2", "v3"]
    assert (root / "new" / "q.exported").read_bytes() == b"program"
    jitcache._write(root / "new", root / "new" / "r.exported", b"again")  # the version's later programs keep all
    assert sorted(p.name for p in root.iterdir()) == ["new", "v2", "v3"]


def test_a_cache_directory_that_cannot_be_written_falls_back_to_jax_jit(tmp_path, monkeypatch):
    """The exports folder under a regular file (mkdir fails, as it does on a read-only cache for a user who may
    not write there): the program runs as ``jax.jit`` runs it, nothing is stored, and nothing is raised."""
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setattr(jitcache, "DIRECTORY", blocker / "exports")
    monkeypatch.delenv("JAXCNC_EXPORT_CACHE", raising=False)
    _poly.calls.clear()
    x = np.linspace(0.0, 3.0, 9)
    got = _poly(x, {"a": 2.0}, power=2)
    want = _poly.jitted(x, {"a": 2.0}, power=2)
    for k in want:
        np.testing.assert_array_equal(np.asarray(got[k]), np.asarray(want[k]))
    assert list(_poly.calls.values()) == [None]  # looked up once, then plain jax.jit from now on
    assert blocker.read_text().startswith("a file")
    _poly.calls.clear()


def test_compiled_programs_are_released_when_the_process_is_crowded():
    """Each compiled program maps memory of its own: released, the mappings go back down, and the programs still
    give the same values (compiled again)."""
    xs = [jnp.arange(n, dtype=jnp.float64) for n in range(1, 61)]
    c = {"a": jnp.float64(1.0)}
    first = [np.asarray(_poly(x, c, power=2)["y"]) for x in xs]
    assert _poly.jitted._cache_size() >= len(xs)
    assert not jitcache.release_when_crowded(jitcache.max_map_count())  # far from the limit: kept
    before = jitcache.memory_maps()
    assert jitcache.release_when_crowded(0)
    after = jitcache.memory_maps()
    assert _poly.jitted._cache_size() == 0
    assert after < before - 5 * len(xs), (before, after)  # ~17 mappings per XLA:CPU executable
    again = [np.asarray(_poly(x, c, power=2)["y"]) for x in xs]
    assert all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))


@pytest.mark.parametrize("share, released", [(0.0, True), (1.0, False)])
def test_every_job_starts_by_releasing_programs_when_crowded(monkeypatch, share, released):
    """``plan_job`` checks the mappings as it starts (a long-lived process planning job after job)."""
    from tests.conftest import make_machine
    from tests.helpers import plan_text

    _poly(jnp.ones(3), {"a": jnp.float64(0.0)}, power=1)
    assert _poly.jitted._cache_size() > 0
    monkeypatch.setattr(jitcache, "CROWDED_SHARE", share)
    plan_text("G1 X1 F600\n", make_machine())
    assert (_poly.jitted._cache_size() == 0) == released


def test_a_warm_up_runs_once_per_call_and_a_compile_ahead_every_time():
    """:func:`~jaxcnc.jitcache.warm_ahead` runs a call in the compile-ahead thread the first time this process makes
    it and never again (its result is nobody's: the blends' kernel warmed on made-up blends ran again in every plan
    until 2026-11-29); :func:`~jaxcnc.jitcache.compile_ahead` returns the result every time (computed here once
    seen)."""
    ran = []

    def fn(x):
        ran.append(x.shape)
        return x + 1.0

    first = jitcache.warm_ahead(fn, np.zeros(7))
    assert first is not None and float(first.result()[0]) == 1.0
    assert jitcache.warm_ahead(fn, np.ones(7)) is None  # the same shapes: nothing run
    assert ran == [(7,)]
    again = jitcache.warm_ahead(fn, np.zeros(8))  # other shapes: a first call again
    assert again is not None and again.result().shape == (8,) and ran == [(7,), (8,)]
    assert float(jitcache.compile_ahead(fn, np.full(7, 2.0)).result()[0]) == 3.0  # seen: run here, result returned
    assert ran == [(7,), (8,), (7,)]


def test_a_probed_fact_is_asked_once_per_cache_directory(cache_dir, monkeypatch):
    """``remembered``: the probe runs where its answer is not stored yet (or the file holds something else) and
    wherever there is no cache directory; otherwise the stored answer is read."""
    asked = []

    def probe() -> bool:
        asked.append(1)
        return True

    assert jitcache.remembered("a-test-fact", probe) and len(asked) == 1
    assert jitcache.remembered("a-test-fact", probe) and len(asked) == 1  # read back
    (fact,) = (cache_dir / "exports").glob("a-test-fact-*.fact")
    fact.write_bytes(b"garbage")
    assert jitcache.remembered("a-test-fact", probe) and len(asked) == 2
    assert fact.read_bytes() == b"1"
    assert not jitcache.remembered("another-fact", lambda: False)
    assert not jitcache.remembered("another-fact", probe)  # the stored False, not the probe's True
    monkeypatch.setattr(jitcache, "DIRECTORY", None)
    monkeypatch.setattr(jitcache, "export_dir", lambda: None)
    assert jitcache.remembered("a-test-fact", probe) and len(asked) == 3
