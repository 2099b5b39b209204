"""The detector segmenter's rendering on a GPU: the same views of the real captures rendered with
gsplat and with the CPU renderer, seconds per scene.

Two steps, so that the GPU machine needs only the scene files and this repository (no costmap, no
Zarr, no OpenCV): `prepare` takes, per scene of a data root, the detector's covering views (the
semantics stage's free-space poses at detector.spacing / detector.yaw_step_deg, its camera and
render size) and writes them with the alignment transform (JSON); `run` reads an SPZ / PLY / SOG
source, aligns it and keeps its content (render_check_gpu.load_scene), renders every view in the
stage's batches with each renderer this machine has (gsplat on CUDA: all views, after a warm-up
batch that compiles the kernels; cpu: the first `--cpu-views` views, seconds scaled to all), and
writes the seconds. The detection and the lifting run on the CPU in either case (OpenCV DNN's CPU
path); their seconds come from the CPU run of the stage (docs/benchmarks/bench_semantics_detector.md).
  python -m benchmarks.goals.semantics_detector_gpu prepare --data data/real_indoor --out OUT
  python -m benchmarks.goals.semantics_detector_gpu run OUT --source NAME=PATH ... [--out FILE]
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.captures.render_check_gpu import load_scene
from navcore.io import jsonio


def prepare(data: str, out: Path) -> None:
    from omegaconf import OmegaConf

    from benchmarks.captures.real import compose
    from navcore.io.catalog import Catalog
    from pipeline.config import CONF_DIR
    from stages.semantics.stage import covering_cameras

    cfg = compose(data)
    catalog = Catalog(CONF_DIR.parent / cfg.scenes.catalog, data)
    emb = OmegaConf.to_object(cfg.embodiment)
    scfg = OmegaConf.to_object(cfg.semantics)
    scfg.segmenter, scfg.poses = "detector", "free_space"
    out.mkdir(parents=True, exist_ok=True)
    for scene in catalog.select():
        cm = catalog.dataset("costmaps", scene).load(emb.name)
        t = catalog.dataset("alignment", scene).load()["source_to_aligned"]
        c2w, ks, _ = covering_cameras(scene, catalog, scfg, emb, np.asarray(t), cm)
        (out / f"{scene.name}.json").write_text(jsonio.dumps({
            "scene": scene.name, "transform": t, "cam_to_world": c2w.tolist(), "K": ks.tolist(),
            "width": scfg.width, "height": scfg.height, "batch": scfg.batch, "min_alpha": scfg.min_alpha}))
        print(f"{scene.name}: {len(c2w)} views")


def backends() -> list[str]:
    import torch

    return (["gsplat"] if torch.cuda.is_available() else []) + ["cpu"]


def time_render(gs, spec: dict, backend: str, views: int) -> dict:
    """Seconds to render `views` of the spec's views (RGB-D, the stage's batches) on `backend`."""
    from types import SimpleNamespace

    from navcore.render import Renderer
    from stages.semantics.stage import render_views

    scfg = SimpleNamespace(batch=spec["batch"], width=spec["width"], height=spec["height"], min_alpha=spec["min_alpha"])
    c2w, ks = np.asarray(spec["cam_to_world"])[:views], np.asarray(spec["K"], np.float32)[:views]
    r = Renderer(gs, backend)
    for _ in render_views(r, c2w[:scfg.batch], ks[:scfg.batch], scfg):  # warm-up (gsplat compiles its kernels)
        pass
    t0 = time.perf_counter()
    n = sum(len(b[0]) for b in render_views(r, c2w, ks, scfg))
    return {"views": n, "seconds": time.perf_counter() - t0}


def run(folder: Path, sources: dict[str, str], cpu_views: int, out: Path) -> dict:
    import torch

    rep = {"machine": f"{platform.machine()} {platform.node()}", "cores": torch.get_num_threads(),
           "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None, "scenes": {}}
    if out.is_file():  # scenes run one at a time (a device that carries one capture a call): keep the others
        old = json.loads(out.read_text())
        if (old.get("machine"), old.get("gpu")) == (rep["machine"], rep["gpu"]):
            rep["scenes"] = old.get("scenes", {})
    for name, path in sources.items():
        spec = json.loads((folder / f"{name}.json").read_text())
        gs = load_scene(path, spec["transform"])
        total = len(spec["cam_to_world"])
        row = {"gaussians": len(gs), "views": total, "resolution": [spec["width"], spec["height"]]}
        for be in backends():
            t = time_render(gs, spec, be, total if be == "gsplat" else min(cpu_views, total))
            row[be] = {"views_timed": t["views"], "seconds": round(t["seconds"], 2),
                       "seconds_all_views": round(t["seconds"] * total / t["views"], 1)}
            print(f"{name} {be}: {t['views']} views in {t['seconds']:.1f} s", flush=True)
        rep["scenes"][name] = row
    out.write_text(jsonio.dumps(rep))
    return rep


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("prepare")
    p.add_argument("--data", default="data/real_indoor")
    p.add_argument("--out", required=True)
    r = sub.add_parser("run")
    r.add_argument("folder")
    r.add_argument("--source", action="append", required=True, help="NAME=PATH (NAME: a prepared scene)")
    r.add_argument("--cpu-views", type=int, default=64)
    r.add_argument("--out", default="semantics_detector_gpu.json")
    args = ap.parse_args(argv)
    if args.cmd == "prepare":
        prepare(args.data, Path(args.out))
    else:
        run(Path(args.folder), dict(s.split("=", 1) for s in args.source), args.cpu_views, Path(args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
