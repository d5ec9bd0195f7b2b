"""Mesh intake with trimesh: load, merge vertices within a tolerance, report defects, repair or refuse, place.

Defects found (each with a count and where the first one is):

- holes: edges used by one face only (the surface is not closed); their loops are counted;
- non-manifold edges: edges shared by more than two faces;
- duplicate faces (the same three vertices) and degenerate faces (zero area, or two vertices merged into one);
- isolated shells: connected pieces of surface that cannot enclose material — fewer than four faces, or open and
  not the largest piece;
- inconsistent normals: an edge that both its faces run in the same direction (one face flipped);
- inside-out: a closed mesh whose volume is negative (all normals point in).

- self-intersections, where slicing shows them (:mod:`jaxcnc.pbf.selfint`; with a layer thickness given): loops
  of one cut crossing themselves or each other, at up to 64 of the build's layer heights. Repair builds each layer
  from the union of its loops (non-zero rule), so overlapping shells build as their union.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxcnc.pbf import MeshError

MESH_SUFFIXES = (".stl", ".obj", ".3mf", ".ply", ".off")


@dataclass
class Defect:
    """One kind of defect: how many and where (a point in mm, the first found)."""

    kind: str
    count: int
    where_mm: tuple[float, float, float] | None = None

    def __str__(self) -> str:
        at = "" if self.where_mm is None else " (first near x={:.3f} y={:.3f} z={:.3f} mm)".format(*self.where_mm)
        return f"{self.count} {self.kind}{at}"


@dataclass
class MeshReport:
    """What intake found and did: defects, merged vertices, what repair changed, the shells."""

    file: str
    faces: int
    vertices_in: int
    vertices_merged: int
    shells: int
    defects: list[Defect] = field(default_factory=list)
    repaired: list[str] = field(default_factory=list)

    def defect(self, kind: str) -> Defect | None:
        """The defect of this kind, or ``None``."""
        return next((d for d in self.defects if d.kind == kind), None)

    def summary(self) -> str:
        """One line: the defects, or 'no defects'."""
        return "; ".join(str(d) for d in self.defects) if self.defects else "no defects"


def load_trimesh(path: str | Path):
    """Load a mesh file with trimesh as a triangle soup (no processing); raises :class:`MeshError`."""
    import trimesh

    p = Path(path)
    if p.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{p}: not a mesh file (expected one of {', '.join(MESH_SUFFIXES)})")
    try:
        loaded = trimesh.load(str(p), force="mesh", process=False)
    except FileNotFoundError:
        raise MeshError(f"{p}: no such file") from None
    except Exception as exc:  # trimesh raises many kinds for unreadable files
        raise MeshError(f"{p}: cannot read as {p.suffix[1:].upper()}: {exc}") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError(f"{p}: no triangles in the file")
    if not np.all(np.isfinite(loaded.vertices)):
        raise MeshError(f"{p}: vertices with non-finite coordinates")
    return loaded


def merge_vertices(vertices: np.ndarray, faces: np.ndarray, tol_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices that fall in the same cell of a ``tol_mm`` grid.

    Args:
        vertices: (V, 3) float64, mm. faces: (F, 3) int.
    Returns:
        (V', 3) merged vertices (the first of each cell) and (F, 3) faces re-indexed.
    """
    key = np.round(vertices / tol_mm).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return vertices[first], inverse.reshape(-1)[faces]


