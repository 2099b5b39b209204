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

from navcore.voxels.grid import VoxelGrid
from navcore.voxels.kernel_cpu import RHO_MAX


def min_chi2_over_z(d: torch.Tensor, u: torch.Tensor, w: torch.Tensor, s: torch.Tensor, hz: float) -> torch.Tensor:
    """Vectorized kernel_cpu._min_chi2_over_z: min over t in [-hz, hz] of
    sum_k (max(|d_k + t u_k| - w_k, 0) s_k)^2 for [M, 3] inputs -> [M]."""
    m = d.shape[0]
    safe_u = torch.where(u == 0, torch.ones_like(u), u)
    bp = torch.cat([(w - d) / safe_u, (-w - d) / safe_u], 1)  # [M, 6]
    bp = torch.where(torch.cat([u, u], 1) == 0, torch.full_like(bp, -hz), bp).clamp(-hz, hz)
    ends = torch.tensor([-hz, hz], device=d.device, dtype=d.dtype).expand(m, 2)
    ts = torch.sort(torch.cat([ends, bp], 1), dim=1).values  # [M, 8]
    ta, tb = ts[:, :-1], ts[:, 1:]  # [M, 7] pieces (empty ones are harmless)
    tm = 0.5 * (ta + tb)
    e = d[:, None, :] + tm[..., None] * u[:, None, :]  # [M, 7, 3]
    active = e.abs() > w[:, None, :]
    sg = torch.where(e > 0, 1.0, -1.0)
    a1 = torch.where(active, sg * u[:, None, :] * s[:, None, :], 0.0)
    b1 = torch.where(active, (sg * d[:, None, :] - w[:, None, :]) * s[:, None, :], 0.0)
    qa, qb, qc = (a1 * a1).sum(-1), (2 * a1 * b1).sum(-1), (b1 * b1).sum(-1)
    vert = -qb / (2 * qa).clamp_min(1e-30)
    tv = torch.where(qa > 0, torch.minimum(torch.maximum(vert, ta), tb), torch.where(qb > 0, ta, tb))
    return ((qa * tv + qb) * tv + qc).min(1).values


class TorchVoxelizer:
    """Holds the Gaussian parameters on a device and evaluates x-blocks of the field."""

    def __init__(self, p, grid: VoxelGrid, truncation: float, device: str = "cuda", chunk: int | None = None,
                 exact_z: bool = False):
        self.dev = torch.device(device)
        self.grid = grid
        self.t2 = float(truncation) ** 2
        f = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32, device=self.dev)
        self.means, self.rt, self.inv_sig, self.alpha, self.w = f(p.means), f(p.rt), f(p.inv_sig), f(p.alpha), f(p.w)
        self.lo = torch.as_tensor(p.lo, device=self.dev)
        self.hi = torch.as_tensor(p.hi, device=self.dev)
        self.origin = f(np.asarray(grid.origin))
        self.vs = f(np.asarray(grid.voxel_size))
        self.chunk = chunk or self._default_chunk()
        self.exact_z = exact_z
        self.hz = 0.5 * float(grid.voxel_size[2])
        # slack of each local axis from the voxel's height, folded in by the cheap pre-test
        self.zslack = self.rt[:, :, 2].abs() * self.hz if exact_z else torch.zeros_like(self.w)

    def _default_chunk(self) -> int:
        """(Gaussian, voxel) pairs per chunk: ~600 bytes of temporaries each, so a quarter of the
        free GPU memory (16.7 M pairs, ~10 GB, at most); 1 M pairs on the CPU."""
        if self.dev.type != "cuda":
            return 1 << 20
        free, _ = torch.cuda.mem_get_info(self.dev)
        return int(min(1 << 24, max(1 << 18, free // 4 // 600)))

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
            l = (local.abs() - self.w[g] - self.zslack[g]).clamp_min(0.0) * self.inv_sig[g]
            chi2 = (l * l).sum(1)
            m = chi2 <= self.t2
            if self.exact_z:
                gm = g[m]
                exact = min_chi2_over_z(local[m], self.rt[gm, :, 2], self.w[gm], self.inv_sig[gm], self.hz)
                chi2 = chi2.clone()
                chi2[m] = exact
                m = chi2 <= self.t2
            rho = (self.alpha[g[m]] * torch.exp(-0.5 * chi2[m])).clamp_max(RHO_MAX)
            im = idx[m]
            flat = ((im[:, 0] - x0) * ny + im[:, 1]) * nz + im[:, 2]
            out.index_add_(0, flat, torch.log1p(-rho))
        return out.reshape(bx, ny, nz).cpu().numpy()
