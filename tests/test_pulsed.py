"""Pulse-synchronised planning: point files, windows, the three planners, pulse events and their check."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline

from jaxcnc.bench.pulsed import glass_engraver
from jaxcnc.cli.main import main
from jaxcnc.errors import JaxcncError, MachineFileError, SourceError
from jaxcnc.format import EventKind, TableFile
from jaxcnc.gcode import parse_gcode
from jaxcnc.io.points import PointJob, parse_points, points_from_program, read_points
from jaxcnc.io.raster import superellipsoid_raster, write_xyz
from jaxcnc.machine import parse_machine
from jaxcnc.planners.pulsed import plan_points, pulse_window
from jaxcnc.planners.pulsed.reorder import serpentine_order
from jaxcnc.planners.pulsed.spline import spline_moments
from jaxcnc.planners.pulsed.windows import PulseWindow
from jaxcnc.ticks.pulses import pulse_events, write_pulse_table
from jaxcnc.ticks.table import table_meta, write_samples
from jaxcnc.ticks.verify import measure_table
from jaxcnc.ticks.verify_pulses import check_pulses

GLASS = glass_engraver()


def glass(**laser) -> object:
    """The documents' machine with ``[laser]`` keys (and ``j_max`` on every axis) changed."""
    j = laser.pop("j_max", None)
    text = (
        "[machine]\nname = 'glass'\ntick_hz = 10000\n"
        + "".join(
            f"[axes.{a}]\nv_max = 50.0\na_max = 300.0\nmin = 0.0\nmax = 300.0\n"
            + (f"j_max = {j}\n" if j is not None else "")
            for a in "xyz"
        )
        + "[path]\nfeed = 30.0\nrapid = 50.0\n[laser]\nmode = 'pulsed'\n"
        + "".join(f"{k} = {json.dumps(v)}\n" for k, v in {"pulse_hz": 40.0, "tolerance": 0.05, **laser}.items())
    )
    return parse_machine(text, "glass.toml")


def raster_job(n: int = 1500, seed: int = 1, semi=(4.0, 2.0, 0.3)) -> PointJob:
    pts = superellipsoid_raster(semi, center_mm=(50.0, 50.0, 20.0), seed=seed, max_points=n)
    return PointJob(pts, None, np.arange(1, len(pts) + 1), "raster")


@pytest.fixture(scope="module")
def plans():
    job = raster_job()
    return job, {name: plan_points(job, GLASS, name) for name in ("stop-and-go", "seed", "sync")}


# -- point files ------------------------------------------------------------------------------


def test_point_file_formats():
    text = "# scan of a bird\nx,y,z\n1,2,3\n\n4;5;6\n 7\t8   9 \n"
    job = parse_points(text, "bird.csv")
    assert job.points.tolist() == [[1, 2, 3], [4, 5, 6], [7, 8, 9]]
    assert job.line.tolist() == [3, 5, 6] and job.energy is None
    e = parse_points("x y z energy\n0 0 0 1.5\n1 0 0 2.5\n", "e.xyz")
    assert e.energy.tolist() == [1.5, 2.5]


@pytest.mark.parametrize(
    ("text", "line", "needle"),
    [
        ("0 0 0\n1 1\n", 2, "expected 3 numbers"),
        ("0 0 0\n1 one 1\n", 2, "'one' is not a number"),
        ("0 0 0\n1 nan 1\n", 2, "NaN or infinite"),
        ("0 0 0 1\n1 1 1 -2\n", 2, "negative pulse energy"),
        ("# nothing\n\n", 0, "no points"),
    ],
)
def test_point_file_errors_name_the_line(text, line, needle):
    with pytest.raises(SourceError) as err:
        parse_points(text, "pts.xyz")
    assert err.value.line == line and needle in str(err.value) and str(err.value).startswith("pts.xyz")


@settings(max_examples=150, deadline=None)
@given(st.text(alphabet="0123456789 .,;-+eE\n#xyzna\t", max_size=200))
def test_point_parser_fuzz_clean_errors_only(text):
    try:
        job = parse_points(text, "fuzz.xyz")
    except SourceError as exc:
        assert exc.file == "fuzz.xyz"
    else:
        assert job.points.shape[1] == 3 and np.all(np.isfinite(job.points))


