"""The README's five-minute tour, timed as a new user meets it: each step's command run as printed
(in a scratch folder with its own `data/`, through this checkout's venv), its wall time against the
time the README states for it. Writes data/08_reports/tour.json and docs/benchmarks/bench_tour.md.

    python -m benchmarks.usage.tour [--work DIR] [--repeats N] [--docs]     # make bench-tour

The first step stands for `make dataset` without its set-up (the venv exists): a fresh data root.
A step over its stated time is a finding, reported as such (exit status 1 with --strict).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
BIN = Path(sys.executable).parent


@dataclass(frozen=True)
class Step:
    what: str
    command: str
    """As the README prints it (the test checks it does); `.venv/bin/` is this venv's bin."""
    stated_s: float
    """The time the README states for it."""
    repeat: bool = True
    """Whether a repeat measures the same thing (a first run into an empty root does not repeat)."""


STEPS = (
    Step("generate the default dataset (make dataset, venv ready)", ".venv/bin/navarena run", 90, repeat=False),
    Step("run again: nothing to do", ".venv/bin/navarena run", 15),
    Step("one stage with an override, its own root",
         ".venv/bin/navarena run stages=[costmap] costmap.resolution=0.02 data_root=data_fine", 60, repeat=False),
    Step("query the episodes with pandas", ".venv/bin/python examples/query_episodes.py", 10),
    Step("evaluate the learned PointNav baseline",
         ".venv/bin/navarena eval data --agent pointnav_bc --tasks pointnav --split test --episodes-per-scene 5 "
         "--renderer cpu --width 160 --height 120 --batch-slots 5", 60),
    Step("export 12 training episodes for LeRobot",
         ".venv/bin/navarena export-lerobot --root data --out exports/lerobot_train --split train --episodes 12", 60),
    Step("render 4 episode videos and their page",
         ".venv/bin/navarena render-episodes --root data --out reports --count 4", 60),
)


def in_readme(step: Step, text: str | None = None) -> bool:
    """Whether the README prints the step's command (its continuation lines joined)."""
    text = (text if text is not None else README.read_text()).replace("\\\n", " ")
    return re.sub(r"\s+", " ", step.command) in re.sub(r"\s+", " ", text)


def run_step(step: Step, work: Path) -> tuple[float, int, str]:
    """(wall seconds, exit status, last output lines) of one step in `work`."""
    cmd = step.command.replace(".venv/bin/", f"{BIN}/").replace("examples/", f"{ROOT}/examples/")
    t = time.perf_counter()
    p = subprocess.run(cmd, shell=True, cwd=work, capture_output=True, text=True,
                       env={**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "100"})
    secs = time.perf_counter() - t
    tail = "\n".join((p.stdout + p.stderr).strip().splitlines()[-3:])
    return secs, p.returncode, tail


def measure(work: Path, repeats: int) -> dict:
    rows = []
    for step in STEPS:
        times, rc, tail = [], 0, ""
        for k in range(repeats if step.repeat else 1):
            secs, rc, tail = run_step(step, work)
            times.append(secs)
            print(f"{step.what}: {secs:.1f} s (stated {step.stated_s:.0f} s), exit {rc}", flush=True)
            if rc:
                break
        rows.append({"step": step.what, "command": step.command, "stated_s": step.stated_s,
                     "measured_s": round(statistics.median(times), 1), "runs": [round(t, 1) for t in times],
                     "exit": rc, "within": rc == 0 and statistics.median(times) <= step.stated_s,
                     **({"output_tail": tail} if rc else {})})
    return {"machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}",
            "date": time.strftime("%Y-%m-%d"), "steps": rows,
            "tour_s": round(sum(r["measured_s"] for r in rows[1:]), 1),
            "tour_stated_s": sum(r["stated_s"] for r in rows[1:])}


def markdown(rep: dict) -> str:
    L = ["# The README's tour, timed", "",
         "Each command of the README's tour run as printed, in a fresh folder with its own `data/`, on "
         f"{rep['machine']}; the median of the runs where a repeat measures the same thing "
         "(`make bench-tour`, `benchmarks/usage/tour.py`). The first step is `make dataset` without its set-up "
         "(the venv exists).", "",
         "| step | command | stated | measured | runs (s) | within |", "|---|---|---:|---:|---|---|"]
    for r in rep["steps"]:
        ok = "yes" if r["within"] else ("**no**" if r["exit"] == 0 else f"**failed (exit {r['exit']})**")
        command, runs = r["command"].replace("|", "\\|"), ", ".join(f"{t:.1f}" for t in r["runs"])
        L.append(f"| {r['step']} | `{command}` | {r['stated_s']:.0f} s | {r['measured_s']:.1f} s | {runs} | {ok} |")
    L += ["", f"The tour after the dataset exists: {rep['tour_s']:.0f} s measured against {rep['tour_stated_s']:.0f} s "
          "stated (the README calls it a five-minute tour).", ""]
    return "\n".join(L)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", type=Path, default=None, help="scratch folder (default: a temporary one, removed)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--docs", action="store_true", help="write docs/benchmarks/bench_tour.md")
    ap.add_argument("--strict", action="store_true", help="exit 1 when a step fails or runs over its stated time")
    a = ap.parse_args(argv)
    missing = [s.command for s in STEPS if not in_readme(s)]
    if missing:
        raise SystemExit(f"{README}: no longer prints {missing}: update benchmarks/usage/tour.py STEPS")
    work = a.work or Path(tempfile.mkdtemp(prefix="navarena_tour_"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        rep = measure(work, a.repeats)
    finally:
        if a.work is None:
            shutil.rmtree(work, ignore_errors=True)
    out = ROOT / "data" / "08_reports" / "tour.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(rep, indent=1) + "\n")
    print(markdown(rep))
    if a.docs:
        from benchmarks.pages import write_page

        print(write_page("bench_tour.md", markdown(rep)))
    return 1 if a.strict and not all(r["within"] for r in rep["steps"]) else 0


if __name__ == "__main__":
    sys.exit(main())
