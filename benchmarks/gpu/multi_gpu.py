"""The release stages on every GPU of one host (a multi-GPU machine; figures in docs/benchmarks/bench_multi_gpu.md).

1. release: the whole pipeline (default stages, goal images and a batched oracle evaluation with
   rendering) over `--scenes` synthetic scenes of `--gaussians` Gaussians plus the real indoor
   scenes found in `--real` (SPZ / SOG), Dask CPU workers beside one worker per GPU. From the
   run summary: which worker ran which tasks, the GPU each task's CUDA work used (torch's current
   device and its UUID, against the UUID of the GPU the worker is pinned to), how long CPU stages
   ran beside the GPU stages.
2. scaling: the GPU stages (voxelize, semantics, goal_images, evaluate) forced again on the same
   scenes with 1 GPU and with all of them; throughput = GPU tasks / (last GPU task end - first
   GPU task start), per stage the summed task seconds.
3. env: the vectorised evaluation env (64 slots, 640x480, a 1 M-Gaussian scene of the release
   data), one env group per GPU in its own process, all stepping at once: steps/s per GPU and in
   total, with 1 GPU and with all.

    python -m benchmarks.gpu.multi_gpu --data /tmp/mg --real DIR --out OUT --phases release,scaling,env
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from navcore.io import jsonio

GPU_STAGES = ("voxelize", "semantics", "goal_images", "evaluate")


def gpu_work(episodes: int, renderer: str) -> list[str]:
    """Overrides of the GPU work: goal images on, a batched oracle evaluation of `episodes` episodes
    per scene and task on `renderer`, without videos or plots."""
    return ["evaluate.agent=oracle", "evaluate.batch_slots=64", f"evaluate.episodes_per_scene={episodes}",
            "evaluate.videos=0", "evaluate.trajectory_plots=0", "goal_images.enabled=true",
            f"evaluate.renderer={renderer}"]


def write_catalog(data: Path, real: list[Path], scenes: int, gaussians: int) -> Path:
    """One catalog: the synthetic scenes and the real scenes given (SPZ files, SOG folders, or
    folders holding them)."""
    entries = []
    for r in real:
        if not r.exists():
            raise SystemExit(f"benchmarks.gpu.multi_gpu: --real {r} does not exist")
        for p in sorted(r.iterdir()) if r.is_dir() and not (r / "lod-meta.json").exists() else [r]:
            if p.suffix == ".spz" or (p.is_dir() and (p / "lod-meta.json").exists()):
                src = p / "lod-meta.json" if p.is_dir() else p
                entries.append({"name": p.stem.replace(".", "_"), "group": "real_indoor", "path": str(src.resolve())})
    spec = {"synthetic": {"prefix": "synth", "group": "synthetic", "count": scenes, "first_seed": 0,
                          "num_gaussians": gaussians}, "scenes": entries}
    data.mkdir(parents=True, exist_ok=True)
    f = data / "multi_gpu_catalog.yaml"
    f.write_text(json.dumps(spec, indent=1))  # JSON is YAML
    return f


def compose(data: Path, catalog: Path, *over: str):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return hydra_compose("config", overrides=[f"data_root={data}", f"scenes.catalog={catalog}",
                                                   "executor=local", "executor.dashboard=false", *over])


def gpu_rates(summary: dict) -> dict:
    """GPU-stage throughput of a run: tasks per second of wall time, per stage the task seconds (and
    the goal images rendered)."""
    gpu = [r for r in summary["results"] if r["stage"] in GPU_STAGES and r["status"] == "done" and "finished" in r]
    if not gpu:
        return {"gpu_tasks": 0}
    span = max(r["finished"] for r in gpu) - min(r["started"] for r in gpu)
    per_stage = {}
    for st in GPU_STAGES:
        rs = [r for r in gpu if r["stage"] == st]
        if rs:
            per_stage[st] = {"tasks": len(rs), "task_s": round(sum(r["duration_s"] for r in rs), 2)}
            if st == "goal_images":
                per_stage[st]["images"] = sum(r.get("images", 0) for r in rs)
    return {"gpu_tasks": len(gpu), "span_s": round(span, 2), "tasks_per_s": len(gpu) / span, "per_stage": per_stage,
            "by_gpu": {g: sum(1 for r in gpu if r.get("gpu") == g) for g in sorted({r.get("gpu") for r in gpu})},
            "failures": len(summary["failures"])}


def release(data: Path, catalog: Path, workers: int, work: list[str]) -> dict:
    from pipeline.config import DEFAULT_STAGES
    from pipeline.executor import execute

    stages = [*DEFAULT_STAGES, *(s for s in ("goal_images", "evaluate") if s not in DEFAULT_STAGES)]
    t0 = time.perf_counter()
    s = execute(compose(data, catalog, f"executor.n_workers={workers}", f"stages=[{','.join(stages)}]", *work))
    wall = time.perf_counter() - t0
    steps = [r for r in s["results"] if r["stage"] == "evaluate" and r["status"] == "done"]
    return {"wall_s": round(wall, 1), "counts": s["counts"], "failures": s["failures"], "placement": s.get("placement"),
            "gpu": gpu_rates(s), "eval_steps": sum(r.get("steps", 0) for r in steps),
            "scenes": len({r["scene_id"] for r in s["results"] if r["scene_id"] != "*"})}


def scaling(data: Path, catalog: Path, workers: int, n_gpus: int, work: list[str]) -> dict:
    from pipeline.executor import execute

    out = {}
    for n in sorted({1, n_gpus}):
        t0 = time.perf_counter()
        s = execute(compose(data, catalog, f"executor.n_workers={workers}", f"executor.gpus={n}",
                            f"stages=[{','.join(GPU_STAGES)}]", "force=true", *work))
        out[str(n)] = {**gpu_rates(s), "wall_s": round(time.perf_counter() - t0, 1),
                       "misplaced": len((s.get("placement") or {}).get("misplaced", []))}
    if len(out) > 1:
        out["scaling"] = out[str(n_gpus)]["tasks_per_s"] / out["1"]["tasks_per_s"]
    return out


def env_worker(args) -> None:
    """One env group on this process's GPU (CUDA_VISIBLE_DEVICES set by the parent)."""
    import torch

    from benchmarks.closed_loop.eval import steps_per_second
    from navcore.io.catalog import open_catalog
    from stages.evaluate.stage import scene_context

    cfg = compose(Path(args.data), Path(args.catalog))
    catalog, scenes, _ = open_catalog(cfg)
    scene = next(s for s in scenes if s.synthetic)
    ctx = scene_context(scene, cfg, catalog, True, "gsplat")
    rng = np.random.default_rng(int(args.gpu_rank))
    steps_per_second(ctx, 640, 480, 64, 5, rng, device_obs=True)  # kernels loaded, caches warm
    barrier = Path(args.barrier)
    (barrier / f"ready-{args.gpu_rank}").touch()
    while len(list(barrier.glob("ready-*"))) < args.group:
        time.sleep(0.05)
    t0 = time.time()
    r = steps_per_second(ctx, 640, 480, 64, args.steps, rng, device_obs=True)
    i = torch.cuda.current_device()
    r.update({"started": t0, "finished": time.time(), "cuda_visible": os.environ.get("CUDA_VISIBLE_DEVICES"),
              "cuda_device": i, "gpu_uuid": str(torch.cuda.get_device_properties(i).uuid), "scene": scene.name,
              "gaussians": ctx.renderer.num_gaussians})
    Path(args.result).write_text(jsonio.dumps(r))


