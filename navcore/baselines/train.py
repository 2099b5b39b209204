"""navarena train: a learned PointNav, ImageNav or ObjectNav baseline from a data root or a release
(behaviour cloning, then DAgger).

    navarena train data --out runs/pointnav_bc                  # defaults: 1 BC round + 4 DAgger rounds
    navarena train data --out runs/pn --rounds 1                # behaviour cloning only
    navarena train data --out runs/pn --resume                  # go on from the last finished round
    navarena train data --out runs/objectnav_bc --task objectnav   # RGB-D + the goal category
    navarena train captures --out runs/pn_real --init pointnav_bc  # fine-tune a shipped baseline

Round 0 (behaviour cloning): the expert (the costmap's geodesic oracle, navcore.nav.oracle: the
same one that made the stored action sequences) drives the training episodes in the batched
environment; every step is rendered at the expert's pose and labelled with its action.
Rounds 1..: DAgger. The learner drives (the expert's action is executed instead with probability
beta^round), and every state it visits is labelled with the expert's action there: the geodesic
field gives the oracle's action at any pose, so the learner is taught to recover from its own
mistakes. The rounds' data are aggregated and the network is trained on all of it.
Episodes run under explicit_stop, so the expert's STOP inside the goal region is learned.
ObjectNav's and ImageNav's expert searches (navcore.nav.search; --expert): until the goal (an
instance of the category, the goal image's place) has been in its camera's view it drives to the
nearest unseen free space, then it is the oracle. The oracle alone knows where the goal is, which a
policy that sees only its camera cannot imitate.

After each round the checkpoint is evaluated in closed loop on held-out episodes (the val_unseen
split's scenes, else the test split's), and the run folder gets:
    model.pt                 the policy (navcore.baselines.checkpoint; weights_only loading): the
                             round with the best held-out check (--keep best) or the last one
    rounds/best.pt           the best checked round's weights so far
    model_card.json / .md    data, config, seed, per-round curve (loss, SR, SPL), timings
    rounds/round_<r>.npz     the round's labelled steps (resume reads them back)
    checkpoint.pt            network + optimiser + round (resume)
Deterministic for a seed on one device (the CPU renderer; gsplat's GPU sums are not bitwise
reproducible).
"""
from __future__ import annotations

import math
import os
import platform
import time
from collections import Counter
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch
from torch import nn

from navcore.baselines.agent import default_device
from navcore.baselines.checkpoint import load_checkpoint, save_checkpoint
from navcore.baselines.model import NO_ACTION, NavNet, NavSpec, goal_input, observation_input, parameter_count
from navcore.eval.dataset import open_dataset
from navcore.io import jsonio
from navcore.io.atomic import atomic_path, write_text_atomic
from navcore.nav.actions import STOP
from navcore.nav.oracle import DiscreteOracle
from navcore.nav.poses import goal_in_robot_frame
from navcore.nav.search import SearchingExpert
from navcore.seeds import stream_seed

SEARCHING_TRACKS = ("objectnav", "imagenav")
"""The tracks whose default (auto) labelling expert searches: their goal need not be in view."""


def searches(task: str, expert: str | None) -> bool:
    """Whether a run's labelling expert searches: expert=search. A run's config records the expert
    `auto` resolved to; cards written before that hold `auto`, which then searched on ObjectNav
    alone, and a run from before --expert (None) used the geodesic oracle."""
    return expert == "search" or (expert == "auto" and task == "objectnav")


