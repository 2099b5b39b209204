"""Fault injection: the pipeline's promises (resumable, failure-isolated, deterministic) under the
faults a release job meets on a shared cluster. Each scenario runs a small pipeline (two synthetic
scenes), injects its fault, finishes or resumes, and compares every stored output byte for byte
with an undisturbed reference run (benchmarks.dataset.compare_data; time stamps pinned with
SOURCE_DATE_EPOCH).

Scenarios: kill_run (SIGKILL of the whole run at points spread over the stages, then a rerun that
must redo nothing already done), kill_worker (SIGKILL of a Dask worker in the middle of each
stage), full_disk (a size-limited tmpfs; root only), concurrent (two identical runs, and two
shards, on one data root at once), damaged (outputs truncated or deleted behind their markers),
determinism (1, 2 and 4 workers, and 3 shards run one after the other).

    PYTHONPATH=tests python -m faults.faults [--kills 20] [--only kill_run,full_disk]   # -> data/08_reports/bench_faults.{json,md}
"""
from __future__ import annotations

import argparse
import fcntl
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.dataset.compare_data import compare
from benchmarks.pages import write_page

PROJECT = Path(__file__).resolve().parents[2]
BASE = ("scenes.count=2", "scenes.num_gaussians=40000", "task.pointnav.episodes_per_scene=10",
        "task.imagenav.episodes_per_scene=10", "task.objectnav.episodes_per_scene=10", "executor.dashboard=false")
