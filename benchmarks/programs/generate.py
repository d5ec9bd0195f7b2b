#!/usr/bin/env python3
"""Generate the benchmark programs in this folder (deterministic; standard library only).

    python benchmarks/programs/generate.py [output folder]

Six programs, two of each kind, normalised like the peer programs in ``shared/peers/programs``:
``G21 G90 G17 G91.1`` and ``G64`` first, absolute mm, X Y Z on every move, arcs as G2/G3 with I J
centre offsets (G17), F in mm/min (modal, written when it changes), no S/T/G40/R words, no dwells,
``M2`` last.  Coordinates are written with at most 4 decimals; every arc's end point lies on the
circle through its start point and its written centre to within 1 µm (checked when written).

- ``cam3d_a``, ``cam3d_b``: 3-D CAM output (pockets with helical entries, trochoidal slots, waterline
  rings, ramped profiles, raster surface finishing with helical U-turn links).
- ``svg_logo_a``, ``svg_logo_b``: SVG outlines converted to G-code (flattened cubic Béziers as short
  G1 segments, SVG arcs and circles as G2/G3, Béziers fitted by biarcs), G0 between contours.
- ``laser_parts_a``, ``laser_parts_b``: nested small laser parts, every contour ``G0`` to the pierce
  point, ``M3``, lead-in, contour of lines and arcs, ``M5``.
"""

from __future__ import annotations

import math
import random
import sys
from pathlib import Path

TAU = 2.0 * math.pi


# ---------------------------------------------------------------------------------------------
# Writer
# ---------------------------------------------------------------------------------------------


def fmt(v: float) -> str:
    s = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def rnd(v: float) -> float:
    return round(v, 4) + 0.0


class Writer:
    """Emits normalised blocks and tracks the (rounded) current position."""

    def __init__(self, title: str):
        self.title = title
        self.lines = ["G21 G90 G17 G91.1", "G64"]
        self.pos = (0.0, 0.0, 0.0)
        self.feed: float | None = None
        self.n_motion = 0
        self.n_arcs = 0
        self.n_laser = 0

    def _xyz(self, p) -> str:
        return f"X{fmt(p[0])} Y{fmt(p[1])} Z{fmt(p[2])}"

    def _f(self, f: float | None) -> str:
        if f is None or f == self.feed:
            return ""
        self.feed = f
        return f" F{fmt(f)}"

    def rapid(self, x: float, y: float, z: float) -> None:
        p = (rnd(x), rnd(y), rnd(z))
        if p == self.pos:
            return
        self.lines.append("G0 " + self._xyz(p))
        self.pos = p
        self.n_motion += 1

    def line(self, x: float, y: float, z: float, f: float | None = None) -> None:
        p = (rnd(x), rnd(y), rnd(z))
        if p == self.pos:
            return
        self.lines.append("G1 " + self._xyz(p) + self._f(f))
        self.pos = p
        self.n_motion += 1

    def arc(self, cx: float, cy: float, x: float, y: float, z: float, cw: bool, f: float | None = None) -> None:
        """G2 (cw) / G3 arc about (cx, cy) to (x, y, z); a tiny arc is written as a line."""
        sx, sy, _ = self.pos
        i, j = rnd(cx - sx), rnd(cy - sy)
        ex, ey = rnd(x), rnd(y)
        r0 = math.hypot(i, j)
        ccx, ccy = sx + i, sy + j
        r1 = math.hypot(ex - ccx, ey - ccy)
        chord = math.hypot(ex - sx, ey - sy)
        if r0 < 0.05 or chord < 0.02:
            self.line(x, y, z, f)
            return
        if abs(r1 - r0) > 0.001:
            raise ValueError(f"{self.title}: arc radii differ by {abs(r1 - r0):.2e} mm (line {len(self.lines) + 1})")
        p = (ex, ey, rnd(z))
        self.lines.append(("G2 " if cw else "G3 ") + self._xyz(p) + f" I{fmt(i)} J{fmt(j)}" + self._f(f))
        self.pos = p
        self.n_motion += 1
        self.n_arcs += 1

    def arc_by_angle(self, cx, cy, r, a1, z, cw, f=None) -> None:
        self.arc(cx, cy, cx + r * math.cos(a1), cy + r * math.sin(a1), z, cw, f)

    def circle(self, cx, cy, r, a0, z0, z1, cw, f=None, pieces=4) -> None:
        """Full turn about (cx, cy) starting (and ending) at angle a0 (the tool must be there), in
        ``pieces`` arcs; Z goes linearly from z0 to z1 (a helix when they differ)."""
        sgn = -1.0 if cw else 1.0
        for k in range(1, pieces + 1):
            a = a0 + sgn * TAU * k / pieces
            self.arc_by_angle(cx, cy, r, a, z0 + (z1 - z0) * k / pieces, cw, f)

    def laser_on(self) -> None:
        self.lines.append("M3")
        self.n_laser += 1

    def laser_off(self) -> None:
        self.lines.append("M5")
        self.n_laser += 1

    def text(self) -> str:
        return "\n".join(self.lines + ["M2"]) + "\n"


# ---------------------------------------------------------------------------------------------
# Geometry helpers: path segments ('L', p) / ('A', centre, p, cw) / ('C', c1, c2, p) in 2-D
# ---------------------------------------------------------------------------------------------


def bez(p0, p1, p2, p3, t):
    u = 1.0 - t
    a, b, c, d = u * u * u, 3 * u * u * t, 3 * u * t * t, t * t * t
    return (a * p0[0] + b * p1[0] + c * p2[0] + d * p3[0], a * p0[1] + b * p1[1] + c * p2[1] + d * p3[1])


def bez_split(p0, p1, p2, p3, t=0.5):
    def lerp(a, b):
        return (a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t)

    a, b, c = lerp(p0, p1), lerp(p1, p2), lerp(p2, p3)
    d, e = lerp(a, b), lerp(b, c)
    f = lerp(d, e)
    return (p0, a, d, f), (f, e, c, p3)


def flatten_adaptive(p0, p1, p2, p3, tol, out, depth=0):
    """Flatten a cubic by recursive halving until its control points lie within ``tol`` of the chord."""
    dx, dy = p3[0] - p0[0], p3[1] - p0[1]
    L = math.hypot(dx, dy)

    def dist(q):
        if L < 1e-12:
            return math.hypot(q[0] - p0[0], q[1] - p0[1])
        return abs((q[0] - p0[0]) * dy - (q[1] - p0[1]) * dx) / L

    if depth > 18 or max(dist(p1), dist(p2)) * 0.75 <= tol:
        out.append(p3)
        return
    a, b = bez_split(p0, p1, p2, p3)
    flatten_adaptive(*a, tol, out, depth + 1)
    flatten_adaptive(*b, tol, out, depth + 1)


