"""A long run under chaos: the scale simulation (benchmarks.scale.bench_scale's SIM scenes) on an
external Dask cluster (a scheduler and two workers under nannies, as on a cluster: executor.address)
while a driver injects faults: a random worker process SIGKILLed every 30-90 s (its nanny starts a
new one), the scheduler SIGKILLed once (at a third of the tasks; a new one starts on the same
address with new workers, the run is started again), the whole run (the client) SIGKILLed
once (at two thirds; started again). The driver reruns the pipeline until it completes.

Then: every (stage, scene) marker must be current with its outputs hashed (verify=checksum), and
the stored bytes must equal an undisturbed run's of the same scenes, run whole afterwards on a
fresh cluster of the same kind, watched by the same loop, with no fault (the
long version's `--sample N` compares a seeded sample of N scenes instead, each scene's bytes
depending on that scene alone: half the time, but no measured time lost). The report gives the
faults injected and survived, the tasks the killed workers held (retried), the wall time lost to
faults (the two runs' wall times: the faults' own cost; every run also estimates a lower bound from itself,
`time_lost_estimate`, which the whole comparison checks) and the client's peak memory.

    PYTHONPATH=tests python -m faults.chaos --minutes 5            # about 5 minutes of chaos (make test-faults)
    PYTHONPATH=tests python -m faults.chaos --minutes 60     # CHAOS_MINUTES=60: 3,300 scenes, about 2 h in all
    -> data/08_reports/chaos.json (chaos_long.json for 60 minutes or more)
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.dataset.compare_data import digests
from benchmarks.scale.bench_scale import SIM
from faults.faults import ENV, PROJECT, _external_cluster, _free_port, _stop, held_locks, markers

SCENES_PER_MINUTE = 55
"""Scenes of the simulation one chaos minute covers on this 2-core machine, faults included, with
a margin: the run must last the minutes asked (2,000 scenes took 46.3 minutes under chaos on
2026-11-27 while test runs shared the machine; alone it ran 52.7 scenes a minute)."""


def held_by(root: Path, pid: int) -> list[str]:
    """The (stage/key) locks process `pid` holds now: the tasks a kill of it makes Dask retry."""
    return [k for k, holder in held_locks(root).items() if holder == pid]


def worker_processes(nannies) -> list:
    """The worker processes (children of the nannies) alive now."""
    import psutil

    out = []
    for n in nannies:
        try:
            out += [c for c in psutil.Process(n.pid).children(recursive=True) if "spawn_main" in " ".join(c.cmdline())]
        except psutil.Error:
            pass
    return out


def client(root: Path, port: int, scenes: int, log: Path, *extra: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "pipeline", f"data_root={root}", f"scenes.count={scenes}", *SIM, *extra,
           f"executor.address=tcp://127.0.0.1:{port}"]
    return subprocess.Popen(cmd, cwd=PROJECT, env={**os.environ, **ENV}, stdout=open(log, "ab"), stderr=subprocess.STDOUT,
                            start_new_session=True)


def chaos(root: Path, work: Path, scenes: int, minutes: float, seed: int = 0, faults: bool = True,
          extra: tuple[str, ...] = ()) -> dict:
    """Run the simulation to completion under faults; returns the figures. With faults=False the
    same run on the same kind of cluster, watched by the same loop, with no fault: the reference
    the time lost is measured against (so it holds the faults' cost alone, not the set-up's)."""
    import psutil

    rng = np.random.default_rng(seed)
    port = _free_port()
    sched, nannies = _external_cluster(port, work)
    from pipeline.graph import DEFAULT_STAGES, closure

    total = scenes * len(closure(list(DEFAULT_STAGES)))  # the (stage, scene) markers of a finished run
    events, attempts, peak, progress = [], 0, 0.0, []
    next_worker_kill = time.time() + rng.uniform(30, 90) if faults else float("inf")
    sched_killed = client_killed = not faults
    log = work / ("chaos_client.log" if faults else "undisturbed.log")
    t0 = time.time()
    try:
        while True:
            attempts += 1
            p = client(root, port, scenes, log, *extra)
            proc = psutil.Process(p.pid)
            while p.poll() is None:
                try:
                    peak = max(peak, proc.memory_info().rss / 2**20)
                except psutil.Error:
                    pass
                done = len(markers(root))
                now = time.time()
                progress.append((now - t0, done))
                if now >= next_worker_kill:
                    ws = worker_processes(nannies)
                    if ws:
                        w = ws[int(rng.integers(len(ws)))]
                        held = held_by(root, w.pid)
                        w.kill()
                        events.append({"t": round(now - t0, 1), "fault": "worker_killed", "tasks_held": held})
                    next_worker_kill = now + rng.uniform(30, 90)
                if not sched_killed and done >= total / 3:
                    _stop(sched)
                    events.append({"t": round(now - t0, 1), "fault": "scheduler_killed", "markers": done})
                    sched_killed = True
                    time.sleep(2)  # the workers close with their scheduler: the cluster starts fresh ones
                    _stop(*nannies)
                    sched, nannies = _external_cluster(port, work)
                elif sched_killed and not client_killed and done >= 2 * total / 3:
                    _stop(p)
                    events.append({"t": round(now - t0, 1), "fault": "client_killed", "markers": done})
                    client_killed = True
                time.sleep(0.5)
            latest = root / "_runs" / "latest.json"
            s = json.loads(latest.read_text()) if latest.exists() else {}
            if p.returncode == 0 and not s.get("failures"):
                break
            if attempts >= 30 or not faults:
                raise RuntimeError(f"the run did not complete in {attempts} attempt(s); see {log}")
    finally:
        _stop(sched, *nannies)
    return {"attempts": attempts, "events": events, "wall_s": round(time.time() - t0, 1), "client_peak_rss_mb": round(peak),
            "minutes_planned": minutes, "time_lost_estimate": time_lost(events, progress, root) if faults else None}


def time_lost(events: list[dict], progress: list[tuple[float, int]], root: Path) -> dict:
    """A lower bound of the wall time the faults cost, from the run itself: a scheduler or client
    kill costs at least the time from the kill until the markers count again passes the count at
    the kill (the orphaned workers of a killed client still finish tasks meanwhile, and the new
    run's start-up is not counted); a killed worker costs the tasks it held, each at the median
    seconds of its stage's computed tasks in the runs' summaries (the other worker goes on)."""
    durations: dict[str, list[float]] = {}
    for f in (root / "_runs").glob("run-*.json"):
        for r in json.loads(f.read_text()).get("results", []):
            if r.get("status") == "done" and r.get("duration_s"):
                durations.setdefault(r["stage"], []).append(r["duration_s"])
    median = {k: float(np.median(v)) for k, v in durations.items()}
    stalls = workers = 0.0
    for e in events:
        if "markers" in e:  # scheduler or client: until progress passes the count at the kill
            after = [t for t, n in progress if t > e["t"] and n > e["markers"]]
            e["stall_s"] = round((after[0] if after else progress[-1][0]) - e["t"], 1)
            stalls += e["stall_s"]
        else:
            e["retried_s"] = round(sum(median.get(k.split("/")[0], 0.0) for k in e["tasks_held"]), 1)
            workers += e["retried_s"]
    return {"stalls_s": round(stalls, 1), "worker_tasks_s": round(workers, 1), "total_s": round(stalls + workers, 1),
            "stage_median_task_s": {k: round(v, 2) for k, v in sorted(median.items())}}


def markers_current(root: Path, scenes: int) -> list[str]:
    """Every (stage, scene) of the simulation whose marker is not current with its outputs hashed."""
    from hydra import compose, initialize_config_dir

    from navcore.io.catalog import open_catalog
    from pipeline.config import CONF_DIR, register_configs
    from pipeline.graph import closure, config_hashes
    from pipeline.tasks import current

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=[f"data_root={root}", f"scenes.count={scenes}", *SIM])
    catalog, selected, _ = open_catalog(cfg)
    hashes = config_hashes(cfg)
    bad = []
    for scene in selected:
        for st in closure(list(cfg.stages)):
            if current(st.name, scene, catalog, hashes.of(st.name, scene), False, "checksum") is None:
                bad.append(f"{st.name}/{scene.scene_id}")
    return bad


def main(argv=None) -> dict:
    from benchmarks import machine, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=float(os.environ.get("CHAOS_MINUTES", 5)))
    ap.add_argument("--scenes", type=int, help=f"default: {SCENES_PER_MINUTE} a minute")
    ap.add_argument("--sample", type=int, default=0,
                    help="scenes compared with an undisturbed run (default 0: all, which measures the time lost)")
    ap.add_argument("--work", default="/tmp/navarena_chaos")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    long = args.minutes >= 60  # the 2,000-scene simulation or more
    # the long version: the 2,000-scene simulation or more, enough scenes to last the minutes asked
    scenes = args.scenes or max(2000 if long else 10, round(args.minutes * SCENES_PER_MINUTE))
    work = Path(args.work)
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    root = work / "data"
    rep = {"machine": machine(), "scenes": scenes, "overrides": SIM, **chaos(root, work, scenes, args.minutes, args.seed)}
    rep["markers_not_current"] = markers_current(root, scenes)
    # the undisturbed run: the same scenes (or a seeded sample) on a fresh cluster of the same kind
    ids = sorted({r["scene_id"] for r in json.loads((root / "_runs" / "latest.json").read_text())["results"]
                  if r["scene_id"] != "*"})
    sample = ids if not args.sample or args.sample >= len(ids) else \
        sorted(np.random.default_rng(args.seed).choice(ids, args.sample, replace=False).tolist())
    und = work / "undisturbed"
    sel = () if sample == ids else (f"scenes.ids=[{','.join(sample)}]",)
    # (chaos() raises when a run does not complete: reaching here, the reference run succeeded)
    rep["undisturbed_wall_s"] = chaos(und, work, scenes, args.minutes, args.seed, faults=False, extra=sel)["wall_s"]
    whole = sample == ids
    a, b = digests(root.resolve()), digests(und.resolve())
    if not whole:  # the sampled scenes' own files (dataset-level files depend on every scene)
        a, b = ({k: v for k, v in d.items() if any(s in k for s in sample)} for d in (a, b))
    rep["compared"] = {"scenes": len(sample), "files": len(b), "whole_root": whole}
    rep["byte_mismatches"] = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))[:50]
    # against the undisturbed run when it ran whole (as long again as the run under chaos); with a
    # sample only the run's own lower bound (time_lost_estimate). A run of the same scenes
    # measured on another commit is no reference: 2,000 scenes under chaos took 2,778 s on 2026-11-27
    # where the undisturbed simulation of 2026-11-24 had taken 2,864 s.
    rep["time_lost_s"] = round(rep["wall_s"] - rep["undisturbed_wall_s"], 1) if whole else None
    rep["time_lost_from"] = "the same scenes on the same kind of cluster, watched alike, with no fault" if whole else None
    rep["tasks_retried"] = sum(len(e.get("tasks_held", [])) for e in rep["events"])
    rep["faults_injected"] = len(rep["events"])
    ok = not rep["markers_not_current"] and not rep["byte_mismatches"]
    rep["faults_survived"] = rep["faults_injected"] if ok else 0
    write_report(args.out, "chaos_long.json" if long else "chaos.json", rep)
    print(json.dumps({k: v for k, v in rep.items() if k not in ("events", "overrides")}, indent=1))
    return rep


if __name__ == "__main__":
    main()
