"""Export a split of a data root as a LeRobot dataset (format v3.0, as the `lerobot` package's
LeRobotDataset reads it): RGB rendered along the expert trajectories as one MP4 per episode and
camera, depth and the expert's actions in Parquet data files, episode / task metadata and stats.

    navarena export-lerobot --root data --out exports/lerobot_train --split train --fps 5 --size 160x120

Layout (v3.0): meta/info.json, meta/stats.json, meta/tasks.parquet,
meta/episodes/chunk-000/file-000.parquet, data/chunk-XXX/file-YYY.parquet (up to
`episodes_per_file` episodes each), videos/observation.images.rgb/chunk-XXX/file-YYY.mp4 (one file
per episode: from_timestamp 0).

Frames: every `20 / fps`-th stored trajectory row (the stored trajectories are 20 Hz) and the last.
Features per frame:
- observation.images.rgb: video (H.264, yuv420p), the embodiment's camera at the expert pose.
- observation.depth: float32 [H, W, 1], metres along the optical axis (0: nothing hit), exact.
- observation.state: float32 [x, y, yaw] in the scene's aligned frame.
- observation.goal: float32 [dx, dy, dyaw]: the goal in the robot frame (ObjectNav: the view point
  the expert reaches), as PointNav's goal vector; the task string names what to find.
- action: float32 [linear_velocity, angular_velocity]: the mean command until the next frame.
- action.waypoint: float32 [dx, dy, dyaw]: the pose change to the next frame in the robot frame.
- action.discrete: int64, the expert's discrete action id at the frame (0 stop, 1 forward, 2 left,
  3 right), and timestamp, frame_index, episode_index, index, task_index.
Tasks are natural-language strings ("Navigate to the chair.", "Navigate to the point goal.",
"Navigate to where the goal image was taken."); episode metadata keeps our scene, task, episode
id, split and difficulty. Deterministic: same data and arguments, the same bytes in every file, the
MP4s included (`navcore.io.video.H264Writer`).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from navarena import quick
from navarena.quick import shorten
from navcore.io import jsonio
from navcore.io.atomic import atomic_path
from navcore.io.catalog import Catalog
from navcore.io.tool_progress import ToolProgress
from navcore.io.video import H264Writer
from navcore.nav.embodiment import Embodiment
from navcore.nav.poses import wrap_angle
from navcore.nav.tasks import TASK_TYPES

CODEBASE_VERSION = "v3.0"
CHUNKS_SIZE = 1000
RGB_KEY = "observation.images.rgb"
TRAJECTORY_HZ = 20
TASK_TEXT = {"pointnav": "Navigate to the point goal.", "imagenav": "Navigate to where the goal image was taken."}


def _task_text(task: str, category: str | None) -> str:
    return f"Navigate to the {category}." if task == "objectnav" else TASK_TEXT[task]


def _frames_of(tr: pd.DataFrame, stride: int) -> pd.DataFrame:
    """One episode's rows at the export rate with the actions that lead to the next frame."""
    tr = tr.sort_values("step")
    last = int(tr["step"].iloc[-1])
    keep = (tr["step"] % stride == 0) | (tr["step"] == last)
    f = tr[keep].reset_index(drop=True)
    x, y, yaw = (f[c].to_numpy(np.float64) for c in ("position_x", "position_y", "yaw"))
    dxw, dyw = np.diff(x, append=x[-1]), np.diff(y, append=y[-1])
    c, s = np.cos(yaw), np.sin(yaw)
    f["wp_dx"], f["wp_dy"] = c * dxw + s * dyw, -s * dxw + c * dyw
    f["wp_dyaw"] = wrap_angle(np.diff(yaw, append=yaw[-1]))
    # mean command over each frame's interval of stored rows (the last frame: the last row's)
    seg = np.searchsorted(f["step"].to_numpy(), tr["step"].to_numpy(), side="right") - 1
    for col, out in (("linear_velocity", "cmd_v"), ("angular_velocity", "cmd_w")):
        f[out] = pd.Series(tr[col].to_numpy(np.float64)).groupby(seg).mean().reindex(range(len(f))).to_numpy()
    return f


