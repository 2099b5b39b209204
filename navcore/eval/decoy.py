"""The decoy check: does a policy use its goal? The same episodes are run with the agent shown another
episode's goal (Episode.shown): ImageNav, another goal image of the same scene; ObjectNav, another
goal category of the scene; PointNav, another goal point. Success and every metric stay the true
episode's, so a policy that ignores its goal scores the same both ways, and its goal gain (SR with
the true goal minus SR with the decoy) is 0. `navarena eval --decoy-goal` runs any agent this way.

The decoy of an episode is the scene's episode of the same task with another goal (another category
for ObjectNav, another goal pose otherwise) whose goal lies farthest from the episode's goal: the
most different goal the scene offers, chosen without randomness (ties by episode id)."""
from __future__ import annotations

import dataclasses

import numpy as np

from navcore.eval.episode import Episode


def goal_key(ep: Episode):
    """What identifies an episode's goal: ObjectNav's category, else its goal pose (to the millimetre)."""
    if ep.task == "objectnav":
        return ep.category
    return tuple(np.round(ep.goal_pose, 3))


def decoy_for(ep: Episode, pool: list[Episode]) -> Episode | None:
    """The episode of `pool` (the scene's episodes) whose goal `ep`'s decoy check shows, or None when the
    scene has no other goal for the task."""
    others = sorted((o for o in pool if o.task == ep.task and goal_key(o) != goal_key(ep)), key=lambda o: o.episode_id)
    if not others:
        return None
    far = np.linalg.norm(np.array([o.goal_xy for o in others], float) - np.asarray(ep.goal_xy, float), axis=1)
    return others[int(np.argmax(far))]


def with_decoys(episodes: list[Episode], pool: list[Episode]) -> tuple[list[Episode], list[str]]:
    """Each episode with its decoy goal shown (Episode.shown), and the ids of those left out because
    their scene has no other goal for the task."""
    out, none = [], []
    for ep in episodes:
        d = decoy_for(ep, pool)
        if d is None:
            none.append(ep.episode_id)
        else:
            out.append(dataclasses.replace(ep, shown=d))
    return out, none
