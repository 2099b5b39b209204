"""Does a learned policy use its goal? The same episodes run several ways, each episode's figures
paired across them:

- `goal`: the policy as shipped (its card's decoding), the episode's own goal;
- `decoy`: the same, shown another goal of the scene and split in place of its own, the one whose
  goal pose is farthest from this episode's (navcore.eval.decoy, as `navarena eval --decoy-goal`):
  ImageNav's goal image rendered there, ObjectNav's goal category (a policy that ignores its goal
  scores as with `goal`);
- `greedy` (ImageNav, whose registry name samples): the own goal image, moves by argmax (the
  decoding's share of the figure).

CPU renderer at the policy's training size (160 x 120), one episode of each of the first --per-scene
goals of each scene in the split (a scene's ImageNav episodes share goal images, its ObjectNav
episodes goal categories); ImageNav under the distance protocol, ObjectNav under explicit_stop (the
policy must stop at an instance of its category, which it cannot find without reading it):

    python -m benchmarks.baselines.goal_ablation ROOT [--task imagenav|objectnav] [--split val_unseen]
        [--per-scene 10] [--agent NAME | --checkpoint RUN/model.pt] [--protocol P]   -> data/08_reports/goal_ablation[_objectnav].json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from navcore.baselines.agent import LearnedNavAgent
from navcore.eval.decoy import goal_key, with_decoys

VARIANTS = {"imagenav": ("goal", "decoy", "greedy"), "objectnav": ("goal", "decoy")}
PROTOCOL = {"imagenav": "distance", "objectnav": "explicit_stop"}


def one_per_goal(episodes: list, n: int) -> list:
    """The first episode (by id) of each distinct goal, at most n: a scene's ImageNav episodes share
    goals (about 10 starts each), its ObjectNav episodes categories, and a decoy must come from
    another goal."""
    seen, out = set(), []
    for ep in sorted(episodes, key=lambda e: e.episode_id):
        key = goal_key(ep)
        if key not in seen and len(out) < n:
            seen.add(key)
            out.append(ep)
    return out


def measure(root: str, split: str = "val_unseen", per_scene: int = 10, agent: str | None = None,
            width: int = 160, height: int = 120, slots: int = 16, task: str = "imagenav",
            protocol: str | None = None, checkpoint: str | None = None) -> dict:
    from navcore.eval.dataset import NavDataset
    from navcore.eval.loop import InProcessBatch, run_episodes_batched

    agent, protocol = agent or f"{task}_bc", protocol or PROTOCOL[task]
    # a shipped name, or a run's model.pt (a trial), which decodes greedily as navarena eval's --agent learned
    net = {"checkpoint": checkpoint} if checkpoint else {"name": agent}
    ds = NavDataset(root)
    cfg = ds.env_config(width=width, height=height, protocol=protocol)
    variants = VARIANTS[task]
    rows = {v: [] for v in variants}
    seconds = {v: 0.0 for v in variants}
    for sid in ds.scene_ids(task):
        pool = ds.episodes(sid, task, split)
        eps = one_per_goal(pool, per_scene)
        if len(eps) < 2:
            continue
        ctx = ds.scene_context(sid, renderer="cpu")
        decoyed, _ = with_decoys(eps, pool)  # each shown the farthest other goal of the scene (navcore.eval.decoy)
        makers = {"goal": lambda: LearnedNavAgent(**net, device="cpu"),
                  "decoy": lambda: LearnedNavAgent(**net, device="cpu"),
                  "greedy": lambda: LearnedNavAgent(**net, device="cpu", sample=False)}
        for v in variants:
            t = time.perf_counter()
            for r in run_episodes_batched(ctx, decoyed if v == "decoy" else eps, InProcessBatch(makers[v]), slots, cfg):
                rows[v].append({"scene_id": sid, "episode_id": r["episode_id"], "sr": float(r["sr"]),
                                "spl": float(r["spl"]), "steps": int(r["steps"]), "path_length": float(r["path_length"])})
            seconds[v] += time.perf_counter() - t
        print(f"{sid}: " + ", ".join(f"{v} SR {np.mean([r['sr'] for r in rows[v]]):.3f}" for v in variants), flush=True)
    return report(rows, seconds, dict(root=str(root), task=task, split=split, per_scene=per_scene, agent=checkpoint or agent,
                                      render=f"{width}x{height} cpu", protocol=protocol))


def sign_test(a, b) -> tuple[int, int, float]:
    """Two runs' successes on the same episodes (booleans, in the same order): the episodes only the
    first solved, only the second, and the two-sided sign test's p over those (1.0 when none)."""
    from scipy.stats import binomtest

    only_a = sum(bool(x) and not y for x, y in zip(a, b))
    only_b = sum(bool(y) and not x for x, y in zip(a, b))
    return only_a, only_b, float(binomtest(only_a, only_a + only_b).pvalue) if only_a + only_b else 1.0


def report(rows: dict[str, list[dict]], seconds: dict[str, float], setting: dict) -> dict:
    """Per variant SR, SPL, steps and walked metres; per pair of variants the episodes that succeed for
    one alone and the sign test's p."""
    key = {v: {(r["scene_id"], r["episode_id"]): r for r in rs} for v, rs in rows.items()}
    common = sorted(set.intersection(*(set(k) for k in key.values())))
    out = {"setting": setting, "episodes": len(common), "variants": {}, "pairs": {}}
    for v in rows:
        rs = [key[v][k] for k in common]
        out["variants"][v] = {"sr": round(float(np.mean([r["sr"] for r in rs])), 4) if rs else None,
                              "spl": round(float(np.mean([r["spl"] for r in rs])), 4) if rs else None,
                              "steps": round(float(np.mean([r["steps"] for r in rs])), 1) if rs else None,
                              "path_m": round(float(np.median([r["path_length"] for r in rs])), 2) if rs else None,
                              "seconds": round(seconds.get(v, 0.0), 1)}
    names = list(rows)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            only_a, only_b, p = sign_test([key[a][k]["sr"] > 0 for k in common], [key[b][k]["sr"] > 0 for k in common])
            out["pairs"][f"{a}/{b}"] = {f"only_{a}": int(only_a), f"only_{b}": int(only_b), "sign_test_p": float(p)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root")
    ap.add_argument("--split", default="val_unseen")
    ap.add_argument("--task", default="imagenav", choices=list(VARIANTS))
    ap.add_argument("--per-scene", type=int, default=10)
    ap.add_argument("--agent", default=None, help="a shipped baseline of the track (TASK_bc)")
    ap.add_argument("--checkpoint", default=None, help="a run's model.pt in place of --agent (a trial, greedy)")
    ap.add_argument("--protocol", default=None, help="distance|explicit_stop (ImageNav: distance; ObjectNav: explicit_stop)")
    ap.add_argument("--out", type=Path, default=None, help="(data/08_reports/goal_ablation[_objectnav].json)")
    a = ap.parse_args(argv)
    a.out = a.out or Path("data/08_reports") / ("goal_ablation.json" if a.task == "imagenav" else f"goal_ablation_{a.task}.json")
    rep = measure(a.root, a.split, a.per_scene, a.agent, task=a.task, protocol=a.protocol, checkpoint=a.checkpoint)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(rep, indent=1) + "\n")
    print(json.dumps(rep, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
