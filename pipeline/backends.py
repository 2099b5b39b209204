"""Where tasks run: a Dask client on a local cluster (CPU workers plus one worker per GPU), on an
existing scheduler (address), or on batch-job workers (dask-jobqueue SLURM / PBS); and the loop
that submits a run's tasks to it.

Placement uses Dask worker resources: GPU workers advertise GPU=1 (and see only their own GPU,
CUDA_VISIBLE_DEVICES), CPU workers CPU=<threads> (and see no GPU); every worker MEMORY=<GB>.
With GPU workers present a stage declared `gpu` asks for GPU=1 and the others for CPU=1, so GPU
stages run one per GPU and never on a CPU worker, and CPU stages fill the CPU workers; every
task also asks for its stage's memory_gb (capped at a worker's memory).
"""
from __future__ import annotations

import contextlib
import functools
import os
import subprocess
import sys
import time
from dataclasses import dataclass

from distributed.diagnostics.plugin import WorkerPlugin
from rich.console import Console

from navcore.io.catalog import Catalog
from pipeline.tasks import FAILED, current, new_run, run_task


def visible_gpus() -> list[str]:
    """The GPU ids this machine gives the run: CUDA_VISIBLE_DEVICES when set, else nvidia-smi's
    list (no torch import: the client process stays light)."""
    env = os.environ.get("CUDA_VISIBLE_DEVICES")
    if env is not None:
        return [d.strip() for d in env.split(",") if d.strip() and d.strip() != "-1"]
    return list(gpu_uuids())


@functools.cache
def gpu_uuids() -> dict[str, str]:
    """nvidia-smi's GPUs of this host, index -> UUID (without the 'GPU-' prefix); empty without
    nvidia-smi. CUDA_VISIBLE_DEVICES does not change what nvidia-smi lists."""
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=index,uuid", "--format=csv,noheader"],
                             capture_output=True, text=True, timeout=20).stdout
    except (OSError, subprocess.SubprocessError):
        return {}
    rows = [[f.strip() for f in ln.split(",")] for ln in out.splitlines() if ln.count(",") == 1]
    return {i: u.removeprefix("GPU-") for i, u in rows}


def gpu_identity() -> dict:
    """Where this process's CUDA work went: the GPU it is pinned to (CUDA_VISIBLE_DEVICES, and that
    GPU's UUID by nvidia-smi) and, once a task has used CUDA, torch's current device and its UUID
    as the driver reports it. Nothing is imported: a process whose tasks never touched CUDA says
    only where it is pinned."""
    pinned = os.environ.get("CUDA_VISIBLE_DEVICES")
    if not pinned:
        return {}
    out = {"gpu": pinned}
    expected = pinned if pinned.startswith("GPU-") else gpu_uuids().get(pinned)
    if expected:
        out["gpu_pinned_uuid"] = expected.removeprefix("GPU-")
    torch = sys.modules.get("torch")
    if torch is not None and torch.cuda.is_initialized():
        i = torch.cuda.current_device()
        out["cuda_device"] = i
        out["gpu_uuid"] = str(torch.cuda.get_device_properties(i).uuid).removeprefix("GPU-")
    return out


def memory_gb(limit) -> float:
    """A Dask memory limit ('8GB', '512MiB', bytes) in GB."""
    from dask.utils import parse_bytes

    return parse_bytes(limit) / 1e9 if isinstance(limit, str) else float(limit) / 1e9


@dataclass
class Placement:
    """What the cluster's workers advertise; `resources(stage)` is a task's request."""

    gpu_workers: int = 0
    worker_memory_gb: float | None = None

    def resources(self, stage) -> dict | None:
        req = {}
        if self.gpu_workers:
            req["GPU" if stage.gpu else "CPU"] = 1
        if self.worker_memory_gb:
            req["MEMORY"] = min(stage.memory_gb, self.worker_memory_gb)
        return req or None


class PinGPU:
    """Worker plugin of GPU batch jobs: worker process k of a job (name suffix -k) sees only the
    job's k-th GPU. Runs at worker start, before any task imports torch."""

    name = "navarena-pin-gpu"

    def setup(self, worker):
        ids = [d for d in os.environ.get("CUDA_VISIBLE_DEVICES", "").split(",") if d]
        k = str(worker.name).rsplit("-", 1)[-1]
        if ids and k.isdigit():
            os.environ["CUDA_VISIBLE_DEVICES"] = ids[int(k) % len(ids)]


