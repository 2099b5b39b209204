"""Opacity field A_v = 1 - prod_i (1 - rho_iv) on a voxel grid, chunked in x-blocks so memory
stays bounded whatever the scene size.

rho_iv = alpha_i * exp(-chi2 / 2), chi2 the squared Mahalanobis distance of the voxel to Gaussian
i, truncated at ``truncation`` sigma. ``sample`` selects where chi2 is taken:
- "center": at the voxel centre x_v, exactly DESIGN.md eq. 1;
- "max" (default): a lower bound of chi2 over the whole voxel, i.e. an upper bound of rho over
  it: exact over the voxel's height, and in x, y each local coordinate is reduced by what the
  voxel's half-width can change it. Trained 3DGS surfaces are thin (normal sigma of millimetres),
  so a voxel centre 2.5 cm from a wall sees rho ~ 0 and centre sampling leaves holes in walls;
  the bound never misses a surface crossing the voxel. bench-spatial measures both.
"""
from __future__ import annotations

import glob
import os
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from navcore.gaussians.model import GaussianScene
from navcore.voxels.grid import VoxelGrid
from navcore.voxels.kernel_cpu import accumulate_block, gaussian_params_kernel


@dataclass
class VoxelizeConfig:
    """Parameters of the opacity-field voxelization."""

    resolution: float = 0.05
    """Voxel edge length, metres."""
    truncation: float = 3.0
    """Support of each Gaussian, in standard deviations (chi2 <= truncation^2)."""
    tau_occ: float = 0.5
    """A voxel is occupied when its effective opacity A_v >= tau_occ."""
    sample: str = "max"
    """'max' (upper bound of rho over the voxel) or 'center' (rho at the voxel centre, DESIGN eq. 1)."""
    min_alpha: float = 1.0 / 255.0
    """Gaussians less opaque than this are ignored (invisible in any render)."""
    block_voxels: int = 64_000_000
    """Voxels per x-block (bounds memory: 4 bytes each for the accumulator)."""
    device: str = "auto"
    """'cpu', 'cuda' or 'auto' (CUDA through torch when available)."""
    store_opacity: bool = False
    """Keep the opacity field A in 02_voxels beside V (uint8, for re-thresholding and inspection;
    no stage reads it; 17 MB for the real hall, as much as its SPZ source). A storage key:
    changing it re-runs voxelize alone."""


@dataclass
class GaussianParams:
    """Per-Gaussian quantities of the kernel for one grid (float64 for exact indexing)."""

    means: np.ndarray  # [G, 3]
    rt: np.ndarray  # [G, 3, 3] R^T
    inv_sig: np.ndarray  # [G, 3]
    alpha: np.ndarray  # [G]
    w: np.ndarray  # [G, 3]
    lo: np.ndarray  # [G, 3] int64
    hi: np.ndarray  # [G, 3] int64


def gaussian_params(scene: GaussianScene, grid: VoxelGrid, cfg: VoxelizeConfig) -> GaussianParams:
    """Kernel parameters of the Gaussians whose truncated support meets the grid.

    The support's world-axis half-extent is truncation * sqrt(sum_k (R_jk sigma_k)^2) (the box of
    the ellipsoid); a voxel is visited when its centre lies within it, plus half a voxel for the
    'max' bound, whose per-local-axis slack from the voxel's x, y extent is
    w_k = sum_{j in x, y} |R_jk| voxel_j / 2 (the z extent is minimized over exactly).
    """
    if cfg.sample not in ("max", "center"):
        raise ValueError(f"voxelize.sample must be 'max' or 'center', got {cfg.sample!r}")
    keep, means, rt, inv_sig, alpha, w, lo, hi = gaussian_params_kernel(
        scene.means, scene.quats, scene.log_scales, scene.opacity_logits, np.asarray(grid.origin, np.float64),
        np.asarray(grid.voxel_size, np.float64), np.asarray(grid.shape, np.int64), float(cfg.truncation),
        cfg.sample == "max", float(cfg.min_alpha), cfg.sample == "max")
    return GaussianParams(means[keep], rt[keep], inv_sig[keep], alpha[keep], w[keep], lo[keep], hi[keep])