def flatten_uniform(p0, p1, p2, p3, seg_len, out):
    """Flatten a cubic into equal parameter steps, about ``seg_len`` long (the simple converters)."""
    L = sum(math.dist(bez(p0, p1, p2, p3, k / 16), bez(p0, p1, p2, p3, (k + 1) / 16)) for k in range(16))
    n = max(2, math.ceil(L / seg_len))
    for k in range(1, n + 1):
        out.append(bez(p0, p1, p2, p3, k / n))


def _unit(v):
    n = math.hypot(v[0], v[1])
    return (v[0] / n, v[1] / n)


def _arc_through(p, t, q):
    """Arc from p with unit tangent t ending at q: (centre, radius, cw) or None for a straight line."""
    n = (-t[1], t[0])
    d = (q[0] - p[0], q[1] - p[1])
    den = 2.0 * (d[0] * n[0] + d[1] * n[1])
    if abs(den) < 1e-9:
        return None
    s = (d[0] * d[0] + d[1] * d[1]) / den
    c = (p[0] + s * n[0], p[1] + s * n[1])
    return c, abs(s), s < 0


def biarc_fit(p0, p1, p2, p3, tol, out, depth=0):
    """Fit a cubic with tangent-continuous arc pairs (gcodetools style), halving until within tol.
    Appends ('A', centre, end, cw) or ('L', end) items."""
    if math.dist(p0, p3) < 1e-6:
        return
    t0 = _unit((p1[0] - p0[0], p1[1] - p0[1])) if math.dist(p0, p1) > 1e-9 else _unit((p2[0] - p0[0], p2[1] - p0[1]))
    t1 = _unit((p3[0] - p2[0], p3[1] - p2[1])) if math.dist(p2, p3) > 1e-9 else _unit((p3[0] - p1[0], p3[1] - p1[1]))
    v = (p3[0] - p0[0], p3[1] - p0[1])
    tt = (t0[0] + t1[0], t0[1] + t1[1])
    vt = v[0] * tt[0] + v[1] * tt[1]
    c = 1.0 - (t0[0] * t1[0] + t0[1] * t1[1])
    vv = v[0] * v[0] + v[1] * v[1]
    items = None
    if c > 1e-9:
        dd = (-vt + math.sqrt(vt * vt + 2.0 * c * vv)) / (2.0 * c)
        pm = ((p0[0] + dd * t0[0] + p3[0] - dd * t1[0]) / 2, (p0[1] + dd * t0[1] + p3[1] - dd * t1[1]) / 2)
        tm = _unit((p3[0] - dd * t1[0] - p0[0] - dd * t0[0], p3[1] - dd * t1[1] - p0[1] - dd * t0[1]))
        a1, a2 = _arc_through(p0, t0, pm), _arc_through(pm, tm, p3)
        items = []
        for a, q in ((a1, pm), (a2, p3)):
            if a is None or a[1] > 2000.0:
                items.append(("L", q))
            else:
                items.append(("A", a[0], q, a[2], a[1]))
        # error: sample the cubic, distance to the nearer piece's circle (or line)
        err = 0.0
        for k in range(1, 16):
            q = bez(p0, p1, p2, p3, k / 16)
            e = math.inf
            for it in items:
                if it[0] == "A":
                    e = min(e, abs(math.dist(q, it[1]) - it[4]))
            if all(it[0] == "L" for it in items):
                e = 0.0
            err = max(err, e)
        if err > tol or any(it[0] == "A" and it[4] < 0.2 for it in items):
            items = None
    if items is None and depth < 12 and math.dist(p0, p3) > 0.05:
        a, b = bez_split(p0, p1, p2, p3)
        biarc_fit(*a, tol, out, depth + 1)
        biarc_fit(*b, tol, out, depth + 1)
        return
    if items is None:
        out.append(("L", p3))
        return
    for it in items:
        out.append(it[:4] if it[0] == "A" else it)


def emit_path(w: Writer, start, items, z, f):
    """Cut a 2-D path of ('L', p) / ('A', centre, p, cw) items at height z."""
    for it in items:
        if it[0] == "L":
            w.line(it[1][0], it[1][1], z, f)
        else:
            _, c, p, cw = it
            w.arc(c[0], c[1], p[0], p[1], z, cw, f)


def rounded_poly(pts, radii):
    """Closed polygon with a tangent fillet of radius radii[i] at each vertex (0 = sharp).
    Returns (start point, items) starting mid-way along the first edge."""
    n = len(pts)
    corners = []  # (in_point, out_point, centre, cw) or (p, p, None, None)
    for i in range(n):
        a, b, c = pts[i - 1], pts[i], pts[(i + 1) % n]
        r = radii[i]
        u1 = _unit((b[0] - a[0], b[1] - a[1]))
        u2 = _unit((c[0] - b[0], c[1] - b[1]))
        cross = u1[0] * u2[1] - u1[1] * u2[0]
        dot = max(-1.0, min(1.0, u1[0] * u2[0] + u1[1] * u2[1]))
        turn = math.acos(dot)
        if r <= 0 or turn < 1e-6:
            corners.append((b, b, None, None))
            continue
        d = r * math.tan(turn / 2)
        pin = (b[0] - u1[0] * d, b[1] - u1[1] * d)
        pout = (b[0] + u2[0] * d, b[1] + u2[1] * d)
        left = 1.0 if cross > 0 else -1.0
        cen = (pin[0] - u1[1] * r * left, pin[1] + u1[0] * r * left)
        corners.append((pin, pout, cen, cross < 0))
    # start midway on edge corners[0].out -> corners[1].in
    s0 = corners[0][1]
    s1 = corners[1 % n][0]
    start = ((s0[0] + s1[0]) / 2, (s0[1] + s1[1]) / 2)
    items = []
    for k in range(1, n + 1):
        pin, pout, cen, cw = corners[k % n]
        items.append(("L", pin))
        if cen is not None:
            items.append(("A", cen, pout, cw))
    items.append(("L", start))
    return start, items


def circle_items(cx, cy, r, a0, cw, pieces=4):
    sgn = -1.0 if cw else 1.0
    start = (cx + r * math.cos(a0), cy + r * math.sin(a0))
    items = []
    for k in range(1, pieces + 1):
        a = a0 + sgn * TAU * k / pieces
        items.append(("A", (cx, cy), (cx + r * math.cos(a), cy + r * math.sin(a)), cw))
    return start, items


def path_length(start, items):
    L, p = 0.0, start
    for it in items:
        L += math.dist(p, it[1] if it[0] == "L" else it[2])
        p = it[1] if it[0] == "L" else it[2]
    return L


