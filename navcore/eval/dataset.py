"""A finished NavArena dataset opened for evaluation and training: a pipeline's data root or a
downloaded release folder, read the same way.

    from navarena import NavDataset, NavEnv
    ds = NavDataset("navarena-v1.0.0")                 # a release folder, or a data root ("data")
    sid = ds.scene_ids("pointnav")[0]
    episodes = ds.episodes(sid, "pointnav", split="test", limit=5)
    ctx = ds.scene_context(sid, renderer="cpu")        # costmap, navigation graph, renderer
    env = NavEnv(ctx, ds.env_config(protocol="distance"))

What each kind gives the environment:
- a data root (`make dataset`): the stored costmap (continuous clearance, the embodiment's radius),
  the navigation graph over the cells episodes may use, the aligned scene less the splats the
  costmap hid from the camera; the embodiment and step sizes its episodes were made with (the
  episodes stage's completion marker).
- a release: each scene's V1 asset, its ROS map (binary occupancy, the robot's radius already
  grown into it: the valid region's edge lies half way between a free and an occupied cell, as
  `navarena verify-release` checks episodes, with the clearance between rebuilt from the distance
  to that edge: navcore.nav.costmap.Costmap.from_inflated_map) and its aligned model; the
  embodiment and step sizes of release.json's resolved config.
"""
from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path

import numpy as np

from navcore.eval.env import EnvConfig, SceneContext
from navcore.eval.episode import Episode
from navcore.nav.actions import ActionSpace
from navcore.nav.embodiment import Embodiment
from navcore.nav.tasks import TASK_TYPES

TASKS = TASK_TYPES
REFERENCE_STRIDE = 10
"""Expert rows kept as an episode's reference path (DTW): every 0.5 s at the trajectories' 20 Hz."""


def _dataclass_of(cls, spec: dict | None, default):
    """`cls` from the keys of `spec` that are its fields (others ignored), or `default`."""
    if not spec:
        return default
    names = {f.name for f in fields(cls)}
    return cls(**{k: v for k, v in spec.items() if k in names})


