"""The CPU renderer's frame rate on this machine, against the plain-PyTorch reference renderer in
the same run: a 1 M-Gaussian synthetic scene and, when a data root with the real indoor scenes is
given, each real scene (aligned), robot views at the LoCoBot camera (random free-space poses), one
view per call. Per scene and size: `fps`, the throughput (views / their total time: what an
evaluation run sees), `fps_median` (1 / the median view's time) and `fps_p10` (the slowest tenth).
A real room's views cost 2-20 times one another (open views deep into the room against a wall
close by), so a median over 20 views moved by a third from one sample of poses to the next: 100
views by default. `cpu_fps_{160,640}`: the lowest throughput over the scenes of >= 1 M Gaussians.

    python -m benchmarks.scale.render_cpu [--real-root /tmp/real2] [--views 20] [--out data/08_reports]
        -> render_cpu.json
    python -m benchmarks.scale.render_cpu --against REV [--real-root ...]   -> render_cpu_ab.json
        the working tree's compiled renderer against git revision REV's, the two interleaved view
        by view in one process (the fair comparison on a shared machine), with how many frames
        came out identical to the byte, the lowest PSNR between the two and the largest median
        depth difference
    python -m benchmarks.scale.render_cpu --bound [--real-root ...]   -> render_cpu_bound.json
        what a perfect occlusion culling could give: per view, the frame rendered from the whole
        scene, then the same frame from only the Gaussians its rasteriser read (a box with an
        unfinished pixel in some tile), which must come out identical to the byte; throughputs
        of both, interleaved view by view
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

SIZES = ((160, 120), (640, 480))


def fps(renderer, vm, K, w, h) -> tuple[float, list[float]]:
    """Throughput (views / total seconds) of one view per call, and each view's seconds."""
    renderer.render(vm[:1], K[:1], w, h)  # warm-up (compiled kernels loaded)
    ts = []
    for i in range(len(vm)):
        t0 = time.perf_counter()
        renderer.render(vm[i:i + 1], K[i:i + 1], w, h)
        ts.append(time.perf_counter() - t0)
    return len(ts) / float(np.sum(ts)), ts


def scene_fps(gs, poses, emb, ref_views: int) -> dict:
    from navcore.render import Renderer
    from navcore.render.camera import embodiment_camera

    fast, ref = Renderer(gs, "cpu"), Renderer(gs, "torch")
    out = {"n_gaussians": len(gs.means), "views": len(poses)}
    for w, h in SIZES:
        vm, K, _, _ = embodiment_camera(emb, poses, w, h)
        f, ts = fps(fast, vm, K, w, h)
        fr, _ = fps(ref, vm[:ref_views], K[:ref_views], w, h)
        out[f"{w}x{h}"] = {"fps": f, "fps_median": 1.0 / float(np.median(ts)),
                           "fps_p10": 1.0 / float(np.percentile(ts, 90)), "torch_reference_fps": fr, "speedup": f / fr}
        print(w, h, out[f"{w}x{h}"], flush=True)
    return out


