"""Stages `episodes` and `objectnav_episodes`: per scene, the configured tasks' episodes and expert
trajectories -> hive-partitioned Parquet (05_episodes, 06_trajectories).

Two graph stages share this code so that a task waits only for what it needs: `episodes` makes the
tasks whose goals are points or views (PointNav, ImageNav) as soon as the costmap and its screening
exist; `objectnav_episodes` makes the tasks whose goals are object instances (ObjectNav) once the
semantics stage has lifted them, which can take an hour on a large capture on a CPU."""
from __future__ import annotations

import time

import numpy as np
import pyarrow as pa
from omegaconf import OmegaConf

from navcore.gaussians.content import camera_scene
from navcore.instances import load_instances
from navcore.io.episode_schema import EPISODE_SCHEMA, TRAJECTORY_SCHEMA, TRAJECTORY_WRITE
from navcore.nav.geodesic import NavGraph, eligible_cells
from navcore.nav.screening import grow, verdict
from navcore.render.view_quality import DefectViews
from navcore.seeds import stream_seed
from stages.episodes.config import EpisodesConfig, PlannerConfig, TaskConfig
from stages.episodes.generate import EpisodeGenerator, scene_split
from stages.episodes.views import NearViews


def write_table(rows_or_cols, schema: pa.Schema, dataset, **options) -> None:
    """Write one Parquet dataset (zstd, no pandas metadata: same rows, same bytes)."""
    if isinstance(rows_or_cols, list):
        table = pa.Table.from_pylist(rows_or_cols, schema=schema)
    else:
        table = pa.table({f.name: pa.array(np.concatenate(rows_or_cols[f.name]) if rows_or_cols else [], type=f.type)
                          for f in schema}, schema=schema)
    dataset.save(table, **(options or {"row_group_size": 1 << 20}))


OBJECT_GOALS = ("objectnav",)
"""Task types whose goals are object instances: made by `objectnav_episodes`, after semantics."""


def stage_tasks(cfg, objects: bool) -> list[str]:
    """The configured tasks (names) one of the two stages makes: those with object goals or the others."""
    return sorted(n for n in cfg.task if (cfg.task[n].type in OBJECT_GOALS) == objects)


def hashed_inputs(cfg) -> dict:
    """`task.*` of PointNav and ImageNav: what `episodes` reads beyond its config sections, its own
    tasks' settings (an ObjectNav change leaves PointNav and ImageNav episodes as they are)."""
    return {n: OmegaConf.to_container(cfg.task[n], resolve=True) for n in stage_tasks(cfg, False)}


def hashed_object_inputs(cfg) -> dict:
    """`task.*` of ObjectNav: what `objectnav_episodes` reads beyond its config sections."""
    return {n: OmegaConf.to_container(cfg.task[n], resolve=True) for n in stage_tasks(cfg, True)}


def remove_scene_partitions(catalog, scene, cfg, objects: bool) -> None:
    """Delete this scene's previous shards of the tasks this stage makes; `episodes` also deletes
    those of tasks no longer configured (a task dropped from the config must not leave stale episodes
    behind), never the current ObjectNav tasks' (the other stage's)."""
    keep = set() if objects else set(stage_tasks(cfg, True))
    mine = set(stage_tasks(cfg, objects))
    for name in ("episodes", "trajectories"):
        for task, ds in catalog.find(name, scene).items():
            if task in mine or (not objects and task not in keep):
                ds.delete()


def screening(scene, cfg, catalog, cm) -> tuple[dict, np.ndarray | None]:
    """The scene's screening entry for the run summary (score, shares, verdict, whether its
    episodes are kept) and the cells episodes keep out of (None with screen.avoid false)."""
    sc = cfg.screen
    layers, attrs = catalog.dataset("quality", scene).load_layers()
    flagged = layers["flagged"]
    if flagged.shape != cm.clearance.shape or not np.allclose(attrs["origin"], cm.origin) \
            or attrs["resolution"] != cm.resolution:
        raise ValueError(f"scene {scene.scene_id!r} ({scene.name}): the quality layer's grid {flagged.shape} at "
                         f"{attrs['origin']} differs from the costmap's {cm.clearance.shape} at {list(cm.origin)} "
                         "(rerun stages=[screen])")
    v = verdict(float(attrs["score"]), sc.warn_below, sc.reject_below)
    entry = {"score": attrs["score"], "verdict": v, "kept": not (sc.reject and v == "reject"),
             **{k: attrs.get(k, 0.0) for k in ("blur_share", "hole_share", "view_blur_share", "view_hole_share",
                                               "unseen_share")}}
    return entry, (grow(flagged, sc.margin_m, cm.resolution) if sc.avoid else None)


def difficulty_shares(episodes: list[dict], dc) -> dict[str, float]:
    """Share of a task's episodes in each difficulty bin, in the bins' order (the run summary reports
    them; a share more than 10 points off an even split is a shortfall, with the reason)."""
    n = max(len(episodes), 1)
    return {name: round(sum(e["difficulty"] == name for e in episodes) / n, 4) for name in dc.names}


def run(scene, cfg, catalog) -> dict:
    """PointNav and ImageNav (every task without object goals)."""
    return generate(scene, cfg, catalog, objects=False)


def run_objects(scene, cfg, catalog) -> dict:
    """ObjectNav (the tasks whose goals are the semantics stage's instances)."""
    return generate(scene, cfg, catalog, objects=True)


