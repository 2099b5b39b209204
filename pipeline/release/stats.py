"""Release statistics in the layout of the paper's Table 4, kept as sums and fixed-bin histograms so
that a release of any size is summarised in constant memory (one scene's table at a time)."""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow as pa

GEODESIC_BINS = np.arange(0.0, 30.5, 0.5)
"""Histogram bins of the geodesic distance, metres (the episodes' range is 1-30 m by default)."""
STEP_BINS = np.arange(0, 4001, 50)
"""Histogram bins of the expert's steps (20 Hz rows)."""
FIELDS = ("episodes", "geodesic", "steps", "seconds", "actions")
"""Sums kept per (task, split, group, difficulty): count, geodesic m, expert rows, expert s, oracle actions."""


class Stats:
    def __init__(self):
        self.sums: dict[tuple[str, str, str, str], np.ndarray] = defaultdict(lambda: np.zeros(len(FIELDS)))
        self.extra_splits: set[str] = set()  # splits whose episodes repeat others' (the eval set): not in totals
        self.geodesic = defaultdict(lambda: np.zeros(len(GEODESIC_BINS) - 1, np.int64))
        self.steps = defaultdict(lambda: np.zeros(len(STEP_BINS) - 1, np.int64))
        self.categories: dict[str, int] = defaultdict(int)

    def add(self, task: str, split: str, group: str, table: pa.Table, total: bool = True) -> None:
        """One scene's episodes of one task and split; total=False: a split of repeated episodes."""
        if not total:
            self.extra_splits.add(split)
        df = table.select(["difficulty", "geodesic_distance", "num_steps", "total_time", "oracle_actions",
                           "goal_object_category"]).to_pandas()
        if df.empty:
            return
        df["actions"] = df["oracle_actions"].map(lambda a: 0 if a is None else len(a))
        for diff, g in df.groupby("difficulty"):
            self.sums[(task, split, group, diff)] += [len(g), g["geodesic_distance"].sum(), g["num_steps"].sum(),
                                                      g["total_time"].sum(), g["actions"].sum()]
        if total:
            self.geodesic[task] += np.histogram(np.clip(df["geodesic_distance"], 0, GEODESIC_BINS[-1] - 1e-6),
                                                GEODESIC_BINS)[0]
            self.steps[task] += np.histogram(np.clip(df["num_steps"], 0, STEP_BINS[-1] - 1), STEP_BINS)[0]
            if task == "objectnav":
                for c, n in df["goal_object_category"].value_counts().items():
                    self.categories[c] += int(n)

    def rows(self, by: str | None = None, split: str | None = None) -> list[dict]:
        """Table 4 rows per task (and per `by`: split | group | difficulty), over the counted splits
        (or one split)."""
        acc: dict[tuple, np.ndarray] = defaultdict(lambda: np.zeros(len(FIELDS)))
        for (task, sp, group, diff), v in self.sums.items():
            if (split is None and sp in self.extra_splits) or (split is not None and sp != split):
                continue
            key = (task,) if by is None else (task, {"split": sp, "group": group, "difficulty": diff}[by])
            acc[key] += v
        out = []
        for key in sorted(acc, key=lambda k: (TASK_ORDER.get(k[0], 9), *[ORDER.get(x, 9) for x in k[1:]], *k[1:])):
            n, geo, steps, secs, acts = acc[key]
            out.append({"task": key[0], **({by: key[1]} if by else {}), "episodes": int(n),
                        "mean_geodesic_m": geo / n if n else None, "mean_expert_steps": steps / n if n else None,
                        "expert_hours": secs / 3600.0, "mean_oracle_actions": acts / n if n else None})
        return out

    def counts(self) -> dict[str, dict[str, int]]:
        """{task: {split: episodes}} including the evaluation set's split."""
        out: dict[str, dict[str, int]] = defaultdict(dict)
        for (task, sp, _, _), v in sorted(self.sums.items()):
            out[task][sp] = out[task].get(sp, 0) + int(v[0])
        return {t: dict(sorted(s.items())) for t, s in sorted(out.items())}

    def total_episodes(self) -> int:
        return int(sum(v[0] for (_, sp, _, _), v in self.sums.items() if sp not in self.extra_splits))

    def plots(self, folder: Path) -> list[str]:
        """PNG plots (geodesic distance and steps per task, ObjectNav categories); relative paths."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        folder.mkdir(parents=True, exist_ok=True)
        written = []
        for name, hists, bins, xlabel in (("geodesic_distance", self.geodesic, GEODESIC_BINS, "geodesic distance (m)"),
                                          ("expert_steps", self.steps, STEP_BINS, "expert steps (20 Hz)")):
            if not hists:
                continue
            fig, ax = plt.subplots(figsize=(7, 3.6), dpi=100)
            for task in sorted(hists, key=lambda t: TASK_ORDER.get(t, 9)):
                ax.stairs(hists[task], bins, label=f"{task} ({int(hists[task].sum())})")
            ax.set_xlabel(xlabel)
            ax.set_ylabel("episodes")
            ax.legend()
            fig.tight_layout()
            fig.savefig(folder / f"{name}.png", metadata={"Software": None})
            plt.close(fig)
            written.append(f"plots/{name}.png")
        if self.categories:
            cats = sorted(self.categories.items(), key=lambda kv: (-kv[1], kv[0]))
            fig, ax = plt.subplots(figsize=(7, 0.3 * len(cats) + 1.2), dpi=100)
            ax.barh([c for c, _ in cats][::-1], [n for _, n in cats][::-1], color="#4c72b0")
            ax.set_xlabel("ObjectNav episodes")
            fig.tight_layout()
            fig.savefig(folder / "objectnav_categories.png", metadata={"Software": None})
            plt.close(fig)
            written.append("plots/objectnav_categories.png")
        return written


TASK_ORDER = {"pointnav": 0, "imagenav": 1, "objectnav": 2}
ORDER = {"easy": 0, "medium": 1, "hard": 2, "train": 0, "val_seen": 1, "val_unseen": 2, "test": 3}
