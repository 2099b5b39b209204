"""The learned baselines' reference run on a GPU machine (docs/evaluation.md, "Baselines"), as
phases that each skip what is already done, so that a run cut by a time limit goes on where it
stopped when started again:

    python -m benchmarks.baselines.reference all --deadline 560     # every phase, stopping in time
    python -m benchmarks.baselines.reference data | train | scaling | eval | pack OUT

- data:    SCENES (160) generated scenes with the TASKS' episodes (pointnav,imagenav,objectnav;
           ObjectNav's goals from the generated scenes' labels), 10 % held out for test (the
           zero-shot set), 5 % for val_unseen; then the zero-shot set is drawn (the evaluate stage,
           oracle, unrendered).
- train:   the reference run of each of the TRAIN_TASKS (default TASKS), <task>_bc (navarena
           train's defaults; ROUNDS rounds, or per track as pointnav=5,imagenav=3), resumable. A track of TASKS left out of TRAIN_TASKS is
           evaluated with its shipped model (navcore/models/<task>_bc).
- scaling: the PointNav recipe on the first 8, 32 and 128 training scenes and on all of them, with
           the same episodes and gradient steps (SCALE_ROUNDS rounds), each checked on the test
           split. Runs alongside train: the GPUs are shared round-robin, the CPU workers split
           between runs by the rounds each has to do.
- eval:    each track's zero-shot set at 640 x 480 (gsplat) for the learned policy (a run trained
           here from its run folder, else the shipped model; nothing is shipped by the run:
           `cards ship` or `cards ship --trial` after reading the figures), distance and
           explicit_stop, then for depth_reactive (last: its failures run the whole step budget),
           one navarena eval per scene and agent, several per GPU; random and the oracle
           unrendered (they read no image). The parts are merged into one results.parquet and
           summary.json per agent, track and protocol, with the steps per second of each part.
- pack:    the cards, the shipped model and the summaries into OUT/baselines.tgz (the device's
           $OUT).

make setup-gpu first (WHEELS=dir offline). Paths: ROOT (data/baselines), RUNS (data/runs), EVAL
(data/baseline_eval); WORKERS (CPU cores - 2); SCENE_IDS (only these of the SCENES: the zero-shot
set's scenes for a call that only evaluates finished runs); TRAIN_SCENES (N: the held-out scenes and the first N
training scenes, a run sized for one GPU on the same zero-shot episodes); SPLIT (the eval phase's split, eval_zeroshot; empty:
every episode of ROOT); EVAL_TASKS and AGENTS (which tracks and agents the eval phase measures: a new
ImageNav run alone is TRAIN_TASKS=imagenav EVAL_TASKS=imagenav AGENTS=learned, its table completed with
an earlier call's other agents on the same episodes); PROTOCOLS (the learned policies', default
distance,explicit_stop; the distance protocol's scenes run first); EVAL_PER_GPU (4: navarena eval processes side by side per
GPU). The learned policies on real captures, from a
release folder of them (no baseline was trained on a real scene): ROOT=RELEASE SPLIT= TASKS=pointnav,imagenav
TRAIN_TASKS=imagenav ... reference eval.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tarfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(os.environ.get("ROOT", "data/baselines"))
RUNS = Path(os.environ.get("RUNS", "data/runs"))
EVAL = Path(os.environ.get("EVAL", "data/baseline_eval"))
SCENES = int(os.environ.get("SCENES", "160"))
ROUNDS = os.environ.get("ROUNDS", "")  # N, or task=N,...; a track not named: navarena train's default


def rounds(task: str) -> int:
    """The reference run's rounds for `task` (ROUNDS: one number for every track, or task=N pairs)."""
    from navcore.baselines.train import TrainConfig

    if ROUNDS.strip().isdigit():
        return int(ROUNDS)
    pairs = dict(p.split("=", 1) for p in ROUNDS.replace(" ", "").split(",") if "=" in p)
    return int(pairs.get(task, TrainConfig().rounds))


