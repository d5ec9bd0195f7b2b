"""The same program planned at two tick rates (issue 13: within 1 %), under the machine's jerk limit or without it.

    python benchmarks/tick_rates.py --planners topp lookahead --j-max 1e6
    python benchmarks/tick_rates.py --planners lookahead --programs meander520 --head 120

Plans each program with each planner on the peers' matched machines (``../shared/peers/machines``,
``m<rate>_t0.01.toml``: 500 mm/s and 10,000 mm/s² per axis, ``corner_tol_mm`` 0.01), with ``j_max`` added to every
axis unless ``--j-max 0``, at each of ``--rates``, as ``jaxcnc plan`` does (``plan_job``; the tables are not
written — ``tests/test_jerk.py`` checks such tables at every tick). Programs are names in ``../shared/peers/programs``
or ``benchmarks/programs`` (``.ngc`` added), or paths; ``--head N`` plans each program's first N lines alone.
Prints the planned time at each rate, their ratio (the last rate over the first) and the planning wall time of the
first plan (JIT compile included where the compile cache is cold); with ``--repeats N`` also the wall time (min/median)
and the CPU time (min) of N more plans in the same process, the steady state.
A program or machine file that is not there, or a program that cannot be planned, is a one-line error (exit 2),
never replaced by another.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

from jaxcnc.bench.common import Stat, measure, run_header
from jaxcnc.errors import JaxcncError
from jaxcnc.gcode import load_gcode, parse_gcode
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job, program_start

ROOT = Path(__file__).resolve().parents[1]
PEERS = ROOT.parent / "shared" / "peers"
DEFAULT_PROGRAMS = ("meander520", "plasmatest", "circle2000", "svg_logo_a", "laser_parts_a")


def find_program(name: str) -> Path:
    """A program by path, or by name in the peers' programs or ``benchmarks/programs``."""
    for path in (Path(name), PEERS / "programs" / f"{name}.ngc", ROOT / "benchmarks" / "programs" / f"{name}.ngc"):
        if path.is_file():
            return path
    raise FileNotFoundError(f"program {name!r}: not a file, nor in {PEERS / 'programs'} or benchmarks/programs")


def machine_text(rate: int, j_max: float, planner: str) -> str:
    """The peers' machine at ``rate`` Hz with ``j_max`` on every axis (none where 0) and ``planner``."""
    path = PEERS / "machines" / f"m{rate}_t0.01.toml"
    if not path.is_file():
        raise FileNotFoundError(f"machine file {path} not found (the peers' matched machines)")
    text = path.read_text()
    if j_max > 0:
        text = re.sub(r"(?m)^(a_max = .*)$", rf"\1\nj_max = {j_max!r}", text)
    return re.sub(r"(?m)^\[machine\]$", f'[machine]\nplanner = "{planner}"', text)


def plan_time(path: Path, text: str, head: int | None, name: str, repeats: int = 0) -> tuple[float, float, Stat | None]:
    """Planned time (s) and planning wall time (s) of the program at ``path`` on the machine ``text``, and with
    ``repeats`` the wall and CPU time of that many more plans of it in this process (compiled: the steady state)."""
    machine = parse_machine(text, name)
    start = program_start(machine)
    if head is None:
        program = load_gcode(path, start=start, home=start)
    else:
        lines = path.read_text().splitlines()[:head]
        program = parse_gcode("\n".join(lines) + "\nM2\n", path.name, start=start, home=start)
    t0 = time.perf_counter()
    job = plan_job(program, machine)
    first = time.perf_counter() - t0
    steady = measure(lambda: plan_job(program, machine), repeats) if repeats else None
    return job.plan.total_time_s, first, steady


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--planners", nargs="+", default=["topp", "lookahead"])
    parser.add_argument("--programs", nargs="+", default=list(DEFAULT_PROGRAMS))
    parser.add_argument("--rates", nargs=2, type=int, default=[1000, 10000])
    parser.add_argument("--j-max", type=float, default=1e6, help="mm/s³ on every axis; 0: none")
    parser.add_argument("--head", type=int, default=None, help="plan each program's first N lines alone")
    parser.add_argument(
        "--repeats", type=int, default=0, help="plan each so many times more: steady wall min/median and CPU (s)"
    )
    args = parser.parse_args(argv)
    if args.head is not None and args.head < 1:
        parser.error("--head takes a count of lines, 1 at least")
    try:
        paths = [find_program(p) for p in args.programs]
        texts = {(r, p): machine_text(r, args.j_max, p) for r in args.rates for p in args.planners}
    except FileNotFoundError as exc:
        print(f"tick_rates: {exc}", file=sys.stderr)
        return 2
    run_header("tick-rates")
    lo, hi = args.rates
    head = f", first {args.head} lines" if args.head else ""
    print(f"  peers' machines, j_max {args.j_max:g} mm/s³{head}; planned s at {lo} / {hi} Hz, ratio, planning wall s")
    for path in paths:
        for planner in args.planners:
            try:
                got = {
                    r: plan_time(path, texts[(r, planner)], args.head, f"m{r}_{planner}", args.repeats)
                    for r in args.rates
                }
            except JaxcncError as exc:  # a program that cannot be planned, a planner that is not there: one line
                print(f"tick_rates: {exc}", file=sys.stderr)
                return 2
            (t_lo, w_lo, s_lo), (t_hi, w_hi, s_hi) = got[lo], got[hi]
            steady = (
                f"; then {s_lo.wall_min:.2f}/{s_lo.wall_median:.2f} / {s_hi.wall_min:.2f}/{s_hi.wall_median:.2f} s"
                f" (CPU {s_lo.cpu_min:.2f} / {s_hi.cpu_min:.2f} s)"
                if s_lo is not None
                else ""
            )
            print(
                f"  {path.stem:14s} {planner:10s} {t_lo:10.4f} / {t_hi:10.4f} s  ratio {t_hi / t_lo:.4f}"
                f"  planned in {w_lo:6.1f} / {w_hi:6.1f} s{steady}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
