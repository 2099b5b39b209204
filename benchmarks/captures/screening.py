"""The reconstruction-quality layer (stages/screen/quality.py, every cue as the stage computes it) against injected defects:
realistic synthetic scenes with blurred and hole regions (synthetic.realism blur_regions /
hole_regions), the layer's recall and precision per kind (cells inside the supported map), and
the real scenes' flagged share with a top-down picture (kept under data/08_reports/screening/,
not committed).
  python -m benchmarks.captures.screening [--seeds 200,201,202] [--level moderate] [--real-data data] [--docs]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

from benchmarks.pages import write_page
from navcore.io import jsonio


def synthetic(seed: int, level: str, n: int, regions: int, radius: float, **layer) -> dict:
    """One realistic synthetic scene with injected blurred and hole regions through content ->
    align -> costmap -> the quality layer (every cue, as the stage computes it): recall and
    precision per kind against the injected regions. layer: QualityConfig overrides."""
    from benchmarks.map.spatial import align_synthetic
    from navcore.gaussians.cameras import cameras_from_json
    from navcore.nav.costmap import Costmap
    from navcore.nav.embodiment import Embodiment
    from navcore.voxels.field import VoxelizeConfig
    from stages.costmap.build import CostmapConfig, build_costmap
    from stages.screen.quality import QualityConfig, screen_layers, validate
    from stages.synthesize.generate import SyntheticConfig, generate_scene
    from stages.synthesize.realism import RealismConfig

    sc = generate_scene(seed, SyntheticConfig(num_gaussians=n, realism=RealismConfig(
        level=level, blur_regions=regions, hole_regions=regions, defect_radius_m=radius)))
    _, t, renderable, aligned = align_synthetic(sc)
    emb = Embodiment()
    lay, _ = build_costmap(aligned, emb, CostmapConfig(), VoxelizeConfig())
    cm = Costmap(lay.clearance, lay.origin, lay.resolution, lay.radius, lay.margin, lay.components)
    valid = ~cm.occupancy & lay.support
    c2w, ks = cameras_from_json({"hfov_deg": 90.0, "poses": sc.cameras}, 64, 48)  # the capture path
    q = screen_layers(aligned, renderable, valid, lay.origin, lay.resolution, emb, QualityConfig(**layer),
                      (t @ c2w, ks, 64, 48))
    can_to_al = t @ sc.transform  # the regions' centres, canonical -> aligned
    regs = [r | {"center": (can_to_al[:3, :3] @ [*r["center"], 0.0] + can_to_al[:3, 3])[:2].tolist()}
            for r in sc.defects]
    all_cells = np.ones(valid.shape, bool)  # holes: wherever they are (their inside is unsupported)
    out = {"seed": seed, "views_rendered": q["views"]}
    blur = q["blur"] | q["view_blur"]
    for kind, layer in (("blur", blur), ("hole", q["hole"])):
        out[kind] = validate(layer, lay.origin, lay.resolution, [r for r in regs if r["kind"] == kind],
                             lay.support if kind == "blur" else all_cells)
    defects = blur | q["hole"] | q["view_hole"]  # the cues of injectable defects; unseen is reported beside
    out["flagged"] = validate(defects, lay.origin, lay.resolution, regs, lay.support | q["hole"])
    out["flagged_share_of_valid"] = float((q["flagged"] & valid).sum() / max(valid.sum(), 1))
    out["unseen_share_of_valid"] = float((q["unseen"] & valid).sum() / max(valid.sum(), 1))
    return out


def sharpness(scene, emb, poses: np.ndarray) -> np.ndarray:
    """[P] share of a 160 x 120 view's 20 x 20 patches whose Laplacian (grey, 0..1) has a standard
    deviation below 0.01: image sharpness, independent of the layer's cues."""
    from scipy import ndimage

    from navcore.render import cpu_fast
    from navcore.render.camera import embodiment_camera

    g = cpu_fast.prepare(scene)
    vm, K, w, h = embodiment_camera(emb, poses, 160, 120)
    out = np.zeros(len(poses))
    for p in range(len(poses)):
        rgb, _, _ = cpu_fast.render_one(g, vm[p], K[p], w, h, 0)
        lap = ndimage.laplace(rgb.mean(2).astype(np.float64))
        out[p] = float((lap.reshape(6, 20, 8, 20).std(axis=(1, 3)) < 0.01).mean())
    return out


