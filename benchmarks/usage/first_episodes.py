"""Your own capture to its first episodes, timed as a new user meets it: `navarena run` on a catalog
of your scenes into a fresh data root, and the moment each output a user waits for appears, from
the command's start. Writes data/08_reports/first_episodes.json.

    python -m benchmarks.usage.first_episodes CATALOG [--root DIR] [--until pointnav|objectnav] [OVERRIDE ...]
    python -m benchmarks.usage.first_episodes my_scenes.yaml semantics.segmenter=detector   # the guide's table

The run is stopped (Ctrl-C, as a user would) once the `--until` output exists for every scene of
the catalog, or at `--limit` seconds; what it had made by then is reported, with each task's episode
count: a scene whose ObjectNav found no goal (a `no_goal_category` shortfall) writes an empty
episodes file, which is timed as it appears and counted as 0 episodes.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent

WATCHED = (  # what a user looks for, in the order it is made: (name, layout entry, its placeholders)
    ("costmap picture", "costmap_picture", {}),
    ("screening picture", "quality_picture", {}),
    ("pointnav episodes", "episodes", {"task": "pointnav"}),
    ("imagenav episodes", "episodes", {"task": "imagenav"}),
    ("objectnav episodes", "episodes", {"task": "objectnav"}),
)


def patterns() -> list[tuple[str, str]]:
    """(name, glob under the data root) of WATCHED, from the data layout (navcore/io/layout.yaml)."""
    import yaml

    from navcore.io.catalog import LAYOUT_FILE

    layout = yaml.safe_load(LAYOUT_FILE.read_text())
    # as Catalog.find fills a template: every scene's path, relative to the root
    return [(name, layout[entry]["path"].format(root=".", scene_id="*", **values)[2:]) for name, entry, values in WATCHED]


def watch(root: Path, proc: subprocess.Popen, scenes: int, until: str, limit: float, t0: float) -> dict[str, float]:
    """Seconds from t0 at which each WATCHED output existed for every scene, polling once a second;
    stops the run (SIGINT, then SIGTERM) when `until` has appeared or at `limit`."""
    seen: dict[str, float] = {}
    watched = patterns()
    while proc.poll() is None and time.monotonic() - t0 < limit:
        for name, pattern in watched:
            if name not in seen and len(list(root.glob(pattern))) >= scenes:
                seen[name] = round(time.monotonic() - t0, 1)
                print(f"{seen[name]:8.1f} s  {name}", flush=True)
        if f"{until} episodes" in seen:
            break
        time.sleep(1.0)
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: to the run and its workers
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.terminate()
            proc.wait()
    return seen


def episode_counts(root: Path) -> dict[str, int]:
    """Episodes per task under a data root, from the Parquet footers (an empty file counts 0)."""
    import pyarrow.parquet as pq

    return {values["task"]: sum(pq.ParquetFile(f).metadata.num_rows for f in root.glob(pattern))
            for (_, entry, values), (_, pattern) in zip(WATCHED, patterns()) if entry == "episodes"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("catalog", type=Path)
    ap.add_argument("overrides", nargs="*", help="more navarena run overrides (e.g. semantics.segmenter=detector)")
    ap.add_argument("--root", type=Path, default=Path("data/first_episodes"), help="the fresh data root (emptied first)")
    ap.add_argument("--until", choices=("pointnav", "objectnav"), default="pointnav")
    ap.add_argument("--limit", type=float, default=3600.0, help="seconds before the run is stopped anyway")
    ap.add_argument("--out", type=Path, default=Path("data/08_reports/first_episodes.json"))
    a = ap.parse_args(argv)
    import yaml

    scenes = len((yaml.safe_load(a.catalog.read_text()) or {}).get("scenes") or [])
    if not scenes:
        ap.error(f"{a.catalog}: no scenes: entries")
    shutil.rmtree(a.root, ignore_errors=True)
    cmd = [str(BIN / "navarena"), "run", f"scenes.catalog={a.catalog.resolve()}", f"data_root={a.root.resolve()}",
           "executor.dashboard=false", *a.overrides]
    log = a.root.parent / f"{a.root.name}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    print("$", " ".join(cmd), f"> {log}", flush=True)
    t0 = time.monotonic()
    with open(log, "w") as out:
        # its own session and process group: Ctrl-C goes to the run and its workers, as from a terminal
        # (a background job of a shell would ignore SIGINT)
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        seen = watch(a.root, proc, scenes, a.until, a.limit, t0)
    result = {"catalog": str(a.catalog), "scenes": scenes, "overrides": a.overrides, "until": a.until,
              "seconds": seen, "episodes": episode_counts(a.root),
              "stopped_at_s": round(time.monotonic() - t0, 1), "exit_status": proc.returncode,
              "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.system()}", "log": str(log)}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result, indent=1))
    return 0 if f"{a.until} episodes" in seen else 1


if __name__ == "__main__":
    sys.exit(main())
