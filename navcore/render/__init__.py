"""Rendering of Gaussian scenes: one interface, two backends.

    r = Renderer(gs, backend="auto")          # gsplat on CUDA when available, else the CPU renderer
    out = r.render(viewmats, Ks, width, height)
    out.rgb    # [B, H, W, 3] float32 in [0, 1]
    out.depth  # [B, H, W] float32 expected depth sum(w z) / sum(w), metres along the optical axis
               # (camera z, not the ray length); 0 where no Gaussian was hit
    out.alpha  # [B, H, W] float32 accumulated opacity

Cameras follow navcore/render/camera.py (OpenCV axes, world -> camera `viewmats`).
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from navcore.gaussians.model import render_sh_degree

if sys.prefix != sys.base_prefix:  # in a venv: gsplat's compiled CUDA kernels live with it (make setup-gpu builds them)
    os.environ.setdefault("TORCH_EXTENSIONS_DIR", str(Path(sys.prefix) / "torch_extensions"))

if TYPE_CHECKING:  # torch is imported when a renderer is built, not when cameras are
    import torch

BACKENDS = ("auto", "cpu", "gsplat", "torch")


@dataclass
class RenderOutput:
    rgb: torch.Tensor    # [B, H, W, 3] float32, [0, 1]
    depth: torch.Tensor  # [B, H, W] float32, metres (expected depth)
    alpha: torch.Tensor  # [B, H, W] float32
    extra: torch.Tensor | None = None  # [B, H, W, C] composited extra features (render(extra=...))


def gsplat_available() -> bool:
    import torch

    if not torch.cuda.is_available():
        return False
    try:
        import gsplat  # noqa: F401
    except ImportError:
        return False
    return True


class Renderer:
    """Renders one scene from batches of cameras.

    Args:
        gs: navcore.gaussians.model.GaussianScene (aligned frame).
        backend: "gsplat" (CUDA), "cpu" (compiled with numba, gsplat's classic-mode rules, work
            proportional to what the camera sees), "torch" (the plain-PyTorch reference of the same
            rules, slow: for checking the others) or "auto" (gsplat when CUDA and gsplat are there).
        sh_degree: SH degree to evaluate (None: all the scene has).
    """

    def __init__(self, gs, backend: str = "auto", sh_degree: int | None = None, device: str | None = None):
        if backend not in BACKENDS:
            raise ValueError(f"unknown renderer backend {backend!r}; choose one of {BACKENDS}")
        if backend == "auto":
            backend = "gsplat" if gsplat_available() else "cpu"
        if backend == "gsplat" and not gsplat_available():
            from navcore.optional import require

            require("gsplat", "renderer backend 'gsplat'")
            raise RuntimeError("renderer backend 'gsplat' needs CUDA (torch.cuda.is_available() is False); use backend='cpu'")
        self.backend = backend
        self.sh_degree = render_sh_degree(sh_degree, gs.sh.shape[1])  # ValueError before any work
        self.num_gaussians = len(gs.means)
        if backend == "cpu":
            from navcore.render.cpu_fast import prepare

            self._g = prepare(gs)
        elif backend == "torch":
            from navcore.render.cpu import gaussian_tensors

            self._g = gaussian_tensors(gs)
        else:
            from navcore.render.gsplat_backend import gaussian_tensors

            self._g = gaussian_tensors(gs, device or "cuda")

    def render(self, viewmats: np.ndarray, Ks: np.ndarray, width: int, height: int, features=None,
               extra=None, far: float = 1e10) -> RenderOutput:
        """viewmats [B, 4, 4] world -> camera, Ks [B, 3, 3]; returns tensors on the backend's device.
        features: optional [N, C] per-Gaussian values composited instead of colour (rgb is then the
        [B, H, W, C] composite, unclamped): e.g. one-hot labels for label masks.
        extra: optional [N, C] per-Gaussian values composited in the same pass as the colour
        (out.extra [B, H, W, C]): pixel-aligned labels at the cost of a few more channels.
        far: Gaussians whose mean lies this far or farther along the optical axis are left out
        (gsplat's far plane; a short one renders only what is near the camera, cheaply)."""
        if self.backend == "cpu":
            from navcore.render.cpu_fast import render
        elif self.backend == "torch":
            from navcore.render.cpu import render
        else:
            from navcore.render.gsplat_backend import render
        rgb, depth, alpha = render(self._g, viewmats, Ks, width, height, self.sh_degree, features=features,
                                   extra=extra, far=far)
        if features is not None:
            return RenderOutput(rgb, depth, alpha)
        return RenderOutput(rgb[..., :3].clamp(0.0, 1.0), depth, alpha, rgb[..., 3:] if extra is not None else None)
