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
from dataclasses import replace
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
               detector_models: dict[str, str] | None = None, final=None,
               candidates: dict[str, str | None] | None = None) -> dict:
    """The measures of the module doc on the scan (or, with `model`, on a 3DGS trained in the scan's
    frame, whose Gaussians take the instance of the nearest scanned point within transfer_radius).
    `overrides`: more config overrides of both runs (e.g. semantics.view_selection=coverage);
    `detector`: the detector model (semantics.detector.model: None is the shipped default);
    `detector_models`: categories boxed by other models (semantics.detector.models); `final`: the
    DetectorConfig whose thresholds, allow-list and min_views make the "defaults" figures (None:
    the shipped defaults). `candidates` ({label: model}): several detectors on the same rendered views,
    one report each ({label: report}; `detector` and `detector_models` are then unused)."""
    from omegaconf import OmegaConf

    from navcore.instances import shipped_instances, table_to_labels
    from navcore.io.models import DEFAULT_MODEL
    from navcore.render import Renderer
    from stages.semantics.detector import COCO_TO_GOAL, DetectorConfig, DetectorSegmenter, box_mask, resolved
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
        runs = candidates if candidates is not None else {None: detector}
        # one detector alone (no candidates): the models the stage would run, the default detector's
        # per-category mix where none is named
        base = resolved(DetectorConfig(model=detector, models=dict(detector_models or {})))
        dcfg = {label: DetectorConfig(categories=all_cats, confidence={}, default_confidence=min(THRESHOLDS),
                                      model_thresholds=False, input_size=input_size,
                                      model=m if candidates is not None else base.model,
                                      models={} if candidates is not None else dict(base.models))
                for label, m in runs.items()}
        dets = {label: DetectorSegmenter(c, {k: scfg.prompt(k) for k in all_cats}) for label, c in dcfg.items()}
        box_cfg = DetectorConfig(mask="box")
        views: dict = {label: [] for label in runs}
        render_s, detect_s = 0.0, dict.fromkeys(runs, 0.0)
        t1 = time.perf_counter()
        for rgb, depth, extra, vm, kk, cw in render_views(renderer, c2w, ks, scfg, oracle.gaussian_features):
            render_s += time.perf_counter() - t1
            for i in range(len(vm)):
                imap = oracle.instance_map(vm[i], kk[i], width, height, extra[i])
                for label, det in dets.items():
                    t2 = time.perf_counter()
                    det.segment(rgb[i], [scfg.prompt(c) for c in all_cats],
                                {"depth": depth[i], "K": kk[i], "cam_to_world": cw[i]})
                    detect_s[label] += time.perf_counter() - t2
                    boxes = []
                    for cat, box, score in det.last_boxes:
                        dm = box_mask(box, depth[i], kk[i], cw[i], dcfg[label])
                        bm = box_mask(box, depth[i], kk[i], cw[i], box_cfg)
                        boxes.append({"category": cat, "score": score, "depth_mask": dm, "box_mask": bm,
                                      "right_depth": right(dm, imap, cat_of_id, prompt_to_cat, cat),
                                      "right_box": right(bm, imap, cat_of_id, prompt_to_cat, cat)})
                    views[label].append((depth[i], kk[i], cw[i], boxes))
            t1 = time.perf_counter()
        gt_cats_present = sorted({x["category"] for x in truth if x["category"] in all_cats})
        reps = {}
        for label, det in dets.items():
            rep = scan_report(views[label], scfg, gs, truth, all_cats, tol, final if candidates is None else None)
            d = scfg.detector
            rep.update({"scene": name, "camera_height_m": emb.camera_height if d.camera_height is None else d.camera_height,
                        "camera_pitch_deg": emb.camera_pitch_deg if d.camera_pitch_deg is None else d.camera_pitch_deg,
                        "spacing_m": d.spacing, "yaw_step_deg": d.yaw_step_deg,
                        "gaussians": int(renderer.num_gaussians), "views": len(views[label]), "input": det.input_size,
                        "detector": (runs[label] or f"{DEFAULT_MODEL} (shipped default)") if candidates is not None
                        else (detector or f"the default detector ({base.model}; " + ", ".join(
                            f"{c}: {m}" for c, m in sorted(base.models.items())) + ")"),
                        "detector_models": dict(detector_models or {}) if candidates is None else {},
                        "view_selection": scfg.view_selection, "coverage": coverage,
                        "resolution": [width, height], "renderer": renderer.backend, "tolerance_m": tol,
                        "ground_truth": {c: sum(1 for x in truth if x["category"] == c) for c in all_cats},
                        "seconds": {"pipeline_to_costmap": round(prep_s, 1), "view_selection": round(select_s, 1),
                                    "render": round(render_s, 1), "detect": round(detect_s[label], 1),
                                    "detect_per_view": round(detect_s[label] / max(len(views[label]), 1), 4)},
                        "categories_in_scan": gt_cats_present})
            if candidates is not None:  # the views and what lifting them needs: defaults_report with chosen thresholds
                rep["_context"] = (views[label], scfg, gs, truth, all_cats, tol)
            reps[label] = rep
        return reps if candidates is not None else reps[None]