# ---------------------------------------------------------------------------------------------
# (a) 3-D CAM programs
# ---------------------------------------------------------------------------------------------

SAFE_Z = 5.0


def helix_entry(w, cx, cy, r, z_from, z_to, turns, f):
    """Helical ramp (G3, 4 arcs per turn) from z_from to z_to at radius r, starting at angle 0."""
    n = int(turns * 4)
    for k in range(1, n + 1):
        a = TAU * k / 4
        w.arc_by_angle(cx, cy, r, a, z_from + (z_to - z_from) * k / n, False, f)


def circ_pocket(w, cx, cy, r_wall, depth, layer, step, f_cut, f_plunge):
    z_prev = 0.0
    w.rapid(cx + 2.0, cy, SAFE_Z)
    w.rapid(cx + 2.0, cy, 0.5)
    w.line(cx + 2.0, cy, 0.0, f_plunge)
    n_layers = math.ceil(depth / layer - 1e-9)
    for li in range(1, n_layers + 1):
        z = -min(depth, li * layer)
        helix_entry(w, cx, cy, 2.0, z_prev, z, 2, f_plunge)
        w.circle(cx, cy, 2.0, 0.0, z, z, False, f_cut)
        r = 2.0
        while r < r_wall - 1e-9:
            r = min(r + step, r_wall)
            w.line(cx + r, cy, z, f_cut)
            w.circle(cx, cy, r, 0.0, z, z, False, f_cut, pieces=2)
        w.circle(cx, cy, r_wall, 0.0, z, z, False, f_cut)  # finishing lap
        w.line(cx + r_wall - 0.5, cy, z + 0.2, f_cut)  # lift off the wall
        w.line(cx + 2.0, cy, z, f_cut)
        z_prev = z
    w.rapid(cx + 2.0, cy, SAFE_Z)


def rect_pocket(w, cx, cy, hx, hy, rc, depth, layer, step, f_cut, f_plunge):
    """Rounded-rectangle pocket: offsets from the centre line out to the wall (corner radius rc);
    inner offsets have smaller radii and become sharp."""
    offs = []
    k = 0
    while True:
        d = k * step
        ax, ay = hx - d, hy - d
        if ay <= 0.3:
            break
        offs.append((ax, ay, max(0.0, rc - d)))
        k += 1
    offs.reverse()
    core = hx - hy  # half length of the centre line
    w.rapid(cx, cy, SAFE_Z)
    w.rapid(cx, cy, 0.5)
    w.line(cx, cy, 0.0, f_plunge)
    z_prev = 0.0
    n_layers = math.ceil(depth / layer - 1e-9)
    for li in range(1, n_layers + 1):
        z = -min(depth, li * layer)
        # ramp down along the centre line (zig-zag)
        w.line(cx + core, cy, (z_prev + z) / 2, f_plunge)
        w.line(cx - core, cy, z, f_plunge)
        w.line(cx, cy, z, f_cut)
        for ax, ay, r in offs:
            pts = [(cx + ax, cy - ay), (cx + ax, cy + ay), (cx - ax, cy + ay), (cx - ax, cy - ay)]
            start, items = rounded_poly(pts, [r] * 4)
            w.line(start[0], start[1], z, f_cut)
            emit_path(w, start, items, z, f_cut)
        w.line(cx + core, cy, z + 0.2, f_cut)
        w.line(cx, cy, z, f_cut)
        z_prev = z
    w.rapid(cx, cy, SAFE_Z)


def trochoidal_slot(w, cx, cy, R, a_from, a_to, rl, adv, z, f):
    """Trochoidal slot along an arc of radius R: per step a cutting half-circle, a return half-circle
    and a short step line."""
    n = max(2, int(abs(R * (a_to - a_from)) / adv))
    pts = []
    for k in range(n + 1):
        a = a_from + (a_to - a_from) * k / n
        p = (cx + R * math.cos(a), cy + R * math.sin(a))
        heading = a + (math.pi / 2 if a_to > a_from else -math.pi / 2)
        pts.append((p, heading))
    p, h = pts[0]
    side = h + math.pi / 2
    w.rapid(p[0] + rl * math.cos(side), p[1] + rl * math.sin(side), SAFE_Z)
    w.rapid(p[0] + rl * math.cos(side), p[1] + rl * math.sin(side), z + 1.0)
    w.line(p[0] + rl * math.cos(side), p[1] + rl * math.sin(side), z, f / 3)
    for idx, (p, h) in enumerate(pts):
        left = h + math.pi / 2
        if idx:
            w.line(p[0] + rl * math.cos(left), p[1] + rl * math.sin(left), z, f)
        # cutting half (front, clockwise from left to right through the heading)
        w.arc_by_angle(p[0], p[1], rl, h, z, True, f)
        w.arc_by_angle(p[0], p[1], rl, h - math.pi / 2, z, True, f)
        # return half (rear), clockwise back to the left side
        w.arc_by_angle(p[0], p[1], rl, h - math.pi, z, True, f)
        w.arc_by_angle(p[0], p[1], rl, left, z, True, f)
    w.rapid(w.pos[0], w.pos[1], SAFE_Z)


def fillet_rings(w, cx, cy, r_boss, r_fil, r_tool, n, f):
    """Ball-nose fillet around a round boss: one helical lap (down dz) per ring, a short radial
    XYZ step between rings (climb, clockwise)."""
    first = True
    for k in range(n + 1):
        th = (math.pi / 2) * k / n
        rr = r_boss + (r_fil + r_tool) * math.sin(th)
        zz = -(r_fil + r_tool) * (1 - math.cos(th))
        if first:
            w.rapid(cx + rr, cy, SAFE_Z)
            w.rapid(cx + rr, cy, zz + 1.0)
            w.line(cx + rr, cy, zz, f / 3)
            first = False
        else:
            w.line(cx + rr, cy, zz, f)
        w.circle(cx, cy, rr, 0.0, zz, zz, True, f)
    w.rapid(w.pos[0], w.pos[1], SAFE_Z)


def engrave_lissajous(w, cx, cy, ax, ay, n_pts, f):
    """3-D engraving along a Lissajous figure, depth varying: short XYZ lines."""

    def pt(t):
        return (cx + ax * math.sin(3 * t + 0.5), cy + ay * math.sin(2 * t), -0.4 - 0.3 * math.sin(5 * t) ** 2)

    p = pt(0.0)
    w.rapid(p[0], p[1], SAFE_Z)
    w.rapid(p[0], p[1], 1.0)
    w.line(p[0], p[1], p[2], 3000.0)
    for k in range(1, n_pts + 1):
        p = pt(TAU * k / n_pts)
        w.line(p[0], p[1], p[2], f)
    w.rapid(p[0], p[1], SAFE_Z)


