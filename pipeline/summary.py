"""The run summary: counts per stage and status, failures, shortfalls, warnings and scene screening, written to
data/_runs (one file per run and latest.json) and printed as tables."""
from __future__ import annotations

import datetime as dt
import os

from rich import box
from rich.console import Console
from rich.markup import escape
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
               # the chain of scenes read from files (no generated-only stages): what their markers hold
               "captured_config_hashes": {s.name: h for s in stages if (h := getattr(hashes, "captured", {}).get(s.name))},
               "counts": {}, "failures": [r for r in results if r["status"] in FAILED],
               "shortfalls": [r for r in results if r.get("shortfall")],
               "warnings": [r for r in results if r.get("warnings")],
               "goal_mappings": [r for r in results if r.get("goal_mapping")],
               "sources_changed": sources_changed(results),
               "screening": screening(results), "results": results}
    placed = placement(results)
    if placed:
        summary["placement"] = placed
    for r in results:
        c = summary["counts"].setdefault(r["stage"], {})
        c[r["status"]] = c.get(r["status"], 0) + 1
    return summary


def sources_changed(results: list[dict]) -> list[dict]:
    """One row per scene whose outputs were recomputed because a file they were made from changed
    (pipeline.sources): the file, its old and new sha256, the stages recomputed or failed for it."""
    rows: dict[str, dict] = {}
    for r in results:
        if r.get("source_changed"):
            row = rows.setdefault(r["scene_id"], {"scene_id": r["scene_id"], "scene": r["scene"], **r["source_changed"],
                                                  "stages": []})
            row["stages"].append(f"{r['stage']}" + ("" if r["status"] == "done" else f" ({r['status']})"))
    return list(rows.values())


def screening(results: list[dict]) -> list[dict]:
    """One screening row per scene: the episodes stage's (score and verdict) where it ran, else
    the screen stage's (score only, verdict None)."""
    rows: dict[str, dict] = {}
    for r in results:
        if r.get("screening") and (r["scene_id"] not in rows or r["screening"].get("verdict") is not None):
            rows[r["scene_id"]] = {"scene_id": r["scene_id"], "scene": r["scene"], **r["screening"]}
    return list(rows.values())


def _union(intervals: list[tuple[float, float]]) -> list[tuple[float, float]]:
    out: list[list[float]] = []
    for a, b in sorted(intervals):
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def _overlap(xs: list[tuple[float, float]], ys: list[tuple[float, float]]) -> float:
    """Seconds covered by both unions of intervals (each sorted and disjoint)."""
    total, i, j = 0.0, 0, 0
    while i < len(xs) and j < len(ys):
        total += max(0.0, min(xs[i][1], ys[j][1]) - max(xs[i][0], ys[j][0]))
        if xs[i][1] < ys[j][1]:
            i += 1
        else:
            j += 1
    return total


def placement(results: list[dict]) -> dict | None:
    """Where a Dask run's tasks ran: per worker its GPU (pinned, and the UUIDs its CUDA work used),
    the tasks it computed by stage and its busy seconds; the tasks whose CUDA work went to a GPU
    other than their worker's (none, or the pinning is broken); how long GPU and CPU stages ran at
    the same time. None for runs without worker records (sync runs, fully cached runs)."""
    placed = [r for r in results if r.get("status") == "done" and "worker" in r and "finished" in r]
    if not placed:
        return None
    workers: dict[str, dict] = {}
    for r in placed:
        w = workers.setdefault(r["worker"], {"gpu": r.get("gpu"), "pinned_uuid": r.get("gpu_pinned_uuid"),
                                             "cuda_uuids": [], "tasks": {}, "busy_s": 0.0})
        w["tasks"][r["stage"]] = w["tasks"].get(r["stage"], 0) + 1
        w["busy_s"] = round(w["busy_s"] + r["finished"] - r["started"], 3)
        if r.get("gpu_uuid") and r["gpu_uuid"] not in w["cuda_uuids"]:
            w["cuda_uuids"].append(r["gpu_uuid"])
    misplaced = [{k: r.get(k) for k in ("stage", "scene_id", "worker", "gpu", "gpu_pinned_uuid", "cuda_device", "gpu_uuid")}
                 for r in placed if "gpu_uuid" in r and (r.get("cuda_device") != 0 or r["gpu_uuid"] != r.get("gpu_pinned_uuid"))]
    on_gpu = _union([(r["started"], r["finished"]) for r in placed if r.get("gpu")])
    on_cpu = _union([(r["started"], r["finished"]) for r in placed if not r.get("gpu")])
    gpu_busy = sum(b - a for a, b in on_gpu)
    return {"workers": dict(sorted(workers.items())), "misplaced": misplaced,
            "gpu_tasks": sum(1 for r in placed if r.get("gpu")),
            "gpu_tasks_with_cuda": sum(1 for r in placed if r.get("gpu_uuid")),
            "gpu_busy_s": round(gpu_busy, 3), "cpu_busy_s": round(sum(b - a for a, b in on_cpu), 3),
            "cpu_gpu_overlap_s": round(_overlap(on_gpu, on_cpu), 3)}


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