def env_groups(data: Path, catalog: Path, n_gpus: int, steps: int) -> dict:
    from pipeline.backends import gpu_uuids

    out = {}
    for n in sorted({1, n_gpus}):
        barrier = data / f"env_barrier_{n}"
        barrier.mkdir(parents=True, exist_ok=True)
        for f in barrier.iterdir():
            f.unlink()
        procs = []
        for k in range(n):
            env = {**os.environ, "CUDA_VISIBLE_DEVICES": str(k)}
            procs.append(subprocess.Popen([sys.executable, "-m", "benchmarks.gpu.multi_gpu", "--env-worker", "--data", str(data),
                                           "--catalog", str(catalog), "--gpu-rank", str(k), "--group", str(n),
                                           "--barrier", str(barrier), "--steps", str(steps),
                                           "--result", str(barrier / f"result-{k}.json")], env=env))
        for p in procs:
            if p.wait() != 0:
                raise RuntimeError(f"an env worker failed (exit {p.returncode})")
        rs = [json.loads((barrier / f"result-{k}.json").read_text()) for k in range(n)]
        smi = gpu_uuids()
        out[str(n)] = {"per_gpu": [{"gpu": r["cuda_visible"], "steps_per_s": round(r["steps_per_s"], 1),
                                    "raw_render_fps": round(r["raw_render_fps"], 1), "cuda_device": r["cuda_device"],
                                    "uuid_matches_pinned": r["gpu_uuid"].removeprefix("GPU-") == smi.get(r["cuda_visible"])}
                                   for r in rs],
                       "total_steps_per_s": round(sum(r["steps_per_s"] for r in rs), 1),
                       "concurrent_s": round(min(r["finished"] for r in rs) - max(r["started"] for r in rs), 2),
                       "scene": rs[0]["scene"], "gaussians": rs[0]["gaussians"]}
    if len(out) > 1:
        out["scaling"] = out[str(n_gpus)]["total_steps_per_s"] / out["1"]["total_steps_per_s"]
    return out


