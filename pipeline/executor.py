"""Run the stage graph over scenes as Dask tasks, one task per (stage, scene).

Dependencies are per scene only: scene B's costmap never waits for scene A's voxels. A task
never raises: failures come back as results, so one bad scene cannot stop the run, and its
downstream stages are skipped with the reason.
"""
from __future__ import annotations

import datetime as dt
import json
import os
import time
import traceback
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from pipeline.atomic import write_text_atomic
from pipeline.catalog import Catalog, SceneEntry
from pipeline.graph import BY_NAME, _load, closure, config_hashes
from pipeline.markers import is_done, write_marker

PROJECT_ROOT = Path(__file__).resolve().parent.parent
FAILED = ("failed", "skipped")


def run_task(stage_name: str, scene: SceneEntry, cfg, catalog: Catalog, config_hash: str, force: bool,
             *upstream: dict) -> dict:
    """Run one (stage, scene) unless it is current; never raises."""
    base = {"stage": stage_name, "scene_id": scene.scene_id, "scene": scene.name}
    for up in upstream:
        if up["status"] in FAILED:
            return {**base, "status": "skipped", "error": f"upstream {up['stage']} {up['status']}"}
    stage = BY_NAME[stage_name]
    if stage.only_synthetic and not scene.synthetic:
        return {**base, "status": "n/a"}
    marker = catalog.path("markers", scene, stage=stage_name)
    if not force and is_done(marker, config_hash):
        return {**base, "status": "cached", **notes(json.loads(marker.read_text()).get("info", {}))}
    marker.unlink(missing_ok=True)  # outputs are about to change: the old marker must not vouch for them
    t0 = time.perf_counter()
    try:
        info = stage.function()(scene, cfg, catalog) or {}
    except Exception as e:  # noqa: BLE001 - recorded, the run goes on
        return {**base, "status": "failed", "error": f"{type(e).__name__}: {e}",
                "traceback": traceback.format_exc(limit=6), "duration_s": round(time.perf_counter() - t0, 3)}
    duration = round(time.perf_counter() - t0, 3)
    write_marker(marker, {"stage": stage_name, "scene_id": scene.scene_id, "config_hash": config_hash,
                          "duration_s": duration, "info": info})
    return {**base, "status": "done", "duration_s": duration, **notes(info)}


def notes(info: dict) -> dict:
    """What a stage's result says the run summary must show: shortfalls (outputs it could not
    yield) and warnings (e.g. a scene whose scale is implausible for metres)."""
    return {k: info[k] for k in ("shortfall", "warnings") if info.get(k)}


def jobqueue_cluster(ex):
    """A dask-jobqueue SLURMCluster / PBSCluster from executor.jobqueue (no jobs started yet)."""
    import dask_jobqueue

    jq = ex.jobqueue
    cls = {"slurm": dask_jobqueue.SLURMCluster, "pbs": dask_jobqueue.PBSCluster}[ex.kind]
    return cls(cores=jq.cores, memory=jq.memory, processes=jq.processes, walltime=jq.walltime, queue=jq.queue,
               account=jq.account, job_extra_directives=list(jq.job_extra_directives),
               log_directory=jq.log_directory, job_name="navarena-worker")


def _client(ex):
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


def _run_on_dask(cfg, catalog: Catalog, chain, record, console: Console) -> None:
    from dask.distributed import as_completed

    client, cluster = _client(cfg.executor)
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


def open_catalog(cfg) -> tuple[Catalog, list[SceneEntry], Path]:
    """The run's catalog (paths relative to the working directory or the project), its selected
    scenes and the catalog file."""
    root = Path(cfg.data_root)
    if not root.is_absolute():
        root = Path.cwd() / root
    cat_file = Path(cfg.scenes.catalog)
    if not cat_file.is_absolute():
        cat_file = (Path.cwd() / cat_file) if (Path.cwd() / cat_file).exists() else PROJECT_ROOT / cat_file
    catalog = Catalog(cat_file, root, cfg.scenes.count, cfg.scenes.num_gaussians)
    return catalog, catalog.select(cfg.scenes.shard, cfg.scenes.num_shards, cfg.scenes.ids, cfg.scenes.limit), cat_file


