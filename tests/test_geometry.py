"""Geometry: exact arcs and helices, batched derivatives in the path parameter, exact lengths, extents."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.gcode import parse_gcode
from jaxcnc.geometry import SpanKind, build_spans
from jaxcnc.geometry.evaluate import evaluate_path, span_arrays
from tests.helpers import at_s


def spans_of(text: str, tol: float = 0.0):
    return build_spans(parse_gcode(text, "g.ngc"), tol)


def test_arcs_are_one_exact_span_each():
    sp = spans_of("G1 X10 F60\nG3 X10 Y0 I-10 J0\nG2 X30 Y0 R10\nG3 X40 Y10 I0 J10\n")
    assert list(sp.kind) == [SpanKind.LINE] + [SpanKind.ARC] * 3
    np.testing.assert_allclose(sp.length[1:], [2 * np.pi * 10, np.pi * 10, np.pi / 2 * 10], rtol=1e-15)
    np.testing.assert_allclose(sp.start[1:], sp.end[:-1], atol=1e-12)  # consecutive spans join


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
    s0 = np.round((cx + r * np.cos(a0), cy + r * np.sin(a0)), 12)
    a1 = a0 + sgn * sweep
    e = (cx + r * np.cos(a1), cy + r * np.sin(a1))
    text = (
        f"G0 X{s0[0]:.12f} Y{s0[1]:.12f}\n{'G2' if cw else 'G3'} X{e[0]:.12f} Y{e[1]:.12f} "
        f"I{cx - s0[0]:.12f} J{cy - s0[1]:.12f} F60\n"
    )
    sp = spans_of(text)
    (k,) = np.flatnonzero(sp.kind == SpanKind.ARC)
    np.testing.assert_allclose(sp.length[k], r * sweep, rtol=1e-9, atol=1e-10)  # G-code written to 1e-12 mm
    s = np.linspace(0, sp.length[k], 41)
    (p,) = at_s(sp, np.full(41, k), s)
    ang = a0 + sgn * s / r  # the point at arc length s from the start sits at this angle
    ref = np.stack([cx + r * np.cos(ang), cy + r * np.sin(ang)], axis=1)
    np.testing.assert_allclose(p[:, :2], ref, atol=1e-9 * max(1.0, r, abs(cx), abs(cy)))


def _finite_differences(sp, idx, s, length):
    """Derivatives 1..3 of the path by central differences in s, each with a step suited to it."""

    def at(x):
        return at_s(sp, idx, x)[0]

    h1, h2, h3 = (f * length[:, None] for f in (1e-5, 1e-3, 3e-3))
    d1 = (at(s + h1[:, 0]) - at(s - h1[:, 0])) / (2 * h1)
    d2 = (at(s + h2[:, 0]) - 2 * at(s) + at(s - h2[:, 0])) / h2**2
    d3 = (at(s + 2 * h3[:, 0]) - 2 * at(s + h3[:, 0]) + 2 * at(s - h3[:, 0]) - at(s - 2 * h3[:, 0])) / (2 * h3**3)
    return d1, d2, d3


@pytest.mark.parametrize(
    "text",
    [
        "G1 X7 F60\nG3 X7 Y0 I-7 J0\n",  # a full circle
        "G0 X5 Y0 Z0\nG3 X0 Y5 Z3 I-5 J0 F60\n",  # a helix
        "G64 P0.2\nG1 X10 F60\nG1 X10 Y10\nG3 X20 Y10 R6\nG1 X25 Y0\n",  # blends with lines and an arc
    ],
)
def test_derivatives_match_finite_differences(text):
    sp = spans_of(text)
    curved = np.flatnonzero(sp.curved)
    idx = np.repeat(curved, 20)
    s = np.tile(np.linspace(0.2, 0.8, 20), curved.size) * sp.length[idx]
    _, d1, d2, d3 = at_s(sp, idx, s, order=3)
    f1, f2, f3 = _finite_differences(sp, idx, s, sp.length[idx])
    np.testing.assert_allclose(d1, f1, atol=1e-7)
    np.testing.assert_allclose(d2, f2, atol=1e-5 * np.abs(d2).max())
    np.testing.assert_allclose(d3, f3, atol=1e-3 * np.abs(d3).max())


def test_arc_tangent_and_curvature_are_exact():
    r = 7.0
    sp = spans_of(f"G1 X{r} F60\nG3 X{r} Y0 I{-r} J0\n")
    (k,) = np.flatnonzero(sp.kind == SpanKind.ARC)
    s = np.linspace(0, sp.length[k], 50)
    p, d1, d2 = at_s(sp, np.full(50, k), s, order=2)
    np.testing.assert_allclose(np.linalg.norm(d1, axis=1), 1.0, rtol=1e-14)  # unit speed
    np.testing.assert_allclose(d2, -p / r**2, atol=1e-14)  # the curvature vector points to the centre


def test_helix_is_exact():
    r, rise = 5.0, 3.0
    sp = spans_of(f"G0 X{r} Y0 Z0\nG3 X{r} Y0 Z{rise} I{-r} J0 F60\n")
    (k,) = np.flatnonzero(sp.kind == SpanKind.ARC)
    assert sp.length[k] == pytest.approx(np.hypot(2 * np.pi * r, rise), rel=1e-15)
    s = np.linspace(0, sp.length[k], 200)
    p, d1 = at_s(sp, np.full(200, k), s, order=1)
    np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), r, rtol=1e-14)
    ang = np.unwrap(np.arctan2(p[:, 1], p[:, 0]))
    np.testing.assert_allclose(p[:, 2], rise * ang / (2 * np.pi), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(d1, axis=1), 1.0, rtol=1e-14)
    np.testing.assert_allclose(sp.end[k], [r, 0, rise], atol=1e-12)


def test_lines_are_arc_length():
    sp = spans_of("G1 X3 Y4 Z12 F60\n")
    assert sp.length[0] == 13.0
    s = np.linspace(0, 13, 14)
    (p,) = at_s(sp, np.zeros(14, int), s)
    np.testing.assert_allclose(p, np.outer(s / 13, [3, 4, 12]), atol=1e-13)


def test_extents_are_exact_and_hold_every_point():
    sp = spans_of("G0 X10 Y0\nG3 X-10 Y0 I-10 J0 F60\nG3 X10 Y0 R10\nG64 P0.3\nG1 X20 Y5\nG1 X25 Y-5\n")
    arcs = sp.kind == SpanKind.ARC
    lo, hi = sp.lo[arcs].min(axis=0), sp.hi[arcs].max(axis=0)
    np.testing.assert_allclose(lo[:2], [-10, -10], atol=1e-12)
    np.testing.assert_allclose(hi[:2], [10, 10], atol=1e-12)
    idx = np.repeat(np.arange(len(sp)), 200)
    s = np.tile(np.linspace(0, 1, 200), len(sp)) * sp.length[idx]
    (p,) = at_s(sp, idx, s)
    assert np.all(p >= sp.lo[idx] - 1e-9) and np.all(p <= sp.hi[idx] + 1e-9)


def test_points_for_dwell_and_events_zero_moves_dropped():
    sp = spans_of("G1 X5 F60\nG1 X5\nG4 P1\nM1\nG1 X6\n")
    assert list(sp.kind) == [SpanKind.LINE, SpanKind.POINT, SpanKind.POINT, SpanKind.LINE]
    assert list(sp.block) == [0, 2, 3, 4]
    np.testing.assert_array_equal(sp.start[1], [5, 0, 0])


@pytest.mark.parametrize("order", [0, 1, 2, 3])
def test_numpy_and_jitted_jax_evaluation_agree(order):
    from jaxcnc.io.curves import curves_program
    from tests.helpers import random_cubic_nurbs

    text = "G64 P0.1\nG1 X1 Y2 F60\nG3 X0 Y1 I-1 J0\nG2 X5 Y1 Z1 R3\nG1 X9 Y0\n"
    parts = [spans_of(text)]
    curve = random_cubic_nurbs(12, seed=1)
    parts.append(build_spans(curves_program([curve], 10.0, start=curve[1][0])))
    for sp in parts:
        rng = np.random.default_rng(order)
        idx = rng.integers(0, len(sp), 500)
        s = rng.random(500) * sp.length[idx]
        ref = evaluate_path(span_arrays(sp), idx, s, order)
        f = jax.jit(lambda a, i, x: evaluate_path(a, i, x, order, xp=jnp))
        out = f(span_arrays(sp, xp=jnp), jnp.asarray(idx), jnp.asarray(s))
        for a, b in zip(ref, out, strict=True):
            np.testing.assert_allclose(np.asarray(b), a, rtol=1e-12, atol=1e-12)


def test_polynomial_spans_meet_their_neighbours_with_unit_speed_and_curvature():
    """At every joint q, q' and — where the geometry is G2 — q'' agree on both sides (blends, curve pieces)."""
    from jaxcnc.io.curves import curves_program
    from tests.helpers import random_cubic_nurbs

    curve = random_cubic_nurbs(30, seed=2)
    for sp in (
        build_spans(curves_program([curve], 10.0, start=curve[1][0])),
        spans_of("G64 P0.05\nG1 X10 F60\nX10 Y10\nG2 X20 Y10 I5 J0\nG1 X30 Y0\nG3 X40 Y0 R6\nG2 X50 Y0 R7\n"),
    ):
        a = span_arrays(sp)
        moving = np.flatnonzero((sp.kind[:-1] != SpanKind.POINT) & (sp.kind[1:] != SpanKind.POINT))
        end = evaluate_path(a, moving, sp.length[moving], 2)
        start = evaluate_path(a, moving + 1, np.zeros(moving.size), 2)
        np.testing.assert_allclose(end[0], start[0], atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(end[1], axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(start[1], axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(end[1], start[1], atol=1e-9)
        poly = np.isin(sp.kind[moving], (SpanKind.CURVE, SpanKind.BLEND)) | np.isin(
            sp.kind[moving + 1], (SpanKind.CURVE, SpanKind.BLEND)
        )
        # no tangential part in q'' at a polynomial span's ends: the curvature vector alone
        for d1, d2 in ((end[1][poly], end[2][poly]), (start[1][poly], start[2][poly])):
            np.testing.assert_allclose(np.sum(d1 * d2, axis=1), 0.0, atol=1e-9 * max(1.0, np.abs(d2).max()))
        np.testing.assert_allclose(end[2][poly], start[2][poly], atol=1e-9 * max(1.0, np.abs(end[2]).max()))


def _spans_by_sort(program):
    """:func:`program_spans` as it is made where curve rows take part: the parts sorted into row order."""
    from jaxcnc.geometry.spans import MIN_LENGTH_MM, arc_fields, concat_spans, line_fields, point_fields, row_norm
    from jaxcnc.program import Kind

    kind = program.kind
    rows_line = np.flatnonzero((kind == Kind.LINE) & (row_norm(program.end - program.start) > MIN_LENGTH_MM))
    rows_arc = np.flatnonzero(kind == Kind.ARC)
    rows_pt = np.flatnonzero((kind == Kind.DWELL) | (kind == Kind.EVENT))
    parts = [(line_fields(program.start[rows_line], program.end[rows_line], rows_line), None)]
    if rows_arc.size:
        parts.append(arc_fields(program, rows_arc))
    parts.append((point_fields(program.end[rows_pt], rows_pt), None))
    return concat_spans(parts, np.concatenate([f["block"] for f, _ in parts]))


@pytest.mark.parametrize(
    "text",
    [
        "G1 X1 F600\nG2 X2 Y1 I0.5 J0.5\nG1 X2\nG4 P0.5\nM3 S100\nG3 X0 Y1 I-1 J0\nG1 X0 Y0 Z1\nM5\nM2\n",
        "G1 X1 F600\nG1 X2\nM2\n",
        "G4 P1\nM2\n",
    ],
)
def test_spans_of_rows_without_curves_are_those_of_the_sorted_parts(text):
    """A program without curve rows takes each kept row as one span in row order (no sort, no scatter of the line
    fields: :func:`~jaxcnc.geometry.spans.program_spans`): the same spans, bit for bit and dtype for dtype, as the
    parts sorted into row order — lines, arcs, helices, zero-length moves (no span), dwells and events."""
    from jaxcnc.geometry.spans import SPAN_FIELDS, program_spans

    program = parse_gcode(text, "rows.ngc")
    fast, ref = program_spans(program), _spans_by_sort(program)
    for key in SPAN_FIELDS:
        a, b = getattr(fast, key), getattr(ref, key)
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint8), b.view(np.uint8)), key
        assert not a.flags.writeable
    assert not np.shares_memory(fast.tangent_in, fast.tangent_out)
    for name in ("center", "e1", "e2", "axis", "radius", "rise", "sweep"):
        np.testing.assert_array_equal(getattr(fast.arcs, name), getattr(ref.arcs, name))


@st.composite
def _row_programs(draw):
    """G-code of lines (some of no length), arcs and helices (ends on their circles), dwells and laser events."""
    x = y = z = 0.0
    lines = ["G21 G90 G17 F600"]
    for _ in range(draw(st.integers(1, 25))):
        what = draw(st.sampled_from(["line", "still", "arc", "dwell", "event"]))
        if what == "line":
            x, y, z = (round(draw(st.floats(-50, 50)), 3) for _ in range(3))
            lines.append(f"G1 X{x} Y{y} Z{z}")
        elif what == "still":
            lines.append(f"G1 X{x:.6f} Y{y:.6f}")
        elif what == "arc":
            i, j = (round(draw(st.floats(-5, 5)), 3) for _ in range(2))
            r = float(np.hypot(i, j))
            if r < 0.01:
                continue
            a = draw(st.floats(0, 2 * np.pi))
            cx, cy = x + i, y + j
            x, y = round(cx + r * np.cos(a), 6), round(cy + r * np.sin(a), 6)
            dz = round(draw(st.sampled_from([0.0, 0.5])), 3)
            z = round(z + dz, 3)
            # (fixed point: str() writes 3.1e-05, which G-code reads as X3.1 and a word E-05)
            lines.append(f"G{draw(st.sampled_from([2, 3]))} X{x:.6f} Y{y:.6f} Z{z} I{i} J{j}")
        elif what == "dwell":
            lines.append("G4 P0.1")
        else:
            lines.append(draw(st.sampled_from(["M3 S100", "M5"])))
    return "\n".join(lines) + "\nM2\n"


@settings(max_examples=60, deadline=None)
@given(_row_programs())
def test_spans_of_random_rows_are_those_of_the_sorted_parts(text):
    """:func:`test_spans_of_rows_without_curves_are_those_of_the_sorted_parts` on random programs."""
    test_spans_of_rows_without_curves_are_those_of_the_sorted_parts(text)
