"""Synthetic programs and machines the benchmarks plan (and where the corpus lies)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jaxcnc.program import Kind, Program, program_from_columns

BENCH_MACHINE = """\
[machine]
name = "bench"
tick_hz = 10000
[axes.x]
v_max = 250.0
a_max = 3000.0
min = -1000.0
max = 1000.0
[axes.y]
v_max = 250.0
a_max = 3000.0
min = -1000.0
max = 1000.0
[path]
feed = 100.0
rapid = 250.0
"""


def synthetic_program(n_blocks: int, seed: int = 0) -> Program:
    """A smooth curve cut into ``n_blocks`` lines of 50–150 µm (CAM output of a spline).

    The curvature oscillates between -0.01 and 0.06 /mm around a positive mean, so the curve
    winds around and stays within about 200 mm; headings change by at most 0.6° per block, so
    junctions are passed moving and only curvature and block length limit the speed.
    """
    rng = np.random.default_rng(seed)
    step = rng.uniform(0.05, 0.15, n_blocks)
    s = np.cumsum(step)
    curvature = 1 / 40 + 0.035 * np.sin(s / 5.0)
    heading = np.cumsum(step * curvature)
    pts = np.zeros((n_blocks + 1, 3))
    pts[1:, 0] = np.cumsum(step * np.cos(heading))
    pts[1:, 1] = np.cumsum(step * np.sin(heading))
    pts[:, :2] -= pts[:, :2].mean(axis=0)
    return program_from_columns(
        file="<synthetic>",
        kind=np.full(n_blocks, Kind.LINE),
        start=pts[:-1],
        end=pts[1:],
        feed=np.full(n_blocks, 100.0),
        line=np.arange(1, n_blocks + 1),
    )


def random_cubic_nurbs(n_points: int = 1000, seed: int = 0) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """A planar cubic NURBS with ``n_points`` control points winding through a 200 mm field."""
    rng = np.random.default_rng(seed)
    ang = np.cumsum(rng.normal(0.0, 0.25, n_points))
    pts = np.cumsum(np.stack([np.cos(ang), np.sin(ang)], axis=1) * rng.uniform(1.0, 3.0, (n_points, 1)), axis=0)
    pts = np.c_[pts - pts.mean(axis=0), np.zeros(n_points)]
    w = rng.uniform(0.5, 2.0, n_points)
    knots = np.concatenate([np.zeros(4), np.linspace(0, 1, n_points - 2)[1:-1], np.ones(4)])
    return 3, pts, w, knots


def shared_dir() -> Path | None:
    """The workplace's ``shared`` folder (corpus, peers) beside this checkout or the current directory, if any."""
    here = Path(__file__).resolve()
    for base in (Path.cwd(), Path.cwd().parent, here.parents[2], here.parents[3]):
        if (base / "shared").is_dir():
            return base / "shared"
    return None


def find_butterfly() -> tuple | None:
    """The corpus butterfly NURBS, or ``None`` when the corpus is absent."""
    from jaxcnc.io.curves import read_curves_json

    shared = shared_dir()
    f = shared / "corpus" / "nurbs" / "butterfly_deg3_iges.json" if shared else None
    return read_curves_json(f)[0] if f is not None and f.is_file() else None


def cam_polyline(n_blocks: int, seed: int = 0, arc_every: int = 50) -> Program:
    """A CAM-style contour of ``n_blocks`` moves: lines of 50–150 µm turning 0.1–5° at every junction,
    with a tangent-free circular arc (radius 1–5 mm, 10–90°) every ``arc_every`` blocks.

    The turn's sign follows a slow sine so that the contour winds around and stays within a few
    hundred mm, as a spline cut into chords by a post processor would.
    """
    rng = np.random.default_rng(seed)
    k = np.arange(n_blocks)
    is_arc = (k % arc_every == arc_every - 1) if arc_every else np.zeros(n_blocks, bool)
    turn = np.radians(rng.uniform(0.1, 5.0, n_blocks)) * np.where(np.sin(k / 97.0) + 0.3 > 0, 1.0, -1.0)
    step = rng.uniform(0.05, 0.15, n_blocks)
    radius = rng.uniform(1.0, 5.0, n_blocks)
    sweep = np.radians(rng.uniform(10.0, 90.0, n_blocks)) * np.sign(turn)
    heading = np.cumsum(turn + np.where(is_arc, sweep, 0.0))  # direction after each block
    h_in = heading - np.where(is_arc, sweep, 0.0)  # direction at each block's start
    # a line moves `step` along its heading; an arc of sweep φ on radius r moves the chord 2 r sin(φ/2)
    # along the mean of its start and end directions
    chord = np.where(is_arc, 2 * radius * np.abs(np.sin(sweep / 2)), step)
    mid = np.where(is_arc, h_in + sweep / 2, heading)
    pts = np.zeros((n_blocks + 1, 3))
    pts[1:, 0] = np.cumsum(chord * np.cos(mid))
    pts[1:, 1] = np.cumsum(chord * np.sin(mid))
    pts[:, :2] -= pts[:, :2].mean(axis=0)
    # arc centres: on the left of the start direction (counter-clockwise) or the right
    left = np.stack([-np.sin(h_in), np.cos(h_in)], axis=1) * np.sign(sweep)[:, None]
    center = np.full((n_blocks, 3), np.nan)
    center[:, :2] = pts[:-1, :2] + radius[:, None] * left
    center[:, 2] = 0.0
    return program_from_columns(
        file="<cam-polyline>",
        kind=np.where(is_arc, Kind.ARC, Kind.LINE),
        start=pts[:-1],
        end=pts[1:],
        center=np.where(is_arc[:, None], center, np.nan),
        turn=np.where(is_arc, np.sign(sweep), 0).astype(np.int8),
        feed=np.full(n_blocks, 100.0),
        blend_tol=np.full(n_blocks, np.inf),
        line=k + 1,
    )


def cam_gcode(n_blocks: int, seed: int = 0) -> str:
    """:func:`cam_polyline` as an RS274 program (G17, mm, absolute; lines G1, arcs G2/G3 with I J from the start;
    F6000 = 100 mm/s; ``G64`` without P: the machine's corner tolerance), coordinates to the micrometre's
    thousandth — what a post processor writes for it (``jaxcnc plan`` reads it as a user's file)."""
    prog = cam_polyline(n_blocks, seed)
    start, end = prog.start, prog.end
    lines = ["G21 G90 G17 G64", f"G0 X{start[0, 0]:.6f} Y{start[0, 1]:.6f}", "F6000"]
    arc = prog.kind == Kind.ARC
    ij = np.where(arc[:, None], prog.center - start, 0.0)
    word = np.where(arc, np.where(prog.turn > 0, "G3", "G2"), "G1")
    for k in range(len(prog)):
        xy = f"{word[k]} X{end[k, 0]:.6f} Y{end[k, 1]:.6f}"
        lines.append(xy + (f" I{ij[k, 0]:.6f} J{ij[k, 1]:.6f}" if arc[k] else ""))
    lines.append("M2")
    return "\n".join(lines) + "\n"
