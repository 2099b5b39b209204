"""Issue 13's proof: storage, the SLURM runs, the 2,000-scene simulation, the release cost and the
CPU renderer, as data/08_reports/bench_scale.{json,md}.

    python -m benchmarks.scale.bench_scale sim [--scenes 2000] [--root /tmp/navarena_sim]   -> sim.json
    python -m benchmarks.scale.bench_scale cost [--root /tmp/navarena_cost] [--fraction 0.1]   -> cost.json
    python -m benchmarks.scale.bench_scale slurm                                             -> slurm.json
    python -m benchmarks.scale.bench_scale report [--data data] [--real-root /tmp/real2] [--compact-root DIR] [--docs FILE]
        (--compact-root: the real scenes run with COMPACT, the options for compressed sources)
        (storage of the two roots, then everything above plus render_cpu.json and, from a CUDA
        run of benchmarks.publishing.release_gpu, release_gpu.json -> bench_scale.json / .md)

Each part writes its own JSON under --out (data/08_reports) so that the long ones (sim: about an
hour on two cores) run once; `report` assembles what is there (`make bench-scale` runs them all).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

from benchmarks import run_polled, write_report
from benchmarks.pages import write_page

PROJECT = Path(__file__).resolve().parents[2]
# tiny procedural scenes: one small room, 20 k Gaussians, 6 episodes, semantics off, coarser
# obstacle and support grids (the defaults' 5 mm obstacle grid dominates a tiny scene's time)
SIM = ["scenes.num_gaussians=20000", "synthetic.layout.rooms_min=1", "synthetic.layout.rooms_max=1",
       "synthetic.layout.room_size_min_m=3.6", "synthetic.layout.room_size_max_m=4.0", "semantics.enabled=false",
       "task=[pointnav,imagenav]", "task.pointnav.episodes_per_scene=4", "task.imagenav.episodes_per_scene=2",
       "costmap.raw_resolution=0.025", "costmap.support_resolution=0.1", "executor.dashboard=false"]
# release density per scene: 8,000 PointNav + ImageNav and 2,800 ObjectNav (22.2 M over 2,000 scenes)
RELEASE = {"pointnav": 4000, "imagenav": 4000, "objectnav": 2800}
RELEASE_SCENES = 2000
PER_EPISODE_STAGES = ("episodes", "objectnav_episodes", "goal_images", "export")


def run_pipeline(root: Path, overrides: list[str], log: Path, env=None) -> dict:
    """python -m pipeline in a subprocess: wall time, the client's peak RSS (polled), exit code."""
    r = run_polled([sys.executable, "-m", "pipeline", f"data_root={root}", *overrides], log, cwd=PROJECT,
                   env={**os.environ, **(env or {})}, interval=0.5)
    if r["exit"] != 0:
        raise SystemExit(f"pipeline run failed (exit {r['exit']}); see {log}")
    return {"wall_s": r["wall_s"], "client_peak_rss_mb": r["peak_rss_mb"], "rc": r["exit"]}


