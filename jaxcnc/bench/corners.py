"""``jaxcnc bench corners``: real programs planned beside Klipper and LinuxCNC on matched limits.

The peers' figures come with their inputs: ``shared/peers/README.md`` (the four programs of
``shared/peers/programs`` planned by Klipper's host planner in batch mode and by LinuxCNC 2.9 on the
machine files of ``shared/peers/machines``) and, for programs written for this benchmark that nobody
tuned the planner on, ``benchmarks/programs/peers.json`` beside them. Peers' times are motion only;
so is jaxcnc's figure here (planned time minus the programmed dwells). For every program the suite
prints jaxcnc's time at 1 kHz and 10 kHz (blends do not depend on the tick rate), the ratio to the
best peer, planning wall and CPU time (first call apart: JIT compile), and the table it writes
checked by the independent verifier: limits at every tick, and every tick's distance from the
programmed path against the blend tolerance.
"""

from __future__ import annotations

import json
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxcnc.bench.common import BenchInputMissing, first_call, measure, run_header
from jaxcnc.bench.programs import shared_dir
from jaxcnc.machine import MachineConfig, load_machine
from jaxcnc.program import Kind

#: The machine files (in shared/peers/machines) the peers were matched on, and the tick-rate twin.
MACHINE_1K, MACHINE_10K = "m1000_t0.01.toml", "m10000_t0.01.toml"


@dataclass
class PeerProgram:
    """A program with the peers' recorded figures (seconds of motion; ``nan`` where not measured)."""

    name: str
    path: Path
    klipper_s: float
    linuxcnc_s: float  # LinuxCNC G64 P0.01 Q0.01
    linuxcnc_q0_s: float = float("nan")  # G64 P0.01 Q0 (no naive-CAM merging)
    klipper_cpu_s: str = ""  # as recorded (a range for the README's programs)

    @property
    def best_peer_s(self) -> float:
        return float(np.nanmin([self.klipper_s, self.linuxcnc_s, self.linuxcnc_q0_s]))


def peers_dir(given: str | Path | None = None) -> Path:
    """``shared/peers`` (or ``given``); :class:`BenchInputMissing` when it is not there."""
    folder = Path(given) if given else (shared_dir() / "peers" if shared_dir() else None)
    if folder is None or not (folder / "README.md").is_file():
        raise BenchInputMissing(
            f"the peers' figures are not here ({folder or 'no shared/ folder beside the checkout'}): "
            "pass --peers DIR (the folder holding README.md, programs/ and machines/)"
        )
    return folder


def read_peers_readme(folder: Path) -> list[PeerProgram]:
    """The programs and figures of the table in ``shared/peers/README.md``."""
    text = (folder / "README.md").read_text()
    lines = [ln for ln in text.splitlines() if ln.startswith("|")]
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    col = {name: i for i, name in enumerate(header)}
    needed = ("Klipper", "LinuxCNC P0.01 Q0.01", "LinuxCNC P0.01 Q0")
    missing = [c for c in needed if c not in col]
    if missing:
        raise BenchInputMissing(f"{folder / 'README.md'}: the figures table lacks the columns {missing}")
    cpu = re.search(r"took ([0-9.]+[–-][0-9.]+) CPU-seconds", text)
    out = []
    for ln in lines[2:]:
        cells = [c.strip() for c in ln.strip("|").split("|")]
        m = re.match(r"`([^`]+)`", cells[0])
        if not m:
            continue
        name = m.group(1)
        path = folder / "programs" / f"{name}.ngc"
        if not path.is_file():
            raise BenchInputMissing(f"{path}: the program of the peers' figures is missing")
        out.append(
            PeerProgram(
                name,
                path,
                float(cells[col["Klipper"]]),
                float(cells[col["LinuxCNC P0.01 Q0.01"]]),
                float(cells[col["LinuxCNC P0.01 Q0"]]),
                cpu.group(1) if cpu else "",
            )
        )
    return out


def read_own_programs(folder: Path, skip: set[str] = frozenset()) -> list[PeerProgram]:
    """Programs written for this benchmark and their peers' figures (``peers.json`` in ``folder``).

    ``skip``: names recorded there only as a reproduction of the peers' README (its own programs).
    """
    data = json.loads((folder / "peers.json").read_text())
    out = []
    for name, rec in data.items():
        if name.startswith("_") or name in skip or not isinstance(rec, dict) or "klipper_s" not in rec:
            continue
        path = folder / f"{name}.ngc"
        if not path.is_file():
            raise BenchInputMissing(f"{path}: listed in {folder / 'peers.json'} but missing")
        cpu = rec.get("klipper_cpu_s")
        out.append(
            PeerProgram(
                name,
                path,
                float(rec.get("klipper_s") or np.nan),
                float(rec.get("linuxcnc_p001_q001_s") or np.nan),
                float(rec.get("linuxcnc_p001_q0_s") or np.nan),
                f"{cpu:.2f}" if isinstance(cpu, int | float) else "",
            )
        )
    return out


