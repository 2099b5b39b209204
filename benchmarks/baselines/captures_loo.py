"""PointNav from the generated world to real captures (issue 82): a policy trained on the generated
scenes alone, evaluated zero-shot on each capture, and leave-one-capture-out fine-tunes (trained on
the generated scenes and two captures, evaluated on the third). Phases, each skipping what is done,
so that a run cut by a machine's time limit goes on where it stopped:

    python -m benchmarks.baselines.captures_loo gen                     # the generated training world
    python -m benchmarks.baselines.captures_loo cap NAME=PATH [...]     # a capture's data root (200 PointNav episodes, half test)
    python -m benchmarks.baselines.captures_loo train [--rounds 4 --episodes 2048]
    python -m benchmarks.baselines.captures_loo zeroshot                # the world's policy (greedy and sampled: world+sample),
                                                                        # pointnav_bc, depth_reactive on every capture
    python -m benchmarks.baselines.captures_loo loo                     # per capture: fine-tune on the others, evaluate on it
                                                                        # greedy and sampled (--loo-decoding); and the control:
                                                                        # the same fine-tune without captures
    python -m benchmarks.baselines.captures_loo report --out DIR        # the table: DIR/captures_loo.{json,md}

gen: the baselines' reference scenes (benchmarks.baselines.reference: the first SCENES=128 generated
scenes' held-out ones and their first TRAIN_SCENES=48 training scenes), PointNav only, in ROOT
(data/pn_world). cap: one data root per capture (data/caps/NAME; the scene's id is NAME, its group
`captures`), whole scene in train and test halves. Evaluations at 640 x 480, gsplat (--renderer),
the distance protocol, the first N (100) test episodes of a capture, one navarena eval process per
(capture, agent), several side by side per GPU. Train under the environment's one collision rule
(navcore.eval.env: a blocked move ends at the last collision-free pose, counted).

On the device machine (2026-12-06): the carry limit (64 MiB with the 27 MB checkout) takes one
capture a call, and a later call removed the folders an earlier one carried and the wheels
installed outside data/. Copy each carried capture into data/src/ and install the wheels into
data/site/ (`pip install --target data/site`), then make the captures' roots from data/src/ paths:
data/ stays between the calls of one machine.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

PY = sys.executable
ROOT = Path(os.environ.get("ROOT", "data/pn_world"))
CAPS = Path(os.environ.get("CAPS", "data/caps"))
RUNS = Path(os.environ.get("RUNS", "data/runs_loo"))
EVAL = Path(os.environ.get("EVAL", "data/eval_loo"))
WORKERS = int(os.environ.get("WORKERS", str(max(1, (os.cpu_count() or 2) - 2))))
WORLD = "pn_world"
CONTROL = "ft_world"
"""loo's control: the world's policy fine-tuned with the leave-one-out recipe on the generated scenes alone."""
AGENTS = ("world", "world+sample", "pointnav_bc", "depth_reactive")
"""Zero-shot on each capture: the generated world's policy (RUNS/pn_world), greedy and with its moves
sampled, the shipped policy, the hand-written controller."""
SAMPLED = "+sample"
"""An agent name's suffix for a learned policy's moves drawn from its distribution (`--agent-arg
sample=true`); its label ends in `_sample`. Greedy, the recurrent policy repeats a blocked move: on the
ScanNet 3DGS 48 of world's 100 episodes stuck, and sampled it reached 0.56 against greedy 0.30."""


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def run(cmd: list, out: Path | None = None, env: dict | None = None) -> int:
    """The reference run's runner (its own process group, output to `out`), no deadline; logged here."""
    from benchmarks.baselines.reference import Deadline
    from benchmarks.baselines.reference import run as run_cmd

    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
    rc = run_cmd([str(c) for c in cmd], Deadline(None), out, env)
    log(f"exit {rc}")
    return rc


def threads(processes: int) -> dict:
    """Each of `processes` side by side gets its share of the cores (benchmarks.baselines.reference.threads)."""
    from benchmarks.baselines.reference import threads as share

    return share(processes)


