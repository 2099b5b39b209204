"""bench-semantics: precision of the semantic layer on synthetic scenes, what each lifting step buys,
and its time per scene.

For each of N procedural scenes (seeds first_seed..; 300 k Gaussians; the 81-ish capture cameras
of each scene as covering poses, rendered at the stage's default 320x240):
- the views are rendered once (RGB-D and the per-Gaussian ground-truth labels in the same pass);
  the oracle's instance map of each view is spoiled by the corruption model at each level (none,
  moderate, heavy: stages/semantics/segmenters.py CORRUPTION_LEVELS), seeded per (scene, level);
- each lifting variant lifts the same masks: the full method, one ablation per step (no erosion,
  no voting, no tie exclusion, votes counted per point instead of per view) and the naive
  baseline (cluster all back-projected mask points per category: no erosion, voting or ties);
- valid-centre rate (predicted centres inside the ground-truth oriented box of an object of the
  predicted category, over all scenes) and recall (ground-truth objects that got a valid centre);
- time per scene: the stage's own path (stages.semantics.stage.predict_instances: render, oracle
  segmentation at moderate, lifting), median over the timed scenes.

Writes data/08_reports/bench_semantics.json and bench_semantics.md (and semantics_gpu.json with
--gpu, merged into the report by a CPU run or --merge-gpu).
    python -m benchmarks.goals.semantics [--scenes 10] [--timed 2] [--jobs 2] [--out data/08_reports]
    python -m benchmarks.goals.semantics --gpu --timed 3 --jobs 8 --out $OUT         (CUDA machine)
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import time
from pathlib import Path

import numpy as np

from benchmarks import machine
from benchmarks.pages import write_page
from navcore.gaussians.cameras import cameras_from_json
from navcore.io import jsonio
from navcore.render import Renderer
from stages.semantics.config import SemanticsConfig
from stages.semantics.lifting import lift
from stages.semantics.precision import score
from stages.semantics.segmenters import CORRUPTION_LEVELS, OracleSegmenter, corrupt
from stages.semantics.stage import category_masks, predict_instances, render_views
from stages.synthesize.generate import SyntheticConfig, generate_scene, object_records

LEVELS = ("none", "moderate", "heavy")
VARIANTS = {
    "full": {},
    "no erosion": {"erosion_px": 0},
    "no voting": {"voting": False},
    "no tie exclusion": {"exclude_ties": False},
    "votes per point": {"support": "points"},
    "naive baseline": {"erosion_px": 0, "voting": False, "exclude_ties": False},
}


def level_seed(seed: int, level: str) -> int:
    return int.from_bytes(hashlib.sha256(f"bench-semantics:{seed}:{level}".encode()).digest()[:8], "little")


def scene_inputs(seed: int, num_gaussians: int, scfg: SemanticsConfig):
    """(synthetic scene, ground-truth objects, cameras -> world, Ks), source frame."""
    s = generate_scene(seed, SyntheticConfig(num_gaussians=num_gaussians))
    c2w, ks = cameras_from_json({"hfov_deg": 90.0, "poses": s.cameras}, scfg.width, scfg.height)
    return s, object_records(s.layout), c2w, ks


def bench_scene(seed: int, args, scfg: SemanticsConfig, timed: bool) -> dict:
    s, objects, c2w, ks = scene_inputs(seed, args.num_gaussians, scfg)
    renderer = Renderer(s.gaussians, args.renderer)
    prompts = [scfg.prompt(c) for c in scfg.categories]
    cats = {o["instance_id"]: scfg.prompt(o["category"]) for o in objects}
    to_canonical = np.linalg.inv(s.transform)
    means = s.gaussians.means
    out = {"seed": seed, "views": len(c2w), "objects": len(objects), "renderer": renderer.backend}
    if timed:  # the stage's own path, oracle at moderate
        if renderer.backend == "gsplat":  # the first call compiles / warms up the kernels
            next(render_views(renderer, c2w[:2], ks[:2], scfg))
        oracle = OracleSegmenter(renderer, s.instance_ids, cats, "moderate", seed)
        _, _, timings = predict_instances(renderer, oracle, c2w, ks, means, scfg)
        out["seconds"] = {k: round(v, 3) for k, v in timings.items()}
    oracle = OracleSegmenter(renderer, s.instance_ids, cats, "none", seed)
    views = []
    t0 = time.perf_counter()
    for rgb, depth, extra, vm, kk, cw in render_views(renderer, c2w, ks, scfg, oracle.gaussian_features):
        for i in range(len(vm)):
            views.append((depth[i], kk[i], cw[i], oracle.instance_map(vm[i], kk[i], scfg.width, scfg.height, extra[i])))
    out["render_s"] = round(time.perf_counter() - t0, 3)
    out["levels"] = {}
    for level in LEVELS:
        rng = np.random.default_rng(level_seed(seed, level))
        frames = [(d, k, c, category_masks(corrupt(imap, cats, prompts, CORRUPTION_LEVELS[level], rng), prompts))
                  for d, k, c, imap in views]
        res = {}
        for name, change in VARIANTS.items():
            lcfg = dataclasses.replace(scfg.lifting, **change)
            cands = lift(frames, means, lcfg)
            pred = [{"category": scfg.categories[c["label"]], "position": c["center"]} for c in cands]
            r = score(pred, objects, scfg.categories, to_canonical)
            res[name] = {k: r[k] for k in ("predicted", "valid", "objects", "found")}
        out["levels"][level] = res
    return out


def summarise(scenes: list[dict]) -> dict:
    """Valid-centre rate and recall per level and variant over all scenes (pooled counts)."""
    table = {}
    for level in LEVELS:
        for name in VARIANTS:
            rows = [s["levels"][level][name] for s in scenes]
            p, v = sum(r["predicted"] for r in rows), sum(r["valid"] for r in rows)
            o, f = sum(r["objects"] for r in rows), sum(r["found"] for r in rows)
            table.setdefault(name, {})[level] = {"valid_center_rate": v / p if p else float("nan"),
                                                  "recall": f / o if o else float("nan"),
                                                  "predicted": p, "valid": v, "objects": o, "found": f}
    return table


def sam3_timing(args, scfg: SemanticsConfig) -> dict:
    """Seconds per scene with the sam3 segmenter (the stage's path: render, SAM3 on every view for all
    prompts, lifting) on the timed scenes. Random weights and a byte-level vocabulary: the forward
    passes cost what the trained model's do; the masks mean nothing (timing only)."""
    import tempfile

    import torch

    from stages.semantics.sam3_segmenter import BPE_FILE, Sam3Segmenter, build_model, write_byte_vocabulary

    with tempfile.TemporaryDirectory() as d:
        torch.manual_seed(0)
        model = build_model(None, str(write_byte_vocabulary(Path(d) / BPE_FILE)), "cuda")
    seg = Sam3Segmenter(model=model, device="cuda", confidence=scfg.sam3.confidence, batch=scfg.sam3.batch)
    rows = []
    for i in range(args.timed):
        s, objects, c2w, ks = scene_inputs(args.first_seed + i, args.num_gaussians, scfg)
        renderer = Renderer(s.gaussians, "gsplat")
        if i == 0:  # warm-up: kernels and cuDNN plans
            seg.segment_batch(np.zeros((scfg.sam3.batch, scfg.height, scfg.width, 3), np.uint8), ["chair"], [{}] * scfg.sam3.batch)
        torch.cuda.synchronize()
        _, _, t = predict_instances(renderer, seg, c2w, ks, s.gaussians.means, scfg)
        rows.append({"views": len(c2w), **{k: round(v, 3) for k, v in t.items()}})
    return {"scenes": rows, "seconds_per_scene": float(np.median([r["total"] for r in rows])),
            "frames_per_s": float(np.median([r["views"] / r["segment"] for r in rows])),
            "prompts": len(scfg.categories), "batch": scfg.sam3.batch, "resolution": scfg.sam3.resolution}


