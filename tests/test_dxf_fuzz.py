"""Hypothesis fuzz of the drawing front end: chaining and validation of random segment soups, damaged DXF bytes."""

from __future__ import annotations

import ezdxf
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from shapely import LinearRing, Polygon

from jaxcnc.errors import SourceError
from jaxcnc.io.drawing import DrawingOptions, assemble, line_piece
from jaxcnc.io.dxf import read_dxf

START = np.zeros(3)


@st.composite
def polygon_soups(draw):
    """Disjoint convex polygons (one per grid cell, some nested in others), their edges shuffled, some
    reversed, some drawn twice, end points moved within a third of the tolerance."""
    n_cells = draw(st.integers(1, 5))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    pieces, truth = [], []
    for cell in range(n_cells):
        cx = 100.0 * cell
        for level, radius in enumerate((40.0, 10.0)[: draw(st.integers(1, 2))]):
            k = draw(st.integers(4, 9))
            step = 2 * np.pi / k  # near-regular: the outer polygon's inradius (> 15 mm) clears the inner one
            ang = np.arange(k) * step + rng.uniform(-0.25, 0.25, k) * step
            pts = np.stack([cx + radius * np.cos(ang), radius * np.sin(ang)], axis=1)
            truth.append((len(pieces), k, level))
            for i in range(k):
                a, b = pts[i], pts[(i + 1) % k]
                pieces.append([a, b])
    jitter = 0.01 / 3
    out = []
    for a, b in pieces:
        a = a + rng.uniform(-jitter, jitter, 2) / np.sqrt(2)
        b = b + rng.uniform(-jitter, jitter, 2) / np.sqrt(2)
        if rng.random() < 0.3:
            a, b = b, a
        out.append(line_piece(a, b, f"LINE #{len(out):X} on layer '0'", len(out) + 1))
        if rng.random() < 0.1:
            out.append(line_piece(b, a, f"LINE #{len(out):X} on layer '0'", len(out) + 1))
    order = rng.permutation(len(out))
    return [out[i] for i in order], truth


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(polygon_soups())
def test_soups_of_closed_polygons_chain_back(soup):
    pieces, truth = soup
    d = assemble(pieces, DrawingOptions(), START, "soup.dxf")
    assert len(d.contours) == len(truth) and all(c.closed for c in d.contours)
    assert sorted(len(c.pieces) for c in d.contours) == sorted(k for _, k, _ in truth)
    assert sorted(c.depth for c in d.contours) == sorted(level for _, _, level in truth)
    p = d.program
    assert np.all(p.end[:-1] == p.start[1:])  # continuous
    polys = [Polygon(c.poly) for c in d.contours]
    for i, outer in enumerate(polys):  # inner before outer
        assert all(j < i for j, inner in enumerate(polys) if j != i and outer.contains(inner))


segments = st.lists(
    st.tuples(*[st.floats(-20, 20, allow_nan=False, allow_infinity=False).map(lambda v: round(v, 1))] * 4),
    min_size=1,
    max_size=14,
)


@settings(max_examples=200, deadline=None)
@given(segments, st.booleans())
def test_random_segment_soups_are_cut_or_refused_with_a_reason(segs, allow_open):
    pieces = [
        line_piece(np.array(s[:2]), np.array(s[2:]), f"LINE #{i:X} on layer '0'", i + 1) for i, s in enumerate(segs)
    ]
    try:
        d = assemble(pieces, DrawingOptions(allow_open=allow_open), START, "soup.dxf")
    except SourceError as exc:
        msg = str(exc)
        assert msg.startswith("soup.dxf") and "\n" not in msg
        assert "nothing to cut" in msg or ("LINE #" in msg and "(" in msg)
        return
    p = d.program
    assert np.all(p.end[:-1] == p.start[1:])
    if not allow_open:  # what passed is closed, simple and crosses nothing (checked again here, independently)
        rings = [LinearRing(c.poly) for c in d.contours]
        assert all(c.closed for c in d.contours) and all(r.is_simple for r in rings)
        for i in range(len(rings)):
            for j in range(i + 1, len(rings)):
                assert not rings[i].intersects(rings[j])


def _good_dxf_bytes() -> bytes:
    import io

    doc = ezdxf.new("R2000", units=4)
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0, 0, 0, 0.5), (20, 0), (20, 10), (0, 10)], format="xyseb", close=True)
    msp.add_circle((10, 5), 2)
    msp.add_spline([(30, 0), (35, 5), (40, 0), (45, 5)])
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue().encode()


GOOD = _good_dxf_bytes()


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(st.tuples(st.integers(0, len(GOOD) - 1), st.binary(min_size=0, max_size=6)), min_size=1, max_size=4),
    st.integers(0, len(GOOD)),
)
def test_damaged_dxf_bytes_give_one_line_errors(tmp_path, edits, cut):
    data = bytearray(GOOD[:cut] if cut < len(GOOD) // 2 else GOOD)
    for at, junk in edits:
        at = min(at, len(data))
        data[at : at + len(junk)] = junk
    p = tmp_path / "fuzz.dxf"
    p.write_bytes(bytes(data))
    try:
        read_dxf(p, START, DrawingOptions(allow_open=True))
    except SourceError as exc:
        msg = str(exc)
        assert msg.startswith(str(p)) and "\n" not in msg
