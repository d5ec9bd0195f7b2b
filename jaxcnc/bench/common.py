"""What every benchmark shares: repeated timing (wall and CPU, min and median), the run's header, inputs.

Absolute times on a shared machine are noise; every suite prints the machine's load average at its
start, the date, and ratios against peers measured in the same run or recorded beside their inputs.
A benchmark whose input is missing says so and fails (exit status 2) instead of measuring something
else.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from jaxcnc.errors import JaxcncError

#: Repeats of every steady-state figure (the issue asks for at least five).
REPEATS = 5


class BenchInputMissing(JaxcncError):
    """A benchmark's input (the peers' programs, the corpus) is not where it should be."""


@dataclass(frozen=True)
class Stat:
    """Wall and CPU seconds of repeated runs: minimum and median over ``n``."""

    wall_min: float
    wall_median: float
    cpu_min: float
    cpu_median: float
    n: int

    def __str__(self) -> str:
        return (
            f"{self.wall_min:.3f}/{self.wall_median:.3f} s wall, {self.cpu_min:.3f}/{self.cpu_median:.3f} s CPU "
            f"(min/median of {self.n})"
        )

    def as_dict(self) -> dict:
        return dict(
            wall_min_s=self.wall_min,
            wall_median_s=self.wall_median,
            cpu_min_s=self.cpu_min,
            cpu_median_s=self.cpu_median,
            repeats=self.n,
        )


def measure(fn: Callable[[], object], repeats: int = REPEATS) -> Stat:
    """Run ``fn`` ``repeats`` times; CPU time is this process's (all its threads)."""
    walls, cpus = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return Stat(min(walls), statistics.median(walls), min(cpus), statistics.median(cpus), repeats)


def first_call(fn: Callable[[], object]) -> float:
    """Wall seconds of one call (the first: JIT compile included)."""
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def git_commit() -> str:
    """The checkout's commit (with ``+`` when the tree has changes), or ``"unknown"``."""
    root = Path(__file__).resolve().parents[2]
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True)  # fmt: skip
    except OSError:
        return "unknown"
    if rev.returncode != 0:
        return "unknown"
    return rev.stdout.strip() + ("+" if dirty.stdout.strip() else "")


def run_header(title: str) -> dict:
    """Print and return the run's context: date, commit, machine, load average, JAX backend."""
    import jax

    import jaxcnc

    info = {
        "suite": title,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "jaxcnc": jaxcnc.__version__,
        "commit": git_commit(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "backend": str(jax.devices()[0]),
        "cpus": os.cpu_count(),
        "load_average": os.getloadavg(),
    }
    load = ", ".join(f"{x:.2f}" for x in info["load_average"])
    print(
        f"jaxcnc bench {title}: {info['date']}, jaxcnc {info['jaxcnc']} ({info['commit']}), JAX {info['jax']} on "
        f"{info['backend']}, {info['cpus']} CPUs, load average {load} at the start"
    )
    return info


def subprocess_json(code: str, env: dict | None = None, cwd: str | None = None) -> dict:
    """Run Python ``code`` in a fresh interpreter; its last output line is JSON. Raises with its stderr."""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=cwd)
    if out.returncode != 0:
        raise RuntimeError(f"benchmark subprocess failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])
