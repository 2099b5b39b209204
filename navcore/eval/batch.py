"""Many episodes of one scene stepped together: one render call per step for all of them."""
from __future__ import annotations

import dataclasses

import numpy as np

from navcore.eval.env import EnvConfig, NavEnv


class BatchNavEnv:
    """N episode slots of one SceneContext; step(actions) moves every running slot, then renders
    all of them in one call (the GPU's batch). Finished slots keep their last observation until
    reset_slots() gives them new episodes."""

    def __init__(self, ctx, n: int, cfg: EnvConfig | None = None, device_obs: bool = False):
        cfg = cfg or EnvConfig()
        self.device_obs = device_obs  # rgb / depth stay torch tensors on the renderer's device
        self.ctx, self.cfg = ctx, cfg
        logic = dataclasses.replace(cfg, render=False)  # the slots never render alone
        self.envs = [NavEnv(ctx, logic) for _ in range(n)]
        self.render_enabled = cfg.render and ctx.renderer is not None
        self.w, self.h = self.envs[0].w, self.envs[0].h
        self._obs: list[dict | None] = [None] * n
        self.errors: dict[int, str] = {}
        """Slots whose last action the environment rejected (the reason); the slot's episode failed."""

    def reset(self, episodes) -> list[dict]:
        for i, ep in enumerate(episodes):
            self.envs[i].reset(ep)
        self._goal_images(range(len(episodes)))
        return self._observe(range(len(episodes)))

    def reset_slots(self, episodes: dict) -> dict:
        """New episodes in several slots ({slot: episode}), their first views in one render call."""
        for i, ep in episodes.items():
            self.envs[i].reset(ep)
        self._goal_images(list(episodes))
        return dict(zip(episodes, self._observe(list(episodes))))

    def step(self, actions, infos: bool = True) -> tuple[list[dict], list[dict] | None]:
        """actions: one per slot (None for a finished slot) -> (observations, infos), one per slot;
        infos=False skips the infos (None; each holds a geodesic lookup) for callers that read the
        episodes' state instead, as the evaluation loop and the trainers' collection do."""
        live = []
        for i, (env, a) in enumerate(zip(self.envs, actions)):
            if a is None or env.state is None or env.state.done:
                continue
            env.apply(a)  # a malformed action spends its step and is recorded (NavEnv.apply)
            live.append(i)
        self._observe(live)
        return list(self._obs), [e.info() if e.state else {} for e in self.envs] if infos else None

    def _goal_images(self, slots) -> None:
        if not self.render_enabled:
            return
        want = [i for i in slots if self.envs[i].state.ep.task == "imagenav"]
        if not want:
            return
        poses = np.stack([self.envs[i].state.ep.shown_goal.goal_pose for i in want])
        rgb, _ = self.ctx.render(poses, self.w, self.h, self.device_obs)
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