def markdown(rep: dict) -> str:
    """docs/benchmarks/bench_multi_gpu.md from multi_gpu.json."""
    m = rep["machine"]
    lines = ["# bench-multi-gpu: several GPUs on one host", "",
             f"{len(m['gpus'])} x {m['gpus'][0]}, {m['cpu_cores']} cores; torch {m['torch']}, Python {m['python']}. "
             f"Reproduce: `make bench-multi-gpu` (`python -m benchmarks.gpu.multi_gpu`).", ""]
    rel = rep.get("release")
    if rel:
        p, g = rel["placement"], rel["gpu"]
        lines += [f"**Release run**: {rel['scenes']} scenes ({rep['scenes']} synthetic of {rep['gaussians']:,} Gaussians "
                  f"and {rel['scenes'] - rep['scenes']} real indoor), {rep['cpu_workers']} CPU workers beside "
                  f"{rep['gpus']} GPU workers, every default stage plus goal images and a batched oracle evaluation "
                  f"(gsplat, 64 slots): {rel['wall_s']:.0f} s. From the run summary's placement section:", "",
                  "| worker | pinned GPU (UUID) | UUID its CUDA work used | tasks | busy s |", "|---|---|---|---|---|"]
        for name, w in p["workers"].items():
            if w["gpu"]:
                lines.append(f"| {name} | {w['gpu']} ({w['pinned_uuid'][:8]}) | {', '.join(u[:8] for u in w['cuda_uuids'])} | "
                             f"{', '.join(f'{k} {v}' for k, v in w['tasks'].items())} | {w['busy_s']:.0f} |")
        cpu = [w for w in p["workers"].values() if not w["gpu"]]
        lines += [f"| {len(cpu)} CPU workers | none | - | {sum(sum(w['tasks'].values()) for w in cpu)} tasks | "
                  f"{sum(w['busy_s'] for w in cpu):.0f} |", "",
                  f"{p['gpu_tasks_with_cuda']} of {p['gpu_tasks']} GPU tasks used CUDA, {len(p['misplaced'])} on a GPU other "
                  f"than their worker's; the GPU stages were busy {p['gpu_busy_s']:.0f} s of wall time and CPU stages ran "
                  f"beside them {p['cpu_gpu_overlap_s']:.0f} s of it. GPU-stage task seconds: "
                  + ", ".join(f"{k} {v['task_s']:.0f}" for k, v in g["per_stage"].items()) + ".", ""]
    gi = rep.get("release_goal_images")
    if gi:
        st = gi["gpu"]["per_stage"]
        lines += [f"**Goal images** (a second release run, {gi.get('scenes_synthetic', gi['scenes'])} synthetic scenes, "
                  f"goal_images.enabled=true): {st['goal_images']['images']} goal images in {st['goal_images']['task_s']:.1f} "
                  f"task seconds over {len(gi['gpu']['by_gpu'])} GPUs; {len(gi['placement']['misplaced'])} tasks misplaced.", ""]
    sc = rep.get("scaling")
    if sc and "scaling" in sc:
        n = str(rep["gpus"])
        lines += ["**GPU-stage throughput, 1 GPU vs all** (voxelize, semantics, goal_images, evaluate forced on the same "
                  "scenes, upstream cached; tasks / wall seconds from the first GPU task's start to the last one's end):", "",
                  "| GPUs | GPU tasks | seconds | tasks/s | tasks per GPU |", "|---|---|---|---|---|"]
        for k in ("1", n):
            r = sc[k]
            lines.append(f"| {k} | {r['gpu_tasks']} | {r['span_s']:.1f} | {r['tasks_per_s']:.3f} | "
                         f"{', '.join(f'{g}: {c}' for g, c in r['by_gpu'].items())} |")
        lines += ["", f"Scaling {sc['scaling']:.2f}x on {n} GPUs ({sc['scaling'] / int(n):.2f} N; target >= 0.8 N).", ""]
    env = rep.get("env")
    if env and "scaling" in env:
        n = str(rep["gpus"])
        e1, en = env["1"], env[n]
        lines += [f"**Vectorised evaluation env, one env group per GPU** (64 slots, 640x480 RGB-D, {e1['scene']} of "
                  f"{e1['gaussians']:,} Gaussians, one process per GPU, all stepping at once):", "",
                  "| GPUs | steps/s per GPU | total steps/s | each process on its pinned GPU |", "|---|---|---|---|"]
        for k, e in (("1", e1), (n, en)):
            per = ", ".join(f"{r['steps_per_s']:,.0f}" for r in e["per_gpu"])
            lines.append(f"| {k} | {per} | "
                         f"{e['total_steps_per_s']:,.0f} | {all(r['uuid_matches_pinned'] for r in e['per_gpu'])} |")
        lines += ["", f"Total {env['scaling']:.2f}x with {n} GPUs.", ""]
    return "\n".join(lines)