def scan_report(views: list, scfg, gs, truth: list[dict], all_cats: list[str], tol: float, final) -> dict:
    """Boxes per category and threshold, lifted instances per threshold, mask and min views, and what
    `final`'s (or the shipped defaults') thresholds lift, from one detector's boxes on the views."""
    from stages.semantics.lifting import lift

    rep: dict = {"boxes": {}, "lifted": {}}
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
    rep["defaults"] = defaults_report(views, scfg, gs, truth, all_cats, tol, final)
    return rep


def defaults_report(views: list, scfg, gs, truth: list[dict], all_cats: list[str], tol: float, final) -> dict:
    """What `final`'s (or the shipped defaults') thresholds, allow-list, min_views and class vote lift
    from one detector's boxes on the views."""
    from stages.semantics.detector import DetectorConfig, resolved
    from stages.semantics.lifting import lift

    cat_index = {c: k for k, c in enumerate(scfg.categories)}
    # the defaults: per-category thresholds (detector.confidence), the allow-list, detector.min_views
    d0 = resolved(final or DetectorConfig())
    frames = []
    for d, k, c, bs in views:
        masks = {}
        for b in bs:
            if b["category"] in d0.categories and b["category"] in cat_index and b["depth_mask"] is not None \
                    and b["score"] >= d0.confidence.get(b["category"], d0.default_confidence):
                masks.setdefault(cat_index[b["category"]], []).append(b["depth_mask"])
        frames.append((d, k, c, masks))
    groups = [[cat_index[c] for c in g if c in cat_index] for g in d0.confusable]
    lcfg = replace(scfg.lifting, min_views=max(scfg.lifting.min_views, d0.min_views),  # the stage's lifting_config
                   min_top_m=max(scfg.lifting.min_top_m, d0.min_top_m), confusable=[g for g in groups if len(g) > 1] or None)
    out = {"confidence": d0.confidence, "default_confidence": d0.default_confidence, "min_views": d0.min_views,
           "categories": d0.categories}
    for key, cfg in (("", lcfg), ("without_class_vote", replace(lcfg, confusable=None))):
        lifted = lift(frames, gs.means, cfg)
        pred = [{"category": scfg.categories[x["label"]], "position": x["center"], "views": x["views"]} for x in lifted]
        s = score_real(pred, truth, all_cats, tol)
        row = {"predicted": s["predicted"], "valid": s["valid"], "valid_center_rate": s["valid_center_rate"],
               "found": s["found"], "objects": s["objects"], "centre_error_m": s["centre_error_m"],
               "per_category": per_category(pred, truth, all_cats, tol),
               "merged": [{"category": scfg.categories[x["label"]], "votes": {scfg.categories[k]: v for k, v in x["label_votes"].items()}}
                          for x in lifted if "label_votes" in x]}
        if key:
            out[key] = row
        else:
            out.update(row)
    return out


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
             cpu_seconds: dict | None = None, candidates: dict | None = None) -> str:
    L = [f"# bench-semantics: the detector on real scenes ({machine_name})", "",
         "The `detector` segmenter (its default model, PP-PicoDet-S 416, COCO, through OpenCV DNN; masks from the rendered "
         "depth inside each box) against the real labelled ScanNet scene0000_02: the scan itself (one Gaussian a "
         "scanned point) and the 3DGS trained on views of it (`make bench-trained-scan`; its Gaussians take the "
         "instance of the nearest scanned point within 5 cm). Ground truth per pixel: the scan's labels rendered in "
         "the same views; per instance: its cleaned instance table (paper Table 5 measure: 92.25 % valid centres).", ""]
    if candidates:
        L += candidates_section(candidates)
    for rep in reps:
        L += section(rep)
    if geometry:
        L += geometry_section(geometry)
    if gpu:
        L += gpu_section(gpu, cpu_seconds or {})
    return "\n".join(L)


