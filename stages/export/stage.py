"""Stage `export`: the canonical episode store -> the formats users already load.

- NavArena navigation layout (NAVARENA_FORMATS.md section 2), per scene and task:
    {exports}/navarena/{dataset}/{group}/{scene_id}/scene_meta.json
    {exports}/navarena/{dataset}/{group}/{scene_id}/{task}/meta/info.json, meta/episodes.parquet,
        data/chunk-{k:06d}/episodes.parquet, data/chunk-{k:06d}/trajectories.parquet
  and, once per dataset, {exports}/navarena/{dataset}/dataset_meta.json.
- Habitat-lab PointNav-v1 / ObjectNav-v1: {exports}/habitat/{task}_v1/{split}/content/{scene_id}.json.gz
  and the split file {split}/{split}.json.gz. Habitat is y-up: a point (x, y, z) of ours is
  (x, z, -y) there, and a heading yaw (counter-clockwise about +z from +x) is the rotation
  [0, sin(t/2), 0, cos(t/2)] about +y with t = yaw - pi/2 (Habitat agents look along -z).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from navcore.io.asset_files import aligned_model, keeps_aligned_file
from navcore.io.episode_schema import TRAJECTORY_WRITE

FORMAT_VERSION = "1.0"

# NavArena's column sets (NAVARENA_FORMATS.md section 2); rotation columns are named
# start_rotation_qx.. / goal_rotation_qx.. and rotation_qx.. (our choice, documented there as open)
NAVARENA_EPISODE_COLUMNS = [
    "episode_id", "chunk_index", "scene_path", "task_type", "split",
    "start_position_x", "start_position_y", "start_position_z",
    "start_rotation_qx", "start_rotation_qy", "start_rotation_qz", "start_rotation_qw",
    "goal_type", "goal_position_x", "goal_position_y", "goal_position_z",
    "goal_rotation_qx", "goal_rotation_qy", "goal_rotation_qz", "goal_rotation_qw",
    "geodesic_distance", "euclidean_distance", "num_steps", "total_time", "avg_speed", "max_speed",
    "goal_image_path", "goal_object_category", "goal_object_id", "instruction_text", "instruction_language",
    "goals_json",
]
NAVARENA_TRAJECTORY_COLUMNS = [
    "episode_id", "step", "timestamp", "position_x", "position_y", "position_z",
    "rotation_qx", "rotation_qy", "rotation_qz", "rotation_qw", "action", "action_id",
    "linear_velocity", "angular_velocity", "linear_velocity_x", "linear_velocity_y",
    "angular_acceleration", "linear_acceleration", "curvature", "phase",
]
NAVARENA_FLOAT64 = ("timestamp", "position_x", "position_y", "position_z", "rotation_qx", "rotation_qy",
                    "rotation_qz", "rotation_qw")
"""Trajectory columns the NavArena layout types as float64 (NAVARENA_FORMATS.md section 3; the
canonical store keeps them float32, which float64 holds exactly)."""
HABITAT_TASKS = ("pointnav", "objectnav")


@dataclass
class ExportConfig:
    """Exports of the episode store."""

    formats: list[str] = field(default_factory=lambda: ["navarena", "habitat"])
    """Which formats to write: navarena (navigation data layout), habitat (PointNav-v1 / ObjectNav-v1)."""
    dataset_name: str = "navarena"
    """Dataset name of the NavArena layout (its folder under exports/navarena)."""
    chunk_size: int = 1000
    """Episodes per chunk of the NavArena layout."""


def habitat_position(x, y, z) -> list[float]:
    """Our z-up point -> Habitat's y-up point."""
    return [float(x), float(z), float(-y)]


def habitat_rotation(yaw: float) -> list[float]:
    """Our heading -> Habitat's [x, y, z, w] agent rotation."""
    t = float(yaw) - math.pi / 2
    return [0.0, math.sin(t / 2), 0.0, math.cos(t / 2)]


def _read(catalog, dataset: str, scene, task: str) -> pa.Table | None:
    return catalog.dataset(dataset, scene, task=task).load_or_none()


def _tasks_of(catalog, scene) -> list[str]:
    return list(catalog.find("episodes", scene))


def navarena_trajectories(tr: pa.Table) -> pa.Table:
    """Canonical trajectory rows -> NavArena trajectories.parquet columns and types."""
    tr = tr.select(NAVARENA_TRAJECTORY_COLUMNS)
    for c in NAVARENA_FLOAT64:
        tr = tr.set_column(tr.schema.get_field_index(c), c, tr[c].cast(pa.float64()))
    return tr


def trajectory_write(table: pa.Table) -> dict:
    """The canonical store's trajectory encoding, for the columns an export keeps."""
    names = set(table.column_names)
    return {**TRAJECTORY_WRITE, "use_dictionary": [c for c in TRAJECTORY_WRITE["use_dictionary"] if c in names],
            "column_encoding": {c: e for c, e in TRAJECTORY_WRITE["column_encoding"].items() if c in names}}


