"""The baselines' network and what it reads from an observation, one per track:

- PointNav: depth plus the goal in the robot frame (distance, bearing);
- ImageNav: RGB (RGB-D with `rgbd`, the training default) plus the goal image, stacked as channels
  into one encoder (early fusion, as GNM does), the GRU giving the context of past frames;
- ObjectNav: RGB-D plus the goal category (an embedding).

Each: a small CNN encoder, the previous action, a GRU over the episode, logits of the four
discrete actions (0 STOP, 1 MOVE_FORWARD, 2 TURN_LEFT, 3 TURN_RIGHT).

Every observation is reduced to a fixed input whatever the camera's resolution: depth (metres, 0
where nothing was hit) -> nothing hit and beyond `max_depth` read as `max_depth`, scaled to [0, 1];
RGB (uint8) scaled to [0, 1]; both area-averaged to the spec's size (torch's adaptive average
pooling), so a policy trained on 160 x 120 renders runs on the evaluation's 640 x 480.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from navcore.labels import GOAL_CATEGORIES

NUM_ACTIONS = 4
NO_ACTION = NUM_ACTIONS
"""The previous-action input at an episode's first step."""

TRACKS = {"pointnav": (True, False, "point"), "imagenav": (False, True, "image"), "objectnav": (True, True, "category")}
"""task -> (depth, RGB, goal kind) of its baseline."""


@dataclass(frozen=True)
class NavSpec:
    """The network's shape and input conventions (stored in every checkpoint)."""

    depth_h: int = 48
    depth_w: int = 64
    """The images' input size (depth, RGB and the goal image alike)."""
    max_depth: float = 5.0
    """Metres: depth beyond it (and 'nothing hit') reads as it."""
    hidden: int = 256
    """GRU state size."""
    embed: int = 256
    """CNN embedding size."""
    task: str = "pointnav"
    """pointnav | imagenav | objectnav: which inputs (TRACKS)."""
    categories: tuple[str, ...] = GOAL_CATEGORIES
    """ObjectNav's goal categories, in the embedding's order."""
    rgbd: bool = False
    """ImageNav: depth as well as RGB (navarena train's ImageNav default; False is the first ImageNav
    network's RGB alone, and a spec written before the field). Other tracks: False."""
    aux_goal: bool = False
    """ImageNav and ObjectNav: a head that predicts the goal's position in the robot frame (log(1 +
    distance), cos, sin of the bearing: goal_input's encoding) from the GRU state, trained as an
    auxiliary loss (navarena train --aux-goal), so that the encoder learns to compare the view with
    the goal image, or to find its goal category (ObjectNav's target: the nearest point of the nearest
    instance's success region, where stopping succeeds); acting never reads it. PointNav: False (its
    goal is an input)."""

    def __post_init__(self):
        if self.task not in TRACKS:
            raise ValueError(f"no baseline network for task {self.task!r} (one of {sorted(TRACKS)})")
        if self.rgbd and self.task != "imagenav":
            raise ValueError(f"rgbd applies to the imagenav network, not {self.task!r} (its inputs are fixed: TRACKS)")
        if self.aux_goal and self.task == "pointnav":
            raise ValueError("aux_goal applies to the imagenav and objectnav networks, not 'pointnav' (its goal is an input)")
        object.__setattr__(self, "categories", tuple(self.categories))

    @property
    def depth(self) -> bool:
        return TRACKS[self.task][0] or self.rgbd

    @property
    def rgb(self) -> bool:
        return TRACKS[self.task][1]

    @property
    def goal(self) -> str:
        return TRACKS[self.task][2]

    @property
    def obs_channels(self) -> int:
        """Channels of one frame: depth, then RGB."""
        return int(self.depth) + 3 * int(self.rgb)

    @property
    def goal_size(self) -> int:
        """Per-step goal values: 3 for a point (log distance, cos, sin of the bearing), 1 for a
        category (its index), 0 for an image (its channels join the frame's)."""
        return {"point": 3, "category": 1, "image": 0}[self.goal]

    def to_dict(self) -> dict:
        d = asdict(self)
        if self.task == "pointnav":  # the fields of a PointNav spec written before the other tracks
            d.pop("task"), d.pop("categories")
        else:
            d["categories"] = list(self.categories)
            for name in ("rgbd", "aux_goal"):  # the fields of a spec written before them (the same network)
                if not d[name]:
                    d.pop(name)
        return d


def _pool(x: torch.Tensor, spec: NavSpec) -> torch.Tensor:
    if x.shape[-2:] != (spec.depth_h, spec.depth_w):
        x = nn.functional.adaptive_avg_pool2d(x, (spec.depth_h, spec.depth_w))
    return x


def depth_input(depth, spec: NavSpec) -> torch.Tensor:
    """[B, H, W] (or [H, W]) depth in metres, numpy or torch on any device -> float32 [B, 1, h, w]
    in [0, 1] at spec's size (see the module docstring)."""
    d = torch.as_tensor(depth)
    if d.ndim == 2:
        d = d[None]
    d = d.float()
    d = torch.where((d <= 0) | ~torch.isfinite(d), torch.full_like(d, spec.max_depth), d)
    d = d.clamp(0.0, spec.max_depth) / spec.max_depth
    return _pool(d[:, None], spec)


def rgb_input(rgb, spec: NavSpec) -> torch.Tensor:
    """[B, H, W, 3] (or [H, W, 3]) uint8 RGB -> float32 [B, 3, h, w] in [0, 1] at spec's size."""
    x = torch.as_tensor(rgb)
    if x.ndim == 3:
        x = x[None]
    return _pool(x.permute(0, 3, 1, 2).float() / 255.0, spec)


