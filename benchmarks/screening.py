"""The reconstruction-quality layer (stages/costmap/quality.py) against injected defects:
realistic synthetic scenes with blurred and hole regions (synthetic.realism blur_regions /
hole_regions), the layer's recall and precision per kind (cells inside the supported map), and
the real scenes' flagged share with a top-down picture (kept under data/08_reports/screening/,
not committed).
  python -m benchmarks.screening [--seeds 200,201,202] [--level moderate] [--real-data data]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from navcore.io import jsonio


def synthetic(seed: int, level: str, n: int, regions: int, radius: float) -> dict:
    from benchmarks.spatial import align_synthetic
    from navcore.voxels.field import VoxelizeConfig
    from stages.costmap.build import CostmapConfig, map_extent, support_mask
    from stages.costmap.quality import QualityConfig, quality_layers, validate
    from stages.synthesize.generate import SyntheticConfig, generate_scene
    from stages.synthesize.realism import RealismConfig

    sc = generate_scene(seed, SyntheticConfig(num_gaussians=n, realism=RealismConfig(
        level=level, blur_regions=regions, hole_regions=regions, defect_radius_m=radius)))
    _, t, _, aligned = align_synthetic(sc)
    ccfg = CostmapConfig()
    origin, shape = map_extent(aligned, ccfg)
    support, _ = support_mask(aligned, origin, shape, ccfg, VoxelizeConfig())
    layers = quality_layers(aligned, origin, shape, ccfg.resolution, QualityConfig())
    can_to_al = t @ sc.transform  # the regions' centres, canonical -> aligned
    regs = [r | {"center": (can_to_al[:3, :3] @ [*r["center"], 0.0] + can_to_al[:3, 3])[:2].tolist()}
            for r in sc.defects]
    all_cells = np.ones(shape, bool)  # holes: wherever they are (their inside is unsupported)
    out = {"seed": seed}
    for kind in ("blur", "hole"):
        out[kind] = validate(layers[kind], origin, ccfg.resolution, [r for r in regs if r["kind"] == kind],
                             support if kind == "blur" else all_cells)
    out["flagged"] = validate(layers["flagged"], origin, ccfg.resolution, regs, support | layers["hole"])
    return out


def real(data: str, folder: Path) -> list[dict]:
    from omegaconf import OmegaConf
    from PIL import Image

    from benchmarks.real import compose
    from navcore.gaussians.content import content_of
    from navcore.io.catalog import Catalog
    from pipeline.config import CONF_DIR
    from stages.costmap.quality import QualityConfig, quality_layers

    cfg = compose(data)
    catalog = Catalog(CONF_DIR.parent / cfg.scenes.catalog, data)
    emb = OmegaConf.to_object(cfg.embodiment)
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for scene in catalog.select():
        gs = content_of(catalog.dataset("aligned", scene).load()[0])
        layers, eattrs, _ = catalog.dataset("costmaps", scene).load_layers(emb.name)
        sup, occ = np.asarray(layers["support"]), np.asarray(layers["occ"])
        q = quality_layers(gs, eattrs["origin"], sup.shape, float(eattrs["resolution"]), QualityConfig())
        free = sup & ~occ
        img = np.full(sup.shape + (3,), 255, np.uint8)
        img[~sup] = (230, 190, 190)
        img[occ & sup] = (60, 60, 60)
        img[q["hole"] & free] = (80, 120, 255)
        img[q["blur"] & free] = (255, 0, 255)
        name = f"{scene.name}_quality_topdown.png"
        Image.fromarray(img[::-1]).save(folder / name)
        rows.append({"scene": scene.name, "free_cells": int(free.sum()),
                     "blur_share_of_free": float((q["blur"] & free).sum() / max(free.sum(), 1)),
                     "hole_share_of_free": float((q["hole"] & free).sum() / max(free.sum(), 1)), "picture": name})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="200,201,202")
    ap.add_argument("--level", default="moderate")
    ap.add_argument("--gaussians", type=int, default=300_000)
    ap.add_argument("--regions", type=int, default=2, help="blurred and hole regions each, per scene")
    ap.add_argument("--radius", type=float, default=0.7)
    ap.add_argument("--real-data", default=None, help="a data root with the real scenes' costmaps")
    ap.add_argument("--out", default="data/08_reports")
    args = ap.parse_args(argv)
    rows = []
    for s in (int(x) for x in args.seeds.split(",")):
        rows.append(synthetic(s, args.level, args.gaussians, args.regions, args.radius))
        print(json.dumps(rows[-1]), flush=True)
    rep = {"synthetic": rows, **{f"{k}_{m}_min": min(r[k][m] for r in rows) for k in ("blur", "hole", "flagged")
                                 for m in ("recall", "precision")}}
    if args.real_data:
        rep["real"] = real(args.real_data, Path(args.out) / "screening")
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "screening.json").write_text(jsonio.dumps(rep, indent=1))
    print(json.dumps({k: v for k, v in rep.items() if k.endswith("_min")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