def navarena_episodes(ep: pa.Table, chunk_size: int) -> pa.Table:
    """Canonical episodes -> NavArena episodes.parquet columns (chunk_index by row order)."""
    n = ep.num_rows
    cols = {}
    for c in NAVARENA_EPISODE_COLUMNS:
        if c == "chunk_index":
            cols[c] = pa.array((np.arange(n) // chunk_size).astype(np.int32))
        elif c == "goal_object_id":
            cols[c] = pc.cast(ep[c], pa.string())
        else:
            cols[c] = ep[c]
    return pa.table(cols)


def export_navarena(scene, catalog, ecfg: ExportConfig, created: str) -> list[str]:
    final = catalog.dataset("export_scene", scene, export_name=ecfg.dataset_name)
    with final.writing() as out:  # the whole scene folder at once: no stale tasks or chunks
        tasks = _fill_navarena_scene(out, scene, catalog, ecfg, created)
    return [str(final.path / t) for t in tasks]


def _fill_navarena_scene(out, scene, catalog, ecfg: ExportConfig, created: str) -> list[str]:
    tasks = _tasks_of(catalog, scene)
    area = None
    for task in tasks:
        ep = _read(catalog, "episodes", scene, task)
        tr = _read(catalog, "trajectories", scene, task)
        gi = _read(catalog, "goal_images", scene, task)
        if gi is not None:  # ImageNav goal views (stage goal_images): files beside the layout, paths in the table
            names = {}
            for eid, jpeg in zip(gi["episode_id"].to_pylist(), gi["jpeg"].to_pylist()):
                names[eid] = f"goal_images/{eid}_goal.jpg"
                out.bytes(f"{task}/{names[eid]}", jpeg)
            ep = ep.set_column(ep.schema.get_field_index("goal_image_path"), "goal_image_path",
                               pa.array([names.get(e) for e in ep["episode_id"].to_pylist()], pa.string()))
        ne = navarena_episodes(ep, ecfg.chunk_size)
        out.parquet(f"{task}/meta/episodes.parquet", ne)
        n_chunks = max(1, math.ceil(ep.num_rows / ecfg.chunk_size))
        for k in range(n_chunks):
            part = ne.slice(k * ecfg.chunk_size, ecfg.chunk_size)
            ids = part["episode_id"]
            tpart = navarena_trajectories(tr.filter(pc.is_in(tr["episode_id"], value_set=ids)))
            out.parquet(f"{task}/data/chunk-{k:06d}/episodes.parquet", part)
            out.parquet(f"{task}/data/chunk-{k:06d}/trajectories.parquet", tpart, **trajectory_write(tpart))
        splits = sorted(set(ep["split"].to_pylist()))
        info = {"dataset_name": ecfg.dataset_name, "scene_path": f"{scene.group}/{scene.scene_id}", "task_type": task,
                "split": splits[0] if len(splits) == 1 else ",".join(splits), "num_episodes": ep.num_rows,
                "num_chunks": n_chunks, "chunk_size": ecfg.chunk_size, "format_version": FORMAT_VERSION,
                "created_date": created,
                "generation_runs": [{"generator": "navarena episodes stage",
                                     "seeds": sorted(set(ep["seed"].to_pylist()))}]}
        out.json(f"{task}/meta/info.json", info)
    asset = catalog.dataset("asset", scene)
    n_obj = None
    m = asset.read_json("manifest.json")
    if m is not None:
        area = m.get("nav_region", {}).get("area_m2")
        labels = asset.read_json("labels.json")
        if labels is not None:
            n_obj = len(labels["labels"])
    out.json("scene_meta.json", {"scene_id": scene.scene_id, "scene_path": f"{scene.group}/{scene.scene_id}", "navigable_area": area,
                 "num_objects": n_obj, "task_types": tasks, "created_date": created, "updated_date": created,
                 "source": {"dataset": scene.group, "original_id": scene.name, "original_name": scene.name}})
    return tasks


def _habitat_episode(row: dict, scene_key: str) -> dict:
    ep = {"episode_id": row["episode_id"], "scene_id": scene_key,
          "start_position": habitat_position(row["start_position_x"], row["start_position_y"], row["start_position_z"]),
          "start_rotation": habitat_rotation(row["start_yaw"]),
          "info": {"geodesic_distance": float(row["geodesic_distance"]),
                   "euclidean_distance": float(row["euclidean_distance"]), "difficulty": row["difficulty"]},
          "shortest_paths": None, "start_room": None}
    if row["task_type"] == "objectnav":
        ep["object_category"] = row["goal_object_category"]
        ep["goals"] = []
        ep["info"]["closest_goal_object_id"] = row["goal_object_id"]
    else:
        ep["goals"] = [{"position": habitat_position(row["goal_position_x"], row["goal_position_y"],
                                                     row["goal_position_z"]),
                        "radius": float(row["success_radius"])}]
    return ep


def export_habitat(scene, catalog, aligned_name: str = "aligned.ply") -> list[str]:
    """Habitat-lab episodes of the scene; their scene_id is the asset's aligned model (aligned_name)."""
    scene_key = f"{scene.group}/{scene.scene_id}/{aligned_name}"
    for old in catalog.find("habitat_content", scene).values():  # tasks or splits since dropped
        old.delete()
    written = []
    for task in _tasks_of(catalog, scene):
        ep = _read(catalog, "episodes", scene, task)
        if ep is None or not ep.num_rows or ep["task_type"][0].as_py() not in HABITAT_TASKS:
            continue
        kind = ep["task_type"][0].as_py()
        rows = ep.to_pylist()
        for split in sorted(set(r["split"] for r in rows)):
            content = {"episodes": [_habitat_episode(r, scene_key) for r in rows if r["split"] == split]}
            if kind == "objectnav":
                content["goals_by_category"] = {}
                for r in rows:
                    key = f"{scene.scene_id}_{r['goal_object_category']}"
                    if key in content["goals_by_category"]:
                        continue
                    content["goals_by_category"][key] = [
                        {"object_id": g["object_id"], "object_category": g["object_category"],
                         "position": habitat_position(*g["position"]),
                         "view_points": [{"agent_state": {"position": habitat_position(*v["position"]),
                                                          "rotation": habitat_rotation(v["yaw"])}, "iou": None}
                                         for v in g["view_points"]]}
                        for g in json.loads(r["goals_json"])]
            out = catalog.dataset("habitat_content", scene, task=task, split=split)
            out.save(content)
            written.append(str(out.path))
    return written


def run(scene, cfg, catalog) -> dict:
    from omegaconf import OmegaConf

    from navcore.io.stamps import build_time

    ecfg: ExportConfig = OmegaConf.to_object(cfg.export)
    unknown = set(ecfg.formats) - {"navarena", "habitat"}
    if unknown:
        raise ValueError(f"export.formats: unknown format(s) {sorted(unknown)} (navarena, habitat)")
    created = build_time()
    out = []
    if "navarena" in ecfg.formats:
        out += export_navarena(scene, catalog, ecfg, created)
    if "habitat" in ecfg.formats:
        asset = catalog.dataset("asset", scene).path
        if not keeps_aligned_file(asset):
            raise ValueError("export.formats has habitat, whose episodes name the asset's aligned model file, and the "
                             "asset keeps none (asset.aligned_format=source): use asset.aligned_format=ply (what "
                             "Habitat reads) or leave habitat out of export.formats")
        out += export_habitat(scene, catalog, aligned_model(asset).name)
    return {"outputs": out}


def finalize(cfg, catalog) -> dict:
    """Dataset-level files, from what the export folder holds (so that shards agree):
    NavArena dataset_meta.json and Habitat's split files."""
    from omegaconf import OmegaConf

    from navcore.io.stamps import build_time

    ecfg: ExportConfig = OmegaConf.to_object(cfg.export)
    out = []
    if "navarena" in ecfg.formats:
        folders = catalog.find("export_scene", export_name=ecfg.dataset_name)  # sorted by group/scene_id
        scenes = [m for m in (f.read_json("scene_meta.json") for f in folders.values()) if m is not None]
        if scenes:
            now = build_time()
            meta = {"dataset_name": ecfg.dataset_name, "format_version": FORMAT_VERSION,
                    "created_date": min(s["created_date"] for s in scenes), "updated_date": now,
                    "scene_ids": [s["scene_id"] for s in scenes], "scene_paths": [s["scene_path"] for s in scenes],
                    "task_types": sorted({t for s in scenes for t in s["task_types"]})}
            meta_ds = catalog.dataset("export_dataset_meta", export_name=ecfg.dataset_name)
            meta_ds.save(meta)
            out.append(str(meta_ds.path))
    if "habitat" in ecfg.formats:
        contents: dict[tuple[str, str], list] = {}
        for key, ds in catalog.find("habitat_content").items():  # task/split/scene_id
            task, split, _ = key.split("/")
            contents.setdefault((task, split), []).append(ds)
        for (task, split), files in sorted(contents.items()):
            top = {"episodes": []}
            if task.startswith("objectnav"):
                cats = sorted({k.split("_", 1)[1] for ds in files for k in ds.load()["goals_by_category"]})
                top["category_to_task_category_id"] = {c: i for i, c in enumerate(cats)}
                top["category_to_mp3d_category_id"] = {c: i for i, c in enumerate(cats)}
            split_ds = catalog.dataset("habitat_split", task=task, split=split)
            split_ds.save(top)
            out.append(str(split_ds.path))
    return {"outputs": out}