def jobqueue_cluster(ex):
    """A dask-jobqueue SLURMCluster / PBSCluster from executor.jobqueue (no jobs started yet)."""
    import dask_jobqueue

    jq = ex.jobqueue
    cls = {"slurm": dask_jobqueue.SLURMCluster, "pbs": dask_jobqueue.PBSCluster}[ex.kind]
    gpus = jq.gpus_per_job > 0
    processes = jq.gpus_per_job if gpus else jq.processes  # one worker process per GPU
    per_worker = memory_gb(jq.memory) / max(processes, 1)
    directives = list(jq.job_extra_directives)
    if gpus:
        directives.append(f"--gres=gpu:{jq.gpus_per_job}" if ex.kind == "slurm" else f"-l ngpus={jq.gpus_per_job}")
    extra = ["--resources", ("GPU=1,CPU=1," if gpus else "") + f"MEMORY={per_worker:.3f}"]
    cluster = cls(cores=jq.cores, memory=jq.memory, processes=processes, walltime=jq.walltime, queue=jq.queue,
                  account=jq.account, job_extra_directives=directives, worker_extra_args=extra,
                  log_directory=jq.log_directory, job_name="navarena-worker")
    return cluster, Placement(int(gpus), per_worker)


def local_cluster(ex, gpus: list[str]):
    """CPU workers (no GPU visible) plus one worker per GPU (pinned to it), as one SpecCluster."""
    import psutil
    from dask.distributed import Nanny, Scheduler, SpecCluster

    if not ex.processes:
        raise ValueError("executor.gpus needs worker processes (executor.processes=true): a thread "
                         "cannot be pinned to its own GPU")
    n = ex.n_workers + len(gpus)
    mem = (psutil.virtual_memory().total / 1e9 / n) if ex.memory_limit == "auto" else memory_gb(ex.memory_limit)
    workers = {}
    for i in range(ex.n_workers):
        workers[f"cpu-{i}"] = {"cls": Nanny, "options": {
            "nthreads": ex.threads_per_worker, "memory_limit": f"{mem:.3f}GB", "silence_logs": 40,
            "resources": {"CPU": ex.threads_per_worker, "MEMORY": mem},
            "env": {"CUDA_VISIBLE_DEVICES": "", "NUMBA_NUM_THREADS": os.environ["NUMBA_NUM_THREADS"]}}}
    for g in gpus:
        workers[f"gpu-{g}"] = {"cls": Nanny, "options": {
            "nthreads": 1, "memory_limit": f"{mem:.3f}GB", "silence_logs": 40,
            "resources": {"GPU": 1, "MEMORY": mem},
            "env": {"CUDA_VISIBLE_DEVICES": g, "NUMBA_NUM_THREADS": os.environ["NUMBA_NUM_THREADS"]}}}
    scheduler = {"cls": Scheduler, "options": {"dashboard_address": ":0" if ex.dashboard else None}}
    return SpecCluster(workers=workers, scheduler=scheduler, silence_logs=40), Placement(len(gpus), mem)