def generate(scene, cfg, catalog, objects: bool) -> dict:
    cpu0 = time.process_time()
    tasks = stage_tasks(cfg, objects)
    ecfg: EpisodesConfig = OmegaConf.to_object(cfg.episodes)
    pcfg: PlannerConfig = OmegaConf.to_object(cfg.planner)
    emb = OmegaConf.to_object(cfg.embodiment)
    cm = catalog.dataset("costmaps", scene).load(emb.name)
    screen, screened = screening(scene, cfg, catalog, cm)
    graph = NavGraph(cm, eligible_cells(cm, ecfg), ecfg.geodesic_neighbourhood)
    views = goal_views = cam = None
    if ecfg.view_near_m > 0 and screen["kept"] and tasks:
        cam, _ = camera_scene(catalog, scene, emb.name, view_dependent=False)
        views = NearViews(cam, cm, emb, ecfg.view_near_m)
    if cfg.screen.avoid and screen["kept"] and any(cfg.task[n].type == "imagenav" for n in tasks):
        if cam is None:
            cam, _ = camera_scene(catalog, scene, emb.name, view_dependent=False)
        q = cfg.screen.layer
        goal_views = (DefectViews(cam, emb, q.view_width, q.view_width * 3 // 4, q.blur_angle, q.blur_sigma_m, q.view_range_m),
                      cfg.screen.goal_view_blur_max)
    setup_s = time.process_time() - cpu0  # per scene, whatever the number of episodes
    remove_scene_partitions(catalog, scene, cfg, objects)
    held_out = scene_split(scene.scene_id, ecfg.scene_splits)
    if held_out:
        ecfg.splits = {held_out: 1.0}
    if screened is not None:
        screen["screened_share_of_graph"] = round(float(screened[graph.cells[:, 0], graph.cells[:, 1]].mean()), 4) \
            if len(graph.cells) else 0.0
    result = {"outputs": [], "tasks": {}, "graph_nodes": len(graph.cells), "graph_edges": graph.num_edges,
              "split": held_out, "setup_cpu_s": round(setup_s, 3), "screening": screen}
    shortfalls = []
    for name in tasks:
        tcfg: TaskConfig = OmegaConf.to_object(cfg.task[name])
        instances, why_none = None, None
        if tcfg.type == "objectnav":
            if tcfg.instance_source == "model_predicted" and not cfg.semantics.enabled:
                # the quick first look (docs/own-capture.md): no goal instances, said, and the other tasks stand
                instances, why_none = [], ("no goal instances: semantics.enabled=false (the semantics stage made none; "
                                           "enable it for ObjectNav: it also reads the labels a dataset ships)")
            else:
                instances = load_instances(scene, catalog, tcfg.instance_source).to_pylist()
        seed = stream_seed(ecfg.seed, scene.scene_id, name)
        if not screen["kept"]:  # screen.reject: the scene's verdict is reject; its shards stay empty
            for ds, schema in (("episodes", EPISODE_SCHEMA), ("trajectories", TRAJECTORY_SCHEMA)):
                out = catalog.dataset(ds, scene, task=name)
                write_table([], schema, out)
                result["outputs"].append(str(out.path))
            result["tasks"][name] = {"episodes": 0, "requested": tcfg.episodes_per_scene, "screened_out": True}
            continue
        gen = EpisodeGenerator(cm, graph, tcfg, ecfg, pcfg, emb, f"{scene.group}/{scene.scene_id}", seed, instances,
                               views, screened, goal_views)
        res = gen.generate()
        for ds, data, schema, options in (("episodes", res.episodes, EPISODE_SCHEMA, {}),
                                          ("trajectories", res.trajectories, TRAJECTORY_SCHEMA, TRAJECTORY_WRITE)):
            out = catalog.dataset(ds, scene, task=name)
            write_table(data, schema, out, **options)
            result["outputs"].append(str(out.path))
        result["tasks"][name] = {
            "episodes": len(res.episodes), "requested": res.requested,
            "trajectory_rows": int(sum(len(a) for a in res.trajectories.get("step", []))),
            "rejections": dict(sorted(res.rejections.items())), "cpu_s": round(res.cpu_s, 3),
            "wall_s": round(res.wall_s, 3), "geodesic_from_expert": res.geodesic_from_expert,
            "expert_fallbacks": res.expert_fallbacks}
        shares = difficulty_shares(res.episodes, ecfg.difficulty)
        result["tasks"][name]["difficulty"] = shares
        if len(res.episodes) < res.requested:
            shortfalls.append({"task": name, "episodes": len(res.episodes), "requested": res.requested,
                               "rejections": dict(sorted(res.rejections.items())), **({"reason": why_none} if why_none else {})})
        elif ecfg.difficulty.balance and res.episodes and max(abs(s - 1 / len(shares)) for s in shares.values()) > 0.1:
            longest = max(e["geodesic_distance"] for e in res.episodes)
            shortfalls.append({"task": name, "episodes": len(res.episodes), "requested": res.requested, "rejections": {},
                               "reason": "difficulty " + " / ".join(f"{k} {v:.0%}" for k, v in shares.items())
                               + f" against {1 / len(shares):.0%} each: the free space holds few starts that far from "
                               f"a goal (longest geodesic {longest:.1f} m; bins end at "
                               f"{', '.join(f'{u:g}' for u in ecfg.difficulty.upper[:-1])} m)"})
    if shortfalls:
        result["shortfall"] = shortfalls
    result["view_checks"] = views.checks if views else 0
    result["goal_view_renders"] = goal_views[0].views if goal_views else 0
    result["cpu_s"] = round(time.process_time() - cpu0, 3)  # the whole stage, all threads
    return result
