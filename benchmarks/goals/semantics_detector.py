"""bench-semantics, "detector on real scenes": the `detector` segmenter (shipped Yolo-Fastest-1.1-XL,
OpenCV DNN, masks from rendered depth) measured against a real labelled scan.

The scan (SceneSplat-style .npy folder, one Gaussian a scanned point, per-point instance and class
ids) runs through the pipeline to its costmap; views are rendered at the stage's free-space poses;
the scan's own labels rendered in the same views (the oracle's instance maps) are the per-pixel
ground truth. Measured:
- per-view box precision per category and threshold: a box is right when most of its mask's pixels
  (depth mask, and the whole box for comparison) belong to a labelled instance of its category;
- lifted instances (the stage's lifting) against the scan's cleaned instance table, per minimum
  number of supporting views: valid-centre rate (paper Table 5: 92.25 %), precision and recall per
  category, centre error;
- seconds: rendering, detection, lifting.

    python -m benchmarks.goals.semantics_detector --scan ../shared/data/real_labelled/scannet_scene0000_02 [--docs]
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import machine, write_report
from benchmarks.goals.semantics_real import prepare_scan, score_real
from benchmarks.pages import write_page

THRESHOLDS = (0.2, 0.3, 0.4, 0.5, 0.6)
MIN_VIEWS = (1, 2, 3, 4, 5)


def per_category(pred: list[dict], truth: list[dict], categories, tol: float) -> dict:
    """Instance precision and recall per category."""
    out = {}
    for cat in categories:
        p = [x for x in pred if x["category"] == cat]
        s = score_real(p, truth, [cat], tol)
        out[cat] = {"predicted": len(p), "valid": s["valid"], "objects": s["objects"], "found": s["found"]}
    return out


def bench_scan(scan: Path, width: int, height: int, tol: float, input_size: int = 320, model: Path | None = None,
               transfer_radius: float = 0.05, spacing: float | None = None, yaw_step: float | None = None,
               camera_height: float | None = None, pitch: float | None = None, robot_camera: bool = False,
               overrides: tuple[str, ...] = (), detector: str | None = None,
               detector_models: dict[str, str] | None = None, final=None) -> dict:
    """The measures of the module doc on the scan (or, with `model`, on a 3DGS trained in the scan's
    frame, whose Gaussians take the instance of the nearest scanned point within transfer_radius).
    `overrides`: more config overrides of both runs (e.g. semantics.view_selection=coverage);
    `detector`: the detector model (semantics.detector.model: None is the shipped default);
    `detector_models`: categories boxed by other models (semantics.detector.models); `final`: the
    DetectorConfig whose thresholds, allow-list and min_views make the "defaults" figures (None:
    the shipped defaults)."""
    from omegaconf import OmegaConf

    from navcore.instances import shipped_instances, table_to_labels
    from navcore.render import Renderer
    from stages.semantics.detector import COCO_TO_GOAL, DetectorConfig, DetectorSegmenter, box_mask
    from stages.semantics.lifting import lift
    from stages.semantics.segmenters import OracleSegmenter, real_truth
    from stages.semantics.stage import covering_cameras, render_views

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        (Path(tmp) / "scan").mkdir()
        (Path(tmp) / "model").mkdir()
        catalog, scene, cfg = prepare_scan(scan, Path(tmp) / "scan", scan.name, overrides=overrides)
        scfg = OmegaConf.to_object(cfg.semantics)
        scfg.width, scfg.height, scfg.poses = width, height, "free_space"
        scfg.segmenter = "detector"  # its pose density (detector.spacing, detector.yaw_step_deg) unless given
        scfg.detector.spacing = spacing or scfg.detector.spacing
        scfg.detector.yaw_step_deg = yaw_step or scfg.detector.yaw_step_deg
        scfg.detector.camera_height = scfg.detector.camera_height if camera_height is None else camera_height
        scfg.detector.camera_pitch_deg = scfg.detector.camera_pitch_deg if pitch is None else pitch
        if robot_camera:  # the embodiment's own camera
            scfg.detector.camera_height = scfg.detector.camera_pitch_deg = None
        emb = OmegaConf.to_object(cfg.embodiment)
        gs, attrs = catalog.dataset("aligned", scene).load()
        t = np.asarray(attrs["source_to_aligned"])
        ceiling = catalog.dataset("alignment", scene).load().get("floor_to_ceiling_m")
        table, _, _ = shipped_instances(scene, gs, t, scfg.vocabulary(scene), scfg.labels, ceiling)
        truth = table_to_labels(table)
        ids, gt_cats = real_truth(scene, catalog, scfg)
        name = scan.name
        if model is not None:  # the trained 3DGS of the scan: its own pipeline, the scan's labels carried over
            from scipy.spatial import cKDTree

            from navcore.instances import transform_labels

            catalog, scene, cfg = prepare_scan(model, Path(tmp) / "model", "scannet_trained", fmt=None, group="real_trained",
                                               overrides=overrides)
            gm, mattrs = catalog.dataset("aligned", scene).load()
            tm = np.asarray(mattrs["source_to_aligned"])
            to_src = lambda x, tf: (x - tf[:3, 3]) @ np.linalg.inv(tf[:3, :3]).T  # noqa: E731
            d, nn = cKDTree(to_src(gs.means, t)).query(to_src(gm.means, tm))
            ids = np.where(d <= transfer_radius, ids[nn], 0)
            truth = transform_labels(truth, tm @ np.linalg.inv(t))
            gs, t, name = gm, tm, f"{scan.name} (trained 3DGS)"
        prep_s = time.perf_counter() - t0
        cm = catalog.dataset("costmaps", scene).load(emb.name)
        cat_of_id = {i: c for i, c in gt_cats.items()}  # instance id -> prompt (category with spaces)
        prompt_to_cat = {scfg.prompt(c): c for c in scfg.categories}
        renderer = Renderer(gs, scfg.renderer)
        oracle = OracleSegmenter(renderer, ids, gt_cats, "none", 0)
        coverage: dict = {}
        t_sel = time.perf_counter()
        c2w, ks, _ = covering_cameras(scene, catalog, scfg, emb, t, cm, gs, coverage)  # semantics.view_selection decides
        select_s = time.perf_counter() - t_sel
        all_cats = sorted(set(COCO_TO_GOAL.values()))
        dcfg = DetectorConfig(categories=all_cats, confidence={}, default_confidence=min(THRESHOLDS), input_size=input_size,
                              model=detector, models=dict(detector_models or {}))
        det = DetectorSegmenter(dcfg, {c: scfg.prompt(c) for c in all_cats})
        box_cfg = DetectorConfig(mask="box")
        views, render_s, detect_s = [], 0.0, 0.0
        t1 = time.perf_counter()
        for rgb, depth, extra, vm, kk, cw in render_views(renderer, c2w, ks, scfg, oracle.gaussian_features):
            render_s += time.perf_counter() - t1
            for i in range(len(vm)):
                imap = oracle.instance_map(vm[i], kk[i], width, height, extra[i])
                t2 = time.perf_counter()
                seg = det.segment(rgb[i], [scfg.prompt(c) for c in all_cats],
                                  {"depth": depth[i], "K": kk[i], "cam_to_world": cw[i]})
                detect_s += time.perf_counter() - t2
                del seg
                boxes = []
                for cat, box, score in det.last_boxes:
                    dm = box_mask(box, depth[i], kk[i], cw[i], dcfg)
                    bm = box_mask(box, depth[i], kk[i], cw[i], box_cfg)
                    boxes.append({"category": cat, "score": score, "depth_mask": dm, "box_mask": bm,
                                  "right_depth": right(dm, imap, cat_of_id, prompt_to_cat, cat),
                                  "right_box": right(bm, imap, cat_of_id, prompt_to_cat, cat)})
                views.append((depth[i], kk[i], cw[i], boxes))
            t1 = time.perf_counter()
        gt_cats_present = sorted({x["category"] for x in truth if x["category"] in all_cats})
        d = scfg.detector
        rep = {"scene": name, "camera_height_m": emb.camera_height if d.camera_height is None else d.camera_height,
               "camera_pitch_deg": emb.camera_pitch_deg if d.camera_pitch_deg is None else d.camera_pitch_deg,
               "spacing_m": scfg.detector.spacing,
               "yaw_step_deg": scfg.detector.yaw_step_deg,
               "gaussians": int(renderer.num_gaussians), "views": len(views), "input": det.input_size,
               "detector": detector or "yolo_fastest_1.1 (shipped)", "detector_models": dict(detector_models or {}),
               "view_selection": scfg.view_selection, "coverage": coverage,
               "resolution": [width, height], "renderer": renderer.backend, "tolerance_m": tol,
               "ground_truth": {c: sum(1 for x in truth if x["category"] == c) for c in all_cats},
               "seconds": {"pipeline_to_costmap": round(prep_s, 1), "view_selection": round(select_s, 1),
                           "render": round(render_s, 1),
                           "detect": round(detect_s, 1), "detect_per_view": round(detect_s / max(len(views), 1), 4)},
               "boxes": {}, "lifted": {}}
        for cat in all_cats:
            rows = [b for _, _, _, bs in views for b in bs if b["category"] == cat]
            rep["boxes"][cat] = {str(th): {"boxes": sum(b["score"] >= th for b in rows),
                                           "right_depth_mask": sum(b["score"] >= th and b["right_depth"] for b in rows),
                                           "right_box": sum(b["score"] >= th and b["right_box"] for b in rows)}
                                 for th in THRESHOLDS}
        cat_index = {c: k for k, c in enumerate(scfg.categories)}
        for th in (0.3, 0.4, 0.5):
            for mode in ("depth_mask", "box_mask"):
                frames = []
                for d, k, c, bs in views:
                    masks: dict[int, list] = {}
                    for b in bs:
                        if b["score"] >= th and b[mode] is not None and b["category"] in cat_index:
                            masks.setdefault(cat_index[b["category"]], []).append(b[mode])
                    frames.append((d, k, c, masks))
                t3 = time.perf_counter()
                cands = lift(frames, gs.means, scfg.lifting)  # min_views 1: filtered below
                lift_s = time.perf_counter() - t3
                for mv in MIN_VIEWS:
                    pred = [{"category": scfg.categories[x["label"]], "position": x["center"], "views": x["views"]}
                            for x in cands if x["views"] >= mv]
                    s = score_real(pred, truth, all_cats, tol)
                    rep["lifted"][f"{th}/{mode}/{mv}"] = {
                        "threshold": th, "mask": mode, "min_views": mv, "lift_s": round(lift_s, 2),
                        "predicted": s["predicted"], "valid": s["valid"], "valid_center_rate": s["valid_center_rate"],
                        "objects": s["objects"], "found": s["found"], "centre_error_m": s["centre_error_m"],
                        "per_category": per_category(pred, truth, all_cats, tol)}
        # the defaults: per-category thresholds (detector.confidence), the allow-list, detector.min_views
        d0 = final or DetectorConfig()
        frames = []
        for d, k, c, bs in views:
            masks = {}
            for b in bs:
                if b["category"] in d0.categories and b["category"] in cat_index and b["depth_mask"] is not None \
                        and b["score"] >= d0.confidence.get(b["category"], d0.default_confidence):
                    masks.setdefault(cat_index[b["category"]], []).append(b["depth_mask"])
            frames.append((d, k, c, masks))
        pred = [{"category": scfg.categories[x["label"]], "position": x["center"], "views": x["views"]}
                for x in lift(frames, gs.means, scfg.lifting) if x["views"] >= d0.min_views]
        s = score_real(pred, truth, all_cats, tol)
        rep["defaults"] = {"confidence": d0.confidence, "default_confidence": d0.default_confidence,
                           "min_views": d0.min_views, "categories": d0.categories, "predicted": s["predicted"],
                           "valid": s["valid"], "valid_center_rate": s["valid_center_rate"],
                           "centre_error_m": s["centre_error_m"], "per_category": per_category(pred, truth, all_cats, tol)}
        rep["categories_in_scan"] = gt_cats_present
        return rep


def right(mask, imap: np.ndarray, cat_of_id: dict, prompt_to_cat: dict, cat: str) -> bool:
    """Whether most of a mask's pixels belong to labelled instances of `cat`."""
    if mask is None or not mask.any():
        return False
    ids = imap[mask]
    hit = np.array([prompt_to_cat.get(cat_of_id.get(int(i)), None) == cat for i in ids])
    return bool(hit.mean() > 0.5)


