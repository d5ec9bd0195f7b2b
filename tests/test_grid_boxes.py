"""The grid's boxes on blends: every box holds the path's ``q'`` and ``q''`` densely sampled inside its interval
(hypothesis, random 3-D corners and arcs), its ends are the path's own values, and the chunked evaluation gives
the same boxes as one call."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.gcode import parse_gcode
from jaxcnc.geometry import SpanKind, build_spans
from jaxcnc.geometry.evaluate import evaluate_path, span_arrays
from jaxcnc.planners import grid as G

#: Points per boxed interval of the dense reference (ends included).
DENSE = 97

corners = st.tuples(
    st.floats(0.05, 8.0),  # length of the move into the next point
    st.floats(-np.pi, np.pi),  # heading in XY
    st.floats(-0.6, 0.6),  # climb (rad): 3-D corners
)


def _program(moves: list[tuple[float, float, float]], tol: float, arc: bool) -> str:
    """G-code of a polyline through ``moves`` (length, heading, climb), an arc in the middle if ``arc``."""
    p = np.zeros(3)
    lines = [f"G64 P{tol:.6f}", "G1 X0 Y0 Z0 F600"]
    for i, (length, heading, climb) in enumerate(moves):
        step = length * np.array([np.cos(climb) * np.cos(heading), np.cos(climb) * np.sin(heading), np.sin(climb)])
        q = p + step
        if arc and i == len(moves) // 2 and np.hypot(*step[:2]) > 0.1:  # an XY arc (helix) bulging to the left
            mid = (p[:2] + q[:2]) / 2
            normal = np.array([-step[1], step[0]]) / np.hypot(*step[:2])
            ij = mid + 0.6 * np.hypot(*step[:2]) * normal - p[:2]
            lines.append(f"G3 X{q[0]:.9f} Y{q[1]:.9f} Z{q[2]:.9f} I{ij[0]:.9f} J{ij[1]:.9f}")
        else:
            lines.append(f"G1 X{q[0]:.9f} Y{q[1]:.9f} Z{q[2]:.9f}")
        p = q
    return "\n".join(lines) + "\n"


def _boxed_grid(text: str, tol: float):
    spans = build_spans(parse_gcode(text, "b.ngc"), tol)
    return spans, G.build_grid(spans, G.interval_counts(spans))


@settings(max_examples=25, deadline=None)
@given(st.lists(corners, min_size=2, max_size=6), st.floats(0.001, 0.3), st.booleans())
def test_every_box_holds_the_densely_sampled_derivatives(moves, tol, arc):
    spans, g = _boxed_grid(_program(moves, tol, arc), tol)
    box = np.flatnonzero(g.boxed)
    if not box.size:
        return
    assert np.all(spans.kind[g.span[box]] == SpanKind.BLEND)
    frac = np.linspace(0.0, 1.0, DENSE)
    where = g.s_start[box, None] + g.delta[box, None] * frac[None]
    _, d1, d2 = evaluate_path(span_arrays(spans), g.span[box, None], where, 2)  # (b, DENSE, 3) each
    # rounding only: the boxes' own samples are computed in another order (XLA against NumPy)
    eps1 = 1e-12 * (1.0 + np.max(np.abs(d1)))
    eps2 = 1e-12 * (1.0 + np.max(np.abs(d2)))
    assert np.all(d1 >= g.t_lo[box, None] - eps1) and np.all(d1 <= g.t_hi[box, None] + eps1)
    assert np.all(d2 >= g.k_lo[box, None] - eps2) and np.all(d2 <= g.k_hi[box, None] + eps2)
    # the bound on |q'| (the feed's cap inside the box) holds too
    assert np.all(np.linalg.norm(d1, axis=2) <= g.speed_hi[box, None] + eps1)
    # the ends are the path's values there
    np.testing.assert_allclose(g.t_a[box], d1[:, 0], rtol=0, atol=eps1)
    np.testing.assert_allclose(g.t_b[box], d1[:, -1], rtol=0, atol=eps1)
    np.testing.assert_allclose(g.k_a[box], d2[:, 0], rtol=0, atol=eps2)
    np.testing.assert_allclose(g.k_b[box], d2[:, -1], rtol=0, atol=eps2)


def test_boxes_need_their_pads():
    """The dense check above fails without the pads (the samples' extremes alone): it tests the bound."""
    rng = np.random.default_rng(3)
    moves = [(rng.uniform(0.5, 3.0), rng.uniform(-np.pi, np.pi), rng.uniform(-0.5, 0.5)) for _ in range(40)]
    spans, g = _boxed_grid(_program(moves, 0.2, True), 0.2)
    box = np.flatnonzero(g.boxed)
    arrays = G.device_spans(spans)
    loose = G.boxes_at(arrays, g.span[box], g.s_start[box], g.delta[box])
    h2 = (g.delta[box] / (G.BOX_SAMPLES - 1)) ** 2 / 8
    frac = np.linspace(0.0, 1.0, G.BOX_SAMPLES)
    where = g.s_start[box, None] + g.delta[box, None] * frac[None]
    _, _, d2, _, d4 = evaluate_path(span_arrays(spans), g.span[box, None], where, 4)
    k_pad = G.BOX_SAFETY * np.max(np.abs(d4), axis=1) * h2[:, None]
    np.testing.assert_allclose(loose[7] - k_pad, np.max(d2, axis=1), rtol=0, atol=1e-9 * np.max(np.abs(d2)))
    dense = g.s_start[box, None] + g.delta[box, None] * np.linspace(0.0, 1.0, DENSE)[None]
    _, _, e2 = evaluate_path(span_arrays(spans), g.span[box, None], dense, 2)
    assert np.any(np.max(e2, axis=1) > np.max(d2, axis=1) + 1e-9 * np.max(np.abs(d2)))  # samples alone miss some


def test_chunked_boxes_equal_one_call(monkeypatch):
    rng = np.random.default_rng(7)
    moves = [(rng.uniform(0.05, 2.0), rng.uniform(-np.pi, np.pi), rng.uniform(-0.3, 0.3)) for _ in range(120)]
    spans, g = _boxed_grid(_program(moves, 0.05, True), 0.05)
    box = np.flatnonzero(g.boxed)
    assert box.size > 300
    arrays = G.device_spans(spans)
    args = (arrays, g.span[box], g.s_start[box], g.delta[box])
    whole = G.boxes_at(*args)
    monkeypatch.setattr(G, "BOX_CHUNK", 256)  # the last of the calls padded
    chunked = G.boxes_at(*args)
    assert [a.shape for a in whole] == [(box.size, 3)] * 8 + [(box.size,)]
    for a, b in zip(whole, chunked, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("q", [0, 1])
def test_boxes_of_few_intervals(q):
    spans, g = _boxed_grid(_program([(2.0, 0.0, 0.0), (2.0, 1.0, 0.0)], 0.1, False), 0.1)
    box = np.flatnonzero(g.boxed)[:q]
    out = G.boxes_at(G.device_spans(spans), g.span[box], g.s_start[box], g.delta[box])
    assert len(out) == 9 and all(x.shape == (q, 3) for x in out[:8]) and out[8].shape == (q,)
