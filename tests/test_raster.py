"""Raster images (issue 16): planned line by line with overscan, power per tick from the image, checked."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from jaxcnc.errors import JaxcncError
from jaxcnc.format import TableFile, TableWriter
from jaxcnc.front_ends import front_end_for
from jaxcnc.io.image import RasterOptions, gcode_per_pixel, raster_job
from jaxcnc.jobs import check_table, plan_file
from jaxcnc.machine import load_machine

MACHINE = """[machine]
name = "engraver"
tick_hz = 10000
discrete_mm = 0.001
[axes.x]
v_max = 200
a_max = 3000
min = 0
max = 300
[axes.y]
v_max = 200
a_max = 3000
min = 0
max = 300
[path]
feed = 50
rapid = 200
"""


@pytest.fixture
def machine_path(tmp_path):
    p = tmp_path / "engraver.toml"
    p.write_text(MACHINE)
    return p


def _image(tmp_path, name="img.png"):
    """A 20 x 30 grey ramp block with a lone black pixel and white margins."""
    a = np.full((20, 30), 255, np.uint8)
    a[5:15, 8:25] = np.linspace(0, 250, 17, dtype=np.uint8)[None, :]
    a[10, 3] = 0
    path = tmp_path / name
    Image.fromarray(a).save(path)
    return path


def test_ticks_on_a_pixel_edge_burn_the_pixel_the_check_reads(tmp_path, machine_path):
    """At 50 mm/s and 10 kHz a tick moves 5 µm and a pixel is 20 ticks: tick midpoints fall on pixel edges (to the
    last bits). The writer takes each tick's pixel from the positions as the table holds them — what the check
    reads — so the two agree on every edge (from float positions they disagreed on 131 ticks of this job)."""
    img = _image(tmp_path)
    out = tmp_path / "edge.ticks"
    plan_file(img, machine_path, out, input_options={"pixel_mm": 0.1, "feed_mm_s": 50}, progress=False)
    table, meas = check_table(out, machine_path)
    p = table.exact_mm()
    mid_x = (p[:-1, 0] + p[1:, 0]) / 2 - table.header.meta["raster"]["origin_mm"][0]
    off_edge = np.abs(mid_x / 0.1 - np.round(mid_x / 0.1))
    lit = np.asarray(table.power[:-1]) > 0
    assert np.count_nonzero(lit & (off_edge < 1e-9)) > 50  # the case is exercised
    assert meas.violations == [] and meas.laser.max_power_error < 1e-6


@pytest.mark.parametrize(
    "opts",
    [
        {"pixel_mm": 0.1, "feed_mm_s": 50},
        {"pixel_mm": 0.1, "feed_mm_s": 50, "unidirectional": True},
        {"dpi": 254, "feed_mm_s": 40, "angle_deg": 90, "bidir_offset_mm": 0.03},
        {"pixel_mm": 0.1, "feed_mm_s": 50, "angle_deg": 30, "dither": "floyd-steinberg"},
    ],
)
def test_raster_plans_and_checks(tmp_path, machine_path, opts):
    img = _image(tmp_path)
    out = tmp_path / "img.ticks"
    rep = plan_file(img, machine_path, out, input_options=opts, progress=False)
    assert rep["violations"] == []
    table, meas = check_table(out, machine_path)
    assert meas.violations == []
    las = meas.laser
    assert las.constant_speed and las.n_lit > 0 and las.max_power_error < 1e-6
    assert las.max_speed_deviation < 1e-6  # lit only at the feed
    if opts.get("angle_deg", 0) % 90 == 0:
        assert las.pixels is not None and las.pixels.n_bad == 0 and las.pixels.n_pixels == 171
    assert table.header.meta["source_options"] == opts
    # the power channel is S · level: never above S, and the darkest pixel burns at S
    power = table.read_power(0, table.n_rows)
    assert power.max() == pytest.approx(1.0) and power.min() == 0.0


def test_one_program_row_per_line_not_per_pixel(tmp_path, machine_path):
    r = raster_job(_image(tmp_path), load_machine(machine_path), RasterOptions(pixel_mm=0.1, feed_mm_s=50))
    assert r.n_lines == 10  # rows 5..14; the lone pixel shares row 10; blank lines skipped
    assert len(r.program) == 4 * r.n_lines
    burn = r.program.laser != 0
    lengths = np.linalg.norm(r.program.end[burn] - r.program.start[burn], axis=1)
    # blank margins skipped: row 10 burns from column 3 to 24, the others from 8 to 24
    assert sorted(np.round(lengths, 9)) == [1.7] * 9 + [2.2]


def test_overscan_too_short_fails_the_check(tmp_path, machine_path):
    img = _image(tmp_path)
    out = tmp_path / "short.ticks"
    plan_file(img, machine_path, out, input_options={"pixel_mm": 0.1, "feed_mm_s": 50, "overscan_mm": 0.05})
    _, meas = check_table(out, machine_path)
    assert any("programmed speed" in str(v) for v in meas.violations)


def test_forged_power_fails_the_check(tmp_path, machine_path):
    """A table re-written with valid checksums but a pixel burned too long: the pixel check names it."""
    img = _image(tmp_path)
    out = tmp_path / "img.ticks"
    plan_file(img, machine_path, out, input_options={"pixel_mm": 0.1, "feed_mm_s": 50}, progress=False)
    t = TableFile(out)
    h = t.header
    power = np.array(t.power)
    lit = np.flatnonzero(power > 0)
    k = int(lit[len(lit) // 2])
    power[k : k + 3] = 0.0  # three ticks dark inside a pixel: its energy is short by three ticks
    forged = tmp_path / "forged.ticks"
    with TableWriter(
        forged, axes=h.axes, tick_hz=h.tick_hz, discrete_mm=h.discrete_mm, n_rows=h.n_rows, meta=h.meta, power=True
    ) as w:
        w.write(np.array(t.positions), np.array(t.fine), power)
        w.events = t.events
    _, meas = check_table(forged, machine_path)
    bad = [str(v) for v in meas.violations if v.quantity == "laser"]
    assert any("power differs" in v for v in bad)
    assert any("pixels" in v and "received an energy" in v for v in bad)
    assert meas.laser.pixels.n_bad >= 1


def test_source_options_refused_and_bad_values(tmp_path, machine_path):
    img = _image(tmp_path)
    m = load_machine(machine_path)
    with pytest.raises(JaxcncError, match="takes no option lead_in_mm"):
        front_end_for(img).load(img, m, lead_in_mm=2.0)
    with pytest.raises(JaxcncError, match="dither"):
        front_end_for(img).load(img, m, dither="ordered")
    with pytest.raises(JaxcncError, match="v_max"):
        front_end_for(img).load(img, m, feed_mm_s=500.0)
    blank = tmp_path / "blank.bmp"
    Image.new("L", (8, 8), 255).save(blank)
    with pytest.raises(JaxcncError, match="blank"):
        front_end_for(blank).load(blank, m)


def test_gcode_per_pixel_same_path(tmp_path, machine_path):
    r = raster_job(_image(tmp_path), load_machine(machine_path), RasterOptions(pixel_mm=0.1, feed_mm_s=50))
    text = gcode_per_pixel(r)
    assert text.count(" S") - text.count(" S0\n") >= 171  # one G1 … S… per lit pixel at least


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=300), st.sampled_from(["png", "bmp", "tif"]), st.integers(0, 60))
def test_broken_image_is_one_line_error(tmp_path, machine_path, junk, suffix, cut):
    """Truncated or corrupted images: a one-line error naming the file, never a traceback."""
    good = tmp_path / f"good.{suffix}"
    Image.fromarray(np.arange(64, dtype=np.uint8).reshape(8, 8)).save(good)
    data = good.read_bytes()
    bad = tmp_path / f"bad.{suffix}"
    bad.write_bytes(data[: len(data) * cut // 60] + junk)
    m = load_machine(machine_path)
    try:
        front_end_for(bad).load(bad, m, pixel_mm=0.1)
    except JaxcncError as exc:
        assert str(bad) in str(exc) and "\n" not in str(exc)


def test_cli_plan_check_and_broken_png(tmp_path, machine_path, capsys):
    from jaxcnc.cli.main import main

    img = _image(tmp_path)
    out = tmp_path / "cli.ticks"
    argv = ["plan", str(img), "--machine", str(machine_path), "-o", str(out), "-q", "--pixel", "0.1"]
    assert main([*argv, "--feed", "40", "--dither", "threshold", "--unidirectional"]) == 0
    assert TableFile(out).header.meta["source_options"] == {
        "pixel_mm": 0.1,
        "feed_mm_s": 40.0,
        "dither": "threshold",
        "unidirectional": True,
    }
    assert main(["check", str(out), "--machine", str(machine_path)]) == 0
    assert "raster: lit only at the feed" in capsys.readouterr().out
    bad = tmp_path / "broken.png"
    bad.write_bytes(img.read_bytes()[:60])
    assert main(["plan", str(bad), "--machine", str(machine_path), "-o", str(tmp_path / "b.ticks")]) == 2
    err = capsys.readouterr().err.strip()
    assert str(bad) in err and "\n" not in err


def test_row_fast_path_equals_sampled_lines(tmp_path, machine_path):
    """At 0° the lines are read from the grid's rows; a hair off 0° they are sampled: the same lines."""
    from jaxcnc.io.image import scan_lines

    r = raster_job(_image(tmp_path), load_machine(machine_path), RasterOptions(pixel_mm=0.1, feed_mm_s=50))
    img = r.image
    tilted = type(img)(img.levels, img.origin_mm, img.pixel_mm, 1e-12, img.power, img.feed_mm_s)
    for uni in (False, True):
        fast, sampled = scan_lines(img, uni), scan_lines(tilted, uni)
        for a, b in zip(fast, sampled, strict=True):
            np.testing.assert_allclose(a, b, atol=1e-9)
