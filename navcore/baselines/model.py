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
from torch.utils.checkpoint import checkpoint

from navcore.labels import GOAL_CATEGORIES

NUM_ACTIONS = 4
NO_ACTION = NUM_ACTIONS
"""The previous-action input at an episode's first step."""

ENCODERS = ("cnn", "resnet", "effnet_lite0")

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
    encoder: str = "cnn"
    """cnn: the first baselines' 4 strided convolutions (64 x 48 in); resnet: a ResNet-9 (a stem and four
    residual stages of two 3 x 3 convolutions, GroupNorm, global average pooling), the encoder of the
    early-fusion ImageNav study, for larger inputs (128 x 96: depth_w=128, depth_h=96), where two views
    of a room can be matched; effnet_lite0: ImageNet-pretrained EfficientNet-Lite0 (navcore.baselines.
    pretrained), frozen, read to its block PRETRAINED_BLOCK (112 channels at 1/16 of the input), then
    trainable layers (`PretrainedEncoder`): RGB tracks only, with depth through the small CNN beside it;
    ImageNav's goal image goes through the same frozen network and joins as feature-map channels. Its
    weights are not stored in checkpoints (the `pretrained` extra's package holds them)."""
    film: bool = False
    """The goal conditions the visual features from the first layers: after each encoder stage, a per-channel
    scale and shift computed from the goal (FiLM). ObjectNav: from the category's embedding, so that what
    the encoder looks for, and the STOP it leads to, depend on the category; ImageNav: from the goal
    image's own encoding by a second encoder (FGPrompt's conditioning). PointNav: False."""

    def __post_init__(self):
        if self.task not in TRACKS:
            raise ValueError(f"no baseline network for task {self.task!r} (one of {sorted(TRACKS)})")
        if self.rgbd and self.task != "imagenav":
            raise ValueError(f"rgbd applies to the imagenav network, not {self.task!r} (its inputs are fixed: TRACKS)")
        if self.aux_goal and self.task == "pointnav":
            raise ValueError("aux_goal applies to the imagenav and objectnav networks, not 'pointnav' (its goal is an input)")
        if self.encoder not in ENCODERS:
            raise ValueError(f"encoder={self.encoder!r}: one of {ENCODERS}")
        if self.encoder == "effnet_lite0" and self.task == "pointnav":
            raise ValueError("encoder=effnet_lite0 reads RGB: the imagenav and objectnav networks, not 'pointnav' (depth only)")
        if self.film and self.task == "pointnav":
            raise ValueError("film applies to the imagenav and objectnav networks, not 'pointnav'")
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
            d.pop("task"), d.pop("categories"), d.pop("film")
            if d["encoder"] == "cnn":
                d.pop("encoder")
        else:
            d["categories"] = list(self.categories)
            for name in ("rgbd", "aux_goal", "film"):  # the fields of a spec written before them (the same network)
                if not d[name]:
                    d.pop(name)
            if d["encoder"] == "cnn":
                d.pop("encoder")
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
        # the goal image joins as channels (early fusion), or, with film, conditions the encoder instead
        channels = spec.obs_channels + (3 if spec.goal == "image" and not spec.film else 0)
        if spec.encoder == "effnet_lite0":  # reads the goal image itself (frames' last 3 channels)
            self.cnn = PretrainedEncoder(spec)
            channels = spec.obs_channels + 3 * (spec.goal == "image")
        elif spec.encoder == "cnn" and not spec.film:  # the first baselines' encoder (their parameter names)
            self.cnn = nn.Sequential(
                nn.Conv2d(channels, 32, 5, stride=2, padding=2), nn.ReLU(),
                nn.Conv2d(32, 64, 3, stride=2, padding=1), nn.ReLU(),
                nn.Conv2d(64, 64, 3, stride=2, padding=1), nn.ReLU(),
                nn.Conv2d(64, 64, 3, stride=2, padding=1), nn.ReLU(),
                nn.Flatten())
        else:
            self.cnn = Encoder(channels, spec.encoder, film=spec.film)
            if spec.film and spec.goal == "image":  # the goal image's encoding (its own encoder) gives the FiLM input
                self.goal_cnn = Encoder(3, spec.encoder)
                self.goal_proj = nn.Linear(self.goal_cnn.width, FILM_INPUT)
        with torch.no_grad():
            probe = torch.zeros(1, channels, spec.depth_h, spec.depth_w)
            n = (self.cnn(probe, torch.zeros(1, FILM_INPUT)) if spec.film and not isinstance(self.cnn, nn.Sequential)
                 else self.cnn(probe)).shape[1]
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
        spec = self.spec
        if spec.encoder == "effnet_lite0":  # the goal image (ImageNav) is read inside; FiLM from the category
            cond = self.goal(goal[:, 0].long()) if spec.film and spec.goal == "category" else None
            parts = [self.fc(self.cnn(frames, cond))]
        elif spec.film:
            if spec.goal == "category":
                cond = self.goal(goal[:, 0].long())
            else:  # the goal image: the frames' last 3 channels (observation_input and the trainer stack it there)
                frames, image = frames[:, :-3], frames[:, -3:]
                cond = torch.relu(self.goal_proj(self.goal_cnn(image)))
            parts = [self.fc(self.cnn(frames, cond))]
        else:
            parts = [self.fc(self.cnn(frames))]
        if spec.goal == "point":
            parts.append(self.goal(goal))
        elif spec.goal == "category":
            parts.append(self.goal(goal[:, 0].long()))
        parts.append(self.prev(prev))
        return torch.cat(parts, 1)

    def forward(self, frames, goal, prev, h0=None, aux: bool = False, chunk: int = 0, valid=None):
        """Sequences: frames [T, B, C, h, w], goal [T, B, goal_size], prev [T, B] -> logits [T, B, 4]
        and the last state [1, B, hidden]; with aux (an aux_goal network) also the goal predictions
        [T, B, 3]. chunk > 0: the T x B frames are encoded `chunk` at a time and, while gradients are
        recorded, the encoder's activations are recomputed in the backward pass instead of kept
        (gradient checkpointing): the same outputs and gradients, the encoder's memory bounded by
        `chunk` frames instead of T x B. valid [T, B] bool (episodes of uneven lengths, padded at
        their ends): frames holds only the valid steps' frames, [N, C, h, w] in valid's row-major
        order, and only those are encoded (a padded step's input to the recurrent layer is zero; it
        comes after its episode's last step, so no valid output depends on it)."""
        t, b = prev.shape
        if valid is None:
            f, g, p = frames.flatten(0, 1), goal.flatten(0, 1), prev.flatten(0, 1)
        else:
            f, g, p = frames, goal[valid], prev[valid]
        if 0 < chunk < len(p):
            encode = (lambda *a: checkpoint(self.features, *a, use_reentrant=False)) if torch.is_grad_enabled() \
                else self.features
            x = torch.cat([encode(f[i:i + chunk], g[i:i + chunk], p[i:i + chunk]) for i in range(0, len(p), chunk)])
        else:
            x = self.features(f, g, p)
        x = x.view(t, b, -1) if valid is None else x.new_zeros(t, b, x.shape[-1]).masked_scatter(valid[..., None], x)
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


