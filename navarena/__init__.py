"""NavArena for its users: a finished dataset (a release or a data root) verified, loaded, trained on
and evaluated in closed loop, without the pipeline.

    from navarena import NavDataset, NavEnv, make_agent, run_episodes, aggregate
    ds = NavDataset("navarena-v1.0.0")
    sid = ds.scene_ids("pointnav")[0]
    ctx = ds.scene_context(sid, renderer="cpu")
    rows = run_episodes(ctx, ds.episodes(sid, "pointnav", limit=5), make_agent("oracle"), ds.env_config())
    print(aggregate(rows)["overall"]["spl"])

The public API (imported on first use, so `import navarena` stays light):
- the data: NavDataset (navcore.eval.dataset), Episode;
- the environment: NavEnv, BatchNavEnv, EnvConfig, SceneContext (navcore.eval), NavGymEnv
  (gymnasium, navarena.gym_env);
- agents and loops: Agent registry AGENTS, make_agent, run_episode, run_episodes,
  run_episodes_batched; metrics METRICS, aggregate;
- the agent-server protocol: serve_agent (an agent behind it), RemoteAgent / RemoteBatchAgent (an
  agent server as an agent);
- training data: ExpertObservations, ExpertObservationStream (navarena.observations).
Commands: `navarena --help` (navarena.cli). Modules: verify_release, evaluate, lerobot,
render_episodes, inspect_scene, doctor, serve_agent. They import nothing of the pipeline
project (pipeline/, stages/: an import contract holds it).
"""
from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("navarena")
    """The installed distribution's version (one source: pyproject.toml)."""
except PackageNotFoundError:  # the sources without an install
    __version__ = "unknown"

_API = {
    "NavDataset": "navcore.eval.dataset", "Episode": "navcore.eval.episode",
    "NavEnv": "navcore.eval.env", "EnvConfig": "navcore.eval.env", "SceneContext": "navcore.eval.env",
    "DynamicsConfig": "navcore.eval.env", "BatchNavEnv": "navcore.eval.batch", "NavGymEnv": "navarena.gym_env",
    "AGENTS": "navcore.eval.agents", "make_agent": "navcore.eval.agents",
    "run_episode": "navcore.eval.loop", "run_episodes": "navcore.eval.loop", "run_episodes_batched": "navcore.eval.loop",
    "METRICS": "navcore.eval.metrics", "aggregate": "navcore.eval.metrics",
    "serve_agent": "navcore.eval.protocol.server", "RemoteAgent": "navcore.eval.protocol.client",
    "RemoteBatchAgent": "navcore.eval.protocol.client",
    "ExpertObservations": "navarena.observations", "ExpertObservationStream": "navarena.observations",
    "ActionSpace": "navcore.nav.actions", "Embodiment": "navcore.nav.embodiment",
}
"""Public name -> the module that defines it."""

__all__ = sorted(_API) + ["__version__"]


def __getattr__(name: str):
    if name in _API:
        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'navarena' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
