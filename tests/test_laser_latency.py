"""Laser latency (issue 16, Deliver 3): the power channel and the laser events commanded early by the machine's
``[laser] on_delay_s``/``off_delay_s`` so that the laser's *output* burns exactly where the program says; the model,
its streaming inverse across chunks, the check, and the one-line errors where the delays cannot be met."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.errors import MachineFileError, SourceError
from jaxcnc.format import EVENT_DTYPE, EventKind, TableFile, TableWriter
from jaxcnc.jobs import check_table, plan_file
from jaxcnc.machine import parse_machine
from jaxcnc.ticks.laser import LatencyShift, commanded_power, delivered_power, reachable_power
from jaxcnc.ticks.verify_laser import check_laser
from tests.conftest import machine_text
from tests.helpers import table_of
from tests.test_raster import MACHINE as RASTER_MACHINE
from tests.test_raster import _image

SQUARE = "G0 X1\nG0 X0\n{mode} S80\nG1 X20 F1200\nG1 Y20\nG1 X0\nG1 Y0\nM5\n"  # lit from the 4th line
EMPTY_EVENTS = np.zeros(0, EVENT_DTYPE)


def delayed_machine(on_s: float, off_s: float, text: str | None = None):
    extra = f"[laser]\non_delay_s = {on_s}\noff_delay_s = {off_s}\n"
    return parse_machine((text or machine_text()) + extra, "delayed.toml")


def output_of(table: TableFile, d_on: int, d_off: int) -> np.ndarray:
    """What the laser emits at each tick of the table (and ``max(d_on, d_off)`` ticks after it) under the model."""
    hi = max(d_on, d_off)
    c = np.r_[np.zeros(hi), table.read_power(0, table.n_rows), np.zeros(2 * hi)].astype(np.float32)
    return delivered_power(c, d_on, d_off)


def _full(x: np.ndarray, d_on: int, d_off: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The command, its output and the reachable output of a whole wanted output ``x`` (dark around it)."""
    hi, lo, h = max(d_on, d_off), min(d_on, d_off), d_off - d_on
    c = commanded_power(np.r_[x, np.zeros(hi + 1)][lo:].astype(np.float32), d_on, d_off)[: x.size]
    y = delivered_power(np.r_[np.zeros(hi), c, np.zeros(hi + 1)].astype(np.float32), d_on, d_off)
    r = x if h <= 0 else reachable_power(np.r_[np.zeros(h + 1), x, np.zeros(h + 1)].astype(np.float32), d_on, d_off)
    return c, y, np.asarray(r)[: x.size]


@st.composite
def outputs(draw):
    d_on, d_off = draw(st.integers(0, 6)), draw(st.integers(0, 6))
    runs = draw(st.lists(st.tuples(st.integers(1, 12), st.integers(1, 12)), min_size=0, max_size=8))
    x = [0.0] * draw(st.integers(0, 9))
    for gap, length in runs:
        x += [draw(st.floats(0.0625, 1.0, width=32)) for _ in range(length)] + [0.0] * gap
    x += [0.0] * draw(st.integers(0, 3))
    cuts = draw(st.lists(st.integers(1, 20), min_size=1, max_size=40))
    return d_on, d_off, np.array(x, np.float32), cuts