def _stats(a: np.ndarray, axis) -> dict:
    return {"min": a.min(axis=axis).tolist(), "max": a.max(axis=axis).tolist(), "mean": a.mean(axis=axis).tolist(),
            "std": a.std(axis=axis).tolist(), "count": [int(a.shape[0])]}


def export_lerobot(root, out, split: str | None = "train", tasks=TASK_TYPES,
                   fps: int = 5, width: int = 160, height: int = 120, depth: bool = True,
                   episodes_per_scene: int | None = None, scenes=None, renderer: str = "auto",
                   embodiment: Embodiment | None = None, episodes_per_file: int = 100, crf: int = 18,
                   batch_size: int = 64, robot_type: str | None = None, quiet: bool = False,
                   episodes: int | None = None) -> dict:
    """Write the LeRobot dataset of `split` of the data root `root` to `out` (replaced whole:
    written beside it and renamed in place): every episode, or the first `episodes_per_scene` of
    each scene and task, or `episodes` in total taken round robin over the scenes and tasks.
    Returns a summary (episodes, frames, bytes). A progress display (episodes, frames, frames/s,
    time left; plain lines without a terminal) unless quiet."""
    from navcore.optional import require
    from navcore.render.frames import SceneFrames, chosen_episodes, round_robin

    require("datasets", "the LeRobot export")  # before any frame is rendered
    if TRAJECTORY_HZ % fps:
        raise ValueError(f"fps must divide the trajectories' {TRAJECTORY_HZ} Hz, got {fps}")
    if width % 2 or height % 2:
        raise ValueError(f"H.264 needs even image sizes, got {width}x{height}")
    stride = TRAJECTORY_HZ // fps
    src = SceneFrames(root, split=split, tasks=tasks, scenes=scenes, width=width, height=height,
                embodiment=embodiment, renderer=renderer)
    emb = src.emb
    cat = Catalog.for_root(root)
    out = Path(out)
    task_index: dict[str, int] = {}
    episodes_meta, data_rows, frames_total = [], [], 0
    stats_acc = {"observation.state": [], "observation.goal": [], "action": [], "action.waypoint": []}
    rgb_sum, rgb_sq, rgb_min, rgb_max, depth_acc = np.zeros(3), np.zeros(3), np.full(3, 255.0), np.zeros(3), []
    sizes = {(sid, task): len(chosen_episodes(cat, cat.scene(sid), task, split, episodes_per_scene,
                                              ["episode_id", "split"])) for sid in src.scene_ids for task in tasks}
    quota = round_robin(sizes, episodes) if episodes is not None else sizes
    total = sum(quota.values())  # the progress display's total
    with atomic_path(out) as tmp, ToolProgress("export-lerobot", total, quiet) as bar:
        tmp.mkdir(parents=True)
        ep_index = 0
        for sid in src.scene_ids:
            scene = cat.scene(sid)
            for task in tasks:
                eps = chosen_episodes(cat, scene, task, split, episodes_per_scene).head(quota.get((sid, task), 0))
                if not len(eps):
                    continue
                tr_all = cat.dataset("trajectories", scene, task=task).load().to_pandas()
                tr_all = tr_all[tr_all["episode_id"].isin(set(eps["episode_id"]))]
                by_ep = dict(tuple(tr_all.groupby("episode_id", sort=False)))
                for e in eps.to_dict("records"):
                    f = _frames_of(by_ep[e["episode_id"]], stride)
                    n = len(f)
                    text = _task_text(task, e.get("goal_object_category"))
                    ti = task_index.setdefault(text, len(task_index))
                    chunk, file = divmod(ep_index, CHUNKS_SIZE)
                    vpath = tmp / f"videos/{RGB_KEY}/chunk-{chunk:03d}/file-{file:03d}.mp4"
                    vpath.parent.mkdir(parents=True, exist_ok=True)
                    video = H264Writer(vpath, fps, crf=crf, b_frames=0)
                    depths = []
                    for a in range(0, n, batch_size):
                        poses = f.iloc[a:a + batch_size][["position_x", "position_y", "yaw"]].to_numpy()
                        rgb_t, depth_t = src.frames(sid, poses)
                        rgb = rgb_t.numpy()
                        for im in rgb:
                            video.add(im)
                        px = rgb.reshape(-1, 3).astype(np.float64) / 255.0
                        rgb_sum += px.sum(0)
                        rgb_sq += (px ** 2).sum(0)
                        rgb_min, rgb_max = np.minimum(rgb_min, px.min(0)), np.maximum(rgb_max, px.max(0))
                        depths.append(depth_t.numpy().astype(np.float32))
                    video.close()
                    dep = np.concatenate(depths)
                    depth_acc.append(dep[:, ::8, ::8].ravel())
                    gx, gy = float(e["goal_position_x"]), float(e["goal_position_y"])
                    gyaw = float(e["goal_yaw"]) if not math.isnan(float(e.get("goal_yaw", math.nan))) else 0.0
                    x, y, yaw = (f[c].to_numpy(np.float64) for c in ("position_x", "position_y", "yaw"))
                    c, s = np.cos(yaw), np.sin(yaw)
                    goal = np.stack([c * (gx - x) + s * (gy - y), -s * (gx - x) + c * (gy - y),
                                     wrap_angle(gyaw - yaw)], 1).astype(np.float32)
                    state = np.stack([x, y, yaw], 1).astype(np.float32)
                    act = f[["cmd_v", "cmd_w"]].to_numpy(np.float32)
                    wp = f[["wp_dx", "wp_dy", "wp_dyaw"]].to_numpy(np.float32)
                    for k, v in (("observation.state", state), ("observation.goal", goal), ("action", act),
                                 ("action.waypoint", wp)):
                        stats_acc[k].append(v)
                    rows = {"observation.state": state, "observation.goal": goal, "action": act,
                            "action.waypoint": wp, "action.discrete": f["action_id"].to_numpy(np.int64),
                            "timestamp": (np.arange(n) / fps).astype(np.float32),
                            "frame_index": np.arange(n, dtype=np.int64),
                            "episode_index": np.full(n, ep_index, np.int64),
                            "index": np.arange(frames_total, frames_total + n, dtype=np.int64),
                            "task_index": np.full(n, ti, np.int64)}
                    if depth:
                        rows["observation.depth"] = dep[..., None]
                    data_file = ep_index // episodes_per_file
                    dchunk, dfile = divmod(data_file, CHUNKS_SIZE)
                    data_rows.append((data_file, rows))
                    episodes_meta.append({
                        "episode_index": ep_index, "tasks": [text], "length": n,
                        "data/chunk_index": dchunk, "data/file_index": dfile,
                        "dataset_from_index": frames_total, "dataset_to_index": frames_total + n,
                        f"videos/{RGB_KEY}/chunk_index": chunk, f"videos/{RGB_KEY}/file_index": file,
                        f"videos/{RGB_KEY}/from_timestamp": 0.0, f"videos/{RGB_KEY}/to_timestamp": n / fps,
                        "meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0,
                        "navarena/scene_id": sid, "navarena/task": task, "navarena/episode_id": e["episode_id"],
                        "navarena/split": e["split"], "navarena/difficulty": e["difficulty"],
                        "navarena/geodesic_distance": float(e["geodesic_distance"])})
                    frames_total += n
                    ep_index += 1
                    bar.advance(1, n)
        if not ep_index:
            import pyarrow.dataset as pads

            eps = Path(root) / "05_episodes"
            present = sorted(set(pads.dataset(eps, partitioning="hive").to_table(columns=["split"])
                                 .column("split").to_pylist())) if eps.is_dir() else []
            raise ValueError(f"no episodes of split {split!r} and tasks {list(tasks)} under {root}; the splits there: "
                             f"{', '.join(present) or 'none'} (whole scenes are held out as val_unseen / test by "
                             "episodes.scene_splits)")
        features = _features(width, height, fps, depth)
        _write_data(tmp, data_rows, features)
        _write_meta(tmp, episodes_meta, task_index, features, fps, frames_total, split, robot_type or emb.name,
                    episodes_per_file, stats_acc, (rgb_sum, rgb_sq, rgb_min, rgb_max, frames_total * width * height),
                    np.concatenate(depth_acc) if depth else None)
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    return {"episodes": ep_index, "frames": frames_total, "bytes": size, "out": str(out)}


