"""Stage `semantics`: ObjectNav goal candidates lifted from multi-view open-vocabulary masks.

Per scene: covering cameras (the source's capture cameras, or poses on free costmap cells at the
embodiment's camera height looking all around), RGB-D rendered there with the scene renderer,
per-category masks from the configured segmenter (registry key: oracle | detector | open_vocab | sam3),
the paper's lifting
(lifting.py) -> the instance table data/04_semantics/{scene_id}/instances.parquet (INSTANCE_SCHEMA,
source "model_predicted"), which the episodes stage's ObjectNav and the asset's labels.json read.
"""
from __future__ import annotations

import time
from dataclasses import asdict, replace

import numpy as np

from navcore.gaussians.cameras import CAMERA_FILE, camera_file, read_cameras
from navcore.instances import labels_to_table, shipped_instances
from navcore.io.progress_log import ProgressLog
from navcore.render.camera import camera_to_world, intrinsics
from stages.semantics.config import CoverageConfig, SemanticsConfig
from stages.semantics.lifting import lift
from stages.semantics.poses import coverage_poses, free_space_poses, surface_targets
from stages.semantics.segmenters import SEGMENTERS, SegmenterUnavailable

ADDED_KEYS = (("semantics", "view_selection", "grid"), ("semantics", "coverage", asdict(CoverageConfig())),
              ("semantics", "detector.models", {}), ("semantics", "lifting.confusable", None),
              ("semantics", "lifting.confusable_overlap", 0.3))
"""Keys added after data roots were made with this stage: at their defaults they leave its hash
as it was (pipeline.graph.Stage.added)."""

def hashed_inputs(cfg) -> dict | None:
    """What the semantics stage reads beyond its config: with the detector segmenter, the models,
    thresholds and allow-list it resolves to (navcore/models/detector.json and the models'
    thresholds.json, re-chosen by a benchmark), and each model's sha256, so that a re-chosen default
    recomputes the scenes it labelled; None for the other segmenters."""
    from omegaconf import OmegaConf

    if OmegaConf.select(cfg, "semantics.segmenter") != "detector":
        return None
    from dataclasses import asdict as _asdict

    from navcore.io.models import SHIPPED
    from stages.semantics.detector import resolved

    try:
        d = resolved(OmegaConf.to_object(cfg.semantics.detector))
    except (OSError, ValueError) as e:  # a missing or bad model: the stage's own task fails with it, not the run
        return {"detector_unresolved": f"{type(e).__name__}: {e}"}
    models = sorted({str(d.model), *map(str, d.models.values())})
    return {"detector": {k: v for k, v in _asdict(d).items() if k in ("model", "models", "confidence", "categories")},
            "sha256": {m: SHIPPED[m].files[SHIPPED[m].network] for m in models if m in SHIPPED}}


def spread(n: int, k: int) -> np.ndarray:
    """Indices of k of n items spread evenly (all when k is 0 or >= n)."""
    if k <= 0 or k >= n:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, k).round().astype(int))


