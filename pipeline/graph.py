"""The stage graph: what each stage needs and which config sections decide its output."""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Callable

from omegaconf import OmegaConf

from stages.align import stage as align
from stages.asset import stage as asset
from stages.costmap import stage as costmap
from stages.episodes import stage as episodes
from stages.evaluate import stage as evaluate
from stages.export import stage as export
from stages.goal_images import stage as goal_images
from stages.ingest import stage as ingest
from stages.screen import stage as screen
from stages.semantics import stage as semantics
from stages.synthesize import stage as synthesize
from stages.voxelize import stage as voxelize


@dataclass(frozen=True)
class Stage:
    """A pipeline stage keyed by scene.

    Attributes:
        name: stage name (config key `stages`, marker folder, and its package stages/<name>/).
        run: its run(scene, cfg, catalog) -> dict.
        needs: upstream stages (per scene).
        config: config sections that determine its output (their change recomputes it); a
            dotted name is a subsection (screen.layer).
        version: bump when the stage's code changes its output (stored outputs of another
            version are recomputed; v2 of voxelize: the bound exact over the voxel height).
        only_synthetic: the stage applies to synthetic scenes only (others pass through).
        inputs: optional function of cfg -> JSON-able data the stage also reads from outside its
            config sections (hashed with them), e.g. embodiment files; None when it reads nothing more.
        finalize: optional function of (cfg, catalog) -> dict, run once after all scenes of the
            stage (dataset-level files); it must derive them from what is on disk, so that shards
            of one dataset agree.
        default: part of the default run (`stages` of the config); evaluate is not.
        gpu: the stage uses a GPU when its worker has one (rendering, the CUDA voxelizer, SAM3);
            with GPU workers in the cluster it runs on them only, one task per GPU at a time.
        memory_gb: the stage's peak memory per scene at the default sizes (a Dask resource: a
            worker runs at most as many tasks at once as its memory holds).
        storage: (section, key, default) of config keys that decide only what this stage keeps
            on disk beside its outputs, never what a later stage reads (`config_hashes`).
        added: (section, key, default) of config keys added to the stage after data roots were made
            (key may be dotted, e.g. detector.models, for a key added inside a nested section)
            with it: left out of its hash while at their default, so that those roots stay valid
            (a value other than the default is hashed: the stage and what follows recompute).
        package: its package stages/<package>/ when it shares one with another stage (None: its name).
        part_of: selecting that stage (`stages=[episodes]`) selects this one too: one user-facing
            step the graph splits so that each half waits only for what it needs.
    """

    name: str
    run: Callable
    needs: tuple[str, ...] = ()
    config: tuple[str, ...] = ()
    version: str = "1"
    only_synthetic: bool = False
    inputs: Callable | None = None
    finalize: Callable | None = None
    default: bool = True
    gpu: bool = False
    memory_gb: float = 1.0
    storage: tuple[tuple[str, str, object], ...] = ()
    added: tuple[tuple[str, str, object], ...] = ()
    package: str | None = None
    part_of: str | None = None


