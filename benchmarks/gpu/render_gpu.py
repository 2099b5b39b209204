"""The CPU renderer against gsplat (CUDA machine): the same cameras rendered by both, and gsplat's
raw frame rate.

For each of 2 synthetic scenes (canonical frame: z up, floor z = 0), 10 robot poses inside the
rooms at the LoCoBot camera (0.88 m, 90 degree hfov, 640x480): PSNR of the CPU image against
gsplat's, and the median / mean absolute difference of expected depth over pixels both see
(alpha > 0.5 in both). Then gsplat's raw frame rate for batches of 640x480 RGB-D frames of a
1 M-Gaussian scene. Writes render_gpu.json to --out.

    python -m benchmarks.gpu.render_gpu [--gaussians 300000] [--views 10] [--out data/08_reports]
"""
from __future__ import annotations

import argparse
import math
import platform
import time

import numpy as np
import torch

from benchmarks import write_report
from navcore.nav.embodiment import Embodiment
from navcore.render import Renderer
from navcore.render.camera import embodiment_camera
from stages.synthesize.generate import SyntheticConfig, generate_scene


def canonical_scene(seed: int, n: int):
    s = generate_scene(seed, SyntheticConfig(num_gaussians=n))
    return s.gaussians.transformed(np.linalg.inv(s.transform)), np.array(s.layout.rooms)


def room_poses(rooms: np.ndarray, k: int, rng, margin: float = 0.6) -> np.ndarray:
    r = rooms[rng.integers(len(rooms), size=k)]
    x = rng.uniform(r[:, 0] + margin, r[:, 2] - margin)
    y = rng.uniform(r[:, 1] + margin, r[:, 3] - margin)
    return np.stack([x, y, rng.uniform(-np.pi, np.pi, k)], 1)


def fps_grid(emb, rng, sizes: list[int], batch: int, repeats: int = 7) -> list[dict]:
    """gsplat RGB-D frames/s per (Gaussians, resolution, frames per call): the median of `repeats`
    timed calls after 3 warm-ups, each call `batch` robot views (or one)."""
    out = []
    for n in sizes:
        gs, rooms = canonical_scene(4, n)
        gp = Renderer(gs, "gsplat")
        poses = room_poses(rooms, batch, rng)
        for w, h in ((640, 480), (160, 120)):
            for b in (1, batch):
                vm, K, ww, hh = embodiment_camera(emb, poses[:b], w, h)
                for _ in range(3):
                    gp.render(vm, K, ww, hh)
                torch.cuda.synchronize()
                times = []
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    gp.render(vm, K, ww, hh)
                    torch.cuda.synchronize()
                    times.append(time.perf_counter() - t0)
                out.append({"gaussians": len(gs.means), "width": w, "height": h, "batch": b,
                            "fps": b / float(np.median(times))})
                print(out[-1], flush=True)
    return out


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a - b) ** 2))
    return 10 * math.log10(1.0 / max(mse, 1e-12))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--gaussians", type=int, default=300_000)
    ap.add_argument("--views", type=int, default=10)
    ap.add_argument("--fps-gaussians", type=int, default=1_000_000)
    ap.add_argument("--fps-batch", type=int, default=64)
    ap.add_argument("--grid-gaussians", default="1000000,1500000",
                    help="scene sizes of the frame-rate grid (x 640x480 / 160x120 x one frame / a batch)")
    ap.add_argument("--out", default="data/08_reports")
    args = ap.parse_args(argv)
    emb = Embodiment()
    rng = np.random.default_rng(0)
    views = []
    for seed in (1, 2):
        gs, rooms = canonical_scene(seed, args.gaussians)
        poses = room_poses(rooms, args.views, rng)
        vm, K, w, h = embodiment_camera(emb, poses)
        gp, cp = Renderer(gs, "gsplat"), Renderer(gs, "cpu")
        for i in range(len(poses)):
            a = gp.render(vm[i:i + 1], K[i:i + 1], w, h)
            t0 = time.perf_counter()
            b = cp.render(vm[i:i + 1], K[i:i + 1], w, h)
            cpu_s = time.perf_counter() - t0
            ga, ca = a.rgb[0].cpu().numpy(), b.rgb[0].numpy()
            both = (a.alpha[0].cpu().numpy() > 0.5) & (b.alpha[0].numpy() > 0.5)
            dd = np.abs(a.depth[0].cpu().numpy() - b.depth[0].numpy())[both]
            views.append({"scene_seed": seed, "pose": poses[i].tolist(), "psnr": psnr(ga, ca),
                          "depth_median_abs_m": float(np.median(dd)) if dd.size else None,
                          "depth_mean_abs_m": float(dd.mean()) if dd.size else None,
                          "covered_fraction": float(both.mean()), "cpu_render_s": cpu_s})
            print(views[-1], flush=True)
    # gsplat raw frame rate: batches of 640x480 RGB-D frames of a 1 M-Gaussian scene
    gs, rooms = canonical_scene(3, args.fps_gaussians)
    gp = Renderer(gs, "gsplat")
    vm, K, w, h = embodiment_camera(emb, room_poses(rooms, args.fps_batch, rng))
    for _ in range(3):
        gp.render(vm, K, w, h)
    torch.cuda.synchronize()
    times = []
    for _ in range(7):
        t0 = time.perf_counter()
        gp.render(vm, K, w, h)
        torch.cuda.synchronize()
        times.append(time.perf_counter() - t0)
    fps = args.fps_batch / float(np.median(times))
    grid = fps_grid(emb, rng, [int(n) for n in args.grid_gaussians.split(",") if n], args.fps_batch)
    result = {"device": torch.cuda.get_device_name(0), "host": platform.node(), "views": len(views),
              "psnr_cpu_vs_gsplat_min": min(v["psnr"] for v in views),
              "psnr_cpu_vs_gsplat_median": float(np.median([v["psnr"] for v in views])),
              "depth_median_abs_m_max": max(v["depth_median_abs_m"] for v in views),
              "depth_mean_abs_m_max": max(v["depth_mean_abs_m"] for v in views),
              "gsplat_raw_fps": fps, "gsplat_fps_batch": args.fps_batch, "gsplat_fps_gaussians": len(gs.means),
              "gsplat_fps_grid": grid,
              "per_view": views}
    write_report(args.out, "render_gpu.json", result, omit=("per_view",))
    return result


if __name__ == "__main__":
    main()
