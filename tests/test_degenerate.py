"""Degenerate programs, job size bounds, machine ranges and repeated pulsed points (issue 14, Deliver 2 and 5).

Each was reproduced on the code before the fix: a feed that underflows planned "10 mm in 0.000 s"; feed 0,
1e-300 or an arc without a turn direction went through the Python API; ``G1 X10 F0.001`` would have written
~144 GB and a long dwell tens of GB before anything refused; ``tick_hz = 1e9`` and ``field_mm = [nan]`` were
accepted; pulsed points repeated apart from each other, or 2 nm apart, or made neighbours by ``--reorder``,
were burned twice.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from jaxcnc.errors import JaxcncError, MachineFileError, SourceError
from jaxcnc.gcode import parse_gcode
from jaxcnc.io.points import PointJob
from jaxcnc.jobs import DEFAULT_BOUNDS, JobBounds, plan_file
from jaxcnc.machine import parse_machine
from jaxcnc.planners.pulsed import plan_points
from jaxcnc.program import MIN_FEED_MM_S, Kind, program_from_columns
from jaxcnc.ticks.deviation import path_deviation
from tests.conftest import machine_text
from tests.test_pulsed import glass

# ---- feeds, durations and arcs below physical sense ---------------------------------------------------------------


def _line(**cols):
    base = {"kind": [Kind.LINE], "start": [[0.0, 0, 0]], "end": [[10.0, 0, 0]], "line": [7]}
    return program_from_columns(file="api.ngc", **{**base, **cols})


@pytest.mark.parametrize("feed", [0.0, 1e-300, 1e-12, -5.0, np.inf])
def test_api_feed_below_physical_sense_is_refused(feed):
    with pytest.raises(SourceError) as info:
        _line(feed=[feed])
    assert str(info.value).startswith("api.ngc:7:") and "feed" in info.value.reason


def test_api_feed_at_the_floor_and_the_machine_default_pass():
    assert _line(feed=[MIN_FEED_MM_S]).feed[0] == MIN_FEED_MM_S
    assert np.isnan(_line().feed[0])  # not set: the machine's feed applies


@pytest.mark.parametrize(
    ("cols", "needle"),
    [
        ({"kind": [Kind.ARC], "center": [[5.0, 0, 0]], "turn": [0]}, "turn"),
        ({"kind": [Kind.ARC], "center": [[np.nan, 0, 0]], "turn": [1]}, "centre"),
        ({"kind": [Kind.ARC], "center": [[0.0, 0, 0]], "turn": [1]}, "radius"),
        ({"kind": [Kind.ARC], "center": [[5.0, 0, 0]], "turn": [1], "plane": [16]}, "plane"),
        ({"kind": [Kind.DWELL], "end": [[0.0, 0, 0]], "dwell_s": [-1.0]}, "dwell"),
        ({"kind": [Kind.DWELL], "end": [[0.0, 0, 0]], "dwell_s": [np.nan]}, "dwell"),
        ({"kind": [Kind.DWELL], "end": [[0.0, 0, 0]], "dwell_s": [np.inf]}, "dwell"),
        ({"end": [[np.inf, 0, 0]]}, "finite"),
        ({"start": [[np.nan, 0, 0]]}, "finite"),
        ({"kind": [9]}, "kind"),
        ({"power": [np.nan]}, "power"),
        ({"blend_tol": [np.nan]}, "blend"),
    ],
)
def test_api_degenerate_rows_are_refused_naming_the_line(cols, needle):
    with pytest.raises(SourceError) as info:
        _line(**cols)
    assert str(info.value).startswith("api.ngc:7:") and needle in info.value.reason, str(info.value)


def test_gcode_feed_that_underflows_is_refused():
    """The issue's teleport: 10 mm "in 0.000 s = 1 tick". The feed is refused as nonsense, located."""
    with pytest.raises(SourceError) as info:
        parse_gcode("G1 X10 F0." + "0" * 300 + "1\n", "t.ngc")
    assert (info.value.line, info.value.column) == (1, 1) and "feed" in info.value.reason


