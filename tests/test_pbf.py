"""Powder-bed fusion (jaxcnc.pbf): mesh intake and defects, slicing, zones, hatching, parameters, builds."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")
pytest.importorskip("pyclipper")

from jaxcnc.cli.main import main  # noqa: E402
from jaxcnc.errors import MachineFileError  # noqa: E402
from jaxcnc.pbf import MeshError  # noqa: E402
from jaxcnc.pbf import contours as cc  # noqa: E402
from jaxcnc.pbf.build import build, verify_build  # noqa: E402
from jaxcnc.pbf.hatch import hatch_region  # noqa: E402
from jaxcnc.pbf.layer import process_chunk  # noqa: E402
from jaxcnc.pbf.mesh import prepare  # noqa: E402
from jaxcnc.pbf.params import default_params, parse_params  # noqa: E402
from jaxcnc.pbf.slice import layer_heights, slice_mesh  # noqa: E402

CORPUS = Path(__file__).resolve().parents[1] / ".." / "shared" / "corpus" / "stl"


def _box(extents, centre=(0.0, 0.0, 0.0)):
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(np.asarray(centre, dtype=float) - m.bounds.mean(axis=0) + [0, 0, 0])
    return m


def _boxes(*specs):
    """Boxes (extents, centre) concatenated into one mesh."""
    return trimesh.util.concatenate([_box(e, c) for e, c in specs])


def _area(loop):
    x, y = loop[:, 0], loop[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


# ---------------------------------------------------------------- mesh intake


def test_defective_stl_reported_with_counts(tmp_path):
    """A box with a hole, three duplicate faces and a stray triangle: each reported, with its count and place."""
    box = _box((10, 10, 10), (0, 0, 5))
    faces = np.vstack([box.faces[1:], box.faces[2:5]])  # face 0 removed (a hole), faces 2..4 twice
    stray = trimesh.Trimesh([[40, 40, 1], [41, 40, 1], [40, 41, 1]], [[0, 1, 2]], process=False)
    mesh = trimesh.util.concatenate([trimesh.Trimesh(box.vertices, faces, process=False), stray])
    path = tmp_path / "broken.stl"
    mesh.export(path)
    with pytest.raises(MeshError) as err:
        prepare(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: mesh defects:")
    assert "3 duplicate faces" in msg
    assert "1 holes (open boundary: 3 edges in 1 loops)" in msg
    assert "1 isolated shells (1 faces) (first near x=40.333 y=40.333 z=1.000 mm)" in msg
    # the command line: exit 2, one line naming the file and the defects, no traceback
    toml = tmp_path / "pbf.toml"
    toml.write_text("[pbf]\nlayer_thickness_mm = 0.5\nhatch_spacing_mm = 0.2\nspot_diameter_mm = 0.1\n")
    assert main(["build", str(path), "-m", str(toml), "-o", str(tmp_path / "out"), "-q", "--workers", "0"]) == 2


def test_inconsistent_normals_and_repair():
    box = _box((10, 10, 10), (0, 0, 5))
    faces = box.faces.copy()
    faces[3] = faces[3][::-1]
    flipped = trimesh.Trimesh(box.vertices, np.vstack([faces, faces[:2]]), process=False)
    with pytest.raises(MeshError, match="edges with inconsistent normals"):
        prepare(flipped)
    fixed = prepare(flipped, repair=True)
    assert "removed 2 duplicate faces" in fixed.report.repaired
    assert len(fixed.faces) == 12
    sl = slice_mesh(fixed.vertices, fixed.faces, np.array([5.0]))
    assert [round(_area(p), 9) for p in sl.layer_loops(0)] == [100.0]


def test_vertex_merge_and_placement():
    box = _box((4, 6, 2), (100, 50, 30))
    v = box.vertices[box.faces].reshape(-1, 3)
    v = v + np.random.default_rng(1).uniform(-2e-7, 2e-7, v.shape)  # a triangle soup, vertices off by < tol
    soup = trimesh.Trimesh(v, np.arange(len(v)).reshape(-1, 3), process=False)
    m = prepare(soup, merge_tol_mm=1e-5, plate_center_mm=(10.0, -5.0))
    assert len(m.vertices) == 8 and m.report.vertices_in == 36
    np.testing.assert_allclose(m.bounds_mm, [[8, -8, 0], [12, -2, 2]], atol=1e-6)


# ---------------------------------------------------------------- slicing


def test_slice_box_orientation_and_area():
    m = prepare(_boxes(((10, 20, 5), (0, 0, 2.5)), ((4, 4, 5), (20, 0, 2.5))))
    z = layer_heights(5.0, 0.1)
    assert len(z) == 50
    sl = slice_mesh(m.vertices, m.faces, z)
    for k in range(len(z)):
        assert sorted(round(_area(p), 9) for p in sl.layer_loops(k)) == [16.0, 200.0]


def test_slice_layers_independent_of_chunk():
    m = prepare(_box((3, 3, 3), (0, 0, 1.5)).subdivide().subdivide())
    z = layer_heights(3.0, 0.07)
    whole = slice_mesh(m.vertices, m.faces, z)
    part = slice_mesh(m.vertices, m.faces, z[10:14])
    for i in range(4):
        for a, b in zip(whole.layer_loops(10 + i), part.layer_loops(i), strict=True):
            assert a.tobytes() == b.tobytes()


@pytest.mark.skipif(not CORPUS.is_dir(), reason="../shared/corpus is absent")
@pytest.mark.parametrize("name", ["frameGuide", "nut", "inversePyramid"])
def test_corpus_sliced_and_hatched(name):
    """Every layer's area equals trimesh's section; hatch length is the hatched area over the spacing."""
    m = prepare(CORPUS / f"{name}.stl")
    p = default_params(layer_thickness_mm=0.1, thin_wall_mm=0.3)
    z = layer_heights(float(m.bounds_mm[1, 2]), p.layer_thickness_mm)
    sl = slice_mesh(m.vertices, m.faces, z)
    tm = trimesh.Trimesh(m.vertices, m.faces, process=False)
    for k in range(0, len(z), max(1, len(z) // 12)):
        sec = tm.section(plane_origin=[0, 0, z[k]], plane_normal=[0, 0, 1])
        planar, _ = sec.to_2D(to_2D=np.eye(4))
        assert sum(_area(q) for q in sl.layer_loops(k)) == pytest.approx(planar.area, rel=1e-9, abs=1e-9)
    scans = process_chunk(m.vertices, m.faces, z, list(range(len(z))), p)
    assert [s.index for s in scans] == list(range(len(z)))
    length = sum(s.hatch_length_mm for s in scans)
    hatched = 0.0
    for k, s in enumerate(scans):
        region = cc.layer_region(sl.layer_loops(k))
        hatched += cc.area_mm2(cc.offset(region, -p.spot_diameter_mm / 2))
        assert (s.vectors["mark"] == 1).any()
    assert length * p.hatch_spacing_mm == pytest.approx(hatched, rel=0.03)


# ---------------------------------------------------------------- zones


def test_thin_wall_areas_within_one_percent():
    """Walls 0.2 and 0.35 mm wide under a 0.5 mm threshold are thin; 0.8 and 2 mm ones are not."""
    widths = [0.2, 0.35, 0.8, 2.0]
    specs = [((w, 10.0, 1.0), (5.0 * i, 0.0, 0.5)) for i, w in enumerate(widths)]
    m = prepare(_boxes(*specs), placement="keep")
    p = default_params(layer_thickness_mm=0.1, thin_wall_mm=0.5, skin_layers=0)
    z = layer_heights(1.0, 0.1)
    scans = process_chunk(m.vertices, m.faces, z, list(range(len(z))), p)
    analytic = (0.2 + 0.35) * 10.0
    for s in scans:
        assert s.zone_area_mm2["thin_wall"] == pytest.approx(analytic, rel=0.01)
        assert s.zone_area_mm2["core"] == pytest.approx((0.8 + 2.0) * 10.0, rel=0.01)
        thin = s.vectors[(s.vectors["mark"] == 1) & (s.vectors["zone"] == 2)]
        assert len(thin) > 0 and np.all(np.minimum(thin["x0_mm"], thin["x1_mm"]) < 5.0 + 0.35)


def test_downskin_and_upskin_areas():
    """A 4x4 post under a 10x10 plate: the plate's first layer is down-skin outside the post, its last up-skin."""
    m = prepare(_boxes(((4, 4, 1), (0, 0, 0.5)), ((10, 10, 1), (0, 0, 1.5))), placement="keep")
    p = default_params(layer_thickness_mm=0.1, skin_layers=1)
    z = layer_heights(2.0, 0.1)
    s = {x.index: x for x in process_chunk(m.vertices, m.faces, z, list(range(len(z))), p)}
    assert s[0].zone_area_mm2["downskin"] == 0.0  # on the plate
    assert s[9].zone_area_mm2["upskin"] == pytest.approx(0.0, abs=1e-9)  # the post goes on up
    assert s[10].zone_area_mm2["downskin"] == pytest.approx(100 - 16, rel=1e-6)
    assert s[10].zone_area_mm2["core"] == pytest.approx(16, rel=1e-6)
    assert s[19].zone_area_mm2["upskin"] == pytest.approx(100, rel=1e-6)
    assert s[15].zone_area_mm2["core"] == pytest.approx(100, rel=1e-6)