def section(rep: dict) -> list[str]:
    L = [f"## {rep['scene']}", "",
         f"{rep['gaussians']:,} Gaussians, {rep['views']} views at free-space poses {rep['spacing_m']} m apart every "
         f"{rep['yaw_step_deg']:g} deg (camera {rep['camera_height_m']} m, pitch {rep['camera_pitch_deg']:g} deg), "
         f"{rep['resolution'][0]} x {rep['resolution'][1]}, "
         f"renderer {rep['renderer']}, detector input {rep['input']}. Seconds on this machine: pipeline to the costmap "
         f"{rep['seconds']['pipeline_to_costmap']}, rendering {rep['seconds']['render']}, detection {rep['seconds']['detect']} "
         f"({rep['seconds']['detect_per_view'] * 1000:.0f} ms a view).", "",
         "Ground-truth goal instances: " + ", ".join(f"{c} {n}" for c, n in rep["ground_truth"].items() if n) + ".", "",
         "Per-view boxes, right (most of the mask on an instance of the box's category) of all boxes, with the depth "
         "mask / with the whole box:", "",
         "| category | " + " | ".join(f"score >= {t}" for t in THRESHOLDS) + " |", "|---|" + "---|" * len(THRESHOLDS)]
    for cat, by in rep["boxes"].items():
        if any(v["boxes"] for v in by.values()):
            L.append(f"| {cat} | " + " | ".join(
                f"{v['right_depth_mask']} / {v['right_box']} of {v['boxes']}" for v in by.values()) + " |")
    L += ["", "Lifted instances against the scan's instances (valid centre: inside the box of an instance of its "
          "category):", "",
          "| score >= | mask | min views | instances | valid | valid-centre rate | objects found | median centre error (m) |",
          "|---|---|---|---|---|---|---|---|"]
    for r in rep["lifted"].values():
        vcr = r["valid_center_rate"]
        med = r["centre_error_m"]["median"]
        L.append(f"| {r['threshold']} | {r['mask']} | {r['min_views']} | {r['predicted']} | {r['valid']} | "
                 f"{'-' if vcr != vcr else f'{vcr:.1%}'} | {r['found']} of {r['objects']} | "
                 f"{'-' if med is None else round(med, 2)} |")
    L += ["", defaults_line(rep["defaults"]), ""]
    return L