def dask_client(ex):
    """(client, cluster or None, Placement)."""
    import logging

    import dask
    from dask.distributed import Client, LocalCluster

    for name in list(logging.root.manager.loggerDict):
        if name.startswith(("distributed", "bokeh", "tornado")):
            logging.getLogger(name).setLevel(logging.WARNING)
    # a worker's death counts against every task it held, queued ones too: a task survives
    # executor.allowed_failures deaths (preempted or crashed workers) before its scene fails; a
    # scene that kills its worker each time (out of memory) fails after as many tries
    dask.config.set({"distributed.scheduler.allowed-failures": int(ex.allowed_failures),
                     "distributed.scheduler.worker-saturation": 1.0})
    if ex.kind == "address" or ex.address:
        if not ex.address:
            raise ValueError("executor.kind=address needs executor.address=tcp://host:port")
        return Client(ex.address), None, Placement(int(ex.gpus or 0))
    if ex.kind in ("slurm", "pbs"):
        cluster, placement = jobqueue_cluster(ex)
        cluster.scale(jobs=ex.jobqueue.jobs)
        client = Client(cluster)
        if placement.gpu_workers:
            client.register_plugin(PinGPU())
        return client, cluster, placement
    if ex.kind != "local":
        raise ValueError(f"executor.kind must be local, address, slurm, pbs or sync, not {ex.kind!r}")
    gpus = visible_gpus() if ex.gpus is None else [str(i) for i in range(int(ex.gpus))]
    # numba threads per worker: share the cores instead of oversubscribing them
    os.environ.setdefault("NUMBA_NUM_THREADS", str(max(1, (os.cpu_count() or 1) // max(ex.n_workers, 1))))
    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_ in its workers, which also freezes glibc's mmap
    # threshold at 128 KiB: every large temporary becomes a fresh mmap and page faults (a
    # semantics scene took 6x longer in a worker than in a process with the torch renderer)
    env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    env.pop("MALLOC_TRIM_THRESHOLD_", None)
    dask.config.set({"distributed.nanny.pre-spawn-environ": env})
    if gpus:
        cluster, placement = local_cluster(ex, gpus)
        return Client(cluster), cluster, placement
    cluster = LocalCluster(n_workers=ex.n_workers, threads_per_worker=ex.threads_per_worker,
                           processes=ex.processes, memory_limit=ex.memory_limit,
                           dashboard_address=":0" if ex.dashboard else None, silence_logs=40)
    return Client(cluster), cluster, Placement()


RUNS: dict[str, tuple] = {}
"""(cfg, catalog) of the runs this worker process serves, by run id (set by RunContext)."""


class RunContext(WorkerPlugin):
    """Worker plugin carrying one run's config and catalog to every worker, once, including the
    workers that start later or restart after a crash (the scheduler hands registered plugins to
    each new worker). Tasks name the run by id: neither O(scenes^2) pickled copies in the client
    (by value, 20,000 tasks took it to 13 GB) nor data that a dying worker can take with it (a
    scattered copy is lost once every worker that held it has died: the kill_worker fault
    scenario cancelled every pending task that way)."""

    def __init__(self, run_id: str, cfg, catalog):
        self.run_id, self.cfg, self.catalog = run_id, cfg, catalog
        self.name = f"navarena-run-{run_id}"

    def setup(self, worker):
        RUNS[self.run_id] = (self.cfg, self.catalog)

    def teardown(self, worker):
        RUNS.pop(self.run_id, None)


def run_placed(stage_name: str, scene, run_id: str, *args) -> dict:
    """run_task of the run `run_id`, its result saying where and when it ran (worker name, start and
    end times: the scale benchmark measures the scheduler's gaps from them, the summary the overlap
    of CPU and GPU stages; on a GPU worker the GPU it is pinned to and the one its CUDA work used,
    see gpu_identity)."""
    from dask.distributed import get_worker

    t0 = time.time()
    cfg, catalog = RUNS[run_id]
    r = run_task(stage_name, scene, cfg, catalog, *args, run=run_identity(run_id))
    r["worker"], r["started"], r["finished"] = str(get_worker().name), round(t0, 3), round(time.time(), 3)
    return {**r, **gpu_identity()}


def run_identity(run_id: str) -> dict:
    """The run's identity (pipeline.tasks.new_run) from its id, "{pid}-{start ns}"."""
    return {"id": run_id, "started_ns": int(run_id.rsplit("-", 1)[1])}


SCHEDULER_LOST = ("the Dask scheduler was lost before this task finished (killed, or unreachable past the "
                  "connection timeout): not run here; nothing it may have half-written is trusted (no marker); "
                  "rerun against a running scheduler")


def run_on_dask(cfg, catalog: Catalog, chain, record, console: Console, run: dict | None = None) -> None:
    """Submit the run's tasks; the cluster starts at the first task that has work to do (a run
    whose every task is current starts none)."""
    from dask.distributed import Future, as_completed

    dask: dict = {}
    run_id = (run or new_run())["id"]
    interrupted = False

    def submit(st, scene, h, force, ups):
        # a task whose inputs are settled and whose marker is current is answered here: a finished
        # run resumes without sending its tasks through the scheduler
        if not any(isinstance(u, Future) or u["status"] in FAILED for u in ups):
            done = current(st.name, scene, catalog, h, force, cfg.get("verify", "size"))
            if done is not None:
                record(done)
                return done
        if not dask:
            dask["client"], dask["cluster"], dask["placement"] = dask_client(cfg.executor)
            if cfg.executor.get("dashboard", True) and dask["client"].dashboard_link:  # off: dask still names a link
                console.print(f"Dask dashboard: {dask['client'].dashboard_link}")
            # the config and the catalog go to every worker once, restarted ones included
            dask["client"].register_plugin(RunContext(run_id, cfg, catalog))
        return dask["client"].submit(run_placed, st.name, scene, run_id, h, force, *ups,
                                     key=f"{st.name}-{scene.scene_id}-{h}-{run_id}", pure=False,
                                     resources=dask["placement"].resources(st))
    try:
        handles = [x for x in chain(submit) if isinstance(x[2], Future)]
        what = {fut.key: (name, scene) for name, scene, fut in handles}
        for fut in as_completed([fut for _, _, fut in handles]) if handles else ():
            try:
                r = fut.result()
            except Exception as e:  # noqa: BLE001 - a killed worker, a lost dependency
                name, sc = what[fut.key]
                error = f"{type(e).__name__}: {e}"
                if "scheduler-connection-lost" in str(e) or dask["client"].status in ("closing", "closed"):
                    error = SCHEDULER_LOST
                elif type(e).__name__ == "KilledWorker":
                    error = (f"the worker running it died every time it was tried (out of memory? "
                             f"executor.memory_limit={cfg.executor.memory_limit}; or killed from outside): {e}")
                r = {"stage": name, "scene_id": sc.scene_id, "scene": sc.name, "status": "failed", "error": error}
            record(r)
    except KeyboardInterrupt:
        interrupted = True
        raise
    finally:
        if dask and interrupted:
            # Ctrl-C (or SIGINT to this process alone, whose workers go on computing): stop the
            # workers without waiting for their tasks, whose outputs are written whole or not at all
            with contextlib.suppress(Exception):
                dask["client"].close(timeout=5)
            if dask["cluster"] is not None:
                with contextlib.suppress(Exception):
                    dask["cluster"].close(timeout=10)
        elif dask:
            dask["client"].close()
            if dask["cluster"] is not None:
                dask["cluster"].close()
