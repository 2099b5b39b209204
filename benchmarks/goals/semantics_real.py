"""bench-semantics, real-scene section: the lifting measured on real labelled geometry.

The oracle segmenter renders a real scene's own per-Gaussian labels (its shipped ground truth:
SceneSplat arrays or a labelled mesh) into per-view instance maps, spoils them with the corruption
model (none / moderate / heavy), and the semantics stage's lifting (erode, back-project, vote,
transfer, DBSCAN) turns them into instance candidates. That isolates the part we own from the 2D
model. Against the scene's cleaned ground-truth instance table (same frame):
- valid-centre rate: predicted centres inside the box of a ground-truth instance of the predicted
  category (grown by --tol metres; paper Table 5: 92.25 %);
- recall per category: ground-truth instances with a valid centre of their category;
- centre error: distance from each valid centre to the centroid of the instance it lies in.
Covering poses: the scene's capture cameras when it ships them (cameras.json), and the costmap's
free-space poses (the stage's fallback); a scan without cameras reports the first as absent.

    python -m benchmarks.goals.semantics_real --scan ../shared/data/real_labelled/scannet_scene0000_02 [--out data/08_reports]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import machine
from benchmarks.goals.semantics import LEVELS, level_seed
from benchmarks.pages import write_page
from navcore.io import jsonio

LEVEL_NAMES = LEVELS


def prepare_scan(scan: Path, root: Path, name: str, fmt: str | None = "npy_folder", stage: str = "costmap",
                 group: str = "real_labelled", overrides: tuple[str, ...] = ()):
    """Run the pipeline up to `stage` on a scan folder (or any scene file, fmt None: by its
    extension) under root, with more config overrides; (catalog, scene, cfg)."""
    from hydra import compose, initialize_config_dir

    from navcore.io.catalog import open_catalog
    from pipeline.config import CONF_DIR, register_configs
    from pipeline.executor import execute

    register_configs()
    fmt_key = f", format: {fmt}" if fmt else ""
    (root / "cat.yaml").write_text(f"scenes:\n  - {{name: {name}, group: {group}, path: {scan}{fmt_key}}}\n")
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=[f"data_root={root / 'data'}", "executor=sync", f"scenes.catalog={root / 'cat.yaml'}",
                                           f"stages=[{stage}]", *overrides])
    s = execute(cfg)
    if s["failures"]:
        raise RuntimeError(f"{scan}: the pipeline failed up to {stage}: {s['failures']}")
    catalog, scenes, _ = open_catalog(cfg)
    return catalog, scenes[0], cfg


def score_real(pred: list[dict], truth: list[dict], categories, tol: float) -> dict:
    """Valid centres, recall per category and centre errors of predictions against a ground-truth
    instance table (both aligned frame)."""
    gt = [t for t in truth if t["category"] in categories and t["bounding_box"]]
    valid, errors, found = 0, [], set()
    for p in pred:
        c = np.asarray(p["position"], float)
        hits = [t for t in gt if t["category"] == p["category"]
                and (np.asarray(t["bounding_box"]["min"]) - tol <= c).all() and (c <= np.asarray(t["bounding_box"]["max"]) + tol).all()]
        if hits:
            valid += 1
            best = min(hits, key=lambda t: np.linalg.norm(c - np.asarray(t["position"])))
            errors.append(float(np.linalg.norm(c - np.asarray(best["position"]))))
            found.update(t["instance_id"] for t in hits)
    per_cat = {}
    for cat in sorted({t["category"] for t in gt}):
        ids = [t["instance_id"] for t in gt if t["category"] == cat]
        per_cat[cat] = {"objects": len(ids), "found": sum(i in found for i in ids)}
    return {"predicted": len(pred), "valid": valid, "valid_center_rate": valid / len(pred) if pred else float("nan"),
            "objects": len(gt), "found": len(found & {t["instance_id"] for t in gt}),
            "recall": len(found & {t["instance_id"] for t in gt}) / len(gt) if gt else float("nan"),
            "recall_by_category": per_cat,
            "centre_error_m": {"median": float(np.median(errors)) if errors else None,
                               "max": float(np.max(errors)) if errors else None}}


def bench_scan(scan: Path, tol: float = 0.0) -> dict:
    from omegaconf import OmegaConf

    from navcore.gaussians.cameras import camera_file
    from navcore.instances import shipped_instances, table_to_labels
    from navcore.render import Renderer
    from stages.semantics.lifting import lift
    from stages.semantics.segmenters import CORRUPTION_LEVELS, OracleSegmenter, corrupt, real_truth
    from stages.semantics.stage import category_masks, covering_cameras, render_views

    with tempfile.TemporaryDirectory() as tmp:
        catalog, scene, cfg = prepare_scan(scan, Path(tmp), scan.name)
        scfg = OmegaConf.to_object(cfg.semantics)
        emb = OmegaConf.to_object(cfg.embodiment)
        gs, attrs = catalog.dataset("aligned", scene).load()
        t = np.asarray(attrs["source_to_aligned"])
        cm = catalog.dataset("costmaps", scene).load(emb.name)
        ceiling = catalog.dataset("alignment", scene).load().get("floor_to_ceiling_m")
        table, origin, _ = shipped_instances(scene, gs, t, scfg.vocabulary(scene), scfg.labels, ceiling)
        truth = table_to_labels(table)
        ids, cats = real_truth(scene, catalog, scfg)
        renderer = Renderer(gs, scfg.renderer)
        prompts = [scfg.prompt(c) for c in scfg.categories]
        pose_sets = {"capture cameras": None, "costmap free space": None}
        if camera_file(scene, catalog) is not None:
            scfg_src = OmegaConf.to_object(cfg.semantics)
            scfg_src.poses = "source"
            pose_sets["capture cameras"] = covering_cameras(scene, catalog, scfg_src, emb, t, cm)[:2]
        scfg.poses = "free_space"
        pose_sets["costmap free space"] = covering_cameras(scene, catalog, scfg, emb, t, cm)[:2]
        oracle = OracleSegmenter(renderer, ids, cats, "none", 0)
        out = {"scene": scan.name, "gaussians": int(renderer.num_gaussians), "labels_from": origin,
               "renderer": renderer.backend, "resolution": [scfg.width, scfg.height], "tolerance_m": tol,
               "ground_truth_goal_instances": sum(1 for x in truth if x["category"] in scfg.categories), "poses": {}}
        for pose_name, cams in pose_sets.items():
            if cams is None:
                out["poses"][pose_name] = {"absent": "the scan ships no capture cameras (cameras.json)"}
                continue
            c2w, ks = cams
            t0 = time.perf_counter()
            views = []
            for _rgb, depth, extra, vm, kk, cw in render_views(renderer, c2w, ks, scfg, oracle.gaussian_features):
                for i in range(len(vm)):
                    views.append((depth[i], kk[i], cw[i], oracle.instance_map(vm[i], kk[i], scfg.width, scfg.height, extra[i])))
            res = {"views": len(views), "render_s": round(time.perf_counter() - t0, 2), "levels": {}}
            for level in LEVEL_NAMES:
                rng = np.random.default_rng(level_seed(0, f"{scan.name}:{level}"))
                frames = [(d, k, c, category_masks(corrupt(imap, cats, prompts, CORRUPTION_LEVELS[level], rng), prompts))
                          for d, k, c, imap in views]
                t1 = time.perf_counter()
                cands = lift(frames, gs.means, scfg.lifting)
                pred = [{"category": scfg.categories[c["label"]], "position": c["center"]} for c in cands]
                res["levels"][level] = {**score_real(pred, truth, scfg.categories, tol),
                                        "lift_s": round(time.perf_counter() - t1, 2)}
            out["poses"][pose_name] = res
        return out


def markdown(rep: dict) -> str:
    lines = ["# Lifting on real labelled geometry", "",
             f"Machine: {rep['machine']}. Command: `python -m benchmarks.goals.semantics_real --scan SCAN` "
             "(the oracle renders each scan's own per-Gaussian labels; see the module doc).", ""]
    for s in rep["scans"]:
        lines += [f"## {s['scene']} ({s['gaussians']:,} Gaussians, labels from {s['labels_from']}; "
                  f"{s['ground_truth_goal_instances']} ground-truth goal instances; {s['renderer']} at "
                  f"{s['resolution'][0]}x{s['resolution'][1]})", ""]
        for pose, r in s["poses"].items():
            if "absent" in r:
                lines += [f"- {pose}: {r['absent']}", ""]
                continue
            lines += [f"Covering poses: {pose} ({r['views']} views, rendered in {r['render_s']} s).", "",
                      "| corruption | valid centres | recall | centre error median / max (m) | predicted |",
                      "|---|---|---|---|---|"]
            for lv, x in r["levels"].items():
                ce = x["centre_error_m"]
                lines.append(f"| {lv} | {x['valid_center_rate']:.1%} ({x['valid']}/{x['predicted']}) | {x['recall']:.1%} "
                             f"({x['found']}/{x['objects']}) | {ce['median'] or float('nan'):.2f} / {ce['max'] or float('nan'):.2f} "
                             f"| {x['predicted']} |")
            lines += ["", "Recall by category (found / objects):", "",
                      "| category | " + " | ".join(r["levels"]) + " |", "|---|" + "---|" * len(r["levels"])]
            cats = sorted(next(iter(r["levels"].values()))["recall_by_category"])
            for c in cats:
                lines.append(f"| {c} | " + " | ".join(f"{x['recall_by_category'][c]['found']}/{x['recall_by_category'][c]['objects']}"
                                                       for x in r["levels"].values()) + " |")
            lines.append("")
    return "\n".join(lines)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scan", action="append", required=True, help="SceneSplat-style folder with shipped labels (repeatable)")
    ap.add_argument("--tol", type=float, default=0.0, help="metres the ground-truth boxes are grown by")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", action="store_true", help="also write docs/bench_semantics_real.md")
    args = ap.parse_args(argv)
    rep = {"machine": machine(), "scans": [bench_scan(Path(s).resolve(), args.tol) for s in args.scan]}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_semantics_real.json").write_text(jsonio.dumps(rep, indent=1, default=str))
    md = markdown(rep)
    (out / "bench_semantics_real.md").write_text(md)
    if args.docs:
        write_page("bench_semantics_real.md", md)
    print(md)
    return rep


if __name__ == "__main__":
    main()
