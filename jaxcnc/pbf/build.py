"""The build driver: a mesh and build parameters in, one file per layer and a manifest with checksums out.

Layout of the output folder::

    manifest.json          what was built from what: the mesh's and the parameters' SHA-256, every layer's file,
                           SHA-256, size, vector count, hatch length, zone areas and estimated time, and whether
                           the build is complete
    layers/L000042.npy     layer 42's vector list (jaxcnc.pbf.order.VECTOR_DTYPE, NumPy .npy)
    build.cli              the whole build as a Common Layer Interface file (binary or ASCII), when complete
    pictures/L000042.png   pictures of some layers: contours and hatches coloured by zone

Every file is written under a temporary name in its folder and renamed when complete, so a name that looks
complete is complete. A rerun in the same folder reads the manifest and skips each layer whose file exists with
the recorded SHA-256; a layer file the manifest does not list (a run stopped before recording it) or whose
checksum differs is computed again. A manifest of another mesh or other parameters is refused.

The layers are computed in chunks (:func:`jaxcnc.pbf.layer.process_chunk`) in this process (``workers=0``) or on
Dask (:mod:`jaxcnc.pbf.distributed`); the files are the same bit for bit either way.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import time
import uuid
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxcnc.pbf import BuildError
from jaxcnc.pbf.params import BuildParams

MANIFEST = "manifest.json"
FORMAT = "jaxcnc-pbf-build/1"
LAYER_DIR = "layers"


def layer_name(k: int) -> str:
    """File name of layer ``k``'s vector list."""
    return f"L{k:06d}.npy"


def sha256_bytes(b: bytes) -> str:
    """Hex SHA-256 of ``b``."""
    return hashlib.sha256(b).hexdigest()


def sha256_file(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a unique temporary name in the same folder, then rename it."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def npy_bytes(a: np.ndarray) -> bytes:
    """The .npy bytes of ``a`` (deterministic: header and data only)."""
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


def run_chunk(
    vertices: np.ndarray,
    faces: np.ndarray,
    z_all_mm: np.ndarray,
    layers: list[int],
    params: BuildParams,
    out: str,
    cli: str = "none",
    lists=None,
) -> tuple[list[dict], dict[int, bytes]]:
    """Compute and write the layers ``layers``; return their manifest records and, unless ``cli`` is ``"none"``,
    each layer's bytes of the CLI export (``"binary"`` or ``"ascii"``; the driver only joins them, so the export's
    work is spread over the workers too). With ``lists`` (a :class:`jaxcnc.pbf.scanlist.ListTarget`) each
    layer's board list is compiled and written beside its vector file. Runs on a worker or here."""
    from jaxcnc.pbf.cli_format import CLILayer, encode_layer, layer_blocks
    from jaxcnc.pbf.layer import process_chunk
    from jaxcnc.pbf.order import layer_time_s

    folder = Path(out) / LAYER_DIR
    records, parts = [], {}
    for scan in process_chunk(vertices, faces, z_all_mm, layers, params):
        if cli != "none":
            layer = CLILayer(scan.z_mm, layer_blocks(scan.vectors))
            parts[scan.index] = encode_layer(layer, params.cli_units_mm, cli == "binary")
        data = npy_bytes(scan.vectors)
        name = layer_name(scan.index)
        atomic_write(folder / name, data)
        records.append(
            dict(
                index=scan.index,
                z_mm=scan.z_mm,
                file=f"{LAYER_DIR}/{name}",
                sha256=sha256_bytes(data),
                bytes=len(data),
                vectors=len(scan.vectors),
                marks=int((scan.vectors["mark"] == 1).sum()),
                hatch_mm=scan.hatch_length_mm,
                time_s=layer_time_s(scan.vectors, params),
                zone_area_mm2=scan.zone_area_mm2,
            )
        )
        if lists is not None:
            from jaxcnc.pbf.scanlist import layer_list_bytes, list_name

            blob = layer_list_bytes(scan.vectors, lists, scan.index, scan.z_mm)
            atomic_write(folder / list_name(scan.index), blob)
            records[-1]["list"] = dict(
                file=f"{LAYER_DIR}/{list_name(scan.index)}", sha256=sha256_bytes(blob), bytes=len(blob),
                target=lists.digest(),
            )  # fmt: skip
    return records, parts


@dataclass
class BuildResult:
    """What a build did: where, how many layers computed and skipped, the estimate, the mesh report."""

    out_dir: Path
    layers: int
    computed: int
    skipped: int
    time_estimate_s: float
    hatch_mm: float
    mesh_report: object
    manifest: dict = field(repr=False, default_factory=dict)
    cli_file: Path | None = None
    pictures: list[Path] = field(default_factory=list)


def chunks_of(indices: list[int], size: int) -> list[list[int]]:
    """Split sorted layer indices into runs of consecutive indices of at most ``size``."""
    out: list[list[int]] = []
    for k in indices:
        if out and k == out[-1][-1] + 1 and len(out[-1]) < size:
            out[-1].append(k)
        else:
            out.append([k])
    return out


def _clean_temporaries(folder: Path) -> None:
    for d in (folder, folder / LAYER_DIR, folder / "pictures"):
        if d.is_dir():
            for p in d.glob(".*.tmp-*"):
                p.unlink(missing_ok=True)


def write_manifest(out: Path, manifest: dict) -> None:
    """Write the manifest (layers sorted by index) atomically."""
    m = dict(manifest)
    m["layers"] = (
        sorted(m["layers"].values(), key=lambda r: r["index"]) if isinstance(m["layers"], dict) else m["layers"]
    )
    atomic_write(out / MANIFEST, (json.dumps(m, indent=1, sort_keys=True) + "\n").encode())


def _holds(out: Path, rec: dict) -> bool:
    f = out / rec.get("file", "")
    return f.is_file() and f.stat().st_size == rec.get("bytes") and sha256_file(f) == rec.get("sha256")


def _previous(out: Path, key: dict, lists_digest: str | None = None) -> dict[int, dict]:
    """Layers of an earlier run of the same build whose files hold their checksums (and, when lists are asked
    for, whose board list was made for the same target and holds its checksum)."""
    path = out / MANIFEST
    if not path.is_file():
        return {}
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError):
        raise BuildError(f"{path}: damaged manifest; remove it (or the folder) to build again") from None
    if not isinstance(old, dict) or old.get("format") != FORMAT:
        raise BuildError(f"{path}: not a jaxcnc powder-bed manifest")
    for k, v in key.items():
        if old.get(k) != v:
            raise BuildError(f"{path}: the folder holds another build ({k} differs); use another folder or remove it")
    keep = {}
    for rec in old.get("layers", []):
        if not _holds(out, rec):
            continue
        if lists_digest is not None:
            li = rec.get("list")
            if not isinstance(li, dict) or li.get("target") != lists_digest or not _holds(out, li):
                continue
        elif "list" in rec and not _holds(out, rec["list"]):
            rec.pop("list")  # a damaged list of an earlier run: dropped (verify_build names its file)
        keep[int(rec["index"])] = rec
    return keep