FILM_INPUT = 32
"""Width of the goal's code that FiLM reads (ObjectNav's category embedding is this wide)."""


class Encoder(nn.Module):
    """A visual encoder of stages, each optionally followed by FiLM (x * (1 + gamma) + beta, per channel,
    from the goal's code): cnn, the first baselines' four strided convolutions; resnet, a ResNet-9 (a
    3 x 3 stem, four residual stages of two 3 x 3 convolutions with GroupNorm, each halving the size),
    average-pooled to a vector."""

    def __init__(self, channels: int, kind: str = "cnn", film: bool = False):
        super().__init__()
        self.kind, self.film = kind, film
        if kind == "cnn":
            widths = [32, 64, 64, 64]
            self.stages = nn.ModuleList(
                nn.Sequential(nn.Conv2d(c_in, c_out, 5 if i == 0 else 3, stride=2, padding=2 if i == 0 else 1), nn.ReLU())
                for i, (c_in, c_out) in enumerate(zip([channels, *widths[:-1]], widths)))
        else:
            widths = [32, 64, 128, 256]
            self.stem = nn.Sequential(nn.Conv2d(channels, 32, 3, padding=1, bias=False), nn.GroupNorm(8, 32), nn.ReLU())
            self.stages = nn.ModuleList(ResBlock(c_in, c_out) for c_in, c_out in zip([32, *widths[:-1]], widths))
        self.width = widths[-1]
        if film:
            self.films = nn.ModuleList(nn.Linear(FILM_INPUT, 2 * w) for w in widths)
            for f in self.films:  # the identity at the start: conditioning is learned, not imposed
                nn.init.zeros_(f.weight), nn.init.zeros_(f.bias)

    def forward(self, x: torch.Tensor, cond: torch.Tensor | None = None) -> torch.Tensor:
        if self.kind != "cnn":
            x = self.stem(x)
        for i, stage in enumerate(self.stages):
            x = stage(x)
            if self.film:
                gamma, beta = self.films[i](cond).chunk(2, 1)
                x = x * (1 + gamma[:, :, None, None]) + beta[:, :, None, None]
        return x.flatten(1) if self.kind == "cnn" else x.mean((2, 3))


