"""Agents: an in-process interface and the baselines, chosen by registry key or "module:Class".

    class MyAgent:
        def reset(self, task: dict) -> None: ...     # task: episode_id, task_type, goal spec
        def act(self, obs: dict):  ...               # an action of navcore.eval.env

Privileged baselines (the oracles) also define bind(env), which the in-process evaluator calls
after each reset: they read the episode's geodesic field, never the rendered frames.
"""
from __future__ import annotations

import math

import numpy as np

from navcore.nav.actions import MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT
from navcore.nav.oracle import DiscreteOracle
from navcore.registry import Registry
from navcore.seeds import stream_seed

AGENTS = Registry("agent", {
    "random": "navcore.eval.agents:RandomAgent",
    "oracle": "navcore.eval.agents:OracleAgent",
    "noisy_oracle": "navcore.eval.agents:NoisyOracleAgent",
    "depth_reactive": "navcore.eval.agents:DepthReactiveAgent",
    # the learned baselines, trained on NavArena's own episodes (navcore/models/<name>/model_card.md)
    "pointnav_bc": "navcore.baselines.agent:pointnav_bc",
    "imagenav_bc": "navcore.baselines.agent:imagenav_bc",
    "objectnav_bc": "navcore.baselines.agent:objectnav_bc",
    # any navarena train run's policy: --agent learned --agent-arg checkpoint=runs/x/model.pt
    "learned": "navcore.baselines.agent:LearnedNavAgent",
})
make_agent = AGENTS.make


def agent_for(spec: str, seed: int = 0, timeout: float = 60.0, batch: bool = False, **kwargs):
    """An agent from a registry name, 'package.module:Class' or a ws:// agent server (a
    RemoteBatchAgent with batch=True). A registry agent gets the seed unless kwargs name one;
    kwargs go to the agent's constructor (or to the remote client)."""
    if spec.startswith(("ws://", "wss://")):
        from navcore.eval.protocol.client import RemoteAgent, RemoteBatchAgent

        return (RemoteBatchAgent if batch else RemoteAgent)(spec, timeout=timeout, **kwargs)
    if spec in AGENTS:
        kwargs.setdefault("seed", seed)
    return make_agent(spec, **kwargs)


class RandomAgent:
    """Uniform over forward / left / right; never stops. Seeded per episode: each episode's moves
    depend on the seed and its episode id only, not on which batch slot or process ran it, so
    --batch-slots and the number of processes leave the figures as they are."""

    def __init__(self, seed: int = 0):
        self.seed = int(seed)
        self.rng = np.random.default_rng(stream_seed(self.seed, "", "random"))

    def reset(self, task: dict) -> None:
        self.rng = np.random.default_rng(stream_seed(self.seed, str(task.get("episode_id", "")), "random"))

    def act(self, obs: dict):
        return int(self.rng.choice([MOVE_FORWARD, TURN_LEFT, TURN_RIGHT]))


class OracleAgent:
    """Follows the costmap geodesic with the discrete actions (stages.episodes.rollout.DiscreteOracle);
    stops inside the success region (ImageNav: after turning to the goal heading)."""

    def __init__(self, **_):
        self.env = None

    def reset(self, task: dict) -> None:
        pass

    def bind(self, env) -> None:
        self.env = env
        ep = env.state.ep
        self.oracle = DiscreteOracle(env.ctx.field(ep).grid, env.ctx.costmap, ep.regions, ep.success_radius,
                                     ep.goal_yaw, ep.heading_tolerance, env.cfg.actions.forward_step, env.turn)

    def act(self, obs: dict):
        s = self.env.state
        a = self.oracle.action(s.x, s.y, s.yaw)
        return STOP if a < 0 else a


class NoisyOracleAgent(OracleAgent):
    """The oracle, but each step a uniformly random move with probability `noise` (seeded)."""

    def __init__(self, noise: float = 0.2, seed: int = 0, **_):
        super().__init__()
        self.noise, self.rng = noise, np.random.default_rng(seed)

    def act(self, obs: dict):
        if self.rng.random() < self.noise:
            return int(self.rng.choice([MOVE_FORWARD, TURN_LEFT, TURN_RIGHT]))
        return super().act(obs)


class DepthReactiveAgent:
    """Navigation from its own sensors only. PointNav (the observation has a goal vector): turns
    towards the goal, moves forward when the central band of the depth image is clear, otherwise
    turns to the side with more free space; stops within `stop_radius` of the goal.
    Tracks without a point goal (ImageNav, ObjectNav): the same obstacle avoidance with no goal to
    turn to, so it explores (forward while clear, else towards the freer side) and never stops; it
    reaches a goal only by driving into its success region (the distance protocol), the reactive
    reference a learned policy of those tracks has to beat."""

    def __init__(self, clearance: float = 0.45, stop_radius: float = 0.3, **_):
        self.clearance, self.stop_radius = clearance, stop_radius

    def reset(self, task: dict) -> None:
        self.last_turn = TURN_LEFT
        self.turns = 0

    def act(self, obs: dict):
        depth = obs.get("depth")
        if "pointgoal" not in obs:
            return self.explore(depth)
        rho, phi = (float(v) for v in obs["pointgoal"])
        if rho <= self.stop_radius:
            return STOP
        if abs(phi) > math.radians(15):
            return TURN_LEFT if phi > 0 else TURN_RIGHT
        if depth is None:
            return MOVE_FORWARD
        clear, freer = self.look(depth)
        if clear:
            return MOVE_FORWARD
        self.last_turn = freer
        return self.last_turn

    def look(self, depth) -> tuple[bool, int]:
        """(is the centre of the depth image's middle band clear beyond `clearance`, the turn towards
        the side with more free space)."""
        h, w = depth.shape
        band = depth[h // 3: 2 * h // 3]
        d = np.where(band > 0, band, np.inf)  # 0 = nothing hit: open
        # "lower": no interpolation, so a centre where nothing was hit reads inf (open), not inf - inf = nan
        clear = np.percentile(d[:, w // 3: 2 * w // 3], 5, method="lower") > self.clearance
        return clear, TURN_LEFT if np.median(d[:, : w // 3]) >= np.median(d[:, 2 * w // 3:]) else TURN_RIGHT

    def explore(self, depth):
        """No goal to turn to: forward while the centre is clear; when blocked, keep turning the way
        it began (a dead end is left by a full turn, not by alternating sides) until it is clear."""
        if depth is None:
            return MOVE_FORWARD
        clear, freer = self.look(depth)
        if clear:
            self.turns = 0
            return MOVE_FORWARD
        if self.turns == 0:
            self.last_turn = freer
        self.turns += 1
        return self.last_turn
