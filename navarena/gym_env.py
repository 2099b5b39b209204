"""A gymnasium.Env over a list of episodes of one scene, for training code."""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from navcore.eval.env import EnvConfig, NavEnv


class NavGymEnv(gym.Env):
    """Episodes taken in turn at each reset (a seeded reset draws one from the seed), discrete
    actions.

    Reward (Habitat's PointNav shaping): geodesic progress towards the goal + slack per step +
    success_reward on success. terminated = success or STOP (explicit protocol); truncated = budget.
    """

    metadata = {"render_modes": []}

    def __init__(self, ctx, episodes, cfg: EnvConfig | None = None, success_reward: float = 2.5,
                 slack: float = -0.01):
        self.env = NavEnv(ctx, cfg)
        self.episodes, self.k = list(episodes), 0
        self.success_reward, self.slack = success_reward, slack
        h, w = self.env.h, self.env.w
        self.action_space = spaces.Discrete(4)
        obs = {"pose": spaces.Box(-np.inf, np.inf, (3,), np.float32),
               "pointgoal": spaces.Box(np.array([0, -math.pi], np.float32), np.array([np.inf, math.pi], np.float32)),
               "pointgoal_xy": spaces.Box(-np.inf, np.inf, (2,), np.float32)}
        if self.env.cfg.render and ctx.renderer is not None:
            obs["rgb"] = spaces.Box(0, 255, (h, w, 3), np.uint8)
            obs["depth"] = spaces.Box(0, np.inf, (h, w), np.float32)
        self.observation_space = spaces.Dict(obs)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if seed is not None:  # a seeded reset picks its episode from the seed (reproducible)
            self.k = int(self.np_random.integers(len(self.episodes)))
        ep = (options or {}).get("episode") or self.episodes[self.k % len(self.episodes)]
        self.k += 1
        obs = self.env.reset(ep)
        self._d = self.env.geodesic_to_goal()
        return self._pointgoal(obs), {"episode_id": ep.episode_id}

    def step(self, action):
        obs, info = self.env.step(int(action))
        d = self.env.geodesic_to_goal()
        reward = (self._d - d if math.isfinite(d) and math.isfinite(self._d) else 0.0) + self.slack
        self._d = d
        if info["success"]:
            reward += self.success_reward
        truncated = info["end_reason"] == "budget"
        terminated = info["done"] and not truncated
        return self._pointgoal(obs), float(reward), terminated, truncated, info

    def _pointgoal(self, obs):
        obs = dict(obs)
        obs.setdefault("pointgoal", np.zeros(2, np.float32))
        obs.setdefault("pointgoal_xy", np.zeros(2, np.float32))
        return {k: v for k, v in obs.items() if k in self.observation_space.spaces}