# ---------------------------------------------------------------- hatching


SQUARE = [np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])]
HOLED = SQUARE + [np.array([[3.0, 3.0], [3.0, 7.0], [7.0, 7.0], [7.0, 3.0]])]


@pytest.mark.parametrize("pattern", ["lines", "meander", "stripes", "islands"])
@pytest.mark.parametrize("angle", [0.0, 30.0, 67.0, 90.0])
def test_hatch_covers_region(pattern, angle):
    h = hatch_region(HOLED, 0.1, angle, pattern, stripe_width_mm=2.0, island_size_mm=2.5)
    seg = h.segments_mm
    mid = seg.mean(axis=1)
    eps = 1e-9  # a hatch on a line through a boundary edge lies on it
    inside = np.all((mid >= -eps) & (mid <= 10 + eps), axis=1) & ~np.all((mid > 3 + eps) & (mid < 7 - eps), axis=1)
    assert inside.all()
    assert h.length_mm * 0.1 == pytest.approx(100 - 16, rel=0.02)
    d = seg[:, 1] - seg[:, 0]
    if pattern != "islands":
        direction = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 180
        assert np.allclose(direction, angle % 180, atol=1e-6)
    else:
        off = (np.degrees(np.arctan2(d[:, 1], d[:, 0])) - angle) % 180  # 0 (black squares) or 90 (white)
        off = np.where(off > 135, off - 180, off)
        assert np.all(np.isclose(off, 0, atol=1e-6) | np.isclose(off, 90, atol=1e-6))
        assert 0.3 < np.isclose(off, 0, atol=1e-6).mean() < 0.7


