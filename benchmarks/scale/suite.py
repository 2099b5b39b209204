"""Issue 13's proof in one command (make bench-scale; about two hours on two cores):

1. the default dataset (when data/ has no run yet), the real indoor scenes in full and compact
   storage (data/real_indoor, data/real_indoor_compact);
2. the release cost: one-core sample runs of a real and a synthetic 1.5 M-Gaussian scene at 1/10 of
   the release density (data/cost_real, data/cost_synthetic; the GPU stage times come from
   release_gpu.json, written on a CUDA machine by `python -m benchmarks.publishing.release_gpu`);
3. the CPU renderer (its frames/s and its bound) on the real scenes;
4. the 2,000-scene simulation and the SLURM tests;
5. the report: data/08_reports/bench_scale.{json,md} and docs/benchmarks/bench_scale.md.

    python -m benchmarks.scale.suite [--skip-runs]   # --skip-runs: reuse the data roots already there
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

from benchmarks.scale.bench_scale import fresh_bench_root

PROJECT = Path(__file__).resolve().parents[2]
COST = ["executor=sync", "goal_images.enabled=true", "task.pointnav.episodes_per_scene=400",
        "task.imagenav.episodes_per_scene=400", "task.objectnav.episodes_per_scene=280"]
"""The release density's episode counts at 1/10 of the scenes' default, one process."""
ONE_CORE = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
            "SOURCE_DATE_EPOCH": "1700000000"}


def _run(args: list[str], env: dict | None = None) -> None:
    cmd = [sys.executable, "-m", *args]
    print("+", " ".join(cmd), flush=True)
    subprocess.run(cmd, cwd=PROJECT, env={**os.environ, **(env or {})}, check=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--skip-runs", action="store_true", help="reuse the pipeline runs' data roots already there")
    ap.add_argument("--docs", default="docs/benchmarks/bench_scale.md")
    a = ap.parse_args(argv)
    try:
        if not a.skip_runs:
            if not (PROJECT / "data/_runs/latest.json").exists():
                _run(["pipeline"])
            _run(["pipeline", "scenes=real_indoor", "data_root=data/real_indoor"])
            _run(["pipeline", "scenes=real_indoor", "data_root=data/real_indoor_compact", "ingest.store=reference",
                  "asset.aligned_format=spz", "voxelize.store_opacity=false"])
            for root in ("data/cost_real", "data/cost_synthetic"):  # a cost sample computes every stage
                fresh_bench_root(PROJECT / root, "bench-scale's cost sample")
            _run(["pipeline", "data_root=data/cost_real", "scenes=real_indoor", "scenes.limit=1", *COST], ONE_CORE)
            _run(["pipeline", "data_root=data/cost_synthetic", "scenes.count=1", "scenes.num_gaussians=1500000",
                  *COST], ONE_CORE)
        _run(["benchmarks.scale.bench_scale", "cost", "data/cost_real", "data/cost_synthetic"])
        _run(["benchmarks.scale.render_cpu", "--real-root", "data/real_indoor"])
        _run(["benchmarks.scale.render_cpu", "--bound", "--real-root", "data/real_indoor"])
        _run(["benchmarks.scale.bench_scale", "sim", "--root", "data/sim"])
        _run(["benchmarks.scale.bench_scale", "slurm"])
        _run(["benchmarks.scale.bench_scale", "report", "--data", "data", "--real-root", "data/real_indoor",
              "--compact-root", "data/real_indoor_compact", "--docs", a.docs])
    except subprocess.CalledProcessError as e:
        print(f"bench-scale: {' '.join(map(str, e.cmd[1:4]))} exited {e.returncode}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
