"""The costmap against scanned geometry: state FP / FN on a real labelled scan.

For a labelled scan (SceneSplat-style folder of ../shared/data/real_labelled: one Gaussian per
scanned point, with the dataset's classes), the pipeline builds the costmap as for any scene; the
truth is the scan itself: robot poses are sampled over the scan's floor (its floor-labelled points,
jittered by up to 2.5 cm), and a pose is blocked when any scanned point that is not floor lies
inside the robot's body cylinder (footprint radius, height band [h_min, h_max] above the aligned
floor). Against that:
- FP: poses the scan shows free that the costmap rejects (target <= 10 %);
- FN: poses the scan shows blocked that the costmap accepts (target <= 0.5 %);
each with its 95 % Wilson interval from the number of poses.

    python -m benchmarks.captures.scan_truth --scan ../shared/data/real_labelled/scannet_scene0000_02 [--poses 4000]
        [--model data/trained_scan/model.ply]   # a 3DGS trained in the scan's frame (benchmarks.captures.train_on_scan)
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from navcore.io import jsonio
from stages.costmap.render_check import wilson


def scan_blocked(xy: np.ndarray, points: np.ndarray, radius: float, h_min: float, h_max: float) -> np.ndarray:
    """[n] bool: a scanned point (aligned frame) with h_min <= z <= h_max lies within `radius` of each pose."""
    from scipy.spatial import cKDTree

    band = points[(points[:, 2] >= h_min) & (points[:, 2] <= h_max)]
    if not len(band):
        return np.zeros(len(xy), bool)
    d, _ = cKDTree(band[:, :2]).query(xy, k=1)
    return d <= radius


def rates(catalog, scene, emb, poses: int, seed: int = 0) -> dict:
    """State FP / FN of a scene's costmap (already built) against its own scanned points (module doc)."""
    from navcore.instances import gaussian_labels

    gs, attrs = catalog.dataset("aligned", scene).load()
    t = np.asarray(attrs["source_to_aligned"])
    cm = catalog.dataset("costmaps", scene).load(emb.name)
    per = gaussian_labels(scene, gs, t)
    pts = gs.means.astype(np.float64)
    if per is None:  # boxes only: the floor is the points within half the body's clearance of the aligned floor
        return {"scene": scene.name, "floor": f"by height: within {emb.h_min / 2:g} m of z = 0 (no per-point labels)",
                **compare(cm, pts, np.abs(pts[:, 2]) <= emb.h_min / 2, emb, poses, seed)}
    _, seg, names = per
    floor_ids = [i + names.id_offset for i, n in enumerate(names.names) if n.strip().lower() == "floor"]
    return {"scene": scene.name, "floor": "labelled", **compare(cm, pts, np.isin(seg, floor_ids), emb, poses, seed)}


def compare(cm, pts: np.ndarray, is_floor: np.ndarray, emb, poses: int, seed: int = 0) -> dict:
    """State FP / FN of a costmap against scanned points [N, 3] (aligned frame) with their floor
    labels: poses on the floor points (jittered 2.5 cm), blocked where a non-floor point lies in
    the body cylinder."""
    rng = np.random.default_rng(seed)
    base = pts[is_floor][rng.integers(is_floor.sum(), size=poses), :2]
    xy = base + rng.uniform(-0.025, 0.025, base.shape)
    truth = scan_blocked(xy, pts[~is_floor], emb.radius, emb.h_min, emb.h_max)
    ours = ~cm.are_states_valid(xy)
    fp, neg = int((ours & ~truth).sum()), int((~truth).sum())
    fn, pos = int((~ours & truth).sum()), int(truth.sum())
    return {"poses": poses, "embodiment": emb.name, "radius_m": emb.radius,
            "band_m": [emb.h_min, emb.h_max], "resolution_m": float(cm.resolution),
            "scan_free": neg, "scan_blocked": pos, "fp": fp, "fn": fn,
            "fp_rate": fp / max(neg, 1), "fp_ci95": wilson(fp, neg),
            "fn_rate": fn / max(pos, 1), "fn_ci95": wilson(fn, pos), "cells": cell_rates(cm, pts, is_floor, emb)}


def cell_rates(cm, pts: np.ndarray, is_floor: np.ndarray, emb, step: float = 0.02) -> dict:
    """The same on every point of a `step` grid over the scan's floor (grid points within 3 cm of
    a floor point): FN / FP as shares of the scan's blocked / free area, no sampling."""
    from scipy.spatial import cKDTree

    fl = pts[is_floor, :2]
    lo, hi = fl.min(0), fl.max(0)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], step) + step / 2, np.arange(lo[1], hi[1], step) + step / 2)
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    xy = xy[cKDTree(fl).query(xy)[0] < 0.03]
    truth = scan_blocked(xy, pts[~is_floor], emb.radius, emb.h_min, emb.h_max)
    ours = ~cm.are_states_valid(xy)
    fn, fp = int((~ours & truth).sum()), int((ours & ~truth).sum())
    band = pts[~is_floor]
    band = band[(band[:, 2] >= emb.h_min) & (band[:, 2] <= emb.h_max)]
    fp_d = cKDTree(band[:, :2]).query(xy[ours & ~truth])[0] if fp and len(band) else np.zeros(0)
    return {"step_m": step, "points": len(xy), "scan_blocked": int(truth.sum()), "fn": fn, "fp": fp,
            "fn_rate": fn / max(int(truth.sum()), 1), "fp_rate": fp / max(int((~truth).sum()), 1),
            "fp_distance_m": {"p10_p50_p90": np.percentile(fp_d, [10, 50, 90]).round(3).tolist() if len(fp_d) else None,
                              "share_within_radius_plus_0.1": float(np.mean(fp_d <= emb.radius + 0.1)) if len(fp_d) else None}}


