"""Issue 19, Deliver 4: each layer compiled into a galvo board list (issue 18's format) and, on request, a tick
table of a layer planned on a scanner-only machine and checked by the independent check."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("trimesh")
pytest.importorskip("pyclipper")
import shapely  # noqa: E402
import trimesh  # noqa: E402

from jaxcnc.errors import MachineFileError  # noqa: E402
from jaxcnc.format.vectors import Op, read_vectors  # noqa: E402
from jaxcnc.machine import load_machine  # noqa: E402
from jaxcnc.pbf import BuildError  # noqa: E402
from jaxcnc.pbf.build import build, verify_build  # noqa: E402
from jaxcnc.pbf.params import default_params  # noqa: E402
from jaxcnc.pbf.scanlist import layer_ticks, list_target, mark_length_mm  # noqa: E402
from tests.conftest import GALVO_PATH, GALVO_XY  # noqa: E402

#: A head (τ 120 µs, 4 m/s² ·1e6) with the settings jaxcnc.scanner.compile.auto_settings chooses for it at
#: 1 m/s marks, 7 m/s jumps, 0.01 mm: laser delays = τ, sky-writing mode 2 with 82-tick run-in/out, limit
#: 8.67°, a jump delay of 2307 ticks (the mirrors settle after a 7 m/s jump).
GALVO = (
    GALVO_XY
    + GALVO_PATH
    + """[galvo]
