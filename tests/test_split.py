"""Stage + scanner split: the [scanner] calibration, the own low-pass split, the documents' seed, the checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxcnc.errors import MachineFileError, PlanningError
from jaxcnc.format import TableFile
from jaxcnc.io.drawing import DrawingOptions, arc_piece, assemble, line_piece
from jaxcnc.machine import parse_machine
from jaxcnc.planners.split import plan_split
from jaxcnc.program import program_start
from jaxcnc.ticks.split import check_split, kinematic_csv, plot_split, write_split_table
from jaxcnc.ticks.verify import measure_table

MACHINE = """\
[machine]
name = "stage-scanner"
tick_hz = 10000
discrete_mm = 0.001
[axes.x]
v_max = 1000
a_max = 4903.325
min = -10
max = 200
[axes.y]
v_max = 1000
a_max = 4903.325
min = -10
max = 200
[axes.u]
v_max = 5000
a_max = 5e6
min = -10
max = 10
[axes.v]
v_max = 5000
a_max = 5e6
min = -10
max = 10
[path]
feed = 100
rapid = 1000
corner_tol_mm = 0.001
[scanner]
axes = ["u", "v"]
field_mm = [{field}, {field}]
{extra}
"""


def machine(field: float = 20.0, extra: str = ""):
    return parse_machine(MACHINE.format(field=field, extra=extra), "scan.toml")


def part(m, teeth: int = 12):
    """A 6 x 4 mm plate with a serrated bottom edge (sharp corners) and a 0.8 mm hole."""
    x = np.linspace(2.0, 8.0, 2 * teeth + 1)
    y = np.where(np.arange(x.size) % 2, 1.8, 2.0)
    pts = list(zip(x, y, strict=True)) + [(8.0, 6.0), (2.0, 6.0)]
    pieces = [line_piece(np.array(a), np.array(b), "LINE", 1) for a, b in zip(pts, pts[1:] + pts[:1], strict=True)]
    pieces += arc_piece(np.array([5.0, 4.0]), 0.4, 0.0, 2 * np.pi, "CIRCLE", 2, 0.002)
    return assemble(pieces, DrawingOptions(), program_start(m), "part.dxf").program


def test_calibration_keys_are_checked():
    m = machine(extra="scale = [1.0, -1.0]\nrotation_deg = 90\noffset_mm = [0.5, 0.0]")
    assert m.scanner.scale == (1.0, -1.0) and m.scanner.rotation_deg == 90 and m.scanner.offset_mm == (0.5, 0.0)
    with pytest.raises(MachineFileError, match="scale"):
        machine(extra="scale = [1.0, 0.0]")
    with pytest.raises(MachineFileError, match="offset_mm"):
        machine(extra="offset_mm = [1.0]")
    with pytest.raises(MachineFileError, match="unknown key 'gain'"):
        machine(extra="gain = 2")


@pytest.mark.parametrize("extra", ["", "scale = [2.0, -1.0]\nrotation_deg = 30\noffset_mm = [0.5, -0.25]"])
def test_own_split_holds_every_limit_field_and_the_contour(tmp_path, extra):
    m = machine(extra=extra)
    prog = part(m)
    plan = plan_split(prog, m)
    table = TableFile(write_split_table(plan, prog, m, tmp_path / "s.ticks"))
    meas = measure_table(table, m)
    assert meas.violations == []  # x, y at 0.5 g and u, v within their own limits, at every tick
    assert max(meas.max_abs_a["x"], meas.max_abs_a["y"]) <= 4903.325
    chk = check_split(table, m, prog)
    assert chk.violations == [] and chk.max_tool_deviation_mm <= 0.001 and chk.max_field_use <= 1.0
    assert meas.max_abs_a["u"] > 1e5  # the scanner takes the corners
    # constant tool speed while moving; the job is the path at the feed plus the filter's two ends
    w = plan.stats["filter_ticks"]
    assert plan.total_time_s == pytest.approx(plan.path_length_mm / plan.feed_mm_s + 2 * (w - 1) / m.tick_hz, abs=2e-4)
    assert plan.feed_mm_s <= 100.0 and plan.feed_mm_s == pytest.approx(100.0, rel=1e-3)
    moving = np.linalg.norm(np.diff(plan.tool, axis=0), axis=1) * m.tick_hz
    assert np.max(moving) <= plan.feed_mm_s * (1 + 1e-9)
    csv = kinematic_csv(plan, tmp_path / "k.csv")
    head = csv.read_text().splitlines()[0].split(",")
    assert head[:5] == ["time_s", "x_mm", "y_mm", "p_mm", "q_mm"] and "abig_mm_s2" in head
    assert plot_split(plan, m, tmp_path / "s.png").stat().st_size > 1000


def test_stage_jerk_limit_widens_the_filter_and_holds_at_every_tick(tmp_path):
    """With j_max on the stage the two averages are ≥ 2·√(F/j) wide (filter_ticks): the jerk measured by the
    check obeys it; without the limit the same part's stage jerk is above it (the limit binds)."""
    free = machine()
    j = 2e5
    limited = parse_machine(
        MACHINE.format(field=20.0, extra="").replace("a_max = 4903.325\n", f"a_max = 4903.325\nj_max = {j:g}\n"),
        "jerk.toml",
    )
    assert limited.axis("x").j_max == j and limited.axis("u").j_max is None
    prog = part(limited)
    plan = plan_split(prog, limited)
    assert plan.stats["filter_ticks"] >= math.ceil(2 * math.sqrt(plan.feed_mm_s / j) * limited.tick_hz)
    table = TableFile(write_split_table(plan, prog, limited, tmp_path / "j.ticks"))
    meas = measure_table(table, limited)
    assert meas.violations == []
    assert max(meas.max_abs_j["x"], meas.max_abs_j["y"]) <= j
    assert check_split(table, limited, prog).violations == []
    loose = plan_split(part(free), free)
    assert loose.stats["max_stage_jerk_mm_s3"] > j > plan.stats["max_stage_jerk_mm_s3"]