def covering_cameras(scene, catalog, scfg: SemanticsConfig, emb, to_aligned: np.ndarray, costmap=None, gs=None,
                     report: dict | None = None):
    """(camera -> world [M, 4, 4] in the aligned frame, Ks [M, 3, 3], "source" | "free_space" |
    "free_space_coverage"). With the aligned Gaussians `gs` and view_selection=coverage, the
    free-space lattice is thinned to the views that cover the scene's surfaces (its figures into
    `report`)."""
    if scfg.view_selection == "coverage" and scfg.poses != "source" and scfg.coverage.k < scfg.lifting.min_support:
        raise ValueError(f"scene {scene.scene_id!r} ({scene.name}): semantics.coverage.k={scfg.coverage.k} is under "
                         f"semantics.lifting.min_support={scfg.lifting.min_support}: a surface seen k times cannot "
                         f"gather the votes the lifting needs; raise k")
    cams = camera_file(scene, catalog) if scfg.poses in ("auto", "source") else None
    if scfg.poses == "source" and cams is None:
        raise FileNotFoundError(f"scene {scene.scene_id!r} ({scene.name}): semantics.poses=source but the scene has "
                                f"no {CAMERA_FILE}; use poses=auto or free_space")
    if scfg.poses not in ("auto", "source", "free_space"):
        raise ValueError(f"semantics.poses={scfg.poses!r}; choose auto | source | free_space")
    if cams is not None:
        c2w, ks = read_cameras(cams, scfg.width, scfg.height)
        c2w, kind = to_aligned @ c2w, "source"
    else:
        valid = ~costmap.occupancy & (costmap.clearance >= 0)
        spacing, yaw_step, height, pitch = scfg.spacing, scfg.yaw_step_deg, emb.camera_height, emb.camera_pitch_deg
        if scfg.segmenter == "detector":
            d = scfg.detector
            spacing, yaw_step = d.spacing, d.yaw_step_deg
            height = height if d.camera_height is None else d.camera_height
            pitch = pitch if d.camera_pitch_deg is None else d.camera_pitch_deg
        poses, kind = free_space_poses(costmap, valid, spacing, yaw_step), "free_space"
        if scfg.view_selection not in ("coverage", "grid"):
            raise ValueError(f"semantics.view_selection={scfg.view_selection!r}; choose coverage | grid")
        if scfg.view_selection == "coverage" and gs is not None and len(poses):
            cov = scfg.coverage
            targets = surface_targets(gs.means, gs.alphas, cov.cell, cov.z_min, cov.z_max)
            poses, rep = coverage_poses(poses, targets, height, pitch, emb.hfov_deg, cov.k, cov.sectors, cov.max_range,
                                        cov.cell, cov.min_gain)
            kind = "free_space_coverage"
            if report is not None:
                report.update(rep)
        c2w = np.stack([camera_to_world(x, y, yaw, height, pitch) for x, y, yaw in poses]) \
            if len(poses) else np.zeros((0, 4, 4))
        ks = np.repeat(intrinsics(scfg.width, scfg.height, emb.hfov_deg)[None], len(c2w), 0)
    keep = spread(len(c2w), scfg.max_views)
    return c2w[keep], ks[keep], kind


def render_views(renderer, c2w: np.ndarray, Ks: np.ndarray, scfg: SemanticsConfig, features=None):
    """Yields per batch of `batch` views: (rgb uint8 [B, H, W, 3], depth [B, H, W] (0 where the
    accumulated opacity is under min_alpha), composited `features` [B, H, W, C] or B Nones,
    viewmats [B, 4, 4], Ks [B, 3, 3], camera -> world [B, 4, 4]), all numpy."""
    import torch

    for s in range(0, len(c2w), scfg.batch):
        vm = np.linalg.inv(c2w[s:s + scfg.batch]).astype(np.float32)
        ks = Ks[s:s + scfg.batch]
        out = renderer.render(vm, ks, scfg.width, scfg.height, extra=features)
        rgb = (out.rgb * 255 + 0.5).to(torch.uint8).cpu().numpy()
        depth = torch.where(out.alpha >= scfg.min_alpha, out.depth, 0.0).cpu().numpy()
        extra = out.extra.cpu().numpy() if out.extra is not None else [None] * len(vm)
        yield rgb, depth, extra, vm, ks, c2w[s:s + scfg.batch]


