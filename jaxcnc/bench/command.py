"""``jaxcnc bench command``: the whole ``jaxcnc plan`` command a user runs — parse, plan, ticks and the table's
check — each run a fresh process, with an empty compile cache (a first run on a machine) and with the cache the
previous run left (every later run), on the peers' 2000-block circle and the 1.5k-2.3k-block CAM programs of
``benchmarks/programs`` (issue 13: at most 15 s with an empty cache, 3 s with a warm one, for a 2000-block
program on the 2-core development machine).

Each cold run gets a new temporary cache directory; the warm runs share one that a cold run filled first. Wall
time is the child process's from start to exit, CPU time its user + system (``RUSAGE_CHILDREN``).
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from jaxcnc.bench.common import BenchInputMissing, run_header
from jaxcnc.bench.corners import MACHINE_1K, own_programs_dir, peers_dir

#: Programs timed by default: the peers' circle and three CAM programs written for the corners suite.
PROGRAMS = ("circle2000", "cam3d_a", "svg_logo_a", "laser_parts_a")
#: The issue's bounds for a 2000-block program (seconds of the whole command).
COLD_TARGET_S, WARM_TARGET_S = 15.0, 3.0


def _run(program: Path, machine: Path, out: Path, cache: Path) -> tuple[float, float]:
    """One ``jaxcnc plan`` in a fresh interpreter with compile cache ``cache``: (wall s, CPU s)."""
    env = dict(os.environ, JAXCNC_CACHE_DIR=str(cache))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "jaxcnc", "plan", str(program), "--machine", str(machine), "-o", str(out)],
        capture_output=True,
        text=True,
        env=env,
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"jaxcnc plan {program} failed:\n{done.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def _programs(names: tuple[str, ...], peers: Path) -> list[Path]:
    own = own_programs_dir()
    out = []
    for name in names:
        candidates = [peers / "programs" / f"{name}.ngc"] + ([own / f"{name}.ngc"] if own else [])
        found = next((p for p in candidates if p.is_file()), None)
        if found is None:
            raise BenchInputMissing(f"{name}.ngc is neither in {peers / 'programs'} nor in benchmarks/programs")
        out.append(found)
    return out


def run_command_benchmarks(
    peers: str | Path | None = None, repeats: int = 5, programs: tuple[str, ...] = PROGRAMS
) -> dict:
    """Time the command on each program, cold and warm, ``repeats`` times each; print and return the figures."""
    folder = peers_dir(peers)
    paths = _programs(programs, folder)
    machine = folder / "machines" / MACHINE_1K
    info = run_header("command")
    print(
        f"  'jaxcnc plan PROGRAM --machine {MACHINE_1K} -o T' (parse, plan, ticks, the table's check), a fresh process "
        f"each; cold: an empty compile cache, warm: the cache a run left; min/median of {repeats}; "
        f"bounds for 2000 blocks: {COLD_TARGET_S:g} s cold, {WARM_TARGET_S:g} s warm"
    )
    print(f"  {'program':<14} {'lines':>6} {'cold wall min/med':>18} {'CPU':>6} {'warm wall min/med':>18} {'CPU':>6}")
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "t.jct"
        for path in paths:
            blocks = sum(1 for line in path.read_text().splitlines() if line.strip())
            cold = [_run(path, machine, out, Path(tempfile.mkdtemp(dir=tmp))) for _ in range(repeats)]
            warm_cache = Path(tempfile.mkdtemp(dir=tmp))
            _run(path, machine, out, warm_cache)  # fills it
            warm = [_run(path, machine, out, warm_cache) for _ in range(repeats)]
            row = {"lines": blocks}
            for name, runs in (("cold", cold), ("warm", warm)):
                walls, cpus = [w for w, _ in runs], [c for _, c in runs]
                row[name] = {
                    "wall_min_s": min(walls),
                    "wall_median_s": statistics.median(walls),
                    "cpu_min_s": min(cpus),
                    "repeats": repeats,
                }
            rows[path.stem] = row
            figures = (row["cold"], row["warm"])
            cells = [f"{r['wall_min_s']:>8.2f}/{r['wall_median_s']:.2f} s {r['cpu_min_s']:>6.1f}" for r in figures]
            print(f"  {path.stem:<14} {blocks:>6} {cells[0]} {cells[1]}")
    return {"info": info, "programs": rows}
