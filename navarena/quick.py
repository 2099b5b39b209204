"""NAVARENA_QUICK=1: the long commands as smoke runs (docs/getting-started.md documents it; the docs
runner sets it). `navarena eval` takes at most 2 episodes a scene and task, each at most 100 steps,
at 160 x 120 unless the command says otherwise; `navarena train` and `train-stop` run one short
round without a held-out check; `export-lerobot` exports 2 episodes and `render-episodes` renders 1
video. The commands are unchanged; each shortened one says so on stderr."""
from __future__ import annotations

import os
import sys

EVAL = {"episodes_per_scene": 2, "width": 160, "height": 120}
EVAL_STEPS = 100
"""navarena eval's step budget of an episode under NAVARENA_QUICK (an untrained policy or a failing
agent would otherwise run its whole budget of 500-1,500 rendered steps)."""
TRAIN = {"rounds": 1, "episodes_per_round": 4, "grad_steps": 5, "val_episodes": 0, "workers": 1, "batch_episodes": 4,
         "slots": 4}
EXPORT = {"episodes": 2}
VIDEOS = {"count": 1}
SIZES = ("width", "height")
"""Set only where the command leaves them unset (an explicit size stays); counts are capped."""
TRAIN_STOP = {"poses_per_scene": 64, "val_poses_per_scene": 16, "grad_steps": 5, "batch": 16}


def quick() -> bool:
    return os.environ.get("NAVARENA_QUICK", "").strip() not in ("", "0", "false", "no")


def shorten(args, caps: dict, command: str) -> None:
    """Under NAVARENA_QUICK, cap each of `caps`' attributes of args (None reads as no limit)."""
    if not quick():
        return
    done = []
    for name, cap in caps.items():
        if not hasattr(args, name):
            continue
        value = getattr(args, name)
        new = cap if value is None else value if name in SIZES else min(value, cap)
        if new != value:
            setattr(args, name, new)
            done.append(f"{name.replace('_', '-')} {new}")
    if done:
        print(f"{command}: NAVARENA_QUICK is set: {', '.join(done)}", file=sys.stderr)


def short_episodes(episodes: list) -> list:
    """Under NAVARENA_QUICK, each episode with at most EVAL_STEPS steps (its metrics then measure a
    smoke run, not the benchmark)."""
    if not quick():
        return episodes
    import dataclasses

    return [dataclasses.replace(e, max_steps=min(int(e.max_steps), EVAL_STEPS)) for e in episodes]
