"""In-process evaluation loop: episodes x agent -> per-episode metrics and executed trajectories."""
from __future__ import annotations

import time

import numpy as np

from navcore.eval.agents import agent_for
from navcore.eval.env import EnvConfig, NavEnv
from navcore.eval.metrics import episode_metrics


def task_info(ep) -> dict:
    """What an agent learns about an episode at reset (no privileged geometry)."""
    info = {"episode_id": ep.episode_id, "task_type": ep.task, "max_steps": ep.max_steps,
            "success_radius": ep.success_radius}
    if ep.task == "objectnav":
        info["goal_category"] = ep.shown_goal.category  # another episode's in the decoy check
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
        env.state.fail()
    s = env.state
    if hasattr(agent, "end"):  # remote agents: episode_end frame
        agent.end({"episode_id": ep.episode_id, "success": bool(s.success), "steps": s.steps,
                   "end_reason": s.end_reason})
    return result_row(env, ep, d0, error, time.perf_counter() - t0)


def result_row(env: NavEnv, ep, d0: float, error: str, seconds: float) -> dict:
    """The per-episode record of a finished episode: metrics, end reason, executed trajectory."""
    s = env.state
    return {"episode_id": ep.episode_id, "task": ep.task, "scene_id": ep.scene_id, "difficulty": ep.difficulty,
            "protocol": env.cfg.protocol, "end_reason": s.end_reason, "error": error,
            "invalid_actions": s.invalid_actions, "action_error": s.action_error,
            **episode_metrics(s, d0, env.geodesic_to_goal(), env.cfg.protocol),
            "geodesic": ep.geodesic, "path_length": s.path_length, "seconds": seconds,
            **({"shown_goal_of": ep.shown.episode_id} if ep.shown is not None else {}),
            "trajectory": np.asarray(s.positions, np.float32)}


def run_episodes(ctx, episodes, agent, cfg: EnvConfig | None = None) -> list[dict]:
    env = NavEnv(ctx, cfg)
    return [run_episode(env, agent, ep) for ep in episodes]


class InProcessBatch:
    """In-process agents behind the batch interface of run_episodes_batched: one agent per slot
    (privileged ones are bound to their slot's environment)."""

    def __init__(self, factory):
        self.factory, self.agents, self.benv = factory, {}, None
        self._spare = factory()  # the first slot's agent, made now to learn what frames the agents read
        self.device_frames = bool(getattr(self._spare, "reads_device_frames", False))
        """The agents read rgb / depth / goal_image as torch tensors on the renderer's device (a learned
        policy on the GPU): the batch environment hands its frames over without copying them to the host."""

    def start(self, tasks: dict) -> None:
        for slot, task in tasks.items():
            self.agents[slot] = self._spare if self._spare is not None else self.factory()
            self._spare = None
            self.agents[slot].reset(task)
            if hasattr(self.agents[slot], "bind") and self.benv is not None:
                self.agents[slot].bind(self.benv.envs[slot])

    def act(self, observations: dict) -> dict:
        slots = list(observations)
        kinds = {type(self.agents[s]) for s in slots}
        batch = getattr(next(iter(kinds)), "act_batch", None) if len(kinds) == 1 else None
        if batch is not None:  # a learned policy: every slot in one forward pass
            return dict(zip(slots, batch([self.agents[s] for s in slots], [observations[s] for s in slots])))
        return {slot: self.agents[slot].act(o) for slot, o in observations.items()}

    def end(self, results: dict) -> None:
        pass