def test_binary_point_file_is_a_clean_error(tmp_path):
    f = tmp_path / "bad.xyz"
    f.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(SourceError, match="not a text file"):
        read_points(f)


def test_gcode_g1_end_points_are_the_points():
    prog = parse_gcode("G0 X50 Y50 Z20\nG1 X50.1 F100\nG1 X50.2\nG0 X51\nG1 Y50.1\n", "p.ngc")
    job = points_from_program(prog)
    assert np.allclose(job.points, [[50.1, 50, 20], [50.2, 50, 20], [51, 50.1, 20]])
    assert job.line.tolist() == [2, 3, 5]


# -- windows ----------------------------------------------------------------------------------


def test_window_of_the_documents_machine():
    w = pulse_window(GLASS)
    assert (w.n_min, w.n_max) == (238, 262)  # 23.75 ms rounds up, 26.25 ms down, at 10 kHz
    assert w.shortest_period_s == pytest.approx(0.02375)


def test_window_without_a_whole_tick_is_a_machine_error():
    m = parse_machine(
        "[machine]\ntick_hz = 1000\n[axes.x]\nv_max=1\na_max=1\nmin=0\nmax=1\n[axes.y]\nv_max=1\na_max=1\nmin=0\n"
        "max=1\n[path]\nfeed=1\nrapid=1\n[laser]\nmode='pulsed'\npulse_hz=400.0\ntolerance=0.01\n",
        "m.toml",
    )
    with pytest.raises(MachineFileError, match="no whole number of ticks"):
        pulse_window(m)


def test_tolerance_of_one_or_more_is_refused():
    with pytest.raises(MachineFileError, match="fraction"):
        glass(tolerance=1.0)


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 400), st.integers(0, 60), st.integers(1, 5000), st.booleans())
def test_snap_up_and_split_give_admissible_intervals(n_min, width, want, idle):
    w = PulseWindow(10000.0, 40.0, 0.05, n_min, n_min + width, idle)
    n, m = w.snap_up(np.array([want]))
    assert n[0] >= want
    if not idle:
        assert m[0] == 1
        return
    assert w.admissible(n, m)[0]
    # nothing shorter is admissible
    for shorter in range(want, int(n[0])):
        mm = np.arange(1, shorter // max(n_min, 1) + 2)
        assert not np.any(w.admissible(np.full_like(mm, shorter), mm))
    ticks = np.concatenate([[0], w.split(np.array([0]), n, m), n])
    gaps = np.diff(ticks)
    assert gaps.size == m[0] and gaps.min() >= w.n_min and gaps.max() <= w.n_max


# -- the spline ---------------------------------------------------------------------------------


def test_spline_rests_with_zero_acceleration_and_equals_scipy():
    rng = np.random.default_rng(3)
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.01, 0.1, 40))])
    y = rng.normal(size=(41, 3))
    pad = 23  # padding rows beyond the knots must not change anything
    t_pad = np.concatenate([t, t[-1] + np.arange(1, pad + 1)])
    y_pad = np.vstack([y, np.repeat(y[-1:], pad, axis=0)])
    M, y_full = (np.asarray(a) for a in spline_moments(t_pad, y_pad, np.int64(41)))
    y_full = y_full[:41]
    # the free knots 1 and 39 were placed; every other knot is interpolated
    assert np.array_equal(np.delete(y_full, [1, 39], axis=0), np.delete(y, [1, 39], axis=0))
    ref = CubicSpline(t, y_full, bc_type="clamped")  # rest (v = 0) at both ends
    assert np.allclose(M[:41], ref(t, 2), atol=1e-9 * np.abs(M).max())
    assert np.abs(M[[0, 40]]).max() == 0 and np.abs(ref(t[[0, -1]], 2)).max() < 1e-9 * np.abs(M).max()
    assert np.all(M[41:] == 0)