ENV = {"SOURCE_DATE_EPOCH": "1700000000", "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


def command(root: Path, *over: str) -> list[str]:
    return [sys.executable, "-m", "pipeline", f"data_root={root}", *BASE, *over]


def start(root: Path, *over: str, log: Path | None = None) -> subprocess.Popen:
    out = open(log or os.devnull, "ab")
    return subprocess.Popen(command(root, *over), cwd=PROJECT, env={**os.environ, **ENV}, stdout=out,
                            stderr=subprocess.STDOUT, start_new_session=True)


def run(root: Path, *over: str, timeout: float = 1800, log: Path | None = None) -> dict:
    p = start(root, *over, log=log or root.parent / f"{root.name}.log")
    rc = p.wait(timeout)
    summary = json.loads((root / "_runs" / "latest.json").read_text()) if (root / "_runs" / "latest.json").exists() \
        else {}
    return {"rc": rc, "summary": summary}


def markers(root: Path) -> set[tuple[str, str]]:
    return {(p.parent.name, p.stem) for p in (root / "_markers").glob("*/*.json") if not p.stem.startswith("_")}


def statuses(summary: dict, status: str) -> set[tuple[str, str]]:
    return {(r["stage"], r["scene_id"]) for r in summary.get("results", []) if r["status"] == status}


def mismatches(ref: Path, root: Path) -> list[str]:
    c = compare(ref, root)
    return [f"only in reference: {x}" for x in c["only_first"]] + [f"only here: {x}" for x in c["only_second"]] + \
        [f"differs: {x}" for x in c["differing"]]


def result(kind: str, injected: int, survived: int, bad: list[str], **extra) -> dict:
    return {"kind": kind, "injected": injected, "survived": survived, "byte_mismatches": len(bad),
            "mismatched_files": bad[:20], **extra}


def held_locks(root: Path, stage: str = "*") -> dict[str, int]:
    """{"stage/key": pid} of the task locks held now (a task of that stage and scene is running)."""
    out = {}
    for lock in sorted((root / "_locks").glob(f"{stage}/*.lock")):
        try:
            fd = os.open(lock, os.O_RDONLY)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
            fcntl.flock(fd, fcntl.LOCK_UN)
        except BlockingIOError:
            parts = lock.read_text().split()
            if len(parts) == 2 and parts[1].isdigit():
                out[f"{lock.parent.name}/{lock.stem}"] = int(parts[1])
        finally:
            os.close(fd)
    return out


def held_lock(root: Path, stage: str) -> int | None:
    """The pid holding a lock of `stage` now (a task of that stage is running there), or None."""
    return next(iter(held_locks(root, stage).values()), None)


# ---- scenarios --------------------------------------------------------------------------------

def kill_run(ref: Path, work: Path, kills: int = 20, seed: int = 0) -> dict:
    """SIGKILL the whole run (its process group) at `kills` points spread over the stages: the k-th
    kill comes once the k/kills share of the reference's (stage, scene) markers exist, after a
    random extra delay; then a rerun must complete, redo nothing that was done, and match."""
    root = work / "kill_run"
    total = len(markers(ref))
    rng = np.random.default_rng(seed)
    killed, points = 0, []
    for k in range(kills):
        target = min(total - 1, round(k * total / kills))
        p = start(root, log=work / "kill_run.log")
        while p.poll() is None and len(markers(root)) < target:
            time.sleep(0.05)
        time.sleep(float(rng.uniform(0.0, 1.5)))
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
            killed += 1
            points.append(len(markers(root)))
    before = markers(root)
    r = run(root)
    redone = sorted(before & statuses(r["summary"], "done"))
    bad = mismatches(ref, root)
    ok = r["rc"] == 0 and not r["summary"].get("failures") and not redone
    return result("kill_run", killed, killed if ok and not bad else 0, bad, markers_at_kills=points,
                  redone_after_rerun=[f"{s}/{c}" for s, c in redone], total_tasks=total)


def kill_worker(ref: Path, work: Path) -> dict:
    """A Dask LocalCluster of 2 workers; while the run goes, SIGKILL the worker process running a
    task of each stage in turn (found through the task's lock file): the scheduler reruns the task
    elsewhere, the run completes and matches."""
    root = work / "kill_worker"
    stages = ["ingest", "voxelize", "align", "costmap", "semantics", "asset", "episodes", "export"]
    p = start(root, "executor=local", "executor.n_workers=2", "executor.threads_per_worker=1",
              log=work / "kill_worker.log")
    killed, hit = 0, []
    pending = list(stages)
    while p.poll() is None and pending:
        for st in list(pending):
            pid = held_lock(root, st)
            if pid and pid != p.pid:
                try:
                    os.kill(pid, signal.SIGKILL)
                    killed += 1
                    hit.append(st)
                except ProcessLookupError:
                    pass
                pending.remove(st)
        time.sleep(0.02)
    rc = p.wait(1800)
    summary = json.loads((root / "_runs" / "latest.json").read_text())
    failures = summary.get("failures", [])
    bad = mismatches(ref, root)
    ok = rc == 0 and not failures  # the run itself absorbed every kill: no rerun
    return result("kill_worker", killed, killed if ok and not bad else 0, bad, stages_hit=hit,
                  failures=[f"{f['stage']}/{f['scene_id']}: {f.get('error', '')[:160]}" for f in failures[:5]])


def full_disk(ref: Path, work: Path) -> dict:
    """A tmpfs a third the size of the reference's data: the run fails the scene whose write hits
    the full disk with a clear error and no marker; after the disk grows, a rerun completes."""
    mnt = work / "small_disk"
    mnt.mkdir(parents=True, exist_ok=True)
    size = sum(p.stat().st_size for p in ref.rglob("*") if p.is_file())
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={max(size // 3, 1 << 20)}",
                                            "tmpfs", str(mnt)], capture_output=True).returncode:
        return result("full_disk", 0, 0, [], skipped="cannot mount a tmpfs here (needs root)")
    try:
        root = mnt / "data"
        log = work / "full_disk_run1.log"
        r1 = run(root, log=log)
        fails = r1["summary"].get("failures", [])
        if not fails:  # no room left for the run summary itself: the console said it
            import re

            text = re.sub(r"\s+", " ", log.read_text(errors="replace"))
            fails = [{"stage": m.group(1), "scene_id": m.group(2), "error": "disk full"}
                     for m in re.finditer(r"failed (\S+) (\w+) \([^)]*\): disk full", text)]
        full = [f for f in fails if "disk full" in f.get("error", "")]
        trusted = [f"{f['stage']}/{f['scene_id']}" for f in full if (root / "_markers" / f["stage"] /
                                                                      f"{f['scene_id']}.json").exists()]
        subprocess.run(["mount", "-o", f"remount,size={size * 3}", str(mnt)], check=True)
        r2 = run(root, log=work / "full_disk_run2.log")
        bad = mismatches(ref, root)
        ok = bool(full) and not trusted and r2["rc"] == 0 and not r2["summary"].get("failures")
        return result("full_disk", len(full), len(full) if ok and not bad else 0, bad,
                      errors=[f["error"][:200] for f in full[:3]], markers_of_failed=trusted)
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def concurrent(ref: Path, work: Path) -> dict:
    """Two identical runs, then two shards, started at once on one data root: no (stage, scene)
    is computed by both, nothing fails, the outputs match."""
    out, injected, survived, bad_all = {}, 0, 0, []
    for name, overs in (("identical", [(), ()]), ("shards", [("scenes.shard=0", "scenes.num_shards=2"),
                                                               ("scenes.shard=1", "scenes.num_shards=2")])):
        root = work / f"concurrent_{name}"
        procs = [start(root, *o, log=work / f"concurrent_{name}_{i}.log") for i, o in enumerate(overs)]
        rcs = [p.wait(1800) for p in procs]
        runs = sorted((root / "_runs").glob("run-*.json"))
        sums = [json.loads(p.read_text()) for p in runs]
        done = [statuses(s, "done") for s in sums]
        # a dataset-level step may run in both (under its lock, one after the other, each over all
        # the scenes present then): the same files; scene tasks must not
        twice = sorted(x for x in set.intersection(*done) if not x[0].endswith(":finalize")) if len(done) == 2 else []
        fails = [f for s in sums for f in s.get("failures", [])]
        bad = mismatches(ref, root)
        injected += 1
        ok = rcs == [0, 0] and len(sums) == 2 and not twice and not fails and not bad
        survived += ok
        bad_all += bad
        out[name] = {"ok": ok, "computed_twice": [f"{s}/{c}" for s, c in twice], "failures": len(fails),
                     "waited": sum(1 for s in sums for r in s.get("results", []) if r.get("waited_s"))}
    return result("concurrent", injected, survived, bad_all, runs=out)


def damaged(ref: Path, work: Path) -> dict:
    """Outputs truncated or deleted behind their markers (one file of each stage's outputs): the
    rerun notices from the markers' manifests, recomputes exactly those, and matches."""
    root = work / "damaged"
    shutil.copytree(ref, root, symlinks=True)
    (root / "_runs").exists() and shutil.rmtree(root / "_runs")
    rng = np.random.default_rng(1)
    hurt = {}
    for m in sorted((root / "_markers").glob("*/*.json")):
        man = json.loads(m.read_text()).get("manifest") or {}
        files = [k for k in man if not os.path.isabs(k) and (root / k).is_file()]
        if not files:
            continue
        k = files[int(rng.integers(len(files)))]
        f = root / k
        if f.stat().st_nlink > 1:  # a hard link shares its bytes with the source: replace, do not cut
            data = f.read_bytes()
            f.unlink()
            f.write_bytes(data)
        if rng.random() < 0.5:
            f.unlink()
        else:
            with open(f, "r+b") as fh:
                fh.truncate(max(0, f.stat().st_size // 2))
        hurt[(m.parent.name, m.stem)] = k
    r = run(root)
    redone = statuses(r["summary"], "done")
    missed = sorted(set(hurt) - redone)
    bad = mismatches(ref, root)
    ok = r["rc"] == 0 and not r["summary"].get("failures") and not missed
    return result("damaged", len(hurt), len(hurt) if ok and not bad else 0, bad,
                  not_recomputed=[f"{s}/{c}" for s, c in missed])


def determinism(ref: Path, work: Path) -> dict:
    """The same config with 1, 2 and 4 Dask workers, and as 3 shards one after the other: every
    stored byte equal to the reference (a sync run)."""
    out, bad_all, survived = {}, [], 0
    variants = {f"workers_{n}": [("executor=local", f"executor.n_workers={n}", "executor.threads_per_worker=1")]
                for n in (1, 2, 4)}
    variants["shards_3"] = [(f"scenes.shard={k}", "scenes.num_shards=3") for k in range(3)]
    for name, runs_ in variants.items():
        root = work / f"determinism_{name}"
        rcs = [run(root, *o)["rc"] for o in runs_]
        bad = mismatches(ref, root)
        ok = all(rc == 0 for rc in rcs) and not bad
        survived += ok
        bad_all += bad
        out[name] = {"ok": ok, "byte_mismatches": len(bad)}
    return result("determinism", len(variants), survived, bad_all, variants=out)


def out_of_memory(ref: Path, work: Path) -> dict:
    """One scene far too large for the worker's memory limit, beside the reference's two: the
    large scene fails with the reason (its worker killed by Dask's nanny on every try), the two
    others complete and match the reference."""
    from faults.fuzz_readers import small_scene
    from navcore.gaussians.formats import write_inria_ply

    big = work / "big" / "scene.ply"
    big.parent.mkdir(parents=True)
    write_inria_ply(big, small_scene(10_000_000, 0, 3))  # 620 MB on disk, well over 1.5 GB once read
    cat = work / "catalog.yaml"
    cat.write_text("synthetic: {count: 2, first_seed: 0, prefix: synth, group: synthetic}\n"
                   f"scenes:\n  - {{name: too_big, group: big, path: {big}, format: inria_ply}}\n")
    root = work / "oom"
    r = run(root, f"scenes.catalog={cat}", "executor=local", "executor.n_workers=1", "executor.threads_per_worker=1",
            "executor.memory_limit=1500MB")
    fails = r["summary"].get("failures", [])
    failed_scenes = {f["scene"] for f in fails}
    reason = next((f["error"] for f in fails if f["scene"] == "too_big" and f["status"] == "failed"), "")
    shutil.rmtree(big.parent, ignore_errors=True)
    bad = mismatches(ref, root)
    # the big scene's outputs (none trusted) are not in the reference; the others must match it
    bad = [b for b in bad if "/big/" not in b and not any(x in b for x in _scene_ids_of(root, "too_big"))]
    ok = failed_scenes == {"too_big"} and "memory" in reason
    return result("out_of_memory", 1, int(ok and not bad), bad, reason=reason[:300],
                  failed_scenes=sorted(failed_scenes))


def _scene_ids_of(root: Path, name: str) -> list[str]:
    s = json.loads((root / "_runs" / "latest.json").read_text()) if (root / "_runs" / "latest.json").exists() else {}
    return sorted({r["scene_id"] for r in s.get("results", []) if r["scene"] == name})


def _free_port() -> int:
    import socket

    with socket.socket() as sk:
        sk.bind(("127.0.0.1", 0))
        return sk.getsockname()[1]


def _external_cluster(port: int, work: Path, workers: int = 2, wait_for: int | None = None
                      ) -> tuple[subprocess.Popen, list[subprocess.Popen]]:
    """A `dask scheduler` on port and `workers` one-thread `dask worker`s, as a cluster on other
    machines would be (executor.address); returns once `wait_for` workers (default: these) are
    connected."""
    from distributed import Client

    dask_cli = str(Path(sys.executable).parent / "dask")
    log = open(work / f"cluster_{port}.log", "ab")
    env = {**os.environ, **ENV}
    sched = subprocess.Popen([dask_cli, "scheduler", "--port", str(port), "--no-dashboard"], stdout=log,
                             stderr=subprocess.STDOUT, env=env, start_new_session=True)
    ws = [subprocess.Popen([dask_cli, "worker", f"tcp://127.0.0.1:{port}", "--nthreads", "1", "--no-dashboard",
                            "--death-timeout", "120"], stdout=log, stderr=subprocess.STDOUT, env=env,
                           start_new_session=True) for _ in range(workers)]
    with Client(f"tcp://127.0.0.1:{port}", timeout=60) as c:
        c.wait_for_workers(wait_for or workers, timeout=120)
    return sched, ws


def _stop(*procs) -> None:
    for p in procs:
        if p is not None and p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def scheduler_killed(ref: Path, work: Path) -> dict:
    """An external scheduler (executor.address) SIGKILLed mid-run: the run stops within a bounded
    time with the reason (no hang), trusts nothing half-written; the workers close with it; a rerun
    against a fresh scheduler and workers on the same address completes and matches the reference."""
    root, port = work / "scheduler_killed", _free_port()
    sched, ws = _external_cluster(port, work)
    try:
        p = start(root, f"executor.address=tcp://127.0.0.1:{port}", log=work / "scheduler_killed_run1.log")
        while p.poll() is None and len(markers(root)) < len(markers(ref)) // 3:
            time.sleep(0.05)
        _stop(sched)
        t0 = time.time()
        rc1 = p.wait(600)
        stop_s = round(time.time() - t0, 1)
        s1 = json.loads((root / "_runs" / "latest.json").read_text())
        lost = [f for f in s1.get("failures", []) if "scheduler was lost" in f.get("error", "")]
        _stop(*ws)  # the workers closed with their scheduler (as dask-jobqueue's do): a fresh cluster
        sched, ws = _external_cluster(port, work)
        r2 = run(root, f"executor.address=tcp://127.0.0.1:{port}", log=work / "scheduler_killed_run2.log")
        bad = mismatches(ref, root)
        ok = rc1 == 1 and lost and stop_s < 120 and r2["rc"] == 0 and not r2["summary"].get("failures")
        return result("scheduler_killed", 1, int(bool(ok) and not bad), bad, stopped_after_s=stop_s,
                      tasks_reported_lost=len(lost), rerun_rc=r2["rc"])
    finally:
        _stop(sched, *ws)


def client_killed(ref: Path, work: Path) -> dict:
    """The client SIGKILLed while an external cluster's workers run its tasks (they go on: orphans);
    a rerun started at once on the same cluster completes, waits for an orphan only while it holds
    the lock of the very (stage, scene) it needs, lets no orphan overwrite what it wrote (the write
    fence of pipeline.tasks.new_run) and matches the reference."""
    root, port = work / "client_killed", _free_port()
    sched, ws = _external_cluster(port, work)
    try:
        p = start(root, f"executor.address=tcp://127.0.0.1:{port}", log=work / "client_killed_run1.log")
        orphan = None
        while p.poll() is None and orphan is None:  # a costmap task running on a worker: kill its client
            orphan = held_lock(root, "costmap")
            time.sleep(0.02)
        _stop(p)
        t0 = time.time()
        r2 = run(root, f"executor.address=tcp://127.0.0.1:{port}", log=work / "client_killed_run2.log")
        waited = [x.get("waited_s", 0) for x in r2["summary"].get("results", []) if x.get("waited_s")]
        bad = mismatches(ref, root)
        ok = orphan is not None and r2["rc"] == 0 and not r2["summary"].get("failures")
        return result("client_killed", 1, int(ok and not bad), bad, orphan_worker_pid=orphan,
                      rerun_s=round(time.time() - t0, 1), rerun_waited_on_locks_s=round(sum(waited), 2))
    finally:
        _stop(sched, *ws)


# ---- batch-cluster scenarios (a one-node SLURM: scripts/slurm_localhost.sh) -----------------------

def _slurm() -> str | None:
    """Why the SLURM scenarios cannot run here, or None."""
    if shutil.which("sbatch") is None or subprocess.run(["sinfo", "-h"], capture_output=True).returncode:
        return "no SLURM here (make test-slurm starts a one-node one: scripts/slurm_localhost.sh, root)"
    return None


def _submit(root: Path, *flags: str) -> str:
    """`make submit`'s array job of the base config over 2 shards; returns its job id."""
    import re

    p = subprocess.run([sys.executable, "-m", "pipeline.submit", "--shards", "2", "--cpus", "1", "--mem", "4G", *flags,
                        "--", f"data_root={root}", *BASE], cwd=PROJECT, env={**os.environ, **ENV},
                       capture_output=True, text=True)
    m = re.search(r"Submitted batch job (\d+)", p.stdout)
    if not m:
        raise RuntimeError(f"sbatch did not take the job: {p.stdout[-500:]} {p.stderr[-500:]}")
    return m.group(1)


def _queued(job: str) -> bool:
    return bool(subprocess.run(["squeue", "-h", "-j", job], capture_output=True, text=True).stdout.strip())


def _wait_job(job: str, timeout: float = 1800) -> None:
    deadline = time.time() + timeout
    while _queued(job):
        if time.time() > deadline:
            subprocess.run(["scancel", job])
            raise TimeoutError(f"SLURM job {job} still queued after {timeout} s")
        time.sleep(1)


def _shard_runs(root: Path, since: float = 0.0) -> list[dict]:
    out = []
    for p in sorted((root / "_runs").glob("run-*-shard*.json")):
        if p.stat().st_mtime >= since:
            out.append(json.loads(p.read_text()))
    return out


def _until_a_third(root: Path, ref: Path, timeout: float = 900) -> None:
    """Wait until a batch job on root has written a third of the reference's markers."""
    deadline = time.time() + timeout
    while len(markers(root)) < len(markers(ref)) // 3 and time.time() < deadline:
        time.sleep(0.2)


def slurm_cancel(ref: Path, work: Path) -> dict:
    """A running array job cancelled (scancel) mid-stage, then resubmitted: it completes, redoes
    nothing that was done, and matches."""
    if (why := _slurm()):
        return result("slurm_cancel", 0, 0, [], skipped=why)
    root = work / "slurm_cancel"
    job = _submit(root, "--requeue-before", "0")
    _until_a_third(root, ref)
    subprocess.run(["scancel", job], check=True)
    _wait_job(job)
    before = markers(root)
    t0 = time.time()
    _wait_job(_submit(root, "--requeue-before", "0"))
    results = [x for r in _shard_runs(root, t0) for x in r["results"]]
    redone = sorted(before & {(x["stage"], x["scene_id"]) for x in results if x["status"] == "done"})
    fails = [f for r in _shard_runs(root, t0) for f in r["failures"]]
    bad = mismatches(ref, root)
    ok = bool(before) and not redone and not fails and len(_shard_runs(root, t0)) == 2
    return result("slurm_cancel", 1, int(ok and not bad), bad, markers_at_cancel=len(before),
                  redone=[f"{s}/{c}" for s, c in redone])


def slurm_time_limit(ref: Path, work: Path) -> dict:
    """Array tasks near their time limit: the submit script asks SLURM for USR1 30 s before the
    limit (`#SBATCH --signal=B:USR1@30`, pipeline.submit --requeue-before); on it each task stops its
    run and requeues itself; the stage it was in carries no marker and is redone; the tasks finish
    after the requeue, and the outputs match.

    The signal is sent here, with the same scancel SLURM's time-limit handler amounts to, once a third
    of the reference's markers exist: SLURM checks time limits about once a minute, so a one-minute
    limit's signal came before or after the ~20 s shard runs by chance (a run in which no task was
    stopped tested nothing and counted 0 injected)."""
    import re

    if (why := _slurm()):
        return result("slurm_time_limit", 0, 0, [], skipped=why)
    root = work / "slurm_time_limit"
    job = _submit(root, "--time", "00:10:00", "--requeue-before", "30", "--max-requeues", "20")
    script = "".join(p.read_text() for p in (root / "_submit").glob("*.sh"))
    wired = "--signal=B:USR1@30" in script and "trap requeue USR1" in script
    _until_a_third(root, ref)
    running = subprocess.run(["squeue", "-h", "-j", job, "-t", "R", "-o", "%i"], capture_output=True,
                             text=True).stdout.split()
    subprocess.run(["scancel", "--signal=USR1", "--batch", job], check=True)
    at_signal = len(markers(root))
    _wait_job(job, 2400)
    logs = "".join(p.read_text(errors="replace") for p in (root / "_submit" / "logs").glob(f"navarena-{job}_*.out"))
    requeues = len(re.findall(r"requeueing", logs))
    last = {}
    for r in _shard_runs(root):
        last[tuple(r["shard"])] = r
    fails = [f for r in last.values() for f in r["failures"]]
    bad = mismatches(ref, root)
    ok = wired and requeues == len(running) > 0 and len(last) == 2 and not fails
    return result("slurm_time_limit", requeues, requeues if ok and not bad else 0, bad, tasks_signalled=len(running),
                  markers_at_signal=at_signal, script_asks_signal=wired, shard_runs=len(_shard_runs(root)),
                  failures=[f.get("error", "")[:120] for f in fails[:3]])


def slurm_double_submit(ref: Path, work: Path) -> dict:
    """The same two shards submitted twice at once by mistake: both arrays run side by side on one
    data root; no (stage, scene) is computed twice, every marker parses, and the outputs match."""
    if (why := _slurm()):
        return result("slurm_double_submit", 0, 0, [], skipped=why)
    root = work / "slurm_double_submit"
    # one task of each array at a time (two CPUs here): shard 0 of both arrays runs side by side
    jobs = [_submit(root, "--requeue-before", "0", "--max-running", "1") for _ in range(2)]
    for j in jobs:
        _wait_job(j)
    runs = _shard_runs(root)
    done = [(x["stage"], x["scene_id"]) for r in runs for x in r["results"]
            if x["status"] == "done" and not x["stage"].endswith(":finalize")]
    twice = sorted({d for d in done if done.count(d) > 1})
    broken = [str(p) for p in (root / "_markers").rglob("*.json") if _unparsable(p)]
    fails = [f for r in runs for f in r["failures"]]
    bad = mismatches(ref, root)
    ok = len(runs) == 4 and not twice and not broken and not fails
    return result("slurm_double_submit", 1, int(ok and not bad), bad, computed_twice=[f"{s}/{c}" for s, c in twice],
                  unparsable_markers=broken, waited=sum(1 for r in runs for x in r["results"] if x.get("waited_s")))


def _unparsable(p: Path) -> bool:
    try:
        json.loads(p.read_text())
        return False
    except ValueError:
        return True


def slurm_worker_cancel(ref: Path, work: Path) -> dict:
    """executor=slurm (Dask workers in SLURM jobs, dask-jobqueue): one of the two worker jobs
    cancelled while it holds tasks; the run goes on with the other (or fails cleanly naming the
    lost worker) and a rerun completes; the outputs match."""
    if (why := _slurm()):
        return result("slurm_worker_cancel", 0, 0, [], skipped=why)
    root = work / "slurm_worker_cancel"
    over = ("executor=slurm", "executor.jobqueue.jobs=2", "executor.jobqueue.cores=1", "executor.jobqueue.processes=1",
            "executor.jobqueue.memory=4GB", "executor.jobqueue.walltime=00:30:00",
            f"executor.jobqueue.log_directory={work / 'slurm_worker_logs'}")
    p = start(root, *over, log=work / "slurm_worker_cancel.log")
    cancelled = None
    while p.poll() is None and cancelled is None:
        jobs = subprocess.run(["squeue", "-h", "-n", "navarena-worker", "-t", "R", "-o", "%i"], capture_output=True,
                              text=True).stdout.split()
        if len(jobs) == 2 and held_lock(root, "costmap"):
            cancelled = jobs[0]
            subprocess.run(["scancel", cancelled])
        time.sleep(0.2)
    rc1 = p.wait(1800)
    s1 = json.loads((root / "_runs" / "latest.json").read_text())
    r2 = run(root, *over, log=work / "slurm_worker_cancel_rerun.log")
    bad = mismatches(ref, root)
    ok = cancelled is not None and r2["rc"] == 0 and not r2["summary"].get("failures")
    return result("slurm_worker_cancel", int(cancelled is not None), int(ok and not bad), bad,
                  first_run_rc=rc1, first_run_failures=[f.get("error", "")[:160] for f in s1.get("failures", [])[:3]])


def changed_source(ref: Path, work: Path) -> dict:
    """Sources that change under a finished run (pipeline.sources). Two real scenes (the reference's
    generated sources copied as outside files, one with a labelled mesh); after a finished run:
    a source replaced with other bytes (that scene recomputed from ingest on, the other cached),
    its labelled mesh edited (semantics on recomputed, nothing upstream), the source truncated
    and deleted (ingest fails naming the file, nothing of the scene trusted), restored, then other
    bytes behind the same size and mtime (noticed with verify=checksum). The final root must
    equal, byte for byte, an undisturbed run made from the final files."""
    from faults.fuzz_inputs import _boxes, write_labelled_ply
    from navcore.gaussians.formats import read_gaussians, write_inria_ply

    root = work / "changed_source"
    src = root / "sources"  # inside the data root: both roots name their sources alike (<ROOT>/sources)
    src.mkdir(parents=True)
    gen = sorted((ref / "00_sources" / "synthetic").glob("*/scene.ply"))
    shutil.copy(gen[0], src / "a.ply")
    shutil.copy(gen[1], src / "b.ply")
    verts, faces = _boxes()
    write_labelled_ply(src / "a_labels.ply", verts + [1.0, 1.0, 0.0], faces, {"label": [6] * 8 + [5] * 8})
    cat = src / "catalog.yaml"
    cat.write_text("scenes:\n  - {name: a, group: real, path: a.ply, labels: {mesh: a_labels.ply, mesh_classes: nyu40}}\n"
                   "  - {name: b, group: real, path: b.ply}\n")
    over = (f"scenes.catalog={cat}",)
    a = src / "a.ply"
    steps, log = {}, work / "changed_source.log"

    def rerun(*extra):
        r = run(root, *over, *extra, log=log)
        return r, {(x["scene"], x["stage"]): x["status"] for x in r["summary"].get("results", [])}

    first, _ = rerun()
    ok0 = first["rc"] == 0
    stages_a = lambda st, want: sorted(k[1] for k, v in st.items() if k[0] == "a" and v == want)  # noqa: E731
    cached_b = lambda st: all(v == "cached" for k, v in st.items() if k[0] == "b" and v != "n/a")  # noqa: E731
    # 1. other bytes at the same path
    g = read_gaussians(a)
    g.means = g.means + np.array([0.05, 0.0, 0.0], g.means.dtype)
    write_inria_ply(a, g)
    r, st = rerun()
    row = (r["summary"].get("sources_changed") or [{}])[0]
    steps["replaced"] = bool(cached_b(st) and "ingest" in stages_a(st, "done") and not stages_a(st, "cached")
                             and row.get("file") == str(a) and row.get("new_sha256"))
    # 2. the labelled mesh edited: semantics and later only
    write_labelled_ply(src / "a_labels.ply", verts + [1.5, 1.0, 0.0], faces, {"label": [6] * 8 + [5] * 8})
    r, st = rerun()
    steps["mesh_edited"] = bool(cached_b(st) and "semantics" in stages_a(st, "done") and
                                {"ingest", "voxelize", "align", "costmap"} <= set(stages_a(st, "cached")))
    # 3. truncated, 4. deleted: ingest fails naming the file; nothing of the scene trusted
    good = a.read_bytes()
    for name, hurt in (("truncated", lambda: a.write_bytes(good[: len(good) // 3])), ("deleted", a.unlink)):
        hurt()
        r, st = rerun()
        err = next((f.get("error", "") for f in r["summary"].get("failures", []) if f["scene"] == "a"
                    and f["stage"] == "ingest"), "")
        sid = next((x["scene_id"] for x in r["summary"].get("results", []) if x["scene"] == "a"), "?")
        steps[name] = bool(r["rc"] == 1 and str(a.name) in err and cached_b(st) and
                           not (root / "_markers" / "ingest" / f"{sid}.json").exists())
    # restored
    a.write_bytes(good)
    r, _ = rerun()
    restored = r["rc"] == 0
    # 5. other bytes behind the same size and mtime: verify=checksum notices
    st0 = a.stat()
    data = bytearray(good)
    data[-3] ^= 0x10
    a.write_bytes(bytes(data))
    os.utime(a, ns=(st0.st_atime_ns, st0.st_mtime_ns))
    _, st = rerun()
    quiet = all(v in ("cached", "n/a") for v in st.values())  # size mode cannot tell (documented)
    r, st = rerun("verify=checksum")
    steps["same_size_and_mtime"] = bool(quiet and r["rc"] == 0 and "ingest" in stages_a(st, "done") and cached_b(st))
    # the undisturbed run from the final files
    und = work / "undisturbed"
    shutil.copytree(src, und / "sources")
    u = run(und, f"scenes.catalog={und / 'sources' / 'catalog.yaml'}", log=work / "undisturbed.log")
    bad = mismatches(und, root)
    ok = ok0 and restored and u["rc"] == 0
    return result("changed_source", len(steps), sum(steps.values()) if ok and not bad else 0, bad, steps=steps)


SCENARIOS = {"kill_run": kill_run, "kill_worker": kill_worker, "full_disk": full_disk, "concurrent": concurrent,
             "damaged": damaged, "determinism": determinism, "out_of_memory": out_of_memory,
             "changed_source": changed_source, "scheduler_killed": scheduler_killed, "client_killed": client_killed,
             "slurm_cancel": slurm_cancel, "slurm_time_limit": slurm_time_limit, "slurm_double_submit": slurm_double_submit,
             "slurm_worker_cancel": slurm_worker_cancel}


def code_digest() -> str:
    """What the reference's bytes depend on: the packages' code, the configs and catalogs, the base
    overrides. A reference made by other code is stale (its bytes legitimately differ)."""
    h = hashlib.sha256(repr(BASE).encode())
    for top in ("navcore", "stages", "pipeline", "conf", "catalogs"):
        for f in sorted((PROJECT / top).rglob("*")):
            if f.is_file() and f.suffix in (".py", ".yaml", ".json", ".csv", ".txt"):
                h.update(str(f.relative_to(PROJECT)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def reference(work: Path) -> Path:
    """The undisturbed run every scenario compares with, reused while the code it was made with is
    today's (its digest is stored beside it), made again otherwise."""
    ref = work / "reference"
    stamp, digest = work / "reference.code.sha256", code_digest()
    if not stamp.exists() or stamp.read_text() != digest or not (ref / "_runs" / "latest.json").exists():
        shutil.rmtree(ref, ignore_errors=True)
        stamp.unlink(missing_ok=True)
        r = run(ref)
        if r["rc"] != 0 or r["summary"].get("failures"):
            raise RuntimeError(f"the undisturbed reference run failed: {r['summary'].get('failures')}")
        stamp.write_text(digest)
    return ref


def run_scenario(name: str, ref: Path, work: Path, kills: int = 20) -> dict:
    """One scenario in a fresh folder work/name, timed."""
    d = work / name
    if d.exists():
        shutil.rmtree(d, ignore_errors=True)
    d.mkdir(parents=True)
    t0 = time.perf_counter()
    r = SCENARIOS[name](ref, d, kills) if name == "kill_run" else SCENARIOS[name](ref, d)
    r["seconds"] = round(time.perf_counter() - t0, 1)
    return r


def markdown(rep: dict) -> str:
    lines = ["# Fault injection and hostile input (issues 14 and 48)", "",
             f"Machine: {rep['machine']}. Reproduce: `make test-faults`.", "",
             "| fault | injected | survived | byte mismatches | seconds | notes |", "|---|---|---|---|---|---|"]
    for r in rep["scenarios"].values():
        notes = {k: v for k, v in r.items() if k not in ("kind", "injected", "survived", "byte_mismatches",
                                                         "mismatched_files", "seconds")}
        lines.append(f"| {r['kind']} | {r['injected']} | {r['survived']} | {r['byte_mismatches']} | "
                     f"{r.get('seconds', '')} | {json.dumps(notes)[:300]} |")
    lines += ["", f"Totals: {rep['faults_injected']} faults injected, {rep['faults_survived']} survived, "
              f"{rep['byte_mismatches']} byte mismatches."]
    fz = rep.get("fuzz")
    if fz:
        lines += ["", "| reader | cases |", "|---|---|"]
        lines += [f"| {k} | {v:,} |" for k, v in fz["cases_per_reader"].items()]
        lines += ["", f"Reader fuzzing: {fz['fuzz_cases']:,} cases, {fz['fuzz_crashes']} crashes, {fz['fuzz_hangs']} "
                  "hangs (`PYTHONPATH=tests python -m faults.fuzz_readers`)."]
    ff = rep.get("fuzz_frames")
    if ff:
        lines += ["", "| agent-server frame (side:type) | cases |", "|---|---|"]
        lines += [f"| {k} | {v:,} |" for k, v in ff["cases_per_frame_type"].items()]
        lines += ["", f"Frame fuzzing: {sum(ff['cases_per_frame_type'].values()):,} cases, {ff['crashes']} crashes "
                  f"(memory included), {ff['hangs']} hangs (`PYTHONPATH=tests python -m faults.fuzz_frames`)."]
    fi = rep.get("fuzz_inputs")
    if fi:
        lines += ["", "| input | cases | crashes | hangs |", "|---|---|---|---|"]
        lines += [f"| {k} | {v:,} | {fi['crashes_per_group'].get(k, 0)} | {fi['hangs_per_group'].get(k, 0)} |"
                  for k, v in fi["cases_per_group"].items()]
        lines += ["", "Catalogs, label folders and labelled meshes: `PYTHONPATH=tests python -m faults.fuzz_inputs` (a "
                  "case ends in an accepted input or a ValueError naming the file)."]
    for ch in (rep.get("chaos"), rep.get("chaos_long")):
        if not ch:
            continue
        kinds: dict[str, int] = {}
        for e in ch["events"]:
            kinds[e["fault"]] = kinds.get(e["fault"], 0) + 1
        lost, est = ch["time_lost_s"], ch.get("time_lost_estimate")
        lost_text = "n/a (a sample)" if lost is None else \
            f"{lost} s (against {ch.get('time_lost_from') or 'an undisturbed run of the same scenes'})"
        lines += ["", f"## A run under chaos ({ch['minutes_planned']:g} minutes planned)", "",
                  f"`PYTHONPATH=tests python -m faults.chaos --minutes {ch['minutes_planned']:g}`: {ch['scenes']:,} scenes of "
                  "the scale simulation on an external Dask cluster (a scheduler, two workers under nannies); "
                  f"faults: {', '.join(f'{k} {v}' for k, v in kinds.items())}.", "",
                  "| figure | value |", "|---|---|",
                  f"| wall time under chaos | {ch['wall_s']} s ({ch['attempts']} runs started) |",
                  f"| undisturbed run of the compared scenes | {ch['undisturbed_wall_s']} s |",
                  f"| time lost to faults | {lost_text} |",
                  *([f"| time lost, the run's own lower bound (stalls after the scheduler / client kills + the killed "
                     f"workers' tasks) | {est['total_s']} s ({est['stalls_s']} + {est['worker_tasks_s']}) |"] if est else []),
                  f"| tasks the killed workers held (retried) | {ch['tasks_retried']} |",
                  f"| client peak memory | {ch['client_peak_rss_mb']} MB |",
                  f"| markers not current (outputs hashed) | {len(ch['markers_not_current'])} |",
                  f"| scenes compared byte for byte | {ch['compared']['scenes']} ({ch['compared']['files']:,} files) |",
                  f"| byte mismatches | {len(ch['byte_mismatches'])} |",
                  *(["", ch["note"]] if ch.get("note") else [])]
    if rep.get("provenance"):  # a merged report's parts were measured at different times
        lines += ["", "Where the parts of this report were measured:", ""] + [f"- {p}" for p in rep["provenance"]]
    if "fuzz_cases" in rep:
        lines += ["", f"All fuzzing: {rep['fuzz_cases']:,} cases, {rep['fuzz_crashes']} crashes, {rep['fuzz_hangs']} hangs."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    from benchmarks import machine, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", default="/tmp/navarena_faults")
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--only", default=",".join(SCENARIOS))
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", action="store_true", help="also write docs/benchmarks/bench_faults.md")
    ap.add_argument("--merge", nargs="+", type=Path,
                    help="instead of running: bench_faults.json files, later ones replacing earlier scenarios")
    ap.add_argument("--provenance", nargs="+", default=[],
                    help="with --merge: where and when each merged part was measured (a line each on the page)")
    args = ap.parse_args(argv)
    rep = {"machine": machine(), "base_overrides": list(BASE), "scenarios": {}, "provenance": args.provenance}
    if args.merge:
        for f in args.merge:
            r = json.loads(Path(f).read_text())
            rep["scenarios"].update(r["scenarios"])
            rep.setdefault("merged_from", []).append({"file": str(f), "scenarios": list(r["scenarios"])})
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    ref = None if args.merge else reference(work)
    for name in ([] if args.merge else args.only.split(",")):
        rep["scenarios"][name] = r = run_scenario(name, ref, work, args.kills)
        print(json.dumps(r), flush=True)
    rep["faults_injected"] = sum(r["injected"] for r in rep["scenarios"].values())
    rep["faults_survived"] = sum(r["survived"] for r in rep["scenarios"].values())
    rep["byte_mismatches"] = sum(r["byte_mismatches"] for r in rep["scenarios"].values())
    fz = Path(args.out) / "fuzz_readers.json"
    if fz.exists():
        f = json.loads(fz.read_text())
        rep["fuzz"] = {k: f[k] for k in ("fuzz_cases", "fuzz_crashes", "fuzz_hangs", "cases_per_reader")}
        rep.update({k: f[k] for k in ("fuzz_cases", "fuzz_crashes", "fuzz_hangs")})
    ff = Path(args.out) / "fuzz_frames.json"
    if ff.exists():  # frames (faults.fuzz_frames) count into the fuzz totals too
        f = json.loads(ff.read_text())
        rep["fuzz_frames"] = {"cases_per_frame_type": {k: v["cases"] for k, v in f["kinds"].items()},
                              "crashes": f["fuzz_frame_crashes"], "hangs": f["fuzz_frame_hangs"],
                              "peak_rss_mb": f.get("peak_rss_mb")}
        for ours, theirs in (("fuzz_cases", "fuzz_frame_cases"), ("fuzz_crashes", "fuzz_frame_crashes"),
                             ("fuzz_hangs", "fuzz_frame_hangs")):
            rep[ours] = rep.get(ours, 0) + f[theirs]
    fi = Path(args.out) / "fuzz_inputs.json"
    if fi.exists():  # catalogs, label folders, labelled meshes (faults.fuzz_inputs)
        f = json.loads(fi.read_text())
        per = {"cases_per_group": f["cases_per_group"], "crashes_per_group": {}, "hangs_per_group": {}}
        for r in f["kinds"].values():
            per["crashes_per_group"][r["input"]] = per["crashes_per_group"].get(r["input"], 0) + r["crash"] + r["memory"]
            per["hangs_per_group"][r["input"]] = per["hangs_per_group"].get(r["input"], 0) + r["hang"]
        rep["fuzz_inputs"] = per
        for k in ("fuzz_cases", "fuzz_crashes", "fuzz_hangs"):
            rep[k] = rep.get(k, 0) + f[k]
    for name in ("chaos", "chaos_long"):  # the runs under chaos (faults.chaos): in the totals
        ch = Path(args.out) / f"{name}.json"
        if not ch.exists():
            continue
        c = json.loads(ch.read_text())
        rep[name] = c
        rep["scenarios"][name] = result(name, c["faults_injected"], c["faults_survived"], c["byte_mismatches"],
                                        scenes=c["scenes"], wall_s=c["wall_s"], tasks_retried=c["tasks_retried"])
        for total, k in (("faults_injected", "injected"), ("faults_survived", "survived"),
                         ("byte_mismatches", "byte_mismatches")):
            rep[total] = sum(r[k] for r in rep["scenarios"].values())
    write_report(args.out, "bench_faults.json", rep)
    (Path(args.out) / "bench_faults.md").write_text(markdown(rep))
    if args.docs:
        write_page("bench_faults.md", markdown(rep))
    return rep


if __name__ == "__main__":
    main()