def test_a_field_too_small_names_the_place_and_the_speed_that_fits():
    m = machine(field=0.2)
    prog = part(m)
    with pytest.raises(PlanningError) as exc:
        plan_split(prog, m)
    msg = str(exc.value)
    assert msg.startswith("part.dxf:") and "outside its 0.2 x 0.2 mm field" in msg and "highest contour speed" in msg
    fits = float(msg.split("fits is ")[1].split(" mm/s")[0])
    assert fits < 100
    plan = plan_split(prog, m, feed_mm_s=fits)
    assert plan.stats["field_use"] <= 1.0


def test_seed_method_reports_the_documents_figures(tmp_path):
    m = machine()
    prog = part(m)
    plan = plan_split(prog, m, method="seed")
    fig = plan.stats["seed"]
    assert fig["sharp_left"] == 0 and 170 < fig["alpha_kr_deg"] < 180
    assert fig["paper_time_s"] >= fig["intent_time_s"] > 0
    table = TableFile(write_split_table(plan, prog, m, tmp_path / "seed.ticks"))
    assert check_split(table, m, prog).violations == []  # the tool still follows the contour
    assert plan.stats["max_stage_accel_mm_s2"] > 4903.325  # the chord smoothing does not bound the stage


def test_needs_a_scanner():
    from tests.conftest import make_machine

    m = make_machine()
    with pytest.raises(PlanningError, match=r"\[scanner\]"):
        plan_split(part(m), m)


def test_cli_plans_splits_checks_and_writes_the_outputs(tmp_path, capsys):
    import ezdxf

    from jaxcnc.cli.main import main

    mfile = tmp_path / "scan.toml"
    mfile.write_text(MACHINE.format(field=20.0, extra=""))
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    msp.add_lwpolyline([(2, 2), (5, 1.5), (8, 2), (8, 6), (2, 6)], close=True)
    msp.add_circle((5, 4), 0.5)
    part_file = tmp_path / "p.dxf"
    doc.saveas(part_file)
    out = tmp_path / "p.ticks"
    csv, png = tmp_path / "k.csv", tmp_path / "p.png"
    args = [
        "plan",
        str(part_file),
        "-m",
        str(mfile),
        "-o",
        str(out),
        "--kinematics",
        str(csv),
        "--split-plot",
        str(png),
    ]
    assert main(args) == 0
    assert "stage + scanner (own)" in capsys.readouterr().out
    assert csv.stat().st_size > 0 and png.stat().st_size > 0
    table = TableFile(out)
    assert list(table.axes) == ["x", "y", "u", "v"] and table.header.meta["split"] == "own"
    assert main(["check", str(out), "-m", str(mfile)]) == 0
    assert "tool point within" in capsys.readouterr().out
    none = tmp_path / "n.ticks"
    assert main(["plan", str(part_file), "-m", str(mfile), "-o", str(none), "--split", "none", "-q"]) == 0
    assert TableFile(none).header.n_rows > table.header.n_rows  # the stage alone is slower


@pytest.mark.slow
def test_must_show_part_three_times_faster_than_the_stage_alone(tmp_path):
    """The issue's figure: sharp corners and small holes at 6 m/min, 0.5 g stage, 20 x 20 mm scanner."""
    from jaxcnc.bench.split import MACHINE as BENCH_MACHINE
    from jaxcnc.bench.split import make_part
    from jaxcnc.front_ends import load_input
    from jaxcnc.planners import plan_job

    m = parse_machine(BENCH_MACHINE, "bench.toml")
    prog = load_input(make_part(tmp_path / "part.dxf"), m)
    plan = plan_split(prog, m)
    table = TableFile(write_split_table(plan, prog, m, tmp_path / "own.ticks"))
    meas, chk = measure_table(table, m), check_split(table, m, prog)
    assert meas.violations == [] and chk.violations == []
    assert max(meas.max_abs_a["x"], meas.max_abs_a["y"]) <= 0.5 * 9806.65
    assert chk.max_field_use <= 1.0 and chk.max_tool_deviation_mm <= m.discrete_mm
    assert plan.feed_mm_s == pytest.approx(100.0, rel=1e-3)
    assert plan.total_time_s <= 1.05 * plan.path_length_mm / plan.feed_mm_s
    alone = plan_job(prog, m).plan.total_time_s  # corners within one discrete, as the tool point
    assert alone >= 3 * plan.total_time_s


@pytest.mark.parametrize(
    ("body", "line", "why"),
    [
        ("G1 X3 Y2 F600\nG4 P0.5\nG1 X4\n", 4, "a dwell cannot be split"),
        ("G1 X3 Y2 F600\nM0\nG1 X4\n", 4, "a pause or tool change stops the tool"),
        ("G1 X3 Y2 F600\nG1 Z1\nG1 X4\n", 4, "moves Z; a stage + scanner split is planar"),
    ],
)
def test_what_a_split_cannot_do_is_refused_naming_the_line(tmp_path, capsys, body, line, why):
    from jaxcnc.cli.main import main

    m = tmp_path / "scan.toml"
    m.write_text(MACHINE.format(field=20.0, extra=""))
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90 M3 S1\nG0 X2 Y2\n" + body + "M5\nM2\n")
    assert main(["plan", str(prog), "-m", str(m), "-o", str(tmp_path / "p.ticks"), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"jaxcnc: error: {prog}:{line}: {why}") and "\n" not in err
    assert not (tmp_path / "p.ticks").exists()
