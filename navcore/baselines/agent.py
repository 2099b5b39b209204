"""The learned baselines as agents of the evaluator (registry names in navcore.eval.agents:
`pointnav_bc`, `imagenav_bc`, `objectnav_bc`), in-process or behind the agent server (navarena serve-agent --agent
pointnav_bc).

    agent = LearnedNavAgent()                               # the shipped pointnav_bc
    agent = LearnedNavAgent(checkpoint="runs/on/model.pt", device="cuda")   # any track's navarena train run

The policy acts greedily (argmax) by default. With `sample=True` its move is drawn from the
network's distribution over the three moves (seeded per episode: the same seed and episode give
the same actions), and it stops only when STOP is the most likely action, so a sampled STOP never
ends an explicit_stop episode. `stop_threshold` sets when it stops instead: when the policy gives
STOP at least that probability. `stop_gate` (a network with the goal-position head, navarena train
--aux-goal) vetoes a STOP where the head puts the goal farther than that many metres: the policy
then takes its most likely move. Sampling breaks the loops a greedy recurrent policy falls into when
it is unsure (turning in place). A shipped baseline's card names the decoding its figures were
measured with (`decoding`; imagenav_bc samples, the others are greedy), and its registry name uses it
unless `sample` is given. `verifier` (ObjectNav: a stop verifier of navarena train-stop,
navcore.baselines.verifier) checks each frame for the goal category: a STOP it gives less than
`stop_check` is vetoed (the policy's most likely move instead), and where it gives at least
`stop_force` the agent stops. A shipped card may name its verifier (`stop_verifier`), which its
registry name then uses unless `verifier` is given ("none": the policy alone). Agents of one
checkpoint and device share one network; the batched evaluator steps all of its slots in one
forward pass (act_batch).
"""
from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np
import torch

from navcore.baselines.checkpoint import CheckpointError, load_checkpoint
from navcore.baselines.model import NO_ACTION, NavNet, NavSpec, observation_input
from navcore.baselines.verifier import category_index, load_verifier, stop_input
from navcore.nav.actions import STOP
from navcore.seeds import stream_seed

MODELS = Path(str(resources.files("navcore") / "models"))


def shipped_card(name: str) -> dict:
    """A shipped baseline's model card (navcore/models/<name>/model_card.json)."""
    card_file = MODELS / name / "model_card.json"
    if not card_file.is_file():
        raise FileNotFoundError(f"no shipped baseline {name!r} ({card_file} is missing; reinstall the package)")
    return json.loads(card_file.read_text())


def shipped(name: str) -> tuple[Path, str]:
    """(model file, published sha256) of a shipped baseline."""
    card = shipped_card(name)
    return MODELS / name / card["file"], card["sha256"]


def default_device(device: str | None) -> str:
    if device in (None, "auto"):
        return "cuda" if torch.cuda.is_available() else "cpu"
    return device


@lru_cache(maxsize=8)
def _load_net(path: str, sha256: str | None, device: str) -> NavNet:
    ck = load_checkpoint(path, sha256=sha256)
    try:
        spec = NavSpec(**ck["spec"])
    except (TypeError, ValueError) as e:
        raise CheckpointError(f"{path}: not a baseline network's spec: {e}") from None
    if spec.task != ck["kind"]:
        raise CheckpointError(f"{path}: a {ck['kind']!r} policy whose network is for {spec.task!r}")
    net = NavNet(spec)
    try:
        net.load_state_dict(ck["state_dict"])
    except RuntimeError as e:
        raise CheckpointError(f"{path}: its weights do not fit the {spec.task} network: {str(e).splitlines()[0]}") from None
    return net.to(device).eval()


