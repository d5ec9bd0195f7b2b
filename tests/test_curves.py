"""B-spline / NURBS geometry: exact decomposition, certified length, a path parameter within 1e-6 of arc length,
curvature, constant feed."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.interpolate import BSpline

from jaxcnc.geometry import SpanKind, build_spans
from jaxcnc.geometry.bezier import homogeneous_power, nurbs_to_bezier
from jaxcnc.geometry.evaluate import evaluate
from jaxcnc.io.curves import curves_program, read_curves_json
from jaxcnc.planners import sample_plan
from jaxcnc.program import make_curve_table
from tests.conftest import CORPUS, make_machine
from tests.helpers import at_s

BUTTERFLY = CORPUS / "nurbs" / "butterfly_deg3_iges.json"
BUTTERFLY_LENGTH = 382.8603111  # mm, the documented length of the butterfly


def butterfly():
    if not BUTTERFLY.is_file():
        pytest.skip("corpus butterfly not available (../shared/corpus is absent)")
    return read_curves_json(BUTTERFLY)[0]


def random_nurbs(degree: int, n: int, seed: int, closed_knots: bool = False):
    rng = np.random.default_rng(seed)
    pts = np.cumsum(rng.normal(0, 10, (n, 3)), axis=0) + 100
    w = rng.uniform(0.3, 3.0, n)
    inner = np.sort(rng.uniform(0, 1, n - degree - 1))
    knots = np.concatenate([np.zeros(degree + 1), inner, np.ones(degree + 1)])
    return degree, pts, w, knots


def scipy_eval(curve, t):
    p, pts, w, knots = curve
    pts3 = np.c_[pts, np.zeros(len(pts))] if pts.shape[1] == 2 else pts
    h = BSpline(knots, np.c_[pts3 * w[:, None], w], p)(t)
    return h[:, :3] / h[:, 3:]


def scipy_length(curve):
    p, pts, w, knots = curve
    pts3 = np.c_[pts, np.zeros(len(pts))] if pts.shape[1] == 2 else pts
    spl = BSpline(knots, np.c_[pts3 * w[:, None], w], p)
    d = spl.derivative()

    def speed(t):
        h, h1 = spl(t), d(t)
        x = h[:3] / h[3]
        return np.linalg.norm((h1[:3] - x * h1[3]) / h[3])

    brk = np.unique(knots)
    return sum(
        quad(speed, a, b, epsabs=1e-14, epsrel=1e-14, limit=200)[0] for a, b in zip(brk[:-1], brk[1:], strict=False)
    )


def bezier_eval_vs_scipy(curve, n=4000, seed=0):
    p, pts, w, knots = curve
    pts3 = np.c_[pts, np.zeros(len(pts))] if pts.shape[1] == 2 else pts
    bp, bw, iv = nurbs_to_bezier(p, pts3, w, knots)
    coeffs = homogeneous_power(bp, bw, bp[:, 0])
    rng = np.random.default_rng(seed)
    k = rng.integers(0, len(iv), n)
    u = rng.random(n)
    (mine,) = evaluate(jnp.asarray(coeffs[k]), jnp.asarray(bp[k, 0]), jnp.asarray(u))
    ref = scipy_eval(curve, iv[k, 0] + (iv[k, 1] - iv[k, 0]) * u)
    return float(np.max(np.abs(np.asarray(mine) - ref)))


def test_butterfly_evaluation_equals_scipy():
    assert bezier_eval_vs_scipy(butterfly()) <= 1e-12


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5, 7])
def test_random_nurbs_evaluation_equals_scipy(degree):
    curve = random_nurbs(degree, 12 + degree, seed=degree)
    assert bezier_eval_vs_scipy(curve) <= 1e-11  # coordinates up to ~200 mm


def test_butterfly_length_is_certified():
    curve = butterfly()
    sp = build_spans(curves_program([curve], 10.0, start=(*curve[1][0], 0.0)))
    curve_spans = sp.kind == SpanKind.CURVE
    length = sp.length[curve_spans].sum()
    assert abs(length - BUTTERFLY_LENGTH) <= 1e-6
    assert abs(length - scipy_length(curve)) <= 1e-8
    assert np.all(sp.polys.length_err <= 1e-9)


def test_random_nurbs_length_matches_quad():
    curve = random_nurbs(5, 20, seed=3)
    sp = build_spans(curves_program([curve], 10.0, start=curve[1][0]))
    assert sp.length[sp.kind == SpanKind.CURVE].sum() == pytest.approx(scipy_length(curve), abs=1e-8)


SQUARE = np.array([[30, 0], [30, 30], [0, 30], [-30, 30], [-30, 0], [-30, -30], [0, -30], [30, -30], [30, 0]], float)
CIRCLE_KNOTS = np.array([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1])


@pytest.mark.parametrize(
    ("corner_w", "radius_tol", "length_tol"),
    [
        (0.70710678118654757, 1e-9, 1e-9),  # exact weights: the circle itself
        (0.707, 1e-3, 1e-2),  # rounded weights as the documents write them: within 1 µm of the circle
    ],
)
def test_nurbs_circle_of_the_documents(corner_w, radius_tol, length_tol):
    w = np.where(np.arange(9) % 2 == 1, corner_w, 1.0)
    curve = (2, SQUARE, w, CIRCLE_KNOTS)
    sp = build_spans(curves_program([curve], 10.0, start=(30.0, 0.0, 0.0)))
    c = sp.kind == SpanKind.CURVE
    assert sp.length[c].sum() == pytest.approx(2 * np.pi * 30, abs=length_tol)
    idx = np.repeat(np.flatnonzero(c), 200)
    (p,) = at_s(sp, idx, np.tile(np.linspace(0, 1, 200), int(c.sum())) * sp.length[idx])
    r = np.hypot(*np.asarray(p)[:, :2].T)
    assert np.max(np.abs(r - 30)) <= radius_tol
    if corner_w > 0.7071:
        np.testing.assert_allclose(sp.kappa_max[c], 1 / 30, rtol=1e-9)


def test_path_parameter_is_arc_length_within_speed_tol():
    """The point at path parameter s of a curve lies where true arc length s reaches (scipy, independently)."""
    from scipy.optimize import brentq

    from jaxcnc.geometry.poly import SPEED_TOL

    curve = random_nurbs(3, 15, seed=7)
    p, pts, w, knots = curve
    sp = build_spans(curves_program([curve], 10.0, start=curve[1][0]))
    spl = BSpline(knots, np.c_[pts * w[:, None], w], p)
    d = spl.derivative()

    def speed(t):
        h, h1 = spl(t), d(t)
        return np.linalg.norm((h1[:3] - h[:3] / h[3] * h1[3]) / h[3])

    c = np.flatnonzero(sp.kind == SpanKind.CURVE)
    s_glob = np.concatenate([[0.0], np.cumsum(sp.length[c])])
    rng = np.random.default_rng(0)
    for _ in range(40):
        k = int(rng.integers(0, c.size))
        s = rng.random() * sp.length[c[k]]
        target = s_glob[k] + s
        t = brentq(lambda x, y=target: quad(speed, knots[0], x, epsabs=1e-13, epsrel=1e-13, limit=400)[0] - y, 0, 1)
        (mine,) = at_s(sp, np.array([c[k]]), np.array([s]))
        miss = np.linalg.norm(mine[0] - scipy_eval(curve, np.array([t]))[0])
        assert miss <= 2 * SPEED_TOL * s + 1e-9


def test_sampled_curvature_maximum():
    curve = random_nurbs(4, 10, seed=11)
    sp = build_spans(curves_program([curve], 10.0, start=curve[1][0]))
    c = np.flatnonzero(sp.kind == SpanKind.CURVE)
    idx = np.repeat(c, 2001)
    s = np.tile(np.linspace(0, 1, 2001), c.size) * sp.length[idx]
    _, d1, d2 = at_s(sp, idx, s, order=2)
    kappa = np.linalg.norm(np.cross(d1, d2), axis=1) / np.linalg.norm(d1, axis=1) ** 3
    dense = kappa.reshape(c.size, 2001).max(axis=1)
    assert np.all(sp.kappa_max[c] <= dense * (1 + 1e-9))
    assert np.all(sp.kappa_max[c] >= 0.9 * dense)  # 33 samples on certified pieces: close to the maximum


def _steady_at_feed(job, feed: float) -> np.ndarray:
    """Mask over the middle ticks of :func:`_arc_per_tick`: the time law is at ``feed`` on all three."""
    _, _, v = sample_plan(job.plan, np.arange(job.plan.n_ticks + 1))
    at_feed = np.abs(v / feed - 1) < 1e-5  # the path parameter's speed is within 1e-6 of the tool's
    return at_feed[:-2] & at_feed[1:-1] & at_feed[2:]


def _arc_per_tick(p: np.ndarray) -> np.ndarray:
    """Path length between consecutive ticks, on the circle through each three consecutive ticks."""
    a, b, c = p[:-2], p[1:-1], p[2:]
    ab = np.linalg.norm(b - a, axis=1)
    kappa = (
        2
        * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        / np.maximum(ab * np.linalg.norm(c - b, axis=1) * np.linalg.norm(c - a, axis=1), 1e-300)
    )
    x = kappa * ab / 2
    return np.where(x > 1e-9, ab * np.arcsin(np.clip(x, 0, 1)) / np.maximum(x, 1e-300), ab)


def test_butterfly_ticks_at_constant_feed(tmp_path):
    curve = butterfly()
    feed = 2.0  # on the machine (v 100 mm/s, a 1000 mm/s²) no limit binds at this feed
    m = make_machine(v=100, a=1000)
    prog = curves_program([curve], feed, start=(*curve[1][0], 0.0))
    job, table, meas = table_of_program(prog, m, tmp_path)
    assert meas.ok, meas.violations
    assert np.all(job.plan.vp[job.spans.kind[job.plan.span] == SpanKind.CURVE] == pytest.approx(feed, rel=1e-5))
    # wherever the time law runs at the feed, the table moves the feed's arc per tick
    per_tick = _arc_per_tick(table.exact_mm())[_steady_at_feed(job, feed)]
    assert per_tick.size > 0.98 * job.plan.n_ticks
    assert np.max(per_tick / (feed / m.tick_hz) - 1) <= 3e-6  # never faster than the feed
    assert np.median(np.abs(per_tick / (feed / m.tick_hz) - 1)) <= 2e-6


def table_of_program(prog, machine, folder):
    from jaxcnc.format import TableFile
    from jaxcnc.planners import plan_job
    from jaxcnc.ticks.table import write_table
    from jaxcnc.ticks.verify import measure_table

    job = plan_job(prog, machine)
    t = TableFile(write_table(job, folder / "c.ticks", progress=False))
    return job, t, measure_table(t, machine)


def test_chain_of_line_arc_cubic_nurbs_at_constant_speed(tmp_path):
    """The documents' validation: a smooth chain of line, arc, cubic and NURBS at constant speed."""
    feed = 20.0
    # line along +x to (10, 0); quarter arc to (20, 10) (tangent +y); cubic continuing +y; NURBS onward
    cubic = (
        3,
        np.array([[20, 10], [20, 15], [25, 20], [30, 20]], float),
        np.ones(4),
        np.array([0, 0, 0, 0, 1, 1, 1, 1], float),
    )
    nurbs = (
        2,
        np.array([[30, 20], [35, 20], [40, 25], [40, 30]], float),
        np.array([1, 0.9, 1.3, 1]),
        np.array([0, 0, 0, 0.5, 1, 1, 1], float),
    )
    m = make_machine(v=100, a=50000)
    base = curves_program([cubic, nurbs], feed, start=(20.0, 10.0, 0.0))
    # prepend a line and an arc by G-code semantics: build the rows by hand
    from jaxcnc.program import Kind, program_from_columns

    n0 = len(base)
    cols = {
        k: np.concatenate([v_head, getattr(base, k)])
        for k, v_head in {
            "kind": np.array([Kind.LINE, Kind.ARC]),
            "start": np.array([[0, 0, 0], [10, 0, 0]], float),
            "end": np.array([[10, 0, 0], [20, 10, 0]], float),
            "center": np.array([[np.nan] * 3, [10, 10, 0]]),
            "turn": np.array([0, 1]),
            "feed": np.array([feed, feed]),
            "curve": np.array([-1, -1]),
            "line": np.array([1, 2]),
            "rapid": np.array([False, False]),
            "stop_before": np.array([True, False]),
        }.items()
    }
    cols["line"][2:] += 2
    cols["stop_before"][2] = False
    prog = program_from_columns(file="chain", curves=base.curves, **cols)
    assert len(prog) == n0 + 2
    job, table, meas = table_of_program(prog, m, tmp_path)
    assert meas.ok, meas.violations
    rest = np.flatnonzero(job.plan.v0 == 0)
    assert list(rest) == [0]  # stopped only at the start: every junction is passed at speed
    per_tick = _arc_per_tick(table.exact_mm())[_steady_at_feed(job, feed)]
    assert per_tick.size > 0.95 * job.plan.n_ticks
    assert np.max(per_tick / (feed / m.tick_hz) - 1) <= 3e-6  # never faster than the feed
    assert np.median(np.abs(per_tick / (feed / m.tick_hz) - 1)) <= 2e-6


