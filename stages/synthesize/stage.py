"""Stage `synthesize`: generate a procedural scene's source file and ground truth."""
from __future__ import annotations

import dataclasses

from omegaconf import OmegaConf

from stages.synthesize.generate import SyntheticConfig, generate_scene, write_synthetic


def run(scene, cfg, catalog) -> dict:
    syn: SyntheticConfig = OmegaConf.to_object(cfg.synthetic)
    if scene.num_gaussians:
        syn = dataclasses.replace(syn, num_gaussians=int(scene.num_gaussians))
    s = generate_scene(int(scene.seed), syn)
    out = catalog.dataset("source_synthetic", scene)
    with out.writing() as tmp:
        write_synthetic(tmp, s, scene.name)
    return {"outputs": [str(out.source_file)], "n_gaussians": len(s.gaussians), "rooms": len(s.layout.rooms),
            "objects": len(s.layout.objects)}
