"""Split jobs (stage + scanner) to tables, their independent check, the per-point kinematic CSV and the picture.

The table has every machine axis: ``x``, ``y`` the stage S1, the scanner axes (``u``, ``v``) its commands,
other axes at home; events: ``BLOCK`` where the tool enters a program row, ``LASER`` where the beam switches.
The check (:func:`check_split`) reads only the table, the machine file and the program: every axis' limits
(:func:`~jaxcnc.ticks.verify.measure_table`, both axis groups), the scanner inside its field at every tick,
and the tool point (main + calibrated scanner) within one discrete of its program row at every tick.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxcnc.format import EVENT_DTYPE, EventKind, TableFile
from jaxcnc.machine import MachineConfig
from jaxcnc.planners.split import SplitPlan, calibration, first_difference, half_field, second_difference
from jaxcnc.program import Program, program_start
from jaxcnc.ticks.sample import ArraySampler
from jaxcnc.ticks.table import table_meta, write_samples

#: Numeric slack on the tool-point distance (mm) beside the one-discrete tolerance.
SLACK_MM = 1e-9


def axis_positions(plan: SplitPlan, machine: MachineConfig) -> np.ndarray:
    """``(n, n_axes)`` machine-axis positions of a split plan (axes in the machine file's order)."""
    home = program_start(machine)
    u, v = machine.scanner.axes[:2]
    cols = {"x": plan.main[:, 0], "y": plan.main[:, 1], u: plan.cmd[:, 0], v: plan.cmd[:, 1]}
    out = np.empty((plan.n_ticks, len(machine.axes)))
    for i, ax in enumerate(machine.axes):
        out[:, i] = cols[ax.name] if ax.name in cols else (home[2] if ax.name == "z" else ax.home)
    return out


def split_events(plan: SplitPlan, program: Program) -> np.ndarray:
    """BLOCK events where the tool enters a row, LASER events where the beam switches (``EVENT_DTYPE``)."""
    new_row = np.flatnonzero(np.concatenate([[True], plan.row[1:] != plan.row[:-1]]) & (plan.row >= 0))
    lit = plan.lit.astype(np.int8)
    switch = np.flatnonzero(np.diff(np.concatenate([[0], lit])) != 0)
    ev = np.zeros(new_row.size + switch.size, EVENT_DTYPE)
    nb = new_row.size
    ev["tick"][:nb], ev["kind"][:nb] = new_row, EventKind.BLOCK
    ev["aux"][:nb], ev["value"][:nb] = program.line[plan.row[new_row]], plan.row[new_row]
    ev["tick"][nb:], ev["kind"][nb:] = switch, EventKind.LASER
    on = plan.lit[switch]
    ev["aux"][nb:] = np.where(on, 3, 0)
    ev["value"][nb:] = np.where(on, program.power[plan.row[switch]], 0.0)
    return ev[np.lexsort((ev["kind"], ev["tick"]))]


def write_split_table(
    plan: SplitPlan, program: Program, machine: MachineConfig, path: str | Path, source_options: dict | None = None
) -> Path:
    """Write the split plan's table (all axes, BLOCK and LASER events, ``split`` in the header; ``source_options``
    as :func:`jaxcnc.ticks.table.write_table` records them)."""
    more = {"source_options": dict(source_options)} if source_options else {}
    meta = table_meta(
        machine,
        program.file,
        f"split-{plan.method}",
        plan.total_time_s,
        n_blocks=program.n_blocks,
        split=plan.method,
        feed_mm_s=plan.feed_mm_s,
        **more,
    )
    return write_samples(path, machine, ArraySampler(axis_positions(plan, machine)), split_events(plan, program), meta)


@dataclass
class SplitCheck:
    """What :func:`check_split` found: the largest tool-point distance and scanner reach, and violations."""

    max_tool_deviation_mm: float
    max_field_use: float
    violations: list[str] = field(default_factory=list)


def check_split(table: TableFile, machine: MachineConfig, program: Program) -> SplitCheck:
    """The scanner inside its field and the tool point within one discrete of the program at every tick."""
    from jaxcnc.ticks.deviation import segment_distance, tool_point_violations, tool_rows_distance

    axes = list(table.axes)
    u, v = machine.scanner.axes[:2]
    pos = np.asarray(table.exact_mm(0, table.n_rows))
    main = pos[:, [axes.index("x"), axes.index("y")]]
    cmd = pos[:, [axes.index(u), axes.index(v)]]
    m_cal, offset = calibration(machine)
    tool = main + offset + cmd @ m_cal.T
    half = half_field(machine)
    use = np.max(np.abs(cmd) / np.where(half > 0, half, 1e-300), axis=1)
    out = SplitCheck(float(use.max()), float(use.max()))
    bad = np.flatnonzero(use > 1.0 + 1e-9)
    for k in bad[:20]:
        out.violations.append(f"tick {k}: scanner at ({cmd[k, 0]:.4g}, {cmd[k, 1]:.4g}) mm, outside its field")
    p3 = np.c_[tool, np.full(tool.shape[0], program.start[0, 2] if len(program) else 0.0)]
    found = tool_rows_distance(table, program, p3)
    if found is None:
        out.violations.append("the table's block events do not match the program")
        return out
    row, d, first_tick = found
    # before the first row: the straight way from where the tool stands at home (calibration) to the start
    lead = np.arange(table.n_rows) < first_tick
    if lead.any():
        home = program_start(machine)
        u_home = np.array([machine.axis(n).home for n in (u, v)])
        t_home = np.r_[home[:2] + offset + m_cal @ u_home, p3[0, 2]]
        k = np.flatnonzero(lead)
        d[k] = segment_distance(
            p3[k], np.broadcast_to(t_home, (k.size, 3)), np.broadcast_to(program.start[0], (k.size, 3))
        )
    out.max_tool_deviation_mm = float(d.max())
    tol = table.header.discrete_mm + SLACK_MM
    out.violations += tool_point_violations(tool, d, row, program, tol)
    return out


def kinematic_csv(plan: SplitPlan, path: str | Path) -> Path:
    """Per-tick kinematics as CSV: time, stage (X Y), scanner (P Q: the tool point, as the documents' table;
    U V: the scanner's own axes), speeds and accelerations of stage, scanner and tool."""
    dt = 1.0 / plan.tick_hz
    t = np.arange(plan.n_ticks) * dt
    vb, vs, vt = (np.linalg.norm(first_difference(x, dt), axis=1) for x in (plan.main, plan.scan, plan.tool))
    ab, asm = (np.linalg.norm(second_difference(x, dt), axis=1) for x in (plan.main, plan.scan))
    cols = np.c_[t, plan.main, plan.tool, plan.cmd, vb, vs, vt, ab, asm, plan.lit.astype(float)]
    head = "time_s,x_mm,y_mm,p_mm,q_mm,u_mm,v_mm,vbig_mm_s,vsmall_mm_s,vtool_mm_s,abig_mm_s2,asmall_mm_s2,laser"
    np.savetxt(path, cols, delimiter=",", header=head, comments="", fmt="%.9g")
    return Path(path)


def plot_split(plan: SplitPlan, machine: MachineConfig, path: str | Path, every_s: float = 0.25) -> Path:
    """S (tool, black), S1 (stage, blue) and S2 (scanner, red, drawn from the stage point) with the field
    drawn around S1 every ``every_s`` seconds (a PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon as Patch

    m_cal, offset = calibration(machine)
    half = half_field(machine)
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(14, 6), gridspec_kw={"width_ratios": [2, 1]})
    ax.plot(plan.tool[:, 0], plan.tool[:, 1], "k-", lw=0.8, label="S (tool)")
    ax.plot(plan.main[:, 0], plan.main[:, 1], "b-", lw=0.8, label="S1 (stage)")
    step = max(1, int(every_s * plan.tick_hz))
    for k in range(0, plan.n_ticks, step):
        field_k = plan.main[k] + offset + corners @ m_cal.T
        ax.add_patch(Patch(field_k, closed=True, fill=False, ec="0.7", lw=0.5))
    ax.set_aspect("equal")
    ax.legend(loc="upper right")
    ax.set_title(f"{plan.method}: {plan.total_time_s:.3f} s at {plan.feed_mm_s * 60:.0f} mm/min; field in grey")
    bx.plot(plan.scan[:, 0], plan.scan[:, 1], "r-", lw=0.6, label="S2 (scanner)")
    bx.add_patch(Patch(offset + corners @ m_cal.T, closed=True, fill=False, ec="0.5"))
    bx.set_aspect("equal")
    bx.legend(loc="upper right")
    bx.set_title("S2 = S - S1 in the field")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
