"""Run the stage graph over scenes as Dask tasks, one task per (stage, scene).

Dependencies are per scene only: scene B's costmap never waits for scene A's voxels. Jobs: the task
(pipeline.tasks), where tasks run (pipeline.backends), the run summary (pipeline.summary); this
module ties them together.
"""
from __future__ import annotations

import contextlib
import datetime as dt
from pathlib import Path

from omegaconf import OmegaConf
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from navcore.io.atomic import sweep_stale_temporaries
from navcore.io.catalog import open_catalog
from pipeline import sources
from pipeline.backends import run_on_dask
from pipeline.config import unknown_keys, unknown_keys_message
from pipeline.config_guard import config_changes, describe, refusal
from pipeline.episode_progress import EpisodeWatcher, rate_column
from pipeline.graph import closure, config_hashes, selection
from pipeline.summary import build_summary, print_summary, write_summary
from pipeline.tasks import finalize_due, new_run, run_finalize, run_task

PROJECT_ROOT = Path(__file__).resolve().parent.parent


def execute(cfg, console: Console | None = None) -> dict:
    """Run the configured stages over the configured scenes; returns (and writes) the run summary."""
    console = console or Console()
    unknown = unknown_keys(cfg)
    if unknown:  # a misspelt key added with `+` would otherwise be accepted and ignored
        raise UnknownKeysError(unknown_keys_message(unknown))
    catalog, scenes, cat_file = open_catalog(cfg, PROJECT_ROOT)
    missing = [sc for sc in scenes if not sc.synthetic and sc.path and not Path(sc.path).exists()]
    for sc in missing:  # before any worker starts: each named, the other scenes still run
        console.print(f"[red]missing source[/]: scene {escape(sc.name)} ({sc.scene_id}): {escape(sc.path)} does not "
                      f"exist (catalog {escape(str(cat_file))}); its stages are skipped")
    scenes = [sc for sc in scenes if sc not in missing]
    stages = closure(list(cfg.stages))
    results: list[dict] = [missing_source_result(st, sc, catalog) for sc in missing for st in stages]
    hashes = config_hashes(cfg)
    selected = set(selection(list(cfg.stages)))
    started = dt.datetime.now(dt.timezone.utc)
    shard = [cfg.scenes.shard, cfg.scenes.num_shards]
    console.print(f"[bold]navarena[/]: {len(scenes)} scene(s) from {cat_file.name} "
                  f"(shard {cfg.scenes.shard}/{cfg.scenes.num_shards}), stages {[s.name for s in stages]}, "
                  f"data in {catalog.root}")
    changes = config_changes(cfg, catalog, scenes, stages, hashes)
    blocked = [] if cfg.force else [s for s, c in changes.items() if s not in selected and not c["storage_only"]]
    if blocked:  # outputs of stages the run does not name would be overwritten: refuse, touch nothing
        msg = refusal(changes, blocked, command_overrides())
        console.print(f"[red]refused[/]: {escape(msg)}")
        summary = build_summary([], started, cat_file, shard, stages, hashes)
        summary["refused"] = msg
        summary["config_changes"] = _changes_record(changes)
        summary["failures"].append({"stage": "run", "scene_id": "*", "scene": "dataset", "status": "failed",
                                    "error": "refused: " + msg.splitlines()[0]})
        return summary
    if changes:
        console.print("[yellow]recomputing because the settings changed[/] (old -> new):")
        for line in describe(changes):
            console.print(f"  {escape(line)}")
    interrupted = run_graph(cfg, catalog, scenes, stages, hashes, selected, results, started, console)
    order = {s.name: i for i, s in enumerate(stages)}
    results.sort(key=lambda r: (r["scene_id"], order[r["stage"]]))
    if any(r["status"] in ("done", "failed") for r in results) and catalog.root.exists():
        # partial outputs of killed runs whose final name this run did not write again
        for p in sweep_stale_temporaries(catalog.root):
            console.print(f"removed a killed writer's partial output: {p}")
    # dataset-level steps of the stages that have one and computed at least one scene in this run
    # (a fully cached stage leaves its dataset-level files as they are)
    if not interrupted:
        results += [run_finalize(st, cfg, catalog) for st in stages if finalize_due(st, results, catalog)]
    summary = build_summary(results, started, cat_file, shard, stages, hashes)
    summary["interrupted"] = interrupted
    if changes:
        summary["config_changes"] = _changes_record(changes)
    summary["allow_failures"] = bool(cfg.get("allow_failures", False))
    names = {sc.name for sc in scenes}
    summary["paths_outside_catalog"] = [o for o in catalog.outside if o["scene"] in names]
    summary["data_root"] = _shown(catalog.root)
    print_summary(summary, console)
    try:
        latest = write_summary(summary, catalog, started, cfg.scenes.shard)
        console.print(f"run summary: {latest}")
    except OSError as e:  # e.g. a full disk: the table above is all there is
        summary["failures"].append({"stage": "run summary", "scene_id": "*", "scene": "dataset", "status": "failed",
                                    "error": f"the run summary could not be written: {e}"})
        console.print(f"[red]the run summary could not be written[/]: {e}")
    return summary


