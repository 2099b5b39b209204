"""Evaluate your own policy in closed loop: a class with reset(task) and act(obs).

    .venv/bin/python examples/custom_policy.py [DATA_ROOT] [--episodes 5]

The same policy runs from the command line, its module importable (here the repository root is on
the path): navarena run stages=[evaluate] evaluate.agent=examples.custom_policy:GoalSeeker

`obs` holds the robot's `pose` (x, y, yaw), the goal (PointNav: `pointgoal` = distance and bearing
in the robot frame), and with rendering on `rgb` [H, W, 3] and `depth` [H, W] (metres). An action is
0 STOP, 1 forward 0.25 m, 2 turn left, 3 turn right (or a waypoint / velocity dict: docs/evaluation.md).
"""
import argparse
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
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
    ap.add_argument("root", nargs="?", default="data")
    ap.add_argument("--episodes", type=int, default=5, help="PointNav episodes a scene")
    ap.add_argument("overrides", nargs="*", help="more config overrides (e.g. scenes.catalog=... as the root was made)")
    a = ap.parse_intermixed_args(argv)
    sys.path.insert(0, str(ROOT))
    from hydra import compose, initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs
    from pipeline.executor import execute

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=[
            f"data_root={Path(a.root).resolve()}", "stages=[evaluate]", "evaluate.agent=examples.custom_policy:GoalSeeker",
            "evaluate.tasks=[pointnav]", f"evaluate.episodes_per_scene={a.episodes}", "evaluate.width=80",
            "evaluate.height=60", "evaluate.renderer=cpu", "evaluate.run=goal_seeker", "executor=sync", *a.overrides])
    summary = execute(cfg)
    if summary["failures"]:
        raise SystemExit(f"evaluation failed: {summary['failures']}")
    import json

    res = json.loads((Path(a.root) / "07_eval" / "goal_seeker" / "summary.json").read_text())
    overall = res["tasks"]["pointnav"]["overall"]
    print(f"GoalSeeker on {res['episodes']} PointNav episodes: SR {overall['sr']:.2f}, SPL {overall['spl']:.2f}")
    return res


if __name__ == "__main__":
    main()