def gen(scenes: int, train: int) -> int:
    os.environ.update({"SCENES": str(scenes), "TRAIN_SCENES": str(train), "TASKS": "pointnav", "ROOT": str(ROOT)})
    from benchmarks.baselines.reference import held_out_and_first_train

    ids = held_out_and_first_train(scenes, train)
    return run([PY, "-m", "pipeline", f"data_root={ROOT}", f"scenes.count={scenes}", f"scenes.ids=[{','.join(ids)}]",
                "task=[pointnav]", "semantics.enabled=false", "episodes.scene_splits.test=0.1", "executor.dashboard=false",
                "stages=[episodes]", f"executor.n_workers={WORKERS}"])


def cap(specs: list[str], episodes: int) -> int:
    rc = 0
    for spec in specs:
        name, path = spec.split("=", 1)
        root = CAPS / name
        root.mkdir(parents=True, exist_ok=True)
        catalog = CAPS / f"{name}.yaml"
        catalog.write_text(f"scenes:\n  - {{name: {name}, group: captures, path: {Path(path).resolve()}}}\n")
        rc |= run([PY, "-m", "pipeline", f"data_root={root}", f"scenes.catalog={catalog}", "task=[pointnav]",
                   f"task.pointnav.episodes_per_scene={episodes}", "episodes.splits.train=0.5", "+episodes.splits.test=0.5",
                   "episodes.scene_splits.val_unseen=0", "episodes.scene_splits.test=0", "semantics.enabled=false",
                   "executor.dashboard=false",
                   "stages=[episodes]", f"executor.n_workers={min(WORKERS, 4)}"])
    return rc


def captures() -> list[str]:
    """The captures whose data roots have finished episodes."""
    return sorted(p.name for p in CAPS.iterdir() if p.is_dir() and any((p / "05_episodes").glob("task=pointnav/*")))


def train(rounds: int, episodes: int, grad_steps: int, extra: list[str]) -> int:
    out = RUNS / WORLD
    if (out / "model_card.json").is_file():
        log(f"{out}: done")
        return 0
    resume = ["--resume"] if (out / "checkpoint.pt").is_file() else []
    return run([PY, "-m", "navarena", "train", ROOT, "--out", out, "--rounds", rounds, "--episodes-per-round", episodes,
                "--grad-steps", grad_steps, "--workers", WORKERS, *resume, *extra], RUNS / f"{WORLD}.log")


def agent_args(agent: str) -> list[str]:
    """navarena eval's agent arguments of an agent name: world, loo_<capture>, ft_world (RUNS' runs), a
    registry name, each learned one optionally with SAMPLED."""
    base, sample = (agent[:-len(SAMPLED)], True) if agent.endswith(SAMPLED) else (agent, False)
    if base == "world" or base.startswith(("loo_", "ft_")):
        args = ["--agent", "learned", "--agent-arg", f"checkpoint={RUNS / (WORLD if base == 'world' else base) / 'model.pt'}"]
    else:
        args = ["--agent", base]
    return args + (["--agent-arg", "sample=true"] if sample else [])


def label_of(agent: str) -> str:
    """The evaluation label's agent part: SAMPLED written as _sample."""
    return agent[:-len(SAMPLED)] + "_sample" if agent.endswith(SAMPLED) else agent


def evaluate(jobs: list[tuple[str, Path, str, str]], n: int, per_gpu: int, renderer: str, size: tuple[int, int]) -> int:
    """jobs: (label, root, split, agent) -> EVAL/label/summary.json, per_gpu processes side by side."""
    todo = [j for j in jobs if not (EVAL / j[0] / "summary.json").is_file()]
    log(f"evaluate: {len(todo)} of {len(jobs)} to run")

    def one(job) -> int:
        label, root, split, agent = job
        return run([PY, "-m", "navarena", "eval", root, *agent_args(agent), "--tasks", "pointnav", "--split", split,
                    "--episodes-per-scene", n, "--renderer", renderer, "--width", size[0], "--height", size[1],
                    "--batch-slots", 50, "--quiet", "--out", EVAL / label], EVAL / f"{label}.log", threads(per_gpu))

    with ThreadPoolExecutor(per_gpu) as pool:
        return max([0, *pool.map(one, todo)])