STAGES: tuple[Stage, ...] = (
    Stage("synthesize", synthesize.run, (), ("synthetic",), only_synthetic=True),
    Stage("ingest", ingest.run, ("synthesize",), ("ingest",), version="3"),
    Stage("voxelize", voxelize.run, ("ingest",), ("voxelize",), version="3", gpu=True, memory_gb=3.0,
          storage=(("voxelize", "store_opacity", False),)),
    Stage("align", align.run, ("voxelize",), ("align",), version="5"),
    Stage("costmap", costmap.run, ("align",), ("costmap", "voxelize", "embodiment"), version="7",
          inputs=costmap.hashed_inputs, added=costmap.ADDED_KEYS),
    Stage("screen", screen.run, ("costmap",), ("screen.layer", "embodiment")),
    # PointNav and ImageNav episodes (and their goal images) before semantics, which can take an hour on a
    # large capture on a CPU: the graph's order is also the order a scene's tasks are started in
    Stage("episodes", episodes.run, ("costmap", "screen"), ("episodes", "planner", "embodiment", "screen"),
          version="10", inputs=episodes.hashed_inputs),  # 10: a point goal that cannot fill the bin whose turn it is gives way
    Stage("goal_images", goal_images.run, ("episodes",), ("goal_images",), gpu=True, memory_gb=2.0),
    Stage("semantics", semantics.run, ("costmap",), ("semantics", "embodiment"), version="3", gpu=True,
          memory_gb=3.0, added=semantics.ADDED_KEYS, inputs=semantics.hashed_inputs),
    Stage("asset", asset.run, ("costmap", "semantics"), ("asset",), version="4"),
    Stage("objectnav_episodes", episodes.run_objects, ("costmap", "semantics", "screen"),
          ("episodes", "planner", "embodiment", "screen"), version="9", inputs=episodes.hashed_object_inputs,
          package="episodes", part_of="episodes"),
    Stage("export", export.run, ("episodes", "objectnav_episodes", "asset", "goal_images"), ("export",),
          finalize=export.finalize),
    Stage("evaluate", evaluate.run, ("episodes", "objectnav_episodes"), ("evaluate", "episodes", "task", "embodiment"),
          version="2",  # 2: the random agent seeded per episode
          finalize=evaluate.finalize, default=False, gpu=True, memory_gb=2.0, inputs=evaluate.hashed_inputs),
)
DEFAULT_STAGES = [s.name for s in STAGES if s.default]
BY_NAME = {s.name: s for s in STAGES}


def selection(selected: list[str]) -> list[str]:
    """The stages a `stages=[...]` list names: each named one and those that are part of it."""
    unknown = [s for s in selected if s not in BY_NAME]
    if unknown:
        raise ValueError(f"unknown stage(s) {unknown}; stages are {[s.name for s in STAGES]}")
    return list(dict.fromkeys([*selected, *(s.name for s in STAGES if s.part_of in selected)]))


def closure(selected: list[str]) -> list[Stage]:
    """Selected stages (with the stages part of them) plus everything upstream of them, in graph order."""
    need: set[str] = set()
    todo = selection(selected)
    while todo:
        n = todo.pop()
        if n not in need:
            need.add(n)
            todo.extend(BY_NAME[n].needs)
    return [s for s in STAGES if s.name in need]


def downstream(name: str) -> set[str]:
    """A stage and every stage that (transitively) needs it."""
    out, grew = {name}, True
    while grew:
        grew = False
        for s in STAGES:
            if s.name not in out and any(n in out for n in s.needs):
                out.add(s.name)
                grew = True
    return out


SCENE_OPTIONS = {"labels": "semantics"}
"""Catalog entry keys that decide a stage's output for that scene alone -> the stage that reads them."""


def scene_hash(stage_hash: str, stage: str, scene) -> str:
    """A stage's hash for one scene: its config hash, mixed with the scene's own catalog options
    (`SCENE_OPTIONS`) when the stage is at or downstream of the one that reads them; a scene
    without options keeps the config hash (data roots written before stay valid)."""
    opts = {k: getattr(scene, k).as_dict() for k, st in sorted(SCENE_OPTIONS.items())
            if getattr(scene, k, None) is not None and stage in downstream(st)}
    if not opts:
        return stage_hash
    return hashlib.sha256(json.dumps({"hash": stage_hash, "scene": opts}, sort_keys=True, default=str).encode()).hexdigest()[:16]


