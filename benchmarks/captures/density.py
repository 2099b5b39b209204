"""The costmap's robustness to the density of a model (issue 84): the same room at several densities.

A 3DGS from another pipeline is often pruned hard (SceneSplat's ScanNet rooms: about 81 k Gaussians for
a 7.8 x 8.3 m room, median scale 4-8 mm, 1 % above 17-23 cm, median opacity 0.45), where the 3DGS
trained here has 600 k. This builds, from one model in the frame of a labelled scan:
- pruned versions that keep the most important Gaussians, importance = opacity x volume (the score
  compact 3DGS pipelines prune by: LightGaussian's global significance without the view term), down to
  a share (50, 25, 12 %) or a count (81 k);
- a SceneSplat-like version: pruned to 81 k, then each Gaussian's scales multiplied so that their
  largest follows a log-normal of median 6 mm and 99th percentile 20 cm, and its opacity replaced, rank
  for rank, by a Beta(0.8, 0.95) draw (median 0.45, many nearly transparent): the statistics the
  held-out scan was reported with;
and measures each one's costmap against the scan (benchmarks.captures.scan_truth: FN and FP per pose
and per area, at each map resolution) and its agreement with the full model's map (the share of the
full map's blocked and free cells that keep their state).

    python -m benchmarks.captures.density [--model data/trained_scan/model.ply] [--scan SCAN] [--docs]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import machine, write_report
from benchmarks.pages import write_page

SHARES = (1.0, 0.5, 0.25, 0.12)
SCENESPLAT_COUNT = 81_369
"""The held-out SceneSplat room's Gaussian count (issue 84)."""
RESOLUTIONS = (0.05, 0.02)


def importance(gs) -> np.ndarray:
    """Opacity x volume (product of the three standard deviations) of each Gaussian."""
    return gs.alphas * np.exp(gs.log_scales.astype(np.float64).sum(1))


def prune(gs, keep: int):
    """The `keep` most important Gaussians (ties: the earlier one), in their original order."""
    keep = int(min(max(keep, 1), len(gs.means)))
    order = np.lexsort((np.arange(len(gs.means)), -importance(gs)))
    return gs.subset(np.sort(order[:keep]))


def scenesplat_like(gs, count: int = SCENESPLAT_COUNT, seed: int = 0, median_scale: float = 0.006,
                    p99_scale: float = 0.2, beta: tuple[float, float] = (0.8, 0.95)):
    """Pruned to `count`, then scales and opacities mapped rank for rank onto the held-out scan's
    reported statistics (module doc); means, rotations, anisotropy and colours kept."""
    from scipy import stats

    from navcore.gaussians.model import GaussianScene

    g = prune(gs, count)
    n = len(g.means)
    rng = np.random.default_rng(seed)
    q = (np.arange(n) + 0.5) / n
    sigma = np.log(p99_scale / median_scale) / stats.norm.ppf(0.99)
    target_scale = np.exp(np.log(median_scale) + sigma * stats.norm.ppf(q))
    largest = g.log_scales.max(1).astype(np.float64)
    rank = np.empty(n, np.int64)
    rank[np.lexsort((np.arange(n), largest))] = np.arange(n)
    log_scales = g.log_scales + (np.log(target_scale[rank]) - largest)[:, None]
    target_alpha = np.sort(rng.beta(*beta, n).clip(1e-3, 0.999))
    arank = np.empty(n, np.int64)
    arank[np.lexsort((np.arange(n), g.alphas))] = np.arange(n)
    alpha = target_alpha[arank]
    return GaussianScene(g.means, g.quats, log_scales, np.log(alpha / (1 - alpha)), g.sh, dict(g.extras))


def statistics(gs) -> dict:
    s = np.exp(gs.log_scales.max(1).astype(np.float64))
    return {"gaussians": int(len(gs.means)), "median_largest_scale_m": round(float(np.median(s)), 4),
            "p99_largest_scale_m": round(float(np.percentile(s, 99)), 3),
            "median_opacity": round(float(np.median(gs.alphas)), 3),
            "share_opacity_below_0.1": round(float(np.mean(gs.alphas < 0.1)), 3)}


def versions(gs, shares=SHARES, seed: int = 0) -> dict:
    """{name: scene} of the module doc."""
    out = {f"{round(s * 100)} %": gs if s >= 1 else prune(gs, round(len(gs.means) * s)) for s in shares}
    out[f"{SCENESPLAT_COUNT // 1000} k, pruned"] = prune(gs, SCENESPLAT_COUNT)
    out[f"{SCENESPLAT_COUNT // 1000} k, SceneSplat-like"] = scenesplat_like(gs, seed=seed)
    return out


