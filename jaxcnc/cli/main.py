"""The ``jaxcnc`` command: plan, check, play, plot, demo, bench.

A contract for scripts and pipelines: exit status 0 on success, 1 when a check finds
violations, 2 for bad input (program, machine file, damaged table) — with one clear line
naming the file, the place and the cause, never a traceback.

``play`` needs NumPy alone: a controller installs ``jaxcnc`` without the planning stack. The
commands that plan import it when they run; without it they say in one line which extra to
install (exit 2).
"""

from __future__ import annotations

import argparse
import importlib.util
import io
import json
import os
import sys
from contextlib import nullcontext
from importlib import resources
from pathlib import Path

import numpy as np

import jaxcnc
from jaxcnc.errors import JaxcncError

#: The extra that installs the planning stack (``pip install 'jaxcnc[plan]'``); the core install is the player.
PLAN_EXTRA = "plan"
#: Top-level modules that only the planning extra installs: a command that finds one missing says so.
PLAN_MODULES = frozenset({"jax", "jaxlib", "scipy", "matplotlib", "tqdm"})
_JOB_API = ("GCODE_SUFFIXES", "check_table", "plan_file")


def __getattr__(name: str):
    """The Job API's names, part of this module's API, imported on first use (not by ``play``)."""
    if name in _JOB_API:
        import jaxcnc.jobs

        return getattr(jaxcnc.jobs, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def missing_plan_extra(command: str, module: str) -> str:
    """The one line said when ``command`` needs ``module`` of the planning extra and it is not installed."""
    return (
        f"'jaxcnc {command}' needs the planning extra, which is not installed (no module {module!r}): "
        f"pip install 'jaxcnc[{PLAN_EXTRA}]'"
    )


class _NoBar:
    """Stands in for tqdm's bar where tqdm is absent (a player-only install): nothing is drawn."""

    def update(self, n: int = 1) -> None:
        pass

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        pass

    def write(self, s: str) -> None:
        print(s)

    def close(self) -> None:
        pass


def _progress_bar(**kwargs):
    """tqdm's bar when tqdm is installed (it comes with the planning extra), else none."""
    try:
        from tqdm.auto import tqdm
    except ModuleNotFoundError:
        return _NoBar()
    return tqdm(**kwargs)


def _bound_ratios(report: dict) -> str:
    """``" = r x the lower bound b s, r' x the certified travel-aware bound b' s"``: each where its bound is above
    0 (a job of one point has no interval, so neither)."""
    parts = []
    bounds = (("lower_bound_s", "the lower bound"), ("lower_bound_travel_s", "the certified travel-aware bound"))
    for key, what in bounds:
        bound = report.get(key) or 0.0
        if bound > 0:
            parts.append(f"{report['burn_time_s'] / bound:.4f} x {what} {bound:.3f} s")
    return " = " + ", ".join(parts) if parts else ""


def _fmt_axes(d: dict[str, float], unit: str) -> str:
    return ", ".join(f"{a}={v:.4g}" for a, v in d.items()) + f" {unit}"


def _jerk_text(max_abs_j: dict[str, float], machine: str) -> str:
    """``"; max |j| x=..., y=... mm/s³"`` for the axes of ``machine`` that have ``j_max`` (``""`` where none has)."""
    from jaxcnc.machine import load_machine

    m = load_machine(machine)
    limited = {a: v for a, v in max_abs_j.items() if a in m.axis_names and m.axis(a).j_max is not None}
    return f"; max |j| {_fmt_axes(limited, 'mm/s³')}" if limited else ""


def _drawing_options(args: argparse.Namespace) -> dict:
    """The drawing options given on the command line (the front end refuses them for inputs that are not
    drawings, naming each)."""
    return {
        "allow_open": True if args.allow_open else None,
        "tol_mm": args.join_tol,
        "feed_mm_s": args.feed,
        "power": args.power,
        "lead_in_mm": args.lead_in,
        "layers": tuple(x.strip() for x in args.layers.split(",")) if args.layers is not None else None,
        # raster images (issue 16; docs/laser.md)
        "pixel_mm": args.pixel,
        "dpi": args.dpi,
        "width_mm": args.width,
        "power_min": args.power_min,
        "dither": args.dither,
        "threshold": args.threshold,
        "unidirectional": True if args.unidirectional else None,
        "angle_deg": args.scan_angle,
        "overscan_mm": args.overscan,
        "bidir_offset_mm": args.bidir_offset,
    }


def _shaping(args: argparse.Namespace) -> dict | None:
    """``plan --shaper`` / ``--avoid-bands`` (issue 20) as :func:`jaxcnc.jobs.plan_file`'s ``shaping``."""
    if not (args.shaper or args.avoid_bands):
        given = {
            "--shaper-hz": args.shaper_hz,
            "--shaper-zeta": args.shaper_zeta,
            "--shaper-tol": args.shaper_tol,
            "--shaper-per-axis": args.shaper_per_axis,
        }
        for flag, value in given.items():
            if value:
                raise JaxcncError(f"{flag} goes with --shaper")
        return None
    from jaxcnc.planners.shaping import parse_bands

    return {
        "shaper": args.shaper,
        "f_hz": args.shaper_hz,
        "zeta": args.shaper_zeta,
        "per_axis": args.shaper_per_axis,
        "tol_mm": args.shaper_tol,
        "bands": parse_bands(args.avoid_bands) if args.avoid_bands else None,
    }


def _print_dynamic(args: argparse.Namespace, report: dict) -> int:
    """The summary of a shaped / band-avoiding plan."""
    if not args.quiet:
        print(
            f"planned {report['input']}: {report['n_blocks']} blocks, {report['path_length_mm']:.1f} mm, "
            f"{report['total_time_s']:.3f} s (unshaped {report['unshaped_time_s']:.3f} s) = {report['n_ticks']} ticks, "
            f"planner {report['planner']} -> {report['table']} ({report['plan_wall_s']:.2f} s)"
        )
        if "shaping" in report:
            sh = report["shaping"]
            print(
                f"  shaper {sh['duration_s'] * 1e3:.2f} ms, held {sh['hold_ticks']} ticks at {sh['rest_points']} rest "
                f"points (+{sh['extra_s']:.3f} s); {sh['stops_added']} corners made stops, {sh['arc_feed_caps']} arcs "
                f"slowed, for a contour tolerance of {sh['contour_tol_mm']:.3g} mm"
            )
        if "speed_bands" in report:
            b = report["speed_bands"]
            bands = ", ".join(f"{lo:.1f}-{hi:.1f}" for lo, hi in b["bands_mm_s"])
            print(f"  speed bands avoided: {bands} mm/s ({b['rows_slowed']} rows slowed)")
        print(
            f"  measured on the table: max |v| {_fmt_axes(report['max_abs_v'], 'mm/s')}; max |a| "
            f"{_fmt_axes(report['max_abs_a'], 'mm/s²')}; at most {report['max_path_deviation_mm'] * 1e3:.3g} µm from "
            f"the programmed path (tolerance {report['path_tolerance_mm'] * 1e3:.3g} µm)"
        )
        if "dynamics" in report:
            d = report["dynamics"]
            print(
                f"  simulated axes: residual vibration after {d['n_stops']} stops max "
                f"{d['max_residual_mm'] * 1e3:.3g} µm (mean {d['mean_residual_mm'] * 1e3:.3g} µm), "
                f"contour error max {d['max_contour_mm'] * 1e3:.3g} µm"
            )
    for line in report["violations"][:50]:
        print(f"violation: {line}", file=sys.stderr)
    return 1 if report["violations"] else 0


def cmd_plan(args: argparse.Namespace) -> int:
    from jaxcnc.jobs import JobBounds, plan_file

    report = plan_file(
        Path(args.input),
        Path(args.machine),
        Path(args.output),
        args.planner,
        progress=False if args.quiet else None,
        dialect=args.dialect,
        reorder=args.reorder,
        split=args.split,
        kinematics=args.kinematics,
        split_plot=args.split_plot,
        bounds=JobBounds(max_ticks=args.max_ticks, max_bytes=args.max_bytes, max_duration_s=args.max_duration),
        allow_repeats=args.allow_repeats,
        input_options=_drawing_options(args),
        shaping=_shaping(args),
    )
    if args.report:
        Path(args.report).write_text(json.dumps(report, indent=2) + "\n")
    if "unshaped_time_s" in report:
        return _print_dynamic(args, report)
    if not args.quiet and "n_points" in report:
        print(
            f"planned {report['input']}: {report['n_points']} points, {report['n_pulses']} pulses "
            f"({report['n_idle_pulses']} idle), planner {report['planner']} "
            f"-> {report['table']} ({report['plan_wall_s']:.2f} s)"
        )
        print(
            f"  burn time {report['burn_time_s']:.3f} s{_bound_ratios(report)}; stop-and-go "
            f"{report['stop_and_go_s']:.3f} s (-{100 * report['reduction_vs_stop_and_go']:.1f} %)"
        )
        if "as_given_burn_time_s" in report:
            print(f"  as given (not re-ordered): {report['as_given_burn_time_s']:.3f} s")
        print(
            f"  measured on the table: max |v| {_fmt_axes(report['max_abs_v'], 'mm/s')}; "
            f"max |a| {_fmt_axes(report['max_abs_a'], 'mm/s²')}; beam within "
            f"{report['max_miss_mm'] * 1e3:.2g} µm of every point at its pulse"
        )
    elif not args.quiet:
        print(
            f"planned {report['input']}: {report['n_blocks']} blocks, {report['path_length_mm']:.1f} mm, "
            f"{report['total_time_s']:.3f} s = {report['n_ticks']} ticks at {report['tick_hz']:g} Hz "
            f"-> {report['table']} ({report['plan_wall_s']:.2f} s)"
        )
        print(
            f"  measured on the table: max |v| {_fmt_axes(report['max_abs_v'], 'mm/s')}; "
            f"max |a| {_fmt_axes(report['max_abs_a'], 'mm/s²')}{_jerk_text(report['max_abs_j'], args.machine)}; at "
            f"most {report['max_path_deviation_mm'] * 1e3:.3g} µm from the programmed path "
            f"(tolerance {report['path_tolerance_mm'] * 1e3:.3g} µm)"
        )
        if report.get("corners_kept_exact"):
            print(
                f"  {report['corners_kept_exact']} corners kept exact under the jerk limits: blended, they would be "
                "passed slower than a stop (docs/planning.md, 'Blending')"
            )
    if not args.quiet and "dynamics" in report:
        d = report["dynamics"]
        print(
            f"  simulated axes: residual vibration after {d['n_stops']} stops max {d['max_residual_mm'] * 1e3:.3g} "
            f"µm, contour error max {d['max_contour_mm'] * 1e3:.3g} µm (--shaper, docs/vibration.md)"
        )
    if not args.quiet and "split" in report:
        print(
            f"  stage + scanner ({report['split']}): {report['feed_mm_s'] * 60:.0f} mm/min along "
            f"{report['path_length_mm']:.1f} mm, scanner at most {100 * report['field_use']:.1f} % of its field"
        )
        if report.get("seed_figures"):
            f = report["seed_figures"]
            print(
                f"  documents' method: chord {f['step_mm']:.3g} mm, alpha_kr {f['alpha_kr_deg']:.2f} deg, their time "
                f"{f['paper_time_s']:.3f} s, max Abig {f['paper_max_abig_mm_s2']:.4g} / Asmall "
                f"{f['paper_max_asmall_mm_s2']:.4g} mm/s²; stage needs {f['intent_max_stage_accel_mm_s2']:.4g} mm/s²"
            )
    if report["violations"]:
        for line in report["violations"][:50]:
            print(f"violation: {line}", file=sys.stderr)
        if report.get("split") == "seed":
            print(
                "jaxcnc: error: the documents' split (--split seed, a reference) breaks these limits: its chord "
                "smoothing does not bound the stage's acceleration; the table is written for comparison",
                file=sys.stderr,
            )
            return 1
        print(
            "jaxcnc: error: the planned table breaks the machine limits, the path tolerance or the pulse windows "
            "(a planner bug; please report it)",
            file=sys.stderr,
        )
        return 1
    return 0


def _path_line(meas) -> str:
    """The check's summary of the path comparison."""
    if meas.path_summary:  # compared by the machine's own check (stage + scanner, stage + galvo)
        return f"  path: {meas.path_summary}"
    if meas.path is None:
        return f"  path: not compared: {meas.path_note}"
    pd = meas.path
    away = "no tick" if pd.n_away == 0 else f"{pd.max_away_mm:.3g} mm"
    return (
        f"  path: max deviation {pd.max_mm:.4g} mm from the programmed path at tick {pd.worst_tick} "
        f"(line {pd.worst_line}, allowed {pd.allowed_at_worst_mm:.4g} mm); away from corners {away}"
    )


def _dynamics_lines(args: argparse.Namespace, table) -> list[str]:
    """``check --dynamics``: the table played through the machine's axis modes (jaxcnc.dynamics), as lines."""
    if not (args.dynamics or args.dynamics_plot):
        return []
    from jaxcnc.dynamics import simulate_table
    from jaxcnc.machine import load_machine

    sim = simulate_table(table, load_machine(args.machine), keep=bool(args.dynamics_plot))
    lines = [
        f"  simulated axes ({sim.modes_text()}): residual vibration after {sim.stop_ticks.size} stops max "
        f"{sim.max_residual_mm * 1e3:.4g} µm, mean {sim.mean_residual_mm * 1e3:.4g} µm; contour error max "
        f"{sim.max_contour_mm * 1e3:.4g} µm (rms {sim.rms_contour_mm * 1e3:.3g}); tracking error max "
        f"{sim.max_tracking_mm * 1e3:.4g} µm"
    ]
    if args.dynamics_plot:
        from jaxcnc.dynamics.picture import plot_simulation

        lines.append(f"  wrote {plot_simulation(sim, args.dynamics_plot, str(args.table))}")
    return lines


def cmd_check(args: argparse.Namespace) -> int:
    from jaxcnc.jobs import check_table

    table, meas = check_table(
        Path(args.table),
        Path(args.machine),
        Path(args.points) if args.points else None,
        Path(args.program) if args.program else None,
        args.dialect,
    )
    h = table.header
    dynamics = _dynamics_lines(args, table)
    if meas.ok:
        checked = "travel, limits and path hold" if meas.path is not None else "travel and limits hold"
        print(
            f"OK {args.table}: {h.n_rows} ticks ({(h.n_rows - 1) / h.tick_hz:.3f} s at {h.tick_hz:g} Hz), "
            f"checksums, {checked}"
        )
        print(
            f"  max |v| {_fmt_axes(meas.max_abs_v, 'mm/s')}; max |a| {_fmt_axes(meas.max_abs_a, 'mm/s²')}"
            f"{_jerk_text(meas.max_abs_j, args.machine)}"
        )
        if meas.pulses is not None:
            pc = meas.pulses
            print(
                f"  pulses: {pc.n_work} work + {pc.n_idle} idle, intervals {pc.min_interval_ticks}-"
                f"{pc.max_interval_ticks} ticks, all in the window; every point burned once, beam within "
                f"{pc.max_miss_mm * 1e3:.2g} µm of it"
            )
        if meas.path is not None or meas.pulses is None:
            print(_path_line(meas))
        if meas.laser is not None:
            lc = meas.laser
            print(
                f"  laser: {lc.n_lit} ticks lit ({lc.n_m4} under M4), the power channel within "
                f"{lc.max_power_error:.2g} of S of its mode, feed and speed at every tick"
            )
            if lc.constant_speed:
                print(f"  raster: lit only at the feed (within {lc.max_speed_deviation:.2g} of it)", end="")
                if lc.pixels is not None:
                    px = lc.pixels
                    print(f"; {px.n_pixels} pixels each within {px.max_error_ticks:.3g} tick of its energy", end="")
                print(f"; {lc.raster_note}" if lc.raster_note else "")
        if dynamics:
            print(*dynamics, sep="\n")
        return 0
    shown = meas.violations if args.max_lines <= 0 else meas.violations[: args.max_lines]
    for v in shown:
        print(v)
    if len(shown) < len(meas.violations):
        print(f"... and {len(meas.violations) - len(shown)} more violations")
    if meas.path is not None or meas.pulses is None:
        print(_path_line(meas), file=sys.stderr)  # standard output: the violations only
    if dynamics:
        print(*dynamics, sep="\n", file=sys.stderr)
    print(f"FAILED {args.table}: {len(meas.violations)} violations", file=sys.stderr)
    return 1


def cmd_play(args: argparse.Namespace) -> int:
    from jaxcnc.cli.control import KEYS_HELP, operator_controls
    from jaxcnc.format import TableFile
    from jaxcnc.hw.player import Player, sigint_stops
    from jaxcnc.hw.sinks import open_sink

    table = TableFile(args.table)  # refuses a damaged file before anything moves
    a_max = None
    if args.machine:
        from jaxcnc.machine import load_machine

        machine = load_machine(args.machine)
        table.require_axes(machine.axis_names, f"machine {machine.name!r}")  # sinks send columns by position
        a_max = np.array([machine.axis(a).a_max for a in table.axes])
    options: dict = {}
    if args.sink == "sim":
        options = {"record": args.record, "realtime": args.realtime, "a_max": a_max}
    elif args.sink in ("halstreamer", "hal"):
        options = {"record": args.record}
    elif args.sink.startswith(("tcp://", "udp://")):
        from jaxcnc.hw.stream import load_key

        try:  # from a file or $JAXCNC_STREAM_KEY, never from the command line
            options = {"key": load_key(args.key_file)}
        except ValueError as exc:
            raise JaxcncError(str(exc)) from None
    if args.key_file and not args.sink.startswith(("tcp://", "udp://")):
        raise JaxcncError("--key-file is for the stream sinks (tcp://, udp://)")
    sink = open_sink(args.sink, **options)
    bar = _progress_bar(total=table.n_rows, unit="tick", unit_scale=True, desc="playing", disable=args.quiet or None)
    last = [0]

    def progress(done: int) -> None:
        bar.update(done - last[0])
        last[0] = done
        if a_max is not None:
            bar.set_postfix_str("HOLD" if player.held else f"feed {player.override:.0%}", refresh=False)

    player = Player(table, sink, a_max=a_max)
    try:
        with sigint_stops(player), operator_controls(player) if a_max is not None else nullcontext() as keys:
            if keys:
                bar.write(KEYS_HELP)
            result = player.run(progress)
    except ConnectionError as exc:
        bar.close()
        raise JaxcncError(f"{args.sink}: {exc}") from None
    bar.close()
    if not args.quiet:
        print(
            f"played {args.table} into {args.sink}: {result.executed_tick + 1} ticks executed "
            f"({result.table_time_s:.3f} s of motion in {result.wall_s:.2f} s, "
            f"{result.real_time_factor:.1f}x real time)"
        )
        if args.record:
            print(f"  recorded drive positions -> {args.record}")
        if getattr(sink, "underruns", 0):
            print(
                f"  warning: the sink's buffer ran low {sink.underruns} times (the player fell behind); "
                "the drives ramped down on the path and waited"
            )
        if player.holds:
            print(f"  feed holds: {player.holds}")
    if result.stopped:
        print(
            f"jaxcnc: stopped: controlled stop, the drives came to rest on the path at tick {result.executed_tick}",
            file=sys.stderr,
        )
        return 130
    return 0 if result.executed_tick + 1 == result.rows_sent else 1


def cmd_plot(args: argparse.Namespace) -> int:
    from jaxcnc.format import TableFile
    from jaxcnc.machine import load_machine
    from jaxcnc.plot import plot_power, plot_table

    machine = load_machine(args.machine) if args.machine else None
    if args.power:
        out = plot_power(TableFile(args.table), args.output)
    else:
        out = plot_table(TableFile(args.table), args.output, machine)
    print(f"wrote {out}")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from jaxcnc.jobs import check_table, plan_file
    from jaxcnc.machine import load_machine
    from jaxcnc.plot import plot_table

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    data = resources.files("jaxcnc.data")
    program = out / "demo-bracket.ngc"
    machine = out / "demo-machine.toml"
    program.write_text(data.joinpath("demo-bracket.ngc").read_text())
    machine.write_text(data.joinpath("demo-machine.toml").read_text())
    table = out / "demo-bracket.ticks"
    print(f"jaxcnc {jaxcnc.__version__} demo: planning a laser-cut bracket ({program}) on {machine}")
    report = plan_file(program, machine, table, progress=False)
    (out / "demo-report.json").write_text(json.dumps(report, indent=2) + "\n")
    tbl, meas = check_table(table, machine)
    fig = plot_table(tbl, out / "demo-bracket.png", machine=load_machine(machine))
    print(
        f"  {report['n_blocks']} blocks, {report['path_length_mm']:.1f} mm of path, "
        f"machining time {report['total_time_s']:.3f} s"
    )
    print(
        f"  table: {table} ({report['n_ticks']} ticks at {report['tick_hz']:g} Hz), "
        f"planned in {report['plan_wall_s']:.2f} s"
    )
    print(
        f"  check: {'OK, every tick within the machine limits' if meas.ok else 'FAILED'}; "
        f"max |v| {_fmt_axes(meas.max_abs_v, 'mm/s')}; max |a| {_fmt_axes(meas.max_abs_a, 'mm/s²')}"
    )
    print(f"  plot: {fig}")
    print(f"  next: jaxcnc plan YOUR.ngc --machine {machine} -o job.ticks --report job.json")
    return 0 if meas.ok else 1


def cmd_expand(args: argparse.Namespace) -> int:
    from jaxcnc.errors import SourceError
    from jaxcnc.gcode.preprocess import expand_text

    path = Path(args.program)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SourceError(str(path), 0, 0, f"cannot read program: {exc}") from None
    from jaxcnc.gcode.dialect import load_dialect

    flat = expand_text(text, str(path), max_lines=args.max_lines, dialect=load_dialect(args.dialect))
    if args.output:
        Path(args.output).write_text(flat)
    else:
        sys.stdout.write(flat)
    return 0


def cmd_build(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from jaxcnc.pbf.build import build
    from jaxcnc.pbf.params import load_params

    params = load_params(args.machine)
    if args.repair:
        params = replace(params, repair=True)
    ticks = _layer_range(args.ticks) if args.ticks else []
    if (args.lists or ticks) and not args.galvo:
        raise JaxcncError("--lists and --ticks need --galvo MACHINE (a scanner-only machine file with [galvo])")
    target = None
    if args.galvo:
        from jaxcnc.pbf.scanlist import list_target

        target = list_target(args.galvo, params)  # the machine file checked before the build: [galvo] needed
    if not args.lists:
        target = None
    bar = None if args.quiet else _progress_bar(desc="layers", unit="layer", total=0, leave=False)

    def progress(done: int, total: int) -> None:
        if bar is not None and hasattr(bar, "total"):
            bar.total = total
            bar.n = done
            bar.refresh()

    try:
        res = build(args.input, params, args.output, workers=args.workers, scheduler=args.scheduler,
                    chunk=args.chunk, cli=args.cli, pictures=args.pictures, progress=progress,
                    lists=target)  # fmt: skip
    finally:
        if bar is not None:
            bar.close()
    if not args.quiet:
        rep = res.mesh_report
        h, m = divmod(round(res.time_estimate_s / 60), 60)
        print(f"{args.input}: {rep.faces} faces, {rep.shells} shell(s); {rep.summary()}")
        for what in rep.repaired:
            print(f"  repaired: {what}")
        print(f"{res.layers} layers of {params.layer_thickness_mm} mm in {res.out_dir}: {res.computed} computed, "
              f"{res.skipped} already done (checksums hold); hatch {res.hatch_mm / 1000:.1f} m")  # fmt: skip
        print(f"estimated build time: {h} h {m:02d} min ({res.time_estimate_s:.0f} s, recoating included)")
        if res.cli_file:
            print(f"CLI ({args.cli}): {res.cli_file}")
        if res.pictures:
            print(f"pictures: {len(res.pictures)} in {res.pictures[0].parent}")
        if target is not None:
            print(f"board lists: {res.layers} in {res.out_dir / 'layers'} (L000000.jxv, ...) for {args.galvo}")
    if ticks:
        from jaxcnc.pbf.scanlist import layer_ticks

        for k in ticks:
            rep = layer_ticks(res.out_dir, k, args.galvo)
            if not args.quiet:
                print(f"layer {k}: {rep['table']}: {rep['n_ticks']} ticks ({rep['total_time_s']:.3f} s), verified")
    return 0


def _layer_range(text: str) -> list[int]:
    """``K`` or ``A-B`` (inclusive) as a list of layer indices; anything else is a usage error."""
    a, sep, b = text.partition("-")
    try:
        lo = int(a)
        hi = int(b) if sep else lo
    except ValueError:
        raise JaxcncError(f"--ticks {text!r}: expected a layer K or a range A-B") from None
    if lo < 0 or hi < lo:
        raise JaxcncError(f"--ticks {text!r}: expected 0 <= A <= B")
    return list(range(lo, hi + 1))


def cmd_bench(args: argparse.Namespace) -> int:
    # each suite imports what it measures: 'bench player' runs in a player-only install
    results: dict = {}
    if args.suite in ("all", "plan"):
        from jaxcnc.bench.plan import run_benchmarks

        sizes = tuple(args.sizes) if args.sizes else None
        results["plan"] = run_benchmarks(
            n_blocks=args.blocks, repeats=args.repeats, baseline=args.baseline, **({"sizes": sizes} if sizes else {})
        )
    if args.suite in ("all", "corners"):
        from jaxcnc.bench.corners import run_corner_benchmarks

        results["corners"] = run_corner_benchmarks(peers=args.peers, repeats=args.repeats)
    if args.suite in ("all", "geometry"):
        from jaxcnc.bench.geometry import run_geometry_benchmarks

        run_geometry_benchmarks(n_eval=args.points, repeats=args.repeats)
    if args.suite in ("all", "player"):
        from jaxcnc.bench.player import run_player_benchmarks

        run_player_benchmarks(seconds=args.seconds)
    if args.suite in ("all", "planners"):
        from jaxcnc.bench.planners import run_planner_benchmarks

        run_planner_benchmarks()
    if args.suite in ("all", "pulsed"):
        from jaxcnc.bench.pulsed import run_pulsed_benchmarks

        results["pulsed"] = run_pulsed_benchmarks(programs=args.programs, check=args.check)
    if args.suite == "pulsed-windows":  # minutes (an optimum per window): not part of 'all'
        from jaxcnc.bench.pulsed_windows import run_pulsed_windows

        results["pulsed-windows"] = run_pulsed_windows()
    if args.suite in ("all", "pbf"):
        from jaxcnc.bench.pbf import run_pbf_benchmarks

        results["pbf"] = run_pbf_benchmarks(stl=args.stl)
    if args.suite in ("all", "split"):
        from jaxcnc.bench.split import run_split_benchmarks

        results["split"] = run_split_benchmarks(repeats=args.repeats)
    if args.suite in ("all", "vibration"):
        from jaxcnc.bench.vibration import run_vibration_benchmarks

        results["vibration"] = run_vibration_benchmarks(repeats=args.repeats)
    if args.suite in ("all", "scanner"):
        from jaxcnc.bench.scanner import run_scanner_benchmarks

        results["scanner"] = run_scanner_benchmarks(repeats=args.repeats)
    if args.suite in ("all", "raster"):
        from jaxcnc.bench.raster import run_raster_benchmark

        results["raster"] = run_raster_benchmark(repeats=min(args.repeats, 2))  # 1M G-code lines a run
    if args.suite in ("all", "command"):
        from jaxcnc.bench.command import run_command_benchmarks

        results["command"] = run_command_benchmarks(peers=args.peers, repeats=args.repeats)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1, default=float) + "\n")
    return 0