def revision_renderer(rev: str):
    """The compiled CPU renderer as it was at git revision rev, imported as its own module: the
    single file navcore/render/cpu_fast.py of older revisions, or the package navcore/render/cpu_fast/
    (its modules copied under a package name of their own, their imports of each other rewritten)."""
    import importlib
    import importlib.util
    import subprocess
    import sys
    import tempfile

    root = Path(__file__).resolve().parents[2]
    git = lambda *a: subprocess.run(["git", *a], cwd=root, capture_output=True, text=True)  # noqa: E731
    tmp = Path(tempfile.mkdtemp(prefix="navarena_rev_"))
    one = git("show", f"{rev}:navcore/render/cpu_fast.py")
    if one.returncode == 0:
        path = tmp / f"cpu_fast_{rev[:12]}.py"
        path.write_text(one.stdout)
        spec = importlib.util.spec_from_file_location(path.stem, path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    name = f"cpu_fast_{rev[:12].replace('-', '_').replace('~', '_')}"
    files = [f for f in git("ls-tree", "--name-only", f"{rev}:navcore/render/cpu_fast/").stdout.split() if f.endswith(".py")]
    if not files:
        raise SystemExit(f"revision {rev} has no navcore/render/cpu_fast(.py)")
    (tmp / name).mkdir()
    for f in files:
        text = git("show", f"{rev}:navcore/render/cpu_fast/{f}").stdout
        (tmp / name / f).write_text(text.replace("navcore.render.cpu_fast", name))
    sys.path.insert(0, str(tmp))
    return importlib.import_module(name)


def scene_ab(gs, poses, emb, old) -> dict:
    """Median ms a frame of rev's renderer and ours on the same views, interleaved."""
    from benchmarks.gpu.render_gpu import psnr
    from navcore.gaussians.model import render_sh_degree
    from navcore.render import cpu_fast as new
    from navcore.render.camera import embodiment_camera

    g_old, g_new = old.prepare(gs), new.prepare(gs)
    deg = render_sh_degree(None, g_new["sh"].shape[1])
    out = {"n_gaussians": len(gs.means), "views": len(poses)}
    for w, h in SIZES:
        vm, K, _, _ = embodiment_camera(emb, poses, w, h)
        old.render_one(g_old, vm[0], K[0], w, h, deg)
        new.render_one(g_new, vm[0], K[0], w, h, deg)
        t_old, t_new, same, psnrs, ddep = [], [], 0, [], []
        for i in range(len(vm)):
            t0 = time.perf_counter()
            a = old.render_one(g_old, vm[i], K[i], w, h, deg)
            t1 = time.perf_counter()
            b = new.render_one(g_new, vm[i], K[i], w, h, deg)
            t_old.append(t1 - t0)
            t_new.append(time.perf_counter() - t1)
            same += all(np.array_equal(x, y) for x, y in zip(a, b))
            psnrs.append(psnr(np.clip(a[0], 0, 1), np.clip(b[0], 0, 1)))
            both = (a[2] > 0.5) & (b[2] > 0.5)
            ddep.append(float(np.median(np.abs(a[1] - b[1])[both])) if both.any() else 0.0)
        out[f"{w}x{h}"] = {"rev_ms": 1000 * float(np.median(t_old)), "ours_ms": 1000 * float(np.median(t_new)),
                           "speedup": float(np.median(t_old) / np.median(t_new)), "identical_frames": same,
                           "psnr_min_db": float(min(psnrs)), "depth_median_diff_max_m": float(max(ddep))}
        print(w, h, out[f"{w}x{h}"], flush=True)
    return out


def scene_bound(gs, poses, emb) -> dict:
    """Throughput of the whole scene against that of the Gaussians each view's rasteriser read."""
    from navcore.gaussians.model import render_sh_degree
    from navcore.render import cpu_fast
    from navcore.render.camera import embodiment_camera

    g = cpu_fast.prepare(gs)
    deg = render_sh_degree(None, g["sh"].shape[1])
    out = {"n_gaussians": len(gs.means), "views": len(poses)}
    for w, h in SIZES:
        vm, K, _, _ = embodiment_camera(emb, poses, w, h)
        cpu_fast.render_one(g, vm[0], K[0], w, h, deg)
        t_all, t_read, n_read, same = [], [], [], 0
        for i in range(len(vm)):
            t0 = time.perf_counter()
            a = cpu_fast.render_one(g, vm[i], K[i], w, h, deg)
            t_all.append(time.perf_counter() - t0)
            visits = np.zeros((len(gs.means), 2), np.uint8)
            cpu_fast.render_one(g, vm[i], K[i], w, h, deg, visits=visits)
            read = visits[:, 0] == 1
            sub = cpu_fast.prepare(gs.subset(read))
            t0 = time.perf_counter()
            b = cpu_fast.render_one(sub, vm[i], K[i], w, h, deg)
            t_read.append(time.perf_counter() - t0)
            n_read.append(int(read.sum()))
            same += all(np.array_equal(x, y) for x, y in zip(a, b))
        out[f"{w}x{h}"] = {"fps": len(vm) / float(np.sum(t_all)), "fps_read_only": len(vm) / float(np.sum(t_read)),
                           "bound_speedup": float(np.sum(t_all) / np.sum(t_read)), "identical_frames": same,
                           "gaussians_read_mean": float(np.mean(n_read))}
        print(w, h, out[f"{w}x{h}"], flush=True)
    return out


def free_poses(costmap, k: int, rng) -> np.ndarray:
    iy, ix = np.nonzero(costmap.clearance >= costmap.radius + costmap.margin)
    pick = rng.choice(len(ix), k, replace=False)
    x = costmap.origin[0] + (ix[pick] + 0.5) * costmap.resolution
    y = costmap.origin[1] + (iy[pick] + 0.5) * costmap.resolution
    return np.stack([x, y, rng.uniform(-np.pi, np.pi, k)], 1)


def main(argv=None) -> dict:
    from benchmarks import write_report
    from benchmarks.gpu.render_gpu import canonical_scene, room_poses
    from navcore.nav.embodiment import Embodiment

    ap = argparse.ArgumentParser()
    ap.add_argument("--real-root", type=Path)
    ap.add_argument("--views", type=int, default=100)
    ap.add_argument("--ref-views", type=int, default=3)
    ap.add_argument("--gaussians", type=int, default=1_000_000)
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--merge", nargs="+", type=Path,
                    help="instead of measuring: render_cpu.json files of repeated runs -> their medians")
    ap.add_argument("--against", metavar="REV", help="compare with git revision REV's compiled renderer instead")
    ap.add_argument("--bound", action="store_true",
                    help="instead: the throughput with a perfect occlusion culling (only the Gaussians read)")
    args = ap.parse_args(argv)
    if args.merge:
        return merge(args.merge, args.out)
    emb, rng = Embodiment(), np.random.default_rng(0)
    old = revision_renderer(args.against) if args.against else None

    def measure(gs, poses):
        if args.bound:
            return scene_bound(gs, poses, emb)
        return scene_ab(gs, poses, emb, old) if old else scene_fps(gs, poses, emb, args.ref_views)

    gs, rooms = canonical_scene(7, args.gaussians)
    rep = {"host": platform.node(), "cpu_cores": os.cpu_count(), "scenes": {}}
    if old:
        rep["against"] = args.against
    rep["scenes"]["synthetic"] = measure(gs, room_poses(rooms, args.views, rng))
    if args.real_root:
        from navcore.io.datasets import AlignedGaussianDataset, CostmapDataset, GaussianDataset

        for ing in sorted(args.real_root.glob("01_scenes/*/ingest.json")):
            d, meta = ing.parent, json.loads(ing.read_text())
            gs, _ = AlignedGaussianDataset(d / "alignment.json", GaussianDataset(d / "gaussians.zarr")).load()
            cm = CostmapDataset(args.real_root / "03_costmaps" / f"{meta['scene_id']}.zarr").load(emb.name)
            rep["scenes"][meta["name"]] = measure(gs, free_poses(cm, args.views, rng))
    if old or args.bound:
        write_report(args.out, "render_cpu_bound.json" if args.bound else "render_cpu_ab.json", rep, omit=("scenes",))
        return rep
    for w, h in SIZES:
        key = f"{w}x{h}"
        rep[f"cpu_fps_{w}"] = min(s[key]["fps"] for s in rep["scenes"].values() if s["n_gaussians"] >= 1_000_000)
    write_report(args.out, "render_cpu.json", rep, omit=("scenes",))
    return rep


