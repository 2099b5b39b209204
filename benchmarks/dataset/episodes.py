"""bench-episodes: the episode dataset of the default synthetic scene set, its throughput and its
checks.

Runs the episodes stage (forced, in this process, so that CPU time is measured) on the default
scenes, then:
- a dataset table like the paper's Table 4 (episodes, mean geodesic and path length, mean steps,
  total duration) per task, and a histogram of geodesic distance by difficulty;
- throughput: validated episodes with expert trajectories per core-second (process CPU time of
  the whole stage, all threads, graph building and IO included), and the projection to the
  22.2 M-episode release;
- checks: every stored trajectory re-checked by the validity filter; every stored geodesic
  against an independent exact any-angle shortest path (a visibility graph over the corner cells
  of the free region, Dijkstra with scipy csgraph), and against the expert's path length.

Writes data/08_reports/bench_episodes.json, bench_episodes.md and bench_episodes_geodesic.png.
  python -m benchmarks.dataset.episodes [--episodes N] [--data data] [--out data/08_reports]
"""
from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from benchmarks import machine
from benchmarks.pages import PAGES_DIR, ROOT, write_page
from navcore.io import jsonio
from navcore.io.datasets import CostmapDataset
from navcore.nav.costmap import Costmap
from navcore.nav.embodiment import Embodiment, Limits
from navcore.nav.geodesic import eligible_cells
from navcore.nav.poses import in_region, object_regions, point_regions
from navcore.nav.tasks import TASK_TYPES
from stages.episodes.config import EpisodesConfig
from stages.episodes.validity import check_trajectory

RELEASE_EPISODES = 22.2e6
TASKS = TASK_TYPES


class VisibilityReference:
    """Shortest paths of the continuous free space, independent of the episodes stage's grid graph:
    a taut path bends only where it touches the boundary of the free region, so a visibility graph
    over the boundary cells (free cells with an occupied 8-neighbour; edges = valid straight
    motions) plus start and goal gives its route to a cell, and a visibility graph over the
    boundary of the valid region sampled 16 times finer near that route gives its length
    (``refined``)."""

    def __init__(self, cm: Costmap, valid: np.ndarray, chunk: int = 2_000_000):
        self.cm = cm
        boundary = valid & ~ndimage.binary_erosion(valid, np.ones((3, 3), bool), border_value=0)
        self.nodes = cm.cell_centers(np.argwhere(boundary))
        n = len(self.nodes)
        iu, ju = np.triu_indices(n, 1)
        rows, cols, w = [], [], []
        for k in range(0, len(iu), chunk):
            a, b = iu[k:k + chunk], ju[k:k + chunk]
            ok = cm.are_motions_valid(np.concatenate([self.nodes[a], self.nodes[b]], 1))
            rows.append(a[ok])
            cols.append(b[ok])
            w.append(np.hypot(*(self.nodes[a[ok]] - self.nodes[b[ok]]).T))
        r, c_, ww = np.concatenate(rows), np.concatenate(cols), np.concatenate(w)
        self.edges = (np.concatenate([r, c_]), np.concatenate([c_, r]), np.concatenate([ww, ww]))

    def distance(self, s: np.ndarray, g: np.ndarray) -> float:
        cm, n = self.cm, len(self.nodes)
        if cm.is_motion_valid(s[0], s[1], g[0], g[1]):
            return float(np.hypot(*(g - s)))
        rows, cols, w = [self.edges[0]], [self.edges[1]], [self.edges[2]]
        for idx, p in ((n, s), (n + 1, g)):
            vis = cm.are_motions_valid(np.concatenate([np.repeat(p[None], n, 0), self.nodes], 1))
            k = np.flatnonzero(vis)
            d = np.hypot(*(self.nodes[k] - p).T)
            rows += [np.full(len(k), idx), k]
            cols += [k, np.full(len(k), idx)]
            w += [d, d]
        graph = coo_matrix((np.concatenate(w), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(n + 2, n + 2)).tocsr()
        dist, pred = dijkstra(graph, indices=n, return_predecessors=True)
        if not np.isfinite(dist[n + 1]):
            return float("inf")
        order, u = [], n + 1
        while u != n:
            order.append(u)
            u = int(pred[u])
        bends = self.nodes[[k for k in order[::-1] if k < len(self.nodes)]]
        return self.refined(s, bends, g)

    def refined(self, s: np.ndarray, bends: np.ndarray, g: np.ndarray, fine: int = 16, corridor: float = 2.0) -> float:
        """The shortest path of the continuous free space near a path through cell centres: the
        valid region's boundary sampled on a grid ``fine`` times finer than the map's, within
        ``corridor`` cells of the path (its boundary points: valid points with an invalid
        4-neighbour), and a visibility graph over them, the start and the goal (edges: valid
        straight motions). A taut path bends only where it touches the boundary, so its length is
        found to within the fine step per bend; independent of the stage's own pulling
        (navcore.nav.geodesic.taut_path, a pattern search on a polyline)."""
        cm = self.cm
        step = cm.resolution / fine
        path = np.concatenate([s[None], bends.reshape(-1, 2), g[None]])
        pad = (corridor + 1) * cm.resolution
        lo, hi = path.min(0) - pad, path.max(0) + pad
        xs, ys = np.arange(lo[0], hi[0], step), np.arange(lo[1], hi[1], step)
        xy = np.stack(np.meshgrid(xs, ys), -1)
        ok = cm.are_states_valid(xy.reshape(-1, 2)).reshape(xy.shape[:2])
        edge = ok & ~ndimage.binary_erosion(ok, [[0, 1, 0], [1, 1, 1], [0, 1, 0]], border_value=1)
        pts = xy[edge]
        # within the corridor: distance to the path's segments
        a, b = path[:-1], path[1:]
        ab = b - a
        t = np.clip(((pts[:, None] - a[None]) * ab[None]).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-18)[None], 0, 1)
        d = np.hypot(*(pts[:, None] - (a[None] + t[..., None] * ab[None])).transpose(2, 0, 1)).min(1)
        pts = np.concatenate([s[None], pts[d <= corridor * cm.resolution], g[None]])
        m = len(pts)
        iu, ju = np.triu_indices(m, 1)
        ok = cm.are_motions_valid(np.concatenate([pts[iu], pts[ju]], 1))
        iu, ju = iu[ok], ju[ok]
        w = np.hypot(*(pts[iu] - pts[ju]).T)
        graph = coo_matrix((np.concatenate([w, w]), (np.concatenate([iu, ju]), np.concatenate([ju, iu]))),
                           shape=(m, m)).tocsr()
        return float(dijkstra(graph, indices=0, min_only=True)[m - 1])