def scene_frames(renderer, segmenter, c2w: np.ndarray, Ks: np.ndarray, scfg: SemanticsConfig, timings: dict,
                 on_batch=None):
    """Yields (depth [H, W], K, camera -> world, {category index: [masks]}) per view: views rendered
    `batch` at a time (RGB-D, plus the segmenter's per-Gaussian features in the same pass),
    segmented by batch; seconds spent go to timings["render"] / ["segment"]; on_batch(n) after
    each batch of n views (the progress log)."""
    prompts = [scfg.prompt(c) for c in scfg.categories]
    views = render_views(renderer, c2w, Ks, scfg, segmenter.gaussian_features)
    while True:
        t0 = time.perf_counter()
        batch = next(views, None)
        if batch is None:
            return
        rgb, depth, extra, vm, ks, cw = batch
        t1 = time.perf_counter()
        segs = segmenter.segment_batch(rgb, prompts, [{"viewmat": v, "K": k, "extra": e, "depth": d, "cam_to_world": c}
                                                      for v, k, e, d, c in zip(vm, ks, extra, depth, cw)])
        timings["render"] = timings.get("render", 0.0) + t1 - t0
        timings["segment"] = timings.get("segment", 0.0) + time.perf_counter() - t1
        if on_batch is not None:
            on_batch(len(segs))
        for i, seg in enumerate(segs):
            yield depth[i], ks[i], cw[i], category_masks(seg, prompts)


def category_masks(seg: dict, prompts: list[str]) -> dict[int, list[np.ndarray]]:
    """A segmenter's {prompt: [(mask, score)]} -> {category index: [masks]} (categories with none left out)."""
    out = {c: [m for m, _ in seg.get(p, [])] for c, p in enumerate(prompts)}
    return {c: m for c, m in out.items() if m}


def lifting_config(scfg: SemanticsConfig):
    """The lifting of this segmenter: the detector's instances need detector.min_views views and
    a top above detector.min_top_m, and its confusable categories are merged by a class vote."""
    if scfg.segmenter == "detector":
        index = {c: k for k, c in enumerate(scfg.categories)}
        groups = [[index[c] for c in g if c in index] for g in scfg.detector.confusable]
        return replace(scfg.lifting, min_views=max(scfg.lifting.min_views, scfg.detector.min_views),
                       min_top_m=max(scfg.lifting.min_top_m, scfg.detector.min_top_m),
                       confusable=scfg.lifting.confusable or [g for g in groups if len(g) > 1] or None)
    return scfg.lifting


def predict_instances(renderer, segmenter, c2w, Ks, means: np.ndarray, scfg: SemanticsConfig, on_batch=None):
    """Instance candidates of one scene: (labels.json entries with source model_predicted and ids
    1..n in (category, -support) order, their support, timings {render, segment, lift, total} s);
    on_batch(n) after each batch of n views is segmented."""
    timings: dict = {}
    t0 = time.perf_counter()
    cands = lift(scene_frames(renderer, segmenter, c2w, Ks, scfg, timings, on_batch), means, lifting_config(scfg))
    total = time.perf_counter() - t0
    timings["lift"] = total - timings.get("render", 0.0) - timings.get("segment", 0.0)
    timings["total"] = total
    cands.sort(key=lambda c: (c["label"], -c["support"], tuple(np.round(c["center"], 6))))
    labels, support = [], {}
    for i, c in enumerate(cands, 1):
        labels.append({"instance_id": i, "category": scfg.categories[c["label"]],
                       "position": [float(v) for v in c["center"]],
                       "bounding_box": {"min": [float(v) for v in c["min"]], "max": [float(v) for v in c["max"]]},
                       "confidence": round(float(c["confidence"]), 6), "source": "model_predicted",
                       "views": int(c["views"]), "agreement": round(float(c["agreement"]), 6)})
        support[i] = c["support"]
    return labels, support, timings


SLOW_VIEWS_PER_S = {"detector": 2.5, "open_vocab": 0.5}
"""Views a second a segmenter was seen to do on a 2-core CPU (the detector on a 747 k-Gaussian apartment:
issue 86), for the estimate said before a long semantics task starts."""


def long_run_hint(scene, views: int, scfg, threshold: int = 500) -> str:
    """The line the run's console prints before a scene's semantics starts when it has many views:
    how many, about how long on a CPU, and the overrides that cut them ('' for a short task)."""
    rate = SLOW_VIEWS_PER_S.get(scfg.segmenter)
    if views < threshold or rate is None:
        return ""
    faster = ("semantics.view_selection=coverage (10-100x fewer views, docs/own-capture.md) or "
              if scfg.view_selection != "coverage" else "")
    return (f"semantics {scene.name}: {views:,} views for the {scfg.segmenter} segmenter, about "
            f"{views / rate / 60:.0f} min on a 2-core CPU ({rate:g} views/s; a GPU is far faster); to cut them: "
            f"{faster}semantics.max_views=N")


