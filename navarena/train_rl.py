"""navarena train-rl: the command line of navcore.baselines.ppo (PPO fine-tuning after BC + DAgger).

    navarena train-rl data --init runs/pointnav_bc/model.pt --out runs/pointnav_ppo
    navarena train-rl data --init objectnav_bc --task objectnav --out runs/on_ppo --updates 400
    navarena train-rl data --out runs/pointnav_ppo --resume

What a run does and writes: navcore/baselines/ppo.py.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import asdict

from navarena.cli import help_all
from navcore.baselines.model import NavSpec
from navcore.baselines.ppo import PPOConfig, PPOTrainer
from navcore.baselines.train import init_checkpoint

ADVANCED = {"epochs", "minibatches", "clip", "gamma", "lam", "value_coef", "entropy_coef", "max_grad_norm",
            "collision_reward", "split", "save_every", "scene_updates"}
"""PPO's finer knobs: shown by --help-all."""


def build_parser(show_all: bool = False) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="navarena train-rl", usage="navarena train-rl ROOT --out OUT [--init MODEL] [options]",
                                 description="Fine-tune a learned baseline with PPO in the batched environment "
                                             "(reward: geodesic progress, success, slack) into --out.")
    ap.add_argument("root", help="a data root (make dataset) or a release folder")
    ap.add_argument("--out", required=True, help="the run folder (model.pt, checkpoint.pt, rl_card.json)")
    ap.add_argument("--init", default=None, help="the policy to start from: a model.pt or a shipped name (pointnav_bc); "
                                                 "none: from scratch")
    ap.add_argument("--resume", action="store_true", help="go on from --out's checkpoint.pt")
    for name, default in asdict(PPOConfig()).items():
        if name == "spec":
            continue
        kind = type(default) if type(default) in (int, float) else str
        ap.add_argument("--" + name.replace("_", "-"), type=kind, default=default, metavar="V",
                        help=f"({default})" if show_all or name not in ADVANCED else argparse.SUPPRESS)
    ap.add_argument("--input", type=int, nargs=2, default=None, metavar=("W", "H"),
                    help="from scratch: the network's input size (64 48)")
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--help-all", action="store_true", help="every option, PPO's finer knobs too")
    return ap


def main(argv: list[str] | None = None) -> int:
    if help_all(build_parser, argv):
        return 0
    a = build_parser().parse_args(argv)
    fields_ = {k: getattr(a, k) for k in PPOConfig.__dataclass_fields__ if k != "spec"}
    if a.init is None:
        w, h = a.input or (64, 48)
        fields_["spec"] = NavSpec(task=a.task, rgbd=a.task == "imagenav", depth_w=w, depth_h=h)
    try:
        cfg = PPOConfig(**fields_)
        trainer = PPOTrainer(a.root, a.out, cfg, init=init_checkpoint(a.init, a.task) if a.init else None, quiet=a.quiet)
    except ValueError as e:
        print(f"navarena train-rl: {e}", file=sys.stderr)
        return 2
    res = trainer.run(resume=a.resume)
    if not a.quiet:
        print(f"wrote {res['model']} ({len(res['curve'])} updates, {res['seconds']} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
