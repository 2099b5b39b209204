"""bench-eval: closed-loop evaluation figures.

CPU (this machine): the oracle and the random agent on every episode of the default dataset (both
protocols; they do not look, so nothing is rendered), the environment's own cost per step
(everything but rendering), and environment steps per second with the CPU renderer at 160x120 and
640x480 on a 100 k-Gaussian scene. GPU (`--gpu`, on a CUDA machine): batched environment steps per
second at 640x480 RGB-D on a 1 M-Gaussian scene with gsplat's raw frame rate of the same batch
beside it, a learned policy's steps per second in one process (the shipped pointnav_bc through the
evaluate verb's batched loop, its frames read in place and, for the ratio, through the host), and
the CPU renderer against gsplat (benchmarks.gpu.render_gpu); written to eval_gpu.json
and merged into the report (`--merge-gpu` folds an existing one in).

Writes data/08_reports/bench_eval.json and bench_eval.md.
    python -m benchmarks.closed_loop.eval [--data data] [--out data/08_reports]
    python -m benchmarks.closed_loop.eval --gpu --out $OUT          (CUDA machine)
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from benchmarks import machine
from benchmarks.pages import write_page
from navcore.eval.env import EnvConfig, NavEnv, SceneContext
from navcore.eval.episode import Episode
from navcore.io import jsonio
from navcore.io.datasets import CostmapDataset
from navcore.nav.costmap import Costmap
from navcore.nav.embodiment import Embodiment
from navcore.nav.geodesic import NavGraph, eligible_cells
from navcore.voxels.field import VoxelizeConfig
from stages.costmap.build import CostmapConfig, build_costmap
from stages.episodes.config import EpisodesConfig


def bench_scene(seed: int, n: int, backend: str = "cpu"):
    """A synthetic scene in its canonical (already aligned) frame with its costmap and graph."""
    from stages.synthesize.generate import SyntheticConfig, generate_scene

    s = generate_scene(seed, SyntheticConfig(num_gaussians=n))
    gs = s.gaussians.transformed(np.linalg.inv(s.transform))
    emb = Embodiment()
    layers, _ = build_costmap(gs, emb, CostmapConfig(), VoxelizeConfig())
    cm = Costmap.from_layers(layers)
    graph = NavGraph(cm, eligible_cells(cm, EpisodesConfig()))
    return SceneContext(cm, graph, emb, gs, backend), emb


def random_episodes(ctx, k: int, rng, max_steps: int = 500) -> list[Episode]:
    cells = ctx.graph.cells[rng.integers(len(ctx.graph.cells), size=(k, 2))]
    out = []
    for i, (a, b) in enumerate(cells):
        s, g = ctx.costmap.cell_centers(np.array([a, b]))
        out.append(Episode(f"b{i}", "pointnav", (s[0], s[1], float(rng.uniform(-np.pi, np.pi))), g, g[None], 0.5,
                           1.0, max_steps, goal_sources=g[None]))
    return out


def steps_per_second(ctx, width: int, height: int, n_slots: int, n_steps: int, rng, device_obs=False) -> dict:
    """Batched random-walk steps per second (render included), median of 3 runs."""
    from navcore.eval.batch import BatchNavEnv

    env = BatchNavEnv(ctx, n_slots, EnvConfig(width=width, height=height, protocol="explicit_stop"),
                      device_obs=device_obs)  # random moves never end an episode: every slot steps
    rates = []
    for _ in range(3):
        env.reset(random_episodes(ctx, n_slots, rng, max_steps=10**6))
        acts = rng.integers(1, 4, size=(n_steps, n_slots))
        env.step(list(acts[0]))  # warm-up
        _sync()
        t0 = time.perf_counter()
        for a in acts[1:]:
            env.step(list(a))
        _sync()
        rates.append(n_slots * (n_steps - 1) / (time.perf_counter() - t0))
    # the renderer alone on the same batch of poses (the raw frame rate beside the env's)
    from navcore.render.camera import embodiment_camera

    poses = np.stack([e.state.pose for e in env.envs]).astype(np.float64)
    vm, k, w, h = embodiment_camera(ctx.emb, poses, width, height)
    raw = []
    for _ in range(3):
        ctx.renderer.render(vm, k, w, h)
        _sync()
        t0 = time.perf_counter()
        for _ in range(10):
            ctx.renderer.render(vm, k, w, h)
        _sync()
        raw.append(10 * n_slots / (time.perf_counter() - t0))
    return {"steps_per_s": float(np.median(rates)), "runs": rates, "raw_render_fps": float(np.median(raw)),
            "slots": n_slots, "width": width, "height": height}


def learned_steps_per_second(ctx, width: int, height: int, n_slots: int, rng, device_frames: bool,
                             episodes: int = 256, max_steps: int = 60) -> dict:
    """The evaluate verb's loop (run_episodes_batched) driving the shipped pointnav_bc in this
    process, render, forward pass and metrics included: policy steps per second over a queue of
    random PointNav episodes (median of 3 runs). device_frames False: the frames go through the host
    (numpy) as they did before the learned agent read the renderer's tensors."""
    from navcore.eval.agents import agent_for
    from navcore.eval.loop import InProcessBatch, run_episodes_batched

    def client() -> InProcessBatch:
        c = InProcessBatch(lambda: agent_for("pointnav_bc"))
        c.device_frames = device_frames
        return c

    cfg = EnvConfig(width=width, height=height, protocol="explicit_stop")
    eps = random_episodes(ctx, episodes, rng, max_steps=max_steps)
    run_episodes_batched(ctx, eps[:n_slots], client(), n_slots, cfg)  # the network loaded, kernels warm
    rates = []
    for _ in range(3):
        c = client()
        _sync()
        t0 = time.perf_counter()
        rows = run_episodes_batched(ctx, eps, c, n_slots, cfg)
        _sync()
        rates.append(sum(r["steps"] for r in rows) / (time.perf_counter() - t0))
    return {"steps_per_s": float(np.median(rates)), "runs": rates, "slots": n_slots, "width": width,
            "height": height, "episodes": episodes, "device_frames": device_frames}