@settings(max_examples=400, deadline=None)
@given(outputs())
def test_streaming_command_inverts_the_laser_model(case):
    """Pushed in arbitrary chunks, the command equals the whole-array inverse; the model turns it back into the
    wanted output (its reachable form) with every burn starting and ending on the wanted tick; where that is
    impossible (a burn before tick d_on, a burn or a gap too short) it raises instead."""
    d_on, d_off, x, cuts = case
    shift = LatencyShift(d_on, d_off, x.size, EMPTY_EVENTS, "prog.nc", 1e4)
    lit = np.r_[0, (x > 0).astype(int), 0]
    rise, fall = np.flatnonzero(np.diff(lit) == 1), np.flatnonzero(np.diff(lit) == -1)
    h = d_off - d_on
    possible = (rise.size == 0 or rise[0] >= d_on) and np.all(fall - rise > h) and np.all(rise[1:] - fall[:-1] > -h)
    parts, i, k = [], 0, 0
    try:
        while i < x.size:
            n = cuts[k % len(cuts)]
            parts.append(shift.push(x[i : i + n]))
            i, k = i + n, k + 1
        parts.append(shift.finish())
    except SourceError as e:
        assert not possible, str(e)
        assert str(e).startswith("prog.nc: laser latency: ")
        return
    assert possible
    c = np.concatenate(parts)
    want_c, y, reach = _full(x, d_on, d_off)
    np.testing.assert_array_equal(c, want_c)
    np.testing.assert_array_equal(y[: x.size] > 0, x > 0)  # the burn exactly where wanted
    assert not y[x.size :].any()
    np.testing.assert_array_equal(y[: x.size], reach)
    if h <= 0:
        np.testing.assert_array_equal(y[: x.size], x)  # no hold: the wanted output itself
    if rise.size:
        assert np.flatnonzero(c > 0)[0] == rise[0] - d_on  # commanded on d_on ticks early


@pytest.mark.parametrize("mode", ["M3", "M4"])
@pytest.mark.parametrize("on_s,off_s", [(0.0005, 0.0002), (0.0002, 0.0007), (0.0003, 0.0003)])
def test_contour_burns_where_the_program_says(tmp_path, mode, on_s, off_s):
    """M3 and M4 on a square with delays: the table commands early, the model's output starts and ends on the ticks
    the zero-latency table burns, equal to it (M4 with off > on: the last off - on ticks held), and check agrees."""
    m = delayed_machine(on_s, off_s)
    d_on, d_off = m.laser.delay_ticks(m.tick_hz)
    prog = SQUARE.format(mode=mode)
    _, table, meas = table_of(prog, m, tmp_path, "late.ticks")
    _, plain, _ = table_of(prog, delayed_machine(0, 0), tmp_path, "plain.ticks")
    assert meas.ok, meas.violations[:3]
    assert table.header.meta["laser_delay_ticks"] == [d_on, d_off]
    want = plain.read_power(0, plain.n_rows)
    y = output_of(table, d_on, d_off)
    lit = np.flatnonzero(want > 0)
    np.testing.assert_array_equal(np.flatnonzero(y > 0), lit)  # burn starts and ends at the programmed ticks
    cmd = np.flatnonzero(table.read_power(0, table.n_rows) > 0)
    assert (cmd[0], cmd[-1]) == (lit[0] - d_on, lit[-1] - d_off)  # commanded that much earlier
    las = table.events[table.events["kind"] == EventKind.LASER]
    plain_las = plain.events[plain.events["kind"] == EventKind.LASER]
    np.testing.assert_array_equal(las["tick"], plain_las["tick"] - np.where(plain_las["value"] > 0, d_on, d_off))
    lc = check_laser(table, m)
    assert lc.violations == [] and lc.max_power_error < 1e-4 and lc.delay_ticks == (d_on, d_off)
    if mode == "M3" or d_off <= d_on:
        np.testing.assert_allclose(y[: want.size], want, rtol=0, atol=1e-5)
        assert lc.max_hold_error < 1e-5
    else:  # M4 slows into the last corner: the held tail is off by a little, and only there
        diff = np.flatnonzero(np.abs(y[: want.size] - want) > 1e-5)
        assert diff.size and diff.min() >= lit[-1] + 1 - (d_off - d_on)
        assert 0 < lc.max_hold_error < 0.1