def throughput_at_density(cfg, per_task: int) -> dict:
    """Generation throughput with many episodes per scene (the release has ~8,300 per scene), from
    the stored costmaps with the stage's own core: process CPU time, graph building included."""
    from omegaconf import OmegaConf

    from navcore.instances import load_instances
    from navcore.io.catalog import open_catalog
    from navcore.nav.geodesic import NavGraph, eligible_cells
    from navcore.seeds import stream_seed
    from stages.episodes.config import PlannerConfig, TaskConfig
    from stages.episodes.generate import EpisodeGenerator

    catalog, scenes, _ = open_catalog(cfg)
    ecfg = OmegaConf.to_object(cfg.episodes)
    pcfg: PlannerConfig = OmegaConf.to_object(cfg.planner)
    emb = OmegaConf.to_object(cfg.embodiment)
    shared, n, cpu = 0.0, dict.fromkeys(TASKS, 0), dict.fromkeys(TASKS, 0.0)
    for scene in scenes:
        c0 = time.process_time()
        cm = catalog.dataset("costmaps", scene).load(emb.name)
        graph = NavGraph(cm, eligible_cells(cm, ecfg), ecfg.geodesic_neighbourhood)
        shared += time.process_time() - c0
        for t in TASKS:
            tcfg: TaskConfig = OmegaConf.to_object(cfg.task[t])
            tcfg.episodes_per_scene = per_task
            inst = load_instances(scene, catalog, tcfg.instance_source).to_pylist() if t == "objectnav" else None
            res = EpisodeGenerator(cm, graph, tcfg, ecfg, pcfg, emb, scene.scene_id,
                                   stream_seed(ecfg.seed, scene.scene_id, t), inst).generate()
            n[t] += len(res.episodes)
            cpu[t] += res.cpu_s
    total = sum(n.values())
    return {"episodes_per_scene_and_task": per_task, "scenes": len(scenes), "shared_cpu_s": round(shared, 2),
            "episodes": n, "episodes_per_core_s": {t: round(n[t] / (cpu[t] + shared * n[t] / total), 1) for t in TASKS}}


