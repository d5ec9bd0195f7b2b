"""Slicing a closed mesh at many heights at once, vectorised over triangles and layers in NumPy.

Every (triangle, layer) pair whose triangle spans the layer's height is found with two ``searchsorted`` calls and
expanded with ``repeat``; the crossing segments of all pairs are computed in one pass. A vertex counts as above the
plane when ``z >= h`` (a symbolic perturbation: a vertex on the plane never makes a face ambiguous), and each
crossing point is computed once per (mesh edge, layer) from the edge's lower-numbered vertex, so the two faces that
share an edge produce the same point bit for bit. Segments are oriented by the face's winding (material on the
left: outer loops counter-clockwise, holes clockwise seen from +z) and chained into loops by matching edge keys;
the loops are ordered by pointer jumping (log2 of the longest loop passes over all segments), not by walking them.

The result for one layer does not depend on which other layers were sliced with it (a distributed build slices
chunks of layers, a serial one all of them: the loops are the same bit for bit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jaxcnc.pbf import MeshError


@dataclass(frozen=True)
class Slices:
    """Closed loops of many layers, flattened.

    Attributes:
        z_mm: (L,) the heights sliced.
        points_mm: (P, 2) loop vertices, loop after loop (a loop is not repeated at its end).
        loop_start: (N + 1,) offsets of each loop in ``points_mm``.
        loop_layer: (N,) the layer index (into ``z_mm``) of each loop, non-decreasing.
    """

    z_mm: np.ndarray
    points_mm: np.ndarray
    loop_start: np.ndarray
    loop_layer: np.ndarray

    def layer_loops(self, k: int) -> list[np.ndarray]:
        """The loops of layer ``k`` as a list of (n, 2) arrays (outer CCW, holes CW)."""
        a, b = np.searchsorted(self.loop_layer, [k, k + 1])
        s = self.loop_start
        return [self.points_mm[s[i] : s[i + 1]] for i in range(a, b)]


def layer_heights(z_top_mm: float, thickness_mm: float) -> np.ndarray:
    """Mid-layer heights of a part from z = 0 to ``z_top_mm``: ``(k + 0.5) * thickness``, every one below the top.

    A last partial layer thinner than half the thickness has no mid-height inside the part and is not built.
    """
    n = int(np.ceil(z_top_mm / thickness_mm - 0.5 - 1e-9))
    return (np.arange(max(n, 0)) + 0.5) * thickness_mm


def _pairs(tri_z: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(triangle, layer) index pairs with zmin < z <= zmax, triangle-major. tri_z: (F, 3); z: (L,) sorted."""
    lo = np.searchsorted(z, tri_z.min(axis=1), side="right")
    hi = np.searchsorted(z, tri_z.max(axis=1), side="right")
    cnt = np.maximum(hi - lo, 0)
    tri = np.repeat(np.arange(len(tri_z)), cnt)
    first = np.repeat(np.cumsum(cnt) - cnt, cnt)
    layer = np.arange(len(tri)) - first + np.repeat(lo, cnt)
    return tri, layer


