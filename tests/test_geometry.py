"""Geometry: exact rational arcs, batched derivatives, exact lengths, closed-form u(s), extents."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.gcode import parse_gcode
from jaxcnc.geometry import SpanKind, build_spans
from jaxcnc.geometry.evaluate import evaluate
from jaxcnc.geometry.inverse import u_of_s


def spans_of(text: str):
    return build_spans(parse_gcode(text, "g.ngc"))


def span_dict(spans):
    from jaxcnc.geometry.inverse import span_arrays

    return span_arrays(spans)


def at_s(spans, idx: np.ndarray, s: np.ndarray, order: int = 0):
    u = u_of_s(span_dict(spans), jnp.asarray(idx), jnp.asarray(s))
    return u, [np.asarray(a) for a in evaluate(jnp.asarray(spans.coeffs[idx]), spans.origin[idx], u, order)]


def ev(spans, idx, u, order=0):
    return evaluate(jnp.asarray(spans.coeffs[idx]), jnp.asarray(spans.origin[idx]), jnp.asarray(u), order)


def test_arcs_split_at_90_degrees_with_exact_lengths():
    sp = spans_of("G1 X10 F60\nG3 X10 Y0 I-10 J0\nG2 X30 Y0 R10\nG3 X40 Y10 I0 J10\n")
    kinds = list(sp.kind)
    assert kinds == [SpanKind.LINE] + [SpanKind.ARC] * 4 + [SpanKind.ARC] * 2 + [SpanKind.ARC]
    np.testing.assert_allclose(sp.length[1:5].sum(), 2 * np.pi * 10, rtol=1e-15)
    np.testing.assert_allclose(sp.length[5:7].sum(), np.pi * 10, rtol=1e-15)
    np.testing.assert_allclose(sp.length[7], np.pi / 2 * 10, rtol=1e-15)
    assert np.all(sp.half_angle[sp.kind == SpanKind.ARC] <= np.pi / 4 + 1e-15)
    # consecutive spans join (end points evaluated from power-basis sums: rounding only)
    np.testing.assert_allclose(sp.start[1:], sp.end[:-1], atol=1e-13)


@settings(max_examples=60, deadline=None)
@given(
    r=st.floats(0.01, 500),
    a0=st.floats(-np.pi, np.pi),
    sweep=st.floats(0.01, 2 * np.pi - 0.01),
    cw=st.booleans(),
    cx=st.floats(-100, 100),
    cy=st.floats(-100, 100),
)
def test_arc_points_lie_on_circle_at_exact_arc_length(r, a0, sweep, cw, cx, cy):
    sgn = -1 if cw else 1
    s0 = (cx + r * np.cos(a0), cy + r * np.sin(a0))
    a1 = a0 + sgn * sweep
    e = (cx + r * np.cos(a1), cy + r * np.sin(a1))
    s0 = np.round(s0, 12)
    text = (
        f"G0 X{s0[0]:.12f} Y{s0[1]:.12f}\n{'G2' if cw else 'G3'} X{e[0]:.12f} Y{e[1]:.12f} "
        f"I{cx - s0[0]:.12f} J{cy - s0[1]:.12f} F60\n"
    )
    sp = spans_of(text)
    arcs = np.flatnonzero(sp.kind == SpanKind.ARC)
    total = sp.length[arcs].sum()
    np.testing.assert_allclose(total, r * sweep, rtol=1e-9, atol=1e-10)  # G-code written to 1e-12 mm
    # points at arc length s from the arc's start sit at angle a0 + sgn * s / r
    s_glob = np.linspace(0, total, 41)
    cum = np.concatenate([[0], np.cumsum(sp.length[arcs])])
    k = np.clip(np.searchsorted(cum, s_glob, side="right") - 1, 0, arcs.size - 1)
    _, (p,) = at_s(sp, arcs[k], s_glob - cum[k])
    ang = a0 + sgn * s_glob / r
    ref = np.stack([cx + r * np.cos(ang), cy + r * np.sin(ang)], axis=1)
    np.testing.assert_allclose(p[:, :2], ref, atol=1e-9 * max(1.0, r, abs(cx), abs(cy)))


def test_derivatives_match_analytic_circle():
    r = 7.0
    sp = spans_of(f"G1 X{r} F60\nG3 X{r} Y0 I{-r} J0\n")
    arcs = np.flatnonzero(sp.kind == SpanKind.ARC)
    idx = np.repeat(arcs, 50)
    s = np.tile(np.linspace(0, sp.length[arcs[0]], 50), arcs.size)
    u, (p, d1, d2) = at_s(sp, idx, s, order=2)
    # chain rule: dP/du = P'(s) ds/du; the tangent is perpendicular to the radius, |P'(s)| = 1
    speed_u = np.linalg.norm(d1, axis=1)
    np.testing.assert_allclose(np.einsum("ij,ij->i", d1[:, :2], p[:, :2]), 0, atol=1e-9)
    # compare with central differences in u
    h = 1e-6
    uu = np.asarray(u)
    (pp,) = ev(sp, idx, np.clip(uu + h, 0, 1))
    (pm,) = ev(sp, idx, np.clip(uu - h, 0, 1))
    inner = (uu > 2 * h) & (uu < 1 - 2 * h)
    fd1 = (np.asarray(pp) - np.asarray(pm)) / (2 * h)
    np.testing.assert_allclose(d1[inner], fd1[inner], rtol=1e-6, atol=1e-6)
    (p1,) = ev(sp, idx, np.clip(uu + 1e-4, 0, 1))
    (p0,) = ev(sp, idx, np.clip(uu - 1e-4, 0, 1))
    fd2 = (np.asarray(p1) - 2 * p + np.asarray(p0)) / 1e-8
    inner = (uu > 2e-4) & (uu < 1 - 2e-4)
    np.testing.assert_allclose(d2[inner], fd2[inner], rtol=1e-4, atol=1e-4 * np.abs(d2).max())
    # curvature |P' x P''| / |P'|^3 = 1/r everywhere on the arc
    curv = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / speed_u**3
    np.testing.assert_allclose(curv, 1 / r, rtol=1e-10)


def test_lines_are_uniform_in_u():
    sp = spans_of("G1 X3 Y4 Z12 F60\n")
    assert sp.length[0] == 13.0
    s = np.linspace(0, 13, 14)
    u, (p,) = at_s(sp, np.zeros(14, int), s)
    np.testing.assert_allclose(np.asarray(u), s / 13, rtol=1e-15)
    np.testing.assert_allclose(p, np.outer(s / 13, [3, 4, 12]), atol=1e-13)


def test_extents_are_exact():
    sp = spans_of("G0 X10 Y0\nG3 X-10 Y0 I-10 J0 F60\nG3 X10 Y0 R10\n")
    arcs = sp.kind == SpanKind.ARC
    lo, hi = sp.lo[arcs].min(axis=0), sp.hi[arcs].max(axis=0)
    np.testing.assert_allclose(lo[:2], [-10, -10], atol=1e-12)
    np.testing.assert_allclose(hi[:2], [10, 10], atol=1e-12)
    # every span's extent contains densely sampled points of it
    idx = np.repeat(np.arange(len(sp)), 200)
    s = np.tile(np.linspace(0, 1, 200), len(sp)) * sp.length[idx]
    _, (p,) = at_s(sp, idx, s)
    assert np.all(p >= sp.lo[idx] - 1e-9) and np.all(p <= sp.hi[idx] + 1e-9)


def test_points_for_dwell_and_events_zero_moves_dropped():
    sp = spans_of("G1 X5 F60\nG1 X5\nG4 P1\nM1\nG1 X6\n")
    assert list(sp.kind) == [SpanKind.LINE, SpanKind.POINT, SpanKind.POINT, SpanKind.LINE]
    assert list(sp.block) == [0, 2, 3, 4]
    np.testing.assert_array_equal(sp.start[1], [5, 0, 0])


@pytest.mark.parametrize("order", [0, 1, 2, 3])
def test_evaluate_is_batched_and_jittable(order):
    import jax

    sp = spans_of("G1 X1 F60\nG3 X0 Y1 I-1 J0\n")
    f = jax.jit(lambda c, o, u: evaluate(c, o, u, order))
    out = f(jnp.asarray(sp.coeffs[[0, 1, 1]]), jnp.asarray(sp.origin[[0, 1, 1]]), jnp.array([0.5, 0.0, 1.0]))
    assert len(out) == order + 1 and out[0].shape == (3, 3)
    np.testing.assert_allclose(np.asarray(out[0][2]), [0, 1, 0], atol=1e-15)


@pytest.mark.parametrize("order", [0, 1, 2, 3])
def test_column_evaluation_equals_row_evaluation(order):
    from jaxcnc.geometry.evaluate import evaluate_spans
    from jaxcnc.geometry.inverse import span_arrays

    sp = spans_of("G1 X1 Y2 F60\nG3 X0 Y1 I-1 J0\nG2 X5 Y1 R3\n")
    arrays = span_arrays(sp)
    rng = np.random.default_rng(order)
    idx = rng.integers(0, len(sp), 500)
    u = rng.random(500)
    rows = ev(sp, idx, u, order)
    cols = evaluate_spans(arrays["coeffs_t"], arrays["origin_t"], jnp.asarray(idx), jnp.asarray(u), order)
    for a, b in zip(rows, cols, strict=True):
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-13, atol=1e-12)
