"""Many episodes of one scene stepped together: one render call per step for all of them, and a
gymnasium wrapper for training code."""
from __future__ import annotations

import math

import numpy as np

from stages.evaluate.env import EnvConfig, NavEnv


class BatchNavEnv:
    """N episode slots of one SceneContext; step(actions) moves every running slot, then renders
    all of them in one call (the GPU's batch). Finished slots keep their last observation until
    reset_slot() gives them a new episode."""

    def __init__(self, ctx, n: int, cfg: EnvConfig | None = None, device_obs: bool = False):
        cfg = cfg or EnvConfig()
        self.device_obs = device_obs  # rgb / depth stay torch tensors on the renderer's device
        self.ctx, self.cfg = ctx, cfg
        logic = EnvConfig(**{**vars(cfg), "render": False})  # the slots never render alone
        self.envs = [NavEnv(ctx, logic) for _ in range(n)]
        self.render_enabled = cfg.render and ctx.renderer is not None
        self.w, self.h = self.envs[0].w, self.envs[0].h
        self._obs: list[dict | None] = [None] * n

    def reset(self, episodes) -> list[dict]:
        for i, ep in enumerate(episodes):
            self.envs[i].reset(ep)
        self._goal_images(range(len(episodes)))
        return self._observe(range(len(episodes)))

    def reset_slot(self, i: int, ep) -> dict:
        self.envs[i].reset(ep)
        self._goal_images([i])
        return self._observe([i])[0]

    def step(self, actions) -> tuple[list[dict], list[dict]]:
        """actions: one per slot (None for a finished slot)."""
        live = []
        for i, (env, a) in enumerate(zip(self.envs, actions)):
            if a is None or env.state is None or env.state.done:
                continue
            env.apply(a)
            live.append(i)
        self._observe(live)
        return list(self._obs), [e.info() if e.state else {} for e in self.envs]

    def _goal_images(self, slots) -> None:
        if not self.render_enabled:
            return
        want = [i for i in slots if self.envs[i].state.ep.task == "imagenav"]
        if not want:
            return
        poses = np.stack([self.envs[i].state.ep.goal_pose for i in want])
        rgb, _ = self.ctx.render(poses, self.w, self.h)
        for k, i in enumerate(want):
            self.envs[i]._goal_image = rgb[k]

    def _observe(self, slots) -> list[dict]:
        slots = list(slots)
        obs = [{"pose": self.envs[i].state.pose, **self.envs[i].goal_observation()} for i in slots]
        if self.render_enabled and slots:
            poses = np.stack([self.envs[i].state.pose for i in slots]).astype(np.float64)
            rgb, depth = self.ctx.render(poses, self.w, self.h, self.device_obs)
            for k, o in enumerate(obs):
                o["rgb"], o["depth"] = rgb[k], depth[k]
        for i, o in zip(slots, obs):
            self._obs[i] = o
        return obs


def gym_env(ctx, episodes, cfg: EnvConfig | None = None, success_reward: float = 2.5, slack: float = -0.01):
    """A gymnasium.Env over a list of episodes (taken in turn at each reset; a seeded reset draws
    one from the seed), discrete actions.

    Reward (Habitat's PointNav shaping): geodesic progress towards the goal + slack per step +
    success_reward on success. terminated = success or STOP (explicit protocol); truncated = budget.
    """
    import gymnasium as gym
    from gymnasium import spaces

    class NavGymEnv(gym.Env):
        metadata = {"render_modes": []}

        def __init__(self):
            self.env = NavEnv(ctx, cfg)
            self.episodes, self.k = list(episodes), 0
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
            reward = (self._d - d if math.isfinite(d) and math.isfinite(self._d) else 0.0) + slack
            self._d = d
            if info["success"]:
                reward += success_reward
            truncated = info["end_reason"] == "budget"
            terminated = info["done"] and not truncated
            return self._pointgoal(obs), float(reward), terminated, truncated, info

        def _pointgoal(self, obs):
            obs = dict(obs)
            obs.setdefault("pointgoal", np.zeros(2, np.float32))
            obs.setdefault("pointgoal_xy", np.zeros(2, np.float32))
            return {k: v for k, v in obs.items() if k in self.observation_space.spaces}

    return NavGymEnv()