def stage_config(cfg, name: str) -> dict:
    """What a stage's hash covers of the config: its sections (resolved; the storage keys of every
    stage left out) and what its `inputs` reads beyond them (key "_inputs"). Recorded in its
    markers, so that a later run can say which keys changed."""
    s = BY_NAME[name]
    storage = [st for x in STAGES for st in x.storage]
    part = {}
    for k in s.config:
        part[k] = OmegaConf.to_container(OmegaConf.select(cfg, k), resolve=True)
        for sec, key, _ in storage:
            if sec == k and isinstance(part[k], dict):
                part[k].pop(key, None)
        for sec, key, default in s.added:  # key may be dotted: a key added inside a nested section
            *inner, leaf = key.split(".")
            node = part[k] if sec == k else None
            for name_ in inner:
                node = node.get(name_) if isinstance(node, dict) else None
            if isinstance(node, dict) and leaf in node and node[leaf] == default:
                node.pop(leaf)
    if s.name == "semantics" and isinstance(part.get("semantics"), dict):
        # a segmenter's own settings decide nothing while another segmenter runs: a new detector default
        # leaves the oracle's data roots as they are
        sem = part["semantics"]
        for seg in ("detector", "sam3", "open_vocab"):
            if sem.get("segmenter") != seg and isinstance(sem.get(seg), dict):
                sem.pop(seg)
    if s.inputs and (extra := s.inputs(cfg)) is not None:  # None: nothing read beyond the sections
        part["_inputs"] = extra
    return part


def stage_storage(cfg, name: str) -> dict:
    """The values of a stage's storage keys (what it stores, not what it computes: `Stage.storage`)."""
    return {f"{sec}.{key}": OmegaConf.select(cfg, f"{sec}.{key}", default=default)
            for sec, key, default in BY_NAME[name].storage}


class StageHashes(dict):
    """Stage -> hash for generated scenes (the dict itself), and `captured`: the hashes for scenes
    read from files, whose chain leaves out the stages that apply to generated scenes only (a
    changed generator setting or default recomputes no real capture). `of(stage, scene)` is the
    hash a (stage, scene) task is keyed with."""

    def __init__(self, synthetic: dict[str, str], captured: dict[str, str]):
        super().__init__(synthetic)
        self.captured = captured

    def of(self, stage: str, scene) -> str:
        captured = not getattr(scene, "synthetic", True) and stage in self.captured  # a generated-only stage: n/a there
        return scene_hash((self.captured if captured else self)[stage], stage, scene)


def config_hashes(cfg) -> StageHashes:
    """Hash per stage of its config sections, its version and its upstream hashes: a changed
    config recomputes that stage and everything downstream of it. Two chains: the dict itself for
    generated scenes, `.captured` for scenes read from files (without the generated-only stages).

    A stage's storage keys (`Stage.storage`) are left out of every section before hashing, so
    that changing one recomputes no later stage (what they read is the same); the stage itself
    is recomputed, its hash mixing in the key's value, but only when the value is not the default:
    a data root written before the key existed stays valid."""
    # each stage's config once (its inputs may read files): both chains hash the same parts
    parts = {s.name: stage_config(cfg, s.name) for s in STAGES}
    return StageHashes(_chain(cfg, parts, synthetic=True), _chain(cfg, parts, synthetic=False))


def _chain(cfg, parts: dict[str, dict], synthetic: bool) -> dict[str, str]:
    chain: dict[str, str] = {}
    out: dict[str, str] = {}
    for s in STAGES:
        if s.only_synthetic and not synthetic:
            continue
        blob = json.dumps({"stage": s.name, "version": s.version, "config": parts[s.name],
                           "needs": [chain[n] for n in s.needs if n in chain]}, sort_keys=True, default=str)
        chain[s.name] = out[s.name] = hashlib.sha256(blob.encode()).hexdigest()[:16]
        kept = {f"{sec}.{key}": v for sec, key, default in s.storage
                if (v := OmegaConf.select(cfg, f"{sec}.{key}", default=default)) != default}
        if kept:
            blob = json.dumps({"content": chain[s.name], "storage": kept}, sort_keys=True, default=str)
            out[s.name] = hashlib.sha256(blob.encode()).hexdigest()[:16]
    return out
