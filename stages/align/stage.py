"""Stage `align`: floor plane from the occupied voxels -> rigid transform; apply it to the
Gaussians (positions and rotations). The voxel field in the aligned frame is re-evaluated from
the transformed Gaussians by the costmap stage (exact, unlike resampling the source grid)."""
from __future__ import annotations

import json

import numpy as np
from omegaconf import OmegaConf

from pipeline.atomic import atomic_path, write_text_atomic
from stages.align.floor import AlignConfig, fit_floor, floor_transform
from stages.gaussians.store import read_scene_zarr, write_scene_zarr
from stages.voxelize.stage import occupied_centers


def run(scene, cfg, catalog) -> dict:
    acfg: AlignConfig = OmegaConf.to_object(cfg.align)
    gs, attrs = read_scene_zarr(catalog.path("scene", scene))
    occ = occupied_centers(catalog.path("voxels", scene))
    n, d, info = fit_floor(occ, gs.means.astype(np.float64), gs.alphas, acfg)
    t = floor_transform(n, d)
    aligned = gs.transformed(t)
    out = catalog.path("aligned", scene)
    with atomic_path(out) as tmp:
        write_scene_zarr(tmp, aligned, {**attrs, "frame": "aligned", "source_to_aligned": t.tolist()})
    tilt = float(np.degrees(np.arccos(np.clip(abs(n[2]), -1, 1))))
    write_text_atomic(catalog.path("alignment", scene), json.dumps(
        {"source_to_aligned": t.tolist(), "floor_normal_source": list(map(float, n)), "floor_offset": d,
         "tilt_from_source_z_deg": tilt, "ransac": info}, indent=1))
    return {"outputs": [str(out)], "tilt_from_source_z_deg": tilt, "floor_candidates": len(info["candidates"])}