def ramped_profile(w, start, items, z_top, z_bot, passes, f):
    """Profile a closed 2-D path in passes; each pass ramps down over the whole lap (Z changes on
    lines and arcs), then a last flat lap at the bottom."""
    L = path_length(start, items)
    w.rapid(start[0], start[1], SAFE_Z)
    w.rapid(start[0], start[1], z_top + 1.0)
    w.line(start[0], start[1], z_top, f / 2)
    z = z_top
    for pidx in range(1, passes + 1):
        z_end = z_top + (z_bot - z_top) * pidx / passes
        s, p = 0.0, start
        for it in items:
            q = it[1] if it[0] == "L" else it[2]
            if it[0] == "L":
                seg = math.dist(p, q)
            else:
                r = math.dist(it[1], p)
                a0 = math.atan2(p[1] - it[1][1], p[0] - it[1][0])
                a1 = math.atan2(q[1] - it[1][1], q[0] - it[1][0])
                da = (a0 - a1) if it[3] else (a1 - a0)
                da %= TAU
                seg = r * da
            s += seg
            zz = z + (z_end - z) * s / L
            if it[0] == "L":
                w.line(q[0], q[1], zz, f)
            else:
                w.arc(it[1][0], it[1][1], q[0], q[1], zz, it[3], f)
            p = q
        z = z_end
    emit_path(w, start, items, z_bot, f)
    w.rapid(start[0], start[1], SAFE_Z)


def cam_outline(cx, cy, scale):
    """A cam lobe: two circles joined by tangent lines (closed, CCW), as path items."""
    r1, r2, d = 14.0 * scale, 7.0 * scale, 26.0 * scale
    c1, c2 = (cx, cy), (cx + d, cy)
    beta = math.asin((r1 - r2) / d)
    up1 = (c1[0] + r1 * math.cos(math.pi / 2 + beta), c1[1] + r1 * math.sin(math.pi / 2 + beta))
    up2 = (c2[0] + r2 * math.cos(math.pi / 2 + beta), c2[1] + r2 * math.sin(math.pi / 2 + beta))
    dn1 = (c1[0] + r1 * math.cos(-math.pi / 2 - beta), c1[1] + r1 * math.sin(-math.pi / 2 - beta))
    dn2 = (c2[0] + r2 * math.cos(-math.pi / 2 - beta), c2[1] + r2 * math.sin(-math.pi / 2 - beta))
    start = dn1
    items = [("L", dn2), ("A", c2, up2, False), ("L", up1), ("A", c1, dn1, False)]
    # split the big arc so no arc exceeds 180 degrees
    left = (c1[0] - r1, c1[1])
    items[-1:] = [("A", c1, left, False), ("A", c1, dn1, False)]
    return start, items


def gen_cam3d_a() -> Writer:
    w = Writer("cam3d_a")
    circ_pocket(w, 60.0, 60.0, 17.0, 6.0, 1.5, 2.5, 12000.0, 4500.0)
    rect_pocket(w, 170.0, 60.0, 37.0, 22.0, 3.0, 6.0, 2.0, 2.5, 12000.0, 4500.0)
    trochoidal_slot(w, 110.0, 140.0, 50.0, math.radians(200), math.radians(340), 3.0, 1.2, -3.0, 15000.0)
    trochoidal_slot(w, 110.0, 140.0, 50.0, math.radians(340), math.radians(200), 3.0, 1.2, -6.0, 15000.0)
    fillet_rings(w, 250.0, 150.0, 20.0, 5.0, 3.0, 18, 12000.0)
    engrave_lissajous(w, 250.0, 60.0, 30.0, 22.0, 400, 6000.0)
    s, items = cam_outline(40.0, 170.0, 1.0)
    ramped_profile(w, s, items, 0.0, -4.5, 3, 12000.0)
    w.rapid(0.0, 0.0, SAFE_Z)
    return w


def surface(x, y):
    bump = 2.5 * math.exp(-((x - 80.0) ** 2 + (y - 60.0) ** 2) / 900.0)
    return -3.0 + bump - 0.6 * math.cos(x / 9.0) * math.sin(y / 11.0)


def raster_row(y, x0, x1, tol, max_seg):
    """Points along a row, split where the surface deviates from the chord by more than tol."""
    res = []

    def rec(a, b, depth=0):
        m = (a + b) / 2
        zm = surface(m, y)
        zl = (surface(a, y) + surface(b, y)) / 2
        if depth < 12 and (abs(b - a) > max_seg or abs(zm - zl) > tol):
            rec(a, m, depth + 1)
            rec(m, b, depth + 1)
        else:
            res.append(b)

    rec(x0, x1)
    return [x0] + res


def gen_cam3d_b() -> Writer:
    w = Writer("cam3d_b")
    # 1. raster finishing over a smooth surface, rows along X, helical U-turn links
    x0, x1, y0, step, rows = 20.0, 140.0, 20.0, 2.5, 33
    w.rapid(x0, y0, SAFE_Z)
    w.rapid(x0, y0, surface(x0, y0) + 1.0)
    w.line(x0, y0, surface(x0, y0), 3000.0)
    for r in range(rows):
        y = y0 + r * step
        xs = raster_row(y, x0, x1, 0.004, 2.0)
        if r % 2:
            xs = xs[::-1]
        for x in xs[1:]:
            w.line(x, y, surface(x, y), 18000.0)
        if r + 1 < rows:
            xe = xs[-1]
            yn = y + step
            cw = r % 2 == 0  # at x1 turning up: clockwise; at x0: counter-clockwise
            w.arc(xe, y + step / 2, xe, yn, surface(xe, yn), cw, 18000.0)
    w.rapid(w.pos[0], w.pos[1], SAFE_Z)
    # 2. helical bore, 10 turns at 1 mm pitch, then a flat lap and a lift
    cx, cy, r = 200.0, 50.0, 8.0
    w.rapid(cx + r, cy, SAFE_Z)
    w.rapid(cx + r, cy, 0.5)
    w.line(cx + r, cy, 0.0, 3000.0)
    helix_entry(w, cx, cy, r, 0.0, -10.0, 10, 6000.0)
    w.circle(cx, cy, r, 0.0, -10.0, -10.0, False, 6000.0)
    w.line(cx + r - 1.0, cy, -9.8, 6000.0)
    w.rapid(cx + r - 1.0, cy, SAFE_Z)
    # 3. hemisphere waterline finishing: rings at 0.4 mm steps in Z, short ramp between rings
    cx, cy, R, rt = 220.0, 130.0, 25.0, 3.0
    first = True
    zs = [-0.4 * k for k in range(0, 63)]
    for zz in zs:
        # ball-nose centre on the offset sphere (radius R + rt) about the pole at z = -rt
        rr = math.sqrt(max(0.0, (R + rt) ** 2 - (R + rt + zz) ** 2)) if (R + rt + zz) > 0 else R + rt
        rr = max(rr, 1.0)
        if first:
            w.rapid(cx + rr, cy, SAFE_Z)
            w.rapid(cx + rr, cy, zz + 1.0)
            w.line(cx + rr, cy, zz, 3000.0)
            first = False
        else:
            w.line(cx + rr, cy, zz, 12000.0)
        w.circle(cx, cy, rr, 0.0, zz, zz, True, 12000.0, pieces=4)
    w.rapid(w.pos[0], w.pos[1], SAFE_Z)
    # 4. a cam-lobe profile at two sizes, ramped in 4 passes
    s, items = cam_outline(170.0, 180.0, 1.2)
    ramped_profile(w, s, items, 0.0, -6.0, 4, 12000.0)
    s, items = cam_outline(40.0, 150.0, 0.8)
    ramped_profile(w, s, items, 0.0, -3.0, 2, 12000.0)
    # 5. 3-D spiral finishing on the raster surface (short XYZ lines, 1 mm apart)
    cx, cy = 80.0, 60.0
    n = 900
    p0 = (cx + 2.0, cy)
    w.rapid(p0[0], p0[1], SAFE_Z)
    w.rapid(p0[0], p0[1], surface(*p0) + 1.0)
    w.line(p0[0], p0[1], surface(*p0), 3000.0)
    for k in range(1, n + 1):
        th = 0.11 * k**0.93
        rr = 2.0 + 0.9 * th
        x, y = cx + rr * math.cos(th), cy + rr * math.sin(th)
        w.line(x, y, surface(x, y), 15000.0)
    w.rapid(w.pos[0], w.pos[1], SAFE_Z)
    w.rapid(0.0, 0.0, SAFE_Z)
    return w