def run_episodes_batched(ctx, episodes, client, slots: int, cfg: EnvConfig | None = None,
                         max_connect_failures: int = 2, on_result=None) -> list[dict]:
    """Episodes through a batch agent (`client`: start(tasks by slot), act(observations by slot) ->
    actions by slot, end(results by slot); e.g. protocol.RemoteBatchAgent), `slots` at a time,
    one render call per step (BatchNavEnv).

    Every episode gets a result row. A client failure fails the episodes in flight, and the queue
    goes on (a RemoteBatchAgent reconnects); after `max_connect_failures` consecutive failures to
    reach the server at all, the rest of the queue fails with that reason instead of waiting for
    each. An action the environment rejects (NaN, malformed) counts as an invalid step of its own
    slot's episode (recorded in `invalid_actions`), which goes on. `on_result(row)` is called as each
    episode finishes."""
    from navcore.eval.batch import BatchNavEnv

    benv = BatchNavEnv(ctx, slots, cfg, device_obs=getattr(client, "device_frames", False))
    if isinstance(client, InProcessBatch):
        client.benv = benv
    queue = list(episodes)
    running: dict[int, tuple] = {}
    rows = []
    obs = {}
    unreachable = 0

    def finish(i, error=""):
        ep, d0, t0 = running.pop(i)
        env = benv.envs[i]
        if error:
            env.state.fail()
        rows.append(result_row(env, ep, d0, error, time.perf_counter() - t0))
        if on_result is not None:
            on_result(rows[-1])
        s = env.state
        return {"episode_id": ep.episode_id, "success": bool(s.success), "steps": s.steps, "end_reason": s.end_reason}

    def fail_all(e):
        nonlocal unreachable
        unreachable = unreachable + 1 if isinstance(e, ConnectionError) else 0
        for i in list(running):
            finish(i, f"{type(e).__name__}: {e}")
        if hasattr(client, "close"):
            client.close()  # the next start reconnects: no stray frame of these episodes is read

    def start(free):
        eps = {i: queue.pop(0) for i in free[:len(queue)]}
        if not eps:
            return
        obs.update(benv.reset_slots(eps))  # the new episodes' first views in one render call
        t0 = time.perf_counter()
        for i, ep in eps.items():
            running[i] = (ep, benv.envs[i].geodesic_to_goal(), t0)
        client.start({i: task_info(ep) for i, ep in eps.items()})

    while queue or running:
        if unreachable >= max_connect_failures:
            while queue:  # the server is gone: record the rest without waiting for each
                ep = queue.pop(0)
                benv.envs[0].reset(ep)
                running[0] = (ep, benv.envs[0].geodesic_to_goal(), time.perf_counter())
                finish(0, "ConnectionError: agent server unreachable (earlier episodes of this scene could not connect)")
            break
        try:
            start([i for i in range(slots) if i not in running])
            actions = client.act({i: obs[i] for i in running})
            acts = [actions.get(i) if i in running else None for i in range(slots)]
            missing = [i for i in running if acts[i] is None]
            if missing:
                raise RuntimeError(f"batch_action has no action for slot(s) {missing}")
        except Exception as e:  # noqa: BLE001 - the client failed: the episodes in flight fail
            fail_all(e)
            continue
        unreachable = 0
        out, _ = benv.step(acts)
        for i in running:
            obs[i] = out[i]
        done = [i for i in list(running) if benv.envs[i].state.done]
        if done:
            ended = {i: finish(i, benv.errors.pop(i, "")) for i in done}
            try:
                client.end(ended)
            except Exception as e:  # noqa: BLE001
                fail_all(e)
    order = {(ep.task, ep.episode_id): k for k, ep in enumerate(episodes)}
    rows.sort(key=lambda r: order.get((r["task"], r["episode_id"]), 0))
    return rows


class AgentUnreachable(ConnectionError):
    """An agent server that could not be reached for several episodes in a row: the evaluation
    stops (what finished is kept) instead of waiting out every remaining episode."""


def _unreachable(row: dict) -> bool:
    return row["error"].startswith("ConnectionError")


def evaluate_episodes(ctx, episodes, agent: str, cfg: EnvConfig, *, seed: int = 0, timeout: float = 60.0,
                      agent_args: dict | None = None, batch_slots: int = 1, videos: int = 0, on_result=None,
                      max_connect_failures: int = 3) -> list[dict]:
    """The evaluate verb: one agent on one scene's episodes, the loop both `navarena eval` and the
    pipeline's `evaluate` stage run. Picks the agent's form (an agent server over the protocol,
    batched or one episode at a time; in-process agents, one per slot when batched), drives the
    episodes, and closes the agent, whatever happened.

    Args:
        ctx: the scene's SceneContext (SceneContext.from_catalog, NavDataset.scene_context).
        episodes: the Episodes to run, in order.
        agent: a registry name, "package.module:Class" or ws://host:port (navcore.eval.agents.agent_for).
        cfg: the environment's config (protocol, render size, step sizes).
        seed: the seed of stochastic agents (per scene: the caller derives it).
        timeout: seconds an agent server may take for an action.
        agent_args: keyword arguments of the agent's constructor (or of the remote client).
        batch_slots: episodes stepped together (> 1: one render call a step, no frames recorded).
        videos: with batch_slots 1, the first `videos` episodes' egocentric RGB frames are passed to on_result.
        on_result: called as each episode finishes, on_result(row, frames) (frames: a list of
            HxWx3 uint8, or None when not recorded).
        max_connect_failures: an agent server that cannot be reached for this many episodes in a row
            stops the evaluation (AgentUnreachable, naming its address).

    Returns:
        The episodes' result rows (navcore.eval.loop.result_row), in the order of `episodes`.
    Raises:
        AgentUnreachable: the agent server could not be reached; the rows reported so far stand.
    """
    kwargs = dict(agent_args or {})
    report = on_result or (lambda row, frames: None)
    remote = agent.startswith(("ws://", "wss://"))
    client = None
    try:
        if batch_slots > 1:
            client = agent_for(agent, seed, timeout, batch=True, **kwargs) if remote else \
                InProcessBatch(lambda: agent_for(agent, seed, timeout, **kwargs))
            rows = run_episodes_batched(ctx, episodes, client, batch_slots, cfg, max_connect_failures,
                                        on_result=lambda row: report(row, None))
            if remote and len(rows) >= max_connect_failures and all(_unreachable(r) for r in rows[-max_connect_failures:]):
                raise AgentUnreachable(f"agent server {agent} unreachable for {max_connect_failures} episodes in a row")
            return rows
        env, client, rows = NavEnv(ctx, cfg), agent_for(agent, seed, timeout, **kwargs), []
        failed = 0
        for k, ep in enumerate(episodes):
            frames = [] if cfg.render and k < videos else None
            rows.append(run_episode(env, client, ep, frames))
            report(rows[-1], frames)
            failed = failed + 1 if remote and _unreachable(rows[-1]) else 0
            if failed >= max_connect_failures:
                raise AgentUnreachable(f"agent server {agent} unreachable for {failed} episodes in a row "
                                       f"({rows[-1]['error']})")
        return rows
    finally:
        if client is not None and hasattr(client, "close"):
            client.close()