def test_meander_alternates_and_lines_do_not():
    mea = hatch_region(SQUARE, 1.0, 0.0, "meander").segments_mm
    lin = hatch_region(SQUARE, 1.0, 0.0, "lines").segments_mm
    assert np.all(lin[:, 1, 0] > lin[:, 0, 0])
    sign = np.sign(mea[:, 1, 0] - mea[:, 0, 0])
    assert np.all(sign[1:] == -sign[:-1])


def test_layer_angle_rotates_67_degrees():
    p = default_params()
    assert [round(p.layer_angle_deg(k), 6) for k in range(4)] == [0.0, 67.0, 134.0, 21.0]


# ---------------------------------------------------------------- parameters


@pytest.mark.parametrize(
    "text, where",
    [
        (
            "[pbf]\nlayer_thickness_mm = 0.03\nhatch_spacing_mm = 0.1\nspot_diameter_mm = 0.1\nbogus = 1\n",
            ":5: [pbf.bogus]",
        ),
        (
            "[pbf]\nlayer_thickness_mm = 0.03\nspot_diameter_mm = 0.1\n",
            ":1: [pbf] missing required key 'hatch_spacing_mm'",
        ),
        (
            "[pbf]\nlayer_thickness_mm = -1\nhatch_spacing_mm = 0.1\nspot_diameter_mm = 0.1\n",
            ":2: [pbf.layer_thickness_mm]",
        ),
        (
            "[pbf]\nlayer_thickness_mm = 0.1\nhatch_spacing_mm = 0.1\nspot_diameter_mm = 0.1\n[axes.x]\nv_max = 1\n",
            "[axes",
        ),
        (
            "[pbf]\nlayer_thickness_mm = 0.1\nhatch_spacing_mm = 0.1\nspot_diameter_mm = 0.1\n[pbf.zone.skin]\n",
            ":5: [pbf.zone.skin]",
        ),
        (
            "[pbf]\nlayer_thickness_mm = 0.1\nhatch_spacing_mm = 0.1\nspot_diameter_mm = 0.1\nhatch_pattern = 'x'\n",
            ":5:",
        ),
    ],
)
def test_params_errors_name_line_and_key(text, where):
    with pytest.raises(MachineFileError) as err:
        parse_params(text, "b.toml")
    assert str(err.value).startswith("b.toml") and where in str(err.value)