SHARED_MODELS = Path(__file__).resolve().parents[3] / "shared" / "models"
CANDIDATES = {"picodet_s_320_coco": "picodet_s_320_coco", "yolox_nano_416_coco": "yolox_nano_416_coco",
              "yolo_fastest_1.1_coco": "yolo_fastest_1.1_coco",
              "picodet_s_416_coco": str(SHARED_MODELS / "picodet_s_416_coco" / "picodet_s_416_coco.onnx")}
"""The detectors compared (label -> semantics.detector.model): the shipped ones and PicoDet-S 416 of
../shared/models (measured where that folder exists; not shipped: on these renders it lifted less)."""


PRECISIONS = (0.5, 0.6, 0.7, 0.8)
"""The per-view precisions a candidate's thresholds are chosen for (choose_thresholds); its figures are
those of the precision whose thresholds lift best on the labelled renders (`lift_key`)."""


def lift_key(reps: list[dict]) -> tuple:
    """Order of preference of one set of thresholds by what it lifts on the labelled renders: valid
    centres >= 90 % on every render first, then the fewest goal instances found on any render, then the
    least valid-centre rate."""
    rates = [r["defaults"]["valid_center_rate"] for r in reps]
    rates = [0.0 if x != x else x for x in rates]
    return (all(x >= 0.9 for x in rates), min(r["defaults"]["found"] for r in reps), min(rates))