# -- the planners -----------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["stop-and-go", "seed", "sync"])
def test_every_planner_writes_a_table_that_checks(plans, name, tmp_path):
    job, planned = plans
    p = planned[name]
    path = write_pulse_table(p, tmp_path / f"{name}.ticks", progress=False)
    table = TableFile(path)
    meas = measure_table(table, GLASS)
    assert meas.ok, meas.violations[:5]
    pc = check_pulses(table, GLASS, job)
    assert pc.ok, pc.violations[:5]
    assert pc.n_work == len(job) and pc.n_idle == p.plan.idle_tick.size
    assert 238 <= pc.min_interval_ticks and pc.max_interval_ticks <= 262
    assert pc.max_miss_mm < 1e-6  # the unquantised beam is on the point
    # the quantised integer position is the point rounded to the discrete
    ev = table.events[table.events["kind"] == EventKind.WORK_PULSE]
    pos = table.positions[ev["tick"]]
    assert np.array_equal(pos, np.round(job.points[ev["aux"]] / 0.001).astype(np.int32))


def test_stop_and_go_is_two_periods_per_point_and_rests(plans):
    job, planned = plans
    p = planned["stop-and-go"].plan
    gaps = np.diff(p.work_tick)
    assert set(np.unique(gaps)) <= {250, 500, 750, 1000}  # whole nominal periods of the free-running lamp
    assert 1.95 < np.mean(gaps) / 250 < 2.2
    tr = p.trajectory
    v_before = (tr.position(p.work_tick) - tr.position(p.work_tick - 1)) * tr.tick_hz
    assert np.abs(v_before).max() < 1e-9  # standing still at every pulse


def test_sync_burns_in_motion_near_the_lower_bound(plans):
    job, planned = plans
    sync, old, seed = planned["sync"], planned["stop-and-go"], planned["seed"]
    lb = (len(job) - 1) * 0.02375
    assert sync.plan.burn_time_s <= 1.10 * lb
    assert sync.plan.burn_time_s <= (1 - 0.45) * old.plan.burn_time_s
    assert sync.plan.burn_time_s < seed.plan.burn_time_s < old.plan.burn_time_s
    tr = sync.plan.trajectory
    w = sync.plan.work_tick[1:-1]
    v = np.linalg.norm(tr.position(w + 1) - tr.position(w - 1), axis=1) * tr.tick_hz / 2
    assert np.median(v) > 4.0  # passes points at ~5 mm/s, never stopping on the rows


def test_seed_stops_at_row_corners_only(plans):
    job, planned = plans
    p = planned["seed"]
    turn = np.flatnonzero(np.abs(np.diff(np.sign(np.diff(job.points[:, 0])))) > 0)  # x reverses after point turn+1
    tr = p.plan.trajectory
    w = p.plan.work_tick
    v = np.linalg.norm(tr.position(w) - tr.position(w - 1), axis=1) * tr.tick_hz
    # at rest on the corner: the last tick before it moves at most what a_max allows in one tick
    assert np.all(v[turn + 1] <= 300.0 / tr.tick_hz)
    assert np.median(v) > 1.0  # elsewhere it passes the points moving
    assert p.plan.stats["stops"] >= turn.size


def test_jerk_limit_holds_at_every_tick(tmp_path):
    m = glass(j_max=20000.0)
    job = raster_job(600)
    p = plan_points(job, m, "sync")
    table = TableFile(write_pulse_table(p, tmp_path / "j.ticks", progress=False))
    meas = measure_table(table, m)
    assert meas.ok, meas.violations[:5]
    assert max(meas.max_abs_j.values()) <= 20000.0 * (1 + 1e-6)
    assert check_pulses(table, m, job).ok
    unlimited = plan_points(job, GLASS, "sync")
    assert p.plan.burn_time_s >= unlimited.plan.burn_time_s


def test_energy_goes_to_the_work_pulses():
    job = raster_job(50)
    job = PointJob(job.points, np.linspace(1, 2, 50), job.line, job.file)
    ev = pulse_events(plan_points(job, GLASS, "sync"))
    work = ev[ev["kind"] == EventKind.WORK_PULSE]
    assert np.allclose(work["value"], np.linspace(1, 2, 50))
    shutter = ev[ev["kind"] == EventKind.SHUTTER]
    assert shutter["aux"][0] == 1 and np.all(np.diff(shutter["aux"].astype(int)) != 0)


