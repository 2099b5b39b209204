"""What the blocked-move rule does to policies that drive and steer (issue 39).

On a data root's stored episodes (no rendering), two policies run under the rule before this change
(a blocked step dropped its turn with its translation; re-implemented here as the reference) and
under each of `evaluate.dynamics.blocked` = stay, truncate, slide:
- server_example: the action statistics of NavArena-Server's forward-and-steer ImageNav example
  (measured by hand against their code: every step a waypoint forward by a uniform 0-0.1 m and a
  fresh, zero-mean uniform turn of at most 0.1 rad); a stand-in with their statistics, not their
  code, which is not in this repository;
- forward_steer: our own stand-in from before (0.25 m forward, a heading change that drifts as a
  random walk in [-0.3, 0.3] rad): bolder than their example, kept as a second, named policy;
- random: the discrete random agent (forward / left / right).
Reports per rule: collision rate (per policy action), metres walked, SR, episodes.

    python -m benchmarks.closed_loop.dynamics --root data [--tasks pointnav,imagenav] [--episodes 40]
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from navcore.io import jsonio


class ServerExample:
    """NavArena-Server's ImageNav example's action statistics: forward U(0, 0.1) m, turn U(-0.1, 0.1) rad, fresh every step (seeded)."""

    def __init__(self, seed: int = 0):
        self.rng = np.random.default_rng(seed)

    def reset(self, task: dict) -> None:
        pass

    def act(self, obs: dict):
        return {"x": float(self.rng.uniform(0.0, 0.1)), "y": 0.0, "yaw": float(self.rng.uniform(-0.1, 0.1))}


class ForwardSteer:
    """0.25 m forward and a drifting heading change every step (seeded)."""

    def __init__(self, seed: int = 0):
        self.rng = np.random.default_rng(seed)
        self.w = 0.0

    def reset(self, task: dict) -> None:
        self.w = 0.0

    def act(self, obs: dict):
        self.w = float(np.clip(self.w + self.rng.normal(0.0, 0.1), -0.3, 0.3))
        return {"x": 0.25, "yaw": self.w}


def old_rule_env(ctx, cfg):
    """The environment with the rule before issue 39: a blocked translation left the pose and the
    step's heading change unchanged."""
    from navcore.eval.env import NavEnv
    from navcore.nav.poses import wrap_angle

    class OldRule(NavEnv):
        def _move(self, dx, dy, dyaw):
            s = self.state
            if dx or dy:
                c, sn = math.cos(s.yaw), math.sin(s.yaw)
                nx, ny = s.x + c * dx - sn * dy, s.y + sn * dx + c * dy
                s.moves += 1
                if not self.ctx.costmap.is_motion_valid(s.x, s.y, nx, ny):
                    s.collisions += 1
                    return
                s.path_length += math.hypot(nx - s.x, ny - s.y)
                s.x, s.y = nx, ny
                s.positions.append((nx, ny))
            s.yaw = float(wrap_angle(s.yaw + dyaw))

    return OldRule(ctx, cfg)


def run(root: Path, tasks: list[str], episodes: int) -> dict:
    from navcore.eval.agents import RandomAgent
    from navcore.eval.env import DynamicsConfig, EnvConfig, NavEnv, SceneContext
    from navcore.eval.episode import Episode
    from navcore.eval.loop import run_episode
    from navcore.io.catalog import Catalog
    from navcore.nav.embodiment import load_embodiment
    from navcore.nav.geodesic import NavGraph

    cat = Catalog.for_root(root)
    emb = load_embodiment("locobot")
    rules = ["before", "stay", "truncate", "slide"]
    agents = {"server_example": ServerExample, "forward_steer": ForwardSteer, "random": RandomAgent}
    acc = {(a, r): {"episodes": 0, "collisions": 0.0, "walked": 0.0, "sr": 0.0} for a in agents for r in rules}
    for sid in cat.scene_ids("episodes"):
        cm = cat.dataset("costmaps", cat.scene(sid)).load(emb.name)
        ctx = SceneContext(cm, NavGraph(cm, ~cm.occupancy), emb)
        for task in tasks:
            ds = cat.dataset("episodes", cat.scene(sid), task=task)
            if not ds.exists():
                continue
            rows = ds.load().to_pandas().head(episodes).to_dict("records")
            eps = [Episode.from_row({**r, "scene_id": sid}) for r in rows]
            for a, cls in agents.items():
                for rule in rules:
                    cfg = EnvConfig(render=False, dynamics=DynamicsConfig(blocked=rule if rule != "before" else "stay"))
                    env = old_rule_env(ctx, cfg) if rule == "before" else NavEnv(ctx, cfg)
                    for k, ep in enumerate(eps):
                        r = run_episode(env, cls(seed=k), ep)
                        m = acc[(a, rule)]
                        m["episodes"] += 1
                        m["collisions"] += r["collision_rate"]
                        m["walked"] += r["path_length"]
                        m["sr"] += r["sr"]
    out = {}
    for (a, rule), m in acc.items():
        n = max(m["episodes"], 1)
        out.setdefault(a, {})[rule] = {"episodes": m["episodes"], "collision_rate": m["collisions"] / n,
                                       "metres_walked": m["walked"] / n, "sr": m["sr"] / n}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default="data")
    ap.add_argument("--tasks", default="pointnav,imagenav")
    ap.add_argument("--episodes", type=int, default=40, help="per scene and task")
    ap.add_argument("--out", default="data/08_reports")
    args = ap.parse_args(argv)
    from benchmarks import machine

    rep = {"machine": machine(), "root": args.root, "results": run(Path(args.root), args.tasks.split(","), args.episodes)}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_dynamics.json").write_text(jsonio.dumps(rep, indent=1))
    for a, by in rep["results"].items():
        for rule, m in by.items():
            print(f"{a:14s} {rule:9s} episodes {m['episodes']:4d}  collision rate {m['collision_rate']:.2f}  "
                  f"walked {m['metres_walked']:.1f} m  SR {m['sr']:.2f}")
    return rep


if __name__ == "__main__":
    main()
