"""DXF drawings as Programs: every entity type, units, layers, blocks, the contour checks, cut order, the corpus."""

from __future__ import annotations

import math
from pathlib import Path

import ezdxf
import numpy as np
import pytest
from shapely import LinearRing, Polygon

from jaxcnc.errors import SourceError
from jaxcnc.format import TableFile
from jaxcnc.io.drawing import DrawingOptions
from jaxcnc.io.dxf import read_dxf
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job
from jaxcnc.program import Kind, LaserMode
from jaxcnc.ticks.deviation import path_deviation
from jaxcnc.ticks.table import write_table
from jaxcnc.ticks.verify import measure_table
from tests.conftest import CORPUS, machine_text

START = np.zeros(3)


def big_machine():
    """The test machine with 10 m of travel (drawings in inches reach far) at 1 kHz."""
    text = machine_text(tick_hz=1000, v=200.0, a=2000.0, rapid=200.0)
    return parse_machine(text.replace("-500.0", "-5000.0").replace("max = 500.0", "max = 5000.0"), "big.toml")


def plan_and_check(drawing, folder: Path) -> float:
    """Plan the drawing's Program, write the table, verify limits and the path; the job time."""
    m = big_machine()
    job = plan_job(drawing.program, m)
    table = TableFile(write_table(job, folder / "d.ticks", progress=False))
    meas = measure_table(table, m)
    path = path_deviation(table, m, drawing.program)
    assert meas.violations == [] and path.violations == [], (meas.violations + path.violations)[:3]
    return job.plan.total_time_s


def continuous(program) -> bool:
    return bool(np.all(program.end[:-1] == program.start[1:]))


def save(doc, tmp_path: Path, name: str = "d.dxf") -> Path:
    p = tmp_path / name
    doc.saveas(p)
    return p


def square(msp, x0: float, y0: float, size: float, layer: str = "0"):
    pts = [(x0, y0), (x0 + size, y0), (x0 + size, y0 + size), (x0, y0 + size)]
    return msp.add_lwpolyline(pts, close=True, dxfattribs={"layer": layer})


# --------------------------------------------------------------------------------------------- entities


def test_lines_arcs_circle_and_cut_order(tmp_path):
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    for a, b in [((0, 0), (40, 0)), ((40, 0), (40, 30)), ((0, 30), (0, 0))]:
        msp.add_line(a, b)
    msp.add_arc((20, 30), 20, 0, 180)  # the top edge, counter-clockwise from (40, 30) to (0, 30)
    msp.add_circle((10, 10), 3)
    msp.add_circle((30, 10), 3)
    d = read_dxf(save(doc, tmp_path), START)
    assert [c.depth for c in d.contours] == [1, 1, 0]  # both holes before the outline
    assert all(c.closed for c in d.contours)
    assert continuous(d.program)
    p = d.program
    assert np.sum(p.kind == Kind.ARC) == 1 + 4  # the arc and two half circles per hole
    assert np.all(p.laser[p.rapid] == LaserMode.OFF) and np.all(p.laser[~p.rapid] == LaserMode.CONSTANT)
    assert np.all(np.isnan(p.feed))  # the machine's [path] feed
    # outer counter-clockwise, holes clockwise (scrap on the right)
    assert LinearRing(d.contours[2].poly).is_ccw and not LinearRing(d.contours[0].poly).is_ccw
    # nearest first: the hole nearer to the start point (0, 0) is cut first
    assert np.linalg.norm(d.contours[0].pieces[0].start - [10, 10]) < 3.01


def test_bulges_spline_ellipse_and_plan(tmp_path):
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    # a slot: two straight edges and two half-circle bulges
    msp.add_lwpolyline([(0, 0, 0, 0, 1), (20, 0, 0, 0, 1), (20, 10), (0, 10)], format="xyseb", close=False)
    msp.add_lwpolyline(
        [(0, 0, 0, 0, 0), (20, 0, 0, 0, 1), (20, 10, 0, 0, 0), (0, 10, 0, 0, 1)], format="xyseb", close=True
    )
    d = read_dxf(save(doc, tmp_path), START, DrawingOptions(allow_open=True))
    assert np.sum(d.program.kind == Kind.ARC) >= 2
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    msp.add_ellipse((50, 50), major_axis=(20, 0), ratio=0.5)
    fit = [(0, 0), (10, 20), (30, -10), (50, 15), (60, 0)]
    s = msp.add_spline(fit)
    msp.add_line((60, 0), (60, -30))
    msp.add_line((60, -30), (0, -30))
    msp.add_line((0, -30), (0, 0))
    assert s.dxftype() == "SPLINE"
    d = read_dxf(save(doc, tmp_path), START)
    assert np.sum(d.program.kind == Kind.CURVE) >= 4 + 1  # the ellipse's quarters and the spline
    assert continuous(d.program)
    assert plan_and_check(d, tmp_path) > 0


