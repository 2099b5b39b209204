"""One task: a (stage, scene) run unless current, its marker written last. A task never raises:
failures come back as results, so one bad scene cannot stop the run, and its downstream stages
are skipped with the reason."""
from __future__ import annotations

import errno
import os
import time
import traceback

from navcore.io.catalog import Catalog, SceneEntry
from pipeline import sources
from pipeline.graph import BY_NAME, stage_config, stage_storage
from pipeline.locks import locked, try_locked
from pipeline.markers import manifest_problem, output_manifest, read_marker, write_marker

FAILED = ("failed", "skipped")


def current(stage_name: str, scene: SceneEntry, catalog: Catalog, config_hash: str, force: bool,
            verify: str = "size") -> dict | None:
    """The result of a (stage, scene) that needs no work (n/a, or its marker current and its
    outputs as its manifest records them), else None. Cheap (a small file read and a stat per
    output file): the executor asks it before submitting, so that a finished run resumes in
    seconds without sending thousands of no-op tasks through the scheduler."""
    base = {"stage": stage_name, "scene_id": scene.scene_id, "scene": scene.name}
    if BY_NAME[stage_name].only_synthetic and not scene.synthetic:
        return {**base, "status": "n/a"}
    marker = catalog.path("markers", scene, stage=stage_name)
    m = None if force else read_marker(marker)
    if m is not None and m.get("config_hash") == config_hash and \
            manifest_problem(m.get("manifest"), catalog.root, verify) is None and \
            sources.problem(m.get("sources"), sources.files(stage_name, scene), verify) is None:
        if m.get("sources") and (fresh := sources.restat(m["sources"])):
            _refresh_sources(marker, catalog.path("locks", stage=stage_name, key=scene.scene_id), m, fresh)
        return {**base, "status": "cached", **notes(m.get("info", {}))}
    return None


def _refresh_sources(marker, lock, m: dict, fresh: dict) -> None:
    """Record a touched source's new mtime in a current marker (same sha256), when no task of that
    (stage, scene) holds its lock and the marker is still the one read; best effort."""
    try:
        with try_locked(lock) as mine:
            if mine and read_marker(marker) == m:
                write_marker(marker, {**m, "sources": fresh})
    except OSError:
        pass


def new_run() -> dict:
    """A run's identity in its markers: id (pid and start time) and start time in ns. A task of an
    older run never overwrites what a newer run wrote (`_run_locked`): the write fence that keeps
    the orphaned tasks of a killed client, still running on an external cluster's workers, from
    replacing a rerun's newer result."""
    t = time.time_ns()
    return {"id": f"{os.getpid()}-{t}", "started_ns": t}


def run_task(stage_name: str, scene: SceneEntry, cfg, catalog: Catalog, config_hash: str, force: bool,
             *upstream: dict, run: dict | None = None) -> dict:
    """Run one (stage, scene) unless it is current; never raises. run: the run's identity
    (`new_run`), recorded in the marker and checked against a newer run's marker."""
    base = {"stage": stage_name, "scene_id": scene.scene_id, "scene": scene.name}
    for up in upstream:
        if up["status"] in FAILED:
            return {**base, "status": "skipped", "error": f"upstream {up['stage']} {up['status']}"}
    stage = BY_NAME[stage_name]
    verify = cfg.get("verify", "size")
    done = current(stage_name, scene, catalog, config_hash, force, verify)
    if done is not None:
        return done
    try:
        with locked(catalog.path("locks", stage=stage_name, key=scene.scene_id)) as waited:
            # another run may have finished this (stage, scene) while we waited for its lock
            done = current(stage_name, scene, catalog, config_hash, force, verify)
            if done is not None:
                return {**done, "waited_s": round(waited, 3)}
            return _run_locked(stage, stage_name, scene, cfg, catalog, config_hash, force, verify, base, run)
    except OSError as e:  # the lock could not be taken (a full disk, a read-only data root)
        return {**base, "status": "failed", "error": describe(e, catalog)}


