"""Where tasks run: a Dask client on a LocalCluster, on an existing scheduler (address), or on
batch-job workers (dask-jobqueue SLURM / PBS); and the loop that submits a run's tasks to it."""
from __future__ import annotations

import os
import time

from rich.console import Console

from pipeline.catalog import Catalog
from pipeline.tasks import run_task


def jobqueue_cluster(ex):
    """A dask-jobqueue SLURMCluster / PBSCluster from executor.jobqueue (no jobs started yet)."""
    import dask_jobqueue

    jq = ex.jobqueue
    cls = {"slurm": dask_jobqueue.SLURMCluster, "pbs": dask_jobqueue.PBSCluster}[ex.kind]
    return cls(cores=jq.cores, memory=jq.memory, processes=jq.processes, walltime=jq.walltime, queue=jq.queue,
               account=jq.account, job_extra_directives=list(jq.job_extra_directives),
               log_directory=jq.log_directory, job_name="navarena-worker")


def dask_client(ex):
    import logging

    import dask
    from dask.distributed import Client, LocalCluster

    for name in list(logging.root.manager.loggerDict):
        if name.startswith(("distributed", "bokeh", "tornado")):
            logging.getLogger(name).setLevel(logging.WARNING)
    # a task that kills its worker (out of memory) is a failure of that scene, not worth 3 retries
    dask.config.set({"distributed.scheduler.allowed-failures": 1})
    if ex.kind == "address" or ex.address:
        if not ex.address:
            raise ValueError("executor.kind=address needs executor.address=tcp://host:port")
        return Client(ex.address), None
    if ex.kind in ("slurm", "pbs"):
        cluster = jobqueue_cluster(ex)
        cluster.scale(jobs=ex.jobqueue.jobs)
        return Client(cluster), cluster
    if ex.kind != "local":
        raise ValueError(f"executor.kind must be local, address, slurm, pbs or sync, not {ex.kind!r}")
    # numba threads per worker: share the cores instead of oversubscribing them
    os.environ.setdefault("NUMBA_NUM_THREADS", str(max(1, (os.cpu_count() or 1) // max(ex.n_workers, 1))))
    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_ in its workers, which also freezes glibc's mmap
    # threshold at 128 KiB: every large temporary (the CPU renderer's per-tile tensors) becomes a
    # fresh mmap and page faults; a semantics scene took 6x longer in a worker than in a process
    import dask

    env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    env.pop("MALLOC_TRIM_THRESHOLD_", None)
    dask.config.set({"distributed.nanny.pre-spawn-environ": env})
    cluster = LocalCluster(n_workers=ex.n_workers, threads_per_worker=ex.threads_per_worker,
                           processes=ex.processes, memory_limit=ex.memory_limit,
                           dashboard_address=":0" if ex.dashboard else None, silence_logs=40)
    return Client(cluster), cluster


def run_on_dask(cfg, catalog: Catalog, chain, record, console: Console) -> None:
    from dask.distributed import as_completed

    client, cluster = dask_client(cfg.executor)
    try:
        if client.dashboard_link:
            console.print(f"Dask dashboard: {client.dashboard_link}")
        run_id = f"{os.getpid()}-{time.time_ns()}"

        def submit(st, scene, h, force, ups):
            return client.submit(run_task, st.name, scene, cfg, catalog, h, force, *ups,
                                 key=f"{st.name}-{scene.scene_id}-{h}-{run_id}", pure=False)
        handles = chain(submit)
        what = {fut.key: (name, scene) for name, scene, fut in handles}
        for fut in as_completed([fut for _, _, fut in handles]):
            try:
                r = fut.result()
            except Exception as e:  # noqa: BLE001 - a killed worker, a lost dependency
                name, sc = what[fut.key]
                r = {"stage": name, "scene_id": sc.scene_id, "scene": sc.name, "status": "failed",
                     "error": f"{type(e).__name__}: {e}"}
            record(r)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
