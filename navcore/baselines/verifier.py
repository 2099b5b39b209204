"""ObjectNav's stop verifier: a per-frame classifier of which goal categories a STOP at the camera's
pose would succeed for (multi-label: one logit per category of navcore.labels.GOAL_CATEGORIES).

The ObjectNav policy reaches an instance of its category far more often than it stops at one: it
learned "stop beside furniture", not "stop beside a chair" (navcore/baselines/design.md). Its
category enters only the recurrent core, after a 64 x 48 encoder that never sees it. The verifier
reads the frame alone, at a higher resolution (128 x 96 by default), and answers for every
category at once, so one frame labels all of them: a pose is positive for a category when it lies
within the success radius of one of that category's success regions (the evaluator's rule,
navcore.nav.poses.region_distance), whatever the yaw. `navarena train-stop` trains it on rendered
poses of the training scenes; the agent (navcore.baselines.agent.LearnedNavAgent, `verifier=`)
vetoes a STOP the verifier gives less than `stop_check` and stops where it gives at least
`stop_force`.

    {"format": "navarena-policy/1", "kind": "objectnav_stop", "spec": {...}, ...}   # the checkpoint
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache

import torch
from torch import nn

from navcore.baselines.checkpoint import CheckpointError, load_checkpoint
from navcore.baselines.model import depth_input, rgb_input
from navcore.labels import GOAL_CATEGORIES

KIND = "objectnav_stop"
"""The checkpoint kind of a stop verifier."""


@dataclass(frozen=True)
class StopSpec:
    """The verifier's input and shape (stored in its checkpoint)."""

    depth_h: int = 96
    depth_w: int = 128
    """Input size of depth and RGB (area-pooled from any render size, as the policies')."""
    max_depth: float = 5.0
    """Metres: depth beyond it (and 'nothing hit') reads as it."""
    width: int = 32
    """Channels of the first convolution (doubled twice)."""
    categories: tuple[str, ...] = GOAL_CATEGORIES
    """The categories, in the logits' order."""

    def __post_init__(self):
        object.__setattr__(self, "categories", tuple(self.categories))

    def to_dict(self) -> dict:
        d = asdict(self)
        d["categories"] = list(self.categories)
        return d


class StopNet(nn.Module):
    """RGB-D [B, 4, h, w] -> logits [B, len(categories)] (sigmoid: P(a STOP here succeeds for it))."""

    def __init__(self, spec: StopSpec = StopSpec()):
        super().__init__()
        self.spec = spec
        w = spec.width

        def block(cin, cout, k=3):
            return [nn.Conv2d(cin, cout, k, stride=2, padding=k // 2), nn.BatchNorm2d(cout), nn.ReLU()]

        self.cnn = nn.Sequential(*block(4, w, 5), *block(w, 2 * w), *block(2 * w, 2 * w), *block(2 * w, 4 * w),
                                 *block(4 * w, 4 * w))
        with torch.no_grad():  # the probe in eval mode: batch norm of one frame at 1 x 1 (small inputs)
            shape = self.cnn.eval()(torch.zeros(1, 4, spec.depth_h, spec.depth_w)).shape
        self.cnn.train()
        self.head = nn.Sequential(nn.Flatten(), nn.Linear(shape[1] * shape[2] * shape[3], 128), nn.ReLU(),
                                  nn.Dropout(0.2), nn.Linear(128, len(spec.categories)))

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        return self.head(self.cnn(frames))


def stop_input(depth, rgb, spec: StopSpec) -> torch.Tensor:
    """Depth [B, H, W] (metres) and RGB [B, H, W, 3] uint8 of any size -> float32 [B, 4, h, w]."""
    return torch.cat([depth_input(depth, spec), rgb_input(rgb, spec)], 1)


def category_index(spec: StopSpec, category: str) -> int:
    try:
        return spec.categories.index(category)
    except ValueError:
        raise ValueError(f"goal category {category!r} is not among the stop verifier's {list(spec.categories)}") from None


@lru_cache(maxsize=8)
def load_verifier(path: str, sha256: str | None, device: str) -> StopNet:
    """A verifier checkpoint (navarena train-stop's stop.pt) on `device`, in eval mode; one network
    per (file, device)."""
    ck = load_checkpoint(path, kind=KIND, sha256=sha256)
    try:
        spec = StopSpec(**ck["spec"])
    except (TypeError, ValueError) as e:
        raise CheckpointError(f"{path}: not a stop verifier's spec: {e}") from None
    net = StopNet(spec)
    try:
        net.load_state_dict(ck["state_dict"])
    except RuntimeError as e:
        raise CheckpointError(f"{path}: its weights do not fit the stop verifier: {str(e).splitlines()[0]}") from None
    return net.to(device).eval()
