"""The run summary: counts per stage and status, failures, shortfalls and warnings, written to
data/_runs (one file per run and latest.json) and printed as tables."""
from __future__ import annotations

import datetime as dt
import os

from rich.console import Console
from rich.table import Table

from navcore.io import jsonio
from navcore.io.atomic import write_text_atomic
from navcore.io.catalog import Catalog
from pipeline.tasks import FAILED


def build_summary(results: list[dict], started: dt.datetime, cat_file, shard: list[int], stages, hashes) -> dict:
    """The summary of a run's (sorted) results."""
    summary = {"started_at": started.isoformat(timespec="seconds"),
               "finished_at": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
               "catalog": str(cat_file), "shard": shard,
               "stages": [s.name for s in stages], "config_hashes": {s.name: hashes[s.name] for s in stages},
               "counts": {}, "failures": [r for r in results if r["status"] in FAILED],
               "shortfalls": [r for r in results if r.get("shortfall")],
               "warnings": [r for r in results if r.get("warnings")],
               "goal_mappings": [r for r in results if r.get("goal_mapping")], "results": results}
    for r in results:
        c = summary["counts"].setdefault(r["stage"], {})
        c[r["status"]] = c.get(r["status"], 0) + 1
    return summary


def write_summary(summary: dict, catalog: Catalog, started: dt.datetime, shard: int):
    """run-{time}-shard{k}-{pid}.json and latest.json under the runs folder; returns latest.json's path."""
    runs = catalog.path("runs")
    stamp = started.strftime("%Y%m%dT%H%M%S")
    text = jsonio.dumps(summary, indent=1, default=str)
    # the process id too: two runs started in the same second (two shards, or the same run twice)
    # must not overwrite each other's summary
    write_text_atomic(runs / f"run-{stamp}-shard{shard}-{os.getpid()}.json", text)
    write_text_atomic(runs / "latest.json", text)
    return runs / "latest.json"


def print_summary(summary: dict, console: Console) -> None:
    t = Table(title="run summary")
    statuses = ["done", "cached", "n/a", "failed", "skipped"]
    t.add_column("stage")
    for s in statuses:
        t.add_column(s, justify="right")
    for stage, c in summary["counts"].items():
        t.add_row(stage, *[str(c.get(s, 0)) for s in statuses])
    console.print(t)
    if summary["failures"]:
        f = Table(title="failures", show_lines=False)
        for col in ("scene", "stage", "status", "error"):
            f.add_column(col, overflow="fold")
        for r in summary["failures"]:
            f.add_row(f"{r['scene_id']} ({r['scene']})", r["stage"], r["status"], r.get("error", ""))
        console.print(f)
    if summary["shortfalls"]:
        f = Table(title="scenes that could not yield the requested outputs")
        for col in ("scene", "stage", "what", "got / asked", "rejections by reason"):
            f.add_column(col, overflow="fold")
        for r in summary["shortfalls"]:
            for s in r["shortfall"]:
                f.add_row(f"{r['scene_id']} ({r['scene']})", r["stage"], s.get("task", ""),
                          f"{s.get('episodes')} / {s.get('requested')}",
                          ", ".join(f"{k} {v}" for k, v in s.get("rejections", {}).items()) or s.get("reason", ""))
        console.print(f)
    if summary.get("goal_mappings"):
        f = Table(title="ObjectNav goal categories from dataset classes (instances)")
        for col in ("scene", "goal category", "dataset classes"):
            f.add_column(col, overflow="fold")
        for r in summary["goal_mappings"]:
            for goal, classes in sorted(r["goal_mapping"].items()):
                f.add_row(f"{r['scene_id']} ({r['scene']})", goal, ", ".join(f"{c} {n}" for c, n in sorted(classes.items())))
        console.print(f)
    if summary["warnings"]:
        f = Table(title="warnings")
        for col in ("scene", "stage", "warning"):
            f.add_column(col, overflow="fold")
        for r in summary["warnings"]:
            for w in r["warnings"]:
                f.add_row(f"{r['scene_id']} ({r['scene']})", r["stage"], w)
        console.print(f)