# ---------------------------------------------------------------------------------------------
# (b) SVG outlines
# ---------------------------------------------------------------------------------------------

# Glyph outlines on a 100-unit em (y up), as closed contours of ('M', p), ('L', p), ('C', c1, c2, p).
GLYPHS = {
    "J": [
        [
            ("M", (60, 100)),
            ("L", (80, 100)),
            ("L", (80, 32)),
            ("C", (80, 8), (66, -2), (45, -2)),
            ("C", (25, -2), (11, 9), (7, 27)),
            ("L", (26, 31)),
            ("C", (29, 21), (35, 16), (44, 16)),
            ("C", (55, 16), (60, 23), (60, 34)),
            ("L", (60, 100)),
        ]
    ],
    "A": [
        [
            ("M", (0, 0)),
            ("L", (20, 0)),
            ("L", (27, 22)),
            ("L", (63, 22)),
            ("L", (70, 0)),
            ("L", (90, 0)),
            ("L", (56, 96)),
            ("C", (54, 99), (52, 100), (49, 100)),
            ("L", (41, 100)),
            ("C", (38, 100), (36, 99), (34, 96)),
            ("L", (0, 0)),
        ],
        [("M", (33, 38)), ("L", (57, 38)), ("L", (45, 75)), ("L", (33, 38))],
    ],
    "X": [
        [
            ("M", (0, 0)),
            ("L", (22, 0)),
            ("L", (43, 35)),
            ("L", (64, 0)),
            ("L", (86, 0)),
            ("L", (54, 51)),
            ("L", (84, 100)),
            ("L", (62, 100)),
            ("L", (43, 67)),
            ("L", (24, 100)),
            ("L", (2, 100)),
            ("L", (32, 51)),
            ("L", (0, 0)),
        ]
    ],
    "C": [
        [
            ("M", (86, 68)),
            ("C", (79, 90), (63, 102), (45, 102)),
            ("C", (18, 102), (0, 80), (0, 50)),
            ("C", (0, 20), (18, -2), (45, -2)),
            ("C", (64, -2), (79, 10), (87, 31)),
            ("L", (68, 37)),
            ("C", (63, 23), (55, 16), (45, 16)),
            ("C", (29, 16), (20, 30), (20, 50)),
            ("C", (20, 70), (29, 84), (45, 84)),
            ("C", (56, 84), (63, 77), (67, 62)),
            ("L", (86, 68)),
        ]
    ],
    "N": [
        [
            ("M", (0, 0)),
            ("L", (18, 0)),
            ("L", (18, 64)),
            ("L", (61, 0)),
            ("L", (80, 0)),
            ("L", (80, 100)),
            ("L", (62, 100)),
            ("L", (62, 36)),
            ("L", (19, 100)),
            ("L", (0, 100)),
            ("L", (0, 0)),
        ]
    ],
    "O": [
        [
            ("M", (45, -2)),
            ("C", (72, -2), (90, 20), (90, 50)),
            ("C", (90, 80), (72, 102), (45, 102)),
            ("C", (18, 102), (0, 80), (0, 50)),
            ("C", (0, 20), (18, -2), (45, -2)),
        ],
        [
            ("M", (45, 16)),
            ("C", (29, 16), (20, 30), (20, 50)),
            ("C", (20, 70), (29, 84), (45, 84)),
            ("C", (61, 84), (70, 70), (70, 50)),
            ("C", (70, 30), (61, 16), (45, 16)),
        ],
    ],
    "S": [
        [
            ("M", (8, 28)),
            ("C", (10, 8), (26, -2), (45, -2)),
            ("C", (68, -2), (84, 10), (84, 30)),
            ("C", (84, 50), (68, 55), (50, 59)),
            ("C", (34, 63), (27, 66), (27, 74)),
            ("C", (27, 81), (34, 86), (45, 86)),
            ("C", (56, 86), (62, 80), (64, 72)),
            ("L", (82, 76)),
            ("C", (79, 93), (65, 102), (45, 102)),
            ("C", (23, 102), (8, 91), (8, 72)),
            ("C", (8, 53), (23, 47), (41, 43)),
            ("C", (58, 39), (65, 37), (65, 28)),
            ("C", (65, 20), (57, 14), (45, 14)),
            ("C", (34, 14), (27, 20), (26, 31)),
            ("L", (8, 28)),
        ]
    ],
}
ADVANCE = {"J": 95, "A": 95, "X": 92, "C": 95, "N": 92, "O": 98, "S": 92, " ": 50}


def glyph_paths(text, x0, y0, size, tracking=0.0):
    """Contours of a text line as lists of ('M'/'L'/'C', points...) in mm."""
    s = size / 100.0
    out = []
    x = x0
    for ch in text:
        for contour in GLYPHS.get(ch, []):
            out.append([(op[0],) + tuple((x + q[0] * s, y0 + q[1] * s) for q in op[1:]) for op in contour])
        x += (ADVANCE[ch] + tracking) * s
    return out