def scheduler_gaps(results: list[dict]) -> dict:
    """Per worker, the idle time between one task's end and its next task's start (the scheduler's
    and the transport's share), over the tasks."""
    by = defaultdict(list)
    for r in results:
        if "started" in r and r.get("duration_s") is not None:
            by[r["worker"]].append((r["started"], r["started"] + r["duration_s"]))
    gaps = []
    for spans in by.values():
        spans.sort()
        gaps += [max(0.0, b[0] - a[1]) for a, b in zip(spans, spans[1:])]
    n = sum(len(v) for v in by.values())
    return {"tasks_timed": n, "workers": len(by), "gap_ms_per_task": 1000 * sum(gaps) / max(n, 1),
            "gap_ms_median": 1000 * sorted(gaps)[len(gaps) // 2] if gaps else 0.0}


BENCH_MARK = ".bench_root"
"""A file in a root a benchmark run made (the simulation's, the cost samples'): only such a root (or an
empty one) is cleared for a new run."""


def fresh_bench_root(root: Path, who: str = "bench_scale sim") -> Path:
    """An empty root for a benchmark run that must compute every task (the simulation's first run, a
    cost sample): a root a benchmark made before is removed (a finished one would turn the run into a
    resume of cached tasks and its figures into nonsense); a non-empty root it did not make is
    refused, naming it and `who` refuses."""
    import shutil

    if root.exists() and any(root.iterdir()):
        if not (root / BENCH_MARK).is_file():
            raise SystemExit(f"{who}: {root} holds files no benchmark made (no {BENCH_MARK}); "
                             "pass another root or remove it")
        shutil.rmtree(root)
    root.mkdir(parents=True, exist_ok=True)
    (root / BENCH_MARK).write_text(f"made by {who}; cleared by its next run\n")
    return root


def sim(args) -> dict:
    root = fresh_bench_root(Path(args.root))
    over = [f"scenes.count={args.scenes}", *SIM]
    first = run_pipeline(root, over, Path(args.out) / "logs" / "sim_run.log")
    latest = root / "_runs" / "latest.json"
    summary = json.loads(latest.read_text())
    results = [r for r in summary["results"] if r["scene_id"] != "*"]
    cached = sum(r["status"] == "cached" for r in results)
    if cached:
        raise SystemExit(f"bench_scale sim: the first run found {cached} tasks cached in {root}: not a first run")
    files = [p for p in root.rglob("*") if p.is_file() and p.parts[len(root.parts)] != "_hydra"]
    by_layer = defaultdict(int)
    for p in files:
        by_layer[p.parts[len(root.parts)]] += 1
    resume = run_pipeline(root, over, Path(args.out) / "logs" / "sim_resume.log")
    again = json.loads(latest.read_text())
    statuses = defaultdict(int)
    for r in again["results"]:
        statuses[r["status"]] += 1
    rep = {"sim_scenes": args.scenes, "overrides": SIM, "tasks": len(results), "run": first,
           "failures": len(summary["failures"]), "counts": summary["counts"], **scheduler_gaps(results),
           "task_seconds": sum(r.get("duration_s") or 0 for r in results),
           "files_per_scene": len(files) / args.scenes, "files_by_layer": dict(by_layer),
           "run_summary_bytes": latest.stat().st_size, "resume": resume, "resume_statuses": dict(statuses),
           "host": platform.node(), "cpu_cores": os.cpu_count()}
    rep["sim_overhead_ms_per_task"] = rep["gap_ms_per_task"]
    rep["sim_resume_s"] = resume["wall_s"]
    write(args.out, "sim.json", rep)
    return rep


TASK_SHARE = {t: n / sum(RELEASE.values()) for t, n in RELEASE.items()}
RELEASE_EPISODES = 22_200_000
EPISODE_SIZED = ("episodes", "objectnav_episodes", "goal_images", "export")
"""Stages whose work grows with the episodes (scaled from the sample); every other stage a sample ran
(synthesize, ingest, voxelize, align, costmap, screen, semantics, asset, and any stage added later) is
counted once a scene, as the run summary timed it."""
GPU_STAGES = ("voxelize", "semantics", "goal_images")
SAM3_FPS_H100 = 16.7
"""SAM3 image model, 8 prompts, bf16, on the H100 (bench-semantics-gpu, 2026-11-22): the segmenting rate of
the cost model when no sam3 timing of the release_gpu.json machine is in semantics_gpu.json."""


def sam3_rate(out: Path, device: str | None) -> tuple[float, str]:
    """(SAM3 frames/s, where it comes from): semantics_gpu.json's sam3 timing (semantics --sam3-timing or
    --sam3-only) when it was measured on `device` (release_gpu.json's GPU), else SAM3_FPS_H100."""
    f = out / "semantics_gpu.json"
    if f.is_file():
        sem = json.loads(f.read_text())
        t = sem.get("sam3_timing")
        if t and t.get("frames_per_s") and sem.get("device") == device:
            return float(t["frames_per_s"]), f"semantics_gpu.json's sam3 timing on {device}"
    return SAM3_FPS_H100, "the H100's sam3 timing of 2026-11-22 (SAM3_FPS_H100)"


def sample_of(root: Path) -> dict:
    """A cost run's per-stage seconds (single core), episodes per task, semantics views, bytes."""
    from benchmarks.dataset.storage import measure

    summary = json.loads((root / "_runs" / "latest.json").read_text())
    sec = {r["stage"]: r.get("duration_s") or 0.0 for r in summary["results"] if r["scene_id"] != "*"}
    if any(r["status"] == "cached" for r in summary["results"]):
        raise SystemExit(f"{root}: the last run reused stages; a cost sample must compute every stage")
    import pyarrow.parquet as pq

    eps = {p.parent.parent.name.split("=", 1)[1]: pq.read_metadata(p).num_rows
           for p in (root / "05_episodes").glob("task=*/scene_id=*/part-0.parquet")}
    sem = json.loads(next((root / "_markers" / "semantics").glob("*.json")).read_text())["info"]
    cm = json.loads(next((root / "_markers" / "costmap").glob("*.json")).read_text())["info"]
    ep = json.loads(next((root / "_markers" / "episodes").glob("*.json")).read_text())["info"]
    on = next((root / "_markers" / "objectnav_episodes").glob("*.json"), None)
    on = json.loads(on.read_text())["info"] if on else {}
    free_m2 = max(e["free_area_m2"] for e in cm["embodiments"].values())
    ing = json.loads(next((root / "01_scenes").glob("*/ingest.json")).read_text())
    st = measure(root)
    return {"name": ing["name"], "gaussians": ing["validation"]["n_kept"], "seconds": sec, "episodes": eps,
            "failures": [f"{r['stage']}: {r.get('error')}" for r in summary["failures"]],
            "semantics_views": sem.get("views", 0), "semantics_renderer": sem.get("renderer"),
            "episodes_setup_s": ep.get("setup_cpu_s", 0.0), "objectnav_episodes_setup_s": on.get("setup_cpu_s", 0.0),
            "free_area_m2": free_m2,
            "bytes_scene": st["scenes"][0]["store_and_asset_bytes"] + st["scenes"][0]["maps_bytes"],
            "source_bytes": st["scenes"][0]["source_bytes"], "bytes_per_episode": st["bytes_per_episode"]}


def extrapolate(sample: dict, gpu: dict | None, objectnav_like: str = "pointnav", sam3_fps: float = SAM3_FPS_H100) -> dict:
    """The 22.2 M release from one scene's sample: 2,000 such scenes at release density."""
    sec, eps = sample["seconds"], sample["episodes"]
    # per-episode cost of the episode-sized stages (tasks the sample lacks, e.g. ObjectNav on an
    # unlabelled real scene, are costed like `objectnav_like`)
    n_sample = sum(eps.values())
    per_scene_eps = {t: RELEASE_EPISODES / RELEASE_SCENES * TASK_SHARE[t] for t in RELEASE}
    scale = sum(per_scene_eps.values()) / max(n_sample, 1)
    goal_per = sec.get("goal_images", 0.0) / max(eps.get("imagenav", 0), 1)
    cpu = {st: t for st, t in sec.items() if st not in EPISODE_SIZED}
    # each episode stage's per-scene set-up (costmap, graph, the blind-view test's scene) does not
    # grow with the episodes; the rest is scaled
    for st in ("episodes", "objectnav_episodes"):
        setup = min(sample.get(f"{st}_setup_s", 0.0), sec.get(st, 0.0))
        cpu[st] = setup + (sec.get(st, 0.0) - setup) * scale
    cpu["goal_images"] = goal_per * per_scene_eps["imagenav"]
    cpu["export"] = sec.get("export", 0.0) * scale
    out = {"per_scene_cpu_only_s": cpu, "release_core_hours_cpu_only": sum(cpu.values()) * RELEASE_SCENES / 3600}
    if gpu:
        g = gpu["stages"]
        # a scene the sample could not segment (a real one without labels: SAM3 would run) is
        # costed with the free-space covering poses of the defaults: one per spacing^2, all around
        from stages.semantics.config import SemanticsConfig

        sc = SemanticsConfig()
        views = sample["semantics_views"] or int(sample["free_area_m2"] / sc.spacing**2 * round(360 / sc.yaw_step_deg))
        gpu_s = {"voxelize": g["voxelize_s"], "goal_images": g["goal_image_s"] * per_scene_eps["imagenav"],
                 "semantics": views * (g["semantics_view_s"] + 1.0 / sam3_fps)}
        cpu_rest = {k: v for k, v in cpu.items() if k not in GPU_STAGES}
        out.update(per_scene_gpu_s=gpu_s, per_scene_cpu_with_gpu_s=cpu_rest,
                   release_core_hours=sum(cpu_rest.values()) * RELEASE_SCENES / 3600,
                   release_gpu_hours=sum(gpu_s.values()) * RELEASE_SCENES / 3600)
    out["release_bytes"] = sample["bytes_scene"] * RELEASE_SCENES + sample["bytes_per_episode"] * RELEASE_EPISODES
    return out


def cost(args) -> dict:
    gpu_file = Path(args.out) / "release_gpu.json"
    gpu = json.loads(gpu_file.read_text()) if gpu_file.exists() else None
    fps, fps_from = sam3_rate(Path(args.out), gpu and gpu.get("device"))
    rep = {"release": {"scenes": RELEASE_SCENES, "episodes": RELEASE_EPISODES, "per_scene": RELEASE},
           "gpu": {k: gpu[k] for k in ("device", "stages")} if gpu else None, "samples": {},
           "sam3_fps": fps, "sam3_fps_from": fps_from}
    for root in args.roots:
        smp = sample_of(Path(root))
        rep["samples"][smp["name"]] = {**smp, **extrapolate(smp, gpu, sam3_fps=fps)}
    worst = max(rep["samples"].values(), key=lambda s: s.get("release_core_hours", s["release_core_hours_cpu_only"]))
    rep["release_core_hours"] = worst.get("release_core_hours")
    rep["release_gpu_hours"] = worst.get("release_gpu_hours")
    rep["release_core_hours_cpu_only"] = worst["release_core_hours_cpu_only"]
    rep["release_bytes"] = worst["release_bytes"]
    rep["host"], rep["cpu_cores"] = platform.node(), os.cpu_count()
    write(args.out, "cost.json", rep)
    return rep


def slurm(args) -> dict:
    """The SLURM tests (tests/test_slurm.py; starts a one-node SLURM here when needed)."""
    import xml.etree.ElementTree as ET

    xml = Path(args.out) / "slurm_junit.xml"
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-m", "slurm", "tests/test_slurm.py",
                        f"--junitxml={xml}"], cwd=PROJECT, capture_output=True, text=True)
    cases = [{"test": c.get("name"), "seconds": float(c.get("time", 0)),
              "outcome": "failed" if c.find("failure") is not None or c.find("error") is not None
              else "skipped" if c.find("skipped") is not None else "passed"} for c in ET.parse(xml).iter("testcase")]
    rep = {"tests": cases, "wall_s": time.perf_counter() - t0,
           "slurm_ok": p.returncode == 0 and len(cases) == 3 and all(c["outcome"] == "passed" for c in cases),
           "what": "make submit: 2-shard array job (2 array tasks, 1 CPU each); a second array job cancelled "
                   "(scancel) once a costmap marker exists, then resubmitted: exactly the finished tasks "
                   "reused; executor=slurm: 1 dask-jobqueue worker job (2 worker processes); each run's "
                   "outputs byte-identical to a local run of the same config"}
    write(args.out, "slurm.json", rep)
    return rep