SCALE_ROUNDS = int(os.environ.get("SCALE_ROUNDS", "2"))
SCALE_SIZES = [int(s) for s in os.environ.get("SCALE_SIZES", "8,32,128,0").split(",") if s]  # 0: every training scene
WORKERS = int(os.environ.get("WORKERS", str(max(1, (os.cpu_count() or 2) - 2))))
TRAIN_ARGS = os.environ.get("TRAIN_ARGS", "").split()  # more navarena train options (a quick trial's smaller sizes)
EVAL_ARGS = os.environ.get("EVAL_ARGS", "").split()  # more navarena eval options
PY = sys.executable
TASKS = os.environ.get("TASKS", "pointnav,imagenav,objectnav").split(",")
# the tracks whose reference run trains here; a track left out is evaluated with its shipped model
TRAIN_TASKS = os.environ.get("TRAIN_TASKS", ",".join(TASKS)).split(",")
# the tracks (default TASKS) and agents (learned, depth_reactive, random, oracle; default all) the eval phase
# measures: a new run of one track against the other agents' tables of an earlier call on the same episodes
EVAL_TASKS = os.environ.get("EVAL_TASKS", ",".join(TASKS)).split(",")
AGENTS = [a for a in os.environ.get("AGENTS", "learned,depth_reactive,random,oracle").split(",") if a]
# the learned policies' protocols (default both): distance alone is the tracks' SR and ImageNav's Pose SR
PROTOCOLS = [p for p in os.environ.get("PROTOCOLS", "distance,explicit_stop").split(",") if p]
# navarena eval processes side by side per GPU in the eval phase (each with its share of the CPU cores)
EVAL_PER_GPU = int(os.environ.get("EVAL_PER_GPU", "4"))
TEST_SHARE = 0.1  # the generated scenes held out for test (the zero-shot set's), beside val_unseen's default share
DATA = [f"data_root={ROOT}", f"scenes.count={SCENES}", f"task=[{','.join(TASKS)}]",
        f"semantics.enabled={'true' if 'objectnav' in TASKS else 'false'}", f"episodes.scene_splits.test={TEST_SHARE}",
        "executor.dashboard=false"]
# SCENE_IDS=a,b,...: only these scenes of the SCENES (an evaluation-only call builds just the zero-shot set's scenes:
# a scene's split is a hash of its id, its episodes its own seed's, so they come out as in the whole set)
SCENE_IDS = [s for s in os.environ.get("SCENE_IDS", "").split(",") if s]
# TRAIN_SCENES=N: every held-out scene of the SCENES and their first N training scenes (a run sized for one GPU
# with the whole set's zero-shot and val_unseen episodes: scene ids computed as the episodes stage splits them)
TRAIN_SCENES = int(os.environ.get("TRAIN_SCENES", "0") or 0)


def held_out_and_first_train(count: int, train: int) -> list[str]:
    """The ids of the catalog's first `count` generated scenes that the episodes stage holds out (val_unseen and
    test, with the data phase's test share) and of the first `train` of the others, in catalog order."""
    from navcore.io.catalog import Catalog
    from stages.episodes.config import EpisodesConfig
    from stages.episodes.generate import scene_split

    splits = {**EpisodesConfig().scene_splits, "test": TEST_SHARE}
    scenes = Catalog(Path(__file__).resolve().parents[2] / "catalogs/synthetic.yaml", ROOT, synthetic_count=count).scenes
    held = [s.scene_id for s in scenes if scene_split(s.scene_id, splits) is not None]
    return held + [s.scene_id for s in scenes if scene_split(s.scene_id, splits) is None][:train]


if TRAIN_SCENES and not SCENE_IDS:
    SCENE_IDS = held_out_and_first_train(SCENES, TRAIN_SCENES)
# the split the eval phase measures; SPLIT= (empty): every episode of ROOT, e.g. a release of real captures, whose
# scenes no baseline was trained on (their split names only the scene's share of a dataset made from them)
SPLIT = os.environ.get("SPLIT", "eval_zeroshot")
DATA += [f"scenes.ids=[{','.join(SCENE_IDS)}]"] if SCENE_IDS else []
RENDERED = [("{task}_bc", "distance"), ("{task}_bc", "explicit_stop"), ("depth_reactive", "distance")]
UNRENDERED = [("random", "distance"), ("oracle", "distance")]


