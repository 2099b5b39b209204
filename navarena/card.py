"""navarena card: a training run's model card, shipped and kept up to date (navcore.baselines.card).

    navarena card ship RUN NAME [--sample]           # RUN/model.pt + its card -> MODELS/NAME
    navarena card evaluation NAME SUMMARY.json ... --conditions TEXT --command CMD
                  [--title T [--real]] [--replace | --add]   # closed-loop figures into the card
    navarena card verifier NAME RUN --stop-check P [--stop-force P] [--selection SUMMARY ...] [--command C]
    navarena card cost NAME                          # CPU ms per step into the card
    navarena card gpu-rate NAME --machine M --setting S AGENT:STEPS:SECONDS ...
    navarena card note NAME TEXT                     # which run this is and why
    navarena card markdown [--check]                 # every card's model_card.md from its JSON

--models DIR picks the folder of cards (default: the library's navcore/models, whose names the
agent registry knows; a checkout's benchmarks/baselines/trials holds runs measured, not shipped).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from navcore.baselines import card
from navcore.baselines.agent import MODELS


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="navarena card", description="A navarena train run's model card: ship it into "
                                 "--models, add closed-loop figures, costs and notes, write its markdown. "
                                 "navarena card COMMAND --help for each.")
    ap.add_argument("--models", type=Path, default=MODELS, help="the folder of cards (default: the installed library's navcore/models)")
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("ship", help="a navarena train run's model.pt and card into --models/NAME")
    s.add_argument("run", type=Path)
    s.add_argument("name")
    s.add_argument("--no-weights", action="store_true", help="only the card (a run measured, not shipped)")
    s.add_argument("--sample", action="store_true", help="the registry name samples its moves (its figures' decoding)")
    e = sub.add_parser("evaluation", help="navarena eval summaries into the card")
    e.add_argument("name")
    e.add_argument("summaries", nargs="+", type=Path)
    e.add_argument("--conditions", required=True, help="what the figures were measured under (one paragraph)")
    e.add_argument("--command", required=True, help="the command that reproduces them")
    e.add_argument("--title", help="a further table under this title (another setting) instead of the main one")
    e.add_argument("--real", action="store_true", help="the further table's episodes are on real captures")
    e.add_argument("--replace", action="store_true", help="re-measured runs in place of those of the same names")
    e.add_argument("--add", action="store_true", help="more runs into the table (names it does not hold yet)")
    v = sub.add_parser("verifier", help="a navarena train-stop run as NAME's stop verifier")
    v.add_argument("name")
    v.add_argument("run", type=Path, help="a navarena train-stop run folder (stop.pt, stop_card.json)")
    v.add_argument("--stop-check", type=float, required=True, help="veto a STOP the verifier gives less than this")
    v.add_argument("--stop-force", type=float, help="stop where the verifier gives at least this (default: never)")
    v.add_argument("--selection", nargs="*", type=Path, default=[],
                   help="the held-out navarena eval summaries the thresholds were chosen on")
    v.add_argument("--command", help="the command that made the selection's runs")
    c = sub.add_parser("cost", help="CPU ms per step of the policy into the card")
    c.add_argument("name")
    n = sub.add_parser("note", help="which run this is and why, into the card")
    n.add_argument("name")
    n.add_argument("text")
    g = sub.add_parser("gpu-rate", help="closed-loop steps/s in the batched GPU environment into the card")
    g.add_argument("name")
    g.add_argument("entries", nargs="+", help="AGENT:STEPS:SECONDS")
    g.add_argument("--machine", required=True)
    g.add_argument("--setting", required=True, help="what ran: episodes, render size and renderer, slots")
    m = sub.add_parser("markdown", help="every card's model_card.md from its JSON")
    m.add_argument("--check", action="store_true", help="write nothing; exit 1 when one is stale")
    return ap


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    models = a.models
    shipped = models.resolve() == MODELS.resolve()  # a folder of trials holds cards without weights
    if a.cmd == "ship":
        if not (a.run / "model_card.json").is_file():
            print(f"navarena card ship: {a.run} is not a navarena train run (no model_card.json)", file=sys.stderr)
            return 2
        print(card.ship(a.run, a.name, models, weights=not a.no_weights, sample=a.sample))
    elif a.cmd == "evaluation":
        card.add_evaluation(a.name, a.summaries, a.conditions, a.command, models, a.title, a.real, a.replace, a.add)
    elif a.cmd == "verifier":
        out = card.ship_verifier(a.run, a.name, a.stop_check, a.stop_force, a.selection, models, command=a.command)
        print(json.dumps(out, indent=1)[:2000])
    elif a.cmd == "cost":
        print(card.cpu_cost(a.name, models=models))
    elif a.cmd == "note":
        card.set_note(a.name, a.text, models)
    elif a.cmd == "gpu-rate":
        print(card.add_gpu_rate(a.name, a.machine, a.setting, a.entries, models))
    elif a.cmd == "markdown":
        stale = card.write_markdown(models, check=a.check, weights=shipped)
        if a.check and stale:
            print("stale (navarena card markdown):", *stale, sep="\n  ")
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
