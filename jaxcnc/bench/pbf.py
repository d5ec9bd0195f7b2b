"""The powder-bed benchmark behind ``jaxcnc bench pbf``: slice + offset + hatch beside PySLM on the same STL.

Both run the same layers of the same placed mesh (PySLM's own example part, frameGuide.stl, from the corpus), the
same layer thickness, hatch spacing, spot compensation, one contour and the same hatch angle per layer (67°
rotation; PySLM's angle 0 hatches along y, so it is given the angle minus 90°). jaxcnc: one vectorised slice of
all the layers, Clipper unions and offsets, scanline hatching (:func:`jaxcnc.pbf.layer.process_chunk`, zones
off, then on). PySLM: ``Part.getVectorSlice`` and ``Hatcher.hatch`` per layer, as its examples do. Printed:
layers/s of each (min/median of repeats), the ratio, and the total hatch length of each and their difference.

PySLM is the ``bench`` extra (``pip install 'jaxcnc[bench]'``, PyPI ``PythonSLM``); without it the suite says so
and measures jaxcnc alone.
"""

from __future__ import annotations

import importlib.util
import statistics
import time
from pathlib import Path

import numpy as np

from jaxcnc.bench.common import BenchInputMissing, measure, run_header

#: The corpus part (PySLM's example frame guide) and where the corpus is, relative to the repository.
DEFAULT_STL = Path(__file__).resolve().parents[2] / ".." / "shared" / "corpus" / "stl" / "frameGuide.stl"


def pyslm_available() -> bool:
    """Whether PySLM (PyPI PythonSLM) is importable."""
    return importlib.util.find_spec("pyslm") is not None


def pyslm_layers(mesh_vertices: np.ndarray, mesh_faces: np.ndarray, z_mm: np.ndarray, params) -> list:
    """Slice and hatch ``z_mm`` with PySLM (one contour, meander); returns its layers."""
    import pyslm
    import trimesh
    from pyslm import hatching

    part = pyslm.Part("bench")
    part.setGeometryByMesh(trimesh.Trimesh(mesh_vertices, mesh_faces, process=False))
    h = hatching.Hatcher()
    h.hatchDistance = params.hatch_spacing_mm
    h.spotCompensation = params.spot_diameter_mm / 2
    h.numInnerContours = 0
    h.numOuterContours = params.contour_count
    h.contourOffset = params.contour_spacing_mm
    h.volumeOffsetHatch = params.hatch_offset_mm
    h.hatchSortMethod = hatching.AlternateSort()
    out = []
    for k, z in enumerate(z_mm):
        h.hatchAngle = params.layer_angle_deg(k) - 90.0
        out.append(h.hatch(part.getVectorSlice(float(z))))
    return out


def pyslm_hatch_length_mm(layers: list) -> float:
    """Total length of the hatch vectors of PySLM layers."""
    from pyslm.geometry import HatchGeometry

    total = 0.0
    for layer in layers:
        if layer is None:
            continue
        for g in layer.geometry:
            if isinstance(g, HatchGeometry):
                seg = np.asarray(g.coords).reshape(-1, 2, 2)
                total += float(np.hypot(*(seg[:, 1] - seg[:, 0]).T).sum())
    return total


def dask_scaling(stl: Path, layers: int = 200, repeats: int = 3) -> dict:
    """A ``layers``-layer build of ``stl`` on a local cluster of 1 and of 2 worker processes (clusters started
    beforehand, not timed), each build into a fresh folder; the files of both are compared byte for byte."""
    import shutil
    import tempfile

    from jaxcnc.pbf.build import build
    from jaxcnc.pbf.distributed import local_cluster
    from jaxcnc.pbf.mesh import prepare
    from jaxcnc.pbf.params import default_params

    mesh = prepare(stl)
    height = float(mesh.bounds_mm[1, 2])
    params = default_params(layer_thickness_mm=height / layers, thin_wall_mm=0.3, hatch_pattern="islands")
    out: dict = {"layers": layers, "layer_thickness_mm": params.layer_thickness_mm}
    folders = {}
    for n in (1, 2):
        cluster = local_cluster(n)
        try:
            walls = []
            for r in range(repeats):
                d = Path(tempfile.mkdtemp(prefix=f"pbf-bench-{n}-"))
                t0 = time.perf_counter()
                build(stl, params, d, scheduler=cluster.scheduler_address, pictures=0, cli="binary")
                walls.append(time.perf_counter() - t0)
                if r == 0:
                    folders[n] = d
                else:
                    shutil.rmtree(d)
        finally:
            cluster.close()
        out[f"workers_{n}_wall_s"] = walls
        print(
            f"  Dask, {n} worker(s): {layers}-layer build min/median {min(walls):.2f}/{statistics.median(walls):.2f} s"
        )
    same = all(
        (folders[1] / f).read_bytes() == (folders[2] / f).read_bytes()
        for f in ["manifest.json", "build.cli"] + [f"layers/{p.name}" for p in (folders[1] / "layers").iterdir()]
    )
    ratio = statistics.median(out["workers_1_wall_s"]) / statistics.median(out["workers_2_wall_s"])
    out.update(speedup=ratio, identical=same)
    print(f"  Dask 2 workers / 1: {ratio:.2f}x faster; files identical: {same}")
    for d in folders.values():
        shutil.rmtree(d)
    return out