TABLE_ROWS = 20
"""Rows a per-scene table prints (the worst first); the rest are counted below it. A 2,000-scene
run listed every scene: thousands of lines, and seconds of the resume spent laying them out."""


def _more(console: Console, rows: list, kind, key: str, root: str) -> None:
    """Under a table cut at TABLE_ROWS: how many rows it left out, counted by `kind`, and where
    the run summary lists them all."""
    if len(rows) <= TABLE_ROWS:
        return
    counts: dict[str, int] = {}
    for r in rows[TABLE_ROWS:]:
        counts[kind(r)] = counts.get(kind(r), 0) + 1
    console.print(f"  ... and {len(rows) - TABLE_ROWS} more ({', '.join(f'{k} {v}' for k, v in sorted(counts.items()))}): "
                  f"every row is under \"{key}\" in {root}/_runs/latest.json", style="dim")


def print_summary(summary: dict, console: Console) -> None:
    t = Table(title="run summary")
    statuses = ["done", "cached", "n/a", "failed", "skipped"]
    t.add_column("stage")
    for s in statuses:
        t.add_column(s, justify="right")
    for stage, c in summary["counts"].items():
        t.add_row(stage, *[str(c.get(s, 0)) for s in statuses])
    console.print(t)
    if summary.get("config_changes"):
        f = Table(title="recomputed because the settings changed (old -> new)")
        for col in ("stage", "scenes", "what changed"):
            f.add_column(col, overflow="fold")
        for stage, c in summary["config_changes"].items():
            f.add_row(stage, str(len(c["scenes"])), escape("; ".join(f"{k}: {a} -> {b}" for k, a, b in c["keys"]) or c["cause"]))
        console.print(f)
    if summary.get("paths_outside_catalog"):
        f = Table(title="catalog paths leading out of the catalog's folder (resolved; check them in a catalog "
                        "someone else wrote)", box=box.SIMPLE_HEAD)
        for col in ("scene", "key", "reads"):
            f.add_column(col, overflow="fold")
        for o in summary["paths_outside_catalog"]:
            f.add_row(escape(o["scene"]), o["key"], escape(o["resolved"]))
        console.print(f, style="dim")
    if summary.get("sources_changed"):
        f = Table(title="recomputed because a file the outputs were made from changed")
        for col in ("scene", "what changed", "stages"):
            f.add_column(col, overflow="fold")
        for r in summary["sources_changed"]:
            f.add_row(f"{r['scene_id']} ({r['scene']})", escape(r["message"]), ", ".join(r["stages"]))
        console.print(f)
    if summary["failures"]:
        f = Table(title="failures", show_lines=False)
        for col in ("scene", "stage", "status", "error"):
            f.add_column(col, overflow="fold")
        shared: dict[str, list[dict]] = {}
        for r in summary["failures"]:
            shared.setdefault(r.get("error", ""), []).append(r)
        for error, rows in shared.items():  # one line for a cause many tasks share (a lost scheduler)
            if len(rows) > 3:
                f.add_row(f"{len({r['scene_id'] for r in rows})} scenes", f"{len(rows)} tasks", rows[0]["status"],
                          escape(error))
                continue
            for r in rows:
                f.add_row(f"{r['scene_id']} ({r['scene']})", r["stage"], r["status"], escape(error))
        console.print(f)
        console.print("[red]some tasks failed[/]: the run exits with status 1" if not summary.get("allow_failures")
                      else "some tasks failed; allow_failures=true: the run exits with status 0")
    root = summary.get("data_root") or "data"  # the run's own (data_root=...), as a user would type it
    if summary["shortfalls"]:
        rows = [(r, x) for r in summary["shortfalls"] for x in r["shortfall"]]
        # the largest deficits first (short of episodes before a difficulty mix that is off)
        rows.sort(key=lambda rx: (-(rx[1].get("requested") or 0) + (rx[1].get("episodes") or 0), rx[0]["scene_id"]))
        f = Table(title="scenes that could not yield the requested outputs")
        for col in ("scene", "stage", "what", "got / asked", "rejections by reason"):
            f.add_column(col, overflow="fold")
        for r, x in rows[:TABLE_ROWS]:
            f.add_row(f"{r['scene_id']} ({r['scene']})", r["stage"], x.get("task", ""),
                      f"{x.get('episodes')} / {x.get('requested')}",
                      ", ".join(f"{k} {v}" for k, v in x.get("rejections", {}).items()) or x.get("reason", ""))
        console.print(f)
        _more(console, rows, lambda rx: f"{rx[0]['stage']} {rx[1].get('task', '')}".strip(), "shortfalls", root)
    if summary.get("goal_mappings"):
        f = Table(title="ObjectNav goal categories from dataset classes (instances)")
        for col in ("scene", "goal category", "dataset classes"):
            f.add_column(col, overflow="fold")
        for r in summary["goal_mappings"]:
            for goal, classes in sorted(r["goal_mapping"].items()):
                f.add_row(f"{r['scene_id']} ({r['scene']})", goal, ", ".join(f"{c} {n}" for c, n in sorted(classes.items())))
        console.print(f)
    if summary.get("screening"):
        f = Table(title="scene screening (score: share of valid cells not flagged)", box=box.SIMPLE_HEAD,
                  padding=(0, 1), collapse_padding=True)
        f.add_column("scene", no_wrap=True, overflow="ellipsis", max_width=18)
        for col in ("score", "blobs", "holes", "blur", "v.holes", "unseen"):
            f.add_column(col, justify="right", no_wrap=True)
        f.add_column("verdict", no_wrap=True)
        f.add_column("episodes", no_wrap=True)
        style = {"pass": "green", "warn": "yellow", "reject": "red"}
        scr = sorted(summary["screening"], key=lambda r: (r["score"], r["scene"]))  # the worst first
        for r in scr[:TABLE_ROWS]:
            f.add_row(escape(r["scene"]), f"{r['score']:.2f}",
                      *(f"{100 * r[k]:.1f}%" for k in ("blur_share", "hole_share", "view_blur_share", "view_hole_share",
                                                        "unseen_share")),
                      f"[{style[r['verdict']]}]{r['verdict']}[/]" if r.get("verdict") else "-",
                      "-" if r.get("kept") is None else "kept" if r["kept"] else "rejected")
        console.print(f)
        _more(console, scr, lambda r: r.get("verdict") or "no verdict", "screening", root)
        console.print("  blobs: floor under blurry blobs; holes: floor holes; blur / v.holes: rendered views blurred / "
                      "with holes; unseen: cells no view covers. A warn keeps the scene, its episodes avoid the flagged "
                      f"cells: look at {root}/03_costmaps/screen/<scene_id>.png (legend on it); screen.reject=true drops "
                      f"rejected scenes. Scene ids: {root}/_runs/latest.json.", style="dim")
    placed = summary.get("placement")
    if placed and any(w["gpu"] for w in placed["workers"].values()):
        f = Table(title="where tasks ran (GPU workers; CPU workers summed)")
        for col in ("worker", "pinned GPU", "CUDA work on", "tasks", "busy s"):
            f.add_column(col, overflow="fold")
        cpu = [w for w in placed["workers"].values() if not w["gpu"]]
        for name, w in placed["workers"].items():
            if w["gpu"]:
                pinned = f"{w['gpu']} ({(w['pinned_uuid'] or '?')[:8]})"
                seen = ", ".join(u[:8] for u in w["cuda_uuids"]) or "-"
                f.add_row(name, pinned, seen, ", ".join(f"{k} {v}" for k, v in w["tasks"].items()), f"{w['busy_s']:.1f}")
        if cpu:
            tasks: dict = {}
            for w in cpu:
                for k, v in w["tasks"].items():
                    tasks[k] = tasks.get(k, 0) + v
            f.add_row(f"{len(cpu)} CPU workers", "none", "-", ", ".join(f"{k} {v}" for k, v in tasks.items()),
                      f"{sum(w['busy_s'] for w in cpu):.1f}")
        console.print(f)
        style = "red" if placed["misplaced"] else "green"
        console.print(f"[{style}]{len(placed['misplaced'])} GPU task(s) ran on a GPU other than their worker's[/]; "
                      f"GPU stages busy {placed['gpu_busy_s']:.1f} s, CPU stages running beside them "
                      f"{placed['cpu_gpu_overlap_s']:.1f} s of it")
    if summary["warnings"]:
        f = Table(title="warnings")
        for col in ("scene", "stage", "warning"):
            f.add_column(col, overflow="fold")
        rows = [(r, w) for r in summary["warnings"] for w in r["warnings"]]
        for r, w in rows[:TABLE_ROWS]:
            f.add_row(f"{r['scene_id']} ({r['scene']})", r["stage"], w)
        console.print(f)
        _more(console, rows, lambda rw: rw[0]["stage"], "warnings", root)