class NavDataset:
    """A data root or a release folder (found by its release.json), read-only.

    Args:
        path: the folder.
        embodiment: the embodiment whose costmap to use (data roots with several; default: the one
            the episodes were made with).
    """

    def __init__(self, path: str | Path, embodiment: str | None = None):
        from navcore.io.release import RELEASE_JSON

        self.path = Path(path).resolve()
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path}: no such folder (a NavArena data root or release folder)")
        self.is_release = (self.path / RELEASE_JSON).is_file()
        self._catalog = None
        self._config: dict = {}
        if self.is_release:
            from navcore.io.release import read_release_json

            info = read_release_json(self.path)
            if "key_columns" not in info:
                raise ValueError(f"{self.path}: a release in the earlier hive layout (episodes/task=.../split=.../"
                                 "scene_id=...); rebuild it with this version's `navarena release`")
            self._config = info.get("config") or {}
        else:
            from navcore.io.catalog import Catalog

            self._catalog = Catalog.for_root(self.path)
            if not (self.path / "05_episodes").is_dir() and not self._catalog.scene_ids("episodes"):
                raise FileNotFoundError(f"{self.path}: neither a release folder (no release.json) nor a data root "
                                        f"with episodes (no 05_episodes/): run the pipeline first, or pass a release")
            sids = self._catalog.scene_ids("episodes")
            if sids:  # the episodes stage's config (every scene of a root shares it)
                marker = self._catalog.dataset("markers", self._catalog.scene(sids[0]), stage="episodes")
                if marker.exists():
                    self._config = marker.load().get("config") or {}
        self.embodiment: Embodiment = _dataclass_of(Embodiment, self._config.get("embodiment"), Embodiment())
        if embodiment and embodiment != self.embodiment.name:
            from navcore.nav.embodiment import load_embodiment

            self.embodiment = load_embodiment(embodiment)
        self.actions: ActionSpace = _dataclass_of(ActionSpace, (self._config.get("episodes") or {}).get("actions"),
                                                  ActionSpace())

    def __repr__(self) -> str:
        return f"NavDataset({str(self.path)!r}, {'release' if self.is_release else 'data root'}, {self.embodiment.name})"

    # ------------------------------------------------------------------ tables
    def _episode_files(self, task: str, scene_id: str | None = None) -> list[Path]:
        if self.is_release:
            return sorted(self.path.glob(f"episodes/{task}/*/{scene_id or '*'}.parquet"))
        return sorted(self.path.glob(f"05_episodes/task={task}/scene_id={scene_id or '*'}/part-0.parquet"))

    def scene_ids(self, task: str | None = None, split: str | None = None) -> list[str]:
        """Scenes with episodes (of `task`, or of any task; of `split`, or of any split), sorted:
        `ds.scene_ids("pointnav", split="test")[0]` is a scene that has PointNav test episodes."""
        import pyarrow.parquet as pq

        out = set()
        for t in ([task] if task else TASKS):
            for p in self._episode_files(t):
                sid = p.stem if self.is_release else p.parent.name.split("=", 1)[1]
                if split is None or (p.parent.name == split if self.is_release else
                                     split in set(pq.read_table(p, columns=["split"]).column("split").to_pylist())):
                    out.add(sid)
        return sorted(out)

    def episode_table(self, scene_id: str, task: str):
        """The episodes of one scene and task as a pandas DataFrame: the canonical columns with task,
        split and scene_id (a release's key columns), from a release or a data root alike."""
        import pandas as pd
        import pyarrow.parquet as pq

        parts = [pq.read_table(f).to_pandas() for f in self._episode_files(task, scene_id)]
        if not parts:
            raise KeyError(f"{self.path}: no {task} episodes of scene {scene_id!r} (scenes: {', '.join(self.scene_ids(task))})")
        df = pd.concat(parts, ignore_index=True)
        for col, value in (("task", task), ("scene_id", scene_id)):
            if col not in df.columns:  # a data root's files: its folders name them
                df.insert(0, col, value)
        return df

    def _reference_paths(self, scene_id: str, task: str, ids: set[str]) -> dict[str, np.ndarray]:
        import pyarrow.dataset as pds

        if self.is_release:
            files = sorted(self.path.glob(f"trajectories/{task}/*/{scene_id}.parquet"))
        else:
            files = sorted(self.path.glob(f"06_trajectories/task={task}/scene_id={scene_id}/part-0.parquet"))
        if not files:
            return {}
        t = pds.dataset([str(f) for f in files], format="parquet").to_table(
            columns=["episode_id", "step", "position_x", "position_y"], filter=pds.field("episode_id").isin(sorted(ids)))
        df = t.to_pandas().sort_values(["episode_id", "step"], kind="stable")
        return {eid: g[["position_x", "position_y"]].to_numpy()[::REFERENCE_STRIDE] for eid, g in df.groupby("episode_id")}

    def episodes(self, scene_id: str, task: str, split: str | None = None, difficulty: str | None = None,
                 limit: int | None = None, ids=None) -> list[Episode]:
        """Episodes of one scene and task for the environment, by episode id: of `split` and
        `difficulty` (None: any), only `ids` when given, at most `limit`; with the expert's path as
        each one's reference (DTW)."""
        eps = self.episode_table(scene_id, task)
        if split:
            eps = eps[eps["split"] == split]
        if difficulty:
            eps = eps[eps["difficulty"] == difficulty]
        if ids is not None:
            eps = eps[eps["episode_id"].isin(set(ids))]
        eps = eps.sort_values("episode_id")
        if limit is not None:
            eps = eps.head(limit)
        refs = self._reference_paths(scene_id, task, set(eps["episode_id"])) if len(eps) else {}
        out = []
        for row in eps.to_dict("records"):
            row["task_type"], row["scene_id"] = task, scene_id
            out.append(Episode.from_row(row, refs.get(row["episode_id"])))
        return out

    def eval_set(self, name: str = "eval_zeroshot"):
        """The listing (task, scene_id, episode_id) of a zero-shot evaluation set, as a DataFrame."""
        import pandas as pd

        f = self.path / ("eval_sets" if self.is_release else "05_eval_sets") / f"{name}.parquet"
        if not f.is_file():
            raise FileNotFoundError(f"{f}: no evaluation set {name!r} here (a release ships eval_sets/{name}.parquet)")
        return pd.read_parquet(f)

    # ------------------------------------------------------------------ scenes
    def _asset(self, scene_id: str) -> Path:
        found = sorted(self.path.glob(f"assets/*/{scene_id}"))
        if not found:
            raise FileNotFoundError(f"{self.path}: scene {scene_id!r} has no asset folder under assets/ (a release "
                                    f"without the scene's model or map: re-download it)")
        return found[0]

    def scene_context(self, scene_id: str, render: bool = True, renderer: str = "auto") -> SceneContext:
        """What every environment of one scene shares: costmap, navigation graph and (render) the
        renderer (auto: gsplat on CUDA, else the CPU renderer; cpu; gsplat)."""
        from navcore.nav.geodesic import NavGraph

        emb = self.embodiment
        if self.is_release:
            from navcore.io.asset_files import load_aligned, read_nav_map
            from navcore.nav.costmap import Costmap

            asset = self._asset(scene_id)
            occ, origin, res = read_nav_map(asset)
            cm = Costmap.from_inflated_map(occ, origin, res, emb.radius)
            graph = NavGraph(cm, ~cm.occupancy, self._neighbourhood())
            gs = load_aligned(asset) if render else None
            return SceneContext(cm, graph, emb, gs, renderer)
        return SceneContext.from_catalog(self._catalog, self._catalog.scene(scene_id), emb,
                                         self._episodes_setting("components"),
                                         self._episodes_setting("min_island_area_m2"), self._neighbourhood(),
                                         render, renderer)

    def _episodes_setting(self, key: str):
        """A key of the episodes config the data was made with (release.json, or the episodes
        stage's marker of a data root)."""
        value = (self._config.get("episodes") or {}).get(key)
        if value is None:
            where = "release.json" if self.is_release else "_markers/episodes/*.json"
            raise ValueError(f"{self.path}: {where} does not record episodes.{key} (a dataset of an older "
                             f"NavArena, or one whose episodes stage did not finish)")
        return value

    def _neighbourhood(self) -> int:
        return int(self._episodes_setting("geodesic_neighbourhood"))

    def env_config(self, **settings) -> EnvConfig:
        """The environment's config with this dataset's step sizes (settings: protocol, width,
        height, render, dynamics; see navcore.eval.env.EnvSettings)."""
        return EnvConfig(actions=self.actions, **settings)

    def info(self) -> dict:
        """What a summary names of the dataset: path, kind, version, embodiment and step sizes."""
        out = {"path": str(self.path), "kind": "release" if self.is_release else "data_root",
               "embodiment": self.embodiment.name, "forward_step": self.actions.forward_step,
               "turn_angle_deg": self.actions.turn_angle_deg}
        if self.is_release:
            out["version"] = json.loads((self.path / "release.json").read_text()).get("version")
        return out