def run(scene, cfg, catalog) -> dict:
    from omegaconf import OmegaConf

    from navcore.render import Renderer
    from navcore.seeds import stream_seed

    scfg: SemanticsConfig = OmegaConf.to_object(cfg.semantics)
    out = catalog.dataset("instances", scene)
    if not scfg.enabled:
        out.delete()
        return {"outputs": [], "enabled": False}
    emb = OmegaConf.to_object(cfg.embodiment)
    gs, attrs = catalog.dataset("aligned", scene).load()
    cm = catalog.dataset("costmaps", scene).load(emb.name)
    shipped = None
    if scfg.shipped_labels:
        align = catalog.dataset("alignment", scene).load()
        shipped = shipped_instances(scene, gs, np.asarray(attrs["source_to_aligned"]), scfg.vocabulary(scene), scfg.labels,
                                    align.get("floor_to_ceiling_m"))
    if shipped is not None:  # the dataset's own truth beats any model
        table, origin, report = shipped
        out.save(table)
        cats = table.column("category").to_pylist()
        return {"outputs": [str(out.path)], "instances": len(cats), "labels_from": origin, "source": "ground_truth",
                "by_category": {c: cats.count(c) for c in sorted(set(cats))}, "labels": report.as_dict(),
                "goal_mapping": report.goal_mapping, **({"warnings": report.warnings} if report.warnings else {})}
    coverage: dict = {}
    t_views = time.perf_counter()
    c2w, ks, kind = covering_cameras(scene, catalog, scfg, emb, np.asarray(attrs["source_to_aligned"]), cm, gs, coverage)
    view_seconds = time.perf_counter() - t_views
    if not len(c2w):
        raise ValueError(f"scene {scene.scene_id!r} ({scene.name}): no covering poses (no free costmap cells)")
    renderer = Renderer(gs, scfg.renderer)
    seed = stream_seed(scfg.seed, scene.scene_id, "semantics")
    try:
        seg = SEGMENTERS.get_class(scfg.segmenter).from_scene(scene, catalog, renderer, scfg, seed)
    except SegmenterUnavailable as e:  # an empty table: the scene's other tasks go on, the summary says why
        out.save(labels_to_table([]))
        res = {"outputs": [str(out.path)], "instances": 0, "segmenter": scfg.segmenter, "unavailable": str(e)}
        objectnav = (cfg.get("task") or {}).get("objectnav")
        if objectnav is not None:  # a shortfall only where ObjectNav episodes were asked for
            res["shortfall"] = [{"task": "objectnav", "episodes": 0, "requested": objectnav.get("episodes_per_scene"),
                                 "reason": f"no goal instances: {e}"}]
        return res
    # views done / total while it runs, for the run's console (pipeline/episode_progress.py): the detector
    # on a large capture's thousands of views runs for many minutes on a CPU
    log = ProgressLog(catalog.dataset("semantics_progress", scene).path)
    log.start(len(c2w), scene=scene.name, scene_id=scene.scene_id, segmenter=scfg.segmenter,
              hint=long_run_hint(scene, len(c2w), scfg))
    labels, support, timings = predict_instances(renderer, seg, c2w, ks, gs.means, scfg,
                                                 on_batch=lambda n: log.item(views=n))
    table = labels_to_table(labels, support)
    out.save(table)
    counts: dict = {}
    for lab in labels:
        counts[lab["category"]] = counts.get(lab["category"], 0) + 1
    return {"outputs": [str(out.path)], "views": len(c2w), "poses": kind, "renderer": renderer.backend,
            "segmenter": scfg.segmenter, "instances": len(labels), "by_category": dict(sorted(counts.items())),
            **({"coverage": coverage} if coverage else {}),
            "seconds": {"view_selection": round(view_seconds, 3), **{k: round(v, 3) for k, v in timings.items()}}}