def svg_path_to_items(contour, mode, tol, seg_len):
    """Convert an SVG-like contour into a start point and line/arc items.
    mode 'flat-adaptive' | 'flat-uniform' | 'biarc'."""
    start = contour[0][1]
    items = []
    p = start
    for op in contour[1:]:
        if op[0] == "L":
            if math.dist(p, op[1]) > 1e-9:
                items.append(("L", op[1]))
            p = op[1]
        elif op[0] == "C":
            if mode == "biarc":
                biarc_fit(p, op[1], op[2], op[3], tol, items)
            else:
                pts = []
                if mode == "flat-adaptive":
                    flatten_adaptive(p, op[1], op[2], op[3], tol, pts)
                else:
                    flatten_uniform(p, op[1], op[2], op[3], seg_len, pts)
                items.extend(("L", q) for q in pts)
            p = op[3]
        elif op[0] == "A":  # ('A', centre, end, cw)
            items.append(("A", op[1], op[2], op[3]))
            p = op[2]
    return start, items


def cut_contour(w, start, items, f, laser=False, z=0.0):
    w.rapid(start[0], start[1], z)
    if laser:
        w.laser_on()
    emit_path(w, start, items, z, f)
    if laser:
        w.laser_off()


def swoosh(x0, y0, length, height, thick):
    """A closed swoosh made of two cubic Béziers on each side."""
    a = (x0, y0)
    b = (x0 + length, y0 + height)
    return [
        ("M", a),
        ("C", (x0 + length * 0.3, y0 - height * 0.6), (x0 + length * 0.7, y0 + height * 0.2), b),
        (
            "C",
            (x0 + length * 0.72, y0 + height * 0.2 + thick),
            (x0 + length * 0.28, y0 - height * 0.6 + 2 * thick),
            (x0 + thick * 0.3, y0 + thick * 0.6),
        ),
        ("L", a),
    ]


def gen_svg_logo_a() -> Writer:
    w = Writer("svg_logo_a")
    f = 18000.0
    w.rapid(12.0, 12.0, 0.0)
    w.laser_on()  # one laser-on for the whole job (GRBL-style laser mode: G0 is dark)
    # frame: rounded rectangle (SVG rect with rx) -> lines + G3 quarter arcs, and an inner one
    for x0, y0, x1, y1, rc in ((10.0, 10.0, 330.0, 150.0, 12.0), (16.0, 16.0, 324.0, 144.0, 6.0)):
        pts = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
        start, items = rounded_poly(pts, [rc] * 4)
        cut_contour(w, start, items, f)
    # title text, adaptive flattening at 5 um (fine converters)
    for contour in glyph_paths("JAXCNC", 30.0, 70.0, 50.0, tracking=8.0):
        start, items = svg_path_to_items(contour, "flat-adaptive", 0.005, 0.0)
        cut_contour(w, start, items, f)
    # subtitle, coarser uniform flattening (0.5 mm pieces)
    for contour in glyph_paths("OSCAJ NXS", 40.0, 28.0, 22.0, tracking=6.0):
        start, items = svg_path_to_items(contour, "flat-uniform", 0.0, 0.5)
        cut_contour(w, start, items, f)
    # swooshes under the title
    for k in range(3):
        c = swoosh(30.0 + 8.0 * k, 58.0 - 3.5 * k, 270.0 - 16.0 * k, 6.0, 1.6)
        start, items = svg_path_to_items(c, "flat-adaptive", 0.005, 0.0)
        cut_contour(w, start, items, f)
    # dots (SVG circles -> four arcs) along the frame, of two sizes
    for k in range(18):
        x = 24.0 + k * 17.3
        for y, r in ((134.0, 2.2), (22.0, 1.2)):
            start, items = circle_items(x, y, r, 0.0, False)
            cut_contour(w, start, items, f)
    w.laser_off()
    w.rapid(0.0, 0.0, 0.0)
    return w


def involute_gear(cx, cy, teeth, module, pts_per_flank=6):
    """Closed gear outline: involute flanks as polylines (converter output), tip and root as arcs."""
    rp = teeth * module / 2.0
    rb = rp * math.cos(math.radians(20.0))
    ra = rp + module
    rf = rp - 1.25 * module
    inv = lambda a: math.tan(a) - a  # noqa: E731
    a_p = math.acos(rb / rp)
    half_tooth = math.pi / (2 * teeth) + inv(a_p)
    a_tip = math.acos(rb / ra)
    items = []
    pitch = TAU / teeth
    start = None
    for t in range(teeth):
        base = t * pitch
        # rising flank (from the root circle up to the tip), centre angle base - half_tooth
        flank = []
        r_start = max(rb, rf)
        for k in range(pts_per_flank + 1):
            r = r_start + (ra - r_start) * k / pts_per_flank
            al = math.acos(min(1.0, rb / r))
            ang = base - half_tooth + inv(al)
            flank.append((cx + r * math.cos(ang), cy + r * math.sin(ang)))
        ang_root0 = base - half_tooth
        p_root = (cx + rf * math.cos(ang_root0), cy + rf * math.sin(ang_root0))
        if start is None:
            start = p_root
        else:
            items.append(("A", (cx, cy), p_root, False))  # root arc (CCW)
        if rf < rb:
            items.append(("L", flank[0]))
        items.extend(("L", q) for q in flank[1:])
        tip_a1 = base + half_tooth - inv(a_tip)
        items.append(("A", (cx, cy), (cx + ra * math.cos(tip_a1), cy + ra * math.sin(tip_a1)), False))  # tip
        falling = []
        for k in range(pts_per_flank, -1, -1):
            r = r_start + (ra - r_start) * k / pts_per_flank
            al = math.acos(min(1.0, rb / r))
            ang = base + half_tooth - inv(al)
            falling.append((cx + r * math.cos(ang), cy + r * math.sin(ang)))
        items.extend(("L", q) for q in falling[1:])
        ang_root1 = base + half_tooth
        if rf < rb:
            items.append(("L", (cx + rf * math.cos(ang_root1), cy + rf * math.sin(ang_root1))))
    items.append(("A", (cx, cy), start, False))
    return start, items


def star_path(cx, cy, n, r_out, r_in, fillet, rot=0.0):
    pts = []
    for k in range(2 * n):
        r = r_out if k % 2 == 0 else r_in
        a = rot + math.pi * k / n
        pts.append((cx + r * math.cos(a), cy + r * math.sin(a)))
    return rounded_poly(pts, [fillet if k % 2 == 0 else fillet * 0.5 for k in range(2 * n)])


