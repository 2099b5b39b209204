"""``navarena eval ROOT``: an agent in closed loop on the episodes of a data root or a release.

    navarena eval navarena-v1.0.0 --agent oracle --tasks pointnav --split test --episodes-per-scene 5
    navarena eval data --agent my_pkg.policy:Agent --protocol explicit_stop --renderer cpu
    navarena eval navarena-v1.0.0 --agent ws://127.0.0.1:8000 --split eval_zeroshot   # an agent server

Writes OUT/results.parquet (one row per episode: metrics, end reason, error, executed trajectory)
and OUT/summary.json (the metrics per task, overall and per difficulty), and prints the table.
The library's own evaluation, with no pipeline: the pipeline's `evaluate` stage runs the same
environment and metrics (navcore.eval) over a data root's scenes as tasks of its run.
Ctrl-C stops after the episode in flight, and what finished is written and summarised.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from navarena import quick
from navarena.quick import shorten
from navcore.eval.dataset import TASKS, NavDataset


def agent_arg(text: str) -> tuple[str, object]:
    """KEY=VALUE of --agent-arg, the value read as YAML (numbers, booleans, lists; else a string)."""
    import yaml

    key, sep, value = text.partition("=")
    if not sep or not key.isidentifier():
        raise argparse.ArgumentTypeError(f"--agent-arg takes KEY=VALUE, got {text!r}")
    return key, yaml.safe_load(value)


def chosen_episodes(ds: NavDataset, args) -> dict[str, list]:
    """scene id -> the episodes to run, every task of args.tasks; the zero-shot set of a data
    root by its listing (a release ships it as its own split)."""
    listing = None
    if args.split and not ds.is_release:
        try:
            listing = ds.eval_set(args.split)
        except FileNotFoundError:
            listing = None
    scenes = args.scenes or ds.scene_ids()
    out: dict[str, list] = {}
    for sid in scenes:
        for task in args.tasks:
            if sid not in ds.scene_ids(task):
                continue
            if listing is not None:
                ids = set(listing[(listing["task"] == task) & (listing["scene_id"] == sid)]["episode_id"])
                eps = ds.episodes(sid, task, None, args.difficulty, args.episodes_per_scene, ids=ids)
            else:
                eps = ds.episodes(sid, task, args.split, args.difficulty, args.episodes_per_scene)
            if getattr(args, "decoy_goal", False) and eps:  # each shown another goal of its scene (navcore.eval.decoy)
                from navcore.eval.decoy import with_decoys

                eps, none = with_decoys(eps, ds.episodes(sid, task))
                if none:
                    print(f"navarena eval: --decoy-goal: {len(none)} {task} episodes of scene {sid} left out: the scene "
                          f"has no other {task} goal", file=sys.stderr)
            out.setdefault(sid, []).extend(quick.short_episodes(eps))
    return {s: e for s, e in out.items() if e}


def summary_table(summary: dict) -> str:
    """The per-task table printed at the end: SR, SPL, NE, CR, steps, overall and per difficulty (n: the
    episodes measured; errored: those that ended in an agent error, apart)."""
    cols = [("episodes", "n", "{:.0f}"), ("errored", "errored", "{:.0f}"), ("sr", "SR", "{:.3f}"), ("spl", "SPL", "{:.3f}"),
            ("ne", "NE m", "{:.2f}"),
            ("collision_rate", "CR", "{:.3f}"), ("steps", "steps", "{:.0f}"), ("pose_sr", "Pose SR", "{:.3f}"),
            ("stop_sr", "Stop SR", "{:.3f}")]
    fmt = lambda f, v: "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f.format(v)  # noqa: E731
    lines = [f"{'task':10s} {'group':8s} " + " ".join(f"{h:>8s}" for _, h, _ in cols)]
    order = {"overall": 0, "easy": 1, "medium": 2, "hard": 3}
    for task, groups in summary["tasks"].items():
        for g, m in sorted(groups.items(), key=lambda kv: (order.get(kv[0], 9), kv[0])):
            lines.append(f"{task:10s} {g:8s} " + " ".join(f"{fmt(f, m.get(k)):>8s}" for k, _, f in cols))
    return "\n".join(lines)


def write_outputs(rows: list[dict], out: Path, meta: dict) -> dict:
    """results.parquet and summary.json under `out` (each written whole, then renamed)."""
    import numpy as np
    import pyarrow as pa

    plain = [{k: v for k, v in r.items() if k != "trajectory"} for r in rows]
    table = pa.Table.from_pylist(plain) if plain else pa.table({})
    if rows:
        traj = [np.asarray(r["trajectory"], np.float32) for r in rows]
        table = table.append_column("trajectory_x", pa.array([t[:, 0].tolist() for t in traj], pa.list_(pa.float32())))
        table = table.append_column("trajectory_y", pa.array([t[:, 1].tolist() for t in traj], pa.list_(pa.float32())))
    return write_results(table, out, meta)


def write_results(table, out: Path, meta: dict) -> dict:
    """A results table (one row per episode, as results.parquet holds it) -> out/results.parquet and
    out/summary.json (meta plus the metrics per task, overall and per difficulty); the summary."""
    import pyarrow.parquet as pq

    from navcore.eval.metrics import aggregate
    from navcore.io.atomic import atomic_path, write_text_atomic

    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / "results.parquet") as tmp:
        pq.write_table(table, tmp)
    rows = table.drop_columns([c for c in ("trajectory_x", "trajectory_y") if c in table.column_names]).to_pylist()
    tasks = sorted({r["task"] for r in rows}, key=lambda t: TASKS.index(t) if t in TASKS else 99)
    summary = {**meta, "episodes": len(rows),
               "tasks": {t: aggregate([r for r in rows if r["task"] == t]) for t in tasks}}
    clean = json.loads(json.dumps(summary, default=float).replace("NaN", "null"))
    write_text_atomic(out / "summary.json", json.dumps(clean, indent=1) + "\n")
    return clean


def evaluate(args) -> tuple[list[dict], bool, str]:
    """Every chosen episode, scene by scene; (rows, interrupted, why the run stopped early: '' when it
    did not). Ctrl-C and SIGTERM stop it after the episode in flight; an agent server that cannot be
    reached for several episodes in a row stops it too."""
    import signal
    from functools import partial

    from navcore.eval.loop import AgentUnreachable, SceneEpisodes, evaluate_episodes, evaluate_scenes
    from navcore.io.tool_progress import ToolProgress
    from navcore.seeds import stream_seed

    ds = NavDataset(args.root, args.embodiment)
    plan = chosen_episodes(ds, args)
    total = sum(map(len, plan.values()))
    if not total:
        raise SystemExit(f"navarena eval: no episodes in {ds.path} for tasks {args.tasks}, split {args.split}, "
                         f"difficulty {args.difficulty} (scenes: {', '.join(ds.scene_ids()) or 'none'})")
    cfg = ds.env_config(protocol=args.protocol, width=args.width, height=args.height, render=not args.no_render)
    rows: list[dict] = []
    interrupted, stopped = False, ""
    budget = {(e.task, e.episode_id, e.scene_id): int(e.max_steps) for eps in plan.values() for e in eps}

    def terminate(signum, frame):  # SIGTERM (a batch system's, kill): as Ctrl-C, keep what finished
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, terminate)
    with ToolProgress("eval", total, args.quiet, budget=sum(budget.values())) as progress:

        def done(row: dict, frames) -> None:
            rows.append(row)
            progress.advance(frames=int(row["steps"]), budget=budget.get((row["task"], row["episode_id"], row["scene_id"]), 0))

        def context(sid):
            return ds.scene_context(sid, render=not args.no_render, renderer=args.renderer)

        seed = {sid: stream_seed(args.seed, sid, "evaluate") % 2**31 for sid in plan}
        try:
            if args.batch_slots > 1:  # every scene through one batch: several in flight keep the slots full
                evaluate_scenes([SceneEpisodes(eps, partial(context, sid), seed[sid]) for sid, eps in plan.items()],
                                args.agent, cfg, timeout=args.timeout, agent_args=dict(args.agent_arg),
                                batch_slots=args.batch_slots, scenes_at_once=args.scenes_at_once, on_result=done)
            else:
                for sid, eps in plan.items():
                    evaluate_episodes(context(sid), eps, args.agent, cfg, seed=seed[sid], timeout=args.timeout,
                                      agent_args=dict(args.agent_arg), on_result=done)
        except KeyboardInterrupt:
            interrupted = True
        except AgentUnreachable as e:
            stopped = str(e)
        finally:
            signal.signal(signal.SIGTERM, previous)
    rank = {(e.task, e.episode_id, e.scene_id): k for k, e in enumerate(e for eps in plan.values() for e in eps)}
    rows.sort(key=lambda r: rank.get((r["task"], r["episode_id"], r["scene_id"]), len(rank)))  # the plan's order
    return rows, interrupted, stopped


def check_agent(spec: str) -> str | None:
    """A user's own agent (`package.module:Class`) resolved before anything runs, from the current
    folder as `python -m` does (it goes first on the import path); the one-line reason when it cannot
    be, else None. Registry names and agent servers are left to the run."""
    import os

    from navcore.eval.agents import AGENTS
    from navcore.registry import load_entry

    if spec in AGENTS or spec.startswith(("ws://", "wss://")) or ":" not in spec:
        return None
    if os.getcwd() not in sys.path and "" not in sys.path:
        sys.path.insert(0, os.getcwd())
    try:
        load_entry(spec)
    except ImportError as e:
        name = getattr(e, "name", None) or spec.partition(":")[0]
        return (f"--agent {spec}: cannot import {name!r} ({e}), looked for in the current folder ({os.getcwd()}) "
                "and the environment's packages")
    except AttributeError as e:
        return f"--agent {spec}: {e}"
    return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="navarena eval", description="Evaluate an agent in closed loop on the episodes "
                                 "of a data root or a release folder (navcore.eval: the pipeline's environment and metrics).")
    ap.add_argument("root", help="a release folder (with release.json) or a data root")
    ap.add_argument("--agent", default="oracle", help="a registered agent (oracle, random, depth_reactive, ...), "
                    "package.module:Class, or ws://host:port (an agent server)")
    ap.add_argument("--agent-arg", action="append", default=[], metavar="K=V", type=agent_arg,
                    help="an argument of the agent (a YAML value; repeatable), e.g. checkpoint=run/model.pt")
    ap.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS)
    ap.add_argument("--split", default=None, help="only this split (train, val_seen, val_unseen, test, eval_zeroshot)")
    ap.add_argument("--difficulty", default=None, choices=("easy", "medium", "hard"))
    ap.add_argument("--episodes-per-scene", type=int, default=None, metavar="N", help="at most this many per scene and task")
    ap.add_argument("--scenes", nargs="*", default=None, metavar="ID", help="scene ids (default: all)")
    ap.add_argument("--protocol", default="distance", choices=("distance", "explicit_stop"))
    ap.add_argument("--renderer", default="auto", choices=("auto", "cpu", "gsplat"))
    ap.add_argument("--no-render", action="store_true", help="no RGB-D (agents that need only the task and pose)")
    ap.add_argument("--width", type=int, default=None, help="image width (default: the embodiment's)")
    ap.add_argument("--height", type=int, default=None)
    ap.add_argument("--batch-slots", type=int, default=1, metavar="N", help="episodes stepped together (one render call per step)")
    ap.add_argument("--scenes-at-once", type=int, default=4, metavar="N",
                    help="with --batch-slots: scenes in flight at once, to keep the slots full")
    ap.add_argument("--embodiment", default=None, metavar="NAME", help="the costmap of this embodiment (data roots with several)")
    ap.add_argument("--seed", type=int, default=0, help="seed of stochastic agents")
    ap.add_argument("--decoy-goal", action="store_true",
                    help="the agent sees another goal of the scene (goal gain check)")
    ap.add_argument("--timeout", type=float, default=30.0, help="agent servers: seconds to wait for each action")
    ap.add_argument("--out", default=None, help="output folder (default: navarena_eval/{agent}_{protocol})")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    args = ap.parse_args(argv)
    if args.batch_slots < 1 or args.scenes_at_once < 1:
        ap.error(f"--batch-slots {args.batch_slots} and --scenes-at-once {args.scenes_at_once}: each at least 1")
    shorten(args, quick.EVAL, "navarena eval")
    if quick.quick():
        print(f"navarena eval: NAVARENA_QUICK is set: at most {quick.EVAL_STEPS} steps an episode", file=sys.stderr)
    import re

    bad = check_agent(args.agent)
    if bad:
        print(f"navarena eval: {bad}", file=sys.stderr)
        return 2

    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{args.agent}_{args.protocol}{'_decoy' if args.decoy_goal else ''}").strip("_")
    out = Path(args.out or Path("navarena_eval") / name)
    try:
        rows, interrupted, stopped = evaluate(args)
    except (FileNotFoundError, KeyError, ValueError) as e:
        print(f"navarena eval: {e}", file=sys.stderr)
        return 2
    meta = {"root": str(Path(args.root).resolve()), "agent": args.agent, "agent_args": dict(args.agent_arg),
            "protocol": args.protocol,
            "split": args.split, "difficulty": args.difficulty, "episodes_per_scene": args.episodes_per_scene,
            "seed": args.seed, "decoy_goal": args.decoy_goal, "render": None if args.no_render else
            {"width": args.width, "height": args.height, "renderer": args.renderer},
            "interrupted": interrupted, "stopped": stopped or None}
    if not rows:
        why = f"stopped: {stopped}" if stopped else "interrupted"
        print(f"navarena eval: {why} before any episode finished; nothing written", file=sys.stderr)
        return 3 if stopped else 130
    summary = write_outputs(rows, out, meta)
    print(summary_table(summary))
    errors = sum(bool(r["error"]) for r in rows)
    print(f"{len(rows)} episodes{' (interrupted)' if interrupted else ''}, {errors} errored (apart: not in the "
          f"metrics); results: {out / 'results.parquet'}, {out / 'summary.json'}")
    if stopped:
        print(f"navarena eval: stopped: {stopped}; the {len(rows) - errors} episodes that finished are kept in {out}",
              file=sys.stderr)
        return 3
    return 130 if interrupted else 0


if __name__ == "__main__":
    sys.exit(main())
