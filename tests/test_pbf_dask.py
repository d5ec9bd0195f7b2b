"""Builds on Dask: the same files as a serial build, and a worker killed mid-build loses nothing."""

from __future__ import annotations

import filecmp
import os
import signal
import threading
import time

import pytest

trimesh = pytest.importorskip("trimesh")
distributed = pytest.importorskip("distributed")

from jaxcnc.pbf.build import build, verify_build  # noqa: E402
from jaxcnc.pbf.distributed import local_cluster  # noqa: E402
from jaxcnc.pbf.params import default_params  # noqa: E402

pytestmark = pytest.mark.slow


def _part():
    """A ring 10 mm tall: 200 layers of 0.05 mm."""
    return trimesh.creation.annulus(r_min=4.0, r_max=9.0, height=10.0, sections=96)


PARAMS = default_params(layer_thickness_mm=0.05, hatch_spacing_mm=0.03, thin_wall_mm=0.3, hatch_pattern="islands")


def _same(a, b):
    cmp = filecmp.dircmp(a / "layers", b / "layers")
    assert not (cmp.diff_files or cmp.left_only or cmp.right_only or cmp.funny_files)
    _, mismatch, errors = filecmp.cmpfiles(a / "layers", b / "layers", cmp.common_files, shallow=False)
    assert not mismatch and not errors
    for name in ("manifest.json", "build.cli"):
        assert (a / name).read_bytes() == (b / name).read_bytes()


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    res = build(_part(), PARAMS, out, workers=0, pictures=0)
    assert res.layers == 200 and verify_build(out) == []
    return out


def test_two_workers_same_files_as_serial(serial, tmp_path):
    res = build(_part(), PARAMS, tmp_path, workers=2, pictures=0)
    assert res.computed == 200
    _same(serial, tmp_path)


def test_killed_worker_layers_rerun(serial, tmp_path):
    """Two worker processes; one is killed with SIGKILL mid-build. Its layers are computed again elsewhere."""
    cluster = local_cluster(2)
    client = distributed.Client(cluster)
    killed = {}

    def killer():
        pids = client.run(os.getpid)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            done = len(list((tmp_path / "layers").glob("L*.npy"))) if (tmp_path / "layers").is_dir() else 0
            if done >= 30:
                addr, pid = sorted(pids.items())[0]
                killed.update(pid=pid, done_before=done)
                os.kill(pid, signal.SIGKILL)
                return
            time.sleep(0.005)

    t = threading.Thread(target=killer)
    t.start()
    try:
        res = build(_part(), PARAMS, tmp_path, scheduler=cluster.scheduler_address, pictures=0, chunk=4)
    finally:
        t.join()
        client.close()
        cluster.close()
    assert killed and killed["done_before"] < 200  # killed mid-build
    with pytest.raises(ProcessLookupError):
        os.kill(killed["pid"], 0)
    assert res.computed == 200 and res.skipped == 0
    assert verify_build(tmp_path) == []  # every file listed, checksums hold, nothing else in layers/
    assert not [p for p in tmp_path.rglob(".*") if p.is_file()]  # no temporary left behind
    _same(serial, tmp_path)