def petal(cx, cy, ang, r0, r1, width):
    """A leaf: two cubic Béziers between radius r0 and r1 along direction ang."""
    c, s = math.cos(ang), math.sin(ang)

    def P(u, v):
        return (cx + u * c - v * s, cy + u * s + v * c)

    a, b = P(r0, 0.0), P(r1, 0.0)
    L = r1 - r0
    return [
        ("M", a),
        ("C", P(r0 + 0.25 * L, width), P(r0 + 0.7 * L, width * 0.9), b),
        ("C", P(r0 + 0.7 * L, -width * 0.6), P(r0 + 0.3 * L, -width * 1.1), a),
    ]


def banner(x0, y0, length, amp, thick, waves):
    """A wavy closed band: upper and lower edges as chains of cubic Béziers."""
    n = waves * 2
    dx = length / n
    top, bot = [], []
    for k in range(n + 1):
        x = x0 + k * dx
        top.append((x, y0 + thick + amp * math.sin(math.pi * k / 2)))
        bot.append((x, y0 + amp * math.sin(math.pi * k / 2)))
    ops = [("M", bot[0])]

    def chain(pts):
        for k in range(1, len(pts)):
            a, b = pts[k - 1], pts[k]
            h = (b[0] - a[0]) / 3.0
            ops.append(("C", (a[0] + h, a[1]), (b[0] - h, b[1]), b))

    chain(bot)
    ops.append(("L", top[-1]))
    chain(top[::-1])
    ops.append(("L", bot[0]))
    return ops


def gen_svg_logo_b() -> Writer:
    w = Writer("svg_logo_b")
    rng = random.Random(20261122)
    f = 15000.0
    w.rapid(60.0, 60.0, 0.0)
    w.laser_on()
    # two gears (polyline flanks + arcs), with hub holes (circles) and lightening holes
    for cx, cy, teeth, m in ((80.0, 80.0, 30, 2.0), (152.5, 80.0, 18, 2.0)):
        start, items = involute_gear(cx, cy, teeth, m)
        cut_contour(w, start, items, f)
        start, items = circle_items(cx, cy, 4.0 + teeth / 6.0, 0.0, True)
        cut_contour(w, start, items, f)
        if teeth > 20:
            for k in range(6):
                a = TAU * k / 6
                hx, hy = cx + 17.0 * math.cos(a), cy + 17.0 * math.sin(a)
                start, items = circle_items(hx, hy, 4.5, a, True)
                cut_contour(w, start, items, f)
    # a star with filleted points
    start, items = star_path(240.0, 80.0, 9, 34.0, 18.0, 2.0, rot=0.1)
    cut_contour(w, start, items, f)
    # a ring of petals, fitted with biarcs (gcodetools style, 10 um)
    for k in range(16):
        ang = TAU * k / 16 + 0.05
        c = petal(240.0, 80.0, ang, 36.0, 58.0 + rng.uniform(-2.0, 2.0), 5.0 + rng.uniform(-0.5, 0.5))
        start, items = svg_path_to_items(c, "biarc", 0.01, 0.0)
        cut_contour(w, start, items, f)
    # wavy banners: biarc-fitted, and a flattened one
    for k, mode in enumerate(("biarc", "flat-uniform", "biarc")):
        c = banner(20.0, 168.0 + 16.0 * k, 300.0, 4.0, 6.0, 6 + 2 * k)
        start, items = svg_path_to_items(c, mode, 0.01, 0.4)
        cut_contour(w, start, items, f)
    # text on the banner area, biarc-fitted glyphs
    for contour in glyph_paths("OSCAN JAX", 40.0, 225.0, 28.0, tracking=10.0):
        start, items = svg_path_to_items(contour, "biarc", 0.01, 0.0)
        cut_contour(w, start, items, f)
    # scattered blobs: closed Bézier loops through random points (Catmull-Rom -> cubic), flattened
    for k in range(10):
        cx, cy = 40.0 + 28.0 * k, 152.0 + rng.uniform(-2.0, 2.0)
        n = 7
        pts = []
        for i in range(n):
            a = TAU * i / n
            r = 7.0 + rng.uniform(-2.5, 2.5)
            pts.append((cx + r * math.cos(a), cy + r * math.sin(a)))
        ops = [("M", pts[0])]
        for i in range(n):
            p0, p1, p2, p3 = pts[i - 1], pts[i], pts[(i + 1) % n], pts[(i + 2) % n]
            c1 = (p1[0] + (p2[0] - p0[0]) / 6, p1[1] + (p2[1] - p0[1]) / 6)
            c2 = (p2[0] - (p3[0] - p1[0]) / 6, p2[1] - (p3[1] - p1[1]) / 6)
            ops.append(("C", c1, c2, p2))
        start, items = svg_path_to_items(ops, "flat-adaptive" if k % 2 else "biarc", 0.01, 0.0)
        cut_contour(w, start, items, f)
    w.laser_off()
    w.rapid(0.0, 0.0, 0.0)
    return w


# ---------------------------------------------------------------------------------------------
# (c) laser parts
# ---------------------------------------------------------------------------------------------


def _start_dir(start, items):
    it = items[0]
    if it[0] == "L":
        q = it[1]
        return _unit((q[0] - start[0], q[1] - start[1]))
    c, cw = it[1], it[3]
    v = (start[0] - c[0], start[1] - c[1])
    return _unit((v[1], -v[0]) if cw else (-v[1], v[0]))


def line_lead_in(w, start, items, f, lead=1.5, left=False):
    """Pierce `lead` mm off the contour's start, square to its first direction (on the right: the
    outside of a counter-clockwise contour; ``left`` for the inside), then a straight lead-in."""
    d = _start_dir(start, items)
    sg = 1.0 if left else -1.0
    pierce = (start[0] - sg * d[1] * lead, start[1] + sg * d[0] * lead)
    w.rapid(pierce[0], pierce[1], 0.0)
    w.laser_on()
    w.line(start[0], start[1], 0.0, f)
    emit_path(w, start, items, 0.0, f)
    w.laser_off()


def hole(w, cx, cy, r, f):
    """Small hole: pierce at the centre, straight lead-in, a full turn in two arcs, M5."""
    w.rapid(cx, cy, 0.0)
    w.laser_on()
    w.line(cx + r, cy, 0.0, f)
    w.arc_by_angle(cx, cy, r, math.pi, 0.0, False, f)
    w.arc_by_angle(cx, cy, r, 0.0, 0.0, False, f)
    w.laser_off()


