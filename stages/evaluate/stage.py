"""Stage `evaluate`: one agent on the stored episodes of each scene, in closed loop.

Outputs under data/07_eval/{run}/: results/scene_id={id}/part-0.parquet (per episode: metrics, the
executed trajectory, end reason, error), videos/*.mp4 (egocentric view of chosen episodes),
plots/*.png (top-down trajectories); the dataset-level finalize step adds summary.json, tables.md
(the layout of the paper's Tables 6 and 7), results.json (navarena-bench's protocol 2.x layout,
stages.evaluate.bench_results) and, across runs, 07_eval/sr_by_difficulty.png.
"""
from __future__ import annotations

import re

import numpy as np
import pyarrow as pa
from omegaconf import OmegaConf

from navcore.eval.env import EnvConfig, SceneContext
from navcore.eval.episode import Episode
from navcore.eval.loop import evaluate_episodes
from navcore.eval.metrics import METRICS
from navcore.io.licences import redistributable
from navcore.io.progress_log import ProgressLog
from navcore.nav.eval_set import EvalSetConfig, listing
from navcore.seeds import stream_seed
from stages.evaluate.config import EvaluateConfig

REFERENCE_STRIDE = 10  # expert rows kept for DTW (every 0.5 s)


def run_name(ecfg: EvaluateConfig) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", ecfg.run).strip("_")


def eval_set_config(cfg) -> EvalSetConfig | None:
    """The release's zero-shot evaluation set when `evaluate.split` names it, else None."""
    es = OmegaConf.select(cfg, "release.eval_set")
    if es is None or cfg.evaluate.split != es.name:
        return None
    return OmegaConf.to_object(es)


def hashed_inputs(cfg) -> dict | None:
    """the zero-shot set's settings: what decides the episodes of an evaluation on the zero-shot set
    beside its config sections, the set's settings and which scenes a public release may hold (None
    for any other split)."""
    es = eval_set_config(cfg)
    if es is None:
        return None
    return {"eval_set": OmegaConf.to_container(cfg.release.eval_set, resolve=True), "public": cfg.release.public,
            "extra_licenses": list(cfg.release.extra_licenses)}


def eval_set_ids(catalog, scene, cfg) -> dict[str, set[str]] | None:
    """{task: episode ids} of `scene` in the zero-shot evaluation set when `evaluate.split` names it
    (the listing a release wrote into the data root, or drawn now from the catalog's scenes that the
    release would hold: navcore/nav/eval_set.py), else None."""
    es = eval_set_config(cfg)
    if es is None:
        return None
    extra = tuple(cfg.release.extra_licenses)
    pool = [s for s in catalog.scenes if not cfg.release.public or redistributable(s.license, extra)[0]]
    chosen = listing(catalog, pool, es, scene)
    mine = chosen[chosen["scene_id"] == scene.scene_id]
    return {t: set(g["episode_id"]) for t, g in mine.groupby("task")}


def load_episodes(catalog, scene, ecfg: EvaluateConfig, eval_ids: dict[str, set[str]] | None = None) -> list[Episode]:
    """The episodes to run: `evaluate.tasks`, then `split` (or, for the zero-shot set, the episode
    ids of `eval_ids`), `difficulty` and `episodes_per_scene`."""
    out = []
    for task in ecfg.tasks:
        src = catalog.dataset("episodes", scene, task=task)
        if not src.exists():
            continue
        eps = src.load().to_pandas()
        if eval_ids is not None:
            eps = eps[eps["episode_id"].isin(eval_ids.get(task, set()))]
        elif ecfg.split:
            eps = eps[eps["split"] == ecfg.split]
        if ecfg.difficulty:
            eps = eps[eps["difficulty"] == ecfg.difficulty]
        eps = eps.sort_values("episode_id")
        if ecfg.episodes_per_scene is not None:
            eps = eps.head(ecfg.episodes_per_scene)
        tr = catalog.dataset("trajectories", scene, task=task).load(
            ["episode_id", "step", "position_x", "position_y"]).to_pandas()
        refs = {eid: g.sort_values("step")[["position_x", "position_y"]].to_numpy()[::REFERENCE_STRIDE]
                for eid, g in tr.groupby("episode_id")}
        for row in eps.to_dict("records"):
            row["task_type"], row["scene_id"] = task, scene.scene_id
            out.append(Episode.from_row(row, refs.get(row["episode_id"])))
    return out


def scene_context(scene, cfg, catalog, render: bool, renderer: str) -> SceneContext:
    """SceneContext.from_catalog with the run's embodiment and episodes config."""
    return SceneContext.from_catalog(catalog, scene, OmegaConf.to_object(cfg.embodiment), cfg.episodes.components,
                                     cfg.episodes.min_island_area_m2, cfg.episodes.geodesic_neighbourhood, render, renderer)


