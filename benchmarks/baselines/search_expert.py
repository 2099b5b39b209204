"""The search-then-go expert (navcore.nav.search) against the geodesic oracle on a data root's
ObjectNav or ImageNav episodes, unrendered: success, steps, when the goal counted as found and how
far from the goal, CPU cost. ImageNav's expert is measured at each --overlap (0: found at a glimpse of
the goal's floor; > 0: once that share of the goal image's surface is in view, navarena train's
view_overlap).

    python -m benchmarks.baselines.search_expert [ROOT] [--task objectnav] [--split train] [--per-scene 25]
    python -m benchmarks.baselines.search_expert data --task imagenav --overlap 0 0.5
"""
from __future__ import annotations

import argparse
import sys
import time


def measure(root: str, split: str = "train", per_scene: int = 25, task: str = "objectnav", overlap: float = 0.0):
    import pandas as pd

    from navcore.eval.dataset import NavDataset
    from navcore.eval.env import EnvConfig, NavEnv
    from navcore.nav.actions import STOP
    from navcore.nav.oracle import DiscreteOracle
    from navcore.nav.search import SearchingExpert

    ds = NavDataset(root)
    rows = []
    for sid in ds.scene_ids(task):
        ctx = ds.scene_context(sid, renderer="cpu")
        for ep in ds.episodes(sid, task, split)[:per_scene]:
            left = ctx.field(ep).grid  # geodesic metres to the goal
            goal = DiscreteOracle(left, ctx.costmap, ep.regions, ep.success_radius, ep.goal_yaw, ep.heading_tolerance)
            ex = SearchingExpert(ctx.graph, goal, ep.regions, ep.success_radius, ctx.emb.hfov_deg,
                                 goal_view=ep.goal_pose if ep.goal_yaw is not None else None, overlap=overlap)
            env = NavEnv(ctx, EnvConfig(render=False, protocol="explicit_stop"))
            env.reset(ep)
            s, found, found_m, t = env.state, None, None, time.perf_counter()
            while not s.done and s.steps < ep.max_steps:
                a = ex.action(s.x, s.y, s.yaw)
                if found is None and ex.found:
                    found, found_m = s.steps, float(left[tuple(ctx.costmap.cells_of([[s.x, s.y]])[0])])
                env.step(STOP if a < 0 else a)
            ref = goal.episode(ep.start, ep.max_steps)
            rows.append({"scene_id": sid, "success": bool(s.success), "steps": s.steps,
                         "oracle_steps": len(ref) if ref is not None else None, "found_at": found,
                         "found_m": found_m,
                         "seconds": time.perf_counter() - t})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root", nargs="?", default="data")
    ap.add_argument("--split", default="train")
    ap.add_argument("--per-scene", type=int, default=25)
    ap.add_argument("--task", default="objectnav", choices=["objectnav", "imagenav"])
    ap.add_argument("--overlap", type=float, nargs="+", default=[0.0], help="ImageNav: the found criteria to measure")
    a = ap.parse_args(argv)
    for overlap in a.overlap if a.task == "imagenav" else [0.0]:
        d = measure(a.root, a.split, a.per_scene, a.task, overlap)
        if d.empty:
            print(f"{a.root}: no {a.task} episodes of split {a.split!r}")
            return 1
        crit = f"overlap {overlap:g}: " if a.task == "imagenav" else ""
        print(f"{crit}{len(d)} episodes of {d.scene_id.nunique()} scene(s): reached {int(d.success.sum())}, "
              f"{d.steps.mean():.1f} steps on average against the oracle's {d.oracle_steps.mean():.1f}, goal found at "
              f"the start in {100 * (d.found_at == 0).mean():.0f} %, found after a median {d.found_at.median():.0f} steps "
              f"{d.found_m.median():.2f} m (geodesic) from the goal, {1000 * d.seconds.sum() / d.steps.sum():.1f} ms a step")
    return 0


if __name__ == "__main__":
    sys.exit(main())
