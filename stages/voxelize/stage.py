"""Stage `voxelize`: opacity field of the ingested (source-frame) scene -> 02_voxels Zarr
(A uint8: opacity in 1/255 steps, unless voxelize.store_opacity=false; V bool, grid origin and voxel
size) over the content's box (floaters are left out).
Written x-block by x-block: memory stays bounded."""
from __future__ import annotations

import numpy as np
from omegaconf import OmegaConf

from navcore.gaussians.content import content_of
from navcore.io.codecs import array_codecs, slab_shards
from navcore.voxels.field import VoxelizeConfig, log_transmittance_blocks
from navcore.voxels.grid import grid_for_points


def run(scene, cfg, catalog) -> dict:
    vcfg: VoxelizeConfig = OmegaConf.to_object(cfg.voxelize)
    gs, _ = catalog.dataset("scene", scene).load()
    gs = content_of(gs)  # floaters neither size the grid nor fill it
    grid = grid_for_points(gs.means, vcfg.resolution, margin=2 * vcfg.resolution)
    out = catalog.dataset("voxels", scene)
    n_occ = 0
    with out.writing() as g:
        chunks = (32, 64, 64)
        # opacity in 1/255 steps (as the 8-bit alpha of images): half the bytes of float16 and fine
        # enough to re-threshold; V is thresholded on the exact values. No stage reads A, so stores
        # written before (float16, no A_scale attribute) stay valid: the stage version is unchanged
        shards = slab_shards(grid.shape, chunks)  # one file per x-slab (navcore.io.codecs)
        a_arr = (g.create_array("A", shape=grid.shape, dtype="uint8", chunks=chunks, shards=shards, fill_value=0,
                                **array_codecs("uint8")) if vcfg.store_opacity else None)
        v_arr = g.create_array("V", shape=grid.shape, dtype="bool", chunks=chunks, shards=shards, fill_value=False,
                               **array_codecs("bool"))
        for x0, blk in log_transmittance_blocks(gs, grid, vcfg):
            a = -np.expm1(blk)
            if a_arr is not None:
                a_arr[x0:x0 + len(blk)] = np.rint(a * 255.0).astype(np.uint8)
            occ = a >= vcfg.tau_occ
            v_arr[x0:x0 + len(blk)] = occ
            n_occ += int(occ.sum())
        scale = {"A_scale": 1.0 / 255.0} if a_arr is not None else {}  # in the order of stores written before
        g.attrs.update({**grid.as_dict(), **scale, "tau_occ": vcfg.tau_occ, "sample": vcfg.sample, "frame": "source"})
    content_voxels = int(np.prod(np.ceil((gs.means.max(0) - gs.means.min(0)) / vcfg.resolution)))
    return {"outputs": [str(out.path)], "grid_shape": list(grid.shape), "grid_voxels": grid.n_voxels,
            "content_voxels": content_voxels, "occupied_voxels": n_occ}

