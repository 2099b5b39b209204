"""The zero-shot evaluation set: a fixed, stratified sample of episodes from scenes held out of training.

The paper evaluates each task on a separate 600-episode set: 180 easy, 240 medium and 180 hard
episodes (step budgets 500 / 1000 / 1500, the episodes' own `max_steps`), sampled across source
groups, layouts (scenes), goal categories and horizons (difficulty). Here it is drawn from the
episodes of the held-out splits (`from_splits`, default the test split of `episodes.scene_splits`):

1. Per task, the largest size N <= `size` whose per-difficulty counts (N split by `proportions`,
   largest remainders) the candidates can fill: the proportions are kept, the set shrinks when
   one difficulty runs short (the release card says so).
2. Per difficulty, the candidates are ordered by a nested round robin: over source groups, within
   a group over its scenes, within a scene over its goal categories (ObjectNav; one stratum for the
   other tasks), within a category by a hash of (seed, task, scene, episode id); the first n are
   taken. So every group, scene and category gets its turn before any gets a second, and the
   choice depends only on the candidates and the seed (no worker, shard or file order).

The selection is a listing of (task, scene_id, episode_id): the release ships those episodes as
their own split, and the evaluate stage runs them with `evaluate.split=<name>`.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np
import pandas as pd


@dataclass
class EvalSetConfig:
    """The zero-shot evaluation set of a release (the paper's 600 episodes a task)."""

    name: str = "eval_zeroshot"
    """Its split name (the release's split, and `evaluate.split=<name>` to run it)."""
    size: int = 600
    """Episodes per task (fewer when the held-out scenes hold fewer at these proportions)."""
    proportions: dict[str, float] = field(default_factory=lambda: {"easy": 0.3, "medium": 0.4, "hard": 0.3})
    """Share of each difficulty (the paper: 180 / 240 / 180 of 600)."""
    from_splits: list[str] = field(default_factory=lambda: ["test"])
    """Splits it is drawn from: scenes held out of training by `episodes.scene_splits`."""
    seed: int = 0
    """Seed of the order within a stratum."""


LISTING_COLUMNS = ["task", "scene_id", "group", "episode_id", "difficulty", "goal_object_category"]
"""Columns of the selection (and of the candidates it is drawn from)."""


def allocate(n: int, proportions: dict[str, float]) -> dict[str, int]:
    """n split by proportions, largest remainders (ties by the proportions' order)."""
    names = list(proportions)
    p = np.asarray([proportions[k] for k in names], float)
    if (p < 0).any() or p.sum() <= 0:
        raise ValueError(f"eval_set.proportions must be non-negative with a positive sum, got {proportions}")
    exact = n * p / p.sum()
    base = np.floor(exact).astype(int)
    rest = n - int(base.sum())
    order = sorted(range(len(names)), key=lambda i: (-(exact[i] - base[i]), i))
    for i in order[:rest]:
        base[i] += 1
    return {k: int(v) for k, v in zip(names, base)}


def feasible_size(available: dict[str, int], size: int, proportions: dict[str, float]) -> int:
    """The largest N <= size whose allocation fits the available counts per difficulty."""
    for n in range(int(size), -1, -1):
        if all(c <= available.get(k, 0) for k, c in allocate(n, proportions).items()):
            return n
    return 0


def _hash(*parts) -> int:
    return int.from_bytes(hashlib.sha256(":".join(map(str, parts)).encode()).digest()[:8], "little")


def _round_robin(df: pd.DataFrame, seed: int, task: str) -> pd.DataFrame:
    """df (one task and difficulty) in nested round-robin order over group, scene, category."""
    df = df.copy()
    cat = df["goal_object_category"].fillna("")
    df["_h"] = [_hash(seed, task, s, e) for s, e in zip(df["scene_id"], df["episode_id"])]
    df["_cat_order"] = [_hash(seed, task, s, "category", c) for s, c in zip(df["scene_id"], cat)]
    df["_scene_order"] = [_hash(seed, task, "scene", s) for s in df["scene_id"]]
    df["_group_order"] = [_hash(seed, task, "group", g) for g in df["group"]]
    df["_cat"] = cat
    # rank within a category, then round robin over the scene's categories, the group's scenes, the groups
    df["_r"] = df.groupby(["scene_id", "_cat"])["_h"].rank(method="first")
    df["_r"] = df.sort_values(["_r", "_cat_order"]).groupby("scene_id").cumcount()
    df["_r"] = df.sort_values(["_r", "_scene_order"]).groupby("group").cumcount()
    df = df.sort_values(["_r", "_group_order"], kind="stable")
    return df.drop(columns=["_h", "_cat_order", "_scene_order", "_group_order", "_cat", "_r"])


def select(candidates: pd.DataFrame, cfg: EvalSetConfig) -> tuple[pd.DataFrame, dict]:
    """(the selected rows of `candidates` (LISTING_COLUMNS, with `split`), sorted by task, scene and
    episode id; a report per task: candidates per difficulty, target and selected counts)."""
    missing = [c for c in LISTING_COLUMNS + ["split"] if c not in candidates.columns]
    if missing:
        raise ValueError(f"eval set candidates lack the column(s) {missing}")
    pool = candidates[candidates["split"].isin(list(cfg.from_splits))
                      & candidates["difficulty"].isin(list(cfg.proportions))]
    parts, report = [], {}
    for task in sorted(pool["task"].unique()):
        t = pool[pool["task"] == task]
        available = t["difficulty"].value_counts().to_dict()
        n = feasible_size(available, cfg.size, cfg.proportions)
        want = allocate(n, cfg.proportions)
        for d, k in want.items():
            if k:
                parts.append(_round_robin(t[t["difficulty"] == d], cfg.seed, task).head(k))
        report[task] = {"candidates": {d: int(available.get(d, 0)) for d in cfg.proportions},
                        "requested": int(cfg.size), "selected": n, "per_difficulty": want,
                        "scenes": int(t["scene_id"].nunique()), "groups": int(t["group"].nunique())}
    cols = LISTING_COLUMNS + ["split"]
    out = pd.concat(parts) if parts else pd.DataFrame(columns=cols)
    out = out[cols].sort_values(["task", "scene_id", "episode_id"], kind="stable").reset_index(drop=True)
    return out, report


def candidates(catalog, scenes, splits: list[str] | None = None) -> pd.DataFrame:
    """The episodes of `scenes` on disk (every task; only `splits` when given) as LISTING_COLUMNS +
    split: what `select` draws from. Reads four small columns per (scene, task)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    parts = []
    for scene in scenes:
        for task, ds in catalog.find("episodes", scene).items():
            t = ds.load(["episode_id", "split", "difficulty", "goal_object_category"])
            if splits is not None:
                t = t.filter(pc.is_in(t["split"], value_set=pa.array(list(splits))))
            if t.num_rows:
                df = t.to_pandas()
                df["task"], df["scene_id"], df["group"] = task, scene.scene_id, scene.group
                parts.append(df)
    if not parts:
        return pd.DataFrame(columns=LISTING_COLUMNS + ["split"])
    return pd.concat(parts, ignore_index=True)[LISTING_COLUMNS + ["split"]]


EPISODE_STAGES = ("episodes", "objectnav_episodes")
"""The pipeline stages that write a scene's episodes (PointNav and ImageNav; ObjectNav, after semantics)."""


def episodes_stamp(catalog, scene) -> str | None:
    """The config hashes of a scene's stored episodes (its episode stages' markers, joined), or None
    when no such stage has run."""
    import json

    stamps = []
    for stage in EPISODE_STAGES:
        try:
            stamps.append(json.loads(catalog.path("markers", scene, stage=stage).read_text()).get("config_hash") or "")
        except (OSError, ValueError):
            stamps.append("")
    return "+".join(stamps) if any(stamps) else None


def settings_json(cfg: EvalSetConfig) -> str:
    """The settings that decide a listing, as its metadata records them."""
    import json

    return json.dumps({"name": cfg.name, "size": cfg.size, "proportions": cfg.proportions,
                       "from_splits": list(cfg.from_splits), "seed": cfg.seed}, sort_keys=True)


def build_listing(catalog, scenes, cfg: EvalSetConfig):
    """(selected rows, per-task report, the listing as a pyarrow table whose metadata records the
    episodes each held-out scene had: `listing` redraws it when they change)."""
    import json

    import pyarrow as pa

    chosen, report = select(candidates(catalog, scenes, list(cfg.from_splits)), cfg)
    stamps = {s.scene_id: episodes_stamp(catalog, s) for s in scenes}
    table = pa.Table.from_pandas(chosen, preserve_index=False)
    meta = {"eval_set": settings_json(cfg),
            "episodes_stamps": json.dumps(stamps, sort_keys=True)}
    table = table.replace_schema_metadata({k: v.encode() for k, v in meta.items()})
    return chosen, report, table


def listing(catalog, scenes, cfg: EvalSetConfig, scene=None) -> pd.DataFrame:
    """The evaluation set's listing in the data root (`eval_set` of the layout): the one a release
    wrote, or else drawn now from `scenes` and saved (same candidates and seed, same bytes). It is
    drawn again when its settings differ from cfg or when `scene`'s episodes changed since."""
    import json

    ds = catalog.dataset("eval_set", eval_set=cfg.name)
    if ds.exists():
        t = ds.load()
        meta = {k.decode(): v.decode() for k, v in (t.schema.metadata or {}).items()}
        same_cfg = meta.get("eval_set") == settings_json(cfg)
        stamps = json.loads(meta.get("episodes_stamps", "{}"))
        if same_cfg and (scene is None or stamps.get(scene.scene_id) == episodes_stamp(catalog, scene)):
            return t.to_pandas()
    chosen, _, table = build_listing(catalog, scenes, cfg)
    ds.save(table)
    return chosen