def run_pbf_benchmarks(stl: str | None = None, layers: int = 200, repeats: int = 3, pyslm_repeats: int = 1) -> dict:
    """Run the comparison on ``layers`` layers spread over the part's height; print and return the figures."""
    from jaxcnc.pbf.layer import process_chunk
    from jaxcnc.pbf.mesh import prepare
    from jaxcnc.pbf.params import default_params
    from jaxcnc.pbf.slice import layer_heights

    path = Path(stl) if stl else DEFAULT_STL
    if not path.is_file():
        raise BenchInputMissing(f"{path}: the benchmark's STL is missing (the corpus: ../shared/corpus/stl)")
    info = run_header("pbf")
    params = default_params(hatch_pattern="meander", thin_wall_mm=0.0, skin_layers=0, contour_count=1)
    mesh = prepare(path)
    z_all = layer_heights(float(mesh.bounds_mm[1, 2]), params.layer_thickness_mm)
    pick = np.unique(np.linspace(0, len(z_all) - 1, min(layers, len(z_all))).round().astype(int))
    z = z_all[pick]
    n = len(z)
    print(
        f"{path.name}: {len(mesh.faces)} faces, {len(z_all)} layers of {params.layer_thickness_mm} mm; {n} of them "
        f"measured; hatch {params.hatch_spacing_mm} mm meander, angle +{params.layer_rotation_deg}°/layer, spot "
        f"{params.spot_diameter_mm} mm, {params.contour_count} contour"
    )

    def ours(p=params):
        return process_chunk(mesh.vertices, mesh.faces, z, list(range(n)), p)

    res = ours()
    our_len = sum(r.hatch_length_mm for r in res)
    st = measure(ours, repeats)
    zoned = default_params(hatch_pattern="meander", thin_wall_mm=0.3, skin_layers=1, contour_count=1)
    st_z = measure(lambda: ours(zoned), repeats)
    out = dict(info=info, stl=str(path), layers=n, jaxcnc=st.as_dict(), jaxcnc_layers_s=n / st.wall_median)
    out["jaxcnc_zones_layers_s"] = n / st_z.wall_median
    out["jaxcnc_hatch_mm"] = our_len
    print(f"  jaxcnc            {n / st.wall_median:9.1f} layers/s  {st}; hatch {our_len:.1f} mm")
    print(f"  jaxcnc + zones    {n / st_z.wall_median:9.1f} layers/s  {st_z} (thin walls 0.3 mm, skins 1 layer)")
    out["dask"] = dask_scaling(path, layers=200, repeats=repeats)
    if not pyslm_available():
        print("  PySLM: not installed (pip install 'jaxcnc[bench]'); its figures are not measured")
        return out
    import pyslm

    layers_p = pyslm_layers(mesh.vertices, mesh.faces, z, params)
    p_len = pyslm_hatch_length_mm(layers_p)
    st_p = measure(lambda: pyslm_layers(mesh.vertices, mesh.faces, z, params), pyslm_repeats)
    ratio = st_p.wall_median / st.wall_median
    diff = (our_len - p_len) / p_len * 100 if p_len else float("nan")
    print(f"  PySLM {pyslm.__version__:<10}  {n / st_p.wall_median:9.1f} layers/s  {st_p}; hatch {p_len:.1f} mm")
    print(f"  jaxcnc / PySLM: {ratio:.1f}x layers/s; hatch length {diff:+.3f} %")
    out.update(pyslm=st_p.as_dict(), pyslm_layers_s=n / st_p.wall_median, pyslm_hatch_mm=p_len)
    out.update(ratio=ratio, hatch_length_diff_pct=diff, pyslm_version=pyslm.__version__)
    return out
