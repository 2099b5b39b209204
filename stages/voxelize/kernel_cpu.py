"""Numba CPU kernel: accumulate log-transmittance sum_i log(1 - rho_iv) over a block of x-slabs.

Parallel over x-slabs: each thread owns its slab, Gaussians are visited in index order, so the
result is bit-identical whatever the number of threads.
"""
from __future__ import annotations

import numba
import numpy as np

RHO_MAX = 0.9999  # keeps log(1 - rho) finite; A saturates at 1 - 1e-4 per Gaussian


@numba.njit(parallel=True, cache=True, fastmath=False)
def accumulate_block(means, rt, inv_sig, alpha, w, lo, hi, slab_ptr, slab_idx,
                     origin, vs, ny, nz, x0, nslab_x, slab_w, trunc2):
    """Log-transmittance of voxels x in [x0, x0 + nslab_x * slab_w) (clipped by caller).

    Args:
        means: [G, 3] float64 centres. rt: [G, 3, 3] R^T (world -> local). inv_sig: [G, 3] 1/sigma.
        alpha: [G] opacity. w: [G, 3] per-local-axis half-extent of a voxel (0 for centre sampling).
        lo, hi: [G, 3] int64 inclusive voxel index ranges of each Gaussian's truncated support.
        slab_ptr: [S + 1] CSR pointers, slab_idx: Gaussian indices per slab, ascending.
        origin, vs: grid origin and voxel size [3]. ny, nz: grid size in y, z.
        x0: first x index of the block. slab_w: x-voxels per slab. trunc2: truncation radius^2 (chi2).
    Returns:
        [nslab_x * slab_w, ny, nz] float32 sum of log(1 - rho).
    """
    out = np.zeros((nslab_x * slab_w, ny, nz), dtype=np.float32)
    for s in numba.prange(nslab_x):
        sx0 = x0 + s * slab_w
        sx1 = sx0 + slab_w - 1
        for p in range(slab_ptr[s], slab_ptr[s + 1]):
            g = slab_idx[p]
            ia, ib = max(lo[g, 0], sx0), min(hi[g, 0], sx1)
            mx, my, mz = means[g, 0], means[g, 1], means[g, 2]
            r00, r01, r02 = rt[g, 0, 0], rt[g, 0, 1], rt[g, 0, 2]
            r10, r11, r12 = rt[g, 1, 0], rt[g, 1, 1], rt[g, 1, 2]
            r20, r21, r22 = rt[g, 2, 0], rt[g, 2, 1], rt[g, 2, 2]
            s0, s1, s2 = inv_sig[g, 0], inv_sig[g, 1], inv_sig[g, 2]
            w0, w1, w2 = w[g, 0], w[g, 1], w[g, 2]
            a = alpha[g]
            for i in range(ia, ib + 1):
                dx = origin[0] + (i + 0.5) * vs[0] - mx
                for j in range(lo[g, 1], hi[g, 1] + 1):
                    dy = origin[1] + (j + 0.5) * vs[1] - my
                    bx = r00 * dx + r01 * dy
                    by = r10 * dx + r11 * dy
                    bz = r20 * dx + r21 * dy
                    for k in range(lo[g, 2], hi[g, 2] + 1):
                        dz = origin[2] + (k + 0.5) * vs[2] - mz
                        l0 = abs(bx + r02 * dz) - w0
                        l1 = abs(by + r12 * dz) - w1
                        l2 = abs(bz + r22 * dz) - w2
                        l0 = l0 * s0 if l0 > 0.0 else 0.0
                        l1 = l1 * s1 if l1 > 0.0 else 0.0
                        l2 = l2 * s2 if l2 > 0.0 else 0.0
                        chi2 = l0 * l0 + l1 * l1 + l2 * l2
                        if chi2 <= trunc2:
                            rho = a * np.exp(-0.5 * chi2)
                            if rho > RHO_MAX:
                                rho = RHO_MAX
                            out[i - x0, j, k] += np.float32(np.log1p(-rho))
    return out


@numba.njit(parallel=True, cache=True)
def gaussian_params_kernel(means, quats, log_scales, logits, origin, vs, shape, truncation, max_mode, min_alpha):
    """Per-Gaussian kernel parameters for a grid (see field.gaussian_params); rows whose support
    misses the grid or whose opacity is below min_alpha get keep = False.

    Returns:
        keep [N] bool, means [N, 3] f64, rt [N, 3, 3] (R^T), inv_sig [N, 3], alpha [N], w [N, 3],
        lo [N, 3] int64, hi [N, 3] int64.
    """
    n = means.shape[0]
    keep = np.zeros(n, dtype=np.bool_)
    m64 = np.empty((n, 3))
    rt = np.empty((n, 3, 3))
    inv_sig = np.empty((n, 3))
    alpha = np.empty(n)
    w = np.zeros((n, 3))
    lo = np.empty((n, 3), dtype=np.int64)
    hi = np.empty((n, 3), dtype=np.int64)
    for g in numba.prange(n):
        a = 1.0 / (1.0 + np.exp(-np.float64(logits[g])))
        alpha[g] = a
        if a < min_alpha:
            continue
        qw, qx, qy, qz = np.float64(quats[g, 0]), np.float64(quats[g, 1]), np.float64(quats[g, 2]), np.float64(quats[g, 3])
        # R (local -> world) from the unit quaternion; rt = R^T
        r = np.empty((3, 3))
        r[0, 0] = 1 - 2 * (qy * qy + qz * qz)
        r[0, 1] = 2 * (qx * qy - qw * qz)
        r[0, 2] = 2 * (qx * qz + qw * qy)
        r[1, 0] = 2 * (qx * qy + qw * qz)
        r[1, 1] = 1 - 2 * (qx * qx + qz * qz)
        r[1, 2] = 2 * (qy * qz - qw * qx)
        r[2, 0] = 2 * (qx * qz - qw * qy)
        r[2, 1] = 2 * (qy * qz + qw * qx)
        r[2, 2] = 1 - 2 * (qx * qx + qy * qy)
        inside = True
        for j in range(3):
            ext2 = 0.0
            for k in range(3):
                sig = np.exp(np.float64(log_scales[g, k]))
                ext2 += (r[j, k] * sig) ** 2
                rt[g, k, j] = r[j, k]
            ext = truncation * np.sqrt(ext2)
            pad = 0.5 * vs[j] if max_mode else 0.0
            mu = np.float64(means[g, j])
            m64[g, j] = mu
            l = int(np.ceil((mu - ext - pad - origin[j]) / vs[j] - 0.5))
            h = int(np.floor((mu + ext + pad - origin[j]) / vs[j] - 0.5))
            lo[g, j] = max(l, 0)
            hi[g, j] = min(h, shape[j] - 1)
            if lo[g, j] > hi[g, j]:
                inside = False
        for k in range(3):
            inv_sig[g, k] = np.exp(-np.float64(log_scales[g, k]))
            if max_mode:
                w[g, k] = 0.5 * (abs(r[0, k]) * vs[0] + abs(r[1, k]) * vs[1] + abs(r[2, k]) * vs[2])
        keep[g] = inside
    return keep, m64, rt, inv_sig, alpha, w, lo, hi