tracking_error_s = 120e-6
mirror_a_max_mm_s2 = 4e6
laser_on_delay_s = 120e-6
laser_off_delay_s = 120e-6
sky_writing = 2
run_in_s = 820e-6
run_out_s = 820e-6
sky_limit_deg = 8.67
jump_delay_s = 0.02307
"""
)
PART = (3.0, 2.0, 0.6)


def _build(tmp_path, lists=True, out="out", **kw):
    m = tmp_path / "g.toml"
    m.write_text(GALVO)
    params = default_params(layer_thickness_mm=0.1, thin_wall_mm=0.3)
    target = list_target(m, params) if lists else None
    res = build(trimesh.creation.box(PART), params, tmp_path / out, pictures=0, lists=target, **kw)
    return res, params, m


def _mark_mm(v: np.ndarray) -> float:
    mk = v["mark"] == 1
    return float(np.hypot(v["x1_mm"] - v["x0_mm"], v["y1_mm"] - v["y0_mm"])[mk].sum())


def test_layer_lists_read_back_execute_on_the_layers_vectors(tmp_path):
    from jaxcnc.scanner.emulator import emulate
    from jaxcnc.scanner.head import HeadModel

    res, params, m = _build(tmp_path, workers=0)
    assert verify_build(res.out_dir) == [] and res.manifest["complete"]
    head = HeadModel.from_machine(load_machine(m))
    for k in (0, 3):  # a down-skin layer and a core one
        rec = res.manifest["layers"][k]
        v = np.load(res.out_dir / rec["file"])
        header, lst = read_vectors(res.out_dir / rec["list"]["file"])
        assert header.meta["layer"] == k and header.tick_hz == 100000 and header.discrete_mm == 0.001
        # the [galvo] settings travel with the list: sky-writing mode 2, 82-tick run-in, the jump delay
        sky = lst[lst["op"] == Op.SET_SKY_WRITING][0]
        assert (sky["aux"], sky["ticks"], sky["pos"][0]) == (2, 82, 82)
        assert lst[lst["op"] == Op.SET_SCANNER_DELAYS][0]["ticks"] == 2307
        # zone speeds and powers: every mark speed of the layer is set in the list
        assert set(lst["value"][lst["op"] == Op.SET_MARK_SPEED]) == set(v["speed_mm_s"][v["mark"] == 1])
        # mark length: the layer's hatch + contour length, within a discrete per mark end
        n_marks = int((v["mark"] == 1).sum())
        contour = _mark_mm(v[v["zone"] == 1])
        assert abs(mark_length_mm(lst, header) - (rec["hatch_mm"] + contour)) <= 2 * n_marks * 0.001
        assert abs(_mark_mm(v) - (rec["hatch_mm"] + contour)) < 1e-9
        # executed on the emulator with the head model: the lit beam lies on the layer's mark vectors
        em = emulate(lst, header, head, load_s=None)
        lit = em.power > 0
        marks = v[v["mark"] == 1]
        lines = shapely.MultiLineString([((a["x0_mm"], a["y0_mm"]), (a["x1_mm"], a["y1_mm"])) for a in marks])
        dist = shapely.distance(shapely.points(em.actual[lit]), lines)
        assert dist.max() < 0.005  # half the 0.01 mm the settings were chosen for
        # and the lit time covers the marks: lit ticks x speed ~ mark length (within the laser delays' ticks)
        assert lit.sum() * header.dt * params.zone("contour").mark_speed_mm_s < _mark_mm(v) * 1.05


def test_lists_resume_and_a_damaged_list_is_made_again(tmp_path):
    res, _, _ = _build(tmp_path, workers=0)
    again, _, _ = _build(tmp_path, workers=0)
    assert again.computed == 0
    f = res.out_dir / res.manifest["layers"][2]["list"]["file"]
    old = f.read_bytes()
    f.write_bytes(old[:-3])
    assert any("checksum differs" in p for p in verify_build(res.out_dir))
    third, _, _ = _build(tmp_path, workers=0)
    assert third.computed == 1 and f.read_bytes() == old and verify_build(res.out_dir) == []


@pytest.mark.slow
def test_lists_made_on_dask_workers_equal_the_serial_ones(tmp_path):
    serial, _, _ = _build(tmp_path, out="serial", workers=0)
    dask, _, _ = _build(tmp_path, out="dask", workers=2, chunk=2)
    for a, b in zip(serial.manifest["layers"], dask.manifest["layers"], strict=True):
        assert a["list"]["sha256"] == b["list"]["sha256"]
        assert (serial.out_dir / a["list"]["file"]).read_bytes() == (dask.out_dir / b["list"]["file"]).read_bytes()


def test_a_layers_tick_table_passes_the_independent_check(tmp_path):
    from jaxcnc.jobs import check_table

    res, _, m = _build(tmp_path, workers=0)
    rep = layer_ticks(res.out_dir, 3, m)
    table, meas = check_table(rep["table"], m, program=rep["program"])
    assert meas.ok, meas.violations[:3]
    assert meas.path is not None and meas.path.n_over == 0
    v = np.load(res.out_dir / res.manifest["layers"][3]["file"])
    lengths = np.hypot(v["x1_mm"] - v["x0_mm"], v["y1_mm"] - v["y0_mm"])
    start = np.hypot(v["x0_mm"][0], v["y0_mm"][0])  # from the machine's home at the origin to the first vector
    # the planned path: every vector, corners blended within the path tolerance (0.01 mm) at most
    assert abs(rep["path_length_mm"] - (lengths.sum() + start)) <= len(v) * meas.path.max_tol_mm
    assert table.header.n_rows == rep["n_ticks"]
    with pytest.raises(BuildError, match=r"layer 99 is not in this build"):
        layer_ticks(res.out_dir, 99, m)


def test_lists_need_a_galvo_machine(tmp_path):
    m = tmp_path / "plain.toml"
    m.write_text(GALVO_XY + GALVO_PATH)
    with pytest.raises(MachineFileError, match=r"plain\.toml: \[galvo\] machine 'galvo' has no \[galvo\] table"):
        list_target(m, default_params())


def test_build_command_writes_lists_and_verified_tick_tables(tmp_path, capsys):
    from jaxcnc.cli.main import main

    (tmp_path / "g.toml").write_text(GALVO)
    (tmp_path / "pbf.toml").write_text(
        "[pbf]\nlayer_thickness_mm = 0.1\nhatch_spacing_mm = 0.1\nspot_diameter_mm = 0.08\n"
    )
    trimesh.creation.box(PART).export(tmp_path / "box.stl")
    base = ["build", str(tmp_path / "box.stl"), "-m", str(tmp_path / "pbf.toml"), "--workers", "0", "--pictures", "0"]
    out = tmp_path / "out"
    assert main([*base, "-o", str(out), "--galvo", str(tmp_path / "g.toml"), "--lists", "--ticks", "1-2"]) == 0
    text = capsys.readouterr().out
    assert "board lists: 6" in text and "layer 2: " in text and "verified" in text
    assert sorted(p.name for p in (out / "layers").glob("*.jxv")) == [f"L{k:06d}.jxv" for k in range(6)]
    assert sorted(p.name for p in (out / "ticks").glob("*.ticks")) == ["L000001.ticks", "L000002.ticks"]
    assert verify_build(out) == []
    # a bad option or a machine without [galvo]: one line, exit 2, nothing built
    assert main([*base, "-o", str(tmp_path / "o2"), "--ticks", "1"]) == 2
    assert main([*base, "-o", str(tmp_path / "o2"), "--galvo", str(tmp_path / "g.toml"), "--ticks", "2x"]) == 2
    assert main([*base, "-o", str(tmp_path / "o2"), "--galvo", str(tmp_path / "pbf.toml"), "--lists"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"jaxcnc: error: {tmp_path / 'pbf.toml'}:1: ")
    assert "need --galvo MACHINE" in err[0] and "--ticks '2x'" in err[1]
    assert not (tmp_path / "o2").exists()
