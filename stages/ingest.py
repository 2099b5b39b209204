"""Stage `ingest`: read a source scene in any supported format, validate it, store it canonically
(Zarr) with a report of what was dropped and why."""
from __future__ import annotations

import json

import numpy as np

from omegaconf import OmegaConf

from pipeline.atomic import atomic_path, write_text_atomic
from stages.gaussians.content import CONTENT_KEY, content_mask
from stages.gaussians.errors import SceneFormatError
from stages.gaussians.formats import read_gaussians
from stages.gaussians.store import write_scene_zarr
from stages.gaussians.validate import sanitize
from stages.synthetic.generate import SOURCE_FILE


def source_path(scene, catalog):
    """Where a scene's source file is (synthetic scenes: the synthesize stage's output)."""
    if scene.synthetic:
        return catalog.path("source_synthetic", scene) / SOURCE_FILE, "inria_ply"
    return scene.path, scene.format


def run(scene, cfg, catalog) -> dict:
    path, fmt = source_path(scene, catalog)
    try:
        raw = read_gaussians(path, fmt, level=cfg.ingest.lod_level)
    except SceneFormatError as e:
        raise SceneFormatError(e.path, e.problem, scene.scene_id) from None
    icfg = OmegaConf.to_object(cfg.ingest)
    limits = icfg.limits
    if icfg.scale != 1.0:  # the source's units -> metres
        if not icfg.scale > 0:
            raise ValueError(f"ingest.scale={icfg.scale} must be positive")
        raw.means *= icfg.scale
        raw.log_scales += np.float32(np.log(icfg.scale))
    clean, report = sanitize(raw, path, scene.scene_id, limits)
    # floaters stay in the renderable model; the mask keeps them out of grids and maps
    mask, content = content_mask(clean.means, icfg.content)
    clean.extras[CONTENT_KEY] = mask
    out = catalog.path("scene", scene)
    with atomic_path(out) as tmp:
        write_scene_zarr(tmp, clean, {"scene_id": scene.scene_id, "source": str(path), "format": fmt})
    rep = {"scene_id": scene.scene_id, "name": scene.name, "group": scene.group, "source": str(path),
           "format": fmt, "scale": icfg.scale, "validation": report.as_dict(), "content": content}
    write_text_atomic(catalog.path("ingest_report", scene), json.dumps(rep, indent=1))
    return {"outputs": [str(out)], "validation": report.summary(), **report.as_dict(), "floaters": content["floaters"],
            "content_box_m": content["content_box_m"]}
