"""The GPU figures of the release cost and of the CPU renderer's agreement (CUDA machine, one run).

1. The compiled CPU renderer against gsplat on a 1 M-Gaussian synthetic scene (canonical frame),
   10 robot views at 160x120 and at 640x480 (LoCoBot camera): PSNR, expected depth difference over
   pixels both cover; gsplat's frame rate at both sizes (batches of 64 views).
2. The GPU stages on a release-size scene (1.5 M Gaussians): voxelize (torch CUDA, 0.05 m),
   goal images (gsplat, 640x480, per image), semantics views (gsplat with label features, 320x240,
   per view).

    python -m benchmarks.publishing.release_gpu [--out data/08_reports]   -> release_gpu.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np


def timed(fn, repeats: int = 5) -> float:
    import torch

    fn()
    torch.cuda.synchronize()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        torch.cuda.synchronize()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def agreement(gs, rooms, emb, sizes, views: int, rng) -> dict:
    from benchmarks.gpu.render_gpu import psnr, room_poses
    from navcore.render import Renderer
    from navcore.render.camera import embodiment_camera

    gp, cp = Renderer(gs, "gsplat"), Renderer(gs, "cpu")
    poses = room_poses(rooms, views, rng)
    out = {}
    for w, h in sizes:
        vm, K, _, _ = embodiment_camera(emb, poses, w, h)
        p, dmed, cov = [], [], []
        for i in range(len(poses)):
            a = gp.render(vm[i:i + 1], K[i:i + 1], w, h)
            b = cp.render(vm[i:i + 1], K[i:i + 1], w, h)
            both = (a.alpha[0].cpu().numpy() > 0.5) & (b.alpha[0].numpy() > 0.5)
            dd = np.abs(a.depth[0].cpu().numpy() - b.depth[0].numpy())[both]
            p.append(psnr(a.rgb[0].cpu().numpy(), b.rgb[0].numpy()))
            dmed.append(float(np.median(dd)) if dd.size else 0.0)
            cov.append(float(both.mean()))
        vm64, K64, _, _ = embodiment_camera(emb, room_poses(rooms, 64, rng), w, h)
        fps = 64 / timed(lambda: gp.render(vm64, K64, w, h))  # noqa: B023
        out[f"{w}x{h}"] = {"psnr_min": min(p), "psnr_median": float(np.median(p)), "depth_median_abs_m_max": max(dmed),
                           "covered_fraction_median": float(np.median(cov)), "gsplat_fps": fps}
        print(f"{w}x{h}", out[f"{w}x{h}"], flush=True)
    return out


def gpu_stages(gs, rooms, emb, rng) -> dict:
    import torch

    from benchmarks.gpu.render_gpu import room_poses
    from navcore.render import Renderer
    from navcore.render.camera import embodiment_camera
    from navcore.voxels.field import VoxelizeConfig, opacity_field
    from navcore.voxels.grid import grid_for_points

    grid = grid_for_points(gs.means, 0.05, margin=0.1, lo_q=0.1, hi_q=99.9)
    vox = timed(lambda: opacity_field(gs, grid, VoxelizeConfig(), device="cuda"), repeats=3)
    r = Renderer(gs, "gsplat")
    vm, K, w, h = embodiment_camera(emb, room_poses(rooms, 64, rng))  # 640x480 goal images
    goal = timed(lambda: (r.render(vm, K, w, h).rgb.clamp(0, 1) * 255).to(torch.uint8).cpu()) / 64
    feats = np.eye(16, dtype=np.float32)[np.arange(len(gs.means)) % 16]
    vm, K, w, h = embodiment_camera(emb, room_poses(rooms, 64, rng), 320, 240)
    sem = timed(lambda: r.render(vm, K, w, h, extra=feats).extra.cpu()) / 64
    return {"n_gaussians": len(gs.means), "voxels": grid.n_voxels, "voxelize_s": vox,
            "goal_image_s": goal, "semantics_view_s": sem}


def main(argv=None) -> dict:
    import torch

    from benchmarks import write_report
    from benchmarks.gpu.render_gpu import canonical_scene
    from navcore.nav.embodiment import Embodiment

    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--gaussians", type=int, default=1_000_000)
    ap.add_argument("--release-gaussians", type=int, default=1_500_000)
    ap.add_argument("--views", type=int, default=10)
    args = ap.parse_args(argv)
    if not torch.cuda.is_available():
        raise SystemExit("no CUDA device: this benchmark needs a GPU")
    emb, rng = Embodiment(), np.random.default_rng(0)
    gs, rooms = canonical_scene(7, args.gaussians)
    rep = {"device": torch.cuda.get_device_name(0), "host": platform.node(), "cpu_cores": os.cpu_count(),
           "agreement_gaussians": len(gs.means),
           "agreement": agreement(gs, rooms, emb, [(160, 120), (640, 480)], args.views, rng)}
    gs, rooms = canonical_scene(8, args.release_gaussians)
    rep["stages"] = gpu_stages(gs, rooms, emb, rng)
    print(json.dumps(rep["stages"], indent=1), flush=True)
    write_report(args.out, "release_gpu.json", rep, omit=("agreement", "stages"))
    return rep


if __name__ == "__main__":
    main()