def _edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Directed edges (3F, 2) of ``faces`` and their face index (3F,)."""
    e = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    return e, np.repeat(np.arange(len(faces)), 3)


def analyse(vertices: np.ndarray, faces: np.ndarray, file: str = "<mesh>") -> tuple[MeshReport, dict]:
    """Find the defects of a vertex-merged mesh.

    Returns the report and the masks/labels repair uses: ``duplicate`` and ``degenerate`` (F,) bool, ``shell``
    (F,) int labels, ``isolated`` (F,) bool.
    """
    import trimesh

    F = len(faces)
    report = MeshReport(file=file, faces=F, vertices_in=0, vertices_merged=len(vertices), shells=0)
    centroid = vertices[faces].mean(axis=1)

    def where(mask: np.ndarray) -> tuple[float, float, float] | None:
        idx = np.flatnonzero(mask)
        return tuple(float(x) for x in centroid[idx[0]]) if len(idx) else None

    same = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    area = np.linalg.norm(np.cross(*(vertices[faces[:, 1:]] - vertices[faces[:, :1]]).transpose(1, 0, 2)), axis=1)
    degenerate = same | (area <= 1e-12 * max(1.0, float(np.ptp(vertices, axis=0).max()) ** 2))
    srt = np.sort(faces, axis=1)
    _, first, counts = np.unique(srt, axis=0, return_index=True, return_counts=True)
    duplicate = np.ones(F, dtype=bool)
    duplicate[first] = False
    duplicate &= ~degenerate
    if duplicate.any():
        report.defects.append(Defect("duplicate faces", int(duplicate.sum()), where(duplicate)))
    if degenerate.any():
        report.defects.append(Defect("degenerate faces", int(degenerate.sum()), where(degenerate)))

    good = ~(duplicate | degenerate)
    gf = faces[good]
    e, ef = _edges(gf)
    es = np.sort(e, axis=1)
    uniq, inv, cnt = np.unique(es, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    boundary = cnt[inv] == 1
    nonman = cnt[inv] > 2
    if nonman.any():
        mid = vertices[e[nonman]].mean(axis=1)[0]
        report.defects.append(Defect("non-manifold edges", int((cnt > 2).sum()), tuple(map(float, mid))))
    # a manifold edge whose two faces run it the same way: winding inconsistent there
    pair = cnt[inv] == 2
    directed = np.unique(e[pair], axis=0, return_counts=True)[1]
    flipped = int((directed > 1).sum())
    # shells: faces connected through shared edges
    order = np.argsort(inv, kind="stable")
    inv_s = inv[order]
    adj_a, adj_b = ef[order][:-1], ef[order][1:]
    joined = inv_s[:-1] == inv_s[1:]
    labels = trimesh.graph.connected_component_labels(np.column_stack([adj_a[joined], adj_b[joined]]), len(gf))
    n_shells = int(labels.max()) + 1 if len(labels) else 0
    report.shells = n_shells
    shell = np.full(F, -1)
    shell[good] = labels
    sizes = np.bincount(labels, minlength=n_shells)
    open_shell = np.zeros(n_shells, dtype=bool)
    np.logical_or.at(open_shell, labels[ef[boundary | nonman]], True)
    isolated_shell = (sizes < 4) | (open_shell & (np.arange(n_shells) != int(np.argmax(sizes))))
    hole_edge = boundary & ~isolated_shell[labels[ef]]  # the edges of an isolated shell are that defect
    if hole_edge.any():
        loops = _count_loops(np.unique(es[hole_edge], axis=0))
        mid = vertices[e[hole_edge]].mean(axis=1)[0]
        report.defects.append(
            Defect(
                f"holes (open boundary: {int(hole_edge.sum())} edges in {loops} loops)", loops, tuple(map(float, mid))
            )
        )
    isolated = np.zeros(F, dtype=bool)
    isolated[good] = isolated_shell[labels]
    if isolated_shell.any():
        report.defects.append(
            Defect(
                f"isolated shells ({int(sizes[isolated_shell].sum())} faces)",
                int(isolated_shell.sum()),
                where(isolated),
            )
        )
    if flipped:
        k = np.flatnonzero(directed > 1)[0]
        report.defects.append(
            Defect(
                "edges with inconsistent normals",
                flipped,
                tuple(map(float, vertices[np.unique(e[pair], axis=0)[k]].mean(0))),
            )
        )
    elif not boundary.any() and not nonman.any() and len(gf):
        tri = vertices[gf]
        volume = float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)
        if volume < 0:
            report.defects.append(Defect("inside-out shell (negative volume)", 1, where(good)))
    return report, dict(duplicate=duplicate, degenerate=degenerate, isolated=isolated, shell=shell)


def _count_loops(edges: np.ndarray) -> int:
    """Number of connected pieces of the boundary edges ``edges`` (E, 2)."""
    import trimesh

    if len(edges) == 0:
        return 0
    nodes, e = np.unique(edges, return_inverse=True)
    labels = trimesh.graph.connected_component_labels(e.reshape(-1, 2), len(nodes))
    return int(labels.max()) + 1


@dataclass
class PreparedMesh:
    """A mesh ready to slice: merged vertices (mm), faces, and what intake found and did."""

    vertices: np.ndarray
    faces: np.ndarray
    report: MeshReport
    digest: str

    @property
    def bounds_mm(self) -> np.ndarray:
        """(2, 3) min and max corner."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])


