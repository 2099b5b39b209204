"""Stage `ingest`: read a source scene in any supported format, validate it, store it canonically
(Zarr: a reference to the source or a copy, ingest.store) with a report of what was dropped and
why."""
from __future__ import annotations

import dataclasses

from omegaconf import OmegaConf

from navcore.gaussians.content import CONTENT_KEY, content_mask
from navcore.gaussians.validate import read_validated


def source_path(scene, catalog):
    """Where a scene's source file is (synthetic scenes: the synthesize stage's output)."""
    if scene.synthetic:
        return catalog.dataset("source_synthetic", scene).source_file, "inria_ply"
    return scene.path, scene.format


def run(scene, cfg, catalog) -> dict:
    path, fmt = source_path(scene, catalog)
    icfg = OmegaConf.to_object(cfg.ingest)
    if icfg.store not in ("auto", "reference", "copy"):
        raise ValueError(f"ingest.store must be auto, reference or copy, not {icfg.store!r}")
    clean, report = read_validated(path, fmt, scene.scene_id, icfg.lod_level, icfg.scale, icfg.limits)
    # floaters stay in the renderable model; the mask keeps them out of grids and maps
    mask, content = content_mask(clean.means, icfg.content)
    clean.extras[CONTENT_KEY] = mask
    out = catalog.dataset("scene", scene)
    ref = icfg.store in ("reference", "auto")
    source = {"path": str(path), "format": fmt, "level": icfg.lod_level, "scale": icfg.scale,
              "limits": dataclasses.asdict(icfg.limits)} if ref else None
    out.save(clean, {"scene_id": scene.scene_id, "source": str(path), "format": fmt}, source)
    rep = {"scene_id": scene.scene_id, "name": scene.name, "group": scene.group, "source": str(path),
           "format": fmt, "scale": icfg.scale, "validation": report.as_dict(), "content": content}
    catalog.dataset("ingest_report", scene).save(rep)
    return {"outputs": [str(out.path)], "validation": report.summary(), **report.as_dict(), "floaters": content["floaters"],
            "content_box_m": content["content_box_m"]}
