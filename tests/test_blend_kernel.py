"""The compiled blend arithmetic: the deviation bound of line–arc blends is never below the blend's true
distance to the pieces it replaces (hypothesis, random junctions, dense reference in NumPy)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.gcode import parse_gcode
from jaxcnc.geometry import blend as B
from jaxcnc.geometry import blend_kernel as K
from jaxcnc.geometry import poly
from jaxcnc.geometry.evaluate import evaluate_path, span_arrays
from jaxcnc.geometry.spans import program_spans


def _polyline_distance(p: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Distance from points ``(Q, 3)`` to the polyline through ``ref`` ``(R, 3)`` (exact per segment)."""
    a, b = ref[:-1], ref[1:]
    ab = b - a
    t = np.clip(np.einsum("qrd,rd->qr", p[:, None] - a[None], ab) / np.maximum(np.sum(ab * ab, 1), 1e-300), 0, 1)
    return np.min(np.linalg.norm(p[:, None] - (a[None] + t[..., None] * ab[None]), axis=2), axis=1)


def _arc_end_at_origin(radius: float, sweep: float, ccw: bool, phi: float) -> tuple[np.ndarray, np.ndarray]:
    """Start and centre of an arc ending at the origin with its end tangent at angle ``phi``."""
    sgn = 1.0 if ccw else -1.0
    center = sgn * radius * np.array([-np.sin(phi), np.cos(phi)])
    rel = -center
    c, s = np.cos(-sgn * sweep), np.sin(-sgn * sweep)
    return center + np.array([c * rel[0] - s * rel[1], s * rel[0] + c * rel[1]]), center


def _arc_start_at_origin(radius: float, sweep: float, ccw: bool, phi: float) -> tuple[np.ndarray, np.ndarray]:
    """End and centre of an arc starting at the origin with its start tangent at angle ``phi``."""
    sgn = 1.0 if ccw else -1.0
    center = sgn * radius * np.array([-np.sin(phi), np.cos(phi)])
    rel = -center
    c, s = np.cos(sgn * sweep), np.sin(sgn * sweep)
    return center + np.array([c * rel[0] - s * rel[1], s * rel[0] + c * rel[1]]), center


junctions = st.tuples(
    st.booleans(),  # line then arc (else arc then line)
    st.floats(0.5, 20.0),  # line length
    st.floats(0.3, 50.0),  # radius
    st.floats(np.deg2rad(10), np.deg2rad(270)),  # sweep
    st.booleans(),  # counter-clockwise
    st.floats(np.deg2rad(0.5), np.deg2rad(150)) | st.floats(-np.deg2rad(150), -np.deg2rad(0.5)),  # kink
    st.floats(0.05, 1.0),  # cut-back as a share of the largest allowed
)


@settings(max_examples=15, deadline=None)
@given(st.lists(junctions, min_size=1, max_size=4))
def test_the_deviation_bound_is_never_below_the_dense_distance(cases):
    for case in cases:
        _check_case(*case)


def test_a_long_cut_back_on_a_tight_arc_crossing_five_times():
    """Found by the property test (2026-11-28): the distances to the two pieces cross five times along this
    blend (u = 0.062, 0.064, 0.657, 0.874, 0.884) and the peak is at the third (0.1675 mm). The kernel then
    bisected the first crossing only and reported 0.1458 mm."""
    _check_case(False, 5.0, 1.0, 4.03125, True, -2.2890625, 0.96875)


def test_a_long_blend_inside_a_wide_arc_is_bounded_usefully():
    """A 10.9 mm blend inside a 4.7 mm arc (found by a random sweep): with 17 samples the bound's terms
    between samples (the chord's sag, the arc's concavity) made it 1.35× the true distance."""
    _check_case(
        False, 12.246336738942334, 4.666916603784459, 3.238868076617338, False, 0.1166119854211792, 0.8928528723728457
    )


def _check_case(line_first, length, radius, sweep, ccw, kink, share) -> None:
    """The deviation bound of one line–arc or arc–line junction against the dense reference (see the property
    test)."""
    g = "G2" if not ccw else "G3"
    if line_first:  # along +X into the origin, then the arc leaving at angle `kink`
        end, center = _arc_start_at_origin(radius, sweep, ccw, kink)
        arc = f"{g} X{end[0]:.9f} Y{end[1]:.9f} I{center[0]:.9f} J{center[1]:.9f}"
        text = f"G0 X{-length:.9f} Y0\nG1 X0 Y0 F600\n{arc}\n"
    else:  # the arc into the origin at angle `kink`, then along +X
        start, center = _arc_end_at_origin(radius, sweep, ccw, kink)
        i, j = center - start
        text = f"G0 X{start[0]:.9f} Y{start[1]:.9f}\n{g} X0 Y0 I{i:.9f} J{j:.9f} F600\nG1 X{length:.9f} Y0\n"
    _check_junction(text, share, radius)