def test_check_catches_a_shifted_pulse_and_a_missed_point(plans, tmp_path):
    job, planned = plans
    p = planned["sync"]
    from jaxcnc.ticks.pulses import TrajectorySampler

    ev = pulse_events(p)
    work = np.flatnonzero(ev["kind"] == EventKind.WORK_PULSE)
    ev["tick"][work[10]] += 3  # fires 0.3 ms late: off the point, and its intervals change
    ev = np.delete(ev, work[20])  # point 20 never burned
    path = write_samples(
        tmp_path / "bad.ticks",
        GLASS,
        TrajectorySampler(p.plan.trajectory, GLASS),
        ev,
        table_meta(GLASS, "raster", "sync", 0.0),
        progress=False,
    )
    pc = check_pulses(TableFile(path), GLASS, job)
    text = "\n".join(map(str, pc.violations))
    assert "misses point 10" in text
    assert "point 20 (raster:21) is burned 0 times" in text
    assert "outside the window" in text


def test_without_idle_pulses_a_gap_the_axes_cannot_bridge_is_an_error():
    m = glass(idle_pulses=False)
    pts = np.array([[50.0, 50.0, 20.0], [50.125, 50.0, 20.0], [53.0, 50.0, 20.0]])
    with pytest.raises(SourceError) as err:
        plan_points(PointJob(pts, None, np.array([4, 5, 6]), "far.xyz"), m, "sync")
    assert err.value.line == 6 and "without idle pulses" in str(err.value)


def test_points_outside_travel_are_refused():
    pts = np.array([[50.0, 50.0, 20.0], [350.0, 50.0, 20.0]])
    with pytest.raises(SourceError) as err:
        plan_points(PointJob(pts, None, np.array([1, 7]), "out.xyz"), GLASS)
    assert err.value.line == 7 and "outside the travel" in str(err.value)


def test_reorder_restores_the_raster_of_a_shuffled_cloud():
    job = raster_job(800)
    shuffled = job.take(np.random.default_rng(0).permutation(len(job)))
    order = serpentine_order(shuffled.points)
    assert np.array_equal(shuffled.points[order], job.points)
    assert np.array_equal(serpentine_order(job.points), np.arange(len(job)))


# -- the command line -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def glass_toml(tmp_path_factory):
    from importlib import resources

    d = tmp_path_factory.mktemp("glass")
    m = d / "glass-engraver.toml"
    m.write_text(resources.files("jaxcnc.data").joinpath("glass-engraver.toml").read_text())
    return m


def test_cli_plan_point_file_report_and_check(glass_toml, tmp_path, capsys):
    job = raster_job(400)
    pts = tmp_path / "bird.xyz"
    write_xyz(pts, job.points)
    out, rep = tmp_path / "bird.ticks", tmp_path / "bird.json"
    assert main(["plan", str(pts), "-m", str(glass_toml), "-o", str(out), "-r", str(rep), "-q"]) == 0
    r = json.loads(rep.read_text())
    for key in (
        "n_points",
        "n_pulses",
        "lower_bound_s",
        "lower_bound_travel_s",
        "stop_and_go_s",
        "total_time_s",
        "burn_time_s",
    ):
        assert key in r
    assert r["n_points"] == 400 and r["n_pulses"] >= 400 and r["violations"] == []
    assert r["lower_bound_s"] <= r["lower_bound_travel_s"] <= r["burn_time_s"] <= 1.10 * r["lower_bound_s"]
    assert r["reduction_vs_stop_and_go"] >= 0.45
    capsys.readouterr()
    assert main(["check", str(out), "-m", str(glass_toml)]) == 0
    assert "every point burned once" in capsys.readouterr().out
    # the source changed since planning: refused unless the points are given
    write_xyz(pts, job.points + 0.01)
    assert main(["check", str(out), "-m", str(glass_toml)]) == 2
    assert "changed since the table was planned" in capsys.readouterr().err
    assert main(["check", str(out), "-m", str(glass_toml), "--points", str(pts)]) == 1
    assert "misses point" in capsys.readouterr().out