def test_insert_blocks_units_layers(tmp_path):
    doc = ezdxf.new(units=1)  # inches
    blk = doc.blocks.new("HOLE")
    blk.add_circle((0, 0), 0.1)
    msp = doc.modelspace()
    doc.layers.add("CUT")
    doc.layers.add("NOTES")
    square(msp, 0, 0, 2, layer="CUT")
    msp.add_blockref("HOLE", (0.5, 0.5), dxfattribs={"layer": "CUT"})
    msp.add_blockref("HOLE", (1.5, 1.5), dxfattribs={"layer": "CUT", "xscale": 2, "yscale": 2})
    msp.add_text("part 7", dxfattribs={"layer": "NOTES"})
    square(msp, 10, 10, 1, layer="NOTES")
    d = read_dxf(save(doc, tmp_path), START, DrawingOptions(layers=("CUT",)))
    assert len(d.contours) == 3
    hole = max(d.contours[:2], key=lambda c: c.poly[:, 0].max())
    assert hole.pieces[0].source.startswith("CIRCLE") and "INSERT" in hole.pieces[0].source
    assert np.ptp(hole.poly[:, 0]) == pytest.approx(2 * 0.2 * 25.4, rel=1e-6)  # scaled 2x, in mm
    assert np.ptp(d.contours[-1].poly[:, 0]) == pytest.approx(2 * 25.4)
    every = read_dxf(save(doc, tmp_path), START)
    assert len(every.contours) == 4 and any("TEXT" in n for n in every.notes)
    with pytest.raises(SourceError, match="no layer 'CUTS'"):
        read_dxf(save(doc, tmp_path), START, DrawingOptions(layers=("CUTS",)))


def test_lead_in_from_the_scrap_side(tmp_path):
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    square(msp, 0, 0, 50)
    msp.add_circle((25, 25), 5)
    d = read_dxf(save(doc, tmp_path), START, DrawingOptions(lead_in_mm=2.0))
    p = d.program
    cuts = np.flatnonzero(p.rapid) + 1  # the row after each rapid is the lead-in
    assert np.all(p.kind[cuts] == Kind.LINE) and np.all(p.laser[cuts] == LaserMode.CONSTANT)
    lead_len = np.linalg.norm(p.end[cuts] - p.start[cuts], axis=1)
    assert np.allclose(lead_len, 2.0)
    hole_entry, outer_entry = p.start[cuts[0], :2], p.start[cuts[1], :2]
    assert np.linalg.norm(hole_entry - [25, 25]) < 5  # inside the hole (scrap)
    assert not (0 < outer_entry[0] < 50 and 0 < outer_entry[1] < 50)  # outside the part


# --------------------------------------------------------------------------------------------- refusals


def test_refusals_name_entity_and_place(tmp_path):
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    bow = msp.add_lwpolyline([(0, 0), (10, 10), (10, 0), (0, 10)], close=True, dxfattribs={"layer": "CUT"})
    with pytest.raises(
        SourceError, match=rf"crosses itself at \(5, 5\) \(LWPOLYLINE #{bow.dxf.handle} on layer 'CUT'\)"
    ):
        read_dxf(save(doc, tmp_path), START)

    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    msp.add_line((0, 0), (10, 0))
    last = msp.add_line((10, 0), (10, 10))
    with pytest.raises(SourceError, match=rf"open contour: LINE #{last.dxf.handle} on layer '0' ends at \(10, 10\)"):
        read_dxf(save(doc, tmp_path), START)
    assert len(read_dxf(save(doc, tmp_path), START, DrawingOptions(allow_open=True)).contours) == 1

    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    square(msp, 0, 0, 10)
    face = msp.add_3dface([(0, 0), (1, 0), (1, 1)])
    with pytest.raises(
        SourceError, match=rf"3DFACE #{face.dxf.handle} on layer '0': 3DFACE entities are not supported"
    ):
        read_dxf(save(doc, tmp_path), START)

    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    square(msp, 0, 0, 10)
    square(msp, 5, 5, 10)
    with pytest.raises(SourceError, match="contours cross or touch at"):
        read_dxf(save(doc, tmp_path), START)

    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    msp.add_line((3, 3), (3, 3))
    with pytest.raises(SourceError, match="nothing to cut"):
        read_dxf(save(doc, tmp_path), START)