def _check_junction(text: str, share: float, min_radius: float) -> None:
    """The deviation bound of the last junction of program ``text``, its blend cut back by ``share`` of the most
    allowed, against the blend at 801 points and the two pieces as 1501-point polylines (on an arc the chords
    lie inside it by at most δ²/8R, R >= ``min_radius``: the slack allowed)."""
    spans = program_spans(parse_gcode(text, "j.ngc"))
    k = np.array([len(spans) - 2])
    ell = share * 0.5 * np.minimum(spans.length[k], spans.length[k + 1])
    arrays = span_arrays(spans)
    pts, _, _ = B._blend_points(spans, k, ell, ell, arrays=arrays)
    coeffs = B._coeffs(pts)
    bound = B._deviation(spans, arrays, k, ell, ell, coeffs)[0]
    u = np.linspace(0.0, 1.0, 801)[None]
    p = poly.bezier_derivatives(coeffs, u, 0)[0][0] + pts[0, 0]
    s_in = np.linspace(spans.length[k[0]] - ell[0], spans.length[k[0]], 1501)
    s_out = np.linspace(0.0, ell[0], 1501)
    ref_in = evaluate_path(arrays, np.full(s_in.size, k[0]), s_in)[0]
    ref_out = evaluate_path(arrays, np.full(s_out.size, k[0] + 1), s_out)[0]
    dense = np.max(np.minimum(_polyline_distance(p, ref_in), _polyline_distance(p, ref_out)))
    sagitta = (ell[0] / 1500) ** 2 / (8 * min_radius)
    assert bound >= dense - sagitta - 1e-12, (text, bound, dense)
    assert bound <= 1.25 * dense + 1e-9, (text, bound, dense)  # and a useful bound, not a loose one


arc_pairs = st.tuples(
    st.floats(0.3, 50.0),  # radius in
    st.floats(np.deg2rad(10), np.deg2rad(270)),  # sweep in
    st.booleans(),  # counter-clockwise in
    st.floats(0.3, 50.0),  # radius out
    st.floats(np.deg2rad(10), np.deg2rad(270)),  # sweep out
    st.booleans(),  # counter-clockwise out
    st.floats(np.deg2rad(0.5), np.deg2rad(150)) | st.floats(-np.deg2rad(150), -np.deg2rad(0.5)),  # kink
    st.floats(0.05, 1.0),  # cut-back as a share of the largest allowed
    st.floats(-0.25, 0.25),  # the second arc's rise along Z per mm along its circle (a helix; 0: in the plane)
)


@settings(max_examples=15, deadline=None)
@given(st.lists(arc_pairs, min_size=1, max_size=3))
def test_the_deviation_bound_of_arc_arc_junctions_is_never_below_the_dense_distance(cases):
    """Arc into the origin (its end tangent along +X), then an arc (or a helix, rising up to 14° as helical
    ramps do) leaving it at angle `kink`: both pieces curve, on either side, the blend inside one and outside the
    other. (On a steep helix the kernel's distance to the helix, taken at the query's own angle, is looser: a
    76° helix of radius 1 gave 1.44× the dense distance, above it as a bound must be.)"""
    for r1, sw1, ccw1, r2, sw2, ccw2, kink, share, rise in cases:
        start, c1 = _arc_end_at_origin(r1, sw1, ccw1, 0.0)
        end, c2 = _arc_start_at_origin(r2, sw2, ccw2, kink)
        g1, g2 = ("G3" if ccw1 else "G2"), ("G3" if ccw2 else "G2")
        i1, j1 = c1 - start
        text = (
            f"G0 X{start[0]:.9f} Y{start[1]:.9f} Z0\n{g1} X0 Y0 I{i1:.9f} J{j1:.9f} F600\n"
            f"{g2} X{end[0]:.9f} Y{end[1]:.9f} Z{rise * r2 * sw2:.9f} I{c2[0]:.9f} J{c2[1]:.9f}\n"
        )
        _check_junction(text, share, min(r1, r2))