#: Curved blocks short enough to turn by less than a grid interval's 1 degree, alone between two rests (found by a
#: red-team pass on 2026-11-28): each was one interval with s-double-dot constant, so it stayed at rest and its
#: trapezoid covered it in no time - the table jumped to its end in one tick (10 kHz: |a| = 1e5 mm/s^2; 1 kHz: within
#: the limits, the cut silently lost).
TINY_CURVES = {
    "1 um arc": "G0 X11 Y10\nG1 F9000\nG3 X10.999 Y10 I0 J-0.1\n",
    "helix, 50 nm in XY and 1 mm in Z": "G0 X11 Y10\nG1 F9000\nG3 X10.99995 Y10 Z1 I0 J-1\n",
    "steep 19 deg helix": "G0 X11 Y10\nG1 F9000\nG2 X11.010261 Y9.998191 Z-0.45 I0 J-0.03\n",
    "1 um arc between exact stops": "G61\nG0 X11 Y10\nG1 F9000 X12\nG3 X11.999 Y10 I0 J-0.1\nG1 X12 Y11\n",
}


@pytest.mark.parametrize("tick_hz", [10000, 1000])
@pytest.mark.parametrize("name", TINY_CURVES)
def test_a_tiny_curve_between_rests_takes_the_time_its_acceleration_needs(tmp_path, name, tick_hz):
    from tests.helpers import table_of

    m = parse_machine(machine_text(tick_hz=tick_hz), "test-machine.toml")
    job, _, meas = table_of(TINY_CURVES[name], m, tmp_path)
    assert meas.ok, meas.violations[:3]
    arc = np.flatnonzero(job.program.kind == Kind.ARC)[0]
    on = job.spans.block[job.plan.span] == arc
    length = float(job.plan.length[on].sum())
    # from rest to rest along a path whose tangent is a unit vector, |q''| >= |s''|: t >= 2 sqrt(L / |a|max)
    a_bound = float(np.linalg.norm([a.a_max for a in m.axes]))
    assert length > 0 and job.plan.duration_s[on].sum() >= 2.0 * np.sqrt(length / a_bound)


#: Arcs whose end lies at the start's angle but not on the start (a red-team pass on 2026-12-08: 1 nm off it, as
#: G91 round-off leaves it): the sweep came out 0, the helix rise 0/0, and planning died in a traceback
#: (``np.repeat``: negative counts). They are whole turns, in the spans and in the check's geometry alike.
ARCS_AT_THEIR_START_ANGLE = {
    "G2, end 1 nm inside": ("G1 X0 Y0 F600\nG2 X0.000000001 Y0 I5 J0\nG1 X1\n", 5.0),
    "G3, end 1 nm outside": ("G1 X0 Y0 F600\nG3 X-0.000000001 Y0 I5 J0\nG1 X1\n", 5.0),
    "G18": ("G18\nG1 X0 Z0 F600\nG2 X0.000000001 Z0 I5 K0\nG1 X1\n", 5.0),
}


@pytest.mark.parametrize("corner_tol", [0.0, 0.01])
@pytest.mark.parametrize("name", ARCS_AT_THEIR_START_ANGLE)
def test_an_arc_ending_at_its_start_angle_is_a_whole_turn(tmp_path, name, corner_tol):
    from tests.helpers import table_of

    text, radius = ARCS_AT_THEIR_START_ANGLE[name]
    m = parse_machine(machine_text(tick_hz=1000).replace("corner_tol_mm = 0.0", f"corner_tol_mm = {corner_tol}"), "m")
    job, table, meas = table_of(text, m, tmp_path)
    dev = path_deviation(table, m, job.program)
    assert meas.ok and dev.ok, (meas.violations[:3], dev.max_mm)
    arc = np.flatnonzero(job.program.kind == Kind.ARC)[0]
    on = job.spans.block == arc
    # the whole circle, less what blends at its ends take (at most a few tolerances' worth)
    assert abs(float(job.spans.length[on].sum()) - 2 * np.pi * radius) <= 1e-9 + 40 * corner_tol


#: Lines shorter than ``program.MIN_MOVE_MM`` at a blended corner (the same red-team pass): the planner gives them no
#: span, but the check took them for moving rows and measured the blend of the rows around them against them alone
#: (up to 0.5 mm "from the path": the table refused as a planner bug, exit 1).
SUB_NANOMETRE_MOVES = {
    "G91 round-off": "G91 G1 X0.1 Y0 F600\nX0.1\nX0.1\nG90 G1 X0.3 Y0\nG1 X1 Y0.7\nG1 X3 Y0.8\n",
    "1e-10 mm before a 3 deg turn": "G1 X1 Y0 F600\nG1 X1.0000000001 Y0\nG1 X3 Y0.1\n",
    "1e-10 mm before a 45 deg turn": "G1 X1 Y0 F600\nG1 X1.0000000001 Y0\nG1 X2 Y1\n",
}