def execute(cfg, console: Console | None = None) -> dict:
    """Run the configured stages over the configured scenes; returns (and writes) the run summary."""
    console = console or Console()
    catalog, scenes, cat_file = open_catalog(cfg)
    root = catalog.root
    stages = closure(list(cfg.stages))
    hashes = config_hashes(cfg)
    selected = set(cfg.stages)
    started = dt.datetime.now(dt.timezone.utc)
    console.print(f"[bold]navarena[/]: {len(scenes)} scene(s) from {cat_file.name} "
                  f"(shard {cfg.scenes.shard}/{cfg.scenes.num_shards}), stages {[s.name for s in stages]}, "
                  f"data in {root}")
    results: list[dict] = []
    progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                        console=console, transient=False)

    def chain(submit):
        """Submit every (stage, scene), each after its own scene's upstream stages only."""
        handles = []
        for scene in scenes:
            prev = {}
            for st in stages:
                prev[st.name] = submit(st, scene, hashes[st.name], cfg.force and st.name in selected,
                                       [prev[n] for n in st.needs if n in prev])
                handles.append((st.name, scene, prev[st.name]))
        return handles

    def record(r: dict) -> None:
        results.append(r)
        if r["status"] == "failed":
            progress.console.print(f"[red]failed[/] {r['stage']} {r['scene_id']} ({r['scene']}): {r['error']}")
        progress.advance(bar)

    with progress:
        bar = progress.add_task("tasks", total=len(scenes) * len(stages))
        if cfg.executor.kind == "sync" and not cfg.executor.address:
            def run_now(st, scene, h, force, ups):
                r = run_task(st.name, scene, cfg, catalog, h, force, *ups)
                record(r)
                return r
            chain(run_now)
        else:
            _run_on_dask(cfg, catalog, chain, record, console)
    order = {s.name: i for i, s in enumerate(stages)}
    results.sort(key=lambda r: (r["scene_id"], order[r["stage"]]))
    results += _finalize(stages, results, cfg, catalog)
    summary = {"started_at": started.isoformat(timespec="seconds"),
               "finished_at": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
               "catalog": str(cat_file), "shard": [cfg.scenes.shard, cfg.scenes.num_shards],
               "stages": [s.name for s in stages], "config_hashes": {s.name: hashes[s.name] for s in stages},
               "counts": {}, "failures": [r for r in results if r["status"] in FAILED],
               "shortfalls": [r for r in results if r.get("shortfall")],
               "warnings": [r for r in results if r.get("warnings")], "results": results}
    for r in results:
        c = summary["counts"].setdefault(r["stage"], {})
        c[r["status"]] = c.get(r["status"], 0) + 1
    runs = catalog.path("runs")
    stamp = started.strftime("%Y%m%dT%H%M%S")
    text = json.dumps(summary, indent=1, default=str)
    write_text_atomic(runs / f"run-{stamp}-shard{cfg.scenes.shard}.json", text)
    write_text_atomic(runs / "latest.json", text)
    _print_summary(summary, console)
    console.print(f"run summary: {runs / 'latest.json'}")
    return summary


def _finalize(stages, results: list[dict], cfg, catalog: Catalog) -> list[dict]:
    """Dataset-level steps of the stages that have one and computed at least one scene in this run
    (a fully cached stage leaves its dataset-level files as they are)."""
    out = []
    for st in stages:
        if not st.finalize or not any(r["stage"] == st.name and r["status"] == "done" for r in results):
            continue
        base = {"stage": f"{st.name}:finalize", "scene_id": "*", "scene": "dataset"}
        t0 = time.perf_counter()
        try:
            info = _load(st.finalize)(cfg, catalog) or {}
            out.append({**base, "status": "done", "duration_s": round(time.perf_counter() - t0, 3),
                        "outputs": info.get("outputs", [])})
        except Exception as e:  # noqa: BLE001 - recorded like a scene failure
            out.append({**base, "status": "failed", "error": f"{type(e).__name__}: {e}",
                        "traceback": traceback.format_exc(limit=6)})
    return out


def _print_summary(summary: dict, console: Console) -> None:
    t = Table(title="run summary")
    statuses = ["done", "cached", "n/a", "failed", "skipped"]
    t.add_column("stage")
    for s in statuses:
        t.add_column(s, justify="right")
    for stage, c in summary["counts"].items():
        t.add_row(stage, *[str(c.get(s, 0)) for s in statuses])
    console.print(t)
    if summary["failures"]:
        f = Table(title="failures", show_lines=False)
        for col in ("scene", "stage", "status", "error"):
            f.add_column(col, overflow="fold")
        for r in summary["failures"]:
            f.add_row(f"{r['scene_id']} ({r['scene']})", r["stage"], r["status"], r.get("error", ""))
        console.print(f)
    if summary["shortfalls"]:
        f = Table(title="scenes that could not yield the requested outputs")
        for col in ("scene", "stage", "what", "got / asked", "rejections by reason"):
            f.add_column(col, overflow="fold")
        for r in summary["shortfalls"]:
            for s in r["shortfall"]:
                f.add_row(f"{r['scene_id']} ({r['scene']})", r["stage"], s.get("task", ""),
                          f"{s.get('episodes')} / {s.get('requested')}",
                          ", ".join(f"{k} {v}" for k, v in s.get("rejections", {}).items()) or s.get("reason", ""))
        console.print(f)
    if summary["warnings"]:
        f = Table(title="warnings")
        for col in ("scene", "stage", "warning"):
            f.add_column(col, overflow="fold")
        for r in summary["warnings"]:
            for w in r["warnings"]:
                f.add_row(f"{r['scene_id']} ({r['scene']})", r["stage"], w)
        console.print(f)


def main_cfg(cfg) -> int:
    summary = execute(cfg)
    return 1 if (cfg.strict and summary["failures"]) else 0


