"""The NumPy evaluation that evaluates each span family on its own rows (``evaluate._evaluate_families``) gives every
row the value it gets evaluated alone, on a path with every span kind the blends make."""

from __future__ import annotations

import numpy as np

from jaxcnc.gcode import parse_gcode
from jaxcnc.geometry import build_spans
from jaxcnc.geometry.evaluate import evaluate_path, span_arrays
from jaxcnc.geometry.spans import SpanKind


def _chords_and_arcs(n: int) -> str:
    """A polyline of ``n`` short chords round a circle, with an arc (G2/G3) every 40 moves and a dwell and a stop
    now and then: every kind of junction the blends meet, and chains of consumed chords across chunk borders."""
    lines = ["G21 G90 G64 P0.01 F3000", "G0 X50 Y0"]
    rng = np.random.default_rng(7)
    angle = 0.0
    for k in range(n):
        angle += 0.01 + 0.002 * rng.standard_normal()
        x, y = 50 * np.cos(angle), 50 * np.sin(angle)
        if k % 40 == 39:
            lines.append(f"G3 X{x:.4f} Y{y:.4f} R50")
        elif k % 97 == 96:
            lines.append("G4 P0.01")
            lines.append(f"G1 X{x:.4f} Y{y:.4f}")
        else:
            lines.append(f"G1 X{x:.4f} Y{y:.4f}")
    return "\n".join(lines) + "\n"


def test_each_family_evaluated_on_its_own_rows_matches_each_row_alone():
    spans = build_spans(parse_gcode(_chords_and_arcs(400)), 0.01)
    assert {SpanKind.LINE, SpanKind.ARC, SpanKind.BLEND, SpanKind.POINT} <= set(np.unique(spans.kind).tolist())
    arrays = span_arrays(spans)
    rng = np.random.default_rng(3)
    span = rng.integers(0, len(spans), 3000)
    s = rng.uniform(-0.1, 1.1, 3000) * spans.length[span]  # some outside the span: clipped
    together = evaluate_path(arrays, span, s, 4)
    for r in rng.choice(3000, 200, replace=False):
        alone = evaluate_path(arrays, span[r : r + 1], s[r : r + 1], 4)
        for d, (x, y) in enumerate(zip(together, alone, strict=True)):
            assert x[r].tobytes() == y[0].tobytes(), (r, d, int(spans.kind[span[r]]))
    # span (m, 1) against s (m, k): the broadcast shape, row by row the same values
    grid = evaluate_path(arrays, span[:50, None], s[:50, None] * np.linspace(0.0, 1.0, 4)[None, :], 2)
    assert grid[2].shape == (50, 4, 3)
    assert grid[0][:, 0].tobytes() == evaluate_path(arrays, span[:50], s[:50] * 0.0, 0)[0].tobytes()