def assemble_cli(
    out: Path,
    manifest: dict,
    binary: bool,
    units_mm: float,
    bounds_mm: np.ndarray,
    parts: dict[int, bytes] | None = None,
) -> Path:
    """Write ``build.cli`` in layer order from each layer's encoded bytes (``parts``, from the workers that
    computed the layers) or, for a layer computed by an earlier run, from its layer file (its checksum checked
    first)."""
    from jaxcnc.pbf.cli_format import CLIData, CLILayer, encode_layer, layer_blocks, write_cli, zone_labels

    parts = parts or {}
    data = CLIData(units_mm=units_mm, binary=binary, labels=zone_labels())
    data.dimension_mm = tuple(float(x) for x in np.concatenate([bounds_mm[0], bounds_mm[1]]))
    encoded = []
    for rec in manifest["layers"]:
        part = parts.get(int(rec["index"]))
        if part is None:
            raw = (out / rec["file"]).read_bytes()
            if sha256_bytes(raw) != rec["sha256"]:
                raise BuildError(f"{out / rec['file']}: checksum differs from the manifest's; build again")
            vec = np.load(io.BytesIO(raw), allow_pickle=False)
            part = encode_layer(CLILayer(rec["z_mm"], layer_blocks(vec)), units_mm, binary)
        data.layers.append(CLILayer(rec["z_mm"], []))  # counted in the header; the bytes are the part's
        encoded.append(part)
    path = out / "build.cli"
    write_cli(path, data, encoded)
    return path