def _untimed(seed_args):
    seed, args = seed_args
    return bench_scene(seed, args, SemanticsConfig(), False)


def run(args) -> dict:
    """Timed scenes one after the other in this process (no contention), the rest over `jobs`
    processes."""
    scfg = SemanticsConfig()
    seeds = [args.first_seed + i for i in range(args.scenes)]
    scenes = []
    for seed in seeds[:args.timed]:
        t = time.perf_counter()
        scenes.append(bench_scene(seed, args, scfg, True))
        print(f"scene seed {seed} (timed): {time.perf_counter() - t:.1f} s", flush=True)
    rest = [(seed, args) for seed in seeds[args.timed:]]
    if args.jobs > 1 and len(rest) > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(min(args.jobs, len(rest)), mp_context=mp.get_context("spawn")) as ex:
            scenes += list(ex.map(_untimed, rest))
    else:
        scenes += [_untimed(r) for r in rest]
    table = summarise(scenes)
    sam3 = sam3_timing(args, scfg) if args.sam3_timing else None
    secs = [s["seconds"]["total"] for s in scenes if "seconds" in s]
    full = table["full"]
    res = {
        "machine": machine(), "device": device_name(), "renderer": scenes[0]["renderer"],
        "scenes": args.scenes, "num_gaussians": args.num_gaussians, "first_seed": args.first_seed,
        "resolution": [scfg.width, scfg.height], "views_per_scene": float(np.mean([s["views"] for s in scenes])),
        "corruption_levels": {k: dataclasses.asdict(v) for k, v in CORRUPTION_LEVELS.items()},
        "valid_center_rate": {lv: full[lv]["valid_center_rate"] for lv in LEVELS},
        "recall": {lv: full[lv]["recall"] for lv in LEVELS},
        "baseline_valid_center_rate": {lv: table["naive baseline"][lv]["valid_center_rate"] for lv in LEVELS},
        "baseline_recall": {lv: table["naive baseline"][lv]["recall"] for lv in LEVELS},
        "variants": table,
        "seconds_per_scene": float(np.median(secs)) if secs else None,
        "seconds_breakdown": {k: float(np.median([s["seconds"][k] for s in scenes if "seconds" in s]))
                              for k in ("render", "segment", "lift")} if secs else None,
        "sam3_timing": sam3,
        "per_scene": scenes,
    }
    return res


