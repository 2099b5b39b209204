"""Torch kernel of the opacity field (used on CUDA; also runs on the CPU so tests can compare
it with the numba kernel). Gaussians are bucketed by the size of their voxel box, each bucket
evaluated as a dense [G, K] batch and scattered with index_add_. CUDA atomics make the float
summation order, hence the last bits, run-dependent; the numba path is the bit-exact reference.
"""
from __future__ import annotations

import numpy as np
import torch

from stages.voxelize.grid import VoxelGrid
from stages.voxelize.kernel_cpu import RHO_MAX

_STEPS = np.array([1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48, 64, 96, 128, 192, 256, 384, 512])


def _bucket(n: np.ndarray) -> np.ndarray:
    i = np.searchsorted(_STEPS, n)
    return np.where(i < len(_STEPS), _STEPS[np.minimum(i, len(_STEPS) - 1)], n)


class TorchVoxelizer:
    """Holds the Gaussian parameters on a device and evaluates x-blocks of the field."""

    def __init__(self, p, grid: VoxelGrid, truncation: float, device: str = "cuda", max_elems: int | None = None):
        self.dev = torch.device(device)
        self.grid = grid
        self.t2 = float(truncation) ** 2
        f = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32, device=self.dev)
        self.means, self.rt, self.inv_sig, self.alpha, self.w = f(p.means), f(p.rt), f(p.inv_sig), f(p.alpha), f(p.w)
        self.lo_np, self.hi_np = p.lo, p.hi
        self.lo = torch.as_tensor(p.lo, device=self.dev)
        self.origin = f(np.asarray(grid.origin))
        self.vs = f(np.asarray(grid.voxel_size))
        self.max_elems = max_elems or (1 << 25 if self.dev.type == "cuda" else 1 << 21)
        self._offsets: dict[tuple, torch.Tensor] = {}

    def _offs(self, key) -> torch.Tensor:
        if key not in self._offsets:
            a, b, c = (torch.arange(k, device=self.dev) for k in key)
            self._offsets[key] = torch.stack(torch.meshgrid(a, b, c, indexing="ij"), -1).reshape(-1, 3)
        return self._offsets[key]

    def block(self, x0: int, bx: int) -> np.ndarray:
        """sum_i log(1 - rho_iv) for x in [x0, x0 + bx): [bx, ny, nz] float32."""
        _, ny, nz = self.grid.shape
        out = torch.zeros(bx * ny * nz, dtype=torch.float32, device=self.dev)
        lo, hi = self.lo_np.copy(), self.hi_np.copy()
        lo[:, 0] = np.maximum(lo[:, 0], x0)
        hi[:, 0] = np.minimum(hi[:, 0], x0 + bx - 1)
        sel = np.nonzero((lo <= hi).all(1))[0]
        if len(sel) == 0:
            return out.reshape(bx, ny, nz).cpu().numpy()
        size = _bucket(hi[sel] - lo[sel] + 1)
        keys, inv = np.unique(size, axis=0, return_inverse=True)
        hi_t = torch.as_tensor(hi, device=self.dev)
        lo_t = torch.as_tensor(lo, device=self.dev)
        for b, key in enumerate(keys):
            gi = sel[inv.reshape(-1) == b]
            offs = self._offs(tuple(int(k) for k in key))
            chunk = max(1, self.max_elems // len(offs))
            for c0 in range(0, len(gi), chunk):
                g = torch.as_tensor(gi[c0:c0 + chunk], device=self.dev)
                idx = lo_t[g][:, None, :] + offs[None]  # [G, K, 3]
                valid = (idx <= hi_t[g][:, None, :]).all(-1)
                centre = self.origin + (idx.to(torch.float32) + 0.5) * self.vs
                d = centre - self.means[g][:, None, :]
                local = torch.einsum("gij,gkj->gki", self.rt[g], d)
                l = (local.abs() - self.w[g][:, None, :]).clamp_min(0.0) * self.inv_sig[g][:, None, :]
                chi2 = (l * l).sum(-1)
                m = valid & (chi2 <= self.t2)
                rho = (self.alpha[g][:, None] * torch.exp(-0.5 * chi2)).clamp_max(RHO_MAX)
                val = torch.log1p(-rho)[m]
                ii = idx[m]
                flat = ((ii[:, 0] - x0) * ny + ii[:, 1]) * nz + ii[:, 2]
                out.index_add_(0, flat, val)
        return out.reshape(bx, ny, nz).cpu().numpy()