class CombinedDataset:
    """Several data roots or releases read as one: their scenes side by side, each read from its own
    folder (training on generated scenes and real captures together: `navarena train ROOT ROOT ...`).
    They must share the embodiment and the step sizes, and a scene id may appear in one of them only.
    The same methods as NavDataset, each answered by the part that holds the scene."""

    def __init__(self, paths, embodiment: str | None = None):
        self.parts = [NavDataset(p, embodiment) for p in paths]
        if not self.parts:
            raise ValueError("CombinedDataset: no folder given")
        first = self.parts[0]
        for ds in self.parts[1:]:
            if (ds.embodiment.name, ds.actions) != (first.embodiment.name, first.actions):
                raise ValueError(f"{ds.path}: embodiment {ds.embodiment.name} with {ds.actions}, where {first.path} has "
                                 f"{first.embodiment.name} with {first.actions}: datasets trained on together must match")
        self._owner: dict[str, NavDataset] = {}
        for ds in self.parts:
            for sid in ds.scene_ids():
                if sid in self._owner:
                    raise ValueError(f"scene {sid!r} is in both {self._owner[sid].path} and {ds.path}")
                self._owner[sid] = ds
        self.path, self.paths = first.path, [ds.path for ds in self.parts]
        self.embodiment, self.actions, self.is_release = first.embodiment, first.actions, False

    def __repr__(self) -> str:
        return f"CombinedDataset({[str(p) for p in self.paths]!r})"

    def _of(self, scene_id: str) -> NavDataset:
        if scene_id not in self._owner:
            raise KeyError(f"scene {scene_id!r} is in none of {[str(p) for p in self.paths]}")
        return self._owner[scene_id]

    def scene_ids(self, task: str | None = None, split: str | None = None) -> list[str]:
        return sorted(s for ds in self.parts for s in ds.scene_ids(task, split))

    def episode_table(self, scene_id: str, task: str):
        return self._of(scene_id).episode_table(scene_id, task)

    def episodes(self, scene_id: str, task: str, split: str | None = None, difficulty: str | None = None,
                 limit: int | None = None, ids=None) -> list[Episode]:
        return self._of(scene_id).episodes(scene_id, task, split, difficulty, limit, ids)

    def scene_context(self, scene_id: str, render: bool = True, renderer: str = "auto") -> SceneContext:
        return self._of(scene_id).scene_context(scene_id, render, renderer)

    def env_config(self, **settings) -> EnvConfig:
        return self.parts[0].env_config(**settings)

    def info(self) -> dict:
        return {**self.parts[0].info(), "kind": "combined", "parts": [ds.info() for ds in self.parts]}


def open_dataset(roots, embodiment: str | None = None):
    """One folder (a path) -> NavDataset; several (a list or tuple of paths) -> CombinedDataset."""
    if isinstance(roots, (list, tuple)):
        return NavDataset(roots[0], embodiment) if len(roots) == 1 else CombinedDataset(roots, embodiment)
    return NavDataset(roots, embodiment)
