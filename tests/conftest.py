"""Shared fixtures: machine files written by the tests, the corpus (skipped when absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from jaxcnc.machine import MachineConfig, parse_machine

# The suite traces its programs as jax.jit does (tests that run the command line in-process turn the compile cache
# on): stored programs (jaxcnc.jitcache) are tested on their own, in tests/test_jitcache.py.
os.environ.setdefault("JAXCNC_EXPORT_CACHE", "0")

#: Memory mappings of the test process above which the compiled programs are released after a module (see
#: :func:`_compiled_programs_released`).
MAPS_LIMIT = 20_000


@pytest.fixture(autouse=True, scope="module")
def _compiled_programs_released():
    """After a module whose programs leave the process with more than ``MAPS_LIMIT`` memory mappings, JAX's compiled
    programs are released (:func:`jaxcnc.jitcache.release_when_crowded`). Each XLA:CPU executable maps memory of its
    own; a process that keeps every program the whole suite compiles passes Linux's ``vm.max_map_count`` (65,530)
    and LLVM segfaults compiling or (de)serialising the next one: CI died at 93 % on 2026-11-28 once the jerk tests
    planned meander520 at 10 kHz as well (6,740 mappings for that test alone). The library's own threshold (half the
    kernel's limit, checked as each job starts) would do for jobs alone; the suite also compiles outside jobs."""
    yield
    from jaxcnc.jitcache import release_when_crowded

    release_when_crowded(MAPS_LIMIT)


REPO = Path(__file__).resolve().parents[1]
CORPUS = REPO.parent / "shared" / "corpus"
EXAMPLE_MACHINE = REPO / "examples" / "machines" / "laser-cutter.toml"

MACHINE_TOML = """\
[machine]
name = "test-machine"
tick_hz = {tick_hz}
discrete_mm = 0.001

[axes.x]
v_max = {v:g}
a_max = {a:g}
min = -500.0
max = 500.0

[axes.y]
v_max = {v:g}
a_max = {a_y:g}
min = -500.0
max = 500.0

[axes.z]
v_max = 50.0
a_max = 500.0
min = -100.0
max = 100.0

[path]
feed = 50.0
rapid = {rapid:g}
chord_tol_mm = 0.001
corner_tol_mm = 0.0
"""


def machine_text(
    tick_hz: float = 10000,
    v: float = 100.0,
    a: float = 1000.0,
    a_y: float | None = None,
    rapid: float = 100.0,
    j: float | None = None,
) -> str:
    """The test machine; ``j``: a jerk limit (mm/s³) on every axis."""
    text = MACHINE_TOML.format(tick_hz=tick_hz, v=v, a=a, a_y=a if a_y is None else a_y, rapid=rapid)
    if j is not None:
        text = "\n".join(ln + (f"\nj_max = {j:g}" if ln.startswith("a_max") else "") for ln in text.splitlines()) + "\n"
    return text


def make_machine(**kw) -> MachineConfig:
    return parse_machine(machine_text(**kw), "test-machine.toml")


@pytest.fixture
def machine() -> MachineConfig:
    return make_machine()


@pytest.fixture
def machine_file(tmp_path: Path) -> Path:
    p = tmp_path / "machine.toml"
    p.write_text(machine_text())
    return p


def corpus_file(name: str) -> Path:
    """A corpus G-code file by a distinctive part of its name; skips the test when absent."""
    folder = CORPUS / "gcode"
    hits = sorted(folder.glob(f"*{name}*")) if folder.is_dir() else []
    if not hits:
        pytest.skip(f"corpus file *{name}* not available (../shared/corpus is absent)")
    return hits[0]


#: A galvo scanner's x/y beam axes at 100 kHz, 1 µm discretes (the scanner tests add [path], [galvo], ...).
GALVO_XY = """[machine]
name = "galvo"
tick_hz = 100000
discrete_mm = 0.001
[axes.x]
v_max = 5000.0
a_max = 2000000.0
min = -50.0
max = 50.0
[axes.y]
v_max = 5000.0
a_max = 2000000.0
min = -50.0
max = 50.0
"""
#: The galvo tests' contour speeds: 1 m/s marks, 5 m/s jumps.
GALVO_PATH = """[path]
feed = 1000.0
rapid = 5000.0
"""