def real(data: str, folder: Path, poses: int = 200) -> list[dict]:
    """The stage's layer on each scene of a data root (run `python -m pipeline stages=[screen]
    scenes=real_indoor data_root=DATA` first): score, shares, the picture (copied to folder), and
    the cross-check with image sharpness: views from random valid poses (random headings), the
    share of blurry patches of those in flagged cells against those in clean cells."""
    import shutil

    from omegaconf import OmegaConf

    from benchmarks.captures.real import compose
    from navcore.gaussians.content import camera_scene
    from navcore.io.catalog import Catalog
    from pipeline.config import CONF_DIR

    cfg = compose(data)
    catalog = Catalog(CONF_DIR.parent / cfg.scenes.catalog, data)
    emb = OmegaConf.to_object(cfg.embodiment)
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for scene in catalog.select():
        layers, attrs = catalog.dataset("quality", scene).load_layers()
        cm = catalog.dataset("costmaps", scene).load(emb.name)
        sup = catalog.dataset("costmaps", scene).load_layers(emb.name)[0]["support"]
        valid = ~cm.occupancy & sup
        rng = np.random.default_rng(0)
        cells = np.argwhere(valid)
        cells = cells[rng.choice(len(cells), min(poses, len(cells)), replace=False)]
        xy = cm.cell_centers(cells)
        pose = np.c_[xy, rng.uniform(-np.pi, np.pi, len(xy))]
        cam, _ = camera_scene(catalog, scene, emb.name, view_dependent=False)
        blurry = sharpness(cam, emb, pose)
        flagged = layers["flagged"][cells[:, 0], cells[:, 1]]
        name = f"{scene.name}_quality_topdown.png"
        shutil.copyfile(catalog.dataset("quality_picture", scene).path, folder / name)
        keys = [k for k in attrs if k.endswith("_share") or k in ("score", "valid_area_m2", "views_rendered",
                                                                    "capture_cameras")]
        rows.append({"scene": scene.name, **{k: attrs[k] for k in keys},
                     "poses": len(pose), "poses_flagged": int(flagged.sum()),
                     "blurry_patches_flagged_median": float(np.median(blurry[flagged])) if flagged.any() else None,
                     "blurry_patches_clean_median": float(np.median(blurry[~flagged])) if (~flagged).any() else None,
                     "blurry_patches_flagged_mean": float(blurry[flagged].mean()) if flagged.any() else None,
                     "blurry_patches_clean_mean": float(blurry[~flagged].mean()) if (~flagged).any() else None,
                     "picture": name})
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
    ap.add_argument("--docs", action="store_true", help="also write docs/bench_screening.md")
    args = ap.parse_args(argv)
    rows = []
    for s in (int(x) for x in args.seeds.split(",") if x):
        rows.append(synthetic(s, args.level, args.gaussians, args.regions, args.radius))
        print(json.dumps(rows[-1]), flush=True)
    rep = {"synthetic": rows, **{f"{k}_{m}_min": min(r[k][m] for r in rows) for k in ("blur", "hole", "flagged")
                                 for m in ("recall", "precision") if rows}}
    if args.real_data:
        rep["real"] = real(args.real_data, Path(args.out) / "screening")
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "screening.json").write_text(jsonio.dumps(rep, indent=1))
    print(json.dumps({k: v for k, v in rep.items() if k.endswith("_min")}))
    if args.docs:
        write_page("bench_screening.md", markdown(rep, args))
    return 0


def markdown(rep: dict, args) -> str:
    """docs/benchmarks/bench_screening.md from a report."""
    import platform

    pc = lambda x: f"{100 * x:.1f} %"  # noqa: E731
    out = ["# Scene and region screening (`make bench-screening`)", "",
           f"Machine: {platform.machine()}, {os.cpu_count()} cores; "
           f"`python -m benchmarks.captures.screening --seeds {args.seeds} --level {args.level} --gaussians {args.gaussians}"
           f" --regions {args.regions} --radius {args.radius}`. Design: stages/screen/design.md.", "",
           "## Injected defects (realistic synthetic scenes, every cue as the stage computes it)", "",
           f"{args.regions} blurred and {args.regions} hole regions of {args.radius} m per scene "
           "(`synthetic.realism.blur_regions / hole_regions`); recall: share of the regions' cells flagged; "
           "precision: share of flagged cells within a region (+0.3 m). Targets 90 % / 80 %.", "",
           "| seed | blur recall | blur precision | hole recall | hole precision | all defect cues: recall / precision |"
           " flagged share of valid cells | of which unseen by the capture path | views |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rep["synthetic"]:
        out.append(f"| {r['seed']} | {pc(r['blur']['recall'])} | {pc(r['blur']['precision'])} | {pc(r['hole']['recall'])}"
                   f" | {pc(r['hole']['precision'])} | {pc(r['flagged']['recall'])} / {pc(r['flagged']['precision'])} |"
                   f" {pc(r['flagged_share_of_valid'])} | {pc(r['unseen_share_of_valid'])} | {r['views_rendered']} |")
    if rep.get("real"):
        out += ["", "## Real scenes (the screen stage's layer; pictures in data/08_reports/screening/, not committed)", "",
                "Cross-check with image sharpness, which no cue uses: views from random valid poses (random "
                "headings, 160 x 120), the share of their 20 x 20 patches whose Laplacian is flat (std < 0.01), "
                "for poses in flagged cells and in clean ones.", "",
                "| scene | valid m2 | score | blobs | floor holes | views: blur | views: holes | unseen (capture cameras) |"
                " views rendered | poses flagged / all | blurry patches, flagged poses (mean) | clean poses (mean) |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rep["real"]:
            out.append(f"| {r['scene']} | {r['valid_area_m2']} | {r['score']:.3f} | {pc(r['blur_share'])} | {pc(r['hole_share'])}"
                       f" | {pc(r['view_blur_share'])} | {pc(r['view_hole_share'])} |"
                       f" {pc(r['unseen_share']) if r.get('capture_cameras') else 'no cameras'} | {r['views_rendered']} |"
                       f" {r['poses_flagged']} / {r['poses']} | {pc(r['blurry_patches_flagged_mean'] or 0)} |"
                       f" {pc(r['blurry_patches_clean_mean'] or 0)} |")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    sys.exit(main())