def agreement(a, b) -> dict:
    """Agreement of costmap b with costmap a (navcore.nav.costmap.Costmap, or a build's layers): the share
    of a's blocked / free supported cells to which b gives the same state (queried at a's cell centres)."""
    from navcore.nav.costmap import Costmap

    a, b = (m if hasattr(m, "are_states_valid") else Costmap.from_layers(m) for m in (a, b))
    ny, nx = a.clearance.shape
    jj, ii = np.meshgrid(np.arange(nx), np.arange(ny))
    xy = np.column_stack([a.origin[0] + (jj.ravel() + 0.5) * a.resolution, a.origin[1] + (ii.ravel() + 0.5) * a.resolution])
    sup = a.clearance.ravel() >= 0
    occ_a, occ_b = ~a.are_states_valid(xy), ~b.are_states_valid(xy)
    blocked, free = sup & occ_a, sup & ~occ_a
    return {"blocked_kept": float(occ_b[blocked].mean()) if blocked.any() else float("nan"),
            "free_kept": float((~occ_b[free]).mean()) if free.any() else float("nan")}


CONFIGS = {"defaults": (), "cell evidence": ("costmap.cell_evidence=true",),
           "cell evidence + density radius": ("costmap.cell_evidence=true", "costmap.outlier_density=2.8"),
           "surface + dense-only noise": ("costmap.evidence=surface", "costmap.noise_dense_count=30"),
           "surface, reach 0.2 spacing, + dense-only noise": ("costmap.evidence=surface", "costmap.noise_dense_count=30",
                                                              "costmap.surface_reach_spacing=0.2")}
"""The costmap settings measured: the defaults and the sparse-evidence options (stages/costmap/build.py)."""


def measure(model: Path, scan: Path, poses: int, resolutions=RESOLUTIONS, seed: int = 0, configs=None) -> dict:
    """Every version of the model at every resolution and costmap setting against the scan (module doc)."""
    from benchmarks.captures.scan_truth import measure_model
    from navcore.gaussians.formats.ply import read_ply, write_inria_ply

    gs = read_ply(model)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, scene in versions(gs, seed=seed).items():
            path = Path(tmp) / f"{name.replace(' ', '_').replace('%', 'pc').replace(',', '')}.ply"
            write_inria_ply(path, scene)
            for (label, extra), res in ((c, r) for c in (configs or CONFIGS).items() for r in resolutions):
                t0 = time.perf_counter()
                m = measure_model(path, scan, poses, seed, overrides=(f"costmap.resolution={res}", *extra), keep_map=True)
                cm = m.pop("map")
                rows.append({"version": name, "config": label, "resolution_m": res, **statistics(scene),
                             "fn_rate": m["fn_rate"], "fp_rate": m["fp_rate"], "fn": m["fn"], "fp": m["fp"],
                             "scan_blocked": m["scan_blocked"], "scan_free": m["scan_free"],
                             "area_fn_rate": m["cells"]["fn_rate"], "area_fp_rate": m["cells"]["fp_rate"],
                             "fp_distance_m": m["cells"]["fp_distance_m"], "seconds": round(time.perf_counter() - t0, 1),
                             "_map": cm})
    for r in rows:  # against the full model's map at the same resolution and setting
        full = next(f for f in rows if f["resolution_m"] == r["resolution_m"] and f["config"] == r["config"])
        r["agreement"] = agreement(full["_map"], r["_map"])
    for r in rows:
        del r["_map"]
    return {"model": str(model), "scan": str(scan), "poses": poses, "rows": rows}


def markdown(rep: dict, machine_name: str) -> str:
    L = [f"# bench-density: the costmap at several densities of one room ({machine_name})", "",
         __doc__.split("\n\n")[1].replace("\n", " "), "",
         f"Model: `{rep['model']}`; truth: `{rep['scan']}` ({rep['poses']} poses, LoCoBot: the body band from the "
         "scanned floor).", "",
         "| version | costmap | map (m) | Gaussians | median / p99 scale (m) | median opacity | FN | FP | area FN | area FP | "
         "FP cells' distance to the scan p10 / p50 / p90 (m) | blocked kept | free kept | s |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rep["rows"]:
        a = r["agreement"]
        fpd = (r["fp_distance_m"] or {}).get("p10_p50_p90") or ["-"] * 3
        L.append(f"| {r['version']} | {r['config']} | {r['resolution_m']} | {r['gaussians']:,} | {r['median_largest_scale_m']} / "
                 f"{r['p99_largest_scale_m']} | {r['median_opacity']} | {r['fn_rate']:.2%} | {r['fp_rate']:.1%} | "
                 f"{r['area_fn_rate']:.2%} | {r['area_fp_rate']:.1%} | {' / '.join(map(str, fpd))} | "
                 f"{a['blocked_kept']:.1%} | {a['free_kept']:.1%} | "
                 f"{r['seconds']} |")
    return "\n".join(L) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default="data/trained_scan/model.ply")
    ap.add_argument("--scan", default="../shared/data/real_labelled/scannet_scene0000_02")
    ap.add_argument("--poses", type=int, default=4000)
    ap.add_argument("--resolutions", default=",".join(map(str, RESOLUTIONS)))
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", action="store_true")
    a = ap.parse_args(argv)
    rep = measure(Path(a.model).resolve(), Path(a.scan).resolve(), a.poses,
                  tuple(float(x) for x in a.resolutions.split(",")))
    rep["robot_radius_m"] = 0.18
    rep["machine"] = machine()
    write_report(a.out, "bench_density.json", rep)
    md = markdown(rep, rep["machine"])
    print(md)
    if a.docs:
        write_page("bench_density.md", md)
    return rep


if __name__ == "__main__":
    main()