_SIZE_UNITS = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}
_TIME_UNITS = {"": 1.0, "s": 1.0, "min": 60.0, "h": 3600.0, "d": 86400.0}


def _positive_number(text: str, units: dict, what: str) -> float:
    """``text`` as a positive finite number with an optional unit suffix from ``units``."""
    t = text.strip()
    body = t.rstrip("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ")
    unit = t[len(body) :]
    unit = {"KiB": "K", "MiB": "M", "GiB": "G", "TiB": "T"}.get(unit, unit)
    try:
        v = float(body) * units[unit]
    except (KeyError, ValueError):
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None
    if not (np.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}")
    return v


def _count(text: str) -> int:
    return int(_positive_number(text.replace("_", "").replace(",", ""), {"": 1}, "a positive count"))


def _size(text: str) -> int:
    return int(_positive_number(text, _SIZE_UNITS, "a size (bytes, or with K, M, G, T: binary units)"))


def _duration(text: str) -> float:
    return _positive_number(text, _TIME_UNITS, "a duration (seconds, or with s, min, h, d)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="jaxcnc",
        description="Plan laser-machine motion ahead of time: a job in (G-code, a DXF/HP-GL drawing, a raster image, "
        "points for pulsed engraving; an STL part for powder bed), a verified tick table out.",
        epilog="Start with 'jaxcnc demo'. Exit status: 0 ok, 1 limits violated / check failed, 2 bad input. "
        "'play' needs NumPy alone; plan, plot, demo and bench need the planning extra: pip install 'jaxcnc[plan]'.",
    )
    p.add_argument("--version", action="version", version=f"jaxcnc {jaxcnc.__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    sp = sub.add_parser(
        "plan",
        help="plan a job (G-code, drawing, image, points) into a tick table",
        description="Parse INPUT, plan its motion on the machine and write the tick table. "
        "INPUT by extension: .ngc .nc .gcode .tap .g .cnc (G-code), .dxf (drawing), .plt .hpgl (HP-GL), .png .bmp "
        ".tif .tiff (raster image), .xyz .csv (points for pulsed engraving: one 'x y z [energy]' per line), or a "
        'plug-in\'s suffix. On a machine with [laser] mode = "pulsed" every point (or every G1 end '
        "point) is burned by one pulse, the motion passing through it at the pulse.",
    )
    sp.add_argument("input", help="the job: a G-code program or a point file")
    sp.add_argument("--machine", "-m", required=True, help="machine description (TOML)")
    sp.add_argument("--output", "-o", required=True, help="table file to write (e.g. job.ticks)")
    sp.add_argument("--report", "-r", help="write a JSON report (times, lengths, measured max v/a/j per axis)")
    sp.add_argument(
        "--planner",
        help="velocity planner by name (default: [machine] planner, else topp): for contours topp (time-optimal, "
        "per-axis limits coupled exactly), lookahead (junction look-ahead), toppra, casadi; for pulsed point jobs "
        "bang (default; sync where the machine sets j_max or has a galvo head), sync, best, seed (the source "
        "documents' per-block method), stop-and-go; or a plug-in's name "
        "(entry-point groups jaxcnc.planners, jaxcnc.pulse_planners)",
    )
    sp.add_argument(
        "--reorder",
        action="store_true",
        help="point jobs: burn the points in serpentine raster order (the report gives the as-given time too)",
    )
    sp.add_argument(
        "--allow-repeats",
        action="store_true",
        help="point jobs: burn a point given twice (within a quarter discrete, anywhere in the job) once per time "
        "it is given; without it such a job is refused, naming both lines",
    )
    sp.add_argument(
        "--max-ticks",
        type=_count,
        default=1_000_000_000,
        help="refuse a job whose table would have more rows, before anything is written (default: 1,000,000,000)",
    )
    sp.add_argument(
        "--max-bytes",
        type=_size,
        default=32 * 2**30,
        help="refuse a job whose table file would be larger, e.g. 500M, 64G (default: 32 GiB)",
    )
    sp.add_argument(
        "--max-duration",
        type=_duration,
        default=24 * 3600.0,
        help="refuse a job that would last longer, e.g. 90s, 30min, 48h, 2d (default: 24 h)",
    )
    sp.add_argument(
        "--dialect",
        help="G-code dialect: linuxcnc (default), siemens, fanuc, or a dialect TOML file",
    )
    sp.add_argument(
        "--split",
        choices=("own", "seed", "none"),
        help="machines with a [scanner]: split the contour between stage and scanner: own (default: low-pass "
        "stage path, residual on the scanner), seed (the source documents' chord smoothing), none (stage alone)",
    )
    g = sp.add_argument_group(
        "drawings (.dxf, .plt/.hpgl)", "how a drawing becomes a cutting job; the table records them for `check`"
    )
    g.add_argument(
        "--allow-open",
        action="store_true",
        help="engrave open and crossing contours as drawn (without it they are refused, naming the entity)",
    )
    g.add_argument("--feed", type=float, metavar="MM_S", help="contour speed in mm/s (default: [path] feed)")
    g.add_argument("--power", type=float, help="laser power scale while cutting, 1 = full (default: 1)")
    g.add_argument("--lead-in", type=float, metavar="MM", help="a straight lead-in of this length from the scrap side")
    g.add_argument(
        "--join-tol",
        type=float,
        metavar="MM",
        help="entity ends closer than this are chained; pieces within it are duplicates (default: 0.01)",
    )
    g.add_argument("--layers", metavar="A,B", help="DXF: cut only these layers (default: every visible one)")
    g = sp.add_argument_group(
        "raster images (.png, .bmp, .tif)",
        "engraved line by line at constant speed (--feed, --power: S at black); the table records them for `check`",
    )
    g.add_argument("--pixel", type=float, metavar="MM", help="pixel size and line pitch (default: the file's DPI)")
    g.add_argument("--dpi", type=float, help="resolution in dots per inch (instead of --pixel)")
    g.add_argument("--width", type=float, metavar="MM", help="engraved width (resampled when a resolution is given)")
    g.add_argument("--power-min", type=float, metavar="FRACTION", help="power at the lightest grey (default: 0)")
    g.add_argument("--dither", choices=("none", "threshold", "floyd-steinberg"), help="default: none (greyscale)")
    g.add_argument("--threshold", type=int, metavar="GREY", help="threshold dithering: black below this (default 128)")
    g.add_argument("--unidirectional", action="store_true", help="every line the same way (default: serpentine)")
    g.add_argument("--scan-angle", type=float, metavar="DEG", help="the scan lines' angle to X (default: 0)")
    g.add_argument("--overscan", type=float, metavar="MM", help="unlit run before/after lines (default: as needed)")
    g.add_argument("--bidir-offset", type=float, metavar="MM", help="reverse lines fire this far early (default: 0)")
    sp.add_argument("--kinematics", help="split jobs: write the per-tick kinematic table here (CSV)")
    sp.add_argument("--split-plot", help="split jobs: draw S, S1, S2 and the field here (PNG)")
    sp.add_argument(
        "--shaper",
        choices=("zv", "mzv", "zvd", "ei", "2hump_ei", "3hump_ei"),
        help="input shaping against vibration (docs/vibration.md): the ticks convolved with this shaper for the "
        "machine's lowest axis mode (mode_hz, mode_zeta) or --shaper-hz; stops held for the shaper, the shaped "
        "table checked",
    )
    sp.add_argument("--shaper-hz", type=float, help="the shaper's design frequency (default: the machine's mode)")
    sp.add_argument("--shaper-zeta", type=float, help="the shaper's design damping ratio (default: the mode's)")
    sp.add_argument(
        "--shaper-per-axis", action="store_true", help="shape each axis for its own first mode (not the path)"
    )
    sp.add_argument(
        "--shaper-tol",
        type=float,
        help="contour error (mm) allowed to shaping's corner and arc smoothing (default: [path] corner_tol_mm)",
    )
    sp.add_argument(
        "--avoid-bands",
        help="keep the feed out of resonant speed bands: 'auto' (the axis modes times the part's repeat lengths) "
        "or LOW-HIGH[,LOW-HIGH] in mm/s",
    )
    sp.add_argument("--quiet", "-q", action="store_true", help="no progress bar or summary")
    sp.set_defaults(func=cmd_plan, needs=("jax",))

    sp = sub.add_parser(
        "check",
        help="verify a table against a machine's limits",
        description="Independently verify a table: checksums, travel, per-axis speed and "
        "acceleration at every tick and, when the program it was planned from is here, every tick's distance "
        "from the programmed path against the blend tolerance (G64 P). Exit 0 only if everything holds; "
        "otherwise one line per violation (tick, axis or line, value, limit).",
    )
    sp.add_argument("table", help="table file")
    sp.add_argument("--machine", "-m", required=True, help="machine description (TOML)")
    sp.add_argument("--max-lines", type=int, default=100, help="print at most this many violations (0: all)")
    sp.add_argument(
        "--points", help="pulsed tables: the point file to check the work pulses against (default: the table's source)"
    )
    sp.add_argument(
        "--program",
        help="the G-code program to measure the path against (default: the table's source when it is here and "
        "unchanged; otherwise the path is not compared, which is said)",
    )
    sp.add_argument(
        "--dialect", help="G-code dialect of the program: linuxcnc (default), siemens, fanuc or a dialect TOML file"
    )
    sp.add_argument(
        "--dynamics",
        action="store_true",
        help="also play the table through the machine's axis modes (mode_hz, mode_zeta): residual vibration after "
        "each stop, contour and tracking error (docs/vibration.md)",
    )
    sp.add_argument("--dynamics-plot", help="with --dynamics: draw commanded vs simulated here (PNG)")
    sp.set_defaults(func=cmd_check)

    sp = sub.add_parser(
        "play",
        help="stream a table to a sink",
        description="Play a table into a sink, keeping its buffer fed. The table's checksums are "
        "verified before anything moves.",
    )
    sp.add_argument("table", help="table file")
    sp.add_argument(
        "--sink",
        default="sim",
        help="where to play: sim (in-process virtual drives), scanner (command-list board emulation), "
        "halstreamer (LinuxCNC's HAL streamer in a servo thread at the tick rate; needs linuxcnc-uspace), "
        "tcp://HOST:PORT or udp://HOST:PORT (the stream protocol; see python -m jaxcnc.hw.receiver)",
    )
    sp.add_argument(
        "--record", help="sim, halstreamer: save the executed drive positions (halstreamer: as sampled) to this .npy"
    )
    sp.add_argument("--realtime", action="store_true", help="sim: run the virtual clock in wall-clock time")
    sp.add_argument(
        "--key-file",
        help="tcp://, udp://: a file holding the shared key that signs every frame (the receiver's; at least "
        "16 bytes); else $JAXCNC_STREAM_KEY if set. Never give a key on the command line",
    )
    sp.add_argument(
        "--machine",
        "-m",
        help="machine file: with it, Ctrl-C makes a controlled stop (ramp down along the path within the "
        "acceleration limits, exit status 130) instead of letting the buffer run out, and the operator "
        "controls work: on a terminal, space = feed hold/resume, +/- = feed override, q = stop; from a pipe, "
        "lines 'hold', 'resume', 'override 0.5', 'stop'",
    )
    sp.add_argument("--quiet", "-q", action="store_true")
    sp.set_defaults(func=cmd_play)

    sp = sub.add_parser(
        "plot",
        help="plot a table: path by speed, v/a/j per axis",
        description="Write a PNG with the XY path coloured by speed and speed, acceleration and "
        "jerk of every axis against time, measured on the table.",
    )
    sp.add_argument("table", help="table file")
    sp.add_argument("--output", "-o", required=True, help="PNG file to write")
    sp.add_argument("--machine", "-m", help="draw this machine's limits")
    sp.add_argument(
        "--power", action="store_true", help="the laser instead: path coloured by power, power and speed over time"
    )
    sp.set_defaults(func=cmd_plot, needs=("matplotlib",))

    sp = sub.add_parser(
        "demo",
        help="plan, check and plot a bundled laser-cutting example",
        description="Plan the bundled bracket program on the bundled machine, check the table, "
        "write a plot and print a summary. The first thing to run.",
    )
    sp.add_argument("--out", default="jaxcnc-demo", help="folder for the demo's files (default: %(default)s)")
    sp.set_defaults(func=cmd_demo, needs=("jax", "matplotlib"))

    sp = sub.add_parser(
        "expand",
        help="print a parametric program flattened to plain ISO-7bit",
        description="Run the preprocessor on PROGRAM: parameters, [expressions] and O-word subroutines, "
        "conditions and loops are executed and the plain ISO-7bit blocks they produce are printed. The "
        "result plans exactly like the original.",
    )
    sp.add_argument("program", help="G-code program")
    sp.add_argument("--output", "-o", help="write here instead of standard output")
    sp.add_argument("--max-lines", type=int, default=10_000_000, help="stop after this many executed lines")
    sp.add_argument("--dialect", default="linuxcnc", help="linuxcnc, siemens, fanuc, or a dialect TOML file")
    sp.set_defaults(func=cmd_expand)

    sp = sub.add_parser(
        "bench",
        help="benchmarks: planning and tick throughput, cycle times against peers",
        description="plan: a CAM contour of 1k-1M blocks with exact and blended corners (each size in a fresh "
        "process: first call, steady wall/CPU min/median, blocks/s, peak memory; --baseline REV measures a git "
        "revision beside), the look-ahead against sequential Python and NumPy, ticks/s. corners: the peers' "
        "programs (shared/peers) and the programs of benchmarks/programs beside Klipper's and LinuxCNC's "
        "planned times, every table checked at the tick rate against limits and the programmed path. geometry: "
        "NURBS evaluation against scipy and geomdl, tick generation on curves. player: table playback into sim "
        "and the TCP receiver. planners: topp beside CasADi and toppra on the butterfly. pulsed: the documents' "
        "14 engraving programs. vibration: no shaping, each input shaper and speed-band avoidance on cornered "
        "parts with a 40 Hz mode (job time, residual vibration, contour error, planning time). scanner: galvo vector "
        "list compilation (vectors/s) and emulation at the 10 us tick (ticks/s) against real time. pbf: slicing and "
        "hatching against PySLM, Dask scaling. split: stage + scanner split against the stage alone and the "
        "documents' method. raster: an image planned natively against the same path as per-pixel G-code. command: "
        "the whole 'jaxcnc plan' (parse, plan, ticks, check) in a fresh process on 1.5k-2.3k-block programs, with an "
        "empty compile cache and a warm one. Every run "
        "prints the date, the commit and the load average; JIT compile time "
        "is reported apart. A missing input is an error (exit 2), never replaced by another.",
    )
    sp.add_argument(
        "--blocks", type=int, default=100_000, help="look-ahead and tick program size (default: %(default)s)"
    )
    sp.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        help="plan: the scaling table's program sizes (default: 1000 10000 100000 1000000)",
    )
    sp.add_argument(
        "--baseline", help="plan: measure the scaling table on this git revision too (a worktree of this checkout)"
    )
    sp.add_argument(
        "--peers", help="corners: the peers' folder (README.md, programs/, machines/; default: shared/peers)"
    )
    sp.add_argument("--json", help="also write the figures as JSON to this file")
    sp.add_argument("--repeats", type=int, default=5, help="steady-state repetitions (default: %(default)s)")
    sp.add_argument("--points", type=int, default=1_000_000, help="NURBS evaluation points (default: %(default)s)")
    sp.add_argument("--seconds", type=float, default=60.0, help="player: table length in s (default: %(default)s)")
    sp.add_argument(
        "--programs", type=int, nargs="+", help="pulsed: run only these of the documents' 14 programs (1-14)"
    )
    sp.add_argument(
        "--check", action="store_true", help="pulsed: also write every table and verify limits, windows and hits"
    )
    sp.add_argument(
        "suite",
        nargs="?",
        default="all",
        choices=(
            "all",
            "plan",
            "corners",
            "geometry",
            "player",
            "planners",
            "pulsed",
            "pulsed-windows",
            "pbf",
            "split",
            "vibration",
            "scanner",
            "raster",
            "command",
        ),
        help="which benchmarks (default: %(default)s)",
    )
    sp.add_argument("--stl", help="pbf: the part (default: the corpus's frameGuide.stl)")
    sp.set_defaults(func=cmd_bench)

    sp = sub.add_parser(
        "build",
        help="powder-bed fusion: slice, contour and hatch a mesh into one vector file per layer",
        description="Build INPUT (STL, OBJ, 3MF, PLY, OFF) with the build parameters of --machine (a TOML file "
        "with a [pbf] table, docs/pbf.md): mesh checked (holes, duplicate, degenerate faces, isolated shells, "
        "normals: refused with exit 2, or repaired with --repair), placed on the plate, sliced, contoured, its "
        "thin walls and skins found, hatched; one vector file per layer and a manifest with checksums in OUTPUT "
        "(a rerun skips layers already done), build.cli, layer pictures and a build-time estimate. Layers are "
        "computed on a local Dask cluster with one worker per core (--workers N, 0: in this process) or on the "
        "cluster of --scheduler.",
    )
    sp.add_argument("input", help="the part: a mesh file")
    sp.add_argument("--machine", "-m", required=True, help="build parameters (TOML with [pbf])")
    sp.add_argument("--output", "-o", required=True, help="output folder")
    sp.add_argument("--workers", type=int, help="local Dask workers (default: one per core; 0: no Dask)")
    sp.add_argument("--scheduler", help="tcp://HOST:PORT of a running Dask scheduler (workers must see OUTPUT)")
    sp.add_argument("--chunk", type=int, help="layers per task (default: about 6 tasks per worker, so loads even out)")
    sp.add_argument(
        "--cli", choices=("binary", "ascii", "none"), default="binary", help="CLI export (default: %(default)s)"
    )
    sp.add_argument("--pictures", type=int, default=4, help="layers to draw (default: %(default)s; -1: all)")
    sp.add_argument("--repair", action="store_true", help="repair mesh defects instead of refusing the mesh")
    sp.add_argument("--galvo", metavar="MACHINE", help="scanner-only machine file ([galvo]) for --lists and --ticks")
    sp.add_argument("--lists", action="store_true", help="a galvo board list per layer (layers/L000042.jxv)")
    sp.add_argument("--ticks", metavar="K|A-B", help="tick tables of these layers, planned on --galvo and verified")
    sp.add_argument("--quiet", "-q", action="store_true", help="no progress bar or summary")
    sp.set_defaults(func=cmd_build, needs=("trimesh", "pyclipper", "dask", "matplotlib"))
    return p


