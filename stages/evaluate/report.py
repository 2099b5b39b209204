"""Evaluation reports: per-run summary.json and tables.md, and a cross-run plot."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pandas as pd

from stages.evaluate.metrics import aggregate

TASKS = ("pointnav", "imagenav", "objectnav")
DIFFICULTIES = ("easy", "medium", "hard")
TABLE6 = [("distance_sr", "Dist. SR"), ("stop_sr", "Stop SR"), ("spl", "SPL"), ("soft_spl", "SoftSPL"),
          ("ne", "NE (m)"), ("collision_rate", "CR"), ("steps", "Steps")]


def load_results(run_dir: Path) -> pd.DataFrame:
    res = run_dir / "results"
    if not res.exists():
        return pd.DataFrame()
    df = pd.read_parquet(res)
    df["scene_id"] = df["scene_id"].astype(str)
    return df


def summarize(df: pd.DataFrame) -> dict:
    out = {"episodes": int(len(df)), "agent_errors": int((df["error"] != "").sum()) if len(df) else 0, "tasks": {}}
    for task in TASKS:
        rows = df[df["task"] == task].to_dict("records")
        if rows:
            out["tasks"][task] = aggregate(rows)
    return out


def _fmt(v) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.3f}"


def tables(summaries: dict[str, dict]) -> str:
    """Markdown in the layout of the paper's Tables 6 (overall, per task) and 7 (per difficulty)."""
    lines = ["## Table 6 layout: overall results per task", ""]
    for task in TASKS:
        runs = {r: s["tasks"][task]["overall"] for r, s in summaries.items() if task in s["tasks"]}
        if not runs:
            continue
        extra = [("pose_sr", "Pose SR"), ("pose_retention", "Pose Ret.")] if task == "imagenav" else []
        cols = TABLE6 + extra
        lines += [f"### {task}", "", "| agent (run) | episodes | " + " | ".join(c for _, c in cols) + " |",
                  "|---" * (len(cols) + 2) + "|"]
        for r, m in runs.items():
            lines.append(f"| {r} | {m['episodes']} | " + " | ".join(_fmt(m.get(k)) for k, _ in cols) + " |")
        lines.append("")
    lines += ["## Table 7 layout: Distance SR / SPL by difficulty", "",
              "| agent (run) | task | " + " | ".join(f"{d} SR | {d} SPL" for d in DIFFICULTIES) + " |",
              "|---" * (2 + 2 * len(DIFFICULTIES)) + "|"]
    for r, s in summaries.items():
        for task, agg in s["tasks"].items():
            cells = []
            for d in DIFFICULTIES:
                m = agg.get(d, {})
                cells += [_fmt(m.get("distance_sr")), _fmt(m.get("spl"))]
            lines.append(f"| {r} | {task} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_sr_by_difficulty(summaries: dict[str, dict], path: Path) -> None:
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
            vals = [agg.get(d, {}).get("distance_sr", np.nan) for d in DIFFICULTIES]
            ax.bar(np.arange(3) + k * width, vals, width, label=r)
        ax.set_xticks(np.arange(3) + 0.4 - width / 2, DIFFICULTIES)
        ax.set_title(task)
        ax.set_ylim(0, 1.05)
    axes[0][0].set_ylabel("Distance SR")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_reports(eval_root: Path, run: str) -> dict:
    from pipeline.atomic import write_text_atomic

    eval_root = Path(eval_root)
    summaries = {}
    for d in sorted(p for p in eval_root.iterdir() if p.is_dir()):
        df = load_results(d)
        if len(df):
            summaries[d.name] = summarize(df)
            if d.name == run:
                write_text_atomic(d / "summary.json", json.dumps(summaries[d.name], indent=1))
    if run in summaries:
        write_text_atomic(eval_root / run / "tables.md", tables({run: summaries[run]}))
    write_text_atomic(eval_root / "tables.md", tables(summaries))
    plot_sr_by_difficulty(summaries, eval_root / "distance_sr_by_difficulty.png")
    return {"outputs": [str(eval_root / run / "summary.json"), str(eval_root / "tables.md"),
                        str(eval_root / "distance_sr_by_difficulty.png")]}