@pytest.mark.parametrize("name", SUB_NANOMETRE_MOVES)
def test_a_move_shorter_than_a_nanometre_at_a_blended_corner_stands(tmp_path, name):
    from jaxcnc.geometry import SpanKind
    from jaxcnc.program import MIN_MOVE_MM
    from tests.helpers import table_of

    m = parse_machine(machine_text(tick_hz=1000).replace("corner_tol_mm = 0.0", "corner_tol_mm = 0.01"), "m")
    job, table, meas = table_of(SUB_NANOMETRE_MOVES[name], m, tmp_path)
    dev = path_deviation(table, m, job.program)
    assert meas.ok and dev.ok, (meas.violations[:3], dev.max_mm)
    short = np.flatnonzero(np.linalg.norm(job.program.end - job.program.start, axis=1) <= MIN_MOVE_MM)
    assert short.size and not np.isin(short, job.spans.block).any()  # no span of its own
    assert np.count_nonzero(job.spans.kind == SpanKind.BLEND) >= 1  # the corner around it is blended


def test_a_plan_larger_than_the_memory_available_is_refused_naming_the_line(monkeypatch):
    """``topp`` refuses a grid that would not fit in the memory available, before planning, naming the source line
    whose spans have the most intervals (P turns: rows of one line). A red-team pass (2026-12-08): 100 blocks of
    ``G2 I0.001 P10000`` (360 M intervals) took 23 GB and were killed after 36 s without a word."""
    from jaxcnc.errors import PlanningError
    from jaxcnc.planners import plan_job, topp

    m = parse_machine(machine_text(tick_hz=1000), "m")
    text = "G1 X0 Y0 F600\nG2 I0.5 J0 P3\nG1 X2\nG2 I0.5 J0 P40\nG1 X3\n"
    prog = parse_gcode(text, "turns.ngc")
    plan_job(prog, m)  # fits
    # 40 turns of 360 intervals on line 4: refused once the memory available is below the estimate
    monkeypatch.setattr(topp, "available_memory_bytes", lambda: 10_000 * topp.PLAN_BYTES_PER_INTERVAL)
    with pytest.raises(PlanningError) as info:
        plan_job(prog, m)
    msg = str(info.value)
    assert msg.startswith("turns.ngc:4: planning needs ") and "14,400 of them on this block" in msg, msg
    monkeypatch.setattr(topp, "available_memory_bytes", lambda: None)  # (where the system does not say)
    plan_job(prog, m)


def test_gcode_arc_turns_are_bounded():
    with pytest.raises(SourceError, match="turns"):
        parse_gcode("G2 X0 Y0 I1 F100 P1000000000\n", "t.ngc")
    assert len(parse_gcode("G2 X0 Y0 I1 F100 P3\n", "t.ngc")) == 3


# ---- job size bounds ---------------------------------------------------------------------------------------------


@pytest.fixture
def machine_file(tmp_path):
    m = tmp_path / "m.toml"
    m.write_text(machine_text())
    return m


def _plan(tmp_path, machine_file, text, **kw):
    prog = tmp_path / "p.ngc"
    prog.write_text(text)
    out = tmp_path / "o.ticks"
    return prog, out, lambda: plan_file(prog, machine_file, out, progress=False, **kw)


@pytest.mark.parametrize(
    ("text", "line", "needle"),
    [
        ("G1 X5 F600\nG1 X10 F0.001\n", 2, "max-duration"),  # ~144 GB of table
        ("G1 X5 F600\nG4 P10000000\n", 2, "max-duration"),  # a dwell of 116 days
        ("G1 X5 F600\nG4 P" + "9" * 300 + "\n", 2, "max-duration"),
        ("G1 X10 F0.0001\n", 1, "max-duration"),  # just above the feed floor: refused by the bound
    ],
)
def test_a_job_beyond_the_bounds_is_refused_before_anything_is_written(tmp_path, machine_file, text, line, needle):
    prog, out, run = _plan(tmp_path, machine_file, text)
    with pytest.raises(SourceError) as info:
        run()
    assert str(info.value).startswith(f"{prog}:{line}:") and needle in info.value.reason, str(info.value)
    assert not out.exists() and not list(tmp_path.glob("*.part"))