def machine() -> dict:
    import platform

    import torch

    return {"gpus": [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())],
            "cpu_cores": os.cpu_count(), "torch": torch.__version__, "python": platform.python_version()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default="data/multi_gpu")
    ap.add_argument("--real", nargs="*", default=[], help="real scenes to add: SPZ files, SOG folders or folders of them")
    ap.add_argument("--scenes", type=int, default=16)
    ap.add_argument("--gaussians", type=int, default=1_000_000)
    ap.add_argument("--workers", type=int, default=None, help="CPU workers (default: cores - GPUs)")
    ap.add_argument("--phases", default="release,scaling,env")
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--eval-episodes", type=int, default=64, help="evaluated episodes per scene and task")
    ap.add_argument("--markdown", action="store_true", help="print the page of an existing multi_gpu.json")
    ap.add_argument("--docs", action="store_true", help="write docs/benchmarks/bench_multi_gpu.md from an existing multi_gpu.json")
    ap.add_argument("--renderer", default="gsplat", help="the evaluation's renderer (cpu: a smoke test without CUDA)")
    # an env worker process (started by the env phase)
    ap.add_argument("--env-worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--catalog", help=argparse.SUPPRESS)
    ap.add_argument("--gpu-rank", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--group", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--barrier", help=argparse.SUPPRESS)
    ap.add_argument("--result", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.env_worker:
        env_worker(args)
        return 0
    if args.markdown or args.docs:
        md = markdown(json.loads((Path(args.out) / "multi_gpu.json").read_text()))
        if args.docs:
            from benchmarks.pages import write_page

            write_page("bench_multi_gpu.md", md)
        print(md)
        return 0
    from pipeline.backends import visible_gpus

    work = gpu_work(args.eval_episodes, args.renderer)

    n_gpus = len(visible_gpus())
    if n_gpus < 1:
        print("benchmarks.gpu.multi_gpu: no GPU here (nvidia-smi lists none)", file=sys.stderr)
        return 2
    data = Path(args.data).resolve()
    catalog = write_catalog(data, [Path(r) for r in args.real], args.scenes, args.gaussians)
    workers = args.workers or max(1, (os.cpu_count() or 2) - n_gpus)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    report_file = out_dir / "multi_gpu.json"
    rep = json.loads(report_file.read_text()) if report_file.exists() else {}
    rep.update({"machine": machine(), "scenes": args.scenes, "gaussians": args.gaussians, "cpu_workers": workers,
                "gpus": n_gpus})
    for phase in args.phases.split(","):
        t0 = time.perf_counter()
        if phase == "release":
            rep["release"] = release(data, catalog, workers, work)
        elif phase == "scaling":
            rep["scaling"] = scaling(data, catalog, workers, n_gpus, work)
        elif phase == "env":
            rep["env"] = env_groups(data, catalog, n_gpus, args.steps)
        else:
            raise SystemExit(f"unknown phase {phase!r} (release, scaling, env)")
        rep.setdefault("phase_s", {})[phase] = round(time.perf_counter() - t0, 1)
        report_file.write_text(jsonio.dumps(rep, indent=1, default=str))
        print(phase, json.dumps({k: v for k, v in rep[phase].items() if k not in ("placement", "failures")},
                                default=str)[:3000], flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
