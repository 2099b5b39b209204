"""The search-then-go ObjectNav expert (navcore.nav.search) against the geodesic oracle on a data
root's ObjectNav episodes, unrendered: success, steps, when the goal came into view, CPU cost.

    python -m benchmarks.baselines.search_expert [ROOT] [--split train] [--per-scene 25]
"""
from __future__ import annotations

import argparse
import sys
import time


def measure(root: str, split: str = "train", per_scene: int = 25):
    import pandas as pd

    from navarena.dataset import NavDataset
    from navcore.eval.env import EnvConfig, NavEnv
    from navcore.nav.actions import STOP
    from navcore.nav.oracle import DiscreteOracle
    from navcore.nav.search import SearchingExpert

    ds = NavDataset(root)
    rows = []
    for sid in ds.scene_ids("objectnav"):
        ctx = ds.scene_context(sid, renderer="cpu")
        for ep in ds.episodes(sid, "objectnav", split)[:per_scene]:
            goal = DiscreteOracle(ctx.field(ep).grid, ctx.costmap, ep.regions, ep.success_radius, ep.goal_yaw,
                                  ep.heading_tolerance)
            ex = SearchingExpert(ctx.graph, goal, ep.regions, ep.success_radius, ctx.emb.hfov_deg)
            env = NavEnv(ctx, EnvConfig(render=False, protocol="explicit_stop"))
            env.reset(ep)
            s, found, t = env.state, None, time.perf_counter()
            while not s.done and s.steps < ep.max_steps:
                a = ex.action(s.x, s.y, s.yaw)
                found = s.steps if found is None and ex.found else found
                env.step(STOP if a < 0 else a)
            ref = goal.episode(ep.start, ep.max_steps)
            rows.append({"scene_id": sid, "success": bool(s.success), "steps": s.steps,
                         "oracle_steps": len(ref) if ref is not None else None, "found_at": found,
                         "seconds": time.perf_counter() - t})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root", nargs="?", default="data")
    ap.add_argument("--split", default="train")
    ap.add_argument("--per-scene", type=int, default=25)
    a = ap.parse_args(argv)
    d = measure(a.root, a.split, a.per_scene)
    if d.empty:
        print(f"{a.root}: no ObjectNav episodes of split {a.split!r}")
        return 1
    print(f"{len(d)} episodes of {d.scene_id.nunique()} scene(s): reached {int(d.success.sum())}, "
          f"{d.steps.mean():.1f} steps on average against the oracle's {d.oracle_steps.mean():.1f}, goal in view at "
          f"the start in {100 * (d.found_at == 0).mean():.0f} %, {1000 * d.seconds.sum() / d.steps.sum():.1f} ms a step")
    return 0


if __name__ == "__main__":
    sys.exit(main())