@dataclass
class TrainConfig:
    """Every setting of a training run (recorded in the model card)."""

    task: str = "pointnav"
    """pointnav | imagenav | objectnav: the track (its network's inputs: navcore.baselines.model)."""
    rounds: int = 5
    """Round 0 is behaviour cloning; rounds 1.. are DAgger."""
    first_round: str = "bc"
    """bc | dagger: what round 0 is. dagger (with --init): the init network drives round 0 as a first
    DAgger round would (beta^1), so a fine-tune spends its rounds on the learner's own mistakes, not
    on more of the expert's rollouts the init network was trained on already."""
    episodes_per_round: int = 3072
    """Training episodes collected per round (drawn over the training scenes)."""
    beta: float = 0.5
    """DAgger: probability beta^round of executing the expert's action instead of the learner's."""
    expert: str = "auto"
    """geodesic | search | auto: the labelling expert. geodesic: the oracle that knows where the goal
    is; search (navcore.nav.search): looks for the goal until it has been in view, then the oracle,
    so its actions follow from what the camera saw. auto: search for ObjectNav and ImageNav,
    geodesic for PointNav (whose goal vector says where to go); resolved when the config is made,
    so the model card names the expert used."""
    view_overlap: float = 0.5
    """ImageNav's searching expert counts the goal as found once its camera sees this share of what
    the goal image shows (navcore.nav.search, goal_view), which a policy can recognise; 0: once it has
    glimpsed the floor where the goal image was taken, as runs before this setting did (a median 6
    steps into an episode: the rest of its labels then came from the geodesic oracle, which the
    student cannot infer, and the trained policy turned in place)."""
    stop_veto: bool = True
    """DAgger: a learner's STOP where the expert does not stop is not executed (the expert's action is),
    so the episode goes on and each false stop along it is labelled; False: the STOP ends the
    episode as in evaluation, and an episode teaches at most one "do not stop here". The ObjectNav
    policy's failures under explicit_stop were STOPs a median 3.9 m from any goal (388 of 600)."""
    max_learner_steps: int = 400
    """A learner-driven episode is cut after this many steps (its labels are kept)."""
    grad_steps: int = 2000
    """Gradient steps after each round's collection."""
    batch_episodes: int = 32
    """Episodes (whole sequences) per gradient step."""
    encode_chunk: int = 1024
    """Frames encoded at once in a gradient step, their activations recomputed in the backward pass
    (NavNet.forward's chunk; 0: every frame of the batch at once). Bounds the encoder's memory: 32
    ImageNav episodes padded to the longest (up to 12,800 frames) through the ResNet-9 at 128 x 96 at
    once took 65 GB of an 80 GB H100 and ran it out of memory. The price: the encoder runs forward
    twice in a step whose batch holds more frames than this."""
    lr: float = 5e-4
    weight_decay: float = 1e-5
    depth_noise: float = 0.0
    """Training augmentation of the depth input (0: off): each pixel's depth times (1 + depth_noise x a
    standard normal draw), and that share of pixels read as 'nothing hit' (holes), as a real sensor or
    a sparse capture's render gives. Drawn anew at every gradient step (the stored frames stay clean)."""
    rgb_noise: float = 0.0
    """Training augmentation of the RGB input and the goal image (0: off): per frame a brightness and
    a contrast factor 1 + rgb_noise x a standard normal draw, plus per-pixel noise of rgb_noise / 2."""
    aux_weight: float = 1.0
    """Weight of the aux_goal head's loss (mean squared error of the goal's encoded position) beside
    the actions' cross-entropy; a network without the head ignores it."""
    slots: int = 64
    """Episodes stepped together per scene (one render call per step)."""
    width: int = 160
    height: int = 120
    """Render size of the training frames (the network pools them to its own input size)."""
    train_split: str = "train"
    val_split: str | None = None
    """Held-out episodes for the per-round closed-loop check (None: val_unseen if present, else test)."""
    val_episodes: int = 64
    keep: str = "best"
    """best | last: the final model.pt is the round with the best held-out check (check_score: SR,
    with ObjectNav's Stop SR averaged in, then SPL; the later round on a tie) or the last round.
    DAgger rounds need not improve: a round whose learner drove lost for most of its episodes can be
    worse than the one before."""
    scenes: int | None = None
    """Use the first N training scenes (the scene-scaling runs); None: all."""
    capture_share: float | None = None
    """The share of each round's episodes drawn from the training scenes outside the generated group
    (`synthetic`: real captures trained on beside generated scenes), spread evenly over them; None:
    every training scene alike (a few captures among a hundred generated scenes would get a few
    per cent)."""
    init: str | None = None
    """Start from these weights instead of random ones (fine-tuning): a checkpoint file of the same
    track, or a shipped baseline's name (navcore/models, sha256-checked). The network takes the
    checkpoint's spec; the card records it and its sha256. E.g. pointnav_bc on the training episodes
    of real captures."""
    workers: int = 0
    """Collection processes (0: this one); on CUDA they share the GPUs round-robin."""
    renderer: str = "auto"
    device: str = "auto"
    seed: int = 0
    spec: NavSpec | None = None
    """The network (None: the task's defaults)."""

    @property
    def searching(self) -> bool:
        return searches(self.task, self.expert)

    def __post_init__(self):
        if self.spec is None:  # ImageNav reads depth too (without it the learner drove into walls, CR 0.48);
            # its aux_goal head is left off: the trial that trained it lost to the one without (0.177 vs 0.231 SR)
            self.spec = NavSpec(task=self.task, rgbd=self.task == "imagenav")
        if self.expert not in ("auto", "geodesic", "search"):
            raise ValueError(f"expert={self.expert!r}: choose auto, geodesic or search")
        if self.expert == "auto":
            self.expert = "search" if self.task in SEARCHING_TRACKS else "geodesic"
        if self.keep not in ("best", "last"):
            raise ValueError(f"keep={self.keep!r}: choose best or last")
        if self.spec.task != self.task:
            raise ValueError(f"the network's task {self.spec.task!r} is not the run's {self.task!r}")