def test_duplicates_and_gaps_within_tolerance(tmp_path):
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    pts = [(0, 0), (10, 0), (10, 10), (0, 10)]
    for i in range(4):
        msp.add_line(pts[i], pts[(i + 1) % 4])
    msp.add_line((10, 10), (0, 10))  # drawn twice
    msp.add_line((0, 10), (10, 10))  # and once backwards
    msp.add_line((20, 0), (30, 0))
    msp.add_line((30.004, 0), (30, 10))  # a 4 µm gap: joined, bridged
    msp.add_line((30, 10), (20, 0))
    d = read_dxf(save(doc, tmp_path), START)
    assert len(d.contours) == 2 and sum("duplicate" in n for n in d.notes) == 2
    assert continuous(d.program)
    with pytest.raises(SourceError, match="open contour"):
        read_dxf(save(doc, tmp_path), START, DrawingOptions(tol_mm=0.001))


def test_unreadable_file_is_one_line(tmp_path):
    p = tmp_path / "broken.dxf"
    p.write_bytes(b"0\nSECTION\n2\nENTITIES\n0\nLINE\n10\nnot-a-number\n")
    with pytest.raises(SourceError) as exc:
        read_dxf(p, START)
    assert str(exc.value).startswith(str(p)) and "\n" not in str(exc.value)


# --------------------------------------------------------------------------------------------- the corpus

#: What each corpus drawing must do: ("plans", number of contours) or ("refused", text of the reason).
CORPUS_EXPECTED = {
    "ConvexAndConcaveHolesAndIslands.dxf": ("plans", 18),
    "Gear.dxf": ("refused", "branch or touch"),  # dimension text and leaders drawn as polylines meet the part
    "InwardArcBox.dxf": ("plans", 1),
    "Minimal-intersection-two-squares.dxf": ("refused", "contours cross or touch at (10, 20)"),
    "Sharp-triangle.dxf": ("plans", 1),
    "SimpleHole.dxf": ("plans", 2),
    "SimpleSquare_OneDuplicateLineAtTop.dxf": ("plans", 1),
    "SingleArcs.dxf": ("refused", "open contour"),  # four separate arcs
    # The manifest says it crosses itself; as drawn, no two non-adjacent lines come within 2.1 mm.
    "SingleLinearSelfIntersection.dxf": ("plans", 1),
    "SingleSpline.dxf": ("plans", 1),
    "SquareWithCircleHoleSimpleR12.dxf": ("plans", 2),
    "SquareWithSquareHole.dxf": ("plans", 2),
    "Vesa_Mount.dxf": ("plans", 7),
    "full_ellipse.dxf": ("plans", 1),
    # The manifest says a segment is missing: read in their OCS (extrusion -Z) its arcs close both holes.
    "missing-segment.dxf": ("plans", 3),
    "square-with-open-curve.dxf": ("refused", "open contour"),
}


def corpus_dxf(name: str) -> Path:
    p = CORPUS / "dxf" / name
    if not p.is_file():
        pytest.skip(f"corpus drawing {name} not available (../shared/corpus is absent)")
    return p


def test_corpus_list_is_complete():
    folder = CORPUS / "dxf"
    if not folder.is_dir():
        pytest.skip("../shared/corpus is absent")
    assert sorted(p.name for p in folder.glob("*.dxf")) == sorted(CORPUS_EXPECTED)


@pytest.mark.parametrize("name", sorted(CORPUS_EXPECTED))
def test_corpus_drawing(name, tmp_path):
    path = corpus_dxf(name)
    what, expect = CORPUS_EXPECTED[name]
    if what == "refused":
        with pytest.raises(SourceError) as exc:
            read_dxf(path, START)
        msg = str(exc.value)
        assert expect in msg and msg.startswith(str(path)) and "#" in msg and "layer" in msg
        if "open" in expect:  # engraving: allowed when open contours are
            assert read_dxf(path, START, DrawingOptions(allow_open=True)).program.n_blocks > 0
        return
    d = read_dxf(path, START)
    assert len(d.contours) == expect and all(c.closed for c in d.contours)
    assert continuous(d.program)
    polys = [Polygon(c.poly) for c in d.contours]
    for i, outer in enumerate(polys):  # a contour is cut after everything nested in it
        assert all(j < i for j, inner in enumerate(polys) if j != i and outer.contains(inner))
    if name == "SimpleSquare_OneDuplicateLineAtTop.dxf":
        assert any("duplicate" in n for n in d.notes)
    if name == "Vesa_Mount.dxf":  # $INSUNITS = 1 (inches)
        assert np.ptp(d.program.end[:, 0]) > 25.4
    if name in ("SingleSpline.dxf", "full_ellipse.dxf", "ConvexAndConcaveHolesAndIslands.dxf"):
        assert np.any(d.program.kind == Kind.CURVE) or np.any(d.program.kind == Kind.LINE)
    assert plan_and_check(d, tmp_path) > 0
    assert math.isfinite(d.cut_length_mm)