# the figures this issue started from (the text, today's main before the work; same machine)
BEFORE = {"bytes_per_scene_ratio_default": 3.98, "bytes_per_episode_default": 17_100,
          "cpu_renderer": "5.4 steps/s at 160x120 on 100 k Gaussians, about 1 s a frame at 640x480",
          "make_test_minutes": "12-15"}


COMPACT = "ingest.store=reference asset.aligned_format=spz voxelize.store_opacity=false"
"""The options for compressed sources (SOG, SPZ): no Zarr copy of a SOG source, the aligned model as
SPZ v4 in place of the V1 asset's INRIA PLY, no voxel opacity field beside V (Makefile: bench-scale)."""


def load(out: Path, name: str) -> dict | None:
    p = out / name
    return json.loads(p.read_text()) if p.exists() else None


def default_scene_ids(data: Path) -> set[str]:
    """The ids of the default scene set (the catalog `make dataset` runs): the data root may also
    hold scenes another catalog put there, which are not the default dataset's storage."""
    from hydra import compose, initialize_config_dir

    from navcore.io.catalog import Catalog
    from pipeline.config import CONF_DIR, register_configs

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=[f"data_root={data}"])
    return {s.scene_id for s in Catalog(CONF_DIR.parent / cfg.scenes.catalog, data).select()}