def compare_candidates(scan: Path, model: Path | None, width: int, height: int, tol: float,
                       candidates: dict[str, str] | None = None, **views) -> dict:
    """Every candidate on the same renders of the scan (and of the 3DGS trained on it): boxes per
    category and threshold; for each precision of PRECISIONS the thresholds `choose_thresholds` picks
    from both renders and what they lift (with the class vote, and without it); the precision whose
    thresholds lift best (`lift_key`) gives the candidate's figures; and a per-category mix of the
    candidates, each category from the candidate that keeps the most right boxes at its thresholds.
    {label: {"model", "chosen", "sweep", "scenes": [rep, ...]}}. `views`: bench_scan's pose options
    (spacing, yaw_step, camera_height, pitch)."""
    import copy

    import cv2

    from navcore.io.models import SHIPPED
    from stages.semantics.detector import DetectorConfig

    darknet = hasattr(cv2.dnn, "readNetFromDarknet")  # OpenCV 5 has none: Yolo-Fastest is left out there
    cands = {k: v for k, v in (candidates or CANDIDATES).items()
             if (not v.endswith(".onnx") or Path(v).is_file()) and (darknet or v not in SHIPPED or
                                                                    not SHIPPED[v].network.endswith(".cfg"))}
    runs = [bench_scan(scan, width, height, tol, candidates=cands, **views)]
    if model is not None:
        runs.append(bench_scan(scan, width, height, tol, model=model, candidates=cands, **views))

    def lifted(views_of, chosen):
        final = DetectorConfig(categories=chosen["categories"], confidence=chosen["confidence"], model_thresholds=False)
        out = []
        for k in range(len(runs)):
            ctx = runs[k][next(iter(cands))]["_context"]
            out.append(defaults_report(views_of(k), *ctx[1:], final))
        return out

    out, per_precision = {}, {}
    for label in cands:
        reps = [r[label] for r in runs]
        sweep = {}
        for prec in PRECISIONS:
            chosen = choose_thresholds(reps, precision=prec)
            sweep[prec] = (chosen, lifted(lambda k, lab=label: runs[k][lab]["_context"][0], chosen))
        per_precision[label] = sweep
        prec = max(PRECISIONS, key=lambda q: (lift_key([{"defaults": d} for d in sweep[q][1]]), -q))
        chosen, defaults = sweep[prec]
        for rep, d in zip(reps, defaults):
            rep["defaults"] = d
        out[label] = {"model": cands[label], "chosen": chosen, "scenes": reps,
                      "sweep": {str(q): [{k: d[k] for k in ("predicted", "valid", "found")} for d in sweep[q][1]]
                                for q in PRECISIONS}}
    # the per-category mix: at each precision, each category from the candidate that keeps the most right
    # boxes at its threshold (pooled); its views combine those candidates' boxes of the same renders
    best_mix = None
    for prec in PRECISIONS:
        best: dict[str, tuple[int, str]] = {}
        for label in cands:
            chosen = per_precision[label][prec][0]
            for cat, th in chosen["confidence"].items():
                right = int(chosen["counts_right_of_boxes"][cat][str(th)].split(" / ")[0])
                if right > best.get(cat, (-1, ""))[0]:
                    best[cat] = (right, label)
        if not best:
            continue
        mix = {cat: label for cat, (_, label) in sorted(best.items())}
        conf = {cat: per_precision[label][prec][0]["confidence"][cat] for cat, label in mix.items()}

        def views_of(k, mix=mix):
            base = runs[k][next(iter(cands))]["_context"][0]
            return [(d, kk, cw, [b for label in sorted(set(mix.values())) for b in runs[k][label]["_context"][0][i][3]
                                 if mix.get(b["category"]) == label]) for i, (d, kk, cw, _) in enumerate(base)]

        defaults = lifted(views_of, {"categories": sorted(mix), "confidence": conf})
        cand = (lift_key([{"defaults": d} for d in defaults]), -prec)
        if best_mix is None or cand > best_mix[0]:
            best_mix = (cand, prec, mix, conf, defaults)
    if best_mix is not None:
        _, prec, mix, conf, defaults = best_mix
        reps = [{"scene": runs[k][next(iter(cands))]["scene"], "views": runs[k][next(iter(cands))]["views"], "boxes": {},
                 "seconds": {"detect_per_view": sum(runs[k][label]["seconds"]["detect_per_view"] for label in set(mix.values()))},
                 "defaults": d} for k, d in enumerate(defaults)]
        out["per-category mix"] = {"model": mix, "chosen": {"confidence": conf, "categories": sorted(mix), "precision": prec},
                                   "scenes": reps}
    for label in cands:
        for rep in out[label]["scenes"]:
            rep.pop("_context", None)
    return copy.deepcopy(out)