def test_params_zone_overrides():
    p = parse_params(
        "[pbf]\nlayer_thickness_mm = 0.05\nhatch_spacing_mm = 0.12\nspot_diameter_mm = 0.1\n"
        "[pbf.zone.downskin]\npower_w = 90.0\n[pbf.scanner]\nskywriting = true\n"
    )
    assert p.zone("downskin").power_w == 90.0 and p.zone("downskin").mark_speed_mm_s == 1500.0
    assert p.scanner.skywriting and p.hatch_pattern == "meander"


# ---------------------------------------------------------------- builds


def test_build_resumes_and_never_trusts_a_damaged_file(tmp_path):
    part = _box((6, 6, 1.2), (0, 0, 0.6))
    p = default_params(layer_thickness_mm=0.1, thin_wall_mm=0.3)
    out = tmp_path / "b"
    first = build(part, p, out, workers=0, pictures=1)
    assert (first.layers, first.computed, first.skipped) == (12, 12, 0)
    whole_cli = (out / "build.cli").read_bytes()  # every layer's CLI bytes encoded where it was computed
    assert verify_build(out) == []
    man = json.loads((out / "manifest.json").read_text())
    assert man["complete"] and man["time_estimate_s"] > 12 * p.scanner.recoat_s
    assert (out / "pictures" / "L000000.png").is_file()
    good = (out / "layers" / "L000005.npy").read_bytes()
    again = build(part, p, out, workers=0, pictures=0)
    assert (again.computed, again.skipped) == (0, 12)
    # a damaged file, a layer the manifest does not list, a temporary file of a killed writer
    (out / "layers" / "L000005.npy").write_bytes(good[:-8])
    man["layers"] = [r for r in man["layers"] if r["index"] != 7]
    (out / "manifest.json").write_text(json.dumps(man))
    (out / "layers" / ".L000009.npy.tmp-1-abc").write_bytes(b"partial")
    third = build(part, p, out, workers=0, pictures=0)
    assert (third.computed, third.skipped) == (2, 10)
    assert (out / "layers" / "L000005.npy").read_bytes() == good
    # ten layers' CLI bytes re-encoded from their files, two from this run's workers: the same export
    assert (out / "build.cli").read_bytes() == whole_cli
    assert verify_build(out) == []
    assert not list((out / "layers").glob(".*"))
    # another part in the same folder is refused
    with pytest.raises(Exception, match="another build"):
        build(_box((5, 6, 1.2), (0, 0, 0.6)), p, out, workers=0)


def test_cli_build_command(tmp_path, capsys):
    stl = tmp_path / "part.stl"
    _box((5, 3, 0.6), (0, 0, 0.3)).export(stl)
    toml = tmp_path / "pbf.toml"
    toml.write_text(
        "[pbf]\nlayer_thickness_mm = 0.1\nhatch_spacing_mm = 0.1\nspot_diameter_mm = 0.08\nhatch_pattern = 'stripes'\n"
    )
    out = tmp_path / "out"
    assert main(["build", str(stl), "-m", str(toml), "-o", str(out), "--workers", "0", "--cli", "ascii"]) == 0
    text = capsys.readouterr().out
    assert "6 layers of 0.1 mm" in text and "estimated build time" in text
    cli = (out / "build.cli").read_text()
    assert cli.startswith("$$HEADERSTART\n$$ASCII\n") and cli.count("$$LAYER/") == 6