@pytest.mark.parametrize(
    ("bounds", "needle"),
    [
        (JobBounds(max_duration_s=5.0), "max-duration"),
        (JobBounds(max_ticks=50_000), "max-ticks"),
        (JobBounds(max_bytes=1_000_000), "max-bytes"),
    ],
)
def test_each_bound_refuses_and_raising_it_lets_the_job_through(tmp_path, machine_file, bounds, needle):
    """10 mm at 1 mm/s: 10 s, 100k ticks, ~2.4 MB; each bound below that refuses, the defaults let it through."""
    _prog, out, run = _plan(tmp_path, machine_file, "G1 X10 F60\n", bounds=bounds)
    with pytest.raises(JaxcncError, match=needle):
        run()
    assert not out.exists()
    report = plan_file(tmp_path / "p.ngc", machine_file, out, progress=False, bounds=DEFAULT_BOUNDS)
    assert report["n_ticks"] > 100_000 and out.exists()


def test_the_exact_plan_is_checked_too(tmp_path, machine_file):
    """The lower bound before planning ignores acceleration; the planned time is checked before writing."""
    # 40 short moves with exact stops: the lower bound (length / feed) is far below the planned time
    text = "G61\nG1 F3000\n" + "".join(f"G1 X{(k % 2) * 0.5 + 1:g}\n" for k in range(40))
    prog, out, run = _plan(tmp_path, machine_file, text)
    planned = run()["total_time_s"]
    out.unlink()
    lower = 40 * 0.5 / 50.0
    assert planned > 2 * lower
    with pytest.raises(JaxcncError, match="max-duration") as info:
        plan_file(prog, machine_file, out, progress=False, bounds=JobBounds(max_duration_s=(lower + planned) / 2))
    assert "planned" in str(info.value)
    assert not out.exists()


def test_bounds_must_be_positive():
    for bad in ({"max_ticks": 0}, {"max_bytes": -1}, {"max_duration_s": float("nan")}):
        with pytest.raises(JaxcncError):
            JobBounds(**bad)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "jaxcnc", *args], capture_output=True, text=True)


def test_cli_bounds_options(tmp_path, machine_file):
    prog = tmp_path / "p.ngc"
    prog.write_text("G1 X10 F0.001\n")
    out = tmp_path / "o.ticks"
    r = _cli("plan", str(prog), "-m", str(machine_file), "-o", str(out), "-q")
    assert r.returncode == 2 and len(r.stderr.splitlines()) == 1, r.stderr
    assert r.stderr.startswith(f"jaxcnc: error: {prog}:1:") and "--max-duration" in r.stderr
    assert not out.exists()
    prog.write_text("G1 X10 F60\n")
    for opt, value in (("--max-duration", "5s"), ("--max-ticks", "50000"), ("--max-bytes", "1M")):
        r = _cli("plan", str(prog), "-m", str(machine_file), "-o", str(out), "-q", opt, value)
        assert r.returncode == 2 and len(r.stderr.splitlines()) == 1 and opt in r.stderr, r.stderr
        assert not out.exists()
    r = _cli("plan", str(prog), "-m", str(machine_file), "-o", str(out), "-q", "--max-duration", "1h")
    assert r.returncode == 0, r.stderr
    r = _cli("plan", str(prog), "-m", str(machine_file), "-o", str(out), "--max-bytes", "lots")
    assert r.returncode == 2 and "--max-bytes" in r.stderr and "Traceback" not in r.stderr


def test_help_states_the_defaults():
    r = _cli("plan", "--help")
    text = " ".join(r.stdout.split())
    assert "--max-ticks" in text and "--max-bytes" in text and "--max-duration" in text
    assert f"{DEFAULT_BOUNDS.max_ticks:,}" in text or str(DEFAULT_BOUNDS.max_ticks) in text
    assert "24 h" in text and "32 GiB" in text and "--allow-repeats" in text


# ---- machine ranges ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("old", "new", "key"),
    [
        ("tick_hz = 10000", "tick_hz = 1e9", "machine.tick_hz"),
        ("tick_hz = 10000", "tick_hz = 0.5", "machine.tick_hz"),
        ("discrete_mm = 0.001", "discrete_mm = 1e-12", "machine.discrete_mm"),
        # 500 mm of travel in 0.3 nm discretes is 1.7e9 discretes: within int32 but without its margin of two
        ("discrete_mm = 0.001", "discrete_mm = 0.0000003", "machine.discrete_mm"),
        ("min = -500.0", "min = -1.5e6", "machine.discrete_mm"),
    ],
)
def test_machine_ranges_keep_int32_positions_safe(old, new, key):
    text = machine_text().replace(old, new, 1)
    assert new in text
    with pytest.raises(MachineFileError) as info:
        parse_machine(text, "m.toml")
    assert info.value.key == key and info.value.line > 0, str(info.value)


