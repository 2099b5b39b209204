"""Evaluate your own policy in closed loop: a class with reset(task) and act(obs), run with the
library alone (navarena: no pipeline) on a data root or a release folder.

    python examples/custom_policy.py [DATA_ROOT_OR_RELEASE] [--episodes 5]

The same policy runs from the command line, its module importable (here the repository root is on
the path): navarena eval data --agent examples.custom_policy:GoalSeeker --tasks pointnav, or in the
pipeline: navarena run stages=[evaluate] evaluate.agent=examples.custom_policy:GoalSeeker

`obs` holds the robot's `pose` (x, y, yaw), the goal (PointNav: `pointgoal` = distance and bearing
in the robot frame), and with rendering on `rgb` [H, W, 3] and `depth` [H, W] (metres). An action is
0 STOP, 1 forward 0.25 m, 2 turn left, 3 turn right (or a waypoint / velocity dict: docs/evaluation.md).
"""
import argparse
import math

STOP, FORWARD, LEFT, RIGHT = 0, 1, 2, 3


class GoalSeeker:
    """Turns towards the point goal, then drives; steps around what the depth shows ahead."""

    def __init__(self, clearance: float = 0.5, **_):
        self.clearance = clearance

    def reset(self, task: dict) -> None:
        self.task = task["task_type"]

    def act(self, obs: dict):
        distance, bearing = (float(v) for v in obs["pointgoal"])
        if distance < 0.3:
            return STOP
        if abs(bearing) > math.radians(20):
            return LEFT if bearing > 0 else RIGHT
        depth = obs.get("depth")
        if depth is not None:
            h, w = depth.shape
            ahead = depth[h // 3: 2 * h // 3, w // 3: 2 * w // 3]
            if ((ahead > 0) & (ahead < self.clearance)).mean() > 0.2:
                return LEFT
        return FORWARD


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("root", nargs="?", default="data", help="a data root or a release folder")
    ap.add_argument("--episodes", type=int, default=5, help="PointNav episodes a scene")
    a = ap.parse_args(argv)
    from navarena import NavDataset, aggregate, run_episodes

    ds = NavDataset(a.root)
    cfg = ds.env_config(width=80, height=60)
    rows = []
    for sid in ds.scene_ids("pointnav"):
        ctx = ds.scene_context(sid, renderer="cpu")
        rows += run_episodes(ctx, ds.episodes(sid, "pointnav", limit=a.episodes), GoalSeeker(), cfg)
    overall = aggregate(rows)["overall"]
    print(f"GoalSeeker on {len(rows)} PointNav episodes: SR {overall['sr']:.2f}, SPL {overall['spl']:.2f}")
    return rows


if __name__ == "__main__":
    main()