@pytest.mark.parametrize(
    ("curve", "needle"),
    [
        ((3, np.zeros((3, 2)), np.ones(3), np.zeros(7)), "at least 4 control points"),
        ((2, np.zeros((4, 2)), np.ones(4), np.zeros(6)), "needs 7 knots"),
        ((2, np.zeros((4, 2)), -np.ones(4), np.zeros(7)), "positive finite weights"),
        ((2, np.zeros((4, 2)), np.ones(4), np.array([0, 0, 0, 2, 1, 1, 1.0])), "must not decrease"),
        ((2, np.zeros((4, 2)), np.ones(4), np.array([0, 0, 0.5, 0.5, 1, 1, 1.0])), "clamped"),
        ((9, np.zeros((12, 2)), np.ones(12), np.zeros(22)), "outside 1..7"),
    ],
)
def test_bad_curve_data(curve, needle):
    with pytest.raises(ValueError, match=needle):
        make_curve_table([curve])


def test_curve_file_errors(tmp_path):
    from jaxcnc.errors import SourceError

    f = tmp_path / "c.json"
    f.write_text('{"degree": 2, "control_points": [[0, 0], [1, 1]], "knots": [0, 0, 0, 1, 1]}')
    with pytest.raises(SourceError, match="at least 3 control points"):
        read_curves_json(f)
    f.write_text("{not json")
    with pytest.raises(SourceError, match="cannot read curve file"):
        read_curves_json(f)


