"""navarena train-rl: PPO fine-tuning of a baseline in the batched environment (PIRLNav's recipe:
behaviour cloning and DAgger first, reinforcement learning after).

    navarena train-rl data --init runs/pointnav_bc/model.pt --out runs/pointnav_ppo
    navarena train-rl data --init objectnav_bc --task objectnav --out runs/on_ppo --updates 400
    navarena train-rl data --out runs/pn_ppo --resume            # go on from the last checkpoint

Each update: `slots` training episodes of one training scene (drawn every `scene_updates` updates)
run `horizon` more steps in the batched environment, the policy sampling its actions; a finished
slot starts the scene's next episode at once, and running episodes go on in the next update. The
reward is Habitat's shaping: the decrease of the geodesic distance to the goal (metres),
`success_reward` when an episode succeeds, `slack_reward` every step and `collision_reward` for a
step whose translation was blocked. Advantages are GAE(gamma, lambda), bootstrapped from the value
at the horizon. The loss is PPO's clipped surrogate, a value loss and an entropy bonus, over
`epochs` passes in `minibatches` groups of slots, each slot's sequence replayed through the GRU from
its state at the rollout's start (reset where an episode began).

The value head is new (a linear read of the GRU state); the policy starts from --init (or from
scratch). Episodes run under `protocol` (explicit_stop: the policy's STOP ends the episode, as the
DAgger collection's expert did).

The run folder gets:
    model.pt           the policy (the same checkpoint format as navarena train's: any learned agent reads it)
    checkpoint.pt      policy, value head, optimiser, update and the curve (--resume goes on from it;
                       written every `save_every` updates and at the end, so a 30-minute machine loses little)
    rl_card.json       config, init, the curve (per update: mean return and SR of the episodes that
                       finished, policy and value losses, entropy, frames/s) and timings
Deterministic for a seed on one device with the CPU renderer.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn

from navcore.baselines.agent import default_device
from navcore.baselines.checkpoint import save_checkpoint
from navcore.baselines.model import NO_ACTION, NavNet, NavSpec, observation_input
from navcore.eval.dataset import open_dataset
from navcore.io import jsonio
from navcore.io.atomic import atomic_path, write_text_atomic
from navcore.seeds import stream_seed


@dataclass
class PPOConfig:
    task: str = "pointnav"
    updates: int = 200
    """PPO updates (each: one rollout of slots x horizon steps, then the optimisation)."""
    slots: int = 32
    """Episodes stepped together (the batched environment's slots)."""
    horizon: int = 64
    """Steps of each slot per rollout (its episodes go on in the next rollout)."""
    scene_updates: int = 8
    """Updates on one training scene before the next is drawn (its running episodes are then cut,
    bootstrapped from the value)."""
    epochs: int = 2
    minibatches: int = 2
    """Groups of slots per epoch (each replays its slots' whole sequences)."""
    lr: float = 2.5e-4
    clip: float = 0.2
    gamma: float = 0.99
    lam: float = 0.95
    value_coef: float = 0.5
    entropy_coef: float = 0.01
    max_grad_norm: float = 0.5
    success_reward: float = 2.5
    slack_reward: float = -0.01
    collision_reward: float = 0.0
    protocol: str = "explicit_stop"
    split: str = "train"
    width: int = 160
    height: int = 120
    """Render size (the network pools it to its own input)."""
    renderer: str = "auto"
    device: str = "auto"
    seed: int = 0
    save_every: int = 10
    spec: NavSpec = field(default_factory=NavSpec)
    """The network's shape, when it does not come from --init."""

    def __post_init__(self):
        if self.slots % self.minibatches:
            raise ValueError(f"slots ({self.slots}) must split into minibatches ({self.minibatches}) evenly")
        if self.protocol not in ("distance", "explicit_stop"):
            raise ValueError(f"protocol={self.protocol!r}: distance or explicit_stop")


class ActorCritic(nn.Module):
    """The baseline's network and a value head on its GRU state."""

    def __init__(self, spec: NavSpec):
        super().__init__()
        self.net = NavNet(spec)
        self.value = nn.Linear(spec.hidden, 1)

    def step(self, frames, goal, prev, h):
        """One step of B slots -> (action distribution, value [B], new state)."""
        logits, h = self.net.step(frames, goal, prev, h)
        return torch.distributions.Categorical(logits=logits), self.value(h[0])[:, 0], h


@dataclass
class Rollout:
    """One update's experience: [T, N, ...] tensors, and the slots' GRU states at its start."""

    frames: torch.Tensor  # uint8
    goal: torch.Tensor
    prev: torch.Tensor
    action: torch.Tensor
    logp: torch.Tensor
    value: torch.Tensor
    reward: torch.Tensor
    done: torch.Tensor  # the episode ended with this step
    first: torch.Tensor  # this step began an episode (the GRU state is reset before it)
    h0: torch.Tensor
    last_value: torch.Tensor


def gae(reward, value, done, last_value, gamma: float, lam: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Generalised advantage estimates and returns of [T, N] rewards (done: the episode ended with the
    step, so nothing after it is bootstrapped)."""
    adv = torch.zeros_like(reward)
    running = torch.zeros_like(last_value)
    for t in reversed(range(reward.shape[0])):
        nxt = last_value if t == reward.shape[0] - 1 else value[t + 1]
        live = 1.0 - done[t]
        delta = reward[t] + gamma * nxt * live - value[t]
        running = delta + gamma * lam * live * running
        adv[t] = running
    return adv, adv + value


class PPOTrainer:
    def __init__(self, root, out, cfg: PPOConfig, init: dict | None = None, quiet: bool = False):
        self.root, self.out, self.cfg, self.quiet = root, Path(out), cfg, quiet
        self.ds = open_dataset(root)
        self.device = default_device(cfg.device)
        self.init = init
        self.spec = NavSpec(**init["spec"]) if init is not None else cfg.spec
        if self.spec.task != cfg.task:
            raise ValueError(f"the network is a {self.spec.task} network, the run's task is {cfg.task}")
        torch.manual_seed(cfg.seed)
        self.model = ActorCritic(self.spec).to(self.device)
        if init is not None:
            self.model.net.load_state_dict(init["state_dict"])
        self.opt = torch.optim.Adam(self.model.parameters(), lr=cfg.lr, eps=1e-5)
        self.scenes = [s for s in self.ds.scene_ids(cfg.task) if len(self.ds.episodes(s, cfg.task, cfg.split))]
        if not self.scenes:
            raise ValueError(f"{root}: no {cfg.task} episodes in the {cfg.split} split to train on")
        self.curve: list[dict] = []
        self.update = 0
        self.frames_seen = 0
        self._ctx: dict = {}
        self._run: dict | None = None

    def _next_episode(self):
        run = self._run
        if not run["order"]:
            run["order"].extend(run["rng"].permutation(len(run["eps"])))
        return run["eps"][run["order"].pop(0)]

    def log(self, msg: str) -> None:
        if not self.quiet:
            print(msg, flush=True)

    def ctx(self, sid: str):
        if sid not in self._ctx:
            if len(self._ctx) >= 4:
                self._ctx.pop(next(iter(self._ctx)))
            self._ctx[sid] = self.ds.scene_context(sid, renderer=self.cfg.renderer)
        return self._ctx[sid]

    @torch.no_grad()
    def rollout(self, u: int) -> tuple[Rollout, list[dict]]:
        """Update u's experience on one training scene, and the episodes that finished in it."""
        from navcore.eval.batch import BatchNavEnv

        cfg, dev, spec = self.cfg, self.device, self.spec
        n = cfg.slots
        if self._run is None or u % cfg.scene_updates == 0:  # a new scene: its episodes from the start
            rng = np.random.default_rng(stream_seed(cfg.seed, "ppo", str(u)) % 2**32)
            sid = self.scenes[int(rng.integers(len(self.scenes)))]
            eps = self.ds.episodes(sid, cfg.task, cfg.split)
            env = BatchNavEnv(self.ctx(sid), n, self.ds.env_config(protocol=cfg.protocol, width=cfg.width,
                                                                   height=cfg.height), device_obs=dev != "cpu")
            self._run = {"rng": rng, "eps": eps, "order": list(rng.permutation(len(eps))), "env": env}
            run = self._run
            run["obs"] = env.reset([self._next_episode() for _ in range(n)])
            run["dist"] = torch.tensor([e.geodesic_to_goal() for e in env.envs], dtype=torch.float32)
            run["h"] = self.model.net.initial_state(n, dev)
            run["prev"] = torch.full((n,), NO_ACTION, dtype=torch.long, device=dev)
            run["first"], run["ret"] = torch.ones(n), torch.zeros(n)
        run = self._run  # the running episodes go on across updates (an episode outlasts a rollout)
        env, obs, dist, h, prev, first, ret = (run[k] for k in ("env", "obs", "dist", "h", "prev", "first", "ret"))
        keys = ("frames", "goal", "prev", "action", "logp", "value", "reward", "done", "first")
        buf: dict[str, list] = {k: [] for k in keys}
        h0, finished = h.clone(), []
        torch.manual_seed(stream_seed(cfg.seed, "ppo-act", str(u)) % 2**63)
        for _ in range(cfg.horizon):
            frames, goal = observation_input(obs, spec, dev)
            # the policy reads the frames as they are stored (8 bits), so that the update's replay of
            # them gives the same log-probabilities (the first epoch's ratio is 1)
            stored = (frames * 255 + 0.5).to(torch.uint8)
            pi, value, h = self.model.step(stored.float() / 255, goal, prev, h)
            action = pi.sample()
            logp = pi.log_prob(action)
            before = [e.state.collisions for e in env.envs]
            obs, infos = env.step(action.tolist())
            reward = torch.zeros(n)
            done = torch.zeros(n)
            for i, (e, info) in enumerate(zip(env.envs, infos)):
                d = float(info["distance_to_goal"])
                progress = dist[i].item() - d if math.isfinite(d) and math.isfinite(dist[i].item()) else 0.0
                reward[i] = max(-1.0, min(1.0, progress)) + cfg.slack_reward + \
                    cfg.success_reward * bool(info["done"] and info["success"]) + \
                    cfg.collision_reward * (e.state.collisions > before[i])
                dist[i] = d
                ret[i] += reward[i]
                done[i] = float(info["done"])
            for k, v in zip(keys, (stored.cpu(), goal.cpu(), prev.cpu(), action.cpu(),
                                   logp.cpu(), value.cpu(), reward, done, first.clone())):
                buf[k].append(v)
            prev = action.clone()
            first = torch.zeros(n)
            ended = [int(i) for i in np.flatnonzero(done.numpy())]
            for i in ended:
                s = env.envs[i].state
                finished.append({"return": float(ret[i]), "success": bool(s.success), "steps": s.steps})
            for i, o in env.reset_slots({i: self._next_episode() for i in ended}).items():  # one render for them all
                obs[i] = o
                dist[i] = env.envs[i].geodesic_to_goal()
                h[:, i] = 0
                prev[i] = NO_ACTION
                first[i] = 1.0
                ret[i] = 0.0
            self.frames_seen += n
        frames, goal = observation_input(obs, spec, dev)
        _, last_value, _ = self.model.step(frames, goal, prev, h)
        run.update(obs=obs, dist=dist, h=h, prev=prev, first=first, ret=ret)
        t = {k: torch.stack(v) for k, v in buf.items()}
        return Rollout(**t, h0=h0.cpu(), last_value=last_value.cpu()), finished

    def replay(self, r: Rollout, slots: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The rollout's `slots` replayed through the current network from the rollout's first state
        (the state reset where an episode began): log-probabilities of the actions taken, values and
        entropies, each [T, len(slots)]."""
        dev = self.device
        h = r.h0[:, slots].to(dev)
        logps, values, ents = [], [], []
        for t in range(r.action.shape[0]):
            h = h * (1.0 - r.first[t, slots].to(dev))[None, :, None]
            frames = r.frames[t, slots].to(dev).float() / 255
            pi, v, h = self.model.step(frames, r.goal[t, slots].to(dev), r.prev[t, slots].to(dev), h)
            logps.append(pi.log_prob(r.action[t, slots].to(dev)))
            values.append(v)
            ents.append(pi.entropy())
        return torch.stack(logps), torch.stack(values), torch.stack(ents)

    def optimise(self, r: Rollout) -> dict:
        cfg, dev = self.cfg, self.device
        adv, ret = gae(r.reward, r.value, r.done, r.last_value, cfg.gamma, cfg.lam)
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        n = r.action.shape[1]
        gen = torch.Generator().manual_seed(stream_seed(cfg.seed, "ppo-mb", str(self.update)) % 2**63)
        stats = {"policy_loss": [], "value_loss": [], "entropy": [], "clip_fraction": []}
        self.model.train()
        for _ in range(cfg.epochs):
            for slots in torch.randperm(n, generator=gen).chunk(cfg.minibatches):
                logp, value, ent = self.replay(r, slots)
                a, old = adv[:, slots].to(dev), r.logp[:, slots].to(dev)
                ratio = torch.exp(logp - old)
                policy_loss = -torch.min(ratio * a, ratio.clamp(1 - cfg.clip, 1 + cfg.clip) * a).mean()
                value_loss = 0.5 * (value - ret[:, slots].to(dev)).pow(2).mean()
                loss = policy_loss + cfg.value_coef * value_loss - cfg.entropy_coef * ent.mean()
                self.opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(self.model.parameters(), cfg.max_grad_norm)
                self.opt.step()
                stats["policy_loss"].append(policy_loss.item())
                stats["value_loss"].append(value_loss.item())
                stats["entropy"].append(ent.mean().item())
                stats["clip_fraction"].append(((ratio - 1).abs() > cfg.clip).float().mean().item())
        self.model.eval()
        return {k: round(float(np.mean(v)), 4) for k, v in stats.items()}

    def run(self, resume: bool = False) -> dict:
        cfg = self.cfg
        self.out.mkdir(parents=True, exist_ok=True)
        if resume and (self.out / "checkpoint.pt").is_file():
            ck = torch.load(self.out / "checkpoint.pt", map_location=self.device, weights_only=True)
            self.model.load_state_dict(ck["model"])
            self.opt.load_state_dict(ck["opt"])
            self.update, self.curve = int(ck["update"]), json.loads(ck["curve"])
            self.log(f"resumed at update {self.update}")
        t_start = time.perf_counter()
        while self.update < cfg.updates:
            t0 = time.perf_counter()
            frames_before = self.frames_seen
            r, finished = self.rollout(self.update)
            t1 = time.perf_counter()
            stats = self.optimise(r)
            entry = {"update": self.update, "episodes": len(finished),
                     "return": round(float(np.mean([f["return"] for f in finished])), 4) if finished else None,
                     "sr": round(float(np.mean([f["success"] for f in finished])), 4) if finished else None,
                     "reward_per_step": round(float(r.reward.mean()), 5), **stats,
                     "frames_per_s": round((self.frames_seen - frames_before) / max(t1 - t0, 1e-9), 1),
                     "update_s": round(time.perf_counter() - t0, 2)}
            self.curve.append(entry)
            self.update += 1
            self.log(f"update {entry['update']}: return {entry['return']}, SR {entry['sr']} ({entry['episodes']} "
                     f"episodes), reward/step {entry['reward_per_step']}, entropy {entry['entropy']}, "
                     f"{entry['frames_per_s']} frames/s")
            if self.update % cfg.save_every == 0 or self.update == cfg.updates:
                self.save()
        return {"model": str(self.out / "model.pt"), "curve": self.curve, "seconds": round(time.perf_counter() - t_start, 1)}

    def save(self) -> None:
        """checkpoint.pt (resume), model.pt (the policy alone, as navarena train writes it) and rl_card.json."""
        with atomic_path(self.out / "checkpoint.pt") as tmp:
            torch.save({"model": self.model.state_dict(), "opt": self.opt.state_dict(), "update": self.update,
                        "curve": jsonio.dumps(self.curve)}, tmp)
        meta = {"recipe": "ppo", "config": {k: v for k, v in asdict(self.cfg).items() if k != "spec"},
                "init": None if self.init is None else self.init.get("sha256"), "updates": self.update}
        sha = save_checkpoint(self.out / "model.pt", self.cfg.task, self.spec.to_dict(), self.model.net.state_dict(), meta)
        card = {"name": self.out.name, "file": "model.pt", "sha256": sha, "task": self.cfg.task, **meta,
                "root": str(self.root), "device": self.device, "curve": self.curve}
        write_text_atomic(self.out / "rl_card.json", jsonio.dumps(card, indent=1, default=str) + "\n")
