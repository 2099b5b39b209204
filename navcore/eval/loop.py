"""In-process evaluation loop: episodes x agent -> per-episode metrics and executed trajectories."""
from __future__ import annotations

import dataclasses
import itertools
import time
from typing import Any, Callable

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
    """In-process agents behind the batch interface of run_scenes_batched: one agent per slot
    (privileged ones are bound to their slot's environment).

    Args:
        factory: makes one agent: factory(), or factory(seed) with `seeded` (the scene's seed of a
            run over several scenes: each scene's agents as evaluate_episodes would make them alone).
        seeded: the factory takes the scene's seed.
        seed: the seed of the agent made first, to learn what frames the agents read (kept for the
            first slot of a scene with that seed)."""

    def __init__(self, factory, seeded: bool = False, seed: int = 0):
        self.factory, self.seeded, self.agents = factory, seeded, {}
        self._spare, self._spare_seed = self._make(seed), seed
        self.device_frames = bool(getattr(self._spare, "reads_device_frames", False))
        """The agents read rgb / depth / goal_image as torch tensors on the renderer's device (a learned
        policy on the GPU): the batch environment hands its frames over without copying them to the host."""

    def _make(self, seed: int):
        return self.factory(seed) if self.seeded else self.factory()

    def start(self, tasks: dict, envs: dict | None = None, seed: int = 0) -> None:
        """New episodes in these slots ({slot: task}); `envs` ({slot: NavEnv}) for agents that bind to
        theirs; `seed`: the scene's (a seeded factory's)."""
        for slot, task in tasks.items():
            spare = self._spare is not None and (not self.seeded or seed == self._spare_seed)
            self.agents[slot] = self._spare if spare else self._make(seed)
            self._spare = None if spare else self._spare
            self.agents[slot].reset(task)
            if hasattr(self.agents[slot], "bind") and envs is not None:
                self.agents[slot].bind(envs[slot])

    def act(self, observations: dict) -> dict:
        slots = list(observations)
        kinds = {type(self.agents[s]) for s in slots}
        batch = getattr(next(iter(kinds)), "act_batch", None) if len(kinds) == 1 else None
        if batch is not None:  # a learned policy: every slot in one forward pass
            return dict(zip(slots, batch([self.agents[s] for s in slots], [observations[s] for s in slots])))
        return {slot: self.agents[slot].act(o) for slot, o in observations.items()}

    def end(self, results: dict) -> None:
        pass


@dataclasses.dataclass
class SceneEpisodes:
    """One scene's share of a batched run (run_scenes_batched)."""

    episodes: list
    context: Callable[[], Any]
    """Makes the scene's SceneContext; called when the scene joins the run (its Gaussians loaded then,
    released when its last episode ends)."""
    seed: int = 0
    """The seed of the scene's in-process agents (InProcessBatch with a seeded factory)."""


def run_episodes_batched(ctx, episodes, client, slots: int, cfg: EnvConfig | None = None,
                         max_connect_failures: int = 2, on_result=None) -> list[dict]:
    """One scene's episodes through a batch agent, `slots` at a time (run_scenes_batched with one scene)."""
    return run_scenes_batched([SceneEpisodes(list(episodes), lambda: ctx)], client, slots, cfg, max_connect_failures,
                              on_result)


class _LiveScene:
    """A scene of run_scenes_batched while its episodes run: its batch environment (one render call
    per step for its slots) and its episodes not started yet."""

    def __init__(self, scene: SceneEpisodes, slots: int, cfg, device_obs: bool):
        from navcore.eval.batch import BatchNavEnv

        self.scene, self.queue = scene, list(scene.episodes)
        self.benv = BatchNavEnv(scene.context(), slots, cfg, device_obs=device_obs)


