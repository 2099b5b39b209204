"""The render check's per-ray hits on the CPU (numba) and on CUDA (PyTorch): the same poses of the
real scenes, their visible clearance from both, and the time each takes.

Two steps, so that the GPU machine needs only the scene files and this repository (no costmap,
no Zarr): `prepare` samples the check's poses on a data root's costmaps (as bench-real does) and
writes, per scene, the alignment transform and the poses (JSON); `run` reads an SPZ / PLY / SOG
source, aligns it with that transform, keeps its content (ingest's rule) and computes the visible
clearance at the poses with every backend this machine has (cpu when numba imports, cuda when
torch sees a GPU), repeated, writing the clearances and the median seconds; `compare` reads two
such outputs (or one with both backends) and reports the agreement.
  python -m benchmarks.captures.render_check_gpu prepare --data data --out OUT [--poses 200]
  python -m benchmarks.captures.render_check_gpu run OUT --source NAME=PATH ... [--repeats 3]
  python -m benchmarks.captures.render_check_gpu compare RESULT.json [RESULT2.json]
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

from navcore.io import jsonio


def prepare(data: str, out: Path, poses: int) -> None:
    from omegaconf import OmegaConf

    from benchmarks.captures.real import compose
    from navcore.io.catalog import Catalog
    from pipeline.config import CONF_DIR
    from stages.costmap.render_check import RenderCheckConfig, sample_poses

    cfg = compose(data)
    catalog = Catalog(CONF_DIR.parent / cfg.scenes.catalog, data)
    emb = OmegaConf.to_object(cfg.embodiment)
    out.mkdir(parents=True, exist_ok=True)
    for scene in catalog.select():
        cm = catalog.dataset("costmaps", scene).load(emb.name)
        align = catalog.dataset("alignment", scene).load()
        xy = sample_poses(cm, poses, RenderCheckConfig().seed)
        (out / f"{scene.name}.json").write_text(jsonio.dumps({
            "scene": scene.name, "transform": align["source_to_aligned"], "xy": xy.tolist(), "embodiment": vars(emb)}))
        print(f"{scene.name}: {len(xy)} poses")


def load_scene(path: str, transform) -> "object":
    from navcore.gaussians.content import content_mask
    from navcore.gaussians.formats import read_gaussians

    g = read_gaussians(path, None)
    g = g.transformed(np.asarray(transform, np.float64))
    mask, _ = content_mask(g.means)
    return g.subset(mask)


def backends() -> list[str]:
    out = []
    try:
        import numba  # noqa: F401

        out.append("cpu")
    except ImportError:
        pass
    try:
        import torch

        if torch.cuda.is_available():
            out.append("cuda")
    except ImportError:
        pass
    return out


def run(folder: Path, sources: dict[str, str], repeats: int, out: Path) -> dict:
    from navcore.nav.embodiment import Embodiment
    from stages.costmap.render_check import RenderCheckConfig, local_floor, visible_clearance

    cfg = RenderCheckConfig()
    rep = {"machine": f"{platform.machine()} {platform.node()}", "backends": backends(), "scenes": {}}
    try:
        import torch

        if torch.cuda.is_available():
            rep["gpu"] = torch.cuda.get_device_name(0)
    except ImportError:
        pass
    for name, path in sources.items():
        spec = json.loads((folder / f"{name}.json").read_text())
        emb = Embodiment(**spec["embodiment"])
        xy = np.asarray(spec["xy"])
        t0 = time.perf_counter()
        gs = load_scene(path, spec["transform"])
        row = {"gaussians": len(gs), "poses": len(xy), "read_s": round(time.perf_counter() - t0, 2)}
        for be in rep["backends"]:
            times, vis = [], None
            for _ in range(repeats + 1):  # the first run compiles / warms up
                t0 = time.perf_counter()
                floor = local_floor(gs, xy, emb, cfg, be)
                vis = visible_clearance(gs, xy, emb, cfg, be, floor)
                times.append(time.perf_counter() - t0)
            row[be] = {"median_s": float(np.median(times[1:])), "first_s": times[0], "visible_clearance":
                       [None if not np.isfinite(v) else float(v) for v in vis], "floor": floor.tolist()}
            print(f"{name} {be}: {row[be]['median_s']:.2f} s median of {repeats} ({len(xy)} poses)", flush=True)
        rep["scenes"][name] = row
    out.write_text(jsonio.dumps(rep))
    return rep


def compare(results: list[dict]) -> dict:
    """Per scene: each backend's median seconds, the largest visible-clearance difference and the
    share of poses with the same verdict (clearance below the robot radius 0.18 m)."""
    merged: dict = {}
    for r in results:
        for name, row in r["scenes"].items():
            for be in r["backends"]:
                merged.setdefault(name, {})[be] = row[be] | {"machine": r.get("gpu") if be == "cuda" else r["machine"]}
    out = {}
    for name, by in merged.items():
        row = {be: {"median_s": round(v["median_s"], 3), "machine": v["machine"]} for be, v in by.items()}
        if {"cpu", "cuda"} <= set(by):
            a = np.array([np.inf if v is None else v for v in by["cpu"]["visible_clearance"]])
            b = np.array([np.inf if v is None else v for v in by["cuda"]["visible_clearance"]])
            fin = np.isfinite(a) & np.isfinite(b)
            row["same_finite"] = float((np.isfinite(a) == np.isfinite(b)).mean())
            row["max_abs_diff_m"] = float(np.abs(a[fin] - b[fin]).max()) if fin.any() else 0.0
            row["same_verdict"] = float(((a < 0.18) == (b < 0.18)).mean())
            row["speedup_cuda_vs_cpu"] = round(by["cpu"]["median_s"] / by["cuda"]["median_s"], 1)
        out[name] = row
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("prepare")
    p.add_argument("--data", default="data")
    p.add_argument("--out", required=True)
    p.add_argument("--poses", type=int, default=200)
    r = sub.add_parser("run")
    r.add_argument("folder")
    r.add_argument("--source", action="append", required=True, help="NAME=PATH (NAME: a prepared scene)")
    r.add_argument("--repeats", type=int, default=3)
    r.add_argument("--out", default="render_check_gpu.json")
    c = sub.add_parser("compare")
    c.add_argument("results", nargs="+")
    args = ap.parse_args(argv)
    if args.cmd == "prepare":
        prepare(args.data, Path(args.out), args.poses)
    elif args.cmd == "run":
        run(Path(args.folder), dict(s.split("=", 1) for s in args.source), args.repeats, Path(args.out))
    else:
        print(json.dumps(compare([json.loads(Path(f).read_text()) for f in args.results]), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