class _ReaderMayLeave(io.TextIOBase):
    """The process's stdout, quiet once its reader has closed the pipe (``jaxcnc check t.ticks | head -1``): the
    command finishes its work and exits with its own status instead of a ``BrokenPipeError`` traceback (the rest
    of its output goes to ``/dev/null``)."""

    def __init__(self, stream) -> None:
        self.stream = stream

    def write(self, text: str) -> int:
        try:
            return self.stream.write(text)
        except BrokenPipeError:
            self._to_null()
            return len(text)

    def flush(self) -> None:
        try:
            self.stream.flush()
        except BrokenPipeError:
            self._to_null()

    def _to_null(self) -> None:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, self.stream.fileno())  # what is still buffered, and the interpreter's flush at exit, land there
        os.close(null)

    def fileno(self) -> int:
        return self.stream.fileno()

    def isatty(self) -> bool:
        return self.stream.isatty()

    @property
    def encoding(self) -> str:
        return self.stream.encoding


def main(argv: list[str] | None = None) -> int:
    if sys.stdout is sys.__stdout__ and sys.stdout is not None:  # (not where a caller captures it)
        sys.stdout = _ReaderMayLeave(sys.stdout)
    try:
        return _main(argv)
    finally:
        if isinstance(sys.stdout, _ReaderMayLeave):
            sys.stdout.flush()
            sys.stdout = sys.stdout.stream


def _main(argv: list[str] | None) -> int:
    args = build_parser().parse_args(argv)
    for module in getattr(args, "needs", ()):  # before anything is written
        if importlib.util.find_spec(module) is None:
            print(f"jaxcnc: error: {missing_plan_extra(args.command, module)}", file=sys.stderr)
            return 2
    try:
        return args.func(args)
    except JaxcncError as exc:
        print(f"jaxcnc: error: {exc}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:  # a command (or an input it was given) that needs the planning stack
        module = (exc.name or "").partition(".")[0]
        if module not in PLAN_MODULES:
            raise
        print(f"jaxcnc: error: {missing_plan_extra(args.command, module)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("jaxcnc: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