def merge(files: list[Path], out) -> dict:
    """Repeated runs (the machines are shared and noisy): per scene and size, the median of the
    runs' frames/s; every run's figure kept beside it."""
    from benchmarks import write_report

    runs = [json.loads(Path(f).read_text()) for f in files]
    rep = {"host": runs[0]["host"], "cpu_cores": runs[0]["cpu_cores"], "runs": len(runs), "scenes": {}}
    for name, s0 in runs[0]["scenes"].items():
        sc = {"n_gaussians": s0["n_gaussians"], "views": s0["views"]}
        for w, h in SIZES:
            key = f"{w}x{h}"
            vals = [r["scenes"][name][key] for r in runs if name in r["scenes"]]
            med = {k: float(np.median([v[k] for v in vals])) for k in ("fps", "fps_median", "fps_p10", "torch_reference_fps")}
            sc[key] = {**med, "speedup": med["fps"] / med["torch_reference_fps"], "fps_runs": [v["fps"] for v in vals]}
        rep["scenes"][name] = sc
    for w, h in SIZES:
        key = f"{w}x{h}"
        rep[f"cpu_fps_{w}"] = min(s[key]["fps"] for s in rep["scenes"].values() if s["n_gaussians"] >= 1_000_000)
    write_report(out, "render_cpu.json", rep, omit=("scenes",))
    return rep


if __name__ == "__main__":
    main()
