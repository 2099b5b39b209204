"""Real batch-scheduler runs (SLURM, one node on this machine; `make test-slurm` starts it with
scripts/slurm_localhost.sh): the sharded array job of `make submit`, a cancelled job resubmitted,
and executor=slurm (Dask workers in SLURM jobs through dask-jobqueue). Every run's outputs must
equal, byte for byte, those of a local run of the same config."""
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.slurm]

SCENES = ["scenes.count=2", "scenes.num_gaussians=60000", "task.pointnav.episodes_per_scene=12",
          "task.imagenav.episodes_per_scene=8", "task.objectnav.episodes_per_scene=8"]
ENV = {**os.environ, "SOURCE_DATE_EPOCH": "1700000000"}


@pytest.fixture(scope="module")
def slurm(project_root):
    if shutil.which("sinfo") is None or subprocess.run(["sinfo", "-h"], capture_output=True).returncode != 0:
        rc = subprocess.run([str(project_root / "scripts" / "slurm_localhost.sh")]).returncode
        assert rc == 0, "scripts/slurm_localhost.sh could not start SLURM"
    return True


@pytest.fixture(scope="module")
def reference(tmp_path_factory, project_root):
    """The same dataset run locally, once."""
    root = tmp_path_factory.mktemp("local") / "data"
    run([sys.executable, "-m", "pipeline", f"data_root={root}", "executor.dashboard=false", *SCENES], project_root)
    return root


def run(cmd, cwd, check=True, **kw):
    p = subprocess.run(cmd, cwd=cwd, env=ENV, capture_output=True, text=True, **kw)
    if check:
        assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
    return p


def same_outputs(a: Path, b: Path):
    from benchmarks.dataset.compare_data import compare

    rep = compare(a, b)
    assert rep["files"][0] > 20 and not (rep["only_first"] or rep["only_second"] or rep["differing"]), rep


def shard_summaries(root: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted((root / "_runs").glob("run-*-shard*.json"))]


def submit(root, project_root, *flags):
    return run(["make", "-s", "submit", "SHARDS=2", f"SUBMIT_FLAGS=--cpus 1 --mem 4G {' '.join(flags)}",
                f"ARGS=data_root={root} {' '.join(SCENES)}"], project_root)


def test_make_submit_array_job(slurm, reference, tmp_path, project_root):
    root = tmp_path / "data"
    submit(root, project_root, "--wait")
    runs = shard_summaries(root)
    assert sorted(r["shard"] for r in runs) == [[0, 2], [1, 2]]  # one run per array task
    assert all(not r["failures"] for r in runs)
    scenes = [{x["scene_id"] for x in r["results"] if x["scene_id"] != "*"} for r in runs]
    assert len(scenes[0]) == len(scenes[1]) == 1 and not scenes[0] & scenes[1]  # disjoint shards
    assert len(list((root / "_submit" / "logs").glob("navarena-*_*.out"))) == 2
    same_outputs(reference, root)


def test_cancelled_job_resubmitted_completes_only_what_is_missing(slurm, reference, tmp_path, project_root):
    root = tmp_path / "data"
    out = submit(root, project_root).stdout
    job = re.search(r"Submitted batch job (\d+)", out).group(1)
    deadline = time.time() + 600
    while not list((root / "_markers" / "costmap").glob("*.json")):  # cancel mid-run
        assert time.time() < deadline, "the job made no progress"
        time.sleep(1)
    run(["scancel", job], project_root)
    while subprocess.run(["squeue", "-h", "-j", job], capture_output=True, text=True).stdout.strip():
        time.sleep(1)
    before = {p.relative_to(root / "_markers") for p in (root / "_markers").rglob("*.json")}
    assert before and not list((root / "_markers" / "export").glob("*.json"))
    t0 = time.time()
    submit(root, project_root, "--wait")
    runs = [r for r in shard_summaries(root) if r["started_at"] >= time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(t0 - 1))]
    results = [x for r in runs for x in r["results"] if x["scene_id"] != "*"]
    cached = {Path(x["stage"]) / f"{x['scene_id']}.json" for x in results if x["status"] == "cached"}
    assert cached == before  # exactly what had finished is reused, the rest is computed
    assert all(x["status"] in ("done", "cached", "n/a") for x in results)
    same_outputs(reference, root)


def test_executor_slurm_dask_jobqueue(slurm, reference, tmp_path, project_root):
    root = tmp_path / "data"
    run([sys.executable, "-m", "pipeline", f"data_root={root}", "executor=slurm", "executor.dashboard=false",
         "executor.jobqueue.jobs=1", "executor.jobqueue.cores=2", "executor.jobqueue.processes=2",
         "executor.jobqueue.memory=8GB", "executor.jobqueue.walltime=00:30:00",
         f"executor.jobqueue.log_directory={tmp_path / 'logs'}", *SCENES], project_root, timeout=1500)
    summary = json.loads((root / "_runs" / "latest.json").read_text())
    assert not summary["failures"]
    workers = {x["worker"] for x in summary["results"] if "worker" in x}
    assert workers and all(w.startswith("SLURMCluster-") for w in workers), workers
    same_outputs(reference, root)