class Steps:
    """Labelled sequences of one or more rounds: per step the frame (uint8 [C, h, w]: depth and/or
    RGB in [0, 255]), the goal values, the previous action, the label and the goal's encoded
    position in the robot frame (float32 [3], goal_input's encoding: the aux_goal target; NaN where
    the task has no goal point); per sequence its goal image (uint8 [3, h, w]; ImageNav, else no
    channels); `starts` index each sequence."""

    FIELDS = ("obs", "goal", "prev", "label", "lengths", "seq_goal", "aux")

    def __init__(self, obs, goal, prev, label, lengths, seq_goal, aux=None):
        self.obs, self.goal, self.prev, self.label, self.seq_goal = obs, goal, prev, label, seq_goal
        # rounds saved before the aux target have none: NaN, which the aux loss skips
        self.aux = np.full((len(label), 3), np.nan, np.float32) if aux is None else aux
        self.lengths = np.asarray(lengths, np.int64)
        self.starts = np.concatenate([[0], np.cumsum(self.lengths)[:-1]]).astype(np.int64)

    @classmethod
    def concat(cls, parts: list["Steps"]) -> "Steps":
        return cls(*(np.concatenate([getattr(p, k) for p in parts]) for k in cls.FIELDS))

    def save(self, path: Path) -> None:
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez_compressed(f, **{k: getattr(self, k) for k in self.FIELDS})

    @classmethod
    def load(cls, path: Path) -> "Steps":
        z = np.load(path)
        return cls(*(z[k] for k in cls.FIELDS if k in z.files))

    def __len__(self) -> int:
        return int(self.lengths.sum())