def device_name() -> str:
    import torch

    return torch.cuda.get_device_name(0) if torch.cuda.is_available() else "cpu"


def markdown(rep: dict) -> str:
    pct = lambda x: f"{100 * x:.1f} %"  # noqa: E731
    lines = ["# bench-semantics", "",
             f"{rep['scenes']} synthetic scenes (seeds {rep['first_seed']}..), {rep['num_gaussians']} Gaussians, "
             f"{rep['views_per_scene']:.0f} capture views each at {rep['resolution'][0]}x{rep['resolution'][1]}; "
             f"metrics from the {rep['renderer']} run on {rep['device']}.", "",
             "Valid-centre rate (predicted centres inside a ground-truth object of their category) / recall "
             "(ground-truth objects that got one), pooled over scenes:", "",
             "| lifting | " + " | ".join(f"{lv}: valid / recall" for lv in LEVELS) + " | predicted (moderate) |",
             "|---|" + "---|" * (len(LEVELS) + 1)]
    for name, row in rep["variants"].items():
        cells = [f"{pct(row[lv]['valid_center_rate'])} / {pct(row[lv]['recall'])}" for lv in LEVELS]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {row['moderate']['predicted']} |")
    lines += ["", "Corruption levels (per object and frame): " + "; ".join(
        f"{k}: bleed {v['bleed_px']} px, miss {v['miss_rate']}, confusion {v['confusion_rate']}, "
        f"false-positive blobs {v['fp_blobs']}/frame" for k, v in rep["corruption_levels"].items()), "",
        "Time per scene (render + segment + lift, oracle at moderate, median):", "",
        "| machine | renderer | seconds per scene | render | segment | lift |", "|---|---|---|---|---|---|"]
    for key in ("gpu", "cpu"):
        t = rep.get(f"timing_{key}")
        if t:
            b = t["breakdown"]
            lines.append(f"| {t['device']} ({t['machine']}) | {t['renderer']} | {t['seconds']:.2f} | "
                         f"{b['render']:.2f} | {b['segment']:.2f} | {b['lift']:.2f} |")
    sam3 = rep.get("sam3_timing")
    if sam3:
        lines.append(f"| {rep['device']} | gsplat + sam3 (random weights: timing only), {sam3['prompts']} prompts, "
                     f"batch {sam3['batch']} | {sam3['seconds_per_scene']:.1f} | | "
                     f"{sam3['frames_per_s']:.1f} frames/s | |")
    cpu = rep.get("cpu_run")
    if cpu:
        same = all(cpu[k] == rep[k] for k in ("valid_center_rate", "recall", "baseline_valid_center_rate"))
        lines += ["", f"CPU-renderer run on the same {cpu['scenes']} scenes: valid-centre rate and recall "
                  + ("identical to the GPU run's at every level." if same else
                     f"{cpu['valid_center_rate']} / {cpu['recall']} (differs from the GPU run).")]
    return "\n".join(lines) + "\n"


