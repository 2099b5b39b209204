"""Where does an ObjectNav policy stop when it stops wrongly? From a navarena eval results.parquet
under explicit_stop and the data root it ran on: for each episode ended by a STOP away from every
goal, how far its end lies from the nearest goal footprint and whether it lies beside an object of
another category (within --beside metres of its box), against the same share for the successful
episodes' ends. A policy that stops beside furniture of any category, not beside its goal's, shows
a share near 1 for the false stops and a much smaller one for the successes:

    python -m benchmarks.baselines.stop_sites ROOT RESULTS.parquet [--beside 1.0]
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from navcore.nav.poses import region_distance


def stop_sites(ends: list[dict], beside: float = 1.0) -> dict:
    """ends: per episode {sr, end_reason, xy (its last position), goal_boxes [k, 4] (its goal
    instances' footprints), other_boxes [m, 4] (the scene's objects of other categories)}."""
    def near_other(e):  # region_distance: to the nearest box (min_x, min_y, max_x, max_y), 0 inside; inf for none
        return bool(region_distance(e["xy"], e["other_boxes"])[0] <= beside)

    false = [e for e in ends if e["sr"] == 0 and e["end_reason"] == "stop"]
    good = [e for e in ends if e["sr"] > 0]
    dist = [float(region_distance(e["xy"], e["goal_boxes"])[0]) for e in false if len(e["goal_boxes"])]
    share = (lambda es: round(float(np.mean([near_other(e) for e in es])), 3) if es else None)
    return {"episodes": len(ends), "successes": len(good), "false_stops": len(false),
            "false_stop_goal_distance_median_m": round(float(np.median(dist)), 2) if dist else None,
            f"false_stops_beside_another_category_{beside:g}m": share(false),
            f"successes_beside_another_category_{beside:g}m": share(good)}


def load(root: str, results: str) -> list[dict]:
    """The `ends` of stop_sites from a results.parquet and its data root (goal footprints from the
    episodes' goals_json, other objects from 04_semantics/<scene>/instances.parquet)."""
    import pandas as pd

    from navcore.eval.dataset import NavDataset

    ds, rows, ends = NavDataset(root), pd.read_parquet(results), []
    for sid, part in rows.groupby("scene_id"):
        table = ds.episode_table(sid, "objectnav").set_index("episode_id")
        inst = pd.read_parquet(ds.path / "04_semantics" / sid / "instances.parquet")
        for _, r in part.iterrows():
            ep = table.loc[r.episode_id]
            goals = json.loads(ep.goals_json)
            other = inst[inst.category != ep.goal_object_category]
            ends.append({"sr": float(r.sr), "end_reason": r.end_reason,
                         "xy": (float(r.trajectory_x[-1]), float(r.trajectory_y[-1])),
                         "goal_boxes": np.array([[*g["footprint"]["min"], *g["footprint"]["max"]] for g in goals
                                                 if g.get("footprint")]).reshape(-1, 4),
                         "other_boxes": other[["min_x", "min_y", "max_x", "max_y"]].to_numpy(np.float64)})
    return ends


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root")
    ap.add_argument("results")
    ap.add_argument("--beside", type=float, default=1.0, help="metres from an object's box (1.0)")
    a = ap.parse_args(argv)
    print(json.dumps(stop_sites(load(a.root, a.results), a.beside), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