def _loop_order(nxt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cycles of the permutation ``nxt`` (N,): per element its cycle's smallest index and its position from it.

    Pointer jumping: O(N log C) for the longest cycle C, no Python loop over elements.
    """
    n = len(nxt)
    label = np.arange(n)
    jump = nxt.copy()
    while True:  # label[i] = min over i and the 2**k - 1 elements after it; stable once it is the cycle's minimum
        new = np.minimum(label, label[jump])
        if np.array_equal(new, label):
            break
        label, jump = new, jump[jump]
    # rank: steps from the root (the cycle's minimum) to each element, by list ranking on the cycle cut before root
    succ = np.where(label[nxt] == nxt, -1, nxt)  # the element before the root ends the list
    dist = (succ >= 0).astype(np.int64)
    s = succ.copy()
    while np.any(s >= 0):
        m = s >= 0
        d_new = dist.copy()
        d_new[m] += dist[s[m]]
        s_new = s.copy()
        s_new[m] = s[s[m]]
        dist, s = d_new, s_new
    length = np.bincount(label, minlength=n)[label]
    return label, length - 1 - dist


def slice_mesh(vertices: np.ndarray, faces: np.ndarray, z_mm: np.ndarray) -> Slices:
    """Slice a closed, consistently wound mesh at the heights ``z_mm``.

    Args:
        vertices: (V, 3) float64 mm. faces: (F, 3) int, counter-clockwise seen from outside.
        z_mm: (L,) increasing heights.
    Returns:
        :class:`Slices` with every layer's closed loops. Raises :class:`MeshError` if a loop does not close
        (an open or non-manifold mesh).
    """
    z = np.asarray(z_mm, dtype=np.float64)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    empty = Slices(z, np.zeros((0, 2)), np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64))
    if len(z) == 0 or len(faces) == 0:
        return empty
    tri_z = vertices[:, 2][faces]
    tri, layer = _pairs(tri_z, z)
    if len(tri) == 0:
        return empty
    # mesh edges: ids of the undirected edges (v_lo, v_hi)
    e_dir = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 3, 2)  # (F, 3, 2): edge i runs v_i -> v_{i+1}
    e_lo, e_hi = e_dir.min(axis=2), e_dir.max(axis=2)
    V = len(vertices)
    ekey = e_lo * V + e_hi
    uniq_e, e_id = np.unique(ekey.reshape(-1), return_inverse=True)
    e_id = e_id.reshape(-1, 3)
    E = len(uniq_e)

    above = tri_z[tri] >= z[layer][:, None]  # (P, 3)
    a_above = above
    b_above = above[:, [1, 2, 0]]
    down = a_above & ~b_above  # the edge goes from above to below: the segment starts here
    up = ~a_above & b_above  # below to above: the segment ends here
    start_edge = np.argmax(down, axis=1)
    end_edge = np.argmax(up, axis=1)
    start_key = layer * E + e_id[tri, start_edge]
    end_key = layer * E + e_id[tri, end_edge]

    # link: the segment that starts where this one ends
    order = np.argsort(start_key, kind="stable")
    sk_sorted = start_key[order]
    pos = np.searchsorted(sk_sorted, end_key)
    pos_c = np.minimum(pos, len(sk_sorted) - 1)
    ok = sk_sorted[pos_c] == end_key
    dup = np.any(sk_sorted[1:] == sk_sorted[:-1])
    if not ok.all() or dup:
        bad = (
            int(np.flatnonzero(~ok)[0])
            if not ok.all()
            else int(order[np.flatnonzero(sk_sorted[1:] == sk_sorted[:-1])[0]])
        )
        c = vertices[faces[tri[bad]]].mean(axis=0)
        raise MeshError(
            f"slice at z={z[layer[bad]]:.4f} mm does not close near x={c[0]:.3f} y={c[1]:.3f} mm "
            "(the mesh is open or non-manifold there)"
        )
    nxt = order[pos_c]

    # the crossing point of each segment's start edge, from the edge's lower-numbered vertex
    v_a = e_dir[tri, start_edge, 0]
    v_b = e_dir[tri, start_edge, 1]
    lo_v, hi_v = np.minimum(v_a, v_b), np.maximum(v_a, v_b)
    p_lo, p_hi = vertices[lo_v], vertices[hi_v]
    h = z[layer]
    t = (h - p_lo[:, 2]) / (p_hi[:, 2] - p_lo[:, 2])
    pts = p_lo[:, :2] + t[:, None] * (p_hi[:, :2] - p_lo[:, :2])

    label, position = _loop_order(nxt)
    seq = np.lexsort((position, label, layer[label]))
    pts = pts[seq]
    lab = label[seq]
    brk = np.flatnonzero(np.diff(lab)) + 1
    loop_start = np.concatenate([[0], brk, [len(lab)]]).astype(np.int64)
    loop_layer = layer[lab[loop_start[:-1]]]
    return Slices(z, pts, loop_start, loop_layer.astype(np.int64))
