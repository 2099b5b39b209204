"""Sharded batch submission: one array job, one pipeline run per shard.

    python -m pipeline.submit --shards 64 --scheduler slurm [--dry-run] [--wait] [--cpus 8] [--mem 32G]
        [--time 04:00:00] [--requeue-before 120] [--queue cpu] -- scenes=synthetic_large costmap.embodiments=[stretch]

Array task k runs ``python -m pipeline scenes.shard=k scenes.num_shards=N executor=local ...``
(every n-th scene in scene-id order: disjoint and deterministic). Completion markers make the
job safe to resubmit: finished (stage, scene) pairs are skipped, failed ones are retried.
The script is written to <data_root>/_submit/ (data_root from the overrides, default data/) and
handed to sbatch / qsub unless --dry-run; --wait blocks until the array job has ended and returns
non-zero when a task failed (sbatch --wait / qsub -W block=true).
"""
from __future__ import annotations

import argparse
import datetime as dt
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parent.parent


def array_script(scheduler: str, shards: int, overrides: list[str], cpus: int, mem: str, walltime: str,
                 queue: str | None, account: str | None, python: str, workdir: Path,
                 logs: str = "data/_submit/logs", requeue_before: int = 0, max_requeues: int = 10,
                 max_running: int = 0) -> str:
    """The batch script of an array job over the shards (logs: its log folder, relative to
    workdir or absolute). requeue_before (SLURM): seconds before the time limit at which a task
    stops its run and puts itself back in the queue (at most max_requeues times): the requeued
    task resumes from the markers, and the stage it was in is redone (its partial outputs carry
    no marker and are never trusted); 0: a task that reaches its limit is killed (resubmit it).
    max_running: at most this many of the array's tasks at once (0: as many as the cluster runs)."""
    if shards < 1:
        raise ValueError("--shards must be >= 1")
    over = " ".join(shlex.quote(o) for o in overrides)
    if scheduler == "slurm":
        throttle = f"%{max_running}" if max_running > 0 else ""
        head = ["#!/bin/bash", "#SBATCH --job-name=navarena", f"#SBATCH --array=0-{shards - 1}{throttle}",
                f"#SBATCH --cpus-per-task={cpus}", f"#SBATCH --mem={mem}", f"#SBATCH --time={walltime}",
                f"#SBATCH --output={logs}/navarena-%A_%a.out"]
        head += [f"#SBATCH --partition={queue}"] if queue else []
        head += [f"#SBATCH --account={account}"] if account else []
        head += ["#SBATCH --requeue", f"#SBATCH --signal=B:USR1@{requeue_before}", "#SBATCH --open-mode=append"] \
            if requeue_before > 0 else []  # append: a requeued task's log keeps what its earlier runs said
        index = "$SLURM_ARRAY_TASK_ID"
    elif scheduler == "pbs":
        head = ["#!/bin/bash", "#PBS -N navarena", f"#PBS -J 0-{shards - 1}",
                f"#PBS -l select=1:ncpus={cpus}:mem={mem}", f"#PBS -l walltime={walltime}",
                f"#PBS -o {logs}/", "#PBS -j oe"]
        head += [f"#PBS -q {queue}"] if queue else []
        head += [f"#PBS -A {account}"] if account else []
        head += [f"#PBS -W max_run_subjobs={max_running}"] if max_running > 0 else []  # PBS Pro's array throttle
        index = "$PBS_ARRAY_INDEX"
    else:
        raise ValueError(f"scheduler must be slurm or pbs, not {scheduler!r}")
    run = (f"{shlex.quote(python)} -m pipeline scenes.shard={index} scenes.num_shards={shards} "
           f"executor=local executor.n_workers={cpus} executor.dashboard=false {over}").rstrip()
    if scheduler == "slurm" and requeue_before > 0:
        # the run in the background, so that the time-limit signal reaches this shell's trap at once
        body = [f"cd {shlex.quote(str(workdir))}",
                'task="${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}"',
                "requeue() {",
                f'    echo "navarena: {requeue_before} s before the time limit: stopping shard {index} and requeueing $task"',
                '    kill -TERM "$run" 2>/dev/null; wait "$run"',
                f'    if [ "${{SLURM_RESTART_COUNT:-0}}" -lt {max_requeues} ]; then scontrol requeue "$task"; exit 0; fi',
                f'    echo "navarena: requeued {max_requeues} times already: giving up (resubmit to go on)"; exit 1',
                "}",
                "trap requeue USR1",
                f"{run} &",
                "run=$!",
                'wait "$run"',
                'status=$?',
                'exit "$status"']
        return "\n".join(head + ["set -uo pipefail"] + body) + "\n"
    body = [f"cd {shlex.quote(str(workdir))}", run]
    return "\n".join(head + ["set -euo pipefail"] + body) + "\n"


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    overrides = argv[argv.index("--") + 1:] if "--" in argv else []
    argv = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shards", type=int, required=True)
    ap.add_argument("--scheduler", choices=["slurm", "pbs"], default="slurm")
    ap.add_argument("--cpus", type=int, default=8)
    ap.add_argument("--mem", default="32G")
    ap.add_argument("--time", default="04:00:00")
    ap.add_argument("--queue")
    ap.add_argument("--account")
    ap.add_argument("--requeue-before", type=int, default=120, metavar="S",
                    help="SLURM: seconds before the time limit at which a task requeues itself (0: never)")
    ap.add_argument("--max-requeues", type=int, default=10)
    ap.add_argument("--max-running", type=int, default=0, metavar="N", help="at most N array tasks at once (0: no limit)")
    ap.add_argument("--dry-run", action="store_true", help="write the script, do not submit it")
    ap.add_argument("--wait", action="store_true", help="block until the job has ended (its exit status)")
    args = ap.parse_args(argv)
    root = Path(next((o.split("=", 1)[1] for o in overrides if o.startswith("data_root=")), "data"))
    out = (root if root.is_absolute() else PROJECT_ROOT / root) / "_submit"
    (out / "logs").mkdir(parents=True, exist_ok=True)
    script = array_script(args.scheduler, args.shards, overrides, args.cpus, args.mem, args.time, args.queue,
                          args.account, sys.executable, PROJECT_ROOT, str(out / "logs"), args.requeue_before,
                          args.max_requeues, args.max_running)
    path = out / f"navarena-{args.scheduler}-{dt.datetime.now():%Y%m%dT%H%M%S}.sh"
    path.write_text(script)
    print(f"wrote {path}")
    if args.dry_run:
        return 0
    cmd = "sbatch" if args.scheduler == "slurm" else "qsub"
    if shutil.which(cmd) is None:
        print(f"{cmd} is not on PATH: submit {path} yourself", file=sys.stderr)
        return 2
    wait = (["--wait"] if args.scheduler == "slurm" else ["-W", "block=true"]) if args.wait else []
    return subprocess.run([cmd, *wait, str(path)], cwd=PROJECT_ROOT).returncode


if __name__ == "__main__":
    raise SystemExit(main())