def candidates_section(comp: dict) -> list[str]:
    L = ["## Candidate detectors", "",
         "Every candidate on the same renders: the labelled ScanNet scan (one Gaussian a scanned point) and the 3DGS "
         "trained on it, at the detector's free-space poses. Per category, boxes right (most of the depth mask on a "
         "labelled instance of the category) of all boxes at each score; the threshold chosen (`choose_thresholds`: "
         f"the lowest score at which at least a precision p of the boxes are right, with at least {MIN_RIGHT} right, "
         "pooled over both renders; a category that never gets there is left off; p of "
         f"{', '.join(map(str, PRECISIONS))}, the one whose thresholds lift best: valid centres >= 90 % on both "
         "renders first, then the most goal instances found); what those thresholds lift "
         f"(`min_views` {resolved_min_views()}, the bed / sofa class vote), and seconds per view on this machine.", "",
         "| model | scene | category | " + " | ".join(f">= {t}" for t in THRESHOLDS) + " | chosen |",
         "|---|---|---|" + "---|" * len(THRESHOLDS) + "---|"]
    for label, c in comp.items():
        for rep in c["scenes"]:
            for cat, by in rep["boxes"].items():
                if any(v["boxes"] for v in by.values()):
                    cells = " | ".join(f"{v['right_depth_mask']} / {v['boxes']}" for v in by.values())
                    L.append(f"| {label} | {short(rep['scene'])} | {cat} | {cells} | {c['chosen']['confidence'].get(cat, 'off')} |")
    L += ["", "Lifted at the chosen thresholds (valid: centre inside a labelled instance of its category; found: labelled "
          "goal instances with a valid centre), with the class vote and without it:", "",
          "| model | scene | ms a view | instances | valid | valid-centre rate | found | found per category | "
          "without the vote: instances / valid / found | merged by the vote |", "|---|---|---|---|---|---|---|---|---|---|"]
    for label, c in comp.items():
        for rep in c["scenes"]:
            d, w = rep["defaults"], rep["defaults"]["without_class_vote"]
            vcr = d["valid_center_rate"]
            per = ", ".join(f"{k} {v['found']}/{v['objects']}" for k, v in d["per_category"].items() if v["objects"] and v["found"])
            merged = "; ".join(f"{m['category']} ({', '.join(f'{k} {n}' for k, n in m['votes'].items())})" for m in d["merged"])
            L.append(f"| {label} | {short(rep['scene'])} | {rep['seconds']['detect_per_view'] * 1000:.0f} | {d['predicted']} | "
                     f"{d['valid']} | {'-' if vcr != vcr else f'{vcr:.0%}'} | {d['found']} of {d['objects']} | {per or '-'} | "
                     f"{w['predicted']} / {w['valid']} / {w['found']} | {merged or '-'} |")
    L += ["", "The precision sweep: what each candidate's thresholds lift on the scan / the trained 3DGS (instances, valid, "
          "goal instances found) when chosen for each per-view precision:", "",
          "| model | " + " | ".join(f"p {q}" for q in PRECISIONS) + " | chosen |", "|---|" + "---|" * len(PRECISIONS) + "---|"]
    for label, c in comp.items():
        if "sweep" in c:
            cells = [" / ".join(f"{d['predicted']}, {d['valid']}, {d['found']}" for d in c["sweep"][str(q)]) for q in PRECISIONS]
            L.append(f"| {label} | " + " | ".join(cells) + f" | p {c['chosen']['precision']}: "
                     + ", ".join(f"{k} {v}" for k, v in c["chosen"]["confidence"].items()) + " |")
    mix = comp.get("per-category mix")
    if mix:
        L += ["", f"Per-category mix (p {mix['chosen']['precision']}): " + ", ".join(
            f"{cat} from {label} at {mix['chosen']['confidence'][cat]}" for cat, label in mix["model"].items()) + "."]
    return L + [""]


def short(scene: str) -> str:
    return "trained 3DGS" if "trained" in scene else "scan"