def _no_cuda_device() -> bool:
    """Whether this process surely has no CUDA device (no NVIDIA device node, or
    CUDA_VISIBLE_DEVICES hides them all): 'auto' then skips importing torch (3.4 s a stage)."""
    if os.environ.get("CUDA_VISIBLE_DEVICES") in ("", "-1"):
        return True
    return not (os.path.exists("/proc/driver/nvidia") or glob.glob("/dev/nvidia[0-9]*"))


def _use_cuda(cfg: VoxelizeConfig) -> bool:
    if cfg.device == "cpu" or (cfg.device == "auto" and _no_cuda_device()):
        return False
    try:
        import torch
    except ImportError:
        if cfg.device == "cuda":
            raise
        return False
    ok = torch.cuda.is_available()
    if cfg.device == "cuda" and not ok:
        raise RuntimeError("voxelize.device=cuda but torch sees no CUDA device")
    return ok


def log_transmittance_blocks(scene: GaussianScene, grid: VoxelGrid, cfg: VoxelizeConfig,
                             device: str | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """Yield (x0, block) with block [bx, ny, nz] float32 = sum_i log(1 - rho_iv) for x in [x0, x0 + bx).

    device: 'cpu' (numba), 'cuda' or 'torch-cpu' (the torch path on the CPU, for tests);
    None decides from cfg.device.
    """
    p = gaussian_params(scene, grid, cfg)
    nx, ny, nz = grid.shape
    bx = max(1, min(nx, cfg.block_voxels // max(ny * nz, 1)))
    if device is None:
        device = "cuda" if _use_cuda(cfg) else "cpu"
    if device != "cpu":
        from navcore.voxels.kernel_torch import TorchVoxelizer

        tv = TorchVoxelizer(p, grid, cfg.truncation, device="cuda" if device == "cuda" else "cpu",
                            exact_z=cfg.sample == "max")
        for x0 in range(0, nx, bx):
            yield x0, tv.block(x0, min(bx, nx - x0))
        return
    slab_w = 4
    trunc2 = float(cfg.truncation) ** 2
    org = np.asarray(grid.origin, dtype=np.float64)
    vs = np.asarray(grid.voxel_size, dtype=np.float64)
    for x0 in range(0, nx, bx):
        x1 = min(nx, x0 + bx)
        nslab = -(-(x1 - x0) // slab_w)
        # CSR of Gaussians per slab (a Gaussian spanning several slabs is listed in each)
        sel = np.nonzero((p.hi[:, 0] >= x0) & (p.lo[:, 0] < x1))[0]
        s_lo = (np.maximum(p.lo[sel, 0], x0) - x0) // slab_w
        s_hi = (np.minimum(p.hi[sel, 0], x1 - 1) - x0) // slab_w
        counts = s_hi - s_lo + 1
        rep_g = np.repeat(sel, counts)
        rep_s = np.repeat(s_lo, counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
        order = np.lexsort((rep_g, rep_s))
        slab_idx = rep_g[order]
        slab_ptr = np.concatenate([[0], np.cumsum(np.bincount(rep_s, minlength=nslab))]).astype(np.int64)
        out = accumulate_block(p.means, p.rt, p.inv_sig, p.alpha, p.w, p.lo, p.hi, slab_ptr, slab_idx,
                               org, vs, ny, nz, x0, nslab, slab_w, trunc2, cfg.sample == "max")
        yield x0, out[: x1 - x0]


def opacity_field(scene: GaussianScene, grid: VoxelGrid, cfg: VoxelizeConfig, device: str | None = None) -> np.ndarray:
    """Effective opacity A [nx, ny, nz] float32 in [0, 1] (whole grid in memory)."""
    a = np.empty(grid.shape, dtype=np.float32)
    for x0, blk in log_transmittance_blocks(scene, grid, cfg, device):
        a[x0:x0 + len(blk)] = -np.expm1(blk)
    return a


def column_max_opacity(scene: GaussianScene, grid: VoxelGrid, cfg: VoxelizeConfig,
                       device: str | None = None) -> np.ndarray:
    """max_z A over each (x, y) column [nx, ny]; memory is one x-block, not the whole volume."""
    out = np.empty(grid.shape[:2], dtype=np.float32)
    for x0, blk in log_transmittance_blocks(scene, grid, cfg, device):
        out[x0:x0 + len(blk)] = -np.expm1(blk.min(axis=2))
    return out