def _features(w: int, h: int, fps: int, depth: bool) -> dict:
    vec = lambda names: {"dtype": "float32", "shape": [len(names)], "names": names}  # noqa: E731
    feats = {
        RGB_KEY: {"dtype": "video", "shape": [h, w, 3], "names": ["height", "width", "channels"],
                  "info": {"video.height": h, "video.width": w, "video.codec": "h264", "video.pix_fmt": "yuv420p",
                           "video.is_depth_map": False, "video.fps": fps, "video.channels": 3, "has_audio": False}},
        "observation.state": vec(["x", "y", "yaw"]),
        "observation.goal": vec(["dx", "dy", "dyaw"]),
        "action": vec(["linear_velocity", "angular_velocity"]),
        "action.waypoint": vec(["dx", "dy", "dyaw"]),
        "action.discrete": {"dtype": "int64", "shape": [1], "names": None},
        "timestamp": {"dtype": "float32", "shape": [1], "names": None},
        "frame_index": {"dtype": "int64", "shape": [1], "names": None},
        "episode_index": {"dtype": "int64", "shape": [1], "names": None},
        "index": {"dtype": "int64", "shape": [1], "names": None},
        "task_index": {"dtype": "int64", "shape": [1], "names": None},
    }
    if depth:
        feats["observation.depth"] = {"dtype": "float32", "shape": [h, w, 1], "names": ["height", "width", "channel"]}
    return feats