def resolved_min_views() -> int:
    from stages.semantics.detector import DetectorConfig

    return DetectorConfig().min_views


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
    ap.add_argument("--choose", action="store_true",
                    help="write each shipped model's thresholds.json from the candidates' figures (navcore/models)")
    ap.add_argument("--gpu", default="data/08_reports/semantics_detector_gpu.json",
                    help="output of `python -m benchmarks.goals.semantics_detector_gpu run` (a GPU machine); skipped when absent")
    ap.add_argument("--real-root", default=None,
                    help="a data root where the real captures ran with semantics.segmenter=detector (their CPU seconds)")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", action="store_true")
    ap.add_argument("--write-thresholds", nargs="*", default=None, metavar="MODEL",
                    help="only write these shipped models' thresholds.json from the report of an earlier run (--out)")
    a = ap.parse_args(argv)
    from navcore.io.models import SHIPPED

    if a.write_thresholds is not None:
        comp = json.loads((Path(a.out) / "bench_semantics_detector.json").read_text())["candidates"]
        for label in a.write_thresholds or [k for k in comp if k in SHIPPED]:
            print(f"{label}: {write_thresholds(label, comp[label]['chosen'])}")
        print(f"default detector: {write_default_detector(comp)}")
        return []
    scan = Path(a.scan).resolve()
    model = Path(a.model).resolve() if a.model and Path(a.model).is_file() else None
    comp = compare_candidates(scan, model, a.width, a.height, a.tol, spacing=a.spacing, yaw_step=a.yaw_step,
                              camera_height=a.camera_height, pitch=a.pitch)
    if a.choose:
        for label, c in comp.items():
            if label in SHIPPED:
                print(f"{label}: {write_thresholds(label, c['chosen'])}")
        print(f"default detector: {write_default_detector(comp)}")
    # the default detector (navcore/models/detector.json, as --choose just wrote it) on the scan and the model
    reps = [bench_scan(scan, a.width, a.height, a.tol, a.input, m, spacing=a.spacing, yaw_step=a.yaw_step,
                       camera_height=a.camera_height, pitch=a.pitch) for m in [None] + ([model] if model else [])]
    geometry = [reps[0]]
    for g in a.geometry.split():
        h, p = (None, None) if g == "robot" else map(float, g.split(","))
        geometry.append(bench_scan(scan, a.width, a.height, a.tol, a.input, None, spacing=a.spacing, yaw_step=a.yaw_step,
                                   camera_height=h, pitch=p, robot_camera=g == "robot"))
    gpu = json.loads(Path(a.gpu).read_text()) if a.gpu and Path(a.gpu).is_file() else None
    cpu = real_seconds(Path(a.real_root)) if a.real_root else {}
    write_report(a.out, "bench_semantics_detector.json", {"machine": machine(), "candidates": comp, "geometry": geometry[1:],
                                                         "gpu": gpu, "real_cpu_seconds": cpu}, omit=("candidates", "geometry"))
    md = markdown(reps, machine(), geometry if len(geometry) > 1 else None, gpu, cpu, comp)
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



PRECISION = 0.5
"""A category's threshold is the lowest score whose boxes are right at least this often (per view,
pooled over the labelled renders); a category whose boxes never are is left off the allow-list."""
MIN_RIGHT = 4
"""...with at least this many right boxes (fewer say nothing about precision)."""
MIN_EVIDENCE = 10
"""A goal category the default detector's main model boxed fewer times than this on the labelled renders
(at any score) is unmeasured there: it stays on at UNMEASURED_CONFIDENCE."""
UNMEASURED_CONFIDENCE = 0.4
"""The threshold of an unmeasured category (the earlier default's, under which the real fungi room's
tables and screen were lifted right)."""


def choose_thresholds(reps: list[dict], precision: float = PRECISION, min_right: int = MIN_RIGHT) -> dict:
    """Per-category score thresholds and the allow-list of one detector from its boxes on labelled
    renders (reps of bench_scan, pooled): the lowest of THRESHOLDS at which the depth-mask boxes are
    right at least `precision` of the time with at least `min_right` right; the counts they were
    chosen from beside them."""
    cats = sorted({c for r in reps for c in r["boxes"]})
    counts, confidence = {}, {}
    for cat in cats:
        pooled = {th: [sum(r["boxes"][cat][str(th)]["right_depth_mask"] for r in reps if cat in r["boxes"]),
                       sum(r["boxes"][cat][str(th)]["boxes"] for r in reps if cat in r["boxes"])] for th in THRESHOLDS}
        counts[cat] = {str(th): f"{a} / {b}" for th, (a, b) in pooled.items()}
        ok = [th for th, (a, b) in pooled.items() if a >= min_right and a >= precision * b]
        if ok:
            confidence[cat] = min(ok)
    return {"confidence": confidence, "categories": sorted(confidence), "precision": precision, "min_right": min_right,
            "counts_right_of_boxes": counts,
            "chosen_on": [{"scene": r["scene"], "views": r["views"], "resolution": r["resolution"]} for r in reps]}