def _run_locked(stage, stage_name, scene, cfg, catalog, config_hash, force, verify, base, run) -> dict:
    marker = catalog.path("markers", scene, stage=stage_name)
    found = read_marker(marker)
    by = (found or {}).get("run") or {}
    if run and by.get("started_ns", 0) > run["started_ns"]:  # the write fence (new_run)
        return {**base, "status": "skipped", "superseded_by": by.get("id"),
                "error": f"superseded: a newer run ({by.get('id')}) wrote this (stage, scene) while this one's task "
                         "waited; an older run never overwrites a newer one's outputs"}
    old = None if force else found
    extra = {}
    if old is not None and old.get("config_hash") == config_hash:  # why a marker of this config is redone
        changed = sources.problem(old.get("sources"), sources.files(stage_name, scene), verify)
        damaged = manifest_problem(old.get("manifest"), catalog.root, verify)
        if changed:
            extra = {"recomputed": f"source changed: {changed['message']}", "source_changed": changed}
        elif damaged:
            extra = {"recomputed": f"outputs damaged since the last run: {damaged}"}
    marker.unlink(missing_ok=True)  # outputs are about to change: the old marker must not vouch for them
    if stage.finalize:  # nor may the dataset-level files built from them (a later run rebuilds them)
        catalog.path("finalize_marker", stage=stage_name).unlink(missing_ok=True)
    t0 = time.perf_counter()
    try:
        # the outside files as they are when the stage reads them (known: the upstream markers' records)
        ups = [read_marker(catalog.path("markers", scene, stage=n)) or {} for n in stage.needs]
        used = sources.record(sources.files(stage_name, scene), verify,
                              {k: v for m in ups for k, v in (m.get("sources") or {}).items()})
    except OSError as e:
        return {**base, "status": "failed", "error": f"{describe(e, catalog)}{_since(extra)}", **extra}
    try:
        info = stage.run(scene, cfg, catalog) or {}
    except Exception as e:  # noqa: BLE001 - recorded, the run goes on
        return {**base, "status": "failed", "error": f"{describe(e, catalog)}{_since(extra)}",
                "traceback": traceback.format_exc(limit=6), "duration_s": round(time.perf_counter() - t0, 3), **extra}
    duration = round(time.perf_counter() - t0, 3)
    moved = sources.problem(used, list(used), verify)
    if moved:  # the outputs may mix the old and the new bytes: not done
        return {**base, "status": "failed", "duration_s": duration,
                "error": f"a source changed while the stage read it ({moved['message']}); rerun once it is settled"}
    try:
        manifest = output_manifest(info.get("outputs", []), catalog.root)
        write_marker(marker, {"stage": stage_name, "scene_id": scene.scene_id, "config_hash": config_hash,
                              "config": stage_config(cfg, stage_name), "storage": stage_storage(cfg, stage_name),
                              "duration_s": duration, "info": info, "sources": used, "run": run,
                              "manifest": manifest,
                              # keyed by the captured scenes' chain (pipeline.graph.StageHashes): the config
                              # guard tells a root made before that keying from one made with other settings
                              **({} if scene.synthetic else {"keyed": "captured"})})
    except OSError as e:  # an output gone after the stage, or no room for the marker: not done
        marker.unlink(missing_ok=True)
        return {**base, "status": "failed", "error": f"after the stage: {describe(e, catalog)}",
                "duration_s": duration}
    return {**base, "status": "done", "duration_s": duration, **extra, **notes(info)}


def _since(extra: dict) -> str:
    """What a failure's message adds when the task ran because a source changed."""
    return f" (recomputed because {extra['source_changed']['message']})" if "source_changed" in extra else ""


def describe(e: BaseException, catalog: Catalog) -> str:
    """A task's error for the run summary; a full disk says where and what to do."""
    cause, seen = e, set()
    while cause is not None and id(cause) not in seen:  # a library may wrap the OSError
        seen.add(id(cause))
        if isinstance(cause, OSError) and cause.errno in (errno.ENOSPC, errno.EDQUOT):
            return (f"disk full ({os.strerror(cause.errno)}) writing {cause.filename or 'an output'}: nothing of "
                    f"this (stage, scene) is trusted; free space under {catalog.root} and rerun")
        cause = cause.__cause__ or cause.__context__
    return f"{type(e).__name__}: {e}"


def notes(info: dict) -> dict:
    """What a stage's result says the run summary must show: shortfalls (outputs it could not
    yield), warnings (e.g. a scene whose scale is implausible for metres), and where a scene's
    ObjectNav goal categories came from (goal_mapping: goal category -> {dataset class: instances});
    a scene's screening (score, verdict, whether its episodes are kept: the episodes stage);
    and the work a GPU task did (steps: closed-loop environment steps; images: goal images rendered),
    for rates per GPU."""
    return {k: info[k] for k in ("shortfall", "warnings", "goal_mapping", "steps", "images", "screening") if info.get(k)}


def finalize_due(stage, results: list[dict], catalog: Catalog) -> bool:
    """Whether a stage's dataset-level step must run: it computed a scene in this run, or its
    dataset files were never finished since a scene last changed (a run killed in between: the
    scene tasks of the next run are all cached, yet the dataset files are missing or stale)."""
    if not stage.finalize or not any(r["stage"] == stage.name for r in results):
        return False
    if any(r["stage"] == stage.name and r["status"] == "done" for r in results):
        return True
    return not catalog.path("finalize_marker", stage=stage.name).exists()


def run_finalize(stage, cfg, catalog: Catalog) -> dict:
    """A stage's dataset-level step, recorded like a task."""
    base = {"stage": f"{stage.name}:finalize", "scene_id": "*", "scene": "dataset"}
    t0 = time.perf_counter()
    try:
        with locked(catalog.path("locks", stage=stage.name, key="finalize")):  # one writer of dataset files
            info = stage.finalize(cfg, catalog) or {}
            write_marker(catalog.path("finalize_marker", stage=stage.name),
                         {"stage": stage.name, "outputs": info.get("outputs", [])})
        return {**base, "status": "done", "duration_s": round(time.perf_counter() - t0, 3),
                "outputs": info.get("outputs", [])}
    except Exception as e:  # noqa: BLE001 - recorded like a scene failure
        return {**base, "status": "failed", "error": describe(e, catalog),
                "traceback": traceback.format_exc(limit=6)}