def run(scene, cfg, catalog) -> dict:
    ecfg: EvaluateConfig = OmegaConf.to_object(cfg.evaluate)
    ctx = scene_context(scene, cfg, catalog, ecfg.render, ecfg.renderer)
    env_cfg = EnvConfig.of(ecfg, OmegaConf.to_object(cfg.episodes).actions)
    episodes = load_episodes(catalog, scene, ecfg, eval_set_ids(catalog, scene, cfg))
    run = run_name(ecfg)
    videos = []
    log = ProgressLog(catalog.dataset("eval_progress", scene, run=run).path)
    log.start(len(episodes), scene_id=scene.scene_id, scene=scene.name, run=run)

    def logged(row: dict, frames: list | None) -> None:
        log.item(task=row["task"], episode_id=row["episode_id"], success=bool(row["sr"]), spl=row["spl"],
                 steps=int(row["steps"]), end_reason=row["end_reason"], error=row["error"])
        if frames:  # the first evaluate.videos episodes of an unbatched run
            videos.append(write_video(frames, catalog.dataset("eval_video", scene, run=run, task=row["task"],
                                                              episode_id=row["episode_id"])))

    rows = evaluate_episodes(ctx, episodes, ecfg.agent, env_cfg, seed=stream_seed(ecfg.seed, scene.scene_id, "evaluate") % 2**31,
                             timeout=ecfg.timeout_s, agent_args=ecfg.agent_args, batch_slots=ecfg.batch_slots,
                             videos=ecfg.videos, on_result=logged)
    episode_of = {(e.task, e.episode_id): e for e in episodes}
    plots = [plot_trajectory(ctx.costmap, r, episode_of[(r["task"], r["episode_id"])],
                             catalog.dataset("eval_plot", scene, run=run, task=r["task"], episode_id=r["episode_id"]))
             for r in rows[:ecfg.trajectory_plots]]
    out = catalog.dataset("eval_results", scene, run=run)
    write_results(rows, out)
    return {"outputs": [str(out.path), *videos, *plots], "episodes": len(rows), "steps": sum(int(r["steps"]) for r in rows),
            "agent_errors": sum(bool(r["error"]) for r in rows),
            "invalid_actions": sum(int(r.get("invalid_actions", 0)) for r in rows),
            "sr": float(np.mean([r["sr"] for r in rows])) if rows else None, "run": run}


def write_results(rows: list[dict], dataset) -> None:
    metric_cols = list(METRICS)
    # scene_id comes from the hive partition folder
    cols = {c: [r.get(c, "") for r in rows] for c in ("episode_id", "task", "difficulty", "protocol", "end_reason",
                                                       "error", "action_error")}
    table = pa.table({**{c: pa.array(v, pa.string()) for c, v in cols.items()},
                      **{c: pa.array([float(r[c]) for r in rows], pa.float64()) for c in metric_cols},
                      "invalid_actions": pa.array([int(r.get("invalid_actions", 0)) for r in rows], pa.int32()),
                      "geodesic": pa.array([r["geodesic"] for r in rows], pa.float64()),
                      "path_length": pa.array([r["path_length"] for r in rows], pa.float64()),
                      "seconds": pa.array([r["seconds"] for r in rows], pa.float64()),
                      "trajectory_x": pa.array([r["trajectory"][:, 0].tolist() for r in rows], pa.list_(pa.float32())),
                      "trajectory_y": pa.array([r["trajectory"][:, 1].tolist() for r in rows], pa.list_(pa.float32()))})
    dataset.save(table)


def write_video(frames: list[np.ndarray], dataset, fps: int = 10) -> str:
    """Egocentric RGB frames -> H.264 MP4 (odd sizes cut to even)."""
    from navcore.io.video import H264Writer

    with dataset.writing() as tmp, H264Writer(tmp, fps, crf=23) as video:
        for f in frames:
            video.add(f)
    return str(dataset.path)


def plot_trajectory(cm, row: dict, ep: Episode, dataset) -> str:
    """Top-down: free space, the expert's path, the executed path, start and success region."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ny, nx = cm.clearance.shape
    ext = [cm.origin[0], cm.origin[0] + nx * cm.resolution, cm.origin[1], cm.origin[1] + ny * cm.resolution]
    fig, ax = plt.subplots(figsize=(5, 5))
    ax.imshow(~cm.occupancy, origin="lower", extent=ext, cmap="gray", vmin=0, vmax=1)
    if ep.reference_path is not None and len(ep.reference_path):
        ax.plot(*ep.reference_path.T, color="tab:green", lw=1.5, label="expert")
    tr = row["trajectory"]
    ax.plot(tr[:, 0], tr[:, 1], color="tab:red", lw=1.2, label=f"agent ({'success' if row['sr'] else 'failure'})")
    ax.plot(*ep.start[:2], "o", color="tab:blue", label="start")
    from matplotlib.patches import FancyBboxPatch

    for x0, y0, x1, y1 in ep.regions:  # a point's disc, or a footprint grown by the radius
        ax.add_patch(FancyBboxPatch((x0, y0), x1 - x0, y1 - y0, boxstyle=f"round,pad={ep.success_radius}",
                                    color="tab:orange", alpha=0.35))
    ax.set_title(f"{ep.task} {ep.episode_id} ({ep.difficulty}): SPL {row['spl']:.2f}")
    ax.legend(loc="lower right", fontsize=7)
    fig.tight_layout()
    dataset.save(fig, dpi=100)
    plt.close(fig)
    return str(dataset.path)


def finalize(cfg, catalog) -> dict:
    """summary.json and tables.md of this run (all its scenes on disk), and the cross-run plot."""
    from stages.evaluate.report import write_reports

    ecfg = OmegaConf.to_object(cfg.evaluate)
    return write_reports(catalog, run_name(ecfg), ecfg.agent)