def _sync():
    import torch

    if torch.cuda.is_available():
        torch.cuda.synchronize()


def env_overhead_us(ctx, rng, n: int = 20000) -> float:
    """Per-step cost of the environment without rendering (action decoding, the swept-disk check,
    success test, goal vector), microseconds, median of 5 runs."""
    env = NavEnv(ctx, EnvConfig(render=False, protocol="explicit_stop"))  # random moves never end it
    eps = random_episodes(ctx, 50, rng, max_steps=10**9)
    acts = rng.integers(1, 4, size=n)
    runs = []
    for r in range(5):
        env.reset(eps[r])
        t0 = time.perf_counter()
        for a in acts:
            env.step(int(a))
        runs.append((time.perf_counter() - t0) / n * 1e6)
    return float(np.median(runs))


def agents_on_dataset(data: Path) -> dict:
    """Oracle and random agent over every stored episode of the dataset, both protocols."""
    import pandas as pd

    from navcore.eval.agents import make_agent
    from navcore.eval.loop import run_episodes
    from navcore.eval.metrics import aggregate

    eps = pd.read_parquet(data / "05_episodes")
    eps["scene_id"] = eps["scene_id"].astype(str)
    eps["task_type"] = eps["task"].astype(str)
    out = {}
    for agent in ("oracle", "random"):
        for protocol in ("distance", "explicit_stop"):
            rows = []
            for sid, se in eps.groupby("scene_id"):
                cm = CostmapDataset(data / "03_costmaps" / f"{sid}.zarr").load("locobot")
                ctx = SceneContext(cm, NavGraph(cm, eligible_cells(cm, EpisodesConfig())), Embodiment())
                episodes = [Episode.from_row(r) for r in se.to_dict("records")]
                rows += run_episodes(ctx, episodes, make_agent(agent, seed=0), EnvConfig(render=False, protocol=protocol))
            agg = aggregate(rows)["overall"]
            out[f"{agent}_{protocol}"] = {k: agg[k] for k in ("episodes", "sr", "distance_sr", "stop_sr", "spl",
                                                               "soft_spl", "collision_rate", "steps")}
    return out


