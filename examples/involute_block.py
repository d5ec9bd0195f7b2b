"""A block-kind plug-in: Fanuc's involute interpolation, ``G2.2`` / ``G3.2`` (gear flanks, cams).

``G17 G3.2 X… Y… I… J… R… F…`` moves from the current point to X Y along the involute of the base circle
of radius R centred at the start + (I, J): ``G3.2`` turning counter-clockwise, ``G2.2`` clockwise. Installed
as a distribution that declares::

    [project.entry-points."jaxcnc.block_kinds"]
    "G2.2" = "involute_block:Involute"
    "G3.2" = "involute_block:Involute"

the words work in Fanuc-dialect programs (``jaxcnc plan gear.nc -m machine.toml -o gear.ticks --dialect
fanuc``); ``tests/test_plugins.py`` installs it so and plans a gear flank.

Geometry. With ``u(a) = (cos a, sin a)`` and ``n(a) = (−sin a, cos a)``, the involute unwinding from the base
circle in direction ``σ`` (+1 counter-clockwise, −1 clockwise) is

    P(t) = C + R·(u(a) − σ·t·n(a)),   a = φ + σ·t,   t ≥ 0,

so ``P'(t) = R·t·u(a)``: speed ``R·t``, arc length ``R·t²/2``, curvature ``1/(R·t)``, and the tangent turns
with ``σ`` as ``t`` grows. A point at distance ``r ≥ R`` from C has ``t = √(r²/R² − 1)`` and lies at the angle
``a − σ·atan(t)``. A block turning counter-clockwise (G3.2) either unwinds counter-clockwise (moving out,
``t`` growing) or winds back along a clockwise involute (moving in); G2.2 the mirror. The start fixes ``φ``;
the end must lie on that involute (within ``END_TOL_MM``, as a control raises an alarm otherwise).

Lowering: cubic Hermite pieces in ``t`` (end points and derivatives exact), as many as needed, doubling,
until the pieces stay within ``TOL_MM`` of the involute (measured at 16 points per piece against the exact
``P`` at the same ``t``: an upper bound of the distance to the curve), joined into one clamped cubic
B-spline (interior knots of multiplicity 3: the pieces meet with the same tangent).
"""

from __future__ import annotations

import math

import numpy as np

from jaxcnc.blocks import BlockCall, BlockKind, Curve

#: Largest distance of the lowered B-spline from the involute (mm).
TOL_MM = 1e-5
#: How far the programmed end may be from the involute through the start (mm).
END_TOL_MM = 1e-3
MAX_PIECES = 4096


def involute(c: np.ndarray, r: float, phi: float, sigma: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(P (k, 2), dP/dt (k, 2))`` of the involute at parameters ``t`` ``(k,)``."""
    a = phi + sigma * t
    u = np.stack([np.cos(a), np.sin(a)], axis=-1)
    n = np.stack([-np.sin(a), np.cos(a)], axis=-1)
    return c + r * (u - sigma * t[:, None] * n), r * t[:, None] * u


def _hermite(p0, d0, p1, d1, w: np.ndarray) -> np.ndarray:
    """Cubic Hermite pieces ``(m, 2)`` end data evaluated at ``w`` ``(q,)`` in [0, 1]: ``(m, q, 2)``."""
    h00, h10 = 2 * w**3 - 3 * w**2 + 1, w**3 - 2 * w**2 + w
    h01, h11 = -2 * w**3 + 3 * w**2, w**3 - w**2
    f = lambda a, h: a[:, None, :] * h[None, :, None]  # noqa: E731
    return f(p0, h00) + f(d0, h10) + f(p1, h01) + f(d1, h11)


class Involute(BlockKind):
    """G2.2 / G3.2 involute interpolation in the G17 plane (module docstring)."""

    name = "involute interpolation"
    letters = "IJR"
    lengths = "IJR"
    dialects = ("fanuc",)

    def lower(self, block: BlockCall) -> list[Curve]:
        if block.plane != 17:
            raise ValueError("involute interpolation is programmed in the G17 (XY) plane")
        p = block.params
        if "R" not in p or not ("I" in p or "J" in p):
            raise ValueError("needs I, J (base circle centre from the start) and R (its radius)")
        r = p["R"]
        if not (math.isfinite(r) and r > 0):
            raise ValueError(f"base circle radius R{r:g} must be positive")
        s0, e0 = block.start_mm, block.end_mm
        if abs(e0[2] - s0[2]) > 0:
            raise ValueError("Z cannot move during involute interpolation")
        c = s0[:2] + np.array([p.get("I", 0.0), p.get("J", 0.0)])
        rs, re = float(np.linalg.norm(s0[:2] - c)), float(np.linalg.norm(e0[:2] - c))
        if min(rs, re) <= r * (1 + 1e-9):
            raise ValueError(
                f"start and end must lie outside the base circle (R{r:g}; start at {rs:.6g}, end at {re:.6g} mm "
                "from its centre): the involute's curvature is infinite on it"
            )
        ts, te = math.sqrt(rs**2 / r**2 - 1), math.sqrt(re**2 / r**2 - 1)
        if abs(te - ts) < 1e-12:
            raise ValueError("start and end are equally far from the base circle: no involute joins them")
        ccw = block.word == "G3.2"
        sigma = 1 if ccw == (te > ts) else -1  # out along the turning direction, or back along the mirror
        ang_s = math.atan2(s0[1] - c[1], s0[0] - c[0])
        phi = ang_s + sigma * math.atan(ts) - sigma * ts
        (end,), _ = involute(c, r, phi, sigma, np.array([te]))
        miss = float(np.linalg.norm(end - e0[:2]))
        if miss > END_TOL_MM:
            raise ValueError(
                f"the end point is {miss:.4g} mm off the involute through the start (base circle R{r:g} about "
                f"({c[0]:.6g}, {c[1]:.6g})); it would end at ({end[0]:.6g}, {end[1]:.6g})"
            )
        w = np.linspace(0.0, 1.0, 18)[1:-1]
        for m in 2 ** np.arange(0, int(math.log2(MAX_PIECES)) + 1):
            t = np.linspace(ts, te, m + 1)
            pts, der = involute(c, r, phi, sigma, t)
            pts[0], pts[-1] = s0[:2], e0[:2]  # exactly the block's ends
            dt = (te - ts) / m
            q = _hermite(pts[:-1], der[:-1] * dt, pts[1:], der[1:] * dt, w)
            exact, _ = involute(c, r, phi, sigma, (t[:-1, None] + w[None, :] * dt).ravel())
            if np.max(np.linalg.norm(q.reshape(-1, 2) - exact, axis=1)) <= TOL_MM:
                break
        else:
            raise ValueError(f"the involute cannot be followed within {TOL_MM:g} mm by {MAX_PIECES} pieces")
        # Bézier control points of each Hermite piece: P0, P0 + D0/3, P1 − D1/3, P1.
        ctrl = [pts[0]]
        for k in range(m):
            ctrl += [pts[k] + der[k] * dt / 3, pts[k + 1] - der[k + 1] * dt / 3, pts[k + 1]]
        xy = np.asarray(ctrl)
        points = np.column_stack([xy, np.full(len(xy), s0[2])])
        knots = np.concatenate([[0.0] * 4, np.repeat(np.arange(1, m), 3).astype(float), [float(m)] * 4])
        return [Curve(3, points, np.ones(len(points)), knots)]