class Trainer:
    def __init__(self, root, out, cfg: TrainConfig, quiet: bool = False, init: dict | None = None):
        """init: cfg.init's checkpoint when the caller has loaded it already (init_checkpoint)."""
        self.ds, self.out, self.cfg, self.quiet = open_dataset(root), Path(out), cfg, quiet
        self.roots = [str(p) for p in getattr(self.ds, "paths", [self.ds.path])]
        self.device = default_device(cfg.device)
        torch.manual_seed(cfg.seed)
        self.net = NavNet(cfg.spec).to(self.device)
        self.init_sha256 = None
        if cfg.init:
            ck = init if init is not None else init_checkpoint(cfg.init, cfg.task)
            spec = NavSpec(**ck["spec"])
            new_head = cfg.spec.aux_goal and not spec.aux_goal  # --aux-goal on a network without the head
            if replace(spec, aux_goal=spec.aux_goal or new_head) != cfg.spec:
                raise SystemExit(f"navarena train: --init {cfg.init}: its network ({ck['spec']}) is not this run's "
                                 f"({cfg.spec.to_dict()})")
            missing, unexpected = self.net.load_state_dict(ck["state_dict"], strict=False)
            if unexpected or any(not k.startswith("aux.") for k in missing) or (missing and not new_head):
                raise SystemExit(f"navarena train: --init {cfg.init}: its weights do not fit the network "
                                 f"(missing {missing}, unexpected {unexpected})")
            self.init_sha256 = ck["sha256"]
        if cfg.first_round not in ("bc", "dagger"):
            raise SystemExit(f"navarena train: --first-round {cfg.first_round}: bc or dagger")
        if cfg.first_round == "dagger" and not cfg.init:
            raise SystemExit("navarena train: --first-round dagger needs --init (round 0's learner is the init network)")
        self.opt = torch.optim.AdamW(self.net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
        tables = {sid: self.ds.episode_table(sid, cfg.task) for sid in self.ds.scene_ids(cfg.task)}
        self.splits = {sid: set(t["split"]) for sid, t in tables.items()}
        # each scene's catalog group (scene_path is group/scene_id): the card says what kind of scenes taught it
        self.groups = {sid: str(t["scene_path"].iloc[0]).split("/")[0] for sid, t in tables.items() if len(t)}
        self.train_scenes = self.scenes_of(cfg.train_split)
        if cfg.scenes:
            self.train_scenes = self.train_scenes[:cfg.scenes]
        if not self.train_scenes:
            raise SystemExit(f"navarena train: {root} has no {cfg.task} episodes in split {cfg.train_split!r}")
        self.val_split = cfg.val_split or next((s for s in ("val_unseen", "test") if self._has_split(s)), None)
        self.collector = Collector(root, cfg, self.device)  # this process's scenes (evaluation; collection
        self.pool = None                                     # too when workers = 0)
        self.curve: list[dict] = []
        self.frames = 0
        self.best: tuple[float, float, int] | None = None
        """(val SR, val SPL, round) of the best checked round so far (rounds/best.pt holds its weights)."""

    def log(self, msg: str) -> None:
        if not self.quiet:
            print(msg, flush=True)

    def scenes_of(self, split: str) -> list[str]:
        """Scenes with episodes of the split (held-out splits hold whole scenes)."""
        return [sid for sid, splits in self.splits.items() if split in splits]

    def _has_split(self, split: str) -> bool:
        return bool(self.scenes_of(split))

    # ------------------------------------------------------------------ collection
    def collect(self, rnd: int, model: Path, sha: str | None) -> Steps:
        """The round's labelled episodes: each training scene's share of episodes_per_round, in
        scene order (each scene's episodes and random stream depend on the seed, round and scene
        only, so the result is the same with any number of workers)."""
        cfg = self.cfg
        rng = np.random.default_rng(stream_seed(cfg.seed, "train-collect", str(rnd)) % 2**32)
        per_scene = episodes_per_scene(self.train_scenes, [self.groups.get(s) for s in self.train_scenes],
                                       cfg.episodes_per_round, cfg.capture_share, rng)
        learner = str(model) if round_beta(cfg, rnd) < 1.0 else None  # a behaviour-cloning round has none
        jobs = [(sid, int(k), rnd, learner, sha) for sid, k in zip(self.train_scenes, per_scene) if k]
        parts, t0, n_eps, steps = [], time.perf_counter(), 0, 0
        results = self.pool.imap(_collect_job, jobs) if self.pool is not None else map(self.collector.job, jobs)
        for (sid, k, *_), part in zip(jobs, results):
            parts.append(part)
            n_eps, steps = n_eps + k, steps + len(part)
            dt = time.perf_counter() - t0
            left = dt / n_eps * (cfg.episodes_per_round - n_eps)
            self.log(f"  round {rnd} collect: {n_eps}/{cfg.episodes_per_round} episodes, {steps} frames, "
                     f"{steps / dt:.0f} frames/s, {left:.0f} s left")
        self.frames += steps
        return Steps.concat(parts)

    # ------------------------------------------------------------------ training
    def fit(self, data: Steps, rnd: int) -> tuple[float, float, tuple[float, float] | None]:
        """The round's gradient steps: (loss over the first and the last 10 % of the steps, and the
        aux_goal loss's the same way, or None without the head)."""
        cfg, dev = self.cfg, self.device
        rng = np.random.default_rng(stream_seed(cfg.seed, "train-fit", str(rnd)) % 2**32)
        gen = torch.Generator(device=dev).manual_seed(stream_seed(cfg.seed, "train-augment", str(rnd)) % 2**63)
        self.net.train()
        losses, aux_losses, t0 = [], [], time.perf_counter()
        for step in range(cfg.grad_steps):
            pick = rng.integers(0, len(data.lengths), cfg.batch_episodes)
            lens = data.lengths[pick]
            tmax = int(lens.max())
            tidx = np.arange(tmax)[:, None]
            mask = tidx < lens[None]
            rows = np.where(mask, data.starts[pick][None] + np.minimum(tidx, lens[None] - 1), 0)
            # only the episodes' own frames are moved, augmented and encoded, not the padding after
            # the shorter ones (32 ObjectNav episodes padded to their longest were 5-6x their frames)
            frames = augment(torch.from_numpy(data.obs[rows[mask]]).to(dev).float().div_(255)[:, None], cfg, gen)[:, 0]
            if data.seq_goal.shape[1]:  # the episode's goal image as more channels of every frame
                g = torch.from_numpy(data.seq_goal[pick]).to(dev).float().div_(255)
                if cfg.rgb_noise > 0:
                    g = augment_rgb(g, cfg.rgb_noise, gen)
                frames = torch.cat([frames, g[torch.from_numpy(np.nonzero(mask)[1]).to(dev)]], 1)
            goal = torch.from_numpy(data.goal[rows]).to(dev)
            prev = torch.from_numpy(data.prev[rows].astype(np.int64)).to(dev)
            label = torch.from_numpy(data.label[rows].astype(np.int64)).to(dev)
            m = torch.from_numpy(mask).to(dev)
            if cfg.spec.aux_goal:
                logits, _, pred = self.net(frames, goal, prev, aux=True, chunk=cfg.encode_chunk, valid=m)
            else:
                logits, _ = self.net(frames, goal, prev, chunk=cfg.encode_chunk, valid=m)
            loss = (nn.functional.cross_entropy(logits.flatten(0, 1), label.flatten(), reduction="none")
                    * m.flatten()).sum() / m.sum()
            if cfg.spec.aux_goal:  # the goal's position, where the step has one (rounds from before: NaN)
                target = torch.from_numpy(data.aux[rows]).to(dev)
                ok = m & torch.isfinite(target).all(-1)
                err = ((pred - torch.nan_to_num(target)) ** 2).sum(-1) * ok
                aux_loss = err.sum() / ok.sum().clamp(min=1)
                loss = loss + cfg.aux_weight * aux_loss
                aux_losses.append(aux_loss.item())
            self.opt.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(self.net.parameters(), 1.0)
            self.opt.step()
            losses.append(loss.item())
            if (step + 1) % max(1, cfg.grad_steps // 5) == 0:
                dt = time.perf_counter() - t0
                self.log(f"  round {rnd} fit: step {step + 1}/{cfg.grad_steps}, loss {np.mean(losses[-50:]):.3f}, "
                         f"{(cfg.grad_steps - step - 1) * dt / (step + 1):.0f} s left")
        self.net.eval()
        k = max(1, len(losses) // 10)
        aux = (float(np.mean(aux_losses[:k])), float(np.mean(aux_losses[-k:]))) if aux_losses else None
        return float(np.mean(losses[:k])), float(np.mean(losses[-k:])), aux

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, model: Path, sha: str, split: str, n: int, width: int | None = None,
                 height: int | None = None, protocol: str = "distance") -> dict:
        """Closed-loop SR / SPL of the saved policy on n episodes of `split` (distance protocol, or
        explicit_stop: SR is Stop SR)."""
        from navcore.eval.metrics import aggregate

        scenes = self.scenes_of(split)
        per = max(1, math.ceil(n / max(1, len(scenes))))
        jobs = [(sid, split, per, str(model), sha, width or self.cfg.width, height or self.cfg.height, protocol)
                for sid in scenes]
        # one scene per collection worker (each single-threaded, on its own GPU): a check in this
        # process alone is the slowest part of a round
        results = self.pool.imap(_check_job, jobs) if self.pool is not None else map(self.collector.check, jobs)
        return aggregate([row for rows in results for row in rows])["overall"]

    # ------------------------------------------------------------------ the run
    def run(self, resume: bool = False) -> dict:
        cfg, out = self.cfg, self.out
        (out / "rounds").mkdir(parents=True, exist_ok=True)
        first = 0
        if resume and (out / "checkpoint.pt").is_file():
            ck = torch.load(out / "checkpoint.pt", map_location=self.device, weights_only=True)
            self.net.load_state_dict(ck["net"])
            self.opt.load_state_dict(ck["opt"])
            torch.set_rng_state(ck["torch_rng"].cpu())
            self.curve, self.frames = list(ck["curve"]), int(ck["frames"])
            self.best = tuple(ck["best"]) if ck.get("best") is not None else None
            first = int(ck["round"]) + 1
            self.log(f"resuming after round {first - 1}")
        parts = [Steps.load(out / "rounds" / f"round_{r}.npz") for r in range(first)]
        # the learner of the next round is the last round's network (model.pt may hold the best round's)
        # round 0's learner when it is a DAgger round: the init network
        sha = self.save_model(final=False) if first or cfg.first_round == "dagger" else None
        if cfg.workers:
            import torch.multiprocessing as tmp

            gpus = torch.cuda.device_count() if self.device.startswith("cuda") else 0
            self.pool = tmp.get_context("spawn").Pool(cfg.workers, initializer=_init_worker,
                                                      initargs=(self.roots, cfg, self.device, gpus))
        try:
            return self._rounds(first, parts, sha)
        finally:
            if self.pool is not None:
                self.pool.close()
                self.pool.join()
                self.pool = None

    def _rounds(self, first: int, parts: list, sha: str | None) -> dict:
        cfg, out = self.cfg, self.out
        for rnd in range(first, cfg.rounds):
            t0 = time.perf_counter()
            new = self.collect(rnd, out / "model.pt", sha)
            new.save(out / "rounds" / f"round_{rnd}.npz")
            parts.append(new)
            t_collect = time.perf_counter() - t0
            data = Steps.concat(parts)
            t1 = time.perf_counter()
            loss_first, loss, aux = self.fit(data, rnd)
            t_fit = time.perf_counter() - t1
            sha = self.save_model(final=False)
            entry = {"round": rnd, "kind": "bc" if rnd == 0 and cfg.first_round == "bc" else "dagger",
                     "beta": round_beta(cfg, rnd),
                     "new_frames": len(new), "frames": len(data), "episodes": int(len(data.lengths)),
                     "loss_first": round(loss_first, 4), "loss": round(loss, 4), "collect_s": round(t_collect, 1), "fit_s": round(t_fit, 1),
                     "collect_frames_per_s": round(len(new) / t_collect, 1)}
            if aux is not None:
                entry.update({"aux_loss_first": round(aux[0], 4), "aux_loss": round(aux[1], 4)})
            if self.val_split and cfg.val_episodes:
                t2 = time.perf_counter()
                m = self.evaluate(out / "model.pt", sha, self.val_split, cfg.val_episodes)
                # ObjectNav: whether it stops on purpose, the same episodes under explicit_stop
                ms = self.evaluate(out / "model.pt", sha, self.val_split, cfg.val_episodes, protocol="explicit_stop") \
                    if cfg.task == "objectnav" else None
                entry["val_s"] = round(time.perf_counter() - t2, 1)
                entry.update({"val_split": self.val_split, "val_episodes": m["episodes"],
                              "val_sr": round(m["sr"], 4), "val_spl": round(m["spl"], 4)})
                if ms is not None:
                    entry["val_stop_sr"] = round(ms["sr"], 4)
                if self.best is None or check_score(entry) >= self.best[:2]:
                    self.best = (*check_score(entry), rnd)
                    with atomic_path(out / "rounds" / "best.pt") as tmp:
                        torch.save(self.net.state_dict(), tmp)
            self.curve.append(entry)
            self.log(f"round {rnd} ({entry['kind']}): {entry}")
            with atomic_path(out / "checkpoint.pt") as tmp:  # a run killed while writing keeps the last one
                torch.save({"net": self.net.state_dict(), "opt": self.opt.state_dict(), "round": rnd,
                            "torch_rng": torch.get_rng_state(), "curve": self.curve, "frames": self.frames,
                            "best": list(self.best) if self.best else None}, tmp)
        sha = self.save_model(final=True)
        return {"model": str(out / "model.pt"), "sha256": sha, "curve": self.curve}

    TIMING = ("collect_s", "fit_s", "val_s", "collect_frames_per_s")
    """Curve fields that vary run to run (kept in the model card, not in model.pt)."""

    def meta(self) -> dict:
        """What model.pt records: the data, the full config, the seed and the curve (no timings and no
        worker count, so one config and seed on one device give the same bytes with any workers)."""
        info = self.ds.info()
        roots = {"roots": self.roots} if info["kind"] == "combined" else {}
        return {"task": self.cfg.task, "data": {"root": str(self.ds.path), "kind": info["kind"], **roots,
                                                "release": info.get("version"), "train_scenes": self.train_scenes,
                                                "groups": dict(sorted(Counter(self.groups[sid] for sid in self.train_scenes).items())),
                                                "split": self.cfg.train_split},
                "config": {**{k: v for k, v in asdict(self.cfg).items() if k != "workers"}, "spec": self.cfg.spec.to_dict(),
                           **({"init_sha256": self.init_sha256} if self.init_sha256 else {})},
                "seed": self.cfg.seed,
                "curve": [{k: v for k, v in e.items() if k not in self.TIMING} for e in self.curve],
                "parameters": parameter_count(self.net), "frames": self.frames}

    def selected_round(self) -> int:
        """The round whose weights the final model.pt holds (keep: best or last)."""
        last = self.curve[-1]["round"]
        return self.best[2] if self.cfg.keep == "best" and self.best is not None else last

    def save_model(self, final: bool) -> str:
        meta, state = self.meta(), self.net.state_dict()
        if final:
            meta["selected_round"] = self.selected_round()
            if meta["selected_round"] != self.curve[-1]["round"]:
                state = torch.load(self.out / "rounds" / "best.pt", map_location=self.device, weights_only=True)
                self.log(f"model.pt: round {meta['selected_round']}'s weights (the best held-out check, "
                         f"score {self.best[0]:.3f}), not the last round's")
        sha = save_checkpoint(self.out / "model.pt", self.cfg.task, self.cfg.spec.to_dict(), state, meta)
        if final:
            dev = torch.cuda.get_device_name() if self.device.startswith("cuda") else \
                f"{platform.machine()} CPU, {os.cpu_count()} cores"
            card = {"name": self.out.name, "file": "model.pt", "sha256": sha, "licence": "Apache-2.0", **meta,
                    "curve": self.curve, "trained_on": dev, "workers": self.cfg.workers,
                    "train_seconds": train_seconds(self.curve)}
            write_text_atomic(self.out / "model_card.json", jsonio.dumps(card, indent=1, default=str) + "\n")
        return sha


class Collector:
    """Rollouts of training episodes in the batched environment, labelled by the expert (see the
    module docstring); one per process (the trainer's, or each collection worker's)."""

    def __init__(self, root, cfg: TrainConfig, device: str):
        self.ds, self.cfg, self.device = open_dataset(root), cfg, device
        self.net = NavNet(cfg.spec).to(device).eval()
        self._ctx: dict = {}
        self._eps: dict = {}
        self._sha = None

    def ctx(self, sid: str):
        if sid not in self._ctx:
            if len(self._ctx) >= 8:  # a worker meets many scenes over the rounds: keep the last few
                self._ctx.pop(next(iter(self._ctx)))
            self._ctx[sid] = self.ds.scene_context(sid, renderer=self.cfg.renderer)
        return self._ctx[sid]

    def check(self, job) -> list[dict]:
        """The result rows of the first `per` episodes of one scene's `split` for the saved policy
        under `protocol`."""
        from navcore.baselines.agent import LearnedNavAgent
        from navcore.eval.loop import InProcessBatch, run_episodes_batched

        sid, split, per, model, sha, width, height, protocol = job
        eps = self.ds.episodes(sid, self.cfg.task, split)[:per]
        env_cfg = self.ds.env_config(protocol=protocol, width=width, height=height)
        factory = lambda: LearnedNavAgent(checkpoint=model, sha256=sha, device=self.device)  # noqa: E731
        return run_episodes_batched(self.ctx(sid), eps, InProcessBatch(factory), min(self.cfg.slots, len(eps)), env_cfg)

    def job(self, job) -> Steps:
        sid, k, rnd, model, sha = job
        if model is not None and sha != self._sha:  # this round's learner
            ck = load_checkpoint(model, kind=self.cfg.task, sha256=sha)
            self.net.load_state_dict(ck["state_dict"])
            self._sha = sha
        cfg = self.cfg
        if sid not in self._eps:
            self._eps[sid] = self.ds.episodes(sid, cfg.task, cfg.train_split)
        eps = self._eps[sid]
        rng = np.random.default_rng(stream_seed(cfg.seed, sid, f"train-collect-{rnd}") % 2**32)
        pick = rng.choice(len(eps), k, replace=len(eps) < k)
        return self.rollouts(sid, [eps[j] for j in pick], round_beta(cfg, rnd), rng)

    @torch.no_grad()
    def rollouts(self, sid: str, episodes: list, beta: float, rng) -> Steps:
        """Episodes of one scene, `slots` at a time: the executed action is the expert's with
        probability beta, else the learner's; every step is labelled with the expert's."""
        from navcore.eval.batch import BatchNavEnv

        cfg, ctx, dev = self.cfg, self.ctx(sid), self.device
        env_cfg = self.ds.env_config(protocol="explicit_stop", width=cfg.width, height=cfg.height)
        queue = list(episodes)
        n = min(cfg.slots, len(queue))
        benv = BatchNavEnv(ctx, n, env_cfg, device_obs=dev != "cpu")
        seqs: list[dict] = []
        slot_ep, slot_seq, oracle = [None] * n, [None] * n, [None] * n
        h = self.net.initial_state(n, dev)
        prev = torch.full((n,), NO_ACTION, dtype=torch.long, device=dev)

        def start(slots):
            """New episodes in these slots, their first views in one render call (a call per slot
            renders the whole scene once per finished episode)."""
            eps = {i: queue.pop(0) for i in slots[:len(queue)]}
            for i, ep in eps.items():
                begin(i, ep)
            if eps:
                obs.update(benv.reset_slots(eps))

        def begin(i, ep):
            slot_ep[i] = ep
            oracle[i] = DiscreteOracle(ctx.field(ep).grid, ctx.costmap, ep.regions, ep.success_radius, ep.goal_yaw,
                                       ep.heading_tolerance, env_cfg.actions.forward_step, env_cfg.actions.turn)
            if cfg.searching:  # the same oracle once the goal has been in view
                oracle[i] = SearchingExpert(ctx.graph, oracle[i], ep.regions, ep.success_radius, ctx.emb.hfov_deg,
                                            cfg.spec.max_depth, env_cfg.actions.forward_step, env_cfg.actions.turn,
                                            goal_view=ep.goal_pose if ep.goal_yaw is not None else None,  # ImageNav
                                            overlap=cfg.view_overlap)
            slot_seq[i] = {"obs": [], "goal": [], "prev": [], "label": [], "aux": [], "goal_image": None}
            h[:, i] = 0
            prev[i] = NO_ACTION

        obs = {}
        start(list(range(n)))
        while any(e is not None for e in slot_ep):
            live = [i for i in range(n) if slot_ep[i] is not None]
            frames, g = observation_input([obs[i] for i in live], cfg.spec, dev)
            idx = torch.tensor(live, device=dev)
            if beta < 1.0:
                logits, hl = self.net.step(frames, g, prev[idx], h[:, idx])
                h[:, idx] = hl
                learner = logits.argmax(1).tolist()
            f8 = (frames * 255 + 0.5).to(torch.uint8).cpu().numpy()  # the frame's channels, then the goal image's
            c = cfg.spec.obs_channels
            gn, pv = g.cpu().numpy(), prev[idx].cpu().numpy()
            actions = [None] * n
            for k, i in enumerate(live):
                s = benv.envs[i].state
                label = oracle[i].action(s.x, s.y, s.yaw)
                label = STOP if label < 0 else label  # no progress possible: the oracle agent stops too
                seq = slot_seq[i]
                seq["obs"].append(f8[k, :c])
                if seq["goal_image"] is None:
                    seq["goal_image"] = f8[k, c:]
                seq["goal"].append(gn[k])
                seq["prev"].append(pv[k])
                seq["label"].append(label)
                seq["aux"].append(goal_polar(s.x, s.y, s.yaw, slot_ep[i]) if cfg.spec.aux_goal else NO_AUX)
                a = label if beta >= 1.0 or rng.random() < beta else int(learner[k])
                if a == STOP and label != STOP and cfg.stop_veto:  # a false stop: labelled, and the expert goes on
                    a = label
                actions[i] = a
                prev[i] = a
            obs_all, _ = benv.step(actions, infos=False)
            ended = []
            for i in live:
                obs[i] = obs_all[i]
                s = benv.envs[i].state
                if s.done or s.steps >= cfg.max_learner_steps:
                    seqs.append(slot_seq[i])
                    slot_ep[i] = None
                    ended.append(i)
            start(ended)
        return Steps(np.concatenate([np.stack(s["obs"]) for s in seqs]),
                     np.concatenate([np.stack(s["goal"]) for s in seqs]).astype(np.float32),
                     np.concatenate([np.asarray(s["prev"], np.int8) for s in seqs]),
                     np.concatenate([np.asarray(s["label"], np.int8) for s in seqs]),
                     [len(s["label"]) for s in seqs], np.stack([s["goal_image"] for s in seqs]),
                     goal_input(np.concatenate([s["aux"] for s in seqs])).numpy())  # encoded once, NaN kept


NO_AUX = (math.nan, math.nan)
"""A step's aux target where the network has no aux_goal head (NaN: the loss skips it)."""


def episodes_per_scene(scenes: list[str], groups: list, n: int, capture_share: float | None, rng) -> np.ndarray:
    """How many of a round's n episodes each training scene gets: drawn uniformly over the scenes, or
    with capture_share, that share over the scenes outside the `synthetic` group and the rest over
    the generated ones (all over whichever kind is present when the other is not)."""
    real = np.array([g != "synthetic" for g in groups], bool)
    if capture_share is None or real.all() or not real.any():
        return np.bincount(rng.integers(0, len(scenes), n), minlength=len(scenes))
    k = int(round(capture_share * n))
    out = np.zeros(len(scenes), np.int64)
    for mask, m in ((real, k), (~real, n - k)):
        idx = np.flatnonzero(mask)
        out[idx] += np.bincount(rng.integers(0, len(idx), m), minlength=len(idx))
    return out


def augment(frames: torch.Tensor, cfg: TrainConfig, gen: torch.Generator) -> torch.Tensor:
    """[T, B, C, h, w] frames in [0, 1] (depth first when the spec has it, then RGB) with the config's
    training noise (TrainConfig.depth_noise, rgb_noise)."""
    spec = cfg.spec
    if cfg.depth_noise > 0 and spec.depth:
        d = frames[:, :, :1]
        n = torch.randn(d.shape, generator=gen, device=d.device)
        holes = torch.rand(d.shape, generator=gen, device=d.device) < cfg.depth_noise
        d = torch.where(holes, torch.ones_like(d), (d * (1 + cfg.depth_noise * n)).clamp(0, 1))
        frames = torch.cat([d, frames[:, :, 1:]], 2)
    if cfg.rgb_noise > 0 and spec.rgb:
        c = int(spec.depth)
        frames = torch.cat([frames[:, :, :c], augment_rgb(frames[:, :, c:c + 3], cfg.rgb_noise, gen)], 2)
    return frames


def augment_rgb(x: torch.Tensor, sigma: float, gen: torch.Generator) -> torch.Tensor:
    """[..., 3, h, w] in [0, 1]: a brightness and a contrast factor per image, per-pixel noise."""
    shape = (*x.shape[:-3], 1, 1, 1)
    bright = 1 + sigma * torch.randn(shape, generator=gen, device=x.device)
    contrast = 1 + sigma * torch.randn(shape, generator=gen, device=x.device)
    mean = x.mean((-3, -2, -1), keepdim=True)
    x = (x - mean) * contrast + mean * bright
    return (x + 0.5 * sigma * torch.randn(x.shape, generator=gen, device=x.device)).clamp(0, 1)


def init_checkpoint(init: str, task: str) -> dict:
    """The checkpoint --init names (a file, else a shipped baseline's name), with its "sha256"."""
    from navcore.baselines.agent import shipped
    from navcore.baselines.checkpoint import CheckpointError
    from navcore.io.release import sha256_file

    try:
        path, sha = (Path(init), None) if Path(init).is_file() or "/" in init or init.endswith(".pt") else shipped(init)
        ck = load_checkpoint(path, kind=task, sha256=sha)
    except (FileNotFoundError, CheckpointError) as e:
        raise SystemExit(f"navarena train: --init {init}: {e}") from None
    ck["sha256"] = sha or sha256_file(path)
    return ck


def check_score(entry: dict) -> tuple[float, float]:
    """What --keep best ranks a round's held-out check by: the mean SR over the protocols the check ran
    (distance; ObjectNav's explicit_stop too, the track reports both and its policy must stop on
    purpose), then SPL."""
    srs = [entry["val_sr"]] + ([entry["val_stop_sr"]] if entry.get("val_stop_sr") is not None else [])
    return round(sum(srs) / len(srs), 4), entry["val_spl"]


def goal_polar(x: float, y: float, yaw: float, ep) -> tuple[float, float]:
    """The aux_goal head's target at a pose before encoding (goal_input): the episode's goal point in
    the robot frame as (distance, bearing). ObjectNav (an episode with a category): the nearest
    point of the nearest instance's success region (its footprint box, or its centre), which moves
    to whichever instance is nearest as the robot does."""
    goal = ep.goal_xy
    if getattr(ep, "category", None) and ep.regions is not None and len(ep.regions):
        r = np.asarray(ep.regions, np.float64).reshape(-1, 4)
        near = np.column_stack([np.clip(x, r[:, 0], r[:, 2]), np.clip(y, r[:, 1], r[:, 3])])
        goal = near[int(np.argmin(np.hypot(near[:, 0] - x, near[:, 1] - y)))]
    gx, gy = goal_in_robot_frame(x, y, yaw, goal)
    return math.hypot(gx, gy), math.atan2(gy, gx)


_WORKER: dict = {}


def round_beta(cfg: TrainConfig, rnd: int) -> float:
    """The probability that a round executes the expert's action: 1 in a behaviour-cloning round 0,
    beta^k in the k-th DAgger round (first_round dagger: round 0 is the first)."""
    k = rnd + (cfg.first_round == "dagger")
    return cfg.beta ** k if k else 1.0


def _init_worker(root, cfg: TrainConfig, device: str, gpus: int) -> None:
    import multiprocessing

    torch.set_num_threads(1)
    if device.startswith("cuda") and gpus:
        ident = (multiprocessing.current_process()._identity or (1,))[0] - 1
        device = f"cuda:{ident % gpus}"
        torch.cuda.set_device(device)
    _WORKER["c"] = Collector(root, cfg, device)


def _collect_job(job) -> Steps:
    return _WORKER["c"].job(job)


def _check_job(job) -> list[dict]:
    return _WORKER["c"].check(job)


def train_seconds(curve: list[dict]) -> float:
    """Seconds of collection, fitting and validation over every round (a resumed run's too)."""
    return round(sum(e.get(k, 0.0) for e in curve for k in ("collect_s", "fit_s", "val_s")), 1)