def slot_items(cx, cy, half_len, r, ang):
    c, s = math.cos(ang), math.sin(ang)
    a = (cx - half_len * c, cy - half_len * s)
    b = (cx + half_len * c, cy + half_len * s)
    n = (-s * r, c * r)
    start = (a[0] - n[0], a[1] - n[1])
    items = [
        ("L", (b[0] - n[0], b[1] - n[1])),
        ("A", b, (b[0] + n[0], b[1] + n[1]), False),
        ("L", (a[0] + n[0], a[1] + n[1])),
        ("A", a, start, False),
    ]
    return start, items


def gen_laser_parts_a() -> Writer:
    """A nest of 8 x 6 brackets: a rounded rectangle with two holes and a slot each."""
    w = Writer("laser_parts_a")
    f_cut, f_hole = 9000.0, 4800.0
    for row in range(6):
        cols = range(8) if row % 2 == 0 else range(7, -1, -1)
        for col in cols:
            x0, y0 = 12.0 + col * 34.0, 12.0 + row * 26.0
            # inner features first
            hole(w, x0 + 5.0, y0 + 11.0, 1.6, f_hole)
            hole(w, x0 + 25.0, y0 + 11.0, 1.6, f_hole)
            s, items = slot_items(x0 + 15.0, y0 + 5.0, 4.0, 1.25, 0.0)
            w.rapid(x0 + 15.0, y0 + 5.0, 0.0)
            w.laser_on()
            w.line(s[0], s[1], 0.0, f_hole)
            emit_path(w, s, items, 0.0, f_hole)
            w.laser_off()
            # outer contour: rounded rectangle with a notch, corners r 2, notch corners sharp
            pts = [
                (x0, y0),
                (x0 + 30.0, y0),
                (x0 + 30.0, y0 + 16.0),
                (x0 + 19.0, y0 + 16.0),
                (x0 + 19.0, y0 + 19.0),
                (x0 + 11.0, y0 + 19.0),
                (x0 + 11.0, y0 + 16.0),
                (x0, y0 + 16.0),
            ]
            s, items = rounded_poly(pts, [2.0, 2.0, 2.0, 0.0, 1.0, 1.0, 0.0, 2.0])
            line_lead_in(w, s, items, f_cut)
    w.rapid(0.0, 0.0, 0.0)
    return w


def arc_lead_in(w, start, items, f, r=1.0, left=False):
    """Pierce off the contour (right of its first direction, or ``left``), then a quarter-arc
    lead-in that meets the contour tangentially."""
    d = _start_dir(start, items)
    sg = 1.0 if left else -1.0
    nrm = (-d[1] * sg, d[0] * sg)
    c = (start[0] + nrm[0] * r, start[1] + nrm[1] * r)
    pierce = (c[0] - d[0] * r, c[1] - d[1] * r)
    w.rapid(pierce[0], pierce[1], 0.0)
    w.laser_on()
    w.arc(c[0], c[1], start[0], start[1], 0.0, not left, f)
    emit_path(w, start, items, 0.0, f)
    w.laser_off()


def gen_laser_parts_b() -> Writer:
    """A random (seeded) nest of small parts: washers, filleted stars, hex nuts, small gears, tags."""
    w = Writer("laser_parts_b")
    rng = random.Random(4242)
    cell = 24.0
    for row in range(7):
        cols = range(10) if row % 2 == 0 else range(9, -1, -1)
        for col in cols:
            cx, cy = 14.0 + col * cell, 14.0 + row * cell
            kind = rng.choice(["washer", "star", "hex", "gear", "tag"])
            fc = rng.choice([6000.0, 7500.0, 9000.0, 12000.0])
            if kind == "washer":
                r_out, r_in = rng.uniform(7.0, 10.0), rng.uniform(2.0, 4.5)
                hole(w, cx, cy, r_in, fc * 0.6)
                s, items = circle_items(cx, cy, r_out, rng.uniform(0, TAU), True, pieces=4)
                arc_lead_in(w, s, items, fc, left=True)
            elif kind == "star":
                n = rng.choice([5, 6, 7, 8])
                hole(w, cx, cy, 1.5, fc * 0.6)
                r_out, r_in, rot = rng.uniform(9.0, 10.5), rng.uniform(4.5, 6.0), rng.uniform(0, 1)
                s, items = star_path(cx, cy, n, r_out, r_in, 0.8, rot=rot)
                line_lead_in(w, s, items, fc, lead=1.0)
            elif kind == "hex":
                r = rng.uniform(8.0, 10.5)
                hole(w, cx, cy, r * 0.45, fc * 0.6)
                pts = [(cx + r * math.cos(TAU * k / 6 + 0.2), cy + r * math.sin(TAU * k / 6 + 0.2)) for k in range(6)]
                s, items = rounded_poly(pts, [0.6] * 6)
                line_lead_in(w, s, items, fc, lead=1.0)
            elif kind == "gear":
                teeth = rng.choice([12, 14, 16])
                m = 19.0 / (teeth + 2)
                hole(w, cx, cy, 2.0, fc * 0.6)
                s, items = involute_gear(cx, cy, teeth, m, pts_per_flank=4)
                line_lead_in(w, s, items, fc, lead=0.8)
            else:  # tag: rounded rectangle with a hole and a flattened Bézier wave cut-out
                hx, hy = rng.uniform(8.0, 10.5), rng.uniform(4.5, 7.0)
                hole(w, cx - hx + 2.5, cy, 1.1, fc * 0.6)
                wave = banner(cx - hx + 5.0, cy - 1.0, 2 * hx - 7.0, 0.8, 1.6, 2)
                s, items = svg_path_to_items(wave, "flat-adaptive", 0.01, 0.0)
                line_lead_in(w, s, items, fc * 0.6, lead=0.5, left=True)
                pts = [(cx - hx, cy - hy), (cx + hx, cy - hy), (cx + hx, cy + hy), (cx - hx, cy + hy)]
                s, items = rounded_poly(pts, [1.5, 3.0, 3.0, 1.5])
                arc_lead_in(w, s, items, fc)
    w.rapid(0.0, 0.0, 0.0)
    return w


PROGRAMS = {
    "cam3d_a": gen_cam3d_a,
    "cam3d_b": gen_cam3d_b,
    "svg_logo_a": gen_svg_logo_a,
    "svg_logo_b": gen_svg_logo_b,
    "laser_parts_a": gen_laser_parts_a,
    "laser_parts_b": gen_laser_parts_b,
}


def main(argv: list[str]) -> None:
    out = Path(argv[1]) if len(argv) > 1 else Path(__file__).resolve().parent
    out.mkdir(parents=True, exist_ok=True)
    for name, gen in PROGRAMS.items():
        w = gen()
        (out / f"{name}.ngc").write_text(w.text())
        print(f"{name}: {w.n_motion} motion blocks ({w.n_arcs} arcs), {w.n_laser} M3/M5, {len(w.lines) + 1} lines")


if __name__ == "__main__":
    main(sys.argv)