PRETRAINED_BLOCK = 10
"""The last block of the frozen EfficientNet-Lite0 the pretrained encoder reads: the end of its fifth
stage, 112 channels at 1/16 of the input (an 8 x 6 map of a 128 x 96 view)."""


class PretrainedEncoder(nn.Module):
    """encoder=effnet_lite0: the frozen ImageNet EfficientNet-Lite0 to block PRETRAINED_BLOCK on the
    RGB frame (and on ImageNav's goal image, whose map joins the frame's as channels: early fusion at
    the feature level; with film it gives the FiLM input instead), then trainable layers: a 1 x 1 and a
    3 x 3 convolution (128 channels, GroupNorm, each followed by FiLM from the goal's code when film), a
    1 x 1 to 32 channels, flattened (the map keeps where things are). Depth, where the track reads it,
    goes through the first baselines' small CNN beside it. The frozen network is held outside the
    module's parameters: it is neither trained nor stored in checkpoints, follows the module's device
    and dtype, and stays in eval mode (its batch-norm statistics are ImageNet's)."""

    def __init__(self, spec: NavSpec):
        super().__init__()
        from navcore.baselines.pretrained import block_channels, load_pretrained

        self.__dict__["backbone"] = load_pretrained()
        self.depth, self.image_goal, self.film = spec.depth, spec.goal == "image", spec.film
        c = block_channels(PRETRAINED_BLOCK)
        fused = c * (2 if self.image_goal and not self.film else 1)
        self.adapt = nn.Sequential(nn.Conv2d(fused, 128, 1, bias=False), nn.GroupNorm(8, 128), nn.ReLU())
        self.mix = nn.Sequential(nn.Conv2d(128, 128, 3, padding=1, bias=False), nn.GroupNorm(8, 128), nn.ReLU())
        self.out = nn.Sequential(nn.Conv2d(128, 32, 1), nn.ReLU(), nn.Flatten())
        if self.film:
            self.films = nn.ModuleList(nn.Linear(FILM_INPUT, 2 * 128) for _ in range(2))
            for f in self.films:  # the identity at the start, as Encoder's
                nn.init.zeros_(f.weight), nn.init.zeros_(f.bias)
            if self.image_goal:
                self.goal_proj = nn.Linear(c, FILM_INPUT)
        if self.depth:
            self.depth_cnn = Encoder(1, "cnn")

    def _apply(self, fn, recurse=True):
        super()._apply(fn, recurse)
        self.backbone._apply(fn, recurse)
        return self

    def train(self, mode: bool = True):
        super().train(mode)
        self.backbone.eval()
        return self

    def forward(self, frames: torch.Tensor, cond: torch.Tensor | None = None) -> torch.Tensor:
        d = int(self.depth)
        images = frames[:, d:d + 3]
        if self.image_goal:  # one pass of the frozen network over the frames and the goal images
            images = torch.cat([images, frames[:, -3:]])
        with torch.no_grad():
            maps = self.backbone.features(self.backbone.normalise(images), PRETRAINED_BLOCK)
        if self.image_goal:
            maps, goal = maps.chunk(2)
            if self.film:
                cond = torch.relu(self.goal_proj(goal.mean((2, 3))))
            else:
                maps = torch.cat([maps, goal], 1)
        x = maps
        for i, layer in enumerate((self.adapt, self.mix)):
            x = layer(x)
            if self.film:
                gamma, beta = self.films[i](cond).chunk(2, 1)
                x = x * (1 + gamma[:, :, None, None]) + beta[:, :, None, None]
        parts = [self.out(x)]
        if self.depth:
            parts.append(self.depth_cnn(frames[:, :1]))
        return torch.cat(parts, 1)


class ResBlock(nn.Module):
    """Two 3 x 3 convolutions with GroupNorm, the first of stride 2, and a strided 1 x 1 shortcut."""

    def __init__(self, c_in: int, c_out: int):
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(c_in, c_out, 3, stride=2, padding=1, bias=False), nn.GroupNorm(8, c_out), nn.ReLU(),
            nn.Conv2d(c_out, c_out, 3, padding=1, bias=False), nn.GroupNorm(8, c_out))
        self.skip = nn.Sequential(nn.Conv2d(c_in, c_out, 1, stride=2, bias=False), nn.GroupNorm(8, c_out))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.relu(self.body(x) + self.skip(x))


def parameter_count(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())
