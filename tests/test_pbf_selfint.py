"""Issue 19, Deliver 1: self-intersections where slicing shows them — reported, refused, or built as the union."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("trimesh")
pytest.importorskip("pyclipper")
import trimesh  # noqa: E402

from jaxcnc.pbf import MeshError  # noqa: E402
from jaxcnc.pbf.mesh import load_trimesh, merge_vertices, prepare  # noqa: E402
from jaxcnc.pbf.selfint import check_heights_mm, self_intersections  # noqa: E402

CORPUS = Path(__file__).resolve().parents[1] / ".." / "shared" / "corpus" / "stl"


def _two_boxes(offset=(1.0, 0.5, 0.3)) -> trimesh.Trimesh:
    """Two closed 2 mm cubes, the second moved by ``offset``: each shell is whole, together they overlap."""
    a = trimesh.creation.box((2.0, 2.0, 2.0))
    b = trimesh.creation.box((2.0, 2.0, 2.0))
    b.apply_translation(offset)
    return trimesh.util.concatenate([a, b])


def test_overlapping_shells_are_found_where_they_cross():
    m = _two_boxes()
    z = check_heights_mm(-1.0, 1.3, 0.1)  # 23 layers: all checked
    n, at = self_intersections(np.asarray(m.vertices), np.asarray(m.faces), z)
    inside = (z > -0.7) & (z < 1.0)  # the heights where both cubes are cut
    assert n == int(inside.sum())
    # the first crossing: cube a's edge y = 1 meets cube b's edge x = 0, at the lowest height both are cut
    assert at == pytest.approx((0.0, 1.0, z[inside][0]))


def test_touching_and_apart_shells_and_a_single_cube_are_not_self_intersections():
    for mesh in (_two_boxes((2.0, 0.0, 0.0)), _two_boxes((5.0, 0.0, 0.0)), trimesh.creation.box((2.0, 2.0, 2.0))):
        v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        assert self_intersections(v, f, check_heights_mm(-1.0, 1.0, 0.1)) == (0, None)


def test_a_self_intersecting_mesh_is_refused_naming_the_place_and_built_as_the_union_on_repair():
    m = _two_boxes()
    with pytest.raises(MeshError, match=r"^two\.stl: mesh defects: 17 self-intersections \(loops crossing at 17 of "
                       r"23 heights checked\) \(first near x=0\.000 y=1\.000 z=-0\.650 mm\)"):  # fmt: skip
        prepare(m, file="two.stl", check_thickness_mm=0.1)
    prepared = prepare(m, repair=True, file="two.stl", check_thickness_mm=0.1)
    assert prepared.report.defect("self-intersections (loops crossing at 17 of 23 heights checked)").count == 17
    assert any("union of its loops" in r for r in prepared.report.repaired)
    # the union is what is built: a layer through both cubes has 4 + 4 - 1 x 1.5 mm² of part
    from jaxcnc.pbf import contours as cc
    from jaxcnc.pbf.slice import slice_mesh

    sl = slice_mesh(prepared.vertices, prepared.faces, np.array([1.05]))
    assert cc.area_mm2(cc.layer_region(sl.layer_loops(0))) == pytest.approx(6.5, rel=1e-9)
    # without a layer thickness (no check asked for), intake does not look
    assert prepare(m).report.defects == []


@pytest.mark.parametrize("name", ["frameGuide", "nut", "inversePyramid"])
def test_the_corpus_parts_do_not_cross_themselves(name):
    path = CORPUS / f"{name}.stl"
    if not path.is_file():
        pytest.skip("corpus not present")
    t = load_trimesh(path)
    v, f = merge_vertices(np.asarray(t.vertices, np.float64), np.asarray(t.faces), 1e-5)
    z = check_heights_mm(float(v[:, 2].min()), float(v[:, 2].max()), 0.03)
    assert len(z) == 64 and self_intersections(v, f, z) == (0, None)