def report(args) -> dict:
    from benchmarks.dataset.storage import measure

    out = Path(args.out)
    st = {"default": measure(Path(args.data), default_scene_ids(Path(args.data)))}
    if args.real_root and Path(args.real_root).exists():
        st["real_indoor"] = measure(Path(args.real_root))
    if args.compact_root and Path(args.compact_root).exists():
        st["real_indoor, " + COMPACT] = measure(Path(args.compact_root))
    rc, gpu, sm, sl, cs, ab, bd = (load(out, n) for n in ("render_cpu.json", "release_gpu.json", "sim.json", "slurm.json",
                                                          "cost.json", "render_cpu_ab.json", "render_cpu_bound.json"))
    d = st["default"]
    rep = {"host": platform.node(), "cpu_cores": os.cpu_count(), "before": BEFORE, "storage": st,
           "bytes_per_scene_ratio": max(s["ratio_with_maps"] for s in d["scenes"]),
           "bytes_per_episode": d["bytes_per_episode"],
           "slurm_ok": bool(sl and sl["slurm_ok"]), "slurm": sl,
           "sim_scenes": sm and sm["sim_scenes"], "sim_overhead_ms_per_task": sm and sm["sim_overhead_ms_per_task"],
           "sim_resume_s": sm and sm["sim_resume_s"], "sim": sm,
           "release_core_hours": cs and cs["release_core_hours"], "release_gpu_hours": cs and cs["release_gpu_hours"],
           "cost": cs, "cpu_fps_160": rc and rc["cpu_fps_160"], "cpu_fps_640": rc and rc["cpu_fps_640"],
           "cpu_psnr_min": gpu and min(v["psnr_min"] for v in gpu["agreement"].values()),
           "render_cpu": rc, "render_cpu_ab": ab, "render_cpu_bound": bd,
           "render_gpu": gpu and {k: gpu[k] for k in ("device", "agreement_gaussians", "agreement")}}
    write(out, "bench_scale.json", rep)
    md = markdown(rep)
    if args.notes:  # what the run found, how it was made (appended as it is)
        md += "\n" + Path(args.notes).read_text().strip() + "\n"
    (out / "bench_scale.md").write_text(md)
    if args.docs:  # only when asked (make bench-scale): a report into a scratch folder must not replace it
        write_page(Path(args.docs).name, md)
    return rep