def compare_planners(cfg, n: int = 100) -> dict:
    """Each registered planner on the first scene's PointNav: throughput and expert quality."""
    from omegaconf import OmegaConf

    from navcore.io.catalog import open_catalog
    from navcore.nav.geodesic import NavGraph, eligible_cells
    from stages.episodes.config import PlannerConfig, TaskConfig
    from stages.episodes.generate import EpisodeGenerator
    from stages.episodes.planner import PLANNERS

    catalog, scenes, _ = open_catalog(cfg)
    ecfg = OmegaConf.to_object(cfg.episodes)
    emb = OmegaConf.to_object(cfg.embodiment)
    cm = catalog.dataset("costmaps", scenes[0]).load(emb.name)
    graph = NavGraph(cm, eligible_cells(cm, ecfg), ecfg.geodesic_neighbourhood)
    tcfg: TaskConfig = OmegaConf.to_object(cfg.task["pointnav"])
    tcfg.episodes_per_scene = n
    out = {}
    for name in PLANNERS:
        res = EpisodeGenerator(cm, graph, tcfg, ecfg, PlannerConfig(name=name), emb, "bench", 1).generate()
        ratio = np.array([e["path_length"] / e["geodesic_distance"] for e in res.episodes])
        out[name] = {"episodes": len(res.episodes), "episodes_per_core_s": round(len(res.episodes) / res.cpu_s, 1),
                     "expert_over_geodesic_median": round(float(np.median(ratio)), 4),
                     "expert_over_geodesic_p95": round(float(np.quantile(ratio, 0.95)), 4),
                     "rejections": dict(res.rejections)}
    return out


def run_stage(data: str, episodes: int | None) -> dict:
    from hydra import compose, initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs
    from pipeline.executor import execute

    register_configs()
    over = [f"data_root={data}", "executor=sync", "stages=[episodes]", "force=true"]
    if episodes:
        over += [f"task.{t}.episodes_per_scene={episodes}" for t in TASKS]
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=over)
    t0 = time.perf_counter()
    summary = execute(cfg)
    if summary["failures"]:
        raise RuntimeError(f"episodes stage failed: {summary['failures']}")
    return {"wall_s": time.perf_counter() - t0, "cfg": cfg}