def measure(scan: Path, poses: int, seed: int = 0) -> dict:
    """The pipeline up to the costmap on the scan, with a map for every embodiment, then `rates`
    for the main one, and under "embodiments" for each (its own radius and body band)."""
    from benchmarks.goals.semantics_real import prepare_scan
    from navcore.nav.embodiment import embodiment_names, load_embodiment

    names = embodiment_names()
    with tempfile.TemporaryDirectory() as tmp:
        catalog, scene, cfg = prepare_scan(scan, Path(tmp), scan.name,
                                           overrides=(f"costmap.embodiments=[{','.join(names)}]",))
        per = {n: rates(catalog, scene, load_embodiment(n), poses, seed) for n in names}
        return {**per[cfg.embodiment.name], "embodiments": per}


def measure_model(model: Path, scan: Path, poses: int, seed: int = 0, overrides: tuple[str, ...] = (),
                  stage: str = "screen", keep_map: bool = False) -> dict:
    """A 3DGS trained in the scan's frame (benchmarks.captures.train_on_scan: model.ply with its
    cameras.json) through the pipeline up to the screen stage; its costmap against the scan's
    points moved by the model's own alignment (the body band measured from the scanned floor; also
    from the model's z = 0, which adds the alignment's floor offset), the aligned scan floor's
    height and tilt, and the screen stage's score (stage="costmap": no screening). `overrides`: more
    config overrides; keep_map: the costmap itself under "map"."""
    from omegaconf import OmegaConf

    from benchmarks.goals.semantics_real import prepare_scan

    with tempfile.TemporaryDirectory() as tmp:
        catalog, scene, cfg = prepare_scan(model, Path(tmp), "scannet_trained", fmt=None, stage=stage,
                                           group="real_trained", overrides=overrides)
        emb = OmegaConf.to_object(cfg.embodiment)
        t = catalog.dataset("aligned", scene).transform()
        pts = np.load(scan / "coord.npy").astype(np.float64) @ t[:3, :3].T + t[:3, 3]
        names = (scan / "classes.txt").read_text().splitlines()
        is_floor = np.load(scan / "segment.npy") == names.index("floor")
        fl = pts[is_floor]
        a = np.c_[fl[:, :2], np.ones(len(fl))]
        coef = np.linalg.lstsq(a, fl[:, 2], rcond=None)[0]  # the scanned floor's plane in the model's frame
        gs, _ = catalog.dataset("aligned", scene).load(view_dependent=False)
        qattrs = catalog.dataset("quality", scene).load_layers()[1] if stage == "screen" else {}
        align = catalog.dataset("alignment", scene).load()
        cm = catalog.dataset("costmaps", scene).load(emb.name)
        above = pts.copy()  # heights above the scanned floor: the body band is measured from the real floor
        above[:, 2] -= np.c_[pts[:, :2], np.ones(len(pts))] @ coef
        return {"scene": "scannet_scene0000_02, trained 3DGS", "gaussians": len(gs),
                "scan_floor_height_m": float(np.median(fl[:, 2])),
                "scan_floor_tilt_deg": float(np.degrees(np.arctan(np.hypot(*coef[:2])))),
                "cameras": bool(align.get("cameras")),
                "screen": {k: qattrs[k] for k in qattrs if k.endswith("_share") or k in ("score", "capture_cameras")},
                **compare(cm, above, is_floor, emb, poses, seed),
                "in_aligned_heights": {k: v for k, v in compare(cm, pts, is_floor, emb, poses, seed).items()
                                       if k in ("fp", "fn", "fp_rate", "fn_rate", "fp_ci95", "fn_ci95")},
                **({"map": cm} if keep_map else {})}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scan", action="append", required=True)
    ap.add_argument("--model", default=None, help="a trained model.ply in the (first) scan's frame "
                                                   "(benchmarks.captures.train_on_scan): its costmap against the scan")
    ap.add_argument("--poses", type=int, default=4000)
    ap.add_argument("--out", default="data/08_reports")
    args = ap.parse_args(argv)
    from benchmarks import machine

    rep = {"machine": machine(), "scans": [measure(Path(s).resolve(), args.poses) for s in args.scan]}
    if args.model:
        rep["scans"].append(measure_model(Path(args.model).resolve(), Path(args.scan[0]).resolve(), args.poses))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "scan_truth.json").write_text(jsonio.dumps(rep, indent=1))
    for s in [e for r in rep["scans"] for e in r.get("embodiments", {r["embodiment"]: r}).values()]:
        print(f"{s['scene']} ({s['embodiment']}): FP {s['fp_rate']:.1%} ({s['fp']}/{s['scan_free']}, "
              f"95 % {s['fp_ci95'][0]:.1%}-{s['fp_ci95'][1]:.1%}) "
              f"FN {s['fn_rate']:.2%} ({s['fn']}/{s['scan_blocked']}, 95 % {s['fn_ci95'][0]:.2%}-{s['fn_ci95'][1]:.2%}); "
              f"area: FP {s['cells']['fp_rate']:.1%} FN {s['cells']['fn_rate']:.2%}")
    return rep


if __name__ == "__main__":
    main()
