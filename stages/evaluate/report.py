"""Evaluation reports: per-run summary.json and tables.md, and a cross-run plot."""
from __future__ import annotations

import math

import pandas as pd

from navcore.eval.metrics import aggregate
from navcore.nav.tasks import TASK_TYPES

TASKS = TASK_TYPES
DIFFICULTIES = ("easy", "medium", "hard")
TABLE6 = [("sr", "SR"), ("distance_sr", "Dist. SR"), ("stop_sr", "Stop SR"), ("osr", "OSR"), ("spl", "SPL"),
          ("soft_spl", "SoftSPL"), ("ne", "NE (m)"), ("ne_geodesic", "NE geo. (m)"),
          ("collision_rate", "CR (actions)"), ("steps", "Steps")]
LEGEND = ("SR: success under the run's protocol. Dist. SR: distance-protocol runs only; Stop SR and OSR: "
          "explicit-stop runs only ('-' where the run's protocol does not define a metric). NE: planar "
          "Euclidean, NE geo.: costmap geodesic, to the goal. CR (actions): actions with a rejected move / "
          "attempted policy actions (per attempted translation: `collision_rate_moves` in the results).")


def load_results(parts: dict[str, object]) -> pd.DataFrame:
    """One run's per-scene result tables (scene id -> eval_results dataset) as one DataFrame with a
    scene_id column."""
    frames = []
    for scene_id, ds in sorted(parts.items()):
        df = ds.load().to_pandas()
        df["scene_id"] = scene_id
        frames.append(df)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


NULL_MEANS = {
    "distance_sr": "not defined by an explicit_stop run (success there needs STOP inside the region)",
    "stop_sr": "not defined by a distance run (STOP only consumes a step there)",
    "osr": "not defined by a distance run (equal to the distance SR by construction)",
    "pose_sr": "ImageNav only (a goal heading)",
    "pose_retention": "ImageNav only, and undefined when SR is 0",
    "dtw": "no reference path stored for the episode",
    "ndtw": "no reference path stored for the episode",
}
"""Why a metric of the summary may be null (JSON has no NaN; the summary says what null means)."""


def summarize(df: pd.DataFrame) -> dict:
    protocols = sorted(set(df["protocol"])) if len(df) else []
    out = {"episodes": int(len(df)), "agent_errors": int((df["error"] != "").sum()) if len(df) else 0,
           "invalid_actions": int(df["invalid_actions"].sum()) if "invalid_actions" in df else 0,
           "protocol": ",".join(protocols), "null_means": NULL_MEANS, "tasks": {}}
    for task in TASKS:
        rows = df[df["task"] == task].to_dict("records")
        if rows:
            out["tasks"][task] = aggregate(rows)
    return out


def _fmt(v) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.3f}"


def tables(summaries: dict[str, dict]) -> str:
    """Markdown in the layout of the paper's Tables 6 (overall, per task) and 7 (per difficulty)."""
    lines = ["## Table 6 layout: overall results per task", "", LEGEND, ""]
    for task in TASKS:
        runs = {r: s["tasks"][task]["overall"] for r, s in summaries.items() if task in s["tasks"]}
        if not runs:
            continue
        extra = [("pose_sr", "Pose SR"), ("pose_retention", "Pose Ret.")] if task == "imagenav" else []
        cols = TABLE6 + extra
        lines += [f"### {task}", "", "| agent (run) | protocol | episodes | " + " | ".join(c for _, c in cols) + " |",
                  "|---" * (len(cols) + 3) + "|"]
        for r, m in runs.items():
            lines.append(f"| {r} | {summaries[r].get('protocol', '')} | {m['episodes']} | "
                         + " | ".join(_fmt(m.get(k)) for k, _ in cols) + " |")
        lines.append("")
    lines += ["## Table 7 layout: SR / SPL by difficulty (SR under each run's protocol)", "",
              "| agent (run) | protocol | task | " + " | ".join(f"{d} SR | {d} SPL" for d in DIFFICULTIES) + " |",
              "|---" * (3 + 2 * len(DIFFICULTIES)) + "|"]
    for r, s in summaries.items():
        for task, agg in s["tasks"].items():
            cells = []
            for d in DIFFICULTIES:
                m = agg.get(d, {})
                cells += [_fmt(m.get("sr")), _fmt(m.get("spl"))]
            lines.append(f"| {r} | {s.get('protocol', '')} | {task} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_sr_by_difficulty(summaries: dict[str, dict]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    tasks = [t for t in TASKS if any(t in s["tasks"] for s in summaries.values())]
    fig, axes = plt.subplots(1, max(1, len(tasks)), figsize=(4 * max(1, len(tasks)), 3), sharey=True, squeeze=False)
    width = 0.8 / max(1, len(summaries))
    for ax, task in zip(axes[0], tasks):
        for k, (r, s) in enumerate(summaries.items()):
            agg = s["tasks"].get(task, {})
            vals = [agg.get(d, {}).get("sr", np.nan) for d in DIFFICULTIES]
            ax.bar(np.arange(3) + k * width, vals, width, label=f"{r} ({s.get('protocol', '')})")
        ax.set_xticks(np.arange(3) + 0.4 - width / 2, DIFFICULTIES)
        ax.set_title(task)
        ax.set_ylim(0, 1.05)
    axes[0][0].set_ylabel("SR (run's protocol)")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    return fig


def write_reports(catalog, run: str, agent: str = "") -> dict:
    """summary.json, tables.md and results.json (navarena-bench's layout) of `run`, the tables of
    every run and the cross-run plot."""
    import matplotlib.pyplot as plt

    summaries = {}
    by_run: dict[str, dict] = {}
    for key, ds in catalog.find("eval_results").items():  # run/scene_id
        name, scene_id = key.split("/")
        by_run.setdefault(name, {})[scene_id] = ds
    for name, parts in sorted(by_run.items()):
        df = load_results(parts)
        if len(df):
            summaries[name] = summarize(df)
    outputs = []
    if run in summaries:
        from stages.evaluate import bench_results

        root = catalog.dataset("eval_summary", run=run).path.parent
        rel = lambda p: str(p.relative_to(root))  # noqa: E731
        artifacts = {"results_parquet": sorted(rel(ds.path) for ds in by_run[run].values()),
                     "videos": sorted(rel(p) for p in (root / "videos").glob("*.mp4")),
                     "plots": sorted(rel(p) for p in (root / "plots").glob("*.png")),
                     "summary": "summary.json", "tables": "tables.md"}
        doc = bench_results.build(load_results(by_run[run]), run, agent, artifacts)
        bench_results.validate(doc)
        for ds, data in ((catalog.dataset("eval_summary", run=run), summaries[run]),
                         (catalog.dataset("eval_tables", run=run), tables({run: summaries[run]})),
                         (catalog.dataset("eval_bench_results", run=run), doc)):
            ds.save(data)
            outputs.append(str(ds.path))
    all_tables, plot = catalog.dataset("eval_all_tables"), catalog.dataset("eval_sr_plot")
    all_tables.save(tables(summaries))
    fig = plot_sr_by_difficulty(summaries)
    plot.save(fig, dpi=100)
    plt.close(fig)
    return {"outputs": outputs + [str(all_tables.path), str(plot.path)]}