def gpu_main(out: Path) -> dict:
    import torch

    from benchmarks.gpu import render_gpu

    rng = np.random.default_rng(0)
    cmp = render_gpu.main(["--out", str(out), "--grid-gaussians", ""])  # the frame-rate grid is bench_gpu's
    ctx, _ = bench_scene(3, 1_000_000, backend="gsplat")
    batch = 64
    steps = steps_per_second(ctx, 640, 480, batch, 60, rng, device_obs=True)
    one = steps_per_second(ctx, 640, 480, 1, 300, rng, device_obs=True)  # one env: a render call per step
    learned = {f: learned_steps_per_second(ctx, 640, 480, batch, rng, device_frames=f) for f in (True, False)}
    res = {"device": torch.cuda.get_device_name(0), "gpu_steps_per_s": steps["steps_per_s"], "gpu_steps": steps,
           "gpu_steps_per_s_one_env": one["steps_per_s"], "gpu_steps_one_env": one,
           "learned_steps_per_s": learned[True]["steps_per_s"], "learned_steps": learned[True],
           "learned_steps_per_s_host": learned[False]["steps_per_s"], "learned_steps_host": learned[False],
           "gsplat_raw_fps": steps["raw_render_fps"], "gsplat_raw_fps_room_views": cmp["gsplat_raw_fps"],
           "psnr_cpu_vs_gsplat": cmp["psnr_cpu_vs_gsplat_min"],
           "psnr_cpu_vs_gsplat_median": cmp["psnr_cpu_vs_gsplat_median"],
           "depth_mae_m": cmp["depth_median_abs_m_max"], "gaussians": len(ctx.renderer._g["means"])}
    (out / "eval_gpu.json").write_text(jsonio.dumps(res, indent=1))
    print(json.dumps(res, indent=1))
    return res


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="data")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", action="store_true", help="also write docs/benchmarks/bench_eval.md")
    ap.add_argument("--gpu", action="store_true")
    ap.add_argument("--merge-gpu", action="store_true", help="only fold eval_gpu.json into an existing report")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.gpu:
        return gpu_main(out)
    path = out / "bench_eval.json"
    if args.merge_gpu:
        result = json.loads(path.read_text())
    else:
        rng = np.random.default_rng(0)
        ctx, _ = bench_scene(4, 100_000, backend="cpu")
        result = {"machine": machine(),
                  "env_overhead_us": env_overhead_us(ctx, rng)}
        for w, h in ((160, 120), (640, 480)):
            s = steps_per_second(ctx, w, h, 4, 6 if w > 200 else 21, rng)
            result[f"cpu_steps_per_s_{w}"] = s["steps_per_s"]
            result[f"cpu_steps_{w}"] = s
        result["agents"] = agents_on_dataset(Path(args.data))
        a = result["agents"]
        result.update(oracle_sr=a["oracle_distance"]["sr"], oracle_spl=a["oracle_distance"]["spl"],
                      oracle_stop_sr=a["oracle_explicit_stop"]["sr"], oracle_stop_spl=a["oracle_explicit_stop"]["spl"],
                      random_sr=a["random_distance"]["sr"], random_stop_sr=a["random_explicit_stop"]["sr"])
    gpu = out / "eval_gpu.json"
    if gpu.exists():
        g = json.loads(gpu.read_text())
        result.update({k: g[k] for k in ("gpu_steps_per_s", "gsplat_raw_fps", "psnr_cpu_vs_gsplat", "depth_mae_m",
                                         "learned_steps_per_s", "learned_steps_per_s_host") if k in g})
        result["gpu"] = g
    path.write_text(jsonio.dumps(result, indent=1))
    (out / "bench_eval.md").write_text(markdown(result))
    if args.docs:
        write_page("bench_eval.md", markdown(result))
    print(markdown(result))
    return result


def markdown(r: dict) -> str:
    f = lambda k, fmt="{:.3f}": fmt.format(r[k]) if k in r else "not measured"  # noqa: E731
    lines = [f"# bench-eval ({r.get('machine')})", "", "| figure | value | target |", "|---|---|---|",
             f"| CPU renderer vs gsplat, PSNR (min over views) | {f('psnr_cpu_vs_gsplat', '{:.1f} dB')} | >= 35 dB |",
             f"| depth median abs. error (max over views) | {f('depth_mae_m', '{:.2e} m')} | <= 0.01 m |",
             f"| GPU batched env steps/s, 640x480 RGB-D, 1 M Gaussians | {f('gpu_steps_per_s', '{:.0f}')} | >= 1000 |",
             f"| gsplat raw frames/s, same batch | {f('gsplat_raw_fps', '{:.0f}')} | (about 3400) |",
             f"| a learned policy (pointnav_bc) in one process, steps/s, same scene and size, 64 slots | "
             f"{f('learned_steps_per_s', '{:.0f}')} | >= 3000 |",
             f"| the same, its frames through the host (before 2026-12-07) | {f('learned_steps_per_s_host', '{:.0f}')} | |",
             f"| CPU env steps/s, 160x120, 100 k Gaussians | {f('cpu_steps_per_s_160', '{:.2f}')} | |",
             f"| CPU env steps/s, 640x480, 100 k Gaussians | {f('cpu_steps_per_s_640', '{:.2f}')} | |",
             f"| env overhead per step, excluding rendering | {f('env_overhead_us', '{:.1f} us')} | <= 50 us |",
             f"| oracle Distance SR / SPL (distance protocol) | {f('oracle_sr')} / {f('oracle_spl')} | >= 0.99 / >= 0.90 |",
             f"| oracle SR / SPL (explicit stop) | {f('oracle_stop_sr')} / {f('oracle_stop_spl')} | |",
             f"| random SR (distance / explicit stop) | {f('random_sr')} / {f('random_stop_sr')} | |", ""]
    if r.get("gpu"):
        lines += [f"The GPU rows and the CPU renderer against gsplat: {r['gpu'].get('device', 'a CUDA machine')}, by "
                  "`python -m benchmarks.closed_loop.eval --gpu` there (its eval_gpu.json, merged here); the other rows "
                  f"on {r.get('machine')}.", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