def test_cli_summary_names_both_bounds_and_a_single_point_plans(glass_toml, tmp_path, capsys):
    """The printed summary gives the burn time against the plain and the certified travel-aware bound; a job of one
    point (no interval, both bounds 0) plans, prints and checks instead of failing on the ratios."""
    pts = tmp_path / "few.xyz"
    write_xyz(pts, raster_job(60).points)
    assert main(["plan", str(pts), "-m", str(glass_toml), "-o", str(tmp_path / "few.ticks")]) == 0
    out = capsys.readouterr().out
    assert "x the lower bound" in out and "x the certified travel-aware bound" in out
    one = tmp_path / "one.xyz"
    write_xyz(one, np.array([[50.0, 50.0, 20.0]]))
    assert main(["plan", str(one), "-m", str(glass_toml), "-o", str(tmp_path / "one.ticks")]) == 0
    out = capsys.readouterr().out
    assert "1 points, 1 pulses" in out and "x the lower bound" not in out
    assert main(["check", str(tmp_path / "one.ticks"), "-m", str(glass_toml)]) == 0


def test_cli_reorder_reports_both_orders(glass_toml, tmp_path):
    job = raster_job(300)
    shuffled = job.points[np.random.default_rng(2).permutation(len(job))]
    pts = tmp_path / "shuffled.xyz"
    write_xyz(pts, shuffled)
    rep = tmp_path / "r.json"
    args = ["plan", str(pts), "-m", str(glass_toml), "-o", str(tmp_path / "s.ticks"), "-r", str(rep), "-q"]
    assert main([*args, "--reorder"]) == 0
    r = json.loads(rep.read_text())
    assert r["burn_time_s"] < 0.5 * r["as_given_burn_time_s"]
    assert main(["check", str(tmp_path / "s.ticks"), "-m", str(glass_toml)]) == 0


def test_cli_point_file_needs_a_pulsed_machine(tmp_path, capsys):
    from tests.conftest import EXAMPLE_MACHINE

    pts = tmp_path / "p.xyz"
    pts.write_text("0 0 0\n1 0 0\n")
    assert main(["plan", str(pts), "-m", str(EXAMPLE_MACHINE), "-o", str(tmp_path / "o.ticks")]) == 2
    assert 'needs [laser] mode = "pulsed"' in capsys.readouterr().err


def test_cli_bad_point_file_exits_2_with_line(glass_toml, tmp_path, capsys):
    pts = tmp_path / "bad.xyz"
    pts.write_text("50 50 20\n50.1 50 20\n50.1 50 20\n")
    out = tmp_path / "o.ticks"
    assert main(["plan", str(pts), "-m", str(glass_toml), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{pts}:3: the same point as line 2" in err and not out.exists()


def test_reorder_is_refused_for_contours(tmp_path, capsys):
    from tests.conftest import EXAMPLE_MACHINE

    prog = tmp_path / "p.ngc"
    prog.write_text("G1 X1 F60\n")
    assert main(["plan", str(prog), "-m", str(EXAMPLE_MACHINE), "-o", str(tmp_path / "o"), "--reorder"]) == 2
    assert isinstance(JaxcncError("x"), Exception)
    assert "--reorder applies to point-by-point jobs" in capsys.readouterr().err


def test_cli_gcode_on_a_pulsed_machine_burns_the_g1_end_points(glass_toml, tmp_path):
    prog = tmp_path / "dots.ngc"
    lines = ["G21 G90", "G0 X50 Y50 Z20"] + [f"G1 X{50 + 0.125 * (i + 1):.3f} F1800" for i in range(40)] + ["M2"]
    prog.write_text("\n".join(lines) + "\n")
    rep = tmp_path / "r.json"
    out = tmp_path / "dots.ticks"
    assert main(["plan", str(prog), "-m", str(glass_toml), "-o", str(out), "-r", str(rep), "-q"]) == 0
    r = json.loads(rep.read_text())
    assert r["n_points"] == 40 and r["violations"] == []
    assert main(["check", str(out), "-m", str(glass_toml)]) == 0