def episode_markers(data: Path) -> list[dict]:
    """Per scene, the episode stages' markers (`episodes`: PointNav and ImageNav; `objectnav_episodes`)
    as one: their tasks merged, their CPU seconds summed (each stage pays its own set-up)."""
    merged: dict[str, dict] = {}
    for stage in ("episodes", "objectnav_episodes"):
        for p in sorted((data / "_markers" / stage).glob("*.json")):
            m = json.loads(p.read_text())
            into = merged.setdefault(m["scene_id"], {**m, "info": {**m["info"], "tasks": {}, "cpu_s": 0.0}})
            into["info"]["tasks"].update(m["info"].get("tasks", {}))
            into["info"]["cpu_s"] += m["info"].get("cpu_s", 0.0)
    return [merged[k] for k in sorted(merged)]


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--episodes", type=int, default=None, help="episodes per scene and task (default: config)")
    ap.add_argument("--data", default="data")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", action="store_true", help="also write docs/benchmarks/bench_episodes.md (make bench-episodes)")
    ap.add_argument("--density", type=int, default=1000,
                    help="episodes per scene and task of the throughput run at release density (0 = skip)")
    ap.add_argument("--repeats", type=int, default=3, help="repeats of the release-density run (median)")
    ap.add_argument("--planners", type=int, default=1, help="compare the registered planners (0 = skip)")
    ap.add_argument("--geodesic-sample", type=int, default=0,
                    help="check at most this many episodes per scene and task against the reference (0 = all)")
    args = ap.parse_args(argv)
    run = run_stage(args.data, args.episodes)
    data = Path(args.data)
    from navcore.io.catalog import open_catalog

    # the run's scene set only: other scene sets may share the data root (bench-real's real scenes)
    scenes = sorted(s.scene_id for s in open_catalog(run["cfg"])[1])
    markers = episode_markers(data)
    eps = pd.read_parquet(data / "05_episodes")
    trajs = pd.read_parquet(data / "06_trajectories")
    eps["task"] = eps["task"].astype(str)
    eps["scene_id"] = eps["scene_id"].astype(str)
    trajs["task"] = trajs["task"].astype(str)
    trajs["scene_id"] = trajs["scene_id"].astype(str)
    eps = eps[eps["scene_id"].isin(scenes)]
    trajs = trajs[trajs["scene_id"].isin(scenes)]
    scenes = sorted(eps["scene_id"].unique())
    markers = [m for m in markers if m["scene_id"] in scenes]
    cfg = run["cfg"]
    emb = Embodiment(**{k: v for k, v in dict(cfg.embodiment).items()})
    ecfg = EpisodesConfig(**{k: v for k, v in dict(cfg.episodes).items() if k != "difficulty"})

    # throughput: all the stage's CPU time over its episodes, and per task its own generation time
    total_cpu = sum(m["info"]["cpu_s"] for m in markers)
    per_task = {}
    for t in TASKS:
        n = sum(m["info"]["tasks"][t]["episodes"] for m in markers if t in m["info"]["tasks"])
        cpu = sum(m["info"]["tasks"][t]["cpu_s"] for m in markers if t in m["info"]["tasks"])
        per_task[t] = {"episodes": n, "cpu_s": cpu, "episodes_per_core_s": n / cpu if cpu else 0.0}
    shared = total_cpu - sum(v["cpu_s"] for v in per_task.values())  # graphs, IO
    n_all = sum(v["episodes"] for v in per_task.values())
    for t, v in per_task.items():  # charge the shared cost pro rata
        v["episodes_per_core_s_with_shared"] = v["episodes"] / (v["cpu_s"] + shared * v["episodes"] / n_all)

    # re-check every stored trajectory; geodesic vs the independent reference and the expert
    valid_n = checked = 0
    reasons: dict[str, int] = {}
    rel_errs, longer_than_expert, cases = [], 0, []
    rng = np.random.default_rng(0)
    ref_time = 0.0
    for sid in scenes:
        cm = CostmapDataset(data / "03_costmaps" / f"{sid}.zarr").load(emb.name)
        t0 = time.perf_counter()
        ref = VisibilityReference(cm, eligible_cells(cm, ecfg))
        ref_time += time.perf_counter() - t0
        se = eps[eps["scene_id"] == sid]
        st = trajs[trajs["scene_id"] == sid]
        groups = {k: g for k, g in st.groupby(["task", "episode_id"], sort=False)}
        for task, te in se.groupby("task"):
            sample = te if not args.geodesic_sample or len(te) <= args.geodesic_sample else \
                te.iloc[np.sort(rng.choice(len(te), args.geodesic_sample, replace=False))]
            sample_ids = set(sample["episode_id"])
            for e in te.itertuples():
                t = groups[(task, e.episode_id)].sort_values("step")
                if task == "objectnav":
                    regions = object_regions(json.loads(e.goals_json))
                else:
                    regions = point_regions([[e.goal_position_x, e.goal_position_y]])
                r = float(e.success_radius)
                why = check_trajectory(
                    t["position_x"].to_numpy(), t["position_y"].to_numpy(), t["yaw"].to_numpy(),
                    t["linear_velocity"].to_numpy(np.float64), t["angular_velocity"].to_numpy(np.float64), cm,
                    emb.radius, Limits.of(emb), ecfg.dt,
                    lambda x, y: bool(in_region(x, y, regions, r)),
                    e.goal_yaw if task == "imagenav" else None, e.heading_tolerance if task == "imagenav" else None)
                checked += 1
                valid_n += why is None
                if why:
                    reasons[why] = reasons.get(why, 0) + 1
                longer_than_expert += bool(e.geodesic_distance > e.path_length * (1 + 1e-6))
                if e.episode_id in sample_ids:
                    d = ref.distance(np.array([e.start_position_x, e.start_position_y]),
                                     np.array([e.goal_position_x, e.goal_position_y]))
                    rel_errs.append((float(e.geodesic_distance) - d) / d)
                    cases.append({"scene_id": sid, "task": task, "episode_id": e.episode_id,
                                  "stored_m": round(float(e.geodesic_distance), 4), "reference_m": round(d, 4),
                                  "rel_err": (float(e.geodesic_distance) - d) / d})
    rel = np.asarray(rel_errs)

    # the dataset table (paper Table 4) and the per-difficulty histogram
    table = {}
    for t in TASKS:
        te = eps[eps["task"] == t]
        ratio = te["path_length"] / te["geodesic_distance"]
        table[t] = {"episodes": int(len(te)), "mean_geodesic_m": float(te["geodesic_distance"].mean()),
                    "mean_path_m": float(te["path_length"].mean()), "mean_steps": float(te["num_steps"].mean()),
                    "total_hours": float(te["total_time"].sum() / 3600),
                    "mean_oracle_actions": float(te["oracle_actions"].map(len).mean()),
                    "expert_over_geodesic_median": float(ratio.median()),
                    "expert_over_geodesic_p95": float(ratio.quantile(0.95)),
                    "difficulty": {k: int(v) for k, v in te["difficulty"].value_counts().items()}}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    _histogram(eps, cfg, out / "bench_episodes_geodesic.png")
    dense = None
    if args.density:  # repeated: the machine is shared and noisy; medians per task
        runs = [throughput_at_density(cfg, args.density) for _ in range(args.repeats)]
        dense = {**runs[0], "repeats": args.repeats,
                 "episodes_per_core_s": {t: float(np.median([r["episodes_per_core_s"][t] for r in runs]))
                                         for t in TASKS},
                 "episodes_per_core_s_runs": {t: [r["episodes_per_core_s"][t] for r in runs] for t in TASKS}}
    pn_rate = (dense or {}).get("episodes_per_core_s", {}).get(
        "pointnav", per_task["pointnav"]["episodes_per_core_s_with_shared"])
    result = {
        "machine": machine(), "scenes": len(scenes), "planner": cfg.planner.name,
        "episodes_per_core_s": (dense or {}).get("episodes_per_core_s") or
        {t: round(v["episodes_per_core_s_with_shared"], 1) for t, v in per_task.items()},
        "episodes_per_core_s_default_dataset": {t: round(v["episodes_per_core_s_with_shared"], 1)
                                                for t, v in per_task.items()},
        "episodes_per_core_s_generation_only": {t: round(v["episodes_per_core_s"], 1) for t, v in per_task.items()},
        "release_density_run": dense,
        "planners": compare_planners(cfg) if args.planners else None,
        "stage_cpu_s": round(total_cpu, 2), "shared_cpu_s": round(shared, 2),
        "release_core_hours_at_pointnav_rate": round(RELEASE_EPISODES / pn_rate / 3600, 1),
        "valid_fraction": valid_n / checked, "trajectories_checked": checked, "invalid_reasons": reasons,
        "geodesic_max_rel_err": float(np.abs(rel).max()), "geodesic_mean_rel_err": float(rel.mean()),
        "geodesic_p99_abs_rel_err": float(np.quantile(np.abs(rel), 0.99)),
        "geodesic_worst": sorted(cases, key=lambda c: -abs(c["rel_err"]))[:5],
        "geodesic_checked": int(len(rel)), "geodesic_longer_than_expert": longer_than_expert,
        "geodesic_from_expert": {t: sum(m["info"]["tasks"][t]["geodesic_from_expert"] for m in markers) for t in TASKS},
        "reference_build_s": round(ref_time, 2),
        "mean_path_m": {t: round(v["mean_path_m"], 3) for t, v in table.items()},
        "mean_steps": {t: round(v["mean_steps"], 1) for t, v in table.items()},
        "table": table,
        "rejections": {t: dict(sum((Counter(m["info"]["tasks"][t]["rejections"]) for m in markers), Counter()))
                       for t in TASKS},
    }
    (out / "bench_episodes.json").write_text(jsonio.dumps(result, indent=1))
    (out / "bench_episodes.md").write_text(_markdown(result))
    if args.docs:
        write_page("bench_episodes.md", _markdown(result))
        (ROOT / PAGES_DIR / "bench_episodes_geodesic.png").write_bytes((out / "bench_episodes_geodesic.png").read_bytes())
    print(_markdown(result))
    return result