def run_scenes_batched(scenes, client, slots: int, cfg: EnvConfig | None = None, max_connect_failures: int = 2,
                       on_result=None, scenes_at_once: int = 1) -> list[dict]:
    """Episodes of several scenes through a batch agent (`client`: start(tasks by slot), act(observations
    by slot) -> actions by slot, end(results by slot); e.g. protocol.RemoteBatchAgent or InProcessBatch),
    `slots` at a time, with up to `scenes_at_once` scenes in flight: each step, one act call for every
    running slot (a learned policy: one forward pass) and one render call per scene in flight
    (navcore.eval.batch.BatchNavEnv).

    `scenes` (SceneEpisodes, an iterable read as scenes join) join in order: the next one when every
    episode of those in flight has started and a slot is free, so that a scene's last, longest
    episodes run beside the next scene's first ones instead of leaving the slots idle. A scene's
    context is made when it joins and released when its last episode ends. Each episode gets an agent
    of its own, made with its scene's seed, so its result does not depend on the slot or on the scenes
    beside it (for a network batched on a GPU, up to the last bits of the batched arithmetic).

    Every episode gets a result row. A client failure fails the episodes in flight, and the queue
    goes on (a RemoteBatchAgent reconnects); after `max_connect_failures` consecutive failures to
    reach the server at all, the episodes of the scenes in flight fail with that reason instead of
    waiting for each, and no further scene joins. An action the environment rejects (NaN, malformed)
    counts as an invalid step of its own slot's episode (recorded in `invalid_actions`), which goes
    on. `on_result(row)` is called as each episode finishes. Returns the rows in the order of the
    scenes and their episodes."""
    device_obs = bool(getattr(client, "device_frames", False))
    in_process = isinstance(client, InProcessBatch)
    pending = iter(scenes)
    order: dict[tuple, int] = {}
    live: list[_LiveScene] = []
    free = list(range(slots))
    running: dict[int, tuple] = {}  # slot -> (episode, d0, t0, its scene)
    rows, obs = [], {}
    unreachable = 0
    more = True

    def admit():
        nonlocal more
        while more and len(live) < max(1, scenes_at_once) and len(free) > sum(len(s.queue) for s in live):
            scene = next(pending, None)
            if scene is None:
                more = False
            elif scene.episodes:
                for ep in scene.episodes:
                    order.setdefault((ep.task, ep.episode_id, ep.scene_id), len(order))
                live.append(_LiveScene(scene, slots, cfg, device_obs))

    def finish(i, error=""):
        ep, d0, t0, s = running.pop(i)
        env = s.benv.envs[i]
        if error:
            env.state.fail()
        rows.append(result_row(env, ep, d0, error, time.perf_counter() - t0))
        free.append(i)
        free.sort()
        if on_result is not None:
            on_result(rows[-1])
        st = env.state
        return {"episode_id": ep.episode_id, "success": bool(st.success), "steps": st.steps, "end_reason": st.end_reason}

    def slots_of(s):
        return [i for i, r in running.items() if r[3] is s]

    def retire():  # scenes with nothing left to run leave (their Gaussians with them), the next ones join
        live[:] = [s for s in live if s.queue or slots_of(s)]
        if unreachable < max_connect_failures:
            admit()

    def fail_all(e):
        nonlocal unreachable
        unreachable = unreachable + 1 if isinstance(e, ConnectionError) else 0
        for i in list(running):
            finish(i, f"{type(e).__name__}: {e}")
        if hasattr(client, "close"):
            client.close()  # the next start reconnects: no stray frame of these episodes is read
        retire()

    def start():
        for s in live:
            if not (s.queue and free):
                continue
            eps = {free.pop(0): s.queue.pop(0) for _ in range(min(len(free), len(s.queue)))}
            obs.update(s.benv.reset_slots(eps))  # the new episodes' first views in one render call
            t0 = time.perf_counter()
            for i, ep in eps.items():
                running[i] = (ep, s.benv.envs[i].geodesic_to_goal(), t0, s)
            tasks = {i: task_info(ep) for i, ep in eps.items()}
            if in_process:
                client.start(tasks, envs={i: s.benv.envs[i] for i in eps}, seed=s.scene.seed)
            else:
                client.start(tasks)

    admit()
    while live:
        if unreachable >= max_connect_failures:
            more = False  # the server is gone: the rest of the scenes in flight fail without waiting for each
            for s in live:
                while s.queue:
                    ep = s.queue.pop(0)
                    s.benv.envs[0].reset(ep)
                    running[0] = (ep, s.benv.envs[0].geodesic_to_goal(), time.perf_counter(), s)
                    finish(0, "ConnectionError: agent server unreachable (earlier episodes of this scene could not connect)")
            break
        try:
            start()
            actions = client.act({i: obs[i] for i in running})
            missing = [i for i in running if actions.get(i) is None]
            if missing:
                raise RuntimeError(f"batch_action has no action for slot(s) {missing}")
        except Exception as e:  # noqa: BLE001 - the client failed: the episodes in flight fail
            fail_all(e)
            continue
        unreachable = 0
        for s in live:
            mine = set(slots_of(s))
            if mine:
                out, _ = s.benv.step([actions[i] if i in mine else None for i in range(slots)], infos=False)
                for i in mine:
                    obs[i] = out[i]
        done = [i for i in list(running) if running[i][3].benv.envs[i].state.done]
        if done:
            ended = {i: finish(i, running[i][3].benv.errors.pop(i, "")) for i in done}
            try:
                client.end(ended)
            except Exception as e:  # noqa: BLE001
                fail_all(e)
            retire()
    rows.sort(key=lambda r: order.get((r["task"], r["episode_id"], r["scene_id"]), 0))
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
    if batch_slots > 1:
        return evaluate_scenes([SceneEpisodes(list(episodes), lambda: ctx, seed)], agent, cfg, timeout=timeout,
                               agent_args=agent_args, batch_slots=batch_slots, on_result=on_result,
                               max_connect_failures=max_connect_failures)
    kwargs = dict(agent_args or {})
    report = on_result or (lambda row, frames: None)
    remote = agent.startswith(("ws://", "wss://"))
    client = None
    try:
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