class Deadline:
    def __init__(self, seconds: float | None):
        self.end = time.monotonic() + seconds if seconds else None

    def left(self) -> float | None:
        return None if self.end is None else max(0.0, self.end - time.monotonic())

    def over(self) -> bool:
        return self.end is not None and self.left() < 5


def run(cmd: list[str], deadline: Deadline, log: Path | None = None, env: dict | None = None) -> int:
    """A command in its own process group, killed (the whole group) at the deadline; its output
    to `log` or ours. 124 when cut."""
    print("$", " ".join(cmd), flush=True)
    out = open(log, "w") if log else None
    p = subprocess.Popen(cmd, stdout=out or None, stderr=subprocess.STDOUT if out else None,
                         env={**os.environ, **(env or {})}, start_new_session=True)
    try:
        return p.wait(timeout=deadline.left())
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGTERM)
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        return 124
    finally:
        if out:
            out.close()


def gpus() -> int:
    try:
        import torch

        return max(1, torch.cuda.device_count())
    except ImportError:
        return 1


def threads(processes: int) -> dict:
    """The CPU threads of each of `processes` running side by side. Without it every process's torch
    and BLAS take all cores: 8 evaluations on 2 GPUs and 32 cores ran at 16.7 steps/s each at 640 x
    480, against 219 for one alone on one GPU (GPU sharing explains at most 4 x of that; not yet
    re-measured with this split)."""
    k = str(max(1, (os.cpu_count() or 2) // max(1, processes)))
    return {"OMP_NUM_THREADS": k, "MKL_NUM_THREADS": k, "OPENBLAS_NUM_THREADS": k, "NUMBA_NUM_THREADS": k}


def rotated(i: int, n: int) -> str:
    """CUDA_VISIBLE_DEVICES starting at GPU i (the process's cuda:0 is GPU i; workers go round)."""
    return ",".join(str((i + k) % n) for k in range(n))


def data(deadline: Deadline) -> int:
    done = ROOT / ".reference_data_done"
    if done.is_file():
        return 0
    rc = run([PY, "-m", "pipeline", *DATA, "stages=[episodes]", f"executor.n_workers={WORKERS}"], deadline)
    if rc == 0:  # the zero-shot set: drawn by the evaluate stage from the test split's scenes
        rc = run([PY, "-m", "pipeline", *DATA, "stages=[evaluate]", "evaluate.split=eval_zeroshot",
                  f"evaluate.tasks=[{','.join(TASKS)}]", "evaluate.agent=oracle", "evaluate.render=false"], deadline,
                 log=ROOT.parent / "reference_draw.log")
    if rc == 0:
        done.write_text("done\n")
    return rc


def finished(run_dir: Path, rounds: int) -> bool:
    card = run_dir / "model_card.json"
    return card.is_file() and len(json.loads(card.read_text())["curve"]) >= rounds


def train_jobs(which: str) -> list[tuple[Path, list[str], int]]:
    """(run folder, navarena train arguments, rounds) of the reference run and/or the scaling runs."""
    jobs = []
    if which in ("train", "all"):
        jobs += [(RUNS / f"{task}_bc", ["--task", task], rounds(task)) for task in TRAIN_TASKS]
    if which in ("scaling", "all"):
        for n in SCALE_SIZES:
            extra = ["--val-split", "test", "--val-episodes", "160"] + (["--scenes", str(n)] if n else [])
            jobs.append((RUNS / f"scale_{n or 'all'}", extra, SCALE_ROUNDS))
    return [j for j in jobs if not finished(j[0], j[2])]


def train(deadline: Deadline, which: str) -> int:
    """The training runs side by side: the CPU workers split by rounds still to do, GPUs rotated."""
    jobs = train_jobs(which)
    if not jobs:
        return 0
    n_gpu, weights = gpus(), [r for _, _, r in jobs]
    RUNS.mkdir(parents=True, exist_ok=True)

    def one(i):
        out, extra, rounds = jobs[i]
        workers = max(2, WORKERS * weights[i] // sum(weights))
        return run([PY, "-m", "navarena", "train", str(ROOT), "--out", str(out), "--resume", "--rounds", str(rounds),
                    "--workers", str(workers), *extra, *TRAIN_ARGS], deadline, log=out.with_suffix(".log"),
                   env={"CUDA_VISIBLE_DEVICES": rotated(i, n_gpu), **threads(len(jobs))})

    with ThreadPoolExecutor(len(jobs)) as pool:
        rcs = list(pool.map(one, range(len(jobs))))
    for (out, _, _), rc in zip(jobs, rcs):
        print(f"{out.name}: rc {rc}; " + "".join(open(out.with_suffix('.log')).readlines()[-1:]).strip(), flush=True)
    return max(rcs)


def test_scenes() -> list[str]:
    from navcore.eval.dataset import NavDataset

    ds = NavDataset(ROOT)
    return sorted(set(ds.eval_set(SPLIT)["scene_id"])) if SPLIT == "eval_zeroshot" else ds.scene_ids()


def evaluate(deadline: Deadline, per_gpu: int = EVAL_PER_GPU) -> int:
    """Each track's zero-shot set for every agent (see the module docstring), merged per agent,
    track and protocol."""
    from navcore.baselines.agent import MODELS

    trained = [t for t in TRAIN_TASKS if finished(RUNS / f"{t}_bc", rounds(t))]
    tracks = [t for t in TASKS if t in EVAL_TASKS and
              (t in trained or (t not in TRAIN_TASKS and (MODELS / f"{t}_bc").is_dir()))]
    if not tracks:
        print("eval: no reference run has finished its rounds and no track uses a shipped model", flush=True)
        return 1
    scenes, n_gpu = test_scenes(), gpus()
    parts = []  # (folder name, agent arguments, task, protocol, scene or None, more arguments)
    for task in tracks:
        # a run trained here is measured from its own folder; shipping it (cards ship, or ship --trial when it
        # loses to random) is decided on its figures, never before them
        model = RUNS / f"{task}_bc" / "model.pt" if task in trained else MODELS / f"{task}_bc" / "model.pt"
        learned = ["--agent", "learned", "--agent-arg", f"checkpoint={model}"]
        for agent, proto in RENDERED:
            name = agent.format(task=task)
            is_learned = name == f"{task}_bc"
            if ("learned" if is_learned else name) not in AGENTS or (is_learned and proto not in PROTOCOLS):
                continue
            args = learned if is_learned else ["--agent", name]
            for sid in scenes:
                parts.append((f"{name}_{task}_{proto}", args, task, proto, sid,
                              ["--scenes", sid, "--width", "640", "--height", "480", "--renderer", "gsplat",
                               "--batch-slots", "64"]))
        for agent, proto in UNRENDERED:
            if agent not in AGENTS:
                continue
            parts.append((f"{agent}_{task}_{proto}", ["--agent", agent], task, proto, None,
                          ["--no-render", "--batch-slots", "64"]))
    # unrendered first, then the learned policies scene by scene, the distance protocol's every scene before
    # explicit_stop's, then depth_reactive (its failures run the whole budget: the dearest part); a cut keeps whole
    # scenes, and the distance table whole first
    parts.sort(key=lambda p: (p[4] is not None, p[0].startswith("depth_reactive"), p[3] != "distance", p[4] or ""))
    todo = [p for p in parts if not (EVAL / "parts" / p[0] / (p[4] or "all") / "summary.json").is_file()]
    timing: dict = json.loads((EVAL / "timing.json").read_text()) if (EVAL / "timing.json").is_file() else {}

    def one(k):
        name, agent, task, proto, sid, extra = todo[k]
        out = EVAL / "parts" / name / (sid or "all")
        out.parent.mkdir(parents=True, exist_ok=True)
        t = time.perf_counter()
        rc = run([PY, "-m", "navarena", "eval", str(ROOT), *agent, "--protocol", proto, *(["--split", SPLIT] if SPLIT else []),
                  "--tasks", task, "--quiet", *extra, *EVAL_ARGS, "--out", str(out)], deadline,
                 log=out.with_suffix(".log"), env={"CUDA_VISIBLE_DEVICES": str(k % n_gpu), **threads(per_gpu * n_gpu)})
        return k, rc, time.perf_counter() - t

    t0 = time.perf_counter()
    with ThreadPoolExecutor(max(1, per_gpu * n_gpu)) as pool:
        results = list(pool.map(one, range(len(todo))))
    if todo:
        timing.setdefault("phases", []).append({"parts": len(todo), "processes": per_gpu * n_gpu, "gpus": n_gpu,
                                                "seconds": round(time.perf_counter() - t0, 1)})
    for k, rc, secs in results:
        if rc == 0:
            timing[f"{todo[k][0]}/{todo[k][4] or 'all'}"] = round(secs, 1)
    (EVAL / "timing.json").write_text(json.dumps(timing, indent=1) + "\n")
    merge(timing)
    return max([rc for _, rc, _ in results] or [0])


def merge(timing: dict) -> None:
    """Each agent, track and protocol's parts -> EVAL/<agent>_<task>_<protocol>/{results.parquet,
    summary.json}, with its steps and steps per second (a part's wall time includes its process
    start)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from navarena.evaluate import write_results

    for folder in sorted(p for p in (EVAL / "parts").glob("*") if p.is_dir()):
        files = sorted(folder.glob("*/results.parquet"))
        if not files:
            continue
        table = pa.concat_tables([pq.read_table(f) for f in files]).sort_by([("scene_id", "ascending"),
                                                                           ("episode_id", "ascending")])
        first = json.loads((files[0].parent / "summary.json").read_text())
        secs = sum(timing.get(f"{folder.name}/{f.parent.name}", 0.0) for f in files)  # parts' wall seconds
        steps = int(sum(table["steps"].to_pylist()))
        meta = {k: first[k] for k in ("root", "agent", "agent_args", "protocol", "split", "difficulty",
                                      "episodes_per_scene", "seed", "render")}
        suffix = f"_{table['task'][0].as_py()}_{first['protocol']}"
        meta["label"] = folder.name[:-len(suffix)] if folder.name.endswith(suffix) else folder.name
        meta.update({"interrupted": False, "parts": len(files), "steps_total": steps, "part_seconds": round(secs, 1),
                     "steps_per_s_per_process": round(steps / secs, 1) if secs else None})
        write_results(table, EVAL / folder.name, meta)
        print(f"{folder.name}: {table.num_rows} episodes from {len(files)} parts", flush=True)


def pack(out: Path) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    f = out / "baselines.tgz"
    with tarfile.open(f, "w:gz") as tar:
        for p in sorted(RUNS.glob("*/model_card.json")) + sorted(RUNS.glob("*.log")):
            tar.add(p, arcname=str(p.relative_to(RUNS.parent)))
        for p in sorted(RUNS.glob("*/model.pt")):  # a few MB each
            tar.add(p, arcname=str(p.relative_to(RUNS.parent)))
        for p in sorted(EVAL.glob("*/summary.json")) + sorted(EVAL.glob("*/results.parquet")) + \
                sorted(EVAL.glob("timing.json")):
            tar.add(p, arcname=str(p.relative_to(EVAL.parent)))
        for p in sorted(EVAL.glob("parts/*/*.log")):
            tar.add(p, arcname=str(p.relative_to(EVAL.parent)))
    return f


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("phase", choices=("all", "data", "train", "scaling", "eval", "pack"))
    ap.add_argument("out", nargs="?", type=Path, default=None, help="pack: the folder of baselines.tgz")
    ap.add_argument("--deadline", type=float, default=None, help="seconds from now: phases stop (and resume later)")
    a = ap.parse_args(argv)
    deadline = Deadline(a.deadline)
    t0 = time.perf_counter()
    rc = 0
    if a.phase in ("all", "data"):
        rc = data(deadline)
        print(f"[{time.perf_counter() - t0:.0f} s] data: rc {rc}", flush=True)
    if rc == 0 and a.phase in ("all", "train", "scaling") and not deadline.over():
        rc = train(deadline, a.phase)
        print(f"[{time.perf_counter() - t0:.0f} s] {a.phase}: rc {rc}", flush=True)
    if rc == 0 and a.phase in ("all", "eval") and not deadline.over():
        rc = evaluate(deadline)
        print(f"[{time.perf_counter() - t0:.0f} s] eval: rc {rc}", flush=True)
    if a.phase == "pack" or (a.phase == "all" and a.out):
        print(pack(a.out or Path(os.environ.get("OUT", "."))))
    return rc


if __name__ == "__main__":
    sys.exit(main())