def own_programs_dir() -> Path | None:
    """``benchmarks/programs`` of this checkout, when present."""
    folder = Path(__file__).resolve().parents[2] / "benchmarks" / "programs"
    return folder if (folder / "peers.json").is_file() else None


def plan_and_check(program_path: Path, machine: MachineConfig, folder: Path, repeats: int) -> dict:
    """Plan a program (timed), write its table, verify limits and the path; the figures as a dict."""
    from jaxcnc.format import TableFile
    from jaxcnc.gcode import load_gcode
    from jaxcnc.planners import plan_job, program_start
    from jaxcnc.ticks.deviation import path_deviation
    from jaxcnc.ticks.table import write_table
    from jaxcnc.ticks.verify import measure_table

    start = program_start(machine)

    def parse():
        return load_gcode(program_path, start=start, home=start)

    program = parse()
    dwell = float(program.dwell_s[program.kind == Kind.DWELL].sum())
    first = first_call(lambda: plan_job(program, machine))
    stat = measure(lambda: plan_job(parse(), machine), repeats)
    job = plan_job(program, machine)
    table = TableFile(write_table(job, folder / f"{program_path.stem}.ticks", progress=False))
    meas = measure_table(table, machine)
    dev = path_deviation(table, machine, program)
    return {
        "blocks": len(program),
        "total_s": job.plan.total_time_s,
        "motion_s": job.plan.total_time_s - dwell,
        "dwell_s": dwell,
        "first_plan_s": first,
        "plan": stat.as_dict(),
        "violations": len(meas.violations),
        "max_dev_mm": dev.max_mm,
        "dev_ok": dev.ok,
        "max_tol_mm": dev.max_tol_mm,
        "max_abs_a": max(meas.max_abs_a.values()),
    }


def run_corner_benchmarks(peers: str | Path | None = None, repeats: int = 5, own: bool = True) -> dict:
    """Run the suite; print the table and return the figures."""
    folder = peers_dir(peers)  # before anything is printed: a missing input is an error, not a run
    info = run_header("corners")
    programs = read_peers_readme(folder)
    own_dir = own_programs_dir() if own else None
    if own_dir is not None:
        programs += read_own_programs(own_dir, skip={p.name for p in programs})
    elif own:
        print("  (benchmarks/programs/peers.json not found: the programs written for this benchmark are skipped)")
    m1 = load_machine(folder / "machines" / MACHINE_1K)
    m10 = load_machine(folder / "machines" / MACHINE_10K)
    print(
        f"  machines {MACHINE_1K} / {MACHINE_10K}: per-axis v 500 mm/s, a 10000 mm/s², chord 5 µm, corner_tol 0.01 mm;"
        f" motion-only seconds; plan = parse + plan, {repeats} repeats"
    )
    head = (
        f"  {'program':<16} {'blocks':>6} {'jaxcnc 1k':>10} {'10k':>8} {'Klipper':>8} {'LinuxCNC':>8} {'ratio':>7} "
        f"{'plan first':>10} {'plan min/med wall':>17} {'CPU min':>7} {'Klipper CPU':>11} {'viol':>4} {'dev/tol':>7}"
    )
    print(head)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for prog in programs:
            r1 = plan_and_check(prog.path, m1, Path(tmp), repeats)
            r10 = plan_and_check(prog.path, m10, Path(tmp), 1)
            ratio = r1["motion_s"] / prog.best_peer_s
            rows[prog.name] = {
                "peers": {"klipper_s": prog.klipper_s, "linuxcnc_s": prog.linuxcnc_s, "best_s": prog.best_peer_s},
                "hz1000": r1,
                "hz10000": r10,
                "ratio_to_best_peer": ratio,
            }
            print(
                f"  {prog.name:<16} {r1['blocks']:>6} {r1['motion_s']:>10.3f} {r10['motion_s']:>8.3f} "
                f"{prog.klipper_s:>8.3f} {prog.linuxcnc_s:>8.3f} {ratio:>7.4f} {r1['first_plan_s']:>9.2f}s "
                f"{r1['plan']['wall_min_s']:>7.3f}/{r1['plan']['wall_median_s']:.3f} s "
                f"{r1['plan']['cpu_min_s']:>6.3f}s "
                f"{prog.klipper_cpu_s:>11} {r1['violations'] + r10['violations']:>4} "
                f"{max(r1['max_dev_mm'], r10['max_dev_mm']) / r1['max_tol_mm']:>7.3f}"
            )
    worst = max(r["ratio_to_best_peer"] for r in rows.values())
    print(f"  worst ratio to the best peer: {worst:.4f} (1 kHz; one tick is 0.001 s)")
    return {"info": info, "programs": rows}