def _write_data(tmp: Path, data_rows: list, features: dict) -> None:
    """data/chunk-XXX/file-YYY.parquet, written through HF datasets with the feature metadata
    LeRobot's loader reads back."""
    import datasets

    cols_of = {k: v for k, v in features.items() if v["dtype"] != "video"}
    hf = _hf_features(cols_of)
    by_file: dict[int, list[dict]] = {}
    for file_no, rows in data_rows:
        by_file.setdefault(file_no, []).append(rows)
    for file_no, parts in sorted(by_file.items()):
        # whole numpy columns: datasets converts them to Arrow directly (the same bytes as Python
        # lists of every frame's values, ten times faster for the depth images)
        cols = {k: np.concatenate([np.asarray(p[k]) for p in parts]) for k in cols_of}
        chunk, file = divmod(file_no, CHUNKS_SIZE)
        path = tmp / f"data/chunk-{chunk:03d}/file-{file:03d}.parquet"
        path.parent.mkdir(parents=True, exist_ok=True)
        datasets.Dataset.from_dict(cols, features=hf).to_parquet(str(path))


def _hf_features(features: dict):
    """datasets.Features of LeRobot features (as lerobot's get_hf_features_from_features)."""
    import datasets

    out = {}
    for key, ft in features.items():
        shape = tuple(ft["shape"])
        if shape == (1,):
            out[key] = datasets.Value(dtype=ft["dtype"])
        elif len(shape) == 1:
            out[key] = datasets.Sequence(length=shape[0], feature=datasets.Value(dtype=ft["dtype"]))
        elif len(shape) == 3:
            out[key] = datasets.Array3D(shape=shape, dtype=ft["dtype"])
        else:
            raise ValueError(f"feature {key}: unsupported shape {shape}")
    return datasets.Features(out)