@pytest.mark.parametrize("field", ["[nan]", "[inf]", "[-1.0]", "[0.0]", "[1e9]"])
def test_scanner_field_must_be_finite_positive_and_in_range(field):
    text = machine_text() + f'[scanner]\naxes = ["x"]\nfield_mm = {field}\n'
    with pytest.raises(MachineFileError) as info:
        parse_machine(text, "m.toml")
    assert info.value.key == "scanner.field_mm"


def test_a_fine_machine_still_loads():
    m = parse_machine(machine_text().replace("discrete_mm = 0.001", "discrete_mm = 0.00001"), "m.toml")
    assert m.discrete_mm == 1e-5
    assert parse_machine(machine_text().replace("tick_hz = 10000", "tick_hz = 1000000")).tick_hz == 1e6


# ---- pulsed jobs: no point burned twice -------------------------------------------------------------------------


def _job(points, lines=None) -> PointJob:
    pts = np.asarray(points, dtype=np.float64)
    return PointJob(pts, None, np.arange(1, len(pts) + 1) if lines is None else np.asarray(lines), "pts.xyz")


@pytest.mark.parametrize(
    ("points", "first", "second"),
    [
        ([[10, 10, 10], [11, 10, 10], [12, 10, 10], [10, 10, 10]], 1, 4),  # not consecutive
        ([[10, 10, 10], [11, 10, 10], [11, 10, 10]], 2, 3),  # consecutive (moved here from the point-file parser)
        ([[10, 10, 10], [11, 10, 10], [11.000002, 10, 10]], 2, 3),  # 2 nm apart
        ([[10, 10, 10], [11, 10, 10], [12, 10, 10], [11, 10.0002, 10]], 2, 4),  # within a quarter discrete
    ],
)
def test_repeated_points_are_refused_with_both_lines(points, first, second):
    with pytest.raises(SourceError) as info:
        plan_points(_job(points), glass(), "stop-and-go")
    e = info.value
    assert e.line == second and f"line {first}" in e.reason and "--allow-repeats" in e.reason, str(e)


def test_points_a_third_discrete_apart_are_distinct():
    job = _job([[10, 10, 10], [11, 10, 10], [12, 10, 10], [11, 10.0003, 10]])
    assert len(plan_points(job, glass(), "stop-and-go").plan.work_tick) == 4


def test_repeats_on_request_are_burned_each_time():
    job = _job([[10, 10, 10], [11, 10, 10], [12, 10, 10], [10, 10, 10]])
    job = PointJob(job.points, None, job.line, job.file, allow_repeats=True)
    assert len(plan_points(job, glass(), "stop-and-go").plan.work_tick) == 4
    assert job.take(np.array([3, 2, 1, 0])).allow_repeats


def _pulsed_files(tmp_path, text):
    m = tmp_path / "glass.toml"
    m.write_text(
        "[machine]\nname = 'glass'\ntick_hz = 10000\n"
        + "".join(f"[axes.{a}]\nv_max = 50.0\na_max = 300.0\nmin = 0.0\nmax = 300.0\n" for a in "xyz")
        + "[path]\nfeed = 30.0\nrapid = 50.0\n[laser]\nmode = 'pulsed'\npulse_hz = 40.0\ntolerance = 0.05\n"
    )
    pts = tmp_path / "pts.xyz"
    pts.write_text(text)
    return m, pts


@pytest.mark.parametrize("reorder", [False, True])
def test_cli_refuses_repeats_before_and_after_reorder_and_allows_them_on_request(tmp_path, reorder):
    # lines 1 and 3 are the same point; --reorder would make them neighbours
    m, pts = _pulsed_files(tmp_path, "10 10 10\n12 10 10\n10 10 10\n11 10 10\n")
    out = tmp_path / "o.ticks"
    more = ["--reorder"] if reorder else []
    r = _cli("plan", str(pts), "-m", str(m), "-o", str(out), "-q", "--planner", "stop-and-go", *more)
    assert r.returncode == 2 and len(r.stderr.splitlines()) == 1, r.stderr
    assert f"{pts}:3:" in r.stderr and "line 1" in r.stderr and "--allow-repeats" in r.stderr
    assert not out.exists()
    report = tmp_path / "r.json"
    r = _cli(
        "plan", str(pts), "-m", str(m), "-o", str(out), "-q", "--planner", "stop-and-go", "--allow-repeats",
        "-r", str(report), *more,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads(report.read_text())["n_points"] == 4
    r = _cli("check", str(out), "-m", str(m))
    assert r.returncode == 0, r.stdout + r.stderr