def test_length_error_bound_reported():
    # a near-cusp (a loop that almost stops): subdivision keeps the bound and the fits
    pts = np.array([[0, 0], [10, 10], [0, 10], [10, 0]], float)
    curve = (3, pts, np.ones(4), np.array([0, 0, 0, 0, 1, 1, 1, 1], float))
    sp = build_spans(curves_program([curve], 10.0))
    c = sp.kind == SpanKind.CURVE
    assert sp.length[c].sum() == pytest.approx(scipy_length(curve), abs=1e-8)
    assert np.all(sp.polys.length_err <= 1e-9)
    assert math.isfinite(sp.kappa_max[c].max())


@pytest.mark.parametrize(("turns_deg", "rise", "cw"), [(360.0, 2.0, False), (90.0, 0.5, True), (270.0, -7.0, False)])
def test_helix_is_exact(tmp_path, turns_deg, rise, cw):
    from jaxcnc.gcode import parse_gcode

    r = 5.0
    a1 = np.radians(turns_deg) * (-1 if cw else 1)
    end = (r * np.cos(a1), r * np.sin(a1))
    text = f"G0 X{r} Y0 Z0\n{'G2' if cw else 'G3'} X{end[0]:.12f} Y{end[1]:.12f} Z{rise} I{-r} J0 F600\n"
    prog = parse_gcode(text, "helix.ngc")
    sp = build_spans(prog)
    (k,) = np.flatnonzero(sp.kind == SpanKind.ARC)
    s = np.linspace(0, sp.length[k], 400)
    (p,) = at_s(sp, np.full(400, k), s)
    np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), r, rtol=1e-13)  # on the cylinder
    ang = np.unwrap(np.arctan2(p[:, 1], p[:, 0]))
    np.testing.assert_allclose(p[:, 2], rise * ang / a1, atol=1e-9)  # rising in proportion to the angle
    assert sp.length[k] == pytest.approx(np.hypot(r * abs(a1), rise), rel=1e-12)
    job, table, meas = table_of_program(prog, make_machine(), tmp_path)
    assert meas.ok, meas.violations
    np.testing.assert_array_equal(table.positions[-1], np.round(np.array([*end, rise]) / 1e-3))
