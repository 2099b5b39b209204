"""Torch kernel of the opacity field (used on CUDA; also runs on the CPU so tests can compare it
with the numba kernel).

Every (Gaussian, voxel) pair of the block is enumerated flat: a prefix sum over the Gaussians'
voxel-box sizes maps each pair index to its Gaussian (searchsorted) and its voxel (div / mod),
so each chunk is a handful of large kernels whatever the size mix. Contributions are scattered
with index_add_; CUDA atomics make the float summation order, hence the last bits,
run-dependent, so the numba path is the bit-exact reference.
"""
from __future__ import annotations

import numpy as np
import torch

from stages.voxelize.grid import VoxelGrid
from stages.voxelize.kernel_cpu import RHO_MAX


class TorchVoxelizer:
    """Holds the Gaussian parameters on a device and evaluates x-blocks of the field."""

    def __init__(self, p, grid: VoxelGrid, truncation: float, device: str = "cuda", chunk: int | None = None):
        self.dev = torch.device(device)
        self.grid = grid
        self.t2 = float(truncation) ** 2
        f = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32, device=self.dev)
        self.means, self.rt, self.inv_sig, self.alpha, self.w = f(p.means), f(p.rt), f(p.inv_sig), f(p.alpha), f(p.w)
        self.lo = torch.as_tensor(p.lo, device=self.dev)
        self.hi = torch.as_tensor(p.hi, device=self.dev)
        self.origin = f(np.asarray(grid.origin))
        self.vs = f(np.asarray(grid.voxel_size))
        self.chunk = chunk or (1 << 24 if self.dev.type == "cuda" else 1 << 20)

    def block(self, x0: int, bx: int) -> np.ndarray:
        """sum_i log(1 - rho_iv) for x in [x0, x0 + bx): [bx, ny, nz] float32."""
        _, ny, nz = self.grid.shape
        out = torch.zeros(bx * ny * nz, dtype=torch.float32, device=self.dev)
        lo, hi = self.lo.clone(), self.hi.clone()
        lo[:, 0].clamp_(min=x0)
        hi[:, 0].clamp_(max=x0 + bx - 1)
        sel = torch.nonzero((lo <= hi).all(1)).squeeze(1)
        if len(sel) == 0:
            return out.reshape(bx, ny, nz).cpu().numpy()
        lo, size = lo[sel], hi[sel] - lo[sel] + 1
        cnt = size.prod(1)
        cum = torch.cumsum(cnt, 0)
        total = int(cum[-1])
        for e0 in range(0, total, self.chunk):
            e = torch.arange(e0, min(e0 + self.chunk, total), device=self.dev)
            k = torch.searchsorted(cum, e, right=True)  # which selected Gaussian
            off = e - (cum[k] - cnt[k])
            sz = size[k]
            iz = off % sz[:, 2]
            t = off // sz[:, 2]
            iy = t % sz[:, 1]
            ix = t // sz[:, 1]
            idx = lo[k] + torch.stack([ix, iy, iz], 1)
            g = sel[k]
            d = self.origin + (idx.to(torch.float32) + 0.5) * self.vs - self.means[g]
            local = torch.bmm(self.rt[g], d.unsqueeze(-1)).squeeze(-1)
            l = (local.abs() - self.w[g]).clamp_min(0.0) * self.inv_sig[g]
            chi2 = (l * l).sum(1)
            m = chi2 <= self.t2
            rho = (self.alpha[g[m]] * torch.exp(-0.5 * chi2[m])).clamp_max(RHO_MAX)
            im = idx[m]
            flat = ((im[:, 0] - x0) * ny + im[:, 1]) * nz + im[:, 2]
            out.index_add_(0, flat, torch.log1p(-rho))
        return out.reshape(bx, ny, nz).cpu().numpy()
