"""Issue 13's proof: storage, the SLURM runs, the 2,000-scene simulation, the release cost and the
CPU renderer, as data/08_reports/bench_scale.{json,md}.

    python -m benchmarks.bench_scale sim [--scenes 2000] [--root /tmp/navarena_sim]   -> sim.json
    python -m benchmarks.bench_scale cost [--root /tmp/navarena_cost] [--fraction 0.1]   -> cost.json
    python -m benchmarks.bench_scale slurm                                             -> slurm.json
    python -m benchmarks.bench_scale report [--data data] [--real-root /tmp/real2]
        (storage of the two roots, then everything above plus render_cpu.json and, from a CUDA
        run of benchmarks.release_gpu, release_gpu.json -> bench_scale.json / .md)

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

PROJECT = Path(__file__).resolve().parent.parent
# tiny procedural scenes: one small room, 20 k Gaussians, 6 episodes, semantics off
SIM = ["scenes.num_gaussians=20000", "synthetic.layout.rooms_min=1", "synthetic.layout.rooms_max=1",
       "synthetic.layout.room_size_min_m=3.6", "synthetic.layout.room_size_max_m=4.0", "semantics.enabled=false",
       "task=[pointnav,imagenav]", "task.pointnav.episodes_per_scene=4", "task.imagenav.episodes_per_scene=2",
       "executor.dashboard=false"]
# release density per scene: 8,000 PointNav + ImageNav and 2,800 ObjectNav (22.2 M over 2,000 scenes)
RELEASE = {"pointnav": 4000, "imagenav": 4000, "objectnav": 2800}
RELEASE_SCENES = 2000
PER_EPISODE_STAGES = ("episodes", "goal_images", "export")


def run_pipeline(root: Path, overrides: list[str], log: Path, env=None) -> dict:
    """python -m pipeline in a subprocess: wall time, the client's peak RSS (polled), exit code."""
    import psutil

    log.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with open(log, "w") as f:
        p = subprocess.Popen([sys.executable, "-m", "pipeline", f"data_root={root}", *overrides], cwd=PROJECT,
                             stdout=f, stderr=subprocess.STDOUT, env={**os.environ, **(env or {})})
        proc, peak = psutil.Process(p.pid), 0
        while p.poll() is None:
            try:
                peak = max(peak, proc.memory_info().rss)
            except psutil.Error:
                pass
            time.sleep(0.5)
    if p.returncode != 0:
        raise SystemExit(f"pipeline run failed (exit {p.returncode}); see {log}")
    return {"wall_s": time.perf_counter() - t0, "client_peak_rss_mb": peak / 2 ** 20, "rc": p.returncode}


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


def sim(args) -> dict:
    root = Path(args.root)
    over = [f"scenes.count={args.scenes}", *SIM]
    first = run_pipeline(root, over, Path(args.out) / "logs" / "sim_run.log")
    latest = root / "_runs" / "latest.json"
    summary = json.loads(latest.read_text())
    results = [r for r in summary["results"] if r["scene_id"] != "*"]
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


def write(out, name: str, rep: dict) -> None:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_text(json.dumps(rep, indent=1, default=str))
    print(json.dumps({k: v for k, v in rep.items() if not isinstance(v, (dict, list))}, indent=1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="part", required=True)
    s = sub.add_parser("sim")
    s.add_argument("--scenes", type=int, default=2000)
    s.add_argument("--root", default="/tmp/navarena_sim")
    for p in sub.choices.values():
        p.add_argument("--out", default="data/08_reports")
    args = ap.parse_args(argv)
    {"sim": sim}[args.part](args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