class LearnedNavAgent:
    """A learned baseline of any track (navcore.baselines.model.NavNet): the checkpoint's spec
    says which observations it reads.

    Args:
        checkpoint: a policy file of navarena train (None: the shipped `name`).
        name: the shipped baseline read when no checkpoint is given.
        sha256: the checkpoint's expected sha256 (checked on load when given).
        device: auto (CUDA when there) | cpu | cuda[:i].
        sample: draw the move from the policy's distribution instead of argmax (see the module docstring);
            None: as the shipped baseline's card says (`decoding`), greedy for a checkpoint file.
        stop_threshold: STOP when the policy gives it at least this probability (None: when it is the
            argmax); else the most likely (or a sampled) move. Above 0.5 it stops less eagerly.
        stop_gate: metres: a STOP is taken only where the network's goal-position head (aux_goal) puts
            the goal at most this far (None: no gate; a network without the head is refused).
        seed: the sampling stream's seed (the evaluator passes one per scene; each episode's stream is
            derived from it and the episode id).
        verifier: an ObjectNav stop verifier: its stop.pt, or "none" (None: the shipped card's, if it
            names one). stop_check / stop_force: its thresholds (None: the card's; else 0.5 and never).
    """

    reads_device_frames = True
    """The batched evaluator may hand over frames as torch tensors on the renderer's device
    (observation_input reads both): at 640 x 480 and 64 slots, the host round trip of every step's
    frames and goal images cost more than the render and the forward pass together."""

    def __init__(self, checkpoint: str | None = None, name: str = "pointnav_bc", device: str | None = "auto",
                 sha256: str | None = None, sample: bool | None = None, stop_threshold: float | None = None, seed: int = 0,
                 stop_gate: float | None = None, verifier: str | None = None, stop_check: float | None = None,
                 stop_force: float | None = None, **_):
        card = None if checkpoint else shipped_card(name)
        path, digest = (Path(checkpoint), sha256) if card is None else (MODELS / name / card["file"], card["sha256"])
        if sample is None:  # a shipped name decodes as its figures were measured; a file greedily
            sample = card is not None and bool(card.get("decoding", {}).get("sample", False))
        if not isinstance(sample, bool):
            raise ValueError(f"sample={sample!r}: true or false")
        if stop_threshold is not None and not (isinstance(stop_threshold, (int, float)) and 0 < stop_threshold <= 1):
            raise ValueError(f"stop_threshold={stop_threshold!r}: a probability in (0, 1], or none for the argmax")
        self.device = default_device(device)
        self.net = _load_net(str(path), digest, self.device)
        self.task = self.net.spec.task
        if stop_gate is not None and not (isinstance(stop_gate, (int, float)) and stop_gate > 0):
            raise ValueError(f"stop_gate={stop_gate!r}: metres (> 0), or none")
        if stop_gate is not None and not self.net.spec.aux_goal:
            raise ValueError(f"stop_gate needs a network with the goal-position head (navarena train --aux-goal); "
                             f"{path} has none")
        self.stop_gate = None if stop_gate is None else float(stop_gate)
        self.sample, self.seed = sample, int(seed)
        self.stop_threshold = None if stop_threshold is None else float(stop_threshold)
        self.rng = np.random.default_rng(stream_seed(self.seed, "", "learned-sample")) if sample else None
        self.h = None
        self.prev = NO_ACTION
        self._verifier(card, name, verifier, stop_check, stop_force)

    def _verifier(self, card, name, verifier, stop_check, stop_force) -> None:
        shipped_v = (card or {}).get("stop_verifier") if verifier is None else None
        if verifier is None and shipped_v is None or verifier == "none":
            self.verifier = None
            if stop_check is not None or stop_force is not None:
                raise ValueError("stop_check and stop_force apply with a stop verifier (verifier=stop.pt)")
            return
        if self.task != "objectnav":
            raise ValueError(f"a stop verifier applies to objectnav policies, not this {self.task} one")
        if shipped_v is not None:
            vpath, vsha = MODELS / name / shipped_v["file"], shipped_v["sha256"]
            stop_check = shipped_v.get("stop_check") if stop_check is None else stop_check
            stop_force = shipped_v.get("stop_force") if stop_force is None else stop_force
        else:
            vpath, vsha = Path(verifier), None
        for key, v in (("stop_check", stop_check), ("stop_force", stop_force)):
            if v is not None and not (isinstance(v, (int, float)) and 0 <= v <= 1):
                raise ValueError(f"{key}={v!r}: a probability in [0, 1], or none")
        self.verifier = load_verifier(str(vpath), vsha, self.device)
        self.stop_check = 0.5 if stop_check is None else float(stop_check)
        self.stop_force = None if stop_force is None else float(stop_force)

    def reset(self, task: dict) -> None:
        self.h, self.prev = self.net.initial_state(1, self.device), NO_ACTION
        if self.sample:
            self.rng = np.random.default_rng(stream_seed(self.seed, str(task.get("episode_id", "")), "learned-sample"))

    def act(self, obs: dict):
        return type(self).act_batch([self], [obs])[0]

    @classmethod
    @torch.no_grad()
    def act_batch(cls, agents: list, observations: list[dict]) -> list[int]:
        """One forward pass for agents of one network (the batched evaluator's slots)."""
        net, dev = agents[0].net, agents[0].device
        frames, goal = observation_input(observations, net.spec, dev)
        prev = torch.tensor([a.prev for a in agents], device=dev)
        h = torch.cat([a.h if a.h is not None else net.initial_state(1, dev) for a in agents], 1)
        if any(a.stop_gate is not None for a in agents):
            logits, h, aux = net.step(frames, goal, prev, h, aux=True)
            # the head's distance (log1p-encoded, goal_input) beyond the gate: STOP is not an option
            far = torch.expm1(aux[:, 0]).cpu().numpy() > np.array([np.inf if a.stop_gate is None else a.stop_gate
                                                                   for a in agents])
            logits[torch.as_tensor(far, device=logits.device), STOP] = -torch.inf
        else:
            logits, h = net.step(frames, goal, prev, h)
        acts = logits.argmax(1).tolist()
        if any(a.sample or a.stop_threshold is not None or a.verifier is not None for a in agents):
            probs = torch.softmax(logits.double(), 1).cpu().numpy()
            wants = [acts[i] == STOP if a.stop_threshold is None else probs[i, STOP] >= a.stop_threshold
                     for i, a in enumerate(agents)]
            # the verifier's P(a STOP here succeeds for the goal category), asked where it can change the decision
            verified = cls._verify(agents, observations, [i for i, a in enumerate(agents) if a.verifier is not None
                                                          and (wants[i] or a.stop_force is not None)])
            for i, a in enumerate(agents):
                stop = wants[i]
                if i in verified:
                    p = verified[i]
                    stop = (stop and p >= a.stop_check) or (a.stop_force is not None and p >= a.stop_force)
                if stop:
                    acts[i] = STOP
                    continue
                moves = probs[i, STOP + 1:] / probs[i, STOP + 1:].sum()  # FORWARD, LEFT, RIGHT
                acts[i] = STOP + 1 + (int(a.rng.choice(len(moves), p=moves)) if a.sample else int(moves.argmax()))
        for i, a in enumerate(agents):
            a.h, a.prev = h[:, i:i + 1], int(acts[i])
        return [int(x) for x in acts]

    @staticmethod
    def _verify(agents: list, observations: list[dict], slots: list[int]) -> dict[int, float]:
        """slot -> the stop verifier's probability for its goal category, for the given slots (one
        forward pass per verifier network)."""
        out: dict[int, float] = {}
        groups: dict[int, list[int]] = {}
        for i in slots:
            groups.setdefault(id(agents[i].verifier), []).append(i)
        for group in groups.values():
            net, dev = agents[group[0]].verifier, agents[group[0]].device
            obs = [observations[i] for i in group]
            for o in obs:
                if "rgb" not in o or "depth" not in o or "goal_category" not in o:
                    raise ValueError(f"the stop verifier needs rgb, depth and goal_category; got {sorted(o)}")
            x = stop_input(torch.stack([torch.as_tensor(o["depth"]) for o in obs]).to(dev),
                           torch.stack([torch.as_tensor(o["rgb"]) for o in obs]).to(dev), net.spec)
            p = torch.sigmoid(net(x).double()).cpu().numpy()
            for k, i in enumerate(group):
                out[i] = float(p[k, category_index(net.spec, observations[i]["goal_category"])])
        return out


def shipped_agent(name: str):
    """The registry's constructor of the shipped baseline `name` (navcore/models/<name>)."""
    def make(**kwargs) -> LearnedNavAgent:
        return LearnedNavAgent(name=name, **kwargs)
    make.__doc__ = f"The shipped {name} (navcore/models/{name}/model_card.md)."
    return make


pointnav_bc = shipped_agent("pointnav_bc")
imagenav_bc = shipped_agent("imagenav_bc")
objectnav_bc = shipped_agent("objectnav_bc")