def timing(rep: dict) -> dict:
    return {"seconds": rep["seconds_per_scene"], "breakdown": rep["seconds_breakdown"], "device": rep["device"],
            "machine": rep["machine"], "renderer": rep["renderer"]}


def write_report(out: Path, cpu: dict | None, gpu: dict | None, docs: bool = True) -> dict:
    """The report: metrics from the GPU run when there is one (same code; the renderers agree to
    > 75 dB), timings from both; docs: also docs/benchmarks/bench_semantics.md."""
    base = dict(gpu or cpu)
    base.pop("per_scene", None)
    base["timing_gpu"] = timing(gpu) if gpu else None
    base["timing_cpu"] = timing(cpu) if cpu else None
    base["seconds_per_scene_gpu"] = gpu["seconds_per_scene"] if gpu else None
    base["seconds_per_scene_cpu"] = cpu["seconds_per_scene"] if cpu else None
    if cpu and gpu:
        base["cpu_run"] = {k: cpu[k] for k in ("scenes", "valid_center_rate", "recall", "baseline_valid_center_rate")}
    (out / "bench_semantics.json").write_text(jsonio.dumps(base, indent=1))
    md = markdown(base)
    (out / "bench_semantics.md").write_text(md)
    if docs:
        write_page("bench_semantics.md", md)
    return base


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", type=int, default=10)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--timed", type=int, default=2, help="scenes also timed through the stage's path")
    ap.add_argument("--num-gaussians", type=int, default=300_000)
    ap.add_argument("--renderer", default="auto")
    ap.add_argument("--jobs", type=int, default=1, help="processes for the untimed scenes")
    ap.add_argument("--sam3-timing", action="store_true", help="CUDA + sam3: also time the sam3 segmenter")
    ap.add_argument("--sam3-only", action="store_true",
                    help="CUDA + sam3: time the sam3 segmenter alone and fold it into semantics_gpu.json")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--gpu", action="store_true", help="CUDA run: write semantics_gpu.json only")
    ap.add_argument("--merge-gpu", action="store_true", help="only fold semantics_gpu.json into the report")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    gpu_file, cpu_file = out / "semantics_gpu.json", out / "semantics_cpu.json"
    if args.sam3_only:  # fold a sam3 timing into the GPU report already there (a machine with the sam3 extra)
        rep = json.loads(gpu_file.read_text())
        rep["sam3_timing"] = sam3_timing(args, SemanticsConfig())
        gpu_file.write_text(jsonio.dumps(rep, indent=1))
        return rep
    if args.gpu:
        rep = run(args)
        gpu_file.write_text(jsonio.dumps(rep, indent=1))
        return rep
    if not args.merge_gpu:
        cpu_file.write_text(jsonio.dumps(run(args), indent=1))
    load = lambda p: json.loads(p.read_text()) if p.exists() else None  # noqa: E731
    rep = write_report(out, load(cpu_file), load(gpu_file))
    print(markdown(rep))
    return rep


if __name__ == "__main__":
    main()