def _size_rows(scenes: dict, row) -> list[str]:
    """One table row per scene and image size of a renderer benchmark: row(name, scene, size, figures)."""
    return [row(name, s, size, s[size]) for name, s in scenes.items() for size in ("160x120", "640x480")]


def _f(x, nd=2):
    return "n/a" if x is None else (f"{x:,.{nd}f}" if isinstance(x, float) else f"{x:,}")


def markdown(r: dict) -> str:
    L = ["# bench_scale: the release as a job users can afford (issue 13)", "",
         f"Machine: {r['host']}, {r['cpu_cores']} cores (CPU figures); GPU figures from "
         f"{(r['render_gpu'] or {}).get('device', 'no CUDA run')}. Reproduce: `make bench-scale`.", "",
         "| key | value | target |", "|---|---|---|",
         f"| bytes_per_scene_ratio (default dataset, with maps) | {_f(r['bytes_per_scene_ratio'])} | <= 1.5 |",
         f"| bytes_per_episode (with trajectory) | {_f(r['bytes_per_episode'], 0)} | <= 6,000 |",
         f"| slurm_ok | {r['slurm_ok']} | true |",
         f"| sim_scenes | {_f(r['sim_scenes'])} | 2,000 |",
         f"| sim_overhead_ms_per_task | {_f(r['sim_overhead_ms_per_task'], 1)} | |",
         f"| sim_resume_s | {_f(r['sim_resume_s'], 1)} | seconds |",
         f"| release_core_hours | {_f(r['release_core_hours'], 1)} | < 100 |",
         f"| release_gpu_hours | {_f(r['release_gpu_hours'], 2)} | < 10 |",
         f"| cpu_fps_160 (throughput, >= 1 M Gaussians, worst scene) | {_f(r['cpu_fps_160'], 1)} | >= 30 |",
         f"| cpu_fps_640 (throughput, worst scene) | {_f(r['cpu_fps_640'], 1)} | >= 5 |",
         f"| cpu_psnr_min (vs gsplat) | {_f(r['cpu_psnr_min'], 1)} dB | >= 35 |", ""]
    L += ["## Storage", "", "| data root | scene | source MB | stored MB (store + asset + maps) | ratio |",
          "|---|---|---|---|---|"]
    for root, m in r["storage"].items():
        for s in m["scenes"]:
            stored = (s["store_and_asset_bytes"] + s["maps_bytes"]) / 1e6
            L.append(f"| {root} | {s['scene_id']} | {s['source_bytes'] / 1e6:.1f} | {stored:.1f} | "
                     f"{s['ratio_with_maps']:.2f} |")
        L.append(f"| {root} | per episode | | {m['bytes_per_episode'] / 1e3:.2f} KB | |")
    L += ["", f"Before this issue: {r['before']['bytes_per_scene_ratio_default']}x a scene, "
          f"{r['before']['bytes_per_episode_default'] / 1e3:.1f} KB an episode (default dataset).", ""]
    if r["sim"]:
        s = r["sim"]
        L += ["## 2,000-scene simulation", "", f"Overrides: `{' '.join(s['overrides'])}`.", "",
              "| figure | value |", "|---|---|",
              f"| tasks | {s['tasks']:,} ({s['failures']} failed) |", f"| wall time | {s['run']['wall_s']:.0f} s |",
              f"| task seconds (sum) | {s['task_seconds']:.0f} s |",
              f"| scheduler gap per task (mean / median) | {s['gap_ms_per_task']:.1f} / {s['gap_ms_median']:.1f} ms |",
              f"| client peak memory | {s['run']['client_peak_rss_mb']:.0f} MB |",
              f"| files per scene | {s['files_per_scene']:.1f} |",
              f"| run summary | {s['run_summary_bytes'] / 1e6:.2f} MB |",
              f"| resume when all is done | {s['resume']['wall_s']:.1f} s (client {s['resume']['client_peak_rss_mb']:.0f} MB) |",
              ""]
    if r["cost"]:
        c = r["cost"]
        L += ["## Release cost (22.2 M episodes over 2,000 scenes)", "",
              "Stage seconds of one release-size scene on one core of this machine (a sample at 1/10 of the "
              "release density, episode-sized stages scaled linearly, the episode stages' per-scene set-up "
              f"counted once, every other stage once a scene), GPU stages on the {(c.get('gpu') or {}).get('device', 'GPU')} "
              "(semantics: gsplat's label "
              f"views plus SAM3 at {c.get('sam3_fps', SAM3_FPS_H100):.1f} frames/s, {c.get('sam3_fps_from', 'SAM3_FPS_H100')}):", "",
              "| scene | Gaussians | stage | CPU only (s) | with GPU: CPU (s) | with GPU: GPU (s) |", "|---|---|---|---|---|---|"]
        for name, smp in c["samples"].items():
            for stg in smp["per_scene_cpu_only_s"]:
                L.append(f"| {name} | {smp['gaussians']:,} | {stg} | {smp['per_scene_cpu_only_s'].get(stg, 0):.1f} | "
                         f"{smp.get('per_scene_cpu_with_gpu_s', {}).get(stg, 0):.1f} | "
                         f"{smp.get('per_scene_gpu_s', {}).get(stg, 0):.2f} |")
            L.append(f"| {name} | | **release** | {smp['release_core_hours_cpu_only']:,.0f} core-h | "
                     f"{_f(smp.get('release_core_hours'), 0)} core-h | {_f(smp.get('release_gpu_hours'), 1)} GPU-h |")
        L += ["", f"Release bytes (worst scene kind): {c['release_bytes'] / 1e12:.2f} TB.", ""]
    if r["render_cpu"]:
        n_runs = r["render_cpu"].get("runs", 1)
        views = next(iter(r["render_cpu"]["scenes"].values()))["views"]
        L += ["## CPU renderer", "", f"Frames/s: the throughput over {views} random free-space views a scene (views / "
              f"their total time), the median view and the slowest tenth; {n_runs} run(s), their median (this "
              "machine is shared: the runs' throughputs are listed).", "",
              "| scene | Gaussians | size | frames/s | runs | median view | p10 | torch reference | speed-up |",
              "|---|---|---|---|---|---|---|---|---|"]
        L += _size_rows(r["render_cpu"]["scenes"], lambda name, s, size, v: (
            f"| {name} | {s['n_gaussians']:,} | {size} | {v['fps']:.1f} | "
            f"{', '.join(f'{x:.1f}' for x in v.get('fps_runs', [v['fps']]))} | {_f(v.get('fps_median'), 1)} | "
            f"{v['fps_p10']:.1f} | {v['torch_reference_fps']:.2f} | {v['speedup']:.0f}x |"))
        ab = r.get("render_cpu_ab")
        if ab:
            L += ["", f"Against revision {ab['against']}'s renderer, interleaved view by view in one run (`python -m "
                  f"benchmarks.scale.render_cpu --against {ab['against']}`):", "",
                  "| scene | size | that revision ms | ours ms | speed-up | frames identical to the byte | "
                  "PSNR min between them | depth median diff max |", "|---|---|---|---|---|---|---|---|"]
            L += _size_rows(ab["scenes"], lambda name, s, size, v: (
                f"| {name} | {size} | {v['rev_ms']:.1f} | {v['ours_ms']:.1f} | {v['speedup']:.2f}x | "
                f"{v['identical_frames']} of {s['views']} | {_f(v.get('psnr_min_db'), 1)} dB | "
                f"{_f(v.get('depth_median_diff_max_m'), 7)} m |"))
        bd = r.get("render_cpu_bound")
        if bd:
            L += ["", "What a perfect occlusion culling would give (`python -m benchmarks.scale.render_cpu --bound`): each "
                  "view rendered from the whole scene, then from only the Gaussians its rasteriser read (a box with "
                  "an unfinished pixel in some tile; the frame must come out identical to the byte), interleaved:", "",
                  "| scene | size | frames/s, all Gaussians | frames/s, those read only | bound | frames identical | "
                  "Gaussians read (mean) |", "|---|---|---|---|---|---|---|"]
            L += _size_rows(bd["scenes"], lambda name, s, size, v: (
                f"| {name} | {size} | {v['fps']:.1f} | {v['fps_read_only']:.1f} | {v['bound_speedup']:.2f}x | "
                f"{v['identical_frames']} of {s['views']} | {v['gaussians_read_mean']:,.0f} of {s['n_gaussians']:,} |"))
        if r["render_gpu"]:
            L += ["", f"Agreement with gsplat ({r['render_gpu']['device']}, {r['render_gpu']['agreement_gaussians']:,} "
                  "Gaussians, 10 views):", ""]
            for size, v in r["render_gpu"]["agreement"].items():
                L.append(f"- {size}: PSNR min {v['psnr_min']:.1f} dB (median {v['psnr_median']:.1f}), depth median "
                         f"difference <= {v['depth_median_abs_m_max'] * 1000:.4f} mm; gsplat {v['gsplat_fps']:,.0f} frames/s")
        L.append("")
    if r["slurm"]:
        L += ["## SLURM", "", r["slurm"]["what"] + ".", ""]
        L += [f"- {c['test']}: {c['outcome']} ({c['seconds']:.0f} s)" for c in r["slurm"]["tests"]]
        L.append("")
    return "\n".join(L)


def write(out, name: str, rep: dict) -> None:
    write_report(out, name, rep, omit=[k for k, v in rep.items() if isinstance(v, (dict, list))])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="part", required=True)
    s = sub.add_parser("sim")
    s.add_argument("--scenes", type=int, default=2000)
    s.add_argument("--root", default="/tmp/navarena_sim")
    c = sub.add_parser("cost")
    c.add_argument("roots", nargs="+", help="data roots of release-density sample runs (one scene each)")
    sub.add_parser("slurm")
    rp = sub.add_parser("report")
    rp.add_argument("--data", default="data")
    rp.add_argument("--real-root")
    rp.add_argument("--compact-root")
    rp.add_argument("--docs", help="also write the markdown report here (make bench-scale: docs/benchmarks/bench_scale.md)")
    rp.add_argument("--notes", help="a markdown file appended to the report (what the run found)")
    for p in sub.choices.values():
        p.add_argument("--out", default="data/08_reports")
    args = ap.parse_args(argv)
    {"sim": sim, "cost": cost, "slurm": slurm, "report": report}[args.part](args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