def _dense_line_distance(pts: np.ndarray, corner: np.ndarray) -> float:
    """Distance from the quintic Bézier ``pts`` ``(6, 3)`` (20,001 points) to the polyline ``P0``–corner–``P5``."""
    u = np.linspace(0.0, 1.0, 20001)[:, None]
    coeffs = np.einsum("ki,id->kd", K._M5, pts - pts[0])
    p = sum(coeffs[k] * u**k for k in range(6)) + pts[0]
    return float(np.max(_polyline_distance(p, np.stack([pts[0], corner, pts[5]]))))


def _corner_blend(turn_deg, a, b, ka, kb):
    """Control points of a blend as ``blend._blend_points`` makes them: from ``a`` mm before a corner at the
    origin to ``b`` mm after it (the path turns by ``turn_deg`` in XY), with curvature vectors ``ka``, ``kb`` at
    its ends (as a chain of blends gives them: any direction, in the plane and out of it; in units of the
    corner's mean curvature ``2 sin(θ/2) / (a + b)``)."""
    t_in = np.array([1.0, 0.0, 0.0])
    th = np.deg2rad(turn_deg)
    t_out = np.array([np.cos(th), np.sin(th), 0.0])
    lam = a + b
    kappa = 2 * abs(np.sin(th / 2)) / lam
    p0, p5 = -a * t_in, b * t_out
    p1, p4 = p0 + lam / 5 * t_in, p5 - lam / 5 * t_out
    p2 = 2 * p1 - p0 + lam**2 / 20 * kappa * np.asarray(ka)
    p3 = 2 * p4 - p5 + lam**2 / 20 * kappa * np.asarray(kb)
    return np.stack([p0, p1, p2, p3, p4, p5]), np.zeros(3)


line_blends = st.tuples(
    st.floats(0.5, 150.0) | st.floats(-150.0, -0.5),
    st.floats(0.01, 5.0),
    st.floats(0.01, 5.0),
    st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
    st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
)


@settings(max_examples=60, deadline=None)
@given(st.lists(line_blends, min_size=1, max_size=8))
def test_the_line_blend_bound_is_never_below_the_dense_distance(cases):
    """The corner kernel's distance (where it certifies the crossing) and, where it cannot, the deviation
    kernel's (the caller's fallback) against 20,001 points of the blend — asymmetric blends with inner points
    pushed off the legs, in and out of the plane, as chained blends are."""
    n = len(cases)
    cases = cases + [cases[0]] * (8 - n)  # one shape for every example (each size would compile the kernels)
    pts, corner = (np.stack(x) for x in zip(*(_corner_blend(*c) for c in cases), strict=True))
    dev = np.asarray(K.blend_kernel(pts, corner)["dev"])
    lines = {k: np.zeros((len(pts), 3)) for k in ("center", "e1", "e2", "axis")}
    lines.update({k: np.zeros(len(pts)) for k in ("radius", "rise", "lo", "hi")}, is_arc=np.zeros(len(pts), bool))
    coeffs = B._coeffs(pts)
    fallback = np.asarray(
        K.deviation_kernel(coeffs, pts[:, 0], dict(lines, a=pts[:, 0], b=corner), dict(lines, a=corner, b=pts[:, 5]))
    )
    for i in range(n):
        dense = _dense_line_distance(pts[i], corner[i])
        for bound in (dev[i], fallback[i]):
            if np.isfinite(bound):
                assert bound >= dense - 1e-12, (cases[i], bound, dense)
        # and useful: blend_path decides with the lower of the two where the corner kernel's says "too far"
        # (its own reached 1.253x on a 110 deg corner, 4.0 / 1.125 mm legs, the inner points pushed in-plane)
        assert min(dev[i], fallback[i]) <= 1.25 * dense + 1e-9, (cases[i], dev[i], fallback[i], dense)
        assert dev[i] <= 1.5 * dense + 1e-9 or not np.isfinite(dev[i]), (cases[i], dev[i], dense)


def test_a_blend_crossing_the_bisecting_plane_three_times_is_left_to_the_deviation_kernel():
    """An S-shaped control polygon crosses the corner's bisecting plane three times: the corner kernel cannot
    certify a single crossing and says so (inf); blend_path measures it with the deviation kernel instead."""
    pts, corner = _corner_blend(10.0, 1.0, 1.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    pts[2], pts[3] = [0.2, -0.05, 0.0], [-0.2, 0.08, 0.0]  # the inner points swapped across the plane
    n = np.array([1 + np.cos(np.deg2rad(10)), np.sin(np.deg2rad(10)), 0])
    side = np.sign((pts - corner) @ n)
    assert np.sum(side[1:] != side[:-1]) == 3
    assert np.isinf(np.asarray(K.blend_kernel(pts[None], corner[None])["dev"])[0])
