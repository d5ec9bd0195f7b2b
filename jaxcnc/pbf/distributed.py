"""Builds on Dask (dask.distributed): chunks of layers as tasks, results recorded as they come.

By default the build starts a local cluster in this process with one single-threaded worker process per core
(the work is NumPy and Clipper; processes avoid the GIL); ``scheduler="tcp://HOST:PORT"`` uses a running cluster
instead, whose workers must see the output folder at the same path (a shared file system).

Each task computes its layers and writes their files itself (atomically), then returns their records; the driver
adds a record to the manifest only when its task's result arrives. A worker that dies mid-task loses nothing
that was recorded: the scheduler runs its unfinished tasks again on the workers left (up to Dask's
``distributed.scheduler.allowed-failures`` times), and a file it was writing is left under a temporary name that
no one reads and the driver removes. Each layer is a pure function of the mesh, the parameters and its index, so
a layer computed twice is the same file.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable

import numpy as np

from jaxcnc.pbf.params import BuildParams


def local_cluster(workers: int | None = None):
    """A local cluster of ``workers`` (default: one per core) single-threaded worker processes, no dashboard."""
    from dask.distributed import LocalCluster

    n = workers or os.cpu_count() or 1
    return LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=40)


#: Tasks per worker when the chunk size is automatic: enough that the last tasks even out the workers' loads,
#: few enough that the scheduler's cost per task (milliseconds, on the same cores) stays small beside a task.
TASKS_PER_WORKER = 6


def auto_chunk(n_layers: int, n_workers: int) -> int:
    """Layers per task for ``n_layers`` on ``n_workers``: about :data:`TASKS_PER_WORKER` tasks each."""
    return max(1, -(-n_layers // (TASKS_PER_WORKER * max(1, n_workers))))


def run_on_dask(
    vertices: np.ndarray,
    faces: np.ndarray,
    z_all_mm: np.ndarray,
    layers: list[int],
    chunk: int | None,
    params: BuildParams,
    out: str,
    record: Callable[[tuple[list[dict], dict[int, bytes]]], None],
    workers: int | None = None,
    scheduler: str | None = None,
    cli: str = "none",
    lists=None,
) -> None:
    """Run :func:`jaxcnc.pbf.build.run_chunk` on ``layers`` in tasks of ``chunk`` layers (``None``:
    :func:`auto_chunk` for the cluster's workers); call ``record`` with each task's result (its records and its
    layers' CLI bytes) as it ends."""
    from dask.distributed import Client, as_completed

    from jaxcnc.pbf.build import chunks_of, run_chunk

    cluster = None
    if scheduler is None:
        cluster = local_cluster(workers)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        if chunk is None:
            chunk = auto_chunk(len(layers), len(client.scheduler_info().get("workers", {})))
        jobs = chunks_of(layers, chunk)
        run = uuid.uuid4().hex[:8]
        v, f, z = client.scatter([vertices, faces, z_all_mm], broadcast=True)
        futures = [
            client.submit(run_chunk, v, f, z, job, params, out, cli, lists, key=f"pbf-layers-{job[0]}-{job[-1]}-{run}")
            for job in jobs
        ]
        for fut in as_completed(futures):
            record(fut.result())
            fut.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