def build(
    mesh_source,
    params: BuildParams,
    out_dir: str | Path,
    workers: int | None = None,
    scheduler: str | None = None,
    chunk: int | None = None,
    cli: str = "binary",
    pictures: int = 4,
    progress: Callable[[int, int], None] | None = None,
    layers: Iterable[int] | None = None,
    lists=None,
) -> BuildResult:
    """Build a part: prepare the mesh, compute every layer not already done, write the manifest and exports.

    Args:
        mesh_source: a mesh file path or a ``trimesh.Trimesh``.
        params: the build parameters. out_dir: the output folder (created).
        workers: 0 computes here, serially; ``None`` (default) a local Dask cluster with one worker process per
            core; n a local cluster of n. scheduler: ``tcp://HOST:PORT`` of a running Dask scheduler (then
            ``out_dir`` must be reachable by the workers at the same path).
        chunk: layers per task (default: :func:`jaxcnc.pbf.distributed.auto_chunk` — about
            :data:`~jaxcnc.pbf.distributed.TASKS_PER_WORKER` tasks per worker; 8 computing here).
        cli: ``binary``, ``ascii`` or ``none``. pictures: how many layers to draw, spread over the height (0: none;
            -1: all).
        progress: called with (layers done, layers total) as layers finish.
        layers: only these layer indices (the manifest is then incomplete and no CLI is written).
        lists: a :class:`jaxcnc.pbf.scanlist.ListTarget` (from a scanner-only machine file,
            :func:`jaxcnc.pbf.scanlist.list_target`): each layer's board list written beside its vector file
            (``layers/L000042.jxv``), on the worker that computes the layer; ``None``: no lists.
    """
    from jaxcnc.pbf.mesh import prepare
    from jaxcnc.pbf.slice import layer_heights

    out = Path(out_dir)
    try:
        (out / LAYER_DIR).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BuildError(f"{out}: cannot create the build folder: {exc.strerror or exc}") from None
    _clean_temporaries(out)
    mesh = prepare(mesh_source, params.merge_tol_mm, params.repair, params.placement, params.plate_center_mm,
                   check_thickness_mm=params.layer_thickness_mm)  # fmt: skip
    z_all = layer_heights(float(mesh.bounds_mm[1, 2]), params.layer_thickness_mm)
    key = dict(format=FORMAT, mesh_sha256=mesh.digest, params_sha256=params.digest())
    done = _previous(out, key, None if lists is None else lists.digest())
    wanted = sorted(set(range(len(z_all))) if layers is None else {int(k) for k in layers if 0 <= k < len(z_all)})
    todo = [k for k in wanted if k not in done]
    manifest = dict(
        key,
        mesh=dict(
            file=str(mesh.report.file),
            faces=int(len(mesh.faces)),
            shells=mesh.report.shells,
            defects=[str(d) for d in mesh.report.defects],
            repaired=mesh.report.repaired,
            bounds_mm=mesh.bounds_mm.tolist(),
        ),
        params=params.as_dict(),
        layer_count=len(z_all),
        layers=dict(done),
        complete=False,
    )
    write_manifest(out, manifest)
    total = len(wanted)
    n_done = len([k for k in wanted if k in done])
    if progress:
        progress(n_done, total)
    last_write = time.monotonic()

    cli_parts: dict[int, bytes] = {}

    def record(result: tuple[list[dict], dict[int, bytes]]) -> None:
        nonlocal n_done, last_write
        recs, parts = result
        cli_parts.update(parts)
        for r in recs:
            manifest["layers"][r["index"]] = r
        n_done += len(recs)
        if progress:
            progress(n_done, total)
        if time.monotonic() - last_write > 2.0:
            write_manifest(out, manifest)
            last_write = time.monotonic()

    if chunk is not None and chunk < 1:
        raise BuildError(f"chunk {chunk}: a task holds at least one layer")
    if workers == 0 and scheduler is None:
        for job in chunks_of(todo, chunk or 8):
            record(run_chunk(mesh.vertices, mesh.faces, z_all, job, params, str(out), cli, lists))
    elif todo:
        from jaxcnc.pbf.distributed import run_on_dask

        run_on_dask(
            mesh.vertices, mesh.faces, z_all, todo, chunk, params, str(out), record, workers, scheduler, cli, lists
        )
    complete = all(k in manifest["layers"] for k in range(len(z_all)))
    manifest["complete"] = complete
    recs = sorted(manifest["layers"].values(), key=lambda r: r["index"])
    est = float(sum(r["time_s"] for r in recs))
    manifest["time_estimate_s"] = est
    manifest["hatch_mm"] = float(sum(r["hatch_mm"] for r in recs))
    cli_path = None
    if complete and cli != "none":
        cli_path = assemble_cli(out, dict(manifest, layers=recs), cli == "binary", params.cli_units_mm,
                                mesh.bounds_mm, cli_parts)  # fmt: skip
        manifest["cli"] = dict(file=cli_path.name, sha256=sha256_file(cli_path), binary=cli == "binary")
    write_manifest(out, manifest)
    pics = []
    if pictures and recs:
        from jaxcnc.pbf.picture import draw_layers

        idx = [r["index"] for r in recs]
        chosen = idx if pictures < 0 else sorted(set(np.linspace(0, len(idx) - 1, pictures).round().astype(int)))
        pics = draw_layers(out, [recs[i] for i in chosen] if pictures > 0 else recs)
    _clean_temporaries(out)
    return BuildResult(
        out, len(z_all), len(todo), len(wanted) - len(todo), est, manifest["hatch_mm"], mesh.report,
        dict(manifest, layers=recs), cli_path, pics,
    )  # fmt: skip


def verify_build(out_dir: str | Path) -> list[str]:
    """Check a build folder against its manifest: every layer file present with its SHA-256, the CLI's too,
    and no other layer file. Returns the problems found (empty: the build is whole)."""
    out = Path(out_dir)
    m = json.loads((out / MANIFEST).read_text())
    problems = []
    listed = set()
    for rec in m["layers"]:
        for r in (rec, rec.get("list")):
            if r is None:
                continue
            f = out / r["file"]
            listed.add(f.name)
            if not f.is_file():
                problems.append(f"{f}: missing")
            elif sha256_file(f) != r["sha256"]:
                problems.append(f"{f}: checksum differs")
    for f in (out / LAYER_DIR).iterdir():
        if f.name not in listed:
            problems.append(f"{f}: not in the manifest")
    if "cli" in m and sha256_file(out / m["cli"]["file"]) != m["cli"]["sha256"]:
        problems.append(f"{out / m['cli']['file']}: checksum differs")
    if not m.get("complete"):
        problems.append(f"{out / MANIFEST}: build not complete")
    return problems
