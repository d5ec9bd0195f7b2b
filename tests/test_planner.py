"""The look-ahead planner: exact passes, analytic times, constant feed, limits at every tick."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxcnc.planners import planner_names
from jaxcnc.planners.lookahead import lookahead
from tests.conftest import make_machine
from tests.helpers import plan_text, span_segments, table_of


def _sequential_lookahead(cap: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """The classic two-loop planner (backward then forward), as a reference."""
    x = cap.astype(float).copy()
    for k in range(len(x) - 2, -1, -1):
        x[k] = min(x[k], x[k + 1] + delta[k])
    for k in range(1, len(x)):
        x[k] = min(x[k], x[k - 1] + delta[k - 1])
    return x


@settings(max_examples=50, deadline=None)
@given(st.integers(1, 300), st.integers(0, 2**32 - 1))
def test_scan_lookahead_equals_sequential(n, seed):
    rng = np.random.default_rng(seed)
    cap = rng.uniform(0, 1e4, n + 1) * (rng.random(n + 1) > 0.2)
    cap[0] = cap[-1] = 0
    delta = rng.uniform(0, 2e3, n) * (rng.random(n) > 0.1)
    got = np.asarray(lookahead(jnp.asarray(cap), jnp.asarray(delta)))
    ref = _sequential_lookahead(cap, delta)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-9)
    # the result is admissible: under the caps and reachable in both directions
    assert np.all(got <= cap + 1e-9)
    assert np.all(np.abs(np.diff(got)) <= delta + 1e-9 * (1 + delta))


def test_registry_has_lookahead():
    assert "lookahead" in planner_names()


@pytest.mark.parametrize(
    ("length", "feed", "a"),
    [
        (100.0, 50.0, 1000.0),  # trapezoid
        (1.0, 50.0, 1000.0),  # triangle: the feed is never reached
        (37.3, 99.0, 250.0),
        (0.05, 10.0, 3000.0),
    ],
)
def test_line_rest_to_rest_takes_analytic_time(tmp_path, length, feed, a):
    m = make_machine(a=a)
    job = plan_text(f"G1 X{length} F{feed * 60}\n", m)
    if length >= feed**2 / a:
        t_an = length / feed + feed / a
    else:
        t_an = 2 * math.sqrt(length / a)
    assert abs(job.plan.total_time_s - t_an) <= 1 / m.tick_hz + 1e-12
    _, table, meas = table_of(f"G1 X{length} F{feed * 60}\n", m, tmp_path)
    assert meas.ok, meas.violations
    assert table.positions[-1, 0] == round(length / m.discrete_mm)


def test_diagonal_line_couples_axis_limits():
    # 3-4-5 line: x moves 0.6 of the path, y 0.8; y's limits bind: v <= 100/0.8, a <= 1000/0.8
    m = make_machine(v=100, a=1000)
    job = plan_text("G1 X300 Y400 F60000\n", m)
    v, a = 100 / 0.8, 1000 / 0.8
    assert abs(job.plan.total_time_s - (500 / v + v / a)) <= 1e-4 + 1e-12


def test_full_circle_keeps_feed_within_0_1_percent(tmp_path):
    m = make_machine(v=200, a=2000)
    feed, r = 60.0, 10.0
    job, table, meas = table_of(f"G0 X{r} Y0\nG3 X{r} Y0 I{-r} J0 F{feed * 60}\nG0 X0 Y0\n", m, tmp_path)
    assert meas.ok, meas.violations
    plan = job.plan
    arc = span_segments(job, 2)
    t0, t1 = plan.group_tick[arc[0]], plan.group_tick[arc[-1] + 1]  # the circle's ticks, rest to rest
    p = table.exact_mm(t0, t1 + 1)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) * m.tick_hz
    ramp = int(math.ceil(2 * feed / (0.5 * 2000) * m.tick_hz))  # generous: ramps use ≥ half of a_max
    steady = speed[ramp:-ramp]
    assert steady.size > 0.7 * speed.size
    assert np.max(np.abs(steady - feed)) / feed < 1e-3
    # every tick on the circle is on the circle, to a thousandth of a discrete
    np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), r, atol=1e-6)


def test_chord_error_at_the_tick_rate(tmp_path):
    # small radius, fast feed, slow ticks: the chord limit binds
    m = make_machine(tick_hz=1000, v=500, a=1e5, rapid=500)
    r, tol = 0.5, 0.001
    job, table, meas = table_of(f"G0 X{r} Y0\nG3 X{r} Y0 I{-r} J0 F{400 * 60}\nG0 X0 Y0\n", m, tmp_path)
    assert meas.ok, meas.violations
    arc = span_segments(job, 2)
    p = table.exact_mm(job.plan.group_tick[arc[0]], job.plan.group_tick[arc[-1] + 1] + 1)[:, :2]
    mid = (p[1:] + p[:-1]) / 2
    sagitta = r - np.hypot(mid[:, 0], mid[:, 1])
    assert sagitta.max() <= tol * (1 + 1e-6)
    assert sagitta.max() > 0.9 * tol  # and the limit is used, not avoided by crawling


@pytest.mark.parametrize("planner", ["topp", "lookahead"])
def test_centripetal_acceleration_stays_within_axis_limits(tmp_path, planner):
    # tight circle at a feed the centripetal limit must cut down
    m = make_machine(v=500, a=500, rapid=500)
    r = 2.0
    job, table, meas = table_of(f"G0 X{r}\nG3 X{r} Y0 I{-r} J0 F{400 * 60}\nG0 X0\n", m, tmp_path, planner=planner)
    assert meas.ok, meas.violations
    v_top = max(job.plan.vp[span_segments(job, 2)])
    if planner == "topp":
        # per axis |K_i| v² ≤ a: where the normal points along an axis v² ≤ a r; between, both
        # axes share the centripetal load and the circle is driven faster (v² up to √2 a r)
        assert math.sqrt(500 * r) * 1.05 < v_top <= math.sqrt(2**0.5 * 500 * r)
        p = table.exact_mm()
        top = np.argmax(p[:, 1])  # y = r: the normal points along -y
        v_top_point = np.hypot(*(p[top + 1, :2] - p[top - 1, :2])) / 2 * m.tick_hz
        assert v_top_point == pytest.approx(math.sqrt(500 * r), rel=3e-3)
        assert max(meas.max_abs_a.values()) > 0.99 * 500
    else:
        # the span-constant planner keeps 1/√2 of the budget for the centripetal part
        assert v_top == pytest.approx(math.sqrt(2**-0.5 * 500 * r), rel=1e-3)
        assert max(meas.max_abs_a.values()) > 0.6 * 500


def test_corners_stop_tangent_junctions_do_not(tmp_path):
    m = make_machine()
    job = plan_text("G1 X10 F3000\nG1 X20\nG1 X20 Y10\nG2 X30 Y20 I10 J0\nG1 X40\n", m)
    v_at_node = np.concatenate([job.plan.v0[job.plan.span_first_segment(len(job.spans))], [0.0]])
    # nodes: 0 start | 1 collinear | 2 90° corner | 3 tangent line->arc (y up) | ... | arc->line tangent | end
    assert v_at_node[1] > 40  # collinear: no stop
    assert v_at_node[2] == 0.0  # corner: exact stop
    assert v_at_node[3] > 40  # tangent line -> arc
    assert v_at_node[-2] > 40  # tangent arc -> line


_STEP = st.tuples(st.sampled_from(["G1", "G2", "G3", "G0"]), st.floats(-40, 40), st.floats(-40, 40), st.floats(5, 200))


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
)
@given(
    steps=st.lists(_STEP, min_size=1, max_size=12),
    a=st.floats(100, 5000),
    v=st.floats(10, 300),
    tick_hz=st.sampled_from([1000, 4000, 10000]),
)
def test_random_programs_hold_every_limit_at_every_tick(tmp_path, steps, a, v, tick_hz):
    m = make_machine(tick_hz=tick_hz, v=v, a=a, a_y=a * 1.3, rapid=v)
    lines, pos = [], (0.0, 0.0)
    for word, x, y, feed in steps:
        x, y = round(x, 3), round(y, 3)
        if (x, y) == pos:
            continue
        chord = math.dist((x, y), pos)
        arc = f" R{chord * 0.75:.4f}" if word in ("G2", "G3") else ""
        lines.append(f"{word} X{x:.3f} Y{y:.3f}{arc} F{feed * 60:.1f}")
        pos = (x, y)
    if not lines:
        return
    job, table, meas = table_of("\n".join(lines) + "\n", m, tmp_path)
    assert meas.ok, [str(x) for x in meas.violations[:5]]
    # blocks that end at rest end on their programmed point, to the discrete
    q = m.discrete_mm
    ends_at_rest = np.flatnonzero(job.plan.v1 == 0)
    nxt = np.append(job.plan.first_tick, job.plan.n_ticks)[ends_at_rest + 1]
    seg_end = job.plan.s_start[ends_at_rest] + job.plan.length[ends_at_rest]
    at_span_end = np.isclose(seg_end, job.spans.length[job.plan.span[ends_at_rest]], rtol=0, atol=1e-12)
    assert at_span_end.all()  # rests happen at span ends only
    expected = np.round(job.spans.end[job.plan.span[ends_at_rest]][:, :2] / q).astype(np.int64)
    np.testing.assert_array_equal(table.positions[nxt][:, :2], expected)


def test_time_law_s_of_t_and_its_speed():
    from jaxcnc.planners.timelaw import sample_plan

    m = make_machine(v=200, a=2000)
    job = plan_text("G1 X30 F6000\nG3 X40 Y10 I0 J10\nG1 Y40\nG4 P0.1\nG1 X0 Y0\n", m)
    ticks = np.arange(job.plan.n_ticks + 1)
    seg, s, v = sample_plan(job.plan, ticks)
    assert s[0] == 0.0 and s[-1] == pytest.approx(job.path_length_mm, abs=1e-9)
    assert np.all(np.diff(s) >= -1e-12)  # never goes backwards
    # the speed is the derivative of s: mean speed over each tick equals the mean of v at its ends
    ds = np.diff(s) * m.tick_hz
    np.testing.assert_allclose(ds, (v[1:] + v[:-1]) / 2, atol=2000 / m.tick_hz)
    assert v.max() == pytest.approx(100.0, rel=1e-4)  # F6000 = 100 mm/s, reached on the long lines
    assert np.all(v >= 0)


def test_a_plan_of_motion_in_zero_time_is_refused():
    """A straight quadratic NURBS (control points evenly spaced on a line) once planned in zero time with
    topp: the one-row table stayed at the start, the program ended 10 mm away, and the table check saw no
    motion at all. plan_job refuses such a time law whatever the planner (known topp defect, see issue 13)."""
    from jaxcnc.errors import PlanningError
    from jaxcnc.io.curves import curves_program
    from jaxcnc.planners import plan_job

    pts = np.array([[0.0, 0, 0], [5, 0, 0], [10, 0, 0]])
    knots = np.r_[np.zeros(3), np.ones(3)]
    prog = curves_program([(2, pts, np.ones(3), knots)], 50.0, start=pts[0])
    machine = make_machine()
    assert plan_job(prog, machine, "lookahead").plan.total_time_s > 0.2  # 10 mm at 50 mm/s at least
    try:
        job = plan_job(prog, machine, "topp")
    except PlanningError as exc:
        assert "in zero time" in str(exc)
    else:  # the defect fixed: then the plan must take the time the motion needs
        assert job.plan.total_time_s > 0.2
