"""navarena train: the command line of navcore.baselines.train (behaviour cloning, then DAgger).

    navarena train data --out runs/pointnav_bc                  # defaults: 1 BC round + 4 DAgger rounds
    navarena train data --out runs/pn --resume                  # go on from the last finished round

What a run does and writes: navcore/baselines/train.py.
"""
from __future__ import annotations

import argparse
import sys

from navarena import quick
from navarena.cli import help_all
from navarena.quick import shorten
from navcore.baselines.model import ENCODERS, TRACKS, NavSpec
from navcore.baselines.train import TrainConfig, Trainer, init_checkpoint


def _flag(text: str) -> bool:
    """A true/false option's value."""
    if text.lower() in ("true", "1", "yes"):
        return True
    if text.lower() in ("false", "0", "no"):
        return False
    raise argparse.ArgumentTypeError(f"{text!r}: true or false")


ADVANCED = ("batch_episodes", "encode_chunk", "slots", "max_learner_steps", "view_overlap", "beta", "stop_veto", "lr", "weight_decay",
            "aux_weight", "train_split", "val_split", "keep", "first_round", "expert")
"""Options `--help` leaves to `--help-all` (so that the help fits a screen): the recipe's finer knobs."""


def build_parser(ap: argparse.ArgumentParser | None = None, show_all: bool = False) -> argparse.ArgumentParser:
    ap = ap or argparse.ArgumentParser(prog="navarena train", usage="navarena train ROOT --out OUT [options]",
                                       description="Train a baseline policy (behaviour cloning, then DAgger) into --out.")
    ap.formatter_class = lambda prog: argparse.HelpFormatter(prog, max_help_position=30)  # one line an option
    ap.add_argument("root", nargs="+", help="data roots or releases (several: trained on together)")
    ap.add_argument("--out", required=True, help="the run folder (model.pt, model_card.json, rounds/)")
    ap.add_argument("--resume", action="store_true", help="go on after the last finished round in --out")
    d = TrainConfig()
    helps = {"task": None, "rounds": "0: behaviour cloning, then DAgger", "episodes_per_round": None, "grad_steps": None,
             "batch_episodes": None, "encode_chunk": "frames encoded at once (checkpointed; 0: all)",
             "slots": "episodes stepped together", "width": "render size", "height": None,
             "val_episodes": "held-out check", "keep": "best|last round into model.pt", "scenes": "first N train scenes",
             "capture_share": "episodes from non-generated scenes", "seed": None,
             "init": "fine-tune: a model.pt or shipped name", "first_round": "bc|dagger: round 0 (dagger: --init drives)",
             "max_learner_steps": None, "expert": "auto|geodesic|search: the labelling expert",
             "view_overlap": "ImageNav: goal view share that is found",
             "workers": "collection processes", "beta": "DAgger mixing",
             "stop_veto": "DAgger: label false STOPs, run on",
             "lr": None, "weight_decay": None, "depth_noise": "augmentation: depth noise and holes",
             "rgb_noise": "augmentation: RGB jitter", "aux_weight": "ImageNav's goal-position loss", "train_split": None, "val_split": None,
             "renderer": "auto|cpu|gsplat", "device": "auto|cpu|cuda"}
    for name, text in helps.items():
        default = "auto" if name == "expert" else getattr(d, name)  # d's auto is resolved for its task
        if name == "task":
            ap.add_argument("--task", default=default, choices=list(TRACKS), metavar="T",
                            help=f"{'|'.join(TRACKS)} ({default})")
            continue
        kind = {int: int, float: float, bool: _flag}.get(type(default), {"scenes": int, "capture_share": float}.get(name, str))
        ap.add_argument("--" + name.replace("_", "-"), type=kind, default=default,
                        metavar={int: "N", float: "X", _flag: "B"}.get(kind, "S"),
                        help=f"{text + ' ' if text else ''}({default})" if show_all or name not in ADVANCED
                        else argparse.SUPPRESS)
    ap.add_argument("--aux-goal", action="store_true",
                    help="also a goal-position head (not PointNav; off)")
    ap.add_argument("--encoder", default="cnn", choices=ENCODERS,
                    help="the visual encoder (cnn; effnet_lite0: frozen ImageNet EfficientNet-Lite0, the pretrained extra)")
    ap.add_argument("--film", action="store_true", help="the goal conditions every encoder stage (not PointNav; off)")
    ap.add_argument("--input", type=int, nargs=2, default=None, metavar=("W", "H"),
                    help="the network's input size (64 48; 128 96 with --encoder resnet or effnet_lite0)")
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--help-all", action="store_true", help="every option, the recipe's finer knobs too")
    return ap


def main(argv: list[str] | None = None) -> int:
    if help_all(build_parser, argv):
        return 0
    a = build_parser().parse_args(argv)
    shorten(a, quick.TRAIN, "navarena train")
    fields_ = {k: getattr(a, k) for k in TrainConfig.__dataclass_fields__ if k != "spec"}
    if a.aux_goal or a.film or a.encoder != "cnn" or a.input:
        if a.task == "pointnav" and (a.aux_goal or a.film or a.encoder == "effnet_lite0"):
            build_parser().error("--aux-goal, --film and --encoder effnet_lite0 apply to --task imagenav and objectnav")
        w, h = a.input or ((64, 48) if a.encoder == "cnn" else (128, 96))
        fields_["spec"] = NavSpec(task=a.task, rgbd=a.task == "imagenav", aux_goal=a.aux_goal, encoder=a.encoder,
                                  film=a.film, depth_w=w, depth_h=h)
    init = init_checkpoint(a.init, a.task) if a.init else None  # read once: its network is this run's
    if init is not None:  # its network, plus the goal-position head when asked for (trained from scratch)
        fields_["spec"] = NavSpec(**{**init["spec"], **({"aux_goal": True} if a.aux_goal else {})})
    cfg = TrainConfig(**fields_)
    try:
        trainer = Trainer(a.root, a.out, cfg, quiet=a.quiet, init=init)
    except FileNotFoundError as e:  # no such data root or release: one line, no traceback
        print(f"navarena train: {e}", file=sys.stderr)
        return 2
    res = trainer.run(resume=a.resume)
    print(f"wrote {res['model']} (sha256 {res['sha256'][:12]}...)")
    return 0



if __name__ == "__main__":
    sys.exit(main())
