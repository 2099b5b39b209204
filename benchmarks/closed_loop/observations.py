"""Frames/s of the renderer-backed observation datasets (navarena.observations).

CPU (this machine): ExpertObservationStream over a data root's stored expert trajectories with
the CPU renderer, as a user without a GPU runs it: frames/s per batch after the first (which loads
the scene and compiles), median over batches, at 160x120 (and 640x480 with --big).

GPU (--gpu, a CUDA machine): the same stream's render path on a release-size synthetic scene
(1.5 M Gaussians, generated in-process: no data root travels to the device), expert-like poses in
its rooms, gsplat, batches of 256 at 160x120 and 64 at 640x480, frames left on the GPU
(device_output, what a GPU training loop takes) and copied to host memory.

    python -m benchmarks.closed_loop.observations --data data [--big]      -> observations_cpu.json
    python -m benchmarks.closed_loop.observations --gpu                    -> observations_gpu.json
"""
from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

import numpy as np


def _stream_fps(stream, batches: int) -> tuple[float, list[float]]:
    """Median frames/s over `batches` batches after the first."""
    rates, it = [], iter(stream)
    next(it)
    for _ in range(batches):
        t0 = time.perf_counter()
        try:
            b = next(it)
        except StopIteration:
            break
        if b["rgb"].is_cuda:
            import torch

            torch.cuda.synchronize()
        rates.append(len(b["rgb"]) / (time.perf_counter() - t0))
    return float(np.median(rates)) if rates else float("nan"), rates


def cpu(args) -> dict:
    from navarena.observations import ExpertObservationStream

    out = {"machine": platform.node(), "cpu_cores": os.cpu_count(), "renderer": "cpu", "data": args.data}
    sizes = [(160, 120)] + ([(640, 480)] if args.big else [])
    for w, h in sizes:
        s = ExpertObservationStream(args.data, tasks=["pointnav", "imagenav"], stride=4, batch_size=32, width=w,
                                    height=h, renderer="cpu", shuffle=True, seed=0)
        fps, rates = _stream_fps(s, args.batches)
        out[f"fps_{w}x{h}"] = fps
        out[f"fps_{w}x{h}_batches"] = [round(r, 1) for r in rates]
        print(f"CPU {w}x{h}: {fps:.1f} frames/s (batches: {[round(r, 1) for r in rates]})", flush=True)
    return out


def gpu(args) -> dict:
    import pandas as pd
    import torch

    from benchmarks.gpu.render_gpu import canonical_scene, room_poses
    from navarena.observations import ExpertObservationStream
    from navcore.render import Renderer

    gs, rooms = canonical_scene(8, args.gaussians)
    rng = np.random.default_rng(0)
    n = 256 * (args.batches + 1)
    poses = room_poses(rooms, n, rng)
    steps = pd.DataFrame({"task": "pointnav", "episode_id": [f"e{i // 100:05d}" for i in range(n)],
                          "step": np.arange(n) % 100, "position_x": poses[:, 0], "position_y": poses[:, 1],
                          "yaw": poses[:, 2], "linear_velocity": 0.3, "angular_velocity": 0.0, "dx": 0.015, "dy": 0.0,
                          "dyaw": 0.0, "action_id": 1, "split": "train", "scene_id": "synthetic"})
    renderer = Renderer(gs, "gsplat")
    out = {"device": torch.cuda.get_device_name(0), "host": platform.node(), "n_gaussians": len(gs.means)}
    with tempfile.TemporaryDirectory() as root:
        for (w, h), bs in (((160, 120), 256), ((640, 480), 64)):
            for on_device in (True, False):
                s = ExpertObservationStream(root, scenes=["synthetic"], batch_size=bs, width=w, height=h,
                                            renderer="gsplat", device_output=on_device)
                s._steps = lambda sid: steps  # noqa: B023 - the in-process scene's poses
                s._renderers = type("R", (), {"get": staticmethod(lambda sid: renderer)})()
                fps, rates = _stream_fps(s, args.batches)
                key = f"fps_{w}x{h}_{'gpu' if on_device else 'host'}"
                out[key] = fps
                print(f"GPU {w}x{h} batch {bs} frames on {'GPU' if on_device else 'host'}: {fps:.0f} frames/s",
                      flush=True)
    return out


def main(argv=None) -> dict:
    from benchmarks import write_report

    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="data")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--gpu", action="store_true")
    ap.add_argument("--big", action="store_true", help="CPU: also 640x480")
    ap.add_argument("--batches", type=int, default=8)
    ap.add_argument("--gaussians", type=int, default=1_500_000)
    args = ap.parse_args(argv)
    rep = gpu(args) if args.gpu else cpu(args)
    write_report(args.out, "observations_gpu.json" if args.gpu else "observations_cpu.json", rep)
    return rep


if __name__ == "__main__":
    main()