def _histogram(eps: pd.DataFrame, cfg, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(cfg.episodes.difficulty.names)
    fig, axes = plt.subplots(1, len(TASKS), figsize=(4 * len(TASKS), 3), sharey=True)
    bins = np.linspace(0, max(1.0, float(eps["geodesic_distance"].max())) * 1.02, 31)
    for ax, t in zip(axes, TASKS):
        te = eps[eps["task"] == t]
        ax.hist([te.loc[te["difficulty"] == n, "geodesic_distance"] for n in names], bins=bins, stacked=True,
                label=names)
        ax.set_title(f"{t} ({len(te)} episodes)")
        ax.set_xlabel("geodesic distance (m)")
    axes[0].set_ylabel("episodes")
    axes[-1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _markdown(r: dict) -> str:
    lines = [f"# bench-episodes ({r['scenes']} synthetic scenes, planner {r['planner']}; {r['machine']})", "",
             "| task | episodes | mean geodesic (m) | mean path (m) | mean steps (20 Hz) | total (h) | oracle actions "
             "| expert / geodesic (median, p95) | easy / medium / hard |",
             "|---|---|---|---|---|---|---|---|---|"]
    for t, v in r["table"].items():
        d = v["difficulty"]
        lines.append(f"| {t} | {v['episodes']} | {v['mean_geodesic_m']:.2f} | {v['mean_path_m']:.2f} | "
                     f"{v['mean_steps']:.0f} | {v['total_hours']:.2f} | {v['mean_oracle_actions']:.1f} | "
                     f"{v['expert_over_geodesic_median']:.3f}, {v['expert_over_geodesic_p95']:.3f} | "
                     f"{d.get('easy', 0)} / {d.get('medium', 0)} / {d.get('hard', 0)} |")
    d = r.get("release_density_run") or {}
    dens = (f"{d.get('episodes_per_scene_and_task')} episodes per scene and task, median of {d.get('repeats')}"
            if d else "n/a")
    lines += ["", "Validated episodes with expert trajectories per core-second (process CPU time, all threads; "
              "graph building and IO charged pro rata):", "",
              f"| task | at release density ({dens}) | default dataset, whole stage | default dataset, generation only |",
              "|---|---|---|---|"]
    for t in r["episodes_per_core_s"]:
        lines.append(f"| {t} | {r['episodes_per_core_s'][t]:.1f} | {r['episodes_per_core_s_default_dataset'][t]:.1f} | "
                     f"{r['episodes_per_core_s_generation_only'][t]:.1f} |")
    lines += ["", f"22.2 M episodes at the PointNav rate: {r['release_core_hours_at_pointnav_rate']:.1f} core-hours "
              "(paper: about 62).", "",
              f"Checks: {r['valid_fraction'] * 100:.2f} % of {r['trajectories_checked']} stored trajectories pass the "
              f"validity re-check; geodesic vs an independent shortest path of the continuous free space (a "
              f"visibility graph over the valid region's boundary sampled every 1/16 cell) over "
              f"{r['geodesic_checked']} episodes: max |relative error| {r['geodesic_max_rel_err'] * 100:.3f} %, "
              f"p99 {r.get('geodesic_p99_abs_rel_err', float('nan')) * 100:.3f} %, "
              f"mean {r['geodesic_mean_rel_err'] * 100:+.3f} %; geodesic longer than the expert's path: "
              f"{r['geodesic_longer_than_expert']}.", ""]
    if r.get("geodesic_worst"):
        lines += ["Worst geodesics (target: within 1 %):", "", "| scene | task | episode | stored (m) | reference (m) | error |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {c['scene_id']} | {c['task']} | {c['episode_id']} | {c['stored_m']:.4f} | {c['reference_m']:.4f} | "
                  f"{100 * c['rel_err']:+.3f} % |" for c in r["geodesic_worst"]]
        lines.append("")
    if r.get("planners"):
        lines += ["Planners (100 PointNav episodes on the first scene; `planner=<key>`):", "",
                  "| planner | episodes / core-s | expert / geodesic median | p95 |", "|---|---|---|---|"]
        for k, v in r["planners"].items():
            lines.append(f"| {k} | {v['episodes_per_core_s']:.1f} | {v['expert_over_geodesic_median']:.3f} | "
                         f"{v['expert_over_geodesic_p95']:.3f} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
