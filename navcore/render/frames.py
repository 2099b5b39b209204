"""Frames of a finished dataset's expert steps, rendered on demand: which steps (split, tasks,
scenes, stride) and the embodiment's camera over them. Shared by the observation datasets
(navarena.observations), the LeRobot export (navarena.lerobot) and render-episodes
(navarena.render_episodes); reads the data root through the catalog's datasets only.
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np
import pandas as pd
import torch

from navcore.gaussians.content import camera_scene
from navcore.io.catalog import Catalog
from navcore.nav.embodiment import Embodiment

STEP_COLUMNS = ["episode_id", "step", "position_x", "position_y", "yaw", "linear_velocity", "angular_velocity",
                "dx", "dy", "dyaw", "action_id"]


def chosen_episodes(catalog: Catalog, scene, task: str, split: str | None = None, per_scene: int | None = None,
                    columns: list[str] | None = None) -> pd.DataFrame:
    """The episodes of one scene and task a tool works on: of `split` (None: all), by id, the first
    `per_scene` (None: all); empty when the task has none."""
    ds = catalog.dataset("episodes", scene, task=task)
    if not ds.exists():
        return pd.DataFrame(columns=columns or ["episode_id", "split"])
    eps = ds.load(columns).to_pandas()
    if split:
        eps = eps[eps["split"] == split]
    eps = eps.sort_values("episode_id")
    return eps if per_scene is None else eps.head(per_scene)


def round_robin(sizes: dict, total: int) -> dict:
    """How many to take of each key (in the dict's order) for `total` in all, one of each in turn
    while it has some left: {("s1", "pointnav"): 5, ("s2", "pointnav"): 1}, 4 -> {.. 3, .. 1}.
    Keys that get none are left out."""
    taken = dict.fromkeys(sizes, 0)
    left = total
    while left > 0 and any(taken[k] < n for k, n in sizes.items()):
        for k, n in sizes.items():
            if left and taken[k] < n:
                taken[k] += 1
                left -= 1
    return {k: n for k, n in taken.items() if n}


def expert_steps(catalog: Catalog, scene_id: str, tasks, split: str | None = None, stride: int = 1,
                 episodes: int | None = None) -> pd.DataFrame:
    """The expert steps of one scene (every `stride`-th of each episode, its last always kept), with
    task and split columns; at most `episodes` episodes per task (the first by id)."""
    scene = catalog.scene(scene_id)
    parts = []
    for task in tasks:
        eps = chosen_episodes(catalog, scene, task, split, episodes, ["episode_id", "split"])
        if not len(eps):
            continue
        tr = catalog.dataset("trajectories", scene, task=task).load(STEP_COLUMNS).to_pandas()
        tr = tr[tr["episode_id"].isin(set(eps["episode_id"]))]
        tr = tr.sort_values(["episode_id", "step"], kind="stable")
        last = tr.groupby("episode_id")["step"].transform("max")
        tr = tr[(tr["step"] % max(1, stride) == 0) | (tr["step"] == last)]
        tr = tr.merge(eps, on="episode_id", how="left")
        tr.insert(0, "task", task)
        parts.append(tr)
    out = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=["task", *STEP_COLUMNS, "split"])
    out["scene_id"] = scene_id
    return out


class _Renderers:
    """One Renderer per scene, the most recent `keep` kept (the aligned scene loads once)."""

    def __init__(self, catalog: Catalog, backend: str, embodiment: str, keep: int = 2):
        self.catalog, self.backend, self.embodiment, self.keep = catalog, backend, embodiment, keep
        self.cache: OrderedDict[str, object] = OrderedDict()

    def get(self, scene_id: str):
        if scene_id not in self.cache:
            from navcore.render import Renderer

            gs, _ = camera_scene(self.catalog, self.catalog.scene(scene_id), self.embodiment, view_dependent=True)
            self.cache[scene_id] = Renderer(gs, self.backend)
            while len(self.cache) > self.keep:
                self.cache.popitem(last=False)
        self.cache.move_to_end(scene_id)
        return self.cache[scene_id]


class SceneFrames:
    """Which expert steps of a data root (split, tasks, scenes, stride) and how to render them (the
    embodiment's camera at width x height, renderer backend); shared by the datasets, the LeRobot
    export and render-episodes."""

    def __init__(self, root, split: str | None = None, tasks=("pointnav", "imagenav", "objectnav"), scenes=None,
                 stride: int = 1, episodes_per_scene: int | None = None, width: int | None = None,
                 height: int | None = None, embodiment: Embodiment | None = None, renderer: str = "auto",
                 device_output: bool = False, seed: int = 0):
        self.catalog = Catalog.for_root(root)
        self.split, self.tasks, self.stride, self.episodes = split, list(tasks), int(stride), episodes_per_scene
        self.emb = embodiment or Embodiment()
        self.width, self.height = int(width or self.emb.image_width), int(height or self.emb.image_height)
        self.backend, self.device_output, self.seed = renderer, device_output, seed
        self.scene_ids = sorted(scenes) if scenes else self.catalog.scene_ids("trajectories")
        self._renderers: _Renderers | None = None

    def _steps(self, scene_id: str) -> pd.DataFrame:
        return expert_steps(self.catalog, scene_id, self.tasks, self.split, self.stride, self.episodes)

    def frames(self, scene_id: str, poses: np.ndarray):
        """RGB uint8 [B, H, W, 3] and depth float32 [B, H, W] torch tensors at robot poses [B, 3]
        (one render call; on the renderer's device with device_output)."""
        from navcore.render.camera import embodiment_camera

        if self._renderers is None:  # built in the process that iterates (DataLoader workers)
            self._renderers = _Renderers(self.catalog, self.backend, self.emb.name)
        vm, k, w, h = embodiment_camera(self.emb, np.asarray(poses, np.float64), self.width, self.height)
        out = self._renderers.get(scene_id).render(vm, k, w, h)
        rgb = (out.rgb * 255.0 + 0.5).clamp(0, 255).to(torch.uint8)
        if self.device_output:
            return rgb, out.depth
        return rgb.cpu(), out.depth.cpu()

    def render(self, scene_id: str, rows: pd.DataFrame) -> dict:
        """One batch: frames at the rows' poses (one render call) and the rows' expert actions."""
        poses = rows[["position_x", "position_y", "yaw"]].to_numpy(np.float64)
        rgb, depth = self.frames(scene_id, poses)
        f32 = lambda cols: torch.from_numpy(rows[cols].to_numpy(np.float32, copy=True))  # noqa: E731
        return {"rgb": rgb, "depth": depth, "pose": torch.from_numpy(poses.astype(np.float32)),
                "velocity": f32(["linear_velocity", "angular_velocity"]), "waypoint": f32(["dx", "dy", "dyaw"]),
                "action_id": torch.from_numpy(rows["action_id"].to_numpy(np.int64, copy=True)),
                "step": torch.from_numpy(rows["step"].to_numpy(np.int64, copy=True)),
                "episode_id": rows["episode_id"].tolist(), "task": rows["task"].tolist(),
                "scene_id": [scene_id] * len(rows)}
