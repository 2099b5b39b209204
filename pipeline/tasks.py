"""One task: a (stage, scene) run unless current, its marker written last. A task never raises:
failures come back as results, so one bad scene cannot stop the run, and its downstream stages
are skipped with the reason."""
from __future__ import annotations

import errno
import os
import time
import traceback

from navcore.io.catalog import Catalog, SceneEntry
from pipeline.graph import BY_NAME, stage_config, stage_storage
from pipeline.locks import locked
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
            manifest_problem(m.get("manifest"), catalog.root, verify) is None:
        return {**base, "status": "cached", **notes(m.get("info", {}))}
    return None


def run_task(stage_name: str, scene: SceneEntry, cfg, catalog: Catalog, config_hash: str, force: bool,
             *upstream: dict) -> dict:
    """Run one (stage, scene) unless it is current; never raises."""
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
            return _run_locked(stage, stage_name, scene, cfg, catalog, config_hash, force, verify, base)
    except OSError as e:  # the lock could not be taken (a full disk, a read-only data root)
        return {**base, "status": "failed", "error": describe(e, catalog)}


def _run_locked(stage, stage_name, scene, cfg, catalog, config_hash, force, verify, base) -> dict:
    marker = catalog.path("markers", scene, stage=stage_name)
    old = None if force else read_marker(marker)
    damaged = manifest_problem(old.get("manifest"), catalog.root, verify) \
        if old is not None and old.get("config_hash") == config_hash else None
    marker.unlink(missing_ok=True)  # outputs are about to change: the old marker must not vouch for them
    if stage.finalize:  # nor may the dataset-level files built from them (a later run rebuilds them)
        catalog.path("finalize_marker", stage=stage_name).unlink(missing_ok=True)
    t0 = time.perf_counter()
    try:
        info = stage.run(scene, cfg, catalog) or {}
    except Exception as e:  # noqa: BLE001 - recorded, the run goes on
        return {**base, "status": "failed", "error": describe(e, catalog),
                "traceback": traceback.format_exc(limit=6), "duration_s": round(time.perf_counter() - t0, 3)}
    duration = round(time.perf_counter() - t0, 3)
    try:
        manifest = output_manifest(info.get("outputs", []), catalog.root)
        write_marker(marker, {"stage": stage_name, "scene_id": scene.scene_id, "config_hash": config_hash,
                              "config": stage_config(cfg, stage_name), "storage": stage_storage(cfg, stage_name),
                              "duration_s": duration, "info": info,
                              "manifest": manifest})
    except OSError as e:  # an output gone after the stage, or no room for the marker: not done
        marker.unlink(missing_ok=True)
        return {**base, "status": "failed", "error": f"after the stage: {describe(e, catalog)}",
                "duration_s": duration}
    extra = {"recomputed": f"outputs damaged since the last run: {damaged}"} if damaged else {}
    return {**base, "status": "done", "duration_s": duration, **extra, **notes(info)}


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
