"""The stage graph: what each stage needs and which config sections decide its output."""
from __future__ import annotations

import hashlib
import importlib
import json
from dataclasses import dataclass
from typing import Callable

from omegaconf import OmegaConf


@dataclass(frozen=True)
class Stage:
    """A pipeline stage keyed by scene.

    Attributes:
        name: stage name (config key `stages`, marker folder).
        target: "module:function" of its run(scene, cfg, catalog) -> dict.
        needs: upstream stages (per scene).
        config: config sections that determine its output (their change recomputes it).
        version: bump when the stage's code changes its output (stored outputs of another
            version are recomputed; v2 of voxelize: the bound exact over the voxel height).
        only_synthetic: the stage applies to synthetic scenes only (others pass through).
        inputs: optional "module:function" of cfg -> JSON-able data the stage also reads from
            outside its config sections (hashed with them), e.g. embodiment files.
        finalize: optional "module:function" of (cfg, catalog) -> dict, run once after all scenes
            of the stage (dataset-level files); it must derive them from what is on disk, so that
            shards of one dataset agree.
    """

    name: str
    target: str
    needs: tuple[str, ...] = ()
    config: tuple[str, ...] = ()
    version: str = "1"
    only_synthetic: bool = False
    inputs: str | None = None
    finalize: str | None = None

    def function(self) -> Callable:
        return _load(self.target)


def _load(target: str) -> Callable:
    mod, fn = target.split(":")
    return getattr(importlib.import_module(mod), fn)


STAGES: tuple[Stage, ...] = (
    Stage("synthesize", "stages.synthetic.stage:run", (), ("synthetic",), only_synthetic=True),
    Stage("ingest", "stages.ingest:run", ("synthesize",), ("ingest",), version="2"),
    Stage("voxelize", "stages.voxelize.stage:run", ("ingest",), ("voxelize",), version="3"),
    Stage("align", "stages.align.stage:run", ("voxelize",), ("align",), version="3"),
    Stage("costmap", "stages.costmap.stage:run", ("align",), ("costmap", "voxelize", "embodiment"), version="3",
          inputs="stages.costmap.stage:hashed_inputs"),
    Stage("semantics", "stages.semantics.stage:run", ("costmap",), ("semantics", "embodiment")),
    Stage("asset", "stages.asset:run", ("costmap", "semantics"), ("asset",), version="3"),
    Stage("episodes", "stages.episodes.stage:run", ("costmap", "semantics"), ("episodes", "task", "planner", "embodiment")),
    Stage("goal_images", "stages.episodes.goal_images:run", ("episodes",), ("goal_images",)),
    Stage("export", "stages.episodes.export:run", ("episodes", "asset", "goal_images"), ("export",),
          finalize="stages.episodes.export:finalize"),
    Stage("evaluate", "stages.evaluate.stage:run", ("episodes",), ("evaluate", "episodes", "task", "embodiment"),
          finalize="stages.evaluate.stage:finalize"),
)
BY_NAME = {s.name: s for s in STAGES}


def closure(selected: list[str]) -> list[Stage]:
    """Selected stages plus everything upstream of them, in graph order."""
    unknown = [s for s in selected if s not in BY_NAME]
    if unknown:
        raise ValueError(f"unknown stage(s) {unknown}; stages are {[s.name for s in STAGES]}")
    need: set[str] = set()
    todo = list(selected)
    while todo:
        n = todo.pop()
        if n not in need:
            need.add(n)
            todo.extend(BY_NAME[n].needs)
    return [s for s in STAGES if s.name in need]


def config_hashes(cfg) -> dict[str, str]:
    """Hash per stage of its config sections, its version and its upstream hashes: a changed
    config recomputes that stage and everything downstream of it."""
    out: dict[str, str] = {}
    for s in STAGES:
        part = {k: OmegaConf.to_container(cfg[k], resolve=True) for k in s.config}
        if s.inputs:
            part["_inputs"] = _load(s.inputs)(cfg)
        blob = json.dumps({"stage": s.name, "version": s.version, "config": part,
                           "needs": [out[n] for n in s.needs]}, sort_keys=True, default=str)
        out[s.name] = hashlib.sha256(blob.encode()).hexdigest()[:16]
    return out