def zeroshot(n: int, per_gpu: int, renderer: str, size, gen_n: int, agents=AGENTS) -> int:
    jobs = [(f"zs_{c}_{label_of(a)}", CAPS / c, "test", a) for c in captures() for a in agents]
    gen = [(f"gen_{a}", ROOT, "test", a) for a in ("world", "pointnav_bc")] if gen_n else []
    return max(evaluate(jobs, n, per_gpu, renderer, size), evaluate(gen, gen_n, per_gpu, renderer, size))


def loo(rounds: int, episodes: int, grad_steps: int, share: float, n: int, per_gpu: int, renderer: str, size,
        control: bool = True, extra: tuple = (), captures_only: bool = False, parallel: int = 1,
        decodings: tuple = ("", SAMPLED)) -> int:
    caps = captures()
    if len(caps) < 2:
        log(f"loo: needs at least 2 captures, has {caps}")
        return 1
    # (label, the captures trained on): one fine-tune per held-out capture, and the control (the same
    # fine-tune on the generated scenes alone: what the extra rounds buy without the captures)
    plans = [(f"loo_{held}", [CAPS / c for c in caps if c != held]) for held in caps]
    if control and not captures_only:
        plans.append((CONTROL, []))
    runs = []
    for label, others in plans:
        out = RUNS / label
        if (out / "model_card.json").is_file():
            continue
        share_args = ["--capture-share", share] if others and not captures_only else []
        roots = others if captures_only else [ROOT, *others]
        cmd = [PY, "-m", "navarena", "train", *roots, "--out", out, "--init", RUNS / WORLD / "model.pt",
               "--first-round", "dagger", "--rounds", rounds, "--episodes-per-round", episodes, "--grad-steps", grad_steps,
               *share_args, "--workers", max(1, WORKERS // max(1, parallel)), *extra]
        runs.append((cmd, RUNS / f"{label}.log"))
    # `parallel` fine-tunes side by side (1: one after the other, each with every worker): three side by
    # side on one 80 GB GPU ran out of its memory (every collector worker holds a renderer of its scene)
    side = max(1, min(parallel, len(runs)))
    with ThreadPoolExecutor(side) as pool:
        rc = max([0, *pool.map(lambda r: run(*r, threads(side)), runs)])
    # a finished run has its card (written last); a run that failed part-way leaves a model.pt (the
    # --init weights, or an earlier round's) that must not be evaluated as the run's
    done = {label for label, _ in plans if (RUNS / label / "model_card.json").is_file()}
    for label, _ in plans:
        if label not in done:
            log(f"loo: {label} did not finish (no model_card.json; see {RUNS / f'{label}.log'}): not evaluated")
    # each finished run evaluated with every decoding ("": greedy; SAMPLED)
    jobs = [(f"loo_{label_of(c + d)}", CAPS / c, "test", f"loo_{c}{d}") for c in caps if f"loo_{c}" in done for d in decodings]
    if control and CONTROL in done:
        jobs += [(f"zs_{c}_{label_of(CONTROL + d)}", CAPS / c, "test", CONTROL + d) for c in caps for d in decodings]
    return max(rc, evaluate(jobs, n, per_gpu, renderer, size))


RUN_ORDER = ("world", "world_sample", CONTROL, f"{CONTROL}_sample", "loo", "loo_sample", "pointnav_bc", "depth_reactive",
             "random")
"""The capture table's columns: zero-shot, the control, leave-one-out, the shipped policy, the references."""


def run_of(label: str, caps: list[str]) -> tuple[str, str] | None:
    """(capture, run) of an evaluation's label: loo_<capture>[_sample] or zs_<capture>_<agent>."""
    for c in sorted(caps, key=len, reverse=True):
        if label in (f"loo_{c}", f"loo_{c}_sample"):
            return c, "loo" + label[len(f"loo_{c}"):]
        if label.startswith(f"zs_{c}_"):
            return c, label[len(f"zs_{c}_"):]
    return None


def paired(a, b) -> dict:
    """Two runs' successes on the episodes both finished without an error: SR of each, the episodes
    only one of them solved, and the two-sided sign test's p over those."""
    from benchmarks.baselines.goal_ablation import sign_test

    a, b = (x[x["error"].isna() | (x["error"] == "")].set_index("episode_id")["sr"] for x in (a, b))
    both = a.index.intersection(b.index)
    a, b = a[both] > 0.5, b[both] > 0.5
    only_a, only_b, p = sign_test(a.tolist(), b.tolist())
    return {"episodes": len(both), "sr": float(a.mean()) if len(both) else None,
            "sr_ref": float(b.mean()) if len(both) else None, "only": only_a, "only_ref": only_b, "p": round(float(p), 4)}


def capture_table(caps: list[str], ref: str = "depth_reactive") -> tuple[list[dict], list[str]]:
    """Per capture and run: SR on the capture's evaluated test episodes, paired with `ref` on the same
    episodes (rows, and the markdown table: capture x run, 'SR (n); +only / -only_ref, p')."""
    import pandas as pd

    res: dict[tuple[str, str], object] = {}
    for d in sorted(EVAL.glob("*/results.parquet")):
        key = run_of(d.parent.name, caps)
        if key:
            res[key] = pd.read_parquet(d)
    runs = [r for r in RUN_ORDER if any(k[1] == r for k in res)] + sorted({k[1] for k in res} - set(RUN_ORDER))
    rows, lines = [], ["| capture | " + " | ".join(runs) + " |", "|---|" + "---:|" * len(runs)]
    for c in caps:
        cells = []
        for r in runs:
            if (c, r) not in res:
                cells.append("-")
                continue
            if r != ref and (c, ref) in res:
                pr = paired(res[(c, r)], res[(c, ref)])
                rows.append({"capture": c, "run": r, "ref": ref, **pr})
                cells.append(f"{pr['sr']:.2f} ({pr['episodes']}); +{pr['only']} / -{pr['only_ref']}, p {pr['p']:.2g}")
            else:
                t = res[(c, r)]
                rows.append({"capture": c, "run": r, "episodes": len(t), "sr": float(t["sr"].mean())})
                cells.append(f"{t['sr'].mean():.2f} ({len(t)})")
        lines.append(f"| {c} | " + " | ".join(cells) + " |")
    return rows, lines


def report(out: Path) -> dict:
    from navcore.io import jsonio

    rows = []
    for s in sorted(EVAL.glob("*/summary.json")):
        d = json.loads(s.read_text())
        m = d["tasks"]["pointnav"]["overall"]
        rows.append({"label": s.parent.name, "root": Path(d["root"]).name, "agent": d["agent"],
                     "agent_args": d.get("agent_args"), "render": d.get("render"), "episodes": m.get("episodes"),
                     **{k: m.get(k) for k in ("sr", "spl", "ne")}, "cr": m.get("collision_rate")})
    cards = {p.parent.name: json.loads(p.read_text()) for p in RUNS.glob("*/model_card.json")}
    res = {"rows": rows, "runs": {k: {"curve": c["curve"], "data": c["data"], "train_seconds": c.get("train_seconds"),
                                      "trained_on": c.get("trained_on"), "sha256": c["sha256"]} for k, c in cards.items()}}
    out.mkdir(parents=True, exist_ok=True)
    lines = ["| run | data | agent | episodes | SR | SPL | CR |", "|---|---|---|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['label']} | {r['root']} | {r['agent']} | {r['episodes']} | {r['sr']:.3f} | {r['spl']:.3f} | "
                     f"{r['cr']:.3f} |")
    table_rows, table = capture_table(captures())
    res["captures"] = table_rows
    (out / "captures_loo.json").write_text(jsonio.dumps(res, indent=1, default=str) + "\n")  # null, never NaN
    lines += ["", "Per capture (SR on its evaluated test episodes; beside depth_reactive on the same episodes: "
              "episodes only this run solved / only depth_reactive solved, two-sided sign test):", "", *table]
    (out / "captures_loo.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return res


def decodings(spec: str) -> tuple[str, ...]:
    """--loo-decoding greedy,sample -> the agent-name suffixes ("", SAMPLED)."""
    names = [d.strip() for d in spec.split(",") if d.strip()]
    bad = sorted(set(names) - {"greedy", "sample"})
    if bad or not names:
        raise SystemExit(f"captures_loo: --loo-decoding {spec!r}: greedy, sample or both")
    return tuple("" if d == "greedy" else SAMPLED for d in dict.fromkeys(names))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="captures_loo", description=__doc__.split("\n\n")[0])
    ap.add_argument("phase", choices=("gen", "cap", "train", "zeroshot", "loo", "report"))
    ap.add_argument("caps", nargs="*", help="cap: NAME=PATH of each capture")
    ap.add_argument("--scenes", type=int, default=128)
    ap.add_argument("--train-scenes", type=int, default=48)
    ap.add_argument("--cap-episodes", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--episodes", type=int, default=2048)
    ap.add_argument("--grad-steps", type=int, default=2000)
    ap.add_argument("--train-arg", action="append", default=[], help="more navarena train arguments (e.g. --depth-noise=0.05)")
    ap.add_argument("--loo-rounds", type=int, default=1)
    ap.add_argument("--loo-episodes", type=int, default=768)
    ap.add_argument("--loo-grad-steps", type=int, default=1000)
    ap.add_argument("--capture-share", type=float, default=0.5)
    ap.add_argument("--no-control", action="store_true", help="loo: without the control fine-tune on the generated scenes alone")
    ap.add_argument("--captures-only", action="store_true",
                    help="loo: fine-tune on the two other captures alone (no generated scenes, no control; no gen phase needed)")
    ap.add_argument("-n", "--episodes-per-capture", type=int, default=100)
    ap.add_argument("--gen-episodes", type=int, default=30, help="zeroshot: per held-out generated scene (0: none)")
    ap.add_argument("--per-gpu", type=int, default=6)
    ap.add_argument("--parallel", type=int, default=1,
                    help="loo: fine-tunes side by side (each gets WORKERS / parallel collector workers; three side by "
                         "side ran out of an 80 GB GPU's memory)")
    ap.add_argument("--agents", default=",".join(AGENTS), help="zeroshot: which of " + ",".join(AGENTS)
                    + f" (a learned one with {SAMPLED}: its moves sampled)")
    ap.add_argument("--loo-decoding", default="greedy,sample", help="loo: evaluate each fine-tune greedy, sampled or both")
    ap.add_argument("--renderer", default="gsplat")
    ap.add_argument("--size", type=int, nargs=2, default=(640, 480))
    ap.add_argument("--out", type=Path, default=Path("data/08_reports"))
    a = ap.parse_args(argv)
    if a.phase == "gen":
        return gen(a.scenes, a.train_scenes)
    if a.phase == "cap":
        return cap(a.caps, a.cap_episodes)
    if a.phase == "train":
        return train(a.rounds, a.episodes, a.grad_steps, a.train_arg)
    if a.phase == "zeroshot":
        return zeroshot(a.episodes_per_capture, a.per_gpu, a.renderer, a.size, a.gen_episodes, a.agents.split(","))
    if a.phase == "loo":
        return loo(a.loo_rounds, a.loo_episodes, a.loo_grad_steps, a.capture_share, a.episodes_per_capture, a.per_gpu,
                   a.renderer, a.size, not a.no_control, a.train_arg, a.captures_only, a.parallel,
                   decodings(a.loo_decoding))
    report(a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
