"""navarena train-stop: the command line of navcore.baselines.train_stop (ObjectNav's stop verifier).

    navarena train-stop data --out runs/objectnav_stop

What a run does and writes: navcore/baselines/train_stop.py.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import asdict

from navarena import quick
from navarena.quick import shorten
from navcore.baselines.train_stop import StopConfig, StopTrainer
from navcore.baselines.verifier import StopSpec


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="navarena train-stop", usage="navarena train-stop ROOT --out OUT [options]",
                                 description="Train ObjectNav's stop verifier (which categories a STOP here "
                                             "succeeds for) into --out.")
    ap.add_argument("root", help="a data root (make dataset) or a release folder")
    ap.add_argument("--out", required=True, help="the run folder (stop.pt, stop_card.json)")
    d = StopConfig()
    for name, default in asdict(d).items():
        if name == "spec":
            continue
        kind = {int: int, float: float}.get(type(default), int if name == "scenes" else str)
        ap.add_argument("--" + name.replace("_", "-"), type=kind, default=default, metavar="V", help=f"({default})")
    ap.add_argument("--input", type=int, nargs=2, default=[d.spec.depth_w, d.spec.depth_h], metavar=("W", "H"),
                    help=f"the network's input size ({d.spec.depth_w} {d.spec.depth_h})")
    ap.add_argument("--quiet", action="store_true")
    return ap


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    shorten(a, quick.TRAIN_STOP, "navarena train-stop")
    fields_ = {k: getattr(a, k) for k in StopConfig.__dataclass_fields__ if k != "spec"}
    cfg = StopConfig(**fields_, spec=StopSpec(depth_w=a.input[0], depth_h=a.input[1]))
    try:
        trainer = StopTrainer(a.root, a.out, cfg, quiet=a.quiet)
    except FileNotFoundError as e:  # no such data root or release: one line, no traceback
        print(f"navarena train-stop: {e}", file=sys.stderr)
        return 2
    res = trainer.run()
    print(f"wrote {res['model']} (sha256 {res['sha256'][:12]}...)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