def prepare(
    source,
    merge_tol_mm: float = 1e-5,
    repair: bool = False,
    placement: str = "plate",
    plate_center_mm: tuple[float, float] = (0.0, 0.0),
    file: str | None = None,
    check_thickness_mm: float | None = None,
) -> PreparedMesh:
    """Load (a path or a ``trimesh.Trimesh``), merge, check, repair or refuse, and place a mesh.

    Refusal (``repair=False`` and any defect): :class:`MeshError` naming the file and every defect with its count
    and location. Repair: duplicate, degenerate faces and isolated shells removed, normals made consistent and
    outward (trimesh), small holes filled (trimesh); what is still open is refused.
    Placement ``plate``: lowest point on z = 0, the xy bounding-box centre on ``plate_center_mm``; ``keep``: as is.
    ``check_thickness_mm``: the layer thickness; given, the mesh (once free of the other defects) is searched for
    self-intersections at up to 64 of its layer heights (:mod:`jaxcnc.pbf.selfint`): refused, or with ``repair``
    built as each layer's union.
    """
    import hashlib

    import trimesh

    if isinstance(source, (str, Path)):
        file = file or str(source)
        mesh = load_trimesh(source)
    else:
        mesh = source
        file = file or "<mesh>"
    v_in = np.asarray(mesh.vertices, dtype=np.float64)
    vertices, faces = merge_vertices(v_in, np.asarray(mesh.faces, dtype=np.int64), merge_tol_mm)
    report, masks = analyse(vertices, faces, file)
    report.vertices_in = len(v_in)
    if report.defects and not repair:
        raise MeshError(f"{file}: mesh defects: {report.summary()} (repair = true in [pbf] to repair)")
    if report.defects:
        drop = masks["duplicate"] | masks["degenerate"] | masks["isolated"]
        for name in ("duplicate", "degenerate", "isolated"):
            if masks[name].any():
                report.repaired.append(f"removed {int(masks[name].sum())} {name} faces")
        m = trimesh.Trimesh(vertices, faces[~drop], process=False)
        if not m.is_watertight:
            trimesh.repair.fill_holes(m)
            if m.is_watertight:
                report.repaired.append("filled holes")
        trimesh.repair.fix_winding(m)
        trimesh.repair.fix_inversion(m)
        vertices, faces = merge_vertices(np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces), merge_tol_mm)
        after, _ = analyse(vertices, faces, file)
        if after.defects:
            raise MeshError(f"{file}: mesh defects left after repair: {after.summary()}")
        report.repaired.append("normals made consistent and outward")
    if check_thickness_mm is not None and (repair or not report.defects):
        from jaxcnc.pbf.selfint import check_heights_mm, self_intersections

        z = check_heights_mm(float(vertices[:, 2].min()), float(vertices[:, 2].max()), check_thickness_mm)
        n, at = self_intersections(vertices, faces, z)
        if n:
            report.defects.append(
                Defect(f"self-intersections (loops crossing at {n} of {len(z)} heights checked)", n, at)
            )
            if not repair:
                raise MeshError(f"{file}: mesh defects: {report.summary()} (repair = true in [pbf] to repair)")
            report.repaired.append("self-intersections: each layer built from the union of its loops")
    if placement == "plate":
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        shift = np.array([plate_center_mm[0] - (lo[0] + hi[0]) / 2, plate_center_mm[1] - (lo[1] + hi[1]) / 2, -lo[2]])
        vertices = vertices + shift
    elif placement != "keep":
        raise MeshError(f"{file}: unknown placement {placement!r}")
    digest = hashlib.sha256(vertices.tobytes() + faces.astype(np.int64).tobytes()).hexdigest()
    return PreparedMesh(vertices, faces.astype(np.int64), report, digest)