def goal_input(pointgoal) -> torch.Tensor:
    """[B, 2] (distance m, bearing rad; or [2]) -> float32 [B, 3]: log(1 + distance), cos, sin (also
    the aux_goal head's target)."""
    g = torch.as_tensor(np.asarray(pointgoal, np.float32)).reshape(-1, 2)
    return torch.stack([torch.log1p(g[:, 0].clamp(min=0)), torch.cos(g[:, 1]), torch.sin(g[:, 1])], 1)


def category_input(categories: list, spec: NavSpec) -> torch.Tensor:
    """Goal category names -> float32 [B, 1] of their index in spec.categories."""
    index = {c: i for i, c in enumerate(spec.categories)}
    missing = sorted({c for c in categories if c not in index})
    if missing:
        raise ValueError(f"goal categories {missing} are not among the policy's {list(spec.categories)}")
    return torch.tensor([[float(index[c])] for c in categories])


def observation_input(observations: list[dict], spec: NavSpec, device) -> tuple[torch.Tensor, torch.Tensor]:
    """Observations of B episodes -> (frames [B, obs_channels (+3 for a goal image), h, w], goal
    [B, goal_size]) on `device`, as the network reads them."""
    need = (["depth"] if spec.depth else []) + (["rgb"] if spec.rgb else []) + \
        {"point": ["pointgoal"], "image": ["goal_image"], "category": ["goal_category"]}[spec.goal]
    for o in observations:
        if any(k not in o for k in need):
            raise ValueError(f"the {spec.task} baseline needs the observations {need} (rendering on, task "
                             f"{spec.task}); got {sorted(o)}")
    parts = []
    if spec.depth:
        parts.append(depth_input(torch.stack([torch.as_tensor(o["depth"]) for o in observations]).to(device), spec))
    if spec.rgb:
        parts.append(rgb_input(torch.stack([torch.as_tensor(o["rgb"]) for o in observations]).to(device), spec))
    if spec.goal == "image":
        parts.append(rgb_input(torch.stack([torch.as_tensor(o["goal_image"]) for o in observations]).to(device), spec))
        goal = torch.zeros(len(observations), 0)
    elif spec.goal == "point":
        goal = goal_input(np.stack([o["pointgoal"] for o in observations]))
    else:
        goal = category_input([o["goal_category"] for o in observations], spec)
    return torch.cat(parts, 1), goal.to(device)


class NavNet(nn.Module):
    """Frames (+ goal image) CNN + goal + previous action -> GRU -> action logits (see the module
    docstring). PointNav's parameters keep the names and shapes of the first PointNav baseline."""

    def __init__(self, spec: NavSpec = NavSpec()):
        super().__init__()
        self.spec = spec
        channels = spec.obs_channels + (3 if spec.goal == "image" else 0)
        self.cnn = nn.Sequential(
            nn.Conv2d(channels, 32, 5, stride=2, padding=2), nn.ReLU(),
            nn.Conv2d(32, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Flatten())
        with torch.no_grad():
            n = self.cnn(torch.zeros(1, channels, spec.depth_h, spec.depth_w)).shape[1]
        self.fc = nn.Sequential(nn.Linear(n, spec.embed), nn.ReLU())
        goal_width = 0
        if spec.goal == "point":
            self.goal, goal_width = nn.Sequential(nn.Linear(3, 32), nn.ReLU()), 32
        elif spec.goal == "category":
            self.goal, goal_width = nn.Embedding(len(spec.categories), 32), 32
        self.prev = nn.Embedding(NUM_ACTIONS + 1, 16)
        self.gru = nn.GRU(spec.embed + goal_width + 16, spec.hidden)
        self.head = nn.Linear(spec.hidden, NUM_ACTIONS)
        if spec.aux_goal:
            self.aux = nn.Linear(spec.hidden, 3)

    def features(self, frames: torch.Tensor, goal: torch.Tensor, prev: torch.Tensor) -> torch.Tensor:
        """[N, C, h, w], [N, goal_size], [N] long -> [N, F] (the GRU's input)."""
        parts = [self.fc(self.cnn(frames))]
        if self.spec.goal == "point":
            parts.append(self.goal(goal))
        elif self.spec.goal == "category":
            parts.append(self.goal(goal[:, 0].long()))
        parts.append(self.prev(prev))
        return torch.cat(parts, 1)

    def forward(self, frames, goal, prev, h0=None, aux: bool = False):
        """Sequences: frames [T, B, C, h, w], goal [T, B, goal_size], prev [T, B] -> logits [T, B, 4]
        and the last state [1, B, hidden]; with aux (an aux_goal network) also the goal predictions
        [T, B, 3]."""
        t, b = prev.shape
        x = self.features(frames.flatten(0, 1), goal.flatten(0, 1), prev.flatten(0, 1)).view(t, b, -1)
        out, h = self.gru(x, h0)
        return (self.head(out), h, self.aux(out)) if aux else (self.head(out), h)

    def step(self, frames, goal, prev, h, aux: bool = False):
        """One step of B episodes: [B, C, h, w], [B, goal_size], [B], state [1, B, hidden] or None ->
        logits [B, 4] and the state; with aux (an aux_goal network) also the goal predictions [B, 3]."""
        x = self.features(frames, goal, prev)[None]
        out, h = self.gru(x, h)
        return (self.head(out[0]), h, self.aux(out[0])) if aux else (self.head(out[0]), h)

    def initial_state(self, batch: int, device=None) -> torch.Tensor:
        return torch.zeros(1, batch, self.spec.hidden, device=device)


def parameter_count(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())