def evaluate_scenes(scenes, agent: str, cfg: EnvConfig, *, timeout: float = 60.0, agent_args: dict | None = None,
                    batch_slots: int = 64, scenes_at_once: int = 1, on_result=None,
                    max_connect_failures: int = 3) -> list[dict]:
    """The batched evaluate verb over several scenes (`scenes`: SceneEpisodes, each with its context's
    maker and its agents' seed): one agent client for the whole run, `batch_slots` episodes stepped
    together, up to `scenes_at_once` scenes in flight (run_scenes_batched), so that the slots stay
    full when a scene has fewer episodes than slots or runs its last long ones. The arguments are
    evaluate_episodes'; on_result(row, None) as each episode finishes. Returns the rows in the
    scenes' and episodes' order.

    Raises:
        AgentUnreachable: the agent server could not be reached; the rows reported so far stand.
    """
    kwargs = dict(agent_args or {})
    report = on_result or (lambda row, frames: None)
    remote = agent.startswith(("ws://", "wss://"))
    scenes = iter(scenes)
    first = next(scenes, None)
    if first is None:
        return []
    client = None
    try:
        client = agent_for(agent, first.seed, timeout, batch=True, **kwargs) if remote else \
            InProcessBatch(lambda seed: agent_for(agent, seed, timeout, **kwargs), seeded=True, seed=first.seed)
        rows = run_scenes_batched(itertools.chain([first], scenes), client, batch_slots, cfg, max_connect_failures,
                                  on_result=lambda row: report(row, None), scenes_at_once=scenes_at_once)
        if remote and len(rows) >= max_connect_failures and all(_unreachable(r) for r in rows[-max_connect_failures:]):
            raise AgentUnreachable(f"agent server {agent} unreachable for {max_connect_failures} episodes in a row")
        return rows
    finally:
        if client is not None and hasattr(client, "close"):
            client.close()
