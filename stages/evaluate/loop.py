"""In-process evaluation loop: episodes x agent -> per-episode metrics and executed trajectories."""
from __future__ import annotations

import time
import traceback

import numpy as np

from stages.evaluate.env import EnvConfig, NavEnv
from stages.evaluate.metrics import episode_metrics


def task_info(ep) -> dict:
    """What an agent learns about an episode at reset (no privileged geometry)."""
    info = {"episode_id": ep.episode_id, "task_type": ep.task, "max_steps": ep.max_steps,
            "success_radius": ep.success_radius}
    if ep.task == "objectnav":
        info["goal_category"] = ep.category
    return info


def run_episode(env: NavEnv, agent, ep, frames: list | None = None) -> dict:
    """One episode; an agent that raises fails the episode with the reason recorded. `frames`, when
    given, collects the egocentric RGB of every step."""
    t0 = time.perf_counter()
    obs = env.reset(ep)
    if frames is not None and "rgb" in obs:
        frames.append(obs["rgb"])
    d0 = env.geodesic_to_goal()
    error = ""
    try:
        agent.reset(task_info(ep))
        if hasattr(agent, "bind"):
            agent.bind(env)
        while not env.state.done:
            obs, _ = env.step(agent.act(obs))
            if frames is not None and "rgb" in obs:
                frames.append(obs["rgb"])
    except Exception as e:  # noqa: BLE001 - the run goes on; the episode fails
        error = f"{type(e).__name__}: {e}"
        env.state.done, env.state.success, env.state.end_reason = True, False, "agent_error"
        env.state.extra_trace = traceback.format_exc(limit=4)
    s = env.state
    if hasattr(agent, "end"):  # remote agents: episode_end frame
        agent.end({"episode_id": ep.episode_id, "success": bool(s.success), "steps": s.steps,
                   "end_reason": s.end_reason})
    row = {"episode_id": ep.episode_id, "task": ep.task, "scene_id": ep.scene_id, "difficulty": ep.difficulty,
           "protocol": env.cfg.protocol, "end_reason": s.end_reason, "error": error,
           **episode_metrics(s, d0, env.geodesic_to_goal(), env.cfg.protocol),
           "geodesic": ep.geodesic, "path_length": s.path_length, "seconds": time.perf_counter() - t0,
           "trajectory": np.asarray(s.positions, np.float32)}
    return row


def run_episodes(ctx, episodes, agent, cfg: EnvConfig | None = None) -> list[dict]:
    env = NavEnv(ctx, cfg)
    return [run_episode(env, agent, ep) for ep in episodes]
