"""The scanner's vector list of a layer: marks in scan order with the jumps between them, and its time.

The documented vector form (docs/pbf.md) until the scanner command-list format exists: one NumPy structured array
per layer, one row per vector, :data:`VECTOR_DTYPE`:

- ``x0_mm, y0_mm, x1_mm, y1_mm``: the vector;
- ``mark``: 1 laser on (a mark), 0 laser off (a jump);
- ``zone``: :data:`jaxcnc.pbf.params.ZONES` index (a jump carries the zone of the mark it leads to);
- ``path``: contour marks: the index of their closed polyline in the layer; hatches and jumps: -1;
- ``speed_mm_s``: mark speed of the zone, or the jump speed; ``power_w``: the zone's power, 0 on jumps.

Delays and sky-writing are the scanner's (``[pbf.scanner]``), the same for every vector; :func:`layer_time_s`
applies them.
"""

from __future__ import annotations

import numpy as np

from jaxcnc.pbf.params import BuildParams

VECTOR_DTYPE = np.dtype(
    [
        ("x0_mm", "<f8"),
        ("y0_mm", "<f8"),
        ("x1_mm", "<f8"),
        ("y1_mm", "<f8"),
        ("mark", "u1"),
        ("zone", "u1"),
        ("path", "<i4"),
        ("speed_mm_s", "<f8"),
        ("power_w", "<f8"),
    ]
)


def greedy_loops(loops: list[np.ndarray], start_mm: np.ndarray) -> list[int]:
    """Order of closed loops by greedy nearest start point from ``start_mm`` (one step per loop)."""
    if not loops:
        return []
    firsts = np.array([p[0] for p in loops])
    left = np.ones(len(loops), dtype=bool)
    order, cur = [], np.asarray(start_mm, dtype=np.float64)
    for _ in range(len(loops)):
        d = np.where(left, np.hypot(*(firsts - cur).T), np.inf)
        i = int(np.argmin(d))
        order.append(i)
        left[i] = False
        cur = firsts[i]
    return order


def vector_list(
    hatch_segments: np.ndarray,
    hatch_zone: np.ndarray,
    contour_loops: list[np.ndarray],
    contour_zone: list[int],
    params: BuildParams,
) -> np.ndarray:
    """Assemble the layer's vector list: hatches as given (in scan order), then the contours, jumps between.

    Args:
        hatch_segments: (M, 2, 2) mm, in scan order. hatch_zone: (M,) zone ids.
        contour_loops: closed loops (n, 2) (not repeated at the end), scanned in greedy nearest order after the
            hatches. contour_zone: zone id per loop.
    Returns:
        (K,) :data:`VECTOR_DTYPE` rows.
    """
    speeds = np.array([z.mark_speed_mm_s for z in params.zones])
    powers = np.array([z.power_w for z in params.zones])
    segs = [np.asarray(hatch_segments, dtype=np.float64).reshape(-1, 2, 2)]
    zone = [np.asarray(hatch_zone, dtype=np.int64)]
    path = [np.full(len(segs[0]), -1, dtype=np.int64)]
    last = segs[0][-1, 1] if len(segs[0]) else np.zeros(2)
    for n, i in enumerate(greedy_loops(contour_loops, last)):
        p = np.asarray(contour_loops[i], dtype=np.float64)
        segs.append(np.stack([p, np.roll(p, -1, axis=0)], axis=1))
        zone.append(np.full(len(p), contour_zone[i], dtype=np.int64))
        path.append(np.full(len(p), n, dtype=np.int64))
    m = np.concatenate(segs)
    mz = np.concatenate(zone)
    mp = np.concatenate(path)
    K = len(m)
    if K == 0:
        return np.zeros(0, dtype=VECTOR_DTYPE)
    gap = np.zeros(K, dtype=bool)
    gap[1:] = np.any(m[1:, 0] != m[:-1, 1], axis=1)
    n_jumps = int(gap.sum())
    out = np.zeros(K + n_jumps, dtype=VECTOR_DTYPE)
    pos = np.arange(K) + np.cumsum(gap)
    jpos = pos[gap] - 1
    for f, col in (("x0_mm", m[:, 0, 0]), ("y0_mm", m[:, 0, 1]), ("x1_mm", m[:, 1, 0]), ("y1_mm", m[:, 1, 1])):
        out[f][pos] = col
    out["mark"][pos] = 1
    out["zone"][pos] = mz
    out["path"][pos] = mp
    out["speed_mm_s"][pos] = speeds[mz]
    out["power_w"][pos] = powers[mz]
    prev_end = m[np.flatnonzero(gap) - 1, 1]
    nxt_start = m[gap, 0]
    out["x0_mm"][jpos], out["y0_mm"][jpos] = prev_end[:, 0], prev_end[:, 1]
    out["x1_mm"][jpos], out["y1_mm"][jpos] = nxt_start[:, 0], nxt_start[:, 1]
    out["zone"][jpos] = mz[gap]
    out["path"][jpos] = -1
    out["speed_mm_s"][jpos] = params.scanner.jump_speed_mm_s
    return out


def layer_time_s(vectors: np.ndarray, params: BuildParams) -> float:
    """Estimated time of a layer: marks and jumps at their speeds, the scanner's delays, sky-writing, recoating.

    Each run of marks (between jumps) pays the laser-on delay at its start, the laser-off and mark delays at its
    end (or, with sky-writing, ``skywriting_s`` instead), each corner inside a run the polygon delay; each jump its
    delay. The recoater's ``recoat_s`` is added once.
    """
    sc = params.scanner
    if len(vectors) == 0:
        return sc.recoat_s
    length = np.hypot(vectors["x1_mm"] - vectors["x0_mm"], vectors["y1_mm"] - vectors["y0_mm"])
    travel = float(np.sum(length / vectors["speed_mm_s"]))
    mark = vectors["mark"] == 1
    runs = int(mark[0]) + int(np.sum(mark[1:] & ~mark[:-1]))
    jumps = int(np.sum(~mark))
    corners = int(mark.sum()) - runs
    per_run = sc.skywriting_s if sc.skywriting else sc.laser_on_delay_s + sc.laser_off_delay_s + sc.mark_delay_s
    return travel + runs * per_run + corners * sc.polygon_delay_s + jumps * sc.jump_delay_s + sc.recoat_s
