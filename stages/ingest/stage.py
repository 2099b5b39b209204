"""Stage `ingest`: read a source scene in any supported format, validate it, store it canonically
(Zarr) with a report of what was dropped and why."""
from __future__ import annotations

import numpy as np
from omegaconf import OmegaConf

from navcore.gaussians.content import CONTENT_KEY, content_mask
from navcore.gaussians.errors import SceneFormatError
from navcore.gaussians.formats import read_gaussians
from navcore.gaussians.validate import sanitize


def source_path(scene, catalog):
    """Where a scene's source file is (synthetic scenes: the synthesize stage's output)."""
    if scene.synthetic:
        return catalog.dataset("source_synthetic", scene).source_file, "inria_ply"
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
    out = catalog.dataset("scene", scene)
    out.save(clean, {"scene_id": scene.scene_id, "source": str(path), "format": fmt})
    rep = {"scene_id": scene.scene_id, "name": scene.name, "group": scene.group, "source": str(path),
           "format": fmt, "scale": icfg.scale, "validation": report.as_dict(), "content": content}
    catalog.dataset("ingest_report", scene).save(rep)
    return {"outputs": [str(out.path)], "validation": report.summary(), **report.as_dict(), "floaters": content["floaters"],
            "content_box_m": content["content_box_m"]}
