"""gsplat backend (CUDA): `gsplat.rasterization` in classic mode with expected depth ("RGB+ED")."""
from __future__ import annotations

import fcntl
import os
from pathlib import Path

import numpy as np
import torch

from navcore.gaussians.model import render_sh_degree

_kernels_loaded = False


def load_kernels() -> None:
    """Build (first use in this environment) or load gsplat's CUDA kernels, one process at a time.

    gsplat's JIT set-up deletes its build folder when it finds no finished build, so processes that
    start together (the GPU workers of a multi-GPU run on a fresh machine) delete each other's build
    under way: on two H100s every first semantics task failed ('Error building extension',
    ImportError). An exclusive lock beside torch's extension builds makes the first process build
    and the others wait, then load what it built."""
    global _kernels_loaded
    if _kernels_loaded:
        return
    from torch.utils.cpp_extension import get_default_build_root

    root = Path(os.environ.get("TORCH_EXTENSIONS_DIR") or get_default_build_root())
    root.mkdir(parents=True, exist_ok=True)
    with open(root / "navarena-gsplat-build.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes, also if this process dies
        from gsplat.cuda._backend import _C  # noqa: PLC2701 - the import gsplat documents for building its kernels
    if _C is None:
        raise RuntimeError("gsplat has no CUDA kernels: no prebuilt ones, and no CUDA toolkit (nvcc) to build them "
                           "(CUDA_HOME); make setup-gpu checks this")
    _kernels_loaded = True


def gaussian_tensors(gs, device: str = "cuda") -> dict:
    """A GaussianScene as gsplat's inputs on the GPU (computed once per scene); the kernels are
    loaded first (load_kernels)."""
    load_kernels()
    t = lambda a: torch.from_numpy(np.ascontiguousarray(a)).to(device)  # noqa: E731
    return {"means": t(gs.means), "quats": t(gs.quats), "scales": torch.exp(t(gs.log_scales)),
            "opacities": torch.sigmoid(t(gs.opacity_logits)), "sh": t(gs.sh)}


def render(g: dict, viewmats, Ks, width: int, height: int, sh_degree: int | None = None, features=None,
           extra=None, far: float = 1e10):
    """[B] cameras -> rgb [B, H, W, 3] (or the composited features [B, H, W, C]; with `extra`
    [N, C] the colour and the extra features [B, H, W, 3 + C] in one pass), expected depth
    [B, H, W], alpha [B, H, W] (on the GPU)."""
    from gsplat import rasterization, spherical_harmonics

    dev = g["means"].device
    vm = torch.as_tensor(np.asarray(viewmats, np.float32), device=dev)
    K = torch.as_tensor(np.asarray(Ks, np.float32), device=dev)
    deg = render_sh_degree(sh_degree, g["sh"].shape[1])
    colors, deg_arg = g["sh"], deg
    if features is not None:
        colors, deg_arg = torch.as_tensor(features, dtype=torch.float32, device=dev), None
    elif extra is not None:  # evaluate the SH colour per camera as rasterization would, then append
        campos = torch.linalg.inv(vm)[:, :3, 3]
        sh = g["sh"][:, :(deg + 1) ** 2]
        rgb = torch.stack([torch.clamp_min(spherical_harmonics(deg, g["means"] - c, sh) + 0.5, 0.0) for c in campos])
        ex = torch.as_tensor(extra, dtype=torch.float32, device=dev)
        colors, deg_arg = torch.cat([rgb, ex[None].expand(len(vm), -1, -1)], -1), None
    with torch.no_grad():
        out, alpha, _ = rasterization(g["means"], g["quats"], g["scales"], g["opacities"], colors, vm, K,
                                      width, height, sh_degree=deg_arg, render_mode="RGB+ED", packed=True,
                                      rasterize_mode="classic", far_plane=far)
    return out[..., :-1], out[..., -1], alpha[..., 0]