def _shown(path: Path) -> str:
    """A path as the user would type it: relative to the current folder when under it."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _changes_record(changes: dict) -> dict:
    """The config changes as the run summary records them (key tuples as lists)."""
    return {k: v | {"keys": [list(x) for x in v["keys"]]} for k, v in changes.items()}


def run_graph(cfg, catalog, scenes, stages, hashes: dict, selected: set, results: list, started, console) -> bool:
    """Every (stage, scene) task, each after its own scene's upstream stages only, here (executor
    sync) or on Dask, with the progress display; each result appended to `results` as it finishes.
    Returns whether Ctrl-C interrupted the run (what finished is kept)."""
    progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                        rate_column(), console=console, transient=False)
    total = len(scenes) * len(stages)

    def chain(submit):
        """Submit every (stage, scene), each after its own scene's upstream stages only."""
        handles = []
        for scene in scenes:
            prev = {}
            for st in stages:
                prev[st.name] = submit(st, scene, hashes.of(st.name, scene), cfg.force and st.name in selected,
                                       [prev[n] for n in st.needs if n in prev])
                handles.append((st.name, scene, prev[st.name]))
        return handles

    def record(r: dict) -> None:
        results.append(r)
        if r["status"] == "failed":
            progress.console.print(f"[red]failed[/] {r['stage']} {r['scene_id']} ({r['scene']}): {r['error']}")
        elif not progress.console.is_terminal and r["status"] not in ("n/a", "cached"):
            # a log without a terminal gets no bar redrawn: a line per (stage, scene) task run instead
            took = f", {r['duration_s']:.0f} s" if isinstance(r.get("duration_s"), (int, float)) else ""
            progress.console.print(f"[{len(results)}/{total}] {r['status']} {r['stage']} "
                                   f"{r['scene_id']} ({r['scene']}){took}")
        progress.advance(bar)

    try:
        with progress, contextlib.ExitStack() as watch, sources.one_listing_a_run():  # a source listed once a run
            for w in progress_watchers(cfg, catalog, stages, progress, started):
                watch.enter_context(w)
            bar = progress.add_task("tasks", total=total)
            run = new_run()
            if not scenes:
                pass  # nothing to run (every source missing): no workers started
            elif cfg.executor.kind == "sync" and not cfg.executor.address:
                def run_now(st, scene, h, force, ups):
                    r = run_task(st.name, scene, cfg, catalog, h, force, *ups, run=run)
                    record(r)
                    return r
                chain(run_now)
            else:
                run_on_dask(cfg, catalog, chain, record, console, run)
    except KeyboardInterrupt:  # Ctrl-C: keep what finished (every output is written whole), summarise it
        console.print(f"[yellow]interrupted[/]: {len(results)} of {total} (stage, scene) tasks "
                      "finished and are kept; run the same command again to go on")
        return True
    return False


def progress_watchers(cfg, catalog, stages, progress, started) -> list:
    """Bars of the long tasks' own items beside the tasks' bar: evaluate's episodes (one task a
    scene for hours) and semantics' views (minutes a scene with a detector on a CPU)."""
    watchers = []
    if any(st.name == "evaluate" for st in stages):
        from stages.evaluate.stage import run_name

        run = run_name(OmegaConf.to_object(cfg.evaluate))
        watchers.append(EpisodeWatcher(progress, catalog.path("eval_progress", run=run, scene_id="x").parent,
                                       started.timestamp()))
    if any(st.name == "semantics" for st in stages):
        watchers.append(EpisodeWatcher(progress, catalog.path("semantics_progress", scene_id="x").parent,
                                       started.timestamp(), log_each=False, name="semantics views",
                                       count="views", rate="views", unit="views"))
    return watchers


def missing_source_result(stage, scene, catalog) -> dict:
    """What the run records for a stage of a scene whose source file is missing (checked before
    any worker starts): ingest failed naming the file, as the stage itself reports it
    (pipeline.tasks.describe), the stages after it skipped."""
    from navcore.gaussians.errors import SceneFileNotFoundError
    from pipeline.tasks import describe as describe_error

    base = {"stage": stage.name, "scene_id": scene.scene_id, "scene": scene.name}
    if stage.only_synthetic:
        return {**base, "status": "n/a"}
    if stage.name == "ingest":
        return {**base, "status": "failed",
                "error": describe_error(SceneFileNotFoundError(scene.path, scene.scene_id), catalog)}
    return {**base, "status": "skipped", "error": "upstream ingest failed"}


def command_overrides() -> list[str] | None:
    """This run's command-line overrides (None outside a Hydra app, e.g. a composed config)."""
    try:
        from hydra.core.hydra_config import HydraConfig

        return list(HydraConfig.get().overrides.task)
    except (ImportError, ValueError):
        return None


class UnknownKeysError(ValueError):
    """The composed config holds keys the schema does not know."""


def main_cfg(cfg) -> int:
    """The exit status of a run: 1 when a (stage, scene) failed or the run was refused, unless
    allow_failures=true; 2 for a config with unknown keys (nothing runs); 130 when Ctrl-C stopped it
    (what finished is kept and summarised)."""
    try:
        summary = execute(cfg)
    except UnknownKeysError as e:
        Console(stderr=True).print(f"[red]navarena[/]: {escape(str(e))}")
        return 2
    if summary.get("interrupted"):
        return 130
    return 1 if (summary["failures"] and not cfg.allow_failures) else 0
