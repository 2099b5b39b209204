"""Configuration of the evaluate stage (section `evaluate`)."""
from __future__ import annotations

from dataclasses import dataclass, field

from navcore.eval.env import EnvSettings
from navcore.nav.tasks import TASK_TYPES


@dataclass
class EvaluateConfig(EnvSettings):
    """Closed-loop evaluation of one agent on stored episodes (protocol, width, height, render:
    EnvSettings; step sizes: episodes.actions, the dataset's)."""

    run: str = "${evaluate.agent}_${evaluate.protocol}"
    """Run name: outputs go to data/07_eval/{run}/ (default: agent and protocol)."""
    agent: str = "oracle"
    """Registry key (random, oracle, noisy_oracle, depth_reactive), "module:Class", or a
    ws://host:port agent server speaking the NavArena protocol."""
    agent_args: dict = field(default_factory=dict)
    """Keyword arguments of the agent's constructor."""
    renderer: str = "auto"
    """auto (gsplat on CUDA, else CPU) | cpu | gsplat."""
    tasks: list[str] = field(default_factory=lambda: list(TASK_TYPES))
    """Tasks to evaluate."""
    split: str | None = None
    """Only this split (null = all); the name of the release's zero-shot evaluation set
    (release.eval_set.name, eval_zeroshot) runs that set: 600 stratified episodes a task from the
    held-out test scenes, each with its difficulty's step budget (navcore/nav/eval_set.py)."""
    difficulty: str | None = None
    """Only this difficulty (null = all)."""
    episodes_per_scene: int | None = None
    """At most this many episodes per scene and task (null = all), the first by episode id."""
    seed: int = 0
    """Seed of stochastic agents (per scene and task, derived from it)."""
    batch_slots: int = 1
    """Episodes stepped together (one render call per step for all). Above 1: the batch flow of the
    agent-server protocol for ws:// agents; in-process agents get one instance per slot."""
    timeout_s: float = 30.0
    """Remote agents: seconds to wait for each action."""
    videos: int = 1
    """mp4 of the egocentric view for this many episodes per scene (needs render=true)."""
    trajectory_plots: int = 3
    """Top-down trajectory plots per scene."""
