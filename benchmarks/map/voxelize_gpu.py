"""Voxelization of a 1M-Gaussian synthetic scene at 0.05 m on CUDA (the torch path), with the
numba CPU path of the same machine beside it and their agreement.

  python -m benchmarks.map.voxelize_gpu [--out data/08_reports]   -> voxelize_gpu.json
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from navcore.io import jsonio


def main(argv=None) -> int:
    import torch

    from navcore.voxels.field import VoxelizeConfig, opacity_field
    from navcore.voxels.grid import grid_for_points
    from stages.synthesize.generate import SyntheticConfig, generate_scene

    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--gaussians", type=int, default=1_000_000)
    args = ap.parse_args(argv)
    if not torch.cuda.is_available():
        raise SystemExit("no CUDA device: this benchmark needs a GPU")
    g = generate_scene(4242, SyntheticConfig(num_gaussians=args.gaussians)).gaussians
    grid = grid_for_points(g.means, 0.05, margin=0.1, lo_q=0.1, hi_q=99.9)
    cfg = VoxelizeConfig()
    opacity_field(g, grid, cfg, device="cuda")  # warm-up: CUDA context, allocator
    torch.cuda.synchronize()
    torch.cuda.reset_peak_memory_stats()
    times = []
    for _ in range(args.repeats):
        torch.cuda.synchronize()
        t0 = time.perf_counter()
        a_gpu = opacity_field(g, grid, cfg, device="cuda")  # end to end: params up, field back to host
        torch.cuda.synchronize()
        times.append(time.perf_counter() - t0)
    peak = torch.cuda.max_memory_allocated() / 2 ** 20
    opacity_field(g.subset(slice(0, 1000)), grid, cfg, device="cpu")
    t0 = time.perf_counter()
    a_cpu = opacity_field(g, grid, cfg, device="cpu")
    cpu_s = time.perf_counter() - t0
    occ_g, occ_c = a_gpu >= cfg.tau_occ, a_cpu >= cfg.tau_occ
    rep = {"device": torch.cuda.get_device_name(0), "n_gaussians": len(g), "grid": list(grid.shape),
           "voxels": grid.n_voxels, "times_s": times, "median_s": float(np.median(times)), "peak_gpu_mb": peak,
           "cpu_numba_s_same_machine": cpu_s, "cpu_cores": os.cpu_count(),
           "occupied_gpu": int(occ_g.sum()), "occupied_cpu": int(occ_c.sum()),
           "occupancy_disagreement": float((occ_g != occ_c).mean()), "max_abs_diff_A": float(np.abs(a_gpu - a_cpu).max())}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "voxelize_gpu.json").write_text(jsonio.dumps(rep, indent=1))
    print(json.dumps(rep, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
