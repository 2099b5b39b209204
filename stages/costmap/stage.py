"""Stage `costmap`: per embodiment, the costmap layers of the aligned scene -> 03_costmaps Zarr
(one group per embodiment: raw, support, occ, clearance, components; the support is computed
once and shared, as all embodiments use one grid)."""
from __future__ import annotations

import numpy as np
from omegaconf import OmegaConf

from navcore.gaussians.content import content_mask_of, content_of
from navcore.io.map_picture import topdown_picture
from navcore.nav.embodiment import load_embodiment
from stages.costmap.build import (
    CostmapConfig,
    build_costmap,
    doorway_gaps,
    hidden_splats,
    map_extent,
    obstacle_classes,
    scale_warnings,
    support_mask,
)


def embodiments(cfg) -> list:
    """The main embodiment, then costmap.embodiments (loaded from navcore/conf/embodiment)."""
    main = OmegaConf.to_object(cfg.embodiment)
    extra = [load_embodiment(n) for n in cfg.costmap.embodiments if n != main.name]
    return [main] + extra


ADDED_KEYS = (("costmap", "evidence", "voxel"), ("costmap", "cell_evidence", False), ("costmap", "cell_evidence_size", 0.1),
              ("costmap", "cell_evidence_share", 0.1), ("costmap", "cell_evidence_floor", 0.05),
              ("costmap", "outlier_density", 0.0), ("costmap", "footprint_max_sigma", 0.0),
              ("costmap", "surface_reach_sigmas", 0.0), ("costmap", "surface_band_sigmas", 2.0), ("costmap", "surface_min_reach", 0.01),
              ("costmap", "surface_reach_spacing", 0.0), ("costmap", "surface_flat_ratio", 0.0),
              ("costmap", "noise_dense_count", 0), ("costmap", "noise_dense_radius", 0.2))
"""Keys added after data roots were made with this stage: at their defaults they leave its hash
as it was (pipeline.graph.Stage.added)."""


def hashed_inputs(cfg) -> list[dict]:
    """the embodiment files: the embodiments this stage builds maps for, as read from
    navcore/conf/embodiment (part of its config hash: editing an embodiment file recomputes the
    costmaps)."""
    return [vars(e) for e in embodiments(cfg)]


def run(scene, cfg, catalog) -> dict:
    ccfg: CostmapConfig = OmegaConf.to_object(cfg.costmap)
    vcfg = OmegaConf.to_object(cfg.voxelize)
    full, _ = catalog.dataset("aligned", scene).load(view_dependent=False)  # geometry and opacity only
    content = content_mask_of(full)
    gs = content_of(full)  # floaters stay out of the maps
    extent = map_extent(gs, ccfg)
    support = support_mask(gs, *extent, ccfg, vcfg)
    cand, isolated, finfo = obstacle_classes(gs, ccfg)
    noise = ~content  # floaters and isolated splats, in the whole scene's order
    noise[np.nonzero(content)[0][isolated]] = True
    noise &= full.alphas >= ccfg.min_obstacle_alpha
    out = catalog.dataset("costmaps", scene)
    result = {"outputs": [str(out.path)], "embodiments": {}}
    with out.writing() as root:
        for emb in embodiments(cfg):
            layers, info = build_costmap(gs, emb, ccfg, vcfg, support=support, extent=extent, candidates=(cand, dict(finfo)))
            hidden = hidden_splats(full, noise, layers, emb, ccfg.hide_noise_sigma) if ccfg.hide_noise else None
            if hidden is not None:
                info["hidden_splats"] = int(len(hidden))
            g = out.write_layers(root, emb, layers, {"info": info}, hidden=hidden)
            if emb.name == cfg.embodiment.name:
                gaps = doorway_gaps(layers.clearance, layers.resolution)  # -1 where unsupported
                g.attrs["doorway_gaps_m"] = gaps
                main = layers
            result["embodiments"][emb.name] = {"free_area_m2": round(info["free_area_m2"], 2),
                                               "hidden_splats": info.get("hidden_splats"),
                                               "main_component_area_m2": round(info["main_component_area_m2"], 2),
                                               "free_components": info["free_components"]}
        root.attrs["main_embodiment"] = cfg.embodiment.name
        ceiling = catalog.dataset("alignment", scene).load().get("floor_to_ceiling_m")
        root.attrs["scale"] = result["scale"] = {"floor_to_ceiling_m": ceiling, "narrowest_gaps_m": gaps[:5]}
        warnings = scale_warnings(ceiling, gaps)
        if warnings:
            result["warnings"] = warnings
        if not np.asarray(support[0]).any():
            raise ValueError("the supported region is empty: no occupied structure found near the floor")
    # the picture to look at first, written here so that it never waits for the later stages (semantics)
    pic = catalog.dataset("costmap_picture", scene)
    pic.save(topdown_picture(main.raw, main.support, main.occ, main.components, main.resolution, cfg.embodiment.name))
    result["outputs"].append(str(pic.path))
    return result