def defaults_line(d: dict) -> str:
    thresholds = ", ".join(f"{c} {v}" for c, v in d["confidence"].items())
    kept = {c: v for c, v in d["per_category"].items() if c in d["categories"] and (v["predicted"] or v["objects"])}
    n, valid = d["predicted"], d["valid"]
    head = (f"At the defaults (score >= {d['default_confidence']}, {thresholds}; depth masks; {d['min_views']} views; "
            f"categories {', '.join(d['categories'])}): ")
    head += f"{n} instance(s), {valid} valid ({valid / n:.0%} valid centres)" if n else "no instance"
    return head + "; per category (instances / valid / objects / found): " + "; ".join(
        f"{c} {v['predicted']} / {v['valid']} / {v['objects']} / {v['found']}" for c, v in kept.items()) + "."


def geometry_section(rows: list[dict]) -> list[str]:
    """The view-geometry sweep on the scan: boxes per category at the default thresholds, lifted at the defaults."""
    L = ["## View geometry (the scan)", "",
         "The same scan rendered from the free-space poses at other camera heights and pitches "
         "(`--camera-height`, `--pitch`; the detector's views need not be the robot's camera). Boxes right / all at "
         "score >= 0.4, and what the defaults lift:", "",
         "| camera height (m) | pitch (deg) | views | bed boxes | sofa boxes | other boxes | lifted at the defaults | valid | found |",
         "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b = r["boxes"]
        at = lambda c: b.get(c, {}).get("0.4", {"right_depth_mask": 0, "boxes": 0})  # noqa: E731
        other = sum(at(c)["boxes"] for c in b if c not in ("bed", "sofa"))
        d = r["defaults"]
        found = [c for c, v in d["per_category"].items() if v["found"]]
        L.append(f"| {r['camera_height_m']} | {r['camera_pitch_deg']:g} | {r['views']} | {at('bed')['right_depth_mask']} / "
                 f"{at('bed')['boxes']} | {at('sofa')['right_depth_mask']} / {at('sofa')['boxes']} | {other} | "
                 f"{d['predicted']} | {d['valid']} | {', '.join(found) or '-'} |")
    return L + [""]


def gpu_section(gpu: dict, cpu_seconds: dict) -> list[str]:
    """Rendering the detector's views on a GPU (benchmarks.goals.semantics_detector_gpu) against the CPU."""
    L = ["## Seconds per real capture, CPU and GPU", "",
         f"The detector's views of the real captures (../shared/data/real_indoor) rendered with gsplat on {gpu['gpu']} "
         f"and with the CPU renderer on the same machine ({gpu['cores']} threads; first 64 views, scaled), by "
         "`python -m benchmarks.goals.semantics_detector_gpu run` (the device tool; the views from `prepare` on this "
         "machine). Detection and lifting run on the CPU on either machine (OpenCV DNN's CPU path): their seconds are "
         "the stage's on this 2-core machine (`semantics.segmenter=detector` on the capture, its marker's timings).", "",
         "| capture | Gaussians | views | render, gsplat (s) | render, CPU renderer there (s) | render, CPU here (s) | "
         "detect here (s) | lift here (s) | stage here (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for name, row in gpu["scenes"].items():
        c = cpu_seconds.get(name, {})
        L.append(f"| {name} | {row['gaussians']:,} | {row['views']:,} | {row['gsplat']['seconds_all_views']} | "
                 f"{row['cpu']['seconds_all_views']} | {c.get('render', '-')} | {c.get('segment', '-')} | "
                 f"{c.get('lift', '-')} | {c.get('total', '-')} |")
    return L + [""]


def markdown(reps: list[dict], machine_name: str, geometry: list[dict] | None = None, gpu: dict | None = None,
             cpu_seconds: dict | None = None) -> str:
    L = [f"# bench-semantics: the detector on real scenes ({machine_name})", "",
         "The `detector` segmenter (the shipped Yolo-Fastest-1.1-XL, COCO, through OpenCV DNN; masks from the rendered "
         "depth inside each box) against the real labelled ScanNet scene0000_02: the scan itself (one Gaussian a "
         "scanned point) and the 3DGS trained on views of it (`make bench-trained-scan`; its Gaussians take the "
         "instance of the nearest scanned point within 5 cm). Ground truth per pixel: the scan's labels rendered in "
         "the same views; per instance: its cleaned instance table (paper Table 5 measure: 92.25 % valid centres).", ""]
    for rep in reps:
        L += section(rep)
    if geometry:
        L += geometry_section(geometry)
    if gpu:
        L += gpu_section(gpu, cpu_seconds or {})
    return "\n".join(L)


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scan", default="../shared/data/real_labelled/scannet_scene0000_02")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--tol", type=float, default=0.0)
    ap.add_argument("--input", type=int, default=320, help="detector input side (multiple of 32)")
    ap.add_argument("--spacing", type=float, default=None, help="free-space pose spacing, m (detector.spacing: 0.75)")
    ap.add_argument("--yaw-step", type=float, default=None, help="yaw step of the poses, degrees (detector.yaw_step_deg: 30)")
    ap.add_argument("--camera-height", type=float, default=None, help="view camera height, m (detector.camera_height)")
    ap.add_argument("--pitch", type=float, default=None, help="view camera pitch, deg (detector.camera_pitch_deg)")
    ap.add_argument("--model", default="data/trained_scan/model.ply",
                    help="a 3DGS trained in the scan's frame (make bench-trained-scan); skipped when absent")
    ap.add_argument("--geometry", default="robot 1.2,-10 1.5,-20 1.5,-30",
                    help="view geometries of the sweep on the scan besides the defaults: 'robot' (the embodiment's "
                         "camera) or HEIGHT,PITCH, space-separated; '' skips the sweep")
    ap.add_argument("--gpu", default="data/08_reports/semantics_detector_gpu.json",
                    help="output of `python -m benchmarks.goals.semantics_detector_gpu run` (a GPU machine); skipped when absent")
    ap.add_argument("--real-root", default=None,
                    help="a data root where the real captures ran with semantics.segmenter=detector (their CPU seconds)")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", action="store_true")
    a = ap.parse_args(argv)
    scan = Path(a.scan).resolve()
    models = [None] + ([Path(a.model).resolve()] if a.model and Path(a.model).is_file() else [])
    reps = [bench_scan(scan, a.width, a.height, a.tol, a.input, m, spacing=a.spacing, yaw_step=a.yaw_step,
                       camera_height=a.camera_height, pitch=a.pitch) for m in models]
    geometry = [reps[0]]
    for g in a.geometry.split():
        h, p = (None, None) if g == "robot" else map(float, g.split(","))
        geometry.append(bench_scan(scan, a.width, a.height, a.tol, a.input, None, spacing=a.spacing, yaw_step=a.yaw_step,
                                   camera_height=h, pitch=p, robot_camera=g == "robot"))
    gpu = json.loads(Path(a.gpu).read_text()) if a.gpu and Path(a.gpu).is_file() else None
    cpu = real_seconds(Path(a.real_root)) if a.real_root else {}
    write_report(a.out, "bench_semantics_detector.json", {"machine": machine(), "scenes": reps, "geometry": geometry[1:],
                                                         "gpu": gpu, "real_cpu_seconds": cpu}, omit=("scenes", "geometry"))
    md = markdown(reps, machine(), geometry if len(geometry) > 1 else None, gpu, cpu)
    (Path(a.out) / "bench_semantics_detector.md").write_text(md)
    if a.docs:
        write_page("bench_semantics_detector.md", md)
    return reps


def real_seconds(root: Path) -> dict:
    """{capture name: the detector semantics stage's seconds (render, segment, lift, total) and counts} of a
    data root run on catalogs/real_indoor.yaml."""
    from navcore.io.catalog import Catalog
    from pipeline.config import CONF_DIR

    catalog = Catalog(CONF_DIR.parent / "catalogs/real_indoor.yaml", root)
    out = {}
    for scene in catalog.scenes:
        m = catalog.path("markers", scene, stage="semantics")
        if m.is_file():
            info = json.loads(m.read_text()).get("info", {})
            if info.get("segmenter") == "detector":
                out[scene.name] = {**info.get("seconds", {}), "views": info.get("views"),
                                   "instances": info.get("by_category", {})}
    return out


if __name__ == "__main__":
    main()
