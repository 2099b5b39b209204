"""The fault suite, issue 14's and 48's proof, in one command (make test-faults):

1. the fault-injection scenarios against an undisturbed run (pytest -m faults tests/test_faults.py;
   the batch-cluster ones on a one-node SLURM that scripts/slurm_localhost.sh starts when root,
   skipped without it);
2. 10,000 fuzz cases of catalogs, label folders and labelled meshes (fuzz_inputs);
3. a run under chaos (chaos --minutes: 5 by default; 60 runs the scale simulation for an hour);
4. 10,000 fuzz cases of an agent-server frame type (fuzz_frames) and of each reader layout
   (fuzz_readers), three processes side by side (the fuzzers are single-threaded; the readers split
   in two halves of about equal time on this 2-core machine), then the halves' reports merged;
5. data/08_reports/bench_faults.{json,md} and docs/benchmarks/bench_faults.md from all of them.

Each step's log is under data/ (fuzz_*.log); the suite stops at the first step that fails, with
its log's tail, and exits 1.

    PYTHONPATH=tests python -m faults.suite                     # make test-faults
    PYTHONPATH=tests python -m faults.suite --chaos-minutes 60  # CHAOS_MINUTES=60
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

from faults.faults import PROJECT

FUZZ_A = "sog,spz_v2,supersplat_ply,npy_folder"
FUZZ_B = "spz_v3,inria_ply,splat,spz_v4,sog_lod"
"""The reader layouts in two halves of about equal fuzzing time."""


class StepFailed(RuntimeError):
    pass


def _tail(path: Path, n: int) -> str:
    lines = path.read_text(errors="replace").splitlines() if path.exists() else []
    return "\n".join(lines[-n:])


def _run(cmd: list[str], env: dict | None = None) -> None:
    print("+", " ".join(cmd), flush=True)
    r = subprocess.run(cmd, cwd=PROJECT, env={**os.environ, **(env or {})})
    if r.returncode:
        raise StepFailed(f"{' '.join(cmd[2:4])} exited {r.returncode}")


def _start(cmd: list[str], log: Path) -> tuple[subprocess.Popen, Path]:
    print("+", " ".join(cmd), ">", log, flush=True)
    with open(log, "w") as f:
        return subprocess.Popen(cmd, cwd=PROJECT, stdout=f, stderr=subprocess.STDOUT), log


def main(argv: list[str] | None = None) -> int:
    # the steps run as `python -m faults.X`: the suites live in tests/faults, beside the tests that use them
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, (str(PROJECT / "tests"), os.environ.get("PYTHONPATH"))))
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=10000, help="fuzz cases of each fuzzer")
    ap.add_argument("--kills", type=int, default=20, help="worker kills of the kill scenario")
    ap.add_argument("--chaos-minutes", type=float, default=5)
    ap.add_argument("--reports", default="data/08_reports")
    a, pytest_args = ap.parse_known_args(argv)  # the rest: more arguments of the scenarios' pytest run
    py, reports, logs = sys.executable, PROJECT / a.reports, PROJECT / "data"
    reports.mkdir(parents=True, exist_ok=True)
    cases = ["--cases", str(a.cases)]
    try:
        # the batch-cluster scenarios need a one-node SLURM (root); without it they are skipped
        if subprocess.run([str(PROJECT / "scripts/slurm_localhost.sh")], cwd=PROJECT).returncode:
            print("no local SLURM: the batch-cluster scenarios will be skipped", flush=True)
        _run([py, "-m", "pytest", "-q", "-m", "faults", "tests/test_faults.py", *pytest_args],
             env={"NAVARENA_FAULTS_KILLS": str(a.kills),
                  "NAVARENA_FAULTS_REPORT": str(reports / "faults_scenarios.json")})
        p, log = _start([py, "-m", "faults.fuzz_inputs", *cases], logs / "fuzz_inputs.log")
        rc = p.wait()
        print(_tail(log, 6), flush=True)
        if rc:
            raise StepFailed(f"fuzz_inputs exited {rc} (log: {log})")
        _run([py, "-m", "faults.chaos", "--minutes", str(a.chaos_minutes)])
        side = [
            _start([py, "-m", "faults.fuzz_frames", *cases], logs / "fuzz_frames.log"),
            _start([py, "-m", "faults.fuzz_readers", *cases, "--kinds", FUZZ_A,
                    "--work", "/tmp/navarena_fuzz_a", "--out", str(reports / "fuzz_a")], logs / "fuzz_a.log"),
            _start([py, "-m", "faults.fuzz_readers", *cases, "--kinds", FUZZ_B,
                    "--work", "/tmp/navarena_fuzz_b", "--out", str(reports / "fuzz_b")], logs / "fuzz_b.log"),
        ]
        failed = []
        for p, log in side:
            rc = p.wait()
            print(f"== {log.name}\n{_tail(log, 3)}", flush=True)
            if rc:
                failed.append(f"{log.stem} exited {rc} (log: {log})")
        if failed:
            raise StepFailed("; ".join(failed))
        _run([py, "-m", "faults.fuzz_readers", "--merge",
              str(reports / "fuzz_a/fuzz_readers.json"), str(reports / "fuzz_b/fuzz_readers.json")])
        _run([py, "-m", "faults.faults", "--docs", "--merge", str(reports / "faults_scenarios.json")])
    except StepFailed as e:
        print(f"test-faults: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