def test_check_refuses_a_table_commanded_for_other_delays(tmp_path):
    """The same table checked against the machine without latency, and a table whose channel is not early."""
    m = delayed_machine(0.0005, 0.0002)
    _, table, _ = table_of(SQUARE.format(mode="M3"), m, tmp_path, "late.ticks")
    lc = check_laser(table, delayed_machine(0, 0))
    assert any("commanded for laser delays of [5, 2] ticks" in str(v) for v in lc.violations)
    _, plain, _ = table_of(SQUARE.format(mode="M3"), delayed_machine(0, 0), tmp_path, "plain.ticks")
    h = plain.header
    forged = tmp_path / "forged.ticks"
    meta = {**h.meta, "laser_delay_ticks": [5, 2]}  # events commanded early, but the channel is the programmed burn
    with TableWriter(
        forged, axes=h.axes, tick_hz=h.tick_hz, discrete_mm=h.discrete_mm, n_rows=h.n_rows, meta=meta, power=True
    ) as w:
        w.write(np.array(plain.positions), np.array(plain.fine), plain.read_power(0, h.n_rows))
        w.events = table.events
    lc = check_laser(TableFile(forged), m)
    bad = [v for v in lc.violations if "power differs" in str(v)]
    assert bad and bad[0].first_tick <= int(np.flatnonzero(plain.power > 0)[0]) + 5  # the late start is named


def test_raster_with_delays_burns_each_pixel(tmp_path):
    """A raster image with on 0.5 ms / off 0.2 ms: check passes (lit only at the feed, every pixel's energy) and
    the output equals the zero-latency table's channel tick for tick."""
    late, plain = tmp_path / "late.toml", tmp_path / "plain.toml"
    late.write_text(RASTER_MACHINE + "[laser]\non_delay_s = 0.0005\noff_delay_s = 0.0002\n")
    plain.write_text(RASTER_MACHINE)
    img = _image(tmp_path)
    opts = {"pixel_mm": 0.1, "feed_mm_s": 50}
    plan_file(img, late, tmp_path / "late.ticks", input_options=opts, progress=False)
    plan_file(img, plain, tmp_path / "plain.ticks", input_options=opts, progress=False)
    table, meas = check_table(tmp_path / "late.ticks", late)
    assert meas.violations == []
    assert meas.laser.pixels is not None and meas.laser.pixels.n_bad == 0 and meas.laser.max_speed_deviation < 1e-6
    want = TableFile(tmp_path / "plain.ticks").read_power(0, table.n_rows)
    y = output_of(table, 5, 2)
    np.testing.assert_array_equal(y[: want.size], want)
    assert not np.array_equal(table.read_power(0, table.n_rows), want)  # the channel itself is early


@pytest.mark.parametrize(
    "on_s,off_s,prog,line,needle",
    [
        (0.0005, 0, "M3 S10\nG1 X5 F600\nM5\n", 2, "must be switched on 500 µs"),  # lit from tick 0
        (0.0002, 0.001, "G0 X1\nM3 S10\nG4 P0.0005\nM5\nG4 P0.01\n", 3, "shorter than off_delay_s - on_delay_s"),
        (0.001, 0.0002, "G0 X1\nM3 S10\nG4 P0.01\nM5\nG4 P0.0003\nM3\nG4 P0.01\nM5\n", 7, "a dark gap of"),
    ],
)
def test_unreachable_burns_are_one_line_errors(tmp_path, on_s, off_s, prog, line, needle):
    with pytest.raises(SourceError) as e:
        table_of(prog, delayed_machine(on_s, off_s), tmp_path)
    assert e.value.line == line and needle in str(e.value) and "\n" not in str(e.value)
    assert not list(tmp_path.glob("*.part"))  # nothing half-written left behind


@pytest.mark.parametrize(
    "extra,needle",
    [("on_delay_s = 2\n", "ms?"), ("off_delay_s = -0.001\n", "positive finite"), ("on_delay_s = nan\n", "finite")],
)
def test_bad_delay_keys(extra, needle):
    with pytest.raises(MachineFileError, match="laser.*delay_s") as e:
        parse_machine(machine_text() + "[laser]\n" + extra, "m.toml")
    assert needle in str(e.value)