def _write_meta(tmp: Path, episodes_meta, task_index, features, fps, frames, split, robot_type, per_file,
                stats_acc, rgb, depth_sample) -> None:
    meta = tmp / "meta"
    (meta / "episodes/chunk-000").mkdir(parents=True)
    n_eps = len(episodes_meta)
    n_data_files = (n_eps - 1) // per_file + 1
    info = {"codebase_version": CODEBASE_VERSION, "robot_type": robot_type, "total_episodes": n_eps,
            "total_frames": frames, "total_tasks": len(task_index), "chunks_size": CHUNKS_SIZE,
            "data_files_size_in_mb": 100, "video_files_size_in_mb": 200, "fps": fps,
            "splits": {split or "all": f"0:{n_eps}"},
            "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
            "video_path": "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4",
            "features": features, "navarena": {"data_files": n_data_files, "trajectory_hz": TRAJECTORY_HZ}}
    (meta / "info.json").write_text(jsonio.dumps(info, indent=2))
    tasks = pd.DataFrame({"task_index": list(task_index.values())}, index=pd.Index(list(task_index), name="task"))
    tasks.to_parquet(meta / "tasks.parquet")
    stats = {k: _stats(np.concatenate(v), 0) for k, v in stats_acc.items()}
    s, sq, lo, hi, n = rgb
    mean = s / n
    per_chan = lambda v: np.asarray(v, float).reshape(3, 1, 1).tolist()  # noqa: E731
    stats[RGB_KEY] = {"min": per_chan(lo), "max": per_chan(hi), "mean": per_chan(mean),
                      "std": per_chan(np.sqrt(np.maximum(sq / n - mean ** 2, 0))), "count": [frames]}
    if depth_sample is not None:
        d = depth_sample.astype(np.float64)
        stats["observation.depth"] = {k: [[[float(v)]]] for k, v in
                                      (("min", d.min()), ("max", d.max()), ("mean", d.mean()), ("std", d.std()))}
        stats["observation.depth"]["count"] = [frames]
    (meta / "stats.json").write_text(jsonio.dumps(stats, indent=2))
    pq.write_table(pa.Table.from_pylist(episodes_meta), meta / "episodes/chunk-000/file-000.parquet")


def main(argv=None) -> dict:
    """navarena export-lerobot: a split of a data root as a LeRobot (v3.0) dataset."""
    import argparse

    ap = argparse.ArgumentParser(prog="navarena export-lerobot", description=main.__doc__)
    ap.add_argument("--root", default="data", help="data root")
    ap.add_argument("--out", required=True)
    ap.add_argument("--split", default="train")
    ap.add_argument("--tasks", default="pointnav,imagenav,objectnav")
    ap.add_argument("--fps", type=int, default=5, help="frames a second (divides 20)")
    ap.add_argument("--size", default="160x120", help="WIDTHxHEIGHT")
    ap.add_argument("--no-depth", action="store_true")
    ap.add_argument("--episodes-per-scene", type=int, default=None, metavar="N", help="the first N of every scene and task")
    ap.add_argument("--episodes", type=int, default=None, metavar="N",
                    help="N episodes in total, round robin over scenes and tasks (a first try: seconds each on a CPU)")
    ap.add_argument("--renderer", default="auto", choices=["auto", "cpu", "gsplat"])
    ap.add_argument("--quiet", action="store_true", help="no progress display")
    args = ap.parse_args(argv)
    shorten(args, quick.EXPORT, "navarena export-lerobot")
    w, h = (int(v) for v in args.size.lower().split("x"))
    res = export_lerobot(args.root, args.out, args.split or None, args.tasks.split(","), args.fps, w, h,
                         not args.no_depth, args.episodes_per_scene, renderer=args.renderer, quiet=args.quiet,
                         episodes=args.episodes)
    print(json.dumps(res))
    return res