def test_cli_plans_checks_and_refuses(tmp_path, capsys):
    from jaxcnc.cli.main import main

    machine = tmp_path / "m.toml"
    machine.write_text(machine_text(tick_hz=1000, v=200.0, a=2000.0, rapid=200.0))
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    square(msp, 0, 0, 40)
    msp.add_circle((20, 20), 4)
    part = save(doc, tmp_path, "part.dxf")
    table = tmp_path / "part.ticks"
    assert main(["plan", str(part), "-m", str(machine), "-o", str(table), "-q"]) == 0
    assert main(["check", str(table), "-m", str(machine)]) == 0
    assert "path: max deviation" in capsys.readouterr().out  # compared with the drawing, read again
    square(msp, 30, 30, 40)
    bad = save(doc, tmp_path, "bad.dxf")
    assert main(["plan", str(bad), "-m", str(machine), "-o", str(tmp_path / "b.ticks"), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"jaxcnc: error: {bad}:") and "contours cross or touch" in err and "\n" not in err


def test_cli_drawing_options_reach_the_plan_and_the_check(tmp_path, capsys):
    """--allow-open, --lead-in, --feed, --layers on the command line; `check` reads the drawing again with the
    options the header records (without them the lead-ins would not be in the program it compares with)."""
    from jaxcnc.cli.main import main

    machine = tmp_path / "m.toml"
    machine.write_text(machine_text(tick_hz=1000, v=200.0, a=2000.0, rapid=200.0))
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    square(msp, 0, 0, 40, layer="CUT")
    msp.add_circle((20, 20), 4, dxfattribs={"layer": "CUT"})
    msp.add_line((50, 0), (60, 5), dxfattribs={"layer": "MARK"})  # open: engraving only
    part = save(doc, tmp_path, "part.dxf")

    def plan(name: str, *flags: str) -> int:
        return main(["plan", str(part), "-m", str(machine), "-o", str(tmp_path / name), "-q", *flags])

    assert plan("refused.ticks") == 2
    assert "open contour" in capsys.readouterr().err
    assert plan("all.ticks", "--allow-open", "--lead-in", "2", "--feed", "50") == 0
    meta = TableFile(tmp_path / "all.ticks").header.meta
    assert meta["source_options"] == {"allow_open": True, "lead_in_mm": 2.0, "feed_mm_s": 50.0}
    capsys.readouterr()
    assert main(["check", str(tmp_path / "all.ticks"), "-m", str(machine)]) == 0
    out = capsys.readouterr().out
    assert "path: max deviation" in out and "skipped" not in out

    assert plan("cut.ticks", "--layers", "CUT", "--lead-in", "2") == 0  # the open line's layer left out
    cut = TableFile(tmp_path / "cut.ticks")
    assert cut.header.meta["source_options"]["layers"] == ["CUT"]
    assert main(["check", str(tmp_path / "cut.ticks"), "-m", str(machine)]) == 0
    assert "path: max deviation" in capsys.readouterr().out
    fast = TableFile(tmp_path / "all.ticks").header.meta["total_time_s"]
    assert plan("slow.ticks", "--allow-open", "--lead-in", "2", "--feed", "25") == 0
    assert TableFile(tmp_path / "slow.ticks").header.meta["total_time_s"] > 1.5 * fast  # the feed is used

    # a table whose header records options no front end could have been given (written by hand, as a forger
    # would): refused in one line, not a traceback
    drawing_job = plan_job(read_dxf(part, START, DrawingOptions(allow_open=True)).program, parse_machine(
        machine.read_text(), str(machine)))  # fmt: skip
    for forged, why in (
        ({"dialect": 5}, "must be a table of named options"),
        ({"layers": [1]}, "must be a table of named options"),
        ({"tol_mm": "x", "allow_open": True}, "option tol_mm = 'x': must be a finite number"),
    ):
        bad_table = write_table(drawing_job, tmp_path / "forged.ticks", progress=False, source_options=forged)
        capsys.readouterr()
        assert main(["check", str(bad_table), "-m", str(machine)]) == 2
        err = capsys.readouterr().err.strip()
        assert why in err and "\n" not in err, err

    capsys.readouterr()
    assert plan("bad.ticks", "--join-tol", "-1") == 2
    err = capsys.readouterr().err.strip()
    assert err == f"jaxcnc: error: {part}: option tol_mm = -1.0: must be > 0 and <= 1"
    gcode = tmp_path / "p.ngc"
    gcode.write_text("G1 X1 F600\nM2\n")
    assert main(["plan", str(gcode), "-m", str(machine), "-o", str(tmp_path / "g.ticks"), "--lead-in", "2"]) == 2
    assert "G-code input takes no option lead_in_mm" in capsys.readouterr().err
    plt = tmp_path / "p.plt"
    plt.write_text("IN;SP1;PU0,0;PD400,0,400,400,0,400,0,0;PU;")
    assert main(["plan", str(plt), "-m", str(machine), "-o", str(tmp_path / "h.ticks"), "--layers", "A"]) == 2
    assert "HP-GL plot file input takes no option layers" in capsys.readouterr().err
