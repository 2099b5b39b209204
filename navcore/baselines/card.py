"""A learned baseline's model card: the JSON schema a run writes (navcore.baselines.train's
model_card.json), what shipping adds to it (the weights' sha256, closed-loop figures, the stop
verifier, CPU cost, GPU rate, notes) and its markdown (model_card.md). `navarena card` is the
command line; the shipped cards live in navcore/models/<name>/ (MODELS).

    navarena card ship runs/pointnav_bc pointnav_bc          # model.pt + card into navcore/models/
    navarena card evaluation pointnav_bc runs/eval/*/summary.json --conditions ... --command ...
    navarena card markdown                                     # every card's model_card.md
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

from navcore.baselines.agent import MODELS
from navcore.io import jsonio
from navcore.io.release import sha256_file
from navcore.nav.tasks import TASK_TYPES

CARD_COMMAND = "navarena card"
"""The command line that writes cards (named in the generated markdown)."""


def read_card(models: Path, name: str) -> dict:
    """The card of `name` in a models folder; a clear error when it has none."""
    f = models / name / "model_card.json"
    if not f.is_file():
        raise SystemExit(f"{CARD_COMMAND}: {models} has no card {name!r} ({f} missing)")
    return json.loads(f.read_text())


def write_card(models: Path, name: str, card: dict) -> None:
    (models / name / "model_card.json").write_text(jsonio.dumps(card, indent=1) + "\n")  # strict: a NaN is null


def cards(models: Path = MODELS, weights: bool = True) -> dict[str, dict]:
    """The shipped baselines' cards by name (folders with a model card and their model file); with
    weights=False every card (TRIALS')."""
    found = {p.parent.name: json.loads(p.read_text()) for p in sorted(models.glob("*/model_card.json"))}
    return {name: c for name, c in found.items()
            if "sha256" in c and (not weights or (models / name / c["file"]).is_file())}


def ship(run: Path, name: str, models: Path = MODELS, weights: bool = True, sample: bool = False) -> Path:
    """Copy a training run's model.pt into navcore/models/<name>/ with its card (sha256 of the copy);
    without weights, only the card (the run's sha256), e.g. into TRIALS. sample: the card's decoding
    samples the moves (the registry name's default, navcore.baselines.agent)."""
    dst = models / name
    dst.mkdir(parents=True, exist_ok=True)
    card = json.loads((run / "model_card.json").read_text())
    if weights:
        shutil.copyfile(run / "model.pt", dst / "model.pt")
        card["sha256"] = sha256_file(dst / "model.pt")
    card.update({"name": name, "file": "model.pt", "licence": "Apache-2.0"})
    card.pop("decoding", None)
    if sample:
        card["decoding"] = {"sample": True}
    card["data"]["root"] = Path(card["data"]["root"]).name  # no machine's paths in a shipped card
    card.setdefault("evaluation", {})
    write_card(models, name, card)
    return dst


def add_evaluation(name: str, summaries: list[Path], conditions: str, command: str, models: Path = MODELS,
                   title: str | None = None, real: bool = False, replace: bool = False, add: bool = False) -> None:
    """Merge navarena eval summary.json files (one per agent and protocol, named by their folder)
    into the card's `evaluation`, with the conditions they were measured under and the command.
    With a title, a further table instead (`more_evaluations`, replacing one of that title): figures
    in another setting, e.g. on real captures (`real`). replace: re-measured runs in place of the
    table's runs of the same names (the others kept), conditions and command appended to the table's.
    add: the runs join the table (each a name it does not hold yet), conditions and command appended."""
    card = read_card(models, name)
    runs = {}
    for s in summaries:
        summ = json.loads(Path(s).read_text())
        summ["root"] = Path(summ["root"]).name  # no machine's paths in a shipped card
        runs[Path(s).parent.name] = summ
    entry = {"conditions": conditions, "command": command, "runs": runs}
    if replace and add:
        raise SystemExit(f"{CARD_COMMAND} evaluation: --replace or --add, not both")
    if replace or add:  # into the table already there: conditions and command appended to its own
        flag = "--add" if add else "--replace"
        old = card["evaluation"] if not title else next((m for m in card.get("more_evaluations", []) if m["title"] == title), None)
        if add and not old:
            raise SystemExit(f"{CARD_COMMAND} evaluation --add: {name} has no table {title or '(main)'} to add to")
        wrong = sorted(set(runs) & set(old["runs"])) if add else sorted(set(runs) - set((old or {}).get("runs", {})))
        if wrong:
            raise SystemExit(f"{CARD_COMMAND} evaluation {flag}: {name}'s table {title or '(main)'} "
                             f"{'already has' if add else 'has no run'} {', '.join(wrong)}")
        real = old.get("real", real)
        merged = {**old["runs"], **runs} if add else {k: runs.get(k, v) for k, v in old["runs"].items()}
        entry = {"conditions": f"{old['conditions']} {conditions}", "command": f"{old['command']}; {command}",
                 "runs": merged}
    if title:
        more = [m for m in card.get("more_evaluations", []) if m["title"] != title]
        card["more_evaluations"] = more + [{"title": title, "real": real, **entry}]
    else:
        card["evaluation"] = entry
    write_card(models, name, card)


def ship_verifier(run: Path, name: str, stop_check: float, stop_force: float | None = None,
                  selection: list[Path] = (), models: Path = MODELS, command: str | None = None) -> dict:
    """A navarena train-stop run's stop.pt into navcore/models/<name>/ as the stop verifier its
    registry name uses (the card's `stop_verifier`: file, sha256, thresholds, the run's config, data
    and curve), with the held-out runs the thresholds were chosen on (navarena eval summaries, each
    folder named for its setting) and the command that made them."""
    from navcore.baselines.verifier import load_verifier

    dst = models / name
    card = read_card(models, name)
    if card["task"] != "objectnav":
        raise SystemExit(f"{CARD_COMMAND} verifier: {name} is a {card['task']} baseline; a stop verifier is ObjectNav's")
    run_card = json.loads((run / "stop_card.json").read_text())
    sha = sha256_file(run / "stop.pt")
    if sha != run_card["sha256"]:
        raise SystemExit(f"{CARD_COMMAND} verifier: {run / 'stop.pt'} is not the file its card names (sha256 differs)")
    load_verifier(str(run / "stop.pt"), sha, "cpu")  # refuses a file that is not a verifier
    shutil.copyfile(run / "stop.pt", dst / "stop.pt")  # checked first: nothing half-shipped beside the policy
    data = {**run_card["data"], "root": Path(run_card["data"]["root"]).name}  # no machine's paths in a shipped card
    rows = []
    for f in selection:
        summ = json.loads(Path(f).read_text())
        m = summ["tasks"]["objectnav"]["overall"]
        args = summ.get("agent_args") or {}
        rows.append({"setting": Path(f).parent.name, "verifier": "verifier" in args,
                     "stop_check": args.get("stop_check"), "stop_force": args.get("stop_force"),
                     "protocol": summ["protocol"], "split": summ.get("split"), "episodes": m["episodes"],
                     "stop_sr": m.get("stop_sr"), "spl": m.get("spl"), "render": summ.get("render")})
    prev = card.get("stop_verifier") or {}
    card["stop_verifier"] = {"file": "stop.pt", "sha256": sha, "stop_check": stop_check, "stop_force": stop_force,
                             "parameters": run_card["parameters"], "config": run_card["config"], "data": data,
                             "curve": run_card["curve"], "timing": run_card.get("timing"), "selection": rows,
                             "selection_command": command}
    if prev.get("sha256") == sha:  # the same file shipped again: what was measured on it since stays
        card["stop_verifier"] = {**prev, **card["stop_verifier"]}
    write_card(models, name, card)
    return card["stop_verifier"]


def verified_rate_line(v: dict) -> str:
    r = v.get("gpu_eval_rate")
    if not r:
        return ""
    return (f" Closed loop with it in the batched GPU environment: {r['steps_per_s_per_process']:.0f} steps/s per "
            f"navarena eval process ({r['steps']:,} steps in {r['process_seconds']:,} process-seconds; {r['setting']}; "
            f"{r['machine']}).")


def verifier_section(card: dict, level: str = "##") -> str:
    """The card's stop verifier (navcore.baselines.verifier), as markdown; empty without one."""
    v = card.get("stop_verifier")
    if not v:
        return ""
    c, d = v["config"], v["data"]
    sp = c["spec"]
    force = "never stops on its own" if v.get("stop_force") is None else f"stops where it gives at least {v['stop_force']}"
    last = v["curve"][-1].get("val")
    held = (f"Held-out check on {d['val_poses']:,} poses of the {d['val_split']} scenes at P >= 0.5: precision "
            f"{last['precision']:.2f}, recall {last['recall']:.2f} (loss {last['loss']:.3f}; {last['positive_share']:.1%} "
            "of its labels positive)." if last else "No held-out check (the data had no held-out scenes).")
    lines = [f"""
{level} Stop verifier

`{v['file']}`, sha256 `{v['sha256']}` (checked on load), {v['parameters']:,} parameters: a per-frame classifier of
which goal categories a STOP at the camera's pose would succeed for (RGB-D at {sp['depth_w']} x {sp['depth_h']}, one
logit per category; navcore.baselines.verifier). The registry name vetoes the policy's STOP where the verifier gives the
goal category less than {v['stop_check']} (the policy's most likely move instead) and {force};
`--agent-arg verifier=none` runs the policy alone. Trained by `navarena train-stop` on {d['train_poses']:,} poses of
{len(d['train_scenes'])} training scenes of data root `{d['root']}` rendered at {c['width']} x {c['height']} by
{c['renderer']} ({c['near_share']:.0%} within {c['near_range']} m of an object instance, most facing it), labelled by the
evaluator's success rule; {c['grad_steps']} steps of batch {c['batch']}, seed {c['seed']}. {held}{verified_rate_line(v)}
"""]
    if v.get("selection"):
        r0 = v["selection"][0]
        lines.append(f"The thresholds were chosen on {r0['split']} ({r0['episodes']} episodes, {r0['protocol']}), never on "
                     "the zero-shot set:\n")
        lines.append("| setting | verifier | stop_check | stop_force | Stop SR | SPL |\n|---|---|---:|---:|---:|---:|")
        for r in v["selection"]:
            lines.append(f"| {r['setting']} | {'yes' if r['verifier'] else 'no'} | {num(r['stop_check'], 1)} | "
                         f"{num(r['stop_force'], 1)} | {num(r['stop_sr'])} | {num(r['spl'])} |")
        lines.append("")
        if v.get("selection_command"):
            lines.append(f"Reproduce: `{v['selection_command']}`\n")
    return "\n".join(lines) + "\n"


def cpu_cost(name: str, repeats: int = 300, models: Path = MODELS) -> dict:
    """Median milliseconds of one act() of the shipped policy on this machine's CPU (rendering
    excluded), at 640 x 480 and 160 x 120 (every observation its track reads), recorded in the card."""
    import os
    import platform
    import time

    import numpy as np
    import torch

    from navcore.eval.agents import agent_for

    agent = agent_for(name, device="cpu")
    agent.reset({})
    out = {"machine": f"{platform.machine()} CPU, {os.cpu_count()} cores, torch threads {torch.get_num_threads()}"}
    spec, rng = agent.net.spec, np.random.default_rng(0)

    def median_ms(step) -> float:  # 20 warm-up calls, then the median of `repeats`
        for _ in range(20):
            step()
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            step()
            times.append(time.perf_counter() - t)
        return round(1000 * float(np.median(times)), 2)

    for w, h in ((640, 480), (160, 120)):
        # every observation the track's agent gets (it reads those its spec names)
        obs = {"depth": rng.uniform(0.5, 4.0, (h, w)).astype(np.float32),
               "rgb": rng.integers(0, 256, (h, w, 3), dtype=np.uint8),
               "goal_image": rng.integers(0, 256, (h, w, 3), dtype=np.uint8),
               "pointgoal": np.array([3.0, 0.3], np.float32),
               "goal_category": (spec.categories or ["chair"])[0]}
        out[f"{w}x{h}"] = median_ms(lambda: agent.act(obs))
        if getattr(agent, "verifier", None) is not None:  # asked only on a step where the policy would STOP
            from navcore.baselines.verifier import stop_input

            with torch.no_grad():
                out[f"verifier_{w}x{h}"] = median_ms(lambda: agent.verifier(stop_input(
                    torch.as_tensor(obs["depth"])[None], torch.as_tensor(obs["rgb"])[None], agent.verifier.spec)))
    card = read_card(models, name)
    card["cpu_ms_per_step"] = out
    write_card(models, name, card)
    return out


def add_gpu_rate(name: str, machine: str, setting: str, entries: list[str], models: Path = MODELS) -> dict:
    """Closed-loop evaluation speed in the batched GPU environment into the card: per agent the
    steps and the wall seconds of one navarena eval process (its start included)."""
    rate = {"machine": machine, "setting": setting, "agents": {}}
    for e in entries:
        agent, steps, secs = e.rsplit(":", 2)
        rate["agents"][agent] = {"steps": int(steps), "seconds": float(secs),
                                 "steps_per_s": round(int(steps) / float(secs), 1)}
    card = read_card(models, name)
    card["gpu_eval_rate"] = rate
    write_card(models, name, card)
    return rate


def gpu_rate_line(card: dict) -> str:
    r = card.get("gpu_eval_rate")
    if not r:
        return "not measured yet."
    agents = "; ".join(f"{a}: {v['steps']:,} steps in {v['seconds']} s, {v['steps_per_s']} steps/s"
                       for a, v in r["agents"].items())
    return f"{agents} ({r['setting']}; {r['machine']})."


def set_note(name: str, text: str, models: Path = MODELS) -> None:
    """Which run a card is and why (its Limitations paragraph)."""
    card = read_card(models, name)
    card["notes"] = text
    write_card(models, name, card)


TRACKS = list(TASK_TYPES)
ORDER = ["overall", "easy", "medium", "hard"]
COLUMNS = [("SR", "sr"), ("SPL", "spl"), ("NE m", "ne"), ("CR", "collision_rate"), ("AvgSteps", "steps"),
           ("Stop SR", "stop_sr")]
TRACK_COLUMNS = {"imagenav": [("Pose SR", "pose_sr"), ("Pose Ret.", "pose_retention")]}
"""A track's termination diagnostics beside COLUMNS (ImageNav: the final heading within tolerance of
the goal image's, and Pose SR / SR)."""


def num(v, digits: int = 3) -> str:
    return "-" if v is None else (f"{v:.0f}" if digits == 0 else f"{v:.{digits}f}")


def results_table(card: dict, ev: dict | None = None) -> str:
    """Agents x (overall, easy, medium, hard) of the card's evaluation runs (or those of `ev`, one of
    its further evaluations), as markdown."""
    ev = card.get("evaluation") or {} if ev is None else ev
    runs = ev.get("runs") or {}
    if not runs:
        return "_No closed-loop evaluation recorded yet._\n"
    columns = COLUMNS + TRACK_COLUMNS.get(card["task"], [])
    lines = ["| agent | protocol | rendered | group | n | " + " | ".join(c for c, _ in columns) + " |",
             "|---|---|---|---|---:|" + "---:|" * len(columns)]
    for run, summ in runs.items():
        groups = summ["tasks"][card["task"]]
        shown = rendered(summ)
        for group in sorted(groups, key=lambda g: ORDER.index(g) if g in ORDER else len(ORDER)):
            m = groups[group]
            cells = [num(m.get(k), 0 if k == "steps" else 2 if k == "ne" else 3) for _, k in columns]
            lines.append(f"| {run_label(summ)} | {summ['protocol']} | {shown} | {group} | {m['episodes']} | "
                         + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n" + goal_gain_table(card, ev)


def rendered(summ: dict) -> str:
    """How a run's frames were rendered, as its tables say it ("640x480 gsplat", or "no")."""
    r = summ.get("render")
    return f"{r['width'] or ''}x{r['height'] or ''} {r['renderer']}" if r else "no"


def run_label(summ: dict) -> str:
    """A run's agent as its table names it (a decoy run says so)."""
    return (summ.get("label") or summ["agent"]) + (" (decoy goal)" if summ.get("decoy_goal") else "")


def goal_gain_table(card: dict, ev: dict) -> str:
    """The decoy check of an evaluation's runs (navarena eval --decoy-goal, docs/evaluation.md): for each run
    shown another goal of its scene beside the run of the same agent, arguments, protocol, rendering and
    episodes shown its own, SR with each and the goal gain (own minus decoy); ImageNav's Pose SR too. ''
    when the evaluation holds no such pair."""
    task = card["task"]

    def key(summ):
        return (summ.get("label") or summ["agent"], json.dumps(summ.get("agent_args") or {}, sort_keys=True),
                summ["protocol"], json.dumps(summ.get("render"), sort_keys=True), summ.get("split"),
                summ.get("episodes_per_scene"), summ.get("difficulty"))

    runs = (ev.get("runs") or {}).values()
    own = {key(s): s for s in runs if not s.get("decoy_goal") and task in s.get("tasks", {})}
    pairs = [(own[key(s)], s) for s in runs if s.get("decoy_goal") and key(s) in own and task in s.get("tasks", {})]
    if not pairs:
        return ""
    pose = task == "imagenav"
    lines = ["", "Goal gain, the decoy check (the same episodes with another goal of the scene shown, scored on "
             "their own goal):", "",
             "| agent | protocol | rendered | n | SR, own goal | SR, decoy goal | goal gain |"
             + (" Pose SR, own | Pose SR, decoy |" if pose else ""),
             "|---|---|---|---:|---:|---:|---:|" + ("---:|---:|" if pose else "")]
    for a, b in pairs:
        ma, mb = a["tasks"][task]["overall"], b["tasks"][task]["overall"]
        shown = rendered(a)
        n = str(ma["episodes"]) if ma["episodes"] == mb["episodes"] else f"{ma['episodes']} / {mb['episodes']}"
        gain = None if ma.get("sr") is None or mb.get("sr") is None else ma["sr"] - mb["sr"]
        lines.append(f"| {a.get('label') or a['agent']} | {a['protocol']} | {shown} | {n} | {num(ma.get('sr'))} | "
                     f"{num(mb.get('sr'))} | {'-' if gain is None else f'{gain:+.3f}'} |"
                     + (f" {num(ma.get('pose_sr'))} | {num(mb.get('pose_sr'))} |" if pose else ""))
    return "\n".join(lines) + "\n"


def curve_table(card: dict) -> str:
    stop = any("val_stop_sr" in e for e in card["curve"])  # ObjectNav's check under explicit_stop too
    lines = ["| round | kind | beta | new frames | frames | loss (first -> last 10 %) | val SR | val SPL |"
             + (" val Stop SR |" if stop else "") + " collect s | fit s |",
             "|---:|---|---:|---:|---:|---|---:|---:|" + ("---:|" if stop else "") + "---:|---:|"]
    for e in card["curve"]:
        lf = f"{e['loss_first']:.3f} -> " if "loss_first" in e else ""
        aux = f" (goal position {e['aux_loss_first']:.3f} -> {e['aux_loss']:.3f})" if "aux_loss" in e else ""
        lines.append(f"| {e['round']} | {e['kind']} | {e['beta']:.2f} | {e['new_frames']} | {e['frames']} | "
                     f"{lf}{e['loss']:.3f}{aux} | {num(e.get('val_sr'))} | {num(e.get('val_spl'))} | "
                     + (f"{num(e.get('val_stop_sr'))} | " if stop else "")
                     + f"{num(e.get('collect_s'), 1)} | {num(e.get('fit_s'), 1)} |")
    return "\n".join(lines) + "\n"


def cost_line(card: dict) -> str:
    c = card.get("cpu_ms_per_step")
    if not c:
        return f"not measured yet (`{CARD_COMMAND} cost NAME`)."
    verifier = (f" Its stop verifier adds {c['verifier_640x480']} ms ({c['verifier_160x120']} ms at 160 x 120) on a step "
                "where the policy asks to stop." if "verifier_640x480" in c else "")
    return (f"{c['640x480']} ms a step at 640 x 480 observations (those its track reads), {c['160x120']} ms at "
            f"160 x 120 (median, rendering excluded; {c['machine']}; `{CARD_COMMAND} cost {card['name']}`).{verifier}")


def kept(card: dict) -> str:
    """Which round's weights the file holds (cards from before `keep` existed: the last)."""
    if "selected_round" not in card:
        return ""
    checked = any(e.get("val_sr") is not None for e in card["curve"])
    best = card["config"].get("keep", "last") == "best" and checked
    how = "the best held-out check" if best else "the last round" if checked else "the last round: no held-out check ran"
    if best and any(e.get("val_stop_sr") is not None for e in card["curve"]):
        from navcore.baselines.train import check_score

        ranked = max(card["curve"], key=lambda e: (*check_score(e), e["round"]))["round"]  # the later round on a tie
        how += (", by the mean of its SR and Stop SR" if ranked == card["selected_round"] else
                ", by its SR alone: the rule before Stop SR was averaged in")
    return f" The file holds round {card['selected_round']}'s weights ({how})."


def expert(card: dict) -> str:
    """The labelling expert of a card's run (navarena train --expert; cards from before it: geodesic)."""
    from navcore.baselines.train import searches

    if not searches(card["task"], card["config"].get("expert")):
        return "the geodesic oracle"
    overlap = card["config"].get("view_overlap", 0.0)  # cards from before it: a glimpse of the goal's place
    if card["task"] == "imagenav" and overlap > 0:
        return (f"the searching expert: it looks for the goal until its camera sees {overlap:.0%} of what the goal image "
                "shows, then the geodesic oracle")
    return "the searching expert: it looks for the goal until it has been in view, then the geodesic oracle"


def rounds_count(card: dict) -> str:
    n = len(card["curve"])
    return f"{n} round{'s' * (n != 1)}"


def rounds_line(card: dict) -> str:
    """What the card's rounds were: behaviour cloning, then DAgger when there was more than one."""
    if card["config"].get("first_round") == "dagger":  # a fine-tune whose rounds are all DAgger
        return (f"{rounds_count(card)} of DAgger from the --init weights (the learner drives, the expert's action\n"
                "  executed with probability beta^(round + 1)")
    if len(card["curve"]) == 1:
        return "one round: behaviour cloning on the expert's rollouts, no DAgger round (the expert drives"
    return ("round 0 behaviour cloning on the expert's rollouts, then DAgger (the learner drives, the expert's\n"
            "  action executed with probability beta^round")


def decoding(card: dict) -> str:
    """How the registry name picks its moves (the card's `decoding`; greedy when absent)."""
    if card.get("decoding", {}).get("sample"):
        return ("sampled from the policy's distribution over the three moves, seeded per episode (STOP when it is the "
                "most likely action); the figures below were measured so. `--agent-arg sample=false` acts greedily.")
    return "greedy (the most likely action); `--agent-arg sample=true` draws the moves from the policy's distribution."


def network(spec: dict) -> str:
    """The card's one-paragraph description of the network of a NavSpec (as a dict)."""
    size = f"{spec['depth_w']} x {spec['depth_h']}, area-pooled from any render size"
    task = spec.get("task", "pointnav")  # cards from before the other tracks had no task in their spec
    if task == "pointnav":
        inputs = f"depth ({size}, clipped at {spec['max_depth']} m), the goal as (log(1 + distance), cos, sin of the bearing)"
    elif task == "imagenav":
        seen = (f"depth and RGB ({size}, depth clipped at {spec['max_depth']} m)" if spec.get("rgbd")
                else f"RGB ({size})")
        inputs = f"{seen} and the goal image stacked as channels into one encoder (early fusion, as GNM does)"
    else:
        cats = spec.get("categories", ())
        inputs = (f"depth and RGB ({size}, depth clipped at {spec['max_depth']} m), the goal category as a learned "
                  f"embedding ({len(cats)} categories: {', '.join(cats)})")
    if spec.get("aux_goal"):
        goal = "the goal's position" if task == "imagenav" else "the nearest point of the nearest goal instance"
        inputs += (f" (an auxiliary head, trained beside the actions and not used to act unless a stop gate asks it, "
                   f"predicts {goal} in the robot frame from the GRU state)")
    return (f"{inputs} and the previous action; a 4-layer CNN, a GRU of {spec['hidden']} over the "
            "episode, logits of STOP / FORWARD / LEFT / RIGHT.")


def more_tables(card: dict, level: str = "###") -> str:
    """The card's further evaluations (other settings: real captures, the CPU renderer), as sections."""
    return "".join(f"\n{level} {m['title']}\n\n{m['conditions']}\n\n{results_table(card, m)}\n"
                   f"Reproduce: `{m['command']}`\n" for m in card.get("more_evaluations", []))


def groups(card: dict) -> str:
    g = card["data"].get("groups")
    return f" ({', '.join(f'{n} {k}' for k, n in g.items())})" if g else ""


def real_groups(card: dict) -> dict[str, int]:
    """Training scenes per catalog group other than the generator's (cards from before groups were
    recorded: none, they were all generated)."""
    return {g: n for g, n in card["data"].get("groups", {}).items() if g != "synthetic"}


def licence_line(card: dict) -> str:
    other = real_groups(card)
    init = f" Fine-tuned from `{card['config']['init']}`." if card["config"].get("init") else ""
    if not other:
        return f"{card['licence']}. Trained on NavArena's own generated scenes (Apache-2.0), no third-party data.{init}"
    named = ", ".join(f"{n} of group `{g}`" for g, n in other.items())
    return (f"not settled by the project's {card['licence']}: trained on scenes that are not NavArena's generated ones "
            f"({named}), whose sources' licences govern whether these weights may be published.{init}")


def real_note(card: dict) -> str:
    if real_groups(card):
        return "Trained with real captures in its training split (see Data)."
    if any(m.get("real") for m in card.get("more_evaluations", [])):
        return "Trained on generated scenes only; also measured on real captures (above)."
    return "Trained and measured on generated scenes only: the gap to real captures is not measured yet."


def card_markdown(card: dict, shipped: bool = True) -> str:
    """navcore/models/<name>/model_card.md (or a trial's), from its JSON."""
    c, ev = card["config"], card.get("evaluation") or {}
    val = next((e.get("val_split") for e in card["curve"] if e.get("val_split")), None)
    checks = f"closed-loop check after each round on `{val}`" if val else "no closed-loop check between rounds"
    file_line = (f"`{card['file']}`, sha256 `{card['sha256']}` (checked on load)." if shipped else
                 f"not shipped (the run's `{card['file']}` had sha256 `{card['sha256']}`).")
    status = ("It is the interim baseline of its track (see docs/evaluation.md, \"Baselines\", for what is still "
              "missing)." if shipped else "Its weights are not shipped: its training scenes' sources are not ours to "
              "publish." if real_groups(card) else "Its weights are not shipped: a baseline that loses to random is not one.")
    title = f"the learned {card['task']} baseline" if shipped else \
        f"a reference run of the {card['task']} track, measured and not shipped"
    return f"""# {card['name']}: {title}

Generated from model_card.json by `{CARD_COMMAND} markdown`; do not edit.

- **File:** {file_line} {card['parameters']:,} parameters.
- **Licence:** {licence_line(card)}
- **Network:** {network(c['spec'])}
- **Decoding:** {decoding(card)}
- **Data:** data root `{card['data']['root']}`: {len(card['data']['train_scenes'])} training scenes{groups(card)} (split
  `{card['data']['split']}`), {card['frames']:,} labelled frames over {rounds_count(card)}, rendered at
  {c['width']} x {c['height']}; {checks}.
- **Training:** {rounds_line(card)}, every visited state labelled by {expert(card)});
  {c['episodes_per_round']} episodes and {c['grad_steps']} gradient steps of {c['batch_episodes']} whole episodes a
  round, AdamW lr {c['lr']}, seed {card['seed']}.{kept(card)} On {card['trained_on']} ({card.get('workers', 0)} collection
  workers): {card['train_seconds']} s of collection and fitting.
- **Running it on a CPU:** {cost_line(card)}
- **Closed-loop speed in the batched GPU environment:** {gpu_rate_line(card)}

## Training curve

{curve_table(card)}
## Closed-loop evaluation

{ev.get('conditions', '')}

{results_table(card)}
Reproduce: `{ev.get('command', '')}`
{more_tables(card)}{verifier_section(card)}
## Limitations

{card.get('notes') or ''}
{real_note(card)} {status}
"""


def write_markdown(models: Path = MODELS, check: bool = False, weights: bool = True) -> list[str]:
    """Every card's model_card.md in a models folder from its JSON (weights=False: a folder of
    trials, cards whose weights are not shipped); with check, write nothing. Returns the files that
    differ."""
    stale = []
    for name, card in cards(models, weights=weights).items():
        f = models / name / "model_card.md"
        text = card_markdown(card, shipped=weights)
        if not f.is_file() or f.read_text() != text:
            stale.append(str(f))
            if not check:
                f.write_text(text)
    return stale