def write_thresholds(model: str, chosen: dict) -> Path:
    """The shipped model's thresholds file (navcore/models/<model>/thresholds.json), which the
    detector's defaults read (stages.semantics.detector.shipped_thresholds)."""
    from navcore.io.models import MODELS_ROOT, SHIPPED

    out = MODELS_ROOT / SHIPPED[model].folder / "thresholds.json"
    doc = {"about": f"Per-category score thresholds and allow-list of {SHIPPED[model].title}, chosen by "
                    "`python -m benchmarks.goals.semantics_detector --choose` (do not edit by hand): per category the "
                    f"lowest score at which at least {chosen['precision']:.0%} of its boxes (depth masks) were right, with "
                    f"at least {chosen['min_right']} right, pooled over the renders named in chosen_on (the labelled "
                    "ScanNet scan and the 3DGS trained on it; no held-out scene).",
           "model": model, "sha256": SHIPPED[model].files[SHIPPED[model].network], **chosen}
    out.write_text(json.dumps(doc, indent=1) + "\n")
    return out


def write_default_detector(comp: dict) -> Path:
    """navcore/models/detector.json, the default detector: of the candidates that ship and the per-category
    mix of them, the one whose thresholds lift best on the labelled renders (`lift_key`; ties: the
    fewer models, then the faster), with its models per category, thresholds and allow-list."""
    from navcore.io.models import DEFAULT_DETECTOR, SHIPPED

    options = []
    for label, c in comp.items():
        models = c["model"] if isinstance(c["model"], dict) else {cat: label for cat in c["chosen"]["categories"]}
        if not models or not all(m in SHIPPED for m in models.values()):
            continue
        ms = sum(r["seconds"]["detect_per_view"] for r in c["scenes"]) / len(c["scenes"])
        options.append(((lift_key(c["scenes"]), -len(set(models.values())), -ms), label, models, c["chosen"]))
    if not options:
        raise ValueError("no shipped candidate lifted anything: the default detector is left as it was")
    _, label, models, chosen = max(options, key=lambda o: o[0])
    main = max(sorted(set(models.values())), key=lambda m: sum(v == m for v in models.values()))
    # the goal categories the labelled room gives no evidence on (the main model boxed them fewer than
    # MIN_EVIDENCE times at any score, right or wrong) stay on, at UNMEASURED_CONFIDENCE: a room
    # without a plant says nothing against a plant detector (the captures' tables and screen were right)
    chosen = {**chosen, "confidence": dict(chosen["confidence"]), "categories": list(chosen["categories"])}
    unmeasured = []
    counts = comp[main]["chosen"]["counts_right_of_boxes"] if main in comp else {}
    for cat in sorted(counts):
        if cat not in chosen["confidence"] and max(int(v.split(" / ")[1]) for v in counts[cat].values()) < MIN_EVIDENCE:
            chosen["confidence"][cat] = UNMEASURED_CONFIDENCE
            unmeasured.append(cat)
            models = {**models, cat: main}
    chosen["categories"] = sorted(chosen["confidence"])
    doc = {"about": "The `detector` segmenter's default (semantics.detector.model null, models empty), chosen by "
                    "`python -m benchmarks.goals.semantics_detector --choose` (do not edit by hand): of the shipped "
                    "models and their per-category mix, the one whose thresholds lift best on the labelled ScanNet "
                    "scan and the 3DGS trained on it (valid centres >= 90 % on both, then the most goal instances "
                    "found; docs/benchmarks/bench_semantics_detector.md). No held-out scene was used.",
           "chosen_from": label, "model": main, "models": dict(sorted(models.items())),
           "confidence": chosen["confidence"], "categories": chosen["categories"],
           "precision": chosen.get("precision"), "unmeasured": unmeasured}
    DEFAULT_DETECTOR.write_text(json.dumps(doc, indent=1) + "\n")
    return DEFAULT_DETECTOR


if __name__ == "__main__":
    main()
