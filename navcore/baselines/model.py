"""The baselines' networks and what they read from an observation.

PointNavNet: depth plus the goal in the robot frame (distance, bearing) and the previous action;
a small CNN encoder, a GRU over the episode, logits of the four discrete actions (0 STOP,
1 MOVE_FORWARD, 2 TURN_LEFT, 3 TURN_RIGHT).

Every observation is reduced to a fixed input whatever the camera's resolution: depth (metres, 0
where nothing was hit) -> nothing hit and beyond `max_depth` read as `max_depth`, scaled to [0, 1],
area-averaged to `depth_hw` (torch's adaptive average pooling), so a policy trained on 128 x 96
renders runs on the evaluation's 640 x 480.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

NUM_ACTIONS = 4
NO_ACTION = NUM_ACTIONS
"""The previous-action input at an episode's first step."""


@dataclass(frozen=True)
class PointNavSpec:
    """The network's shape and input conventions (stored in every checkpoint)."""

    depth_h: int = 48
    depth_w: int = 64
    max_depth: float = 5.0
    """Metres: depth beyond it (and 'nothing hit') reads as it."""
    hidden: int = 256
    """GRU state size."""
    embed: int = 256
    """CNN embedding size."""

    def to_dict(self) -> dict:
        return asdict(self)


def depth_input(depth, spec: PointNavSpec) -> torch.Tensor:
    """[B, H, W] (or [H, W]) depth in metres, numpy or torch on any device -> float32 [B, 1, h, w]
    in [0, 1] at spec's size (see the module docstring)."""
    d = torch.as_tensor(depth)
    if d.ndim == 2:
        d = d[None]
    d = d.float()
    d = torch.where((d <= 0) | ~torch.isfinite(d), torch.full_like(d, spec.max_depth), d)
    d = d.clamp(0.0, spec.max_depth) / spec.max_depth
    d = d[:, None]
    if d.shape[-2:] != (spec.depth_h, spec.depth_w):
        d = nn.functional.adaptive_avg_pool2d(d, (spec.depth_h, spec.depth_w))
    return d


def goal_input(pointgoal) -> torch.Tensor:
    """[B, 2] (distance m, bearing rad; or [2]) -> float32 [B, 3]: log(1 + distance), cos, sin."""
    g = torch.as_tensor(np.asarray(pointgoal, np.float32)).reshape(-1, 2)
    return torch.stack([torch.log1p(g[:, 0].clamp(min=0)), torch.cos(g[:, 1]), torch.sin(g[:, 1])], 1)


class PointNavNet(nn.Module):
    """Depth CNN + goal + previous action -> GRU -> action logits (see the module docstring)."""

    def __init__(self, spec: PointNavSpec = PointNavSpec()):
        super().__init__()
        self.spec = spec
        self.cnn = nn.Sequential(
            nn.Conv2d(1, 32, 5, stride=2, padding=2), nn.ReLU(),
            nn.Conv2d(32, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Flatten())
        with torch.no_grad():
            n = self.cnn(torch.zeros(1, 1, spec.depth_h, spec.depth_w)).shape[1]
        self.fc = nn.Sequential(nn.Linear(n, spec.embed), nn.ReLU())
        self.goal = nn.Sequential(nn.Linear(3, 32), nn.ReLU())
        self.prev = nn.Embedding(NUM_ACTIONS + 1, 16)
        self.gru = nn.GRU(spec.embed + 32 + 16, spec.hidden)
        self.head = nn.Linear(spec.hidden, NUM_ACTIONS)

    def features(self, depth: torch.Tensor, goal: torch.Tensor, prev: torch.Tensor) -> torch.Tensor:
        """[N, 1, h, w], [N, 3], [N] long -> [N, F] (the GRU's input)."""
        return torch.cat([self.fc(self.cnn(depth)), self.goal(goal), self.prev(prev)], 1)

    def forward(self, depth, goal, prev, h0=None):
        """Sequences: depth [T, B, 1, h, w], goal [T, B, 3], prev [T, B] -> logits [T, B, 4] and the
        last state [1, B, hidden]."""
        t, b = prev.shape
        x = self.features(depth.flatten(0, 1), goal.flatten(0, 1), prev.flatten(0, 1)).view(t, b, -1)
        out, h = self.gru(x, h0)
        return self.head(out), h

    def step(self, depth, goal, prev, h):
        """One step of B episodes: [B, 1, h, w], [B, 3], [B], state [1, B, hidden] or None."""
        x = self.features(depth, goal, prev)[None]
        out, h = self.gru(x, h)
        return self.head(out[0]), h

    def initial_state(self, batch: int, device=None) -> torch.Tensor:
        return torch.zeros(1, batch, self.spec.hidden, device=device)


def parameter_count(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())
