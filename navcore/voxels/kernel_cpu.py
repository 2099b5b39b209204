"""Numba CPU kernel: accumulate log-transmittance sum_i log(1 - rho_iv) over a block of x-slabs.

Parallel over x-slabs: each thread owns its slab, Gaussians are visited in index order, so the
result is bit-identical whatever the number of threads.
"""
from __future__ import annotations

import numba
import numpy as np

RHO_MAX = 0.9999  # keeps log(1 - rho) finite; A saturates at 1 - 1e-4 per Gaussian


@numba.njit(cache=True, inline="always")
def _min_chi2_over_z(d0, d1, d2, u0, u1, u2, w0, w1, w2, s0, s1, s2, hz, ts):
    """min over t in [-hz, hz] of sum_k (max(|d_k + t u_k| - w_k, 0) s_k)^2.

    The voxel's points are its centre plus (a, b, t), |a|, |b| <= half the voxel in x, y and
    |t| <= hz: w_k bounds what a, b can change local coordinate k, t is kept exact. The function
    is convex and piecewise quadratic in t with breakpoints where |d_k + t u_k| = w_k; on each
    piece its minimum is a clamped vertex. ts: scratch array of >= 8 floats.
    """
    n = 0
    ts[n] = -hz
    n += 1
    ts[n] = hz
    n += 1
    for k in range(3):
        dk = d0 if k == 0 else (d1 if k == 1 else d2)
        uk = u0 if k == 0 else (u1 if k == 1 else u2)
        wk = w0 if k == 0 else (w1 if k == 1 else w2)
        if uk != 0.0:
            for sg in (-1.0, 1.0):
                t = (sg * wk - dk) / uk
                if -hz < t < hz:
                    ts[n] = t
                    n += 1
    for i in range(1, n):  # insertion sort of <= 8 values
        v = ts[i]
        j = i - 1
        while j >= 0 and ts[j] > v:
            ts[j + 1] = ts[j]
            j -= 1
        ts[j + 1] = v
    best = np.inf
    for p in range(max(n - 1, 1)):
        ta = ts[p]
        tb = ts[p + 1] if n > 1 else ts[p]
        tm = 0.5 * (ta + tb)
        qa = 0.0
        qb = 0.0
        qc = 0.0
        for k in range(3):
            dk = d0 if k == 0 else (d1 if k == 1 else d2)
            uk = u0 if k == 0 else (u1 if k == 1 else u2)
            wk = w0 if k == 0 else (w1 if k == 1 else w2)
            sk = s0 if k == 0 else (s1 if k == 1 else s2)
            e = dk + tm * uk
            if abs(e) > wk:  # active on this piece: (sg (d + t u) - w)^2 s^2
                sg = 1.0 if e > 0.0 else -1.0
                a1 = sg * uk * sk
                b1 = (sg * dk - wk) * sk
                qa += a1 * a1
                qb += 2.0 * a1 * b1
                qc += b1 * b1
        if qa > 0.0:
            tv = min(max(-qb / (2.0 * qa), ta), tb)
        else:
            tv = ta if qb > 0.0 else tb
        val = (qa * tv + qb) * tv + qc
        if val < best:
            best = val
    return best


@numba.njit(parallel=True, cache=True, fastmath=False)
def accumulate_block(means, rt, inv_sig, alpha, w, lo, hi, slab_ptr, slab_idx,
                     origin, vs, ny, nz, x0, nslab_x, slab_w, trunc2, exact_z):
    """Log-transmittance of voxels x in [x0, x0 + nslab_x * slab_w) (clipped by caller).

    Args:
        means: [G, 3] float64 centres. rt: [G, 3, 3] R^T (world -> local). inv_sig: [G, 3] 1/sigma.
        alpha: [G] opacity. w: [G, 3] per-local-axis half-extent of a voxel (0 for centre sampling).
        lo, hi: [G, 3] int64 inclusive voxel index ranges of each Gaussian's truncated support.
        slab_ptr: [S + 1] CSR pointers, slab_idx: Gaussian indices per slab, ascending.
        origin, vs: grid origin and voxel size [3]. ny, nz: grid size in y, z.
        x0: first x index of the block. slab_w: x-voxels per slab. trunc2: truncation radius^2 (chi2).
        exact_z: with the 'max' bound, minimize over the voxel's height exactly (w then holds
            the x, y part of the slack only) instead of bounding each local axis separately.
    Returns:
        [nslab_x * slab_w, ny, nz] float32 sum of log(1 - rho).
    """
    out = np.zeros((nslab_x * slab_w, ny, nz), dtype=np.float32)
    hz = 0.5 * vs[2]
    for s in numba.prange(nslab_x):
        ts = np.empty(8)
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
            # the loose bound folds the z slack into each local axis; exact_z refines it
            z0 = abs(r02) * hz if exact_z else 0.0
            z1 = abs(r12) * hz if exact_z else 0.0
            z2 = abs(r22) * hz if exact_z else 0.0
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
                        e0 = bx + r02 * dz
                        e1 = by + r12 * dz
                        e2 = bz + r22 * dz
                        l0 = abs(e0) - w0 - z0
                        l1 = abs(e1) - w1 - z1
                        l2 = abs(e2) - w2 - z2
                        l0 = l0 * s0 if l0 > 0.0 else 0.0
                        l1 = l1 * s1 if l1 > 0.0 else 0.0
                        l2 = l2 * s2 if l2 > 0.0 else 0.0
                        chi2 = l0 * l0 + l1 * l1 + l2 * l2
                        if chi2 <= trunc2:
                            if exact_z:
                                chi2 = _min_chi2_over_z(e0, e1, e2, r02, r12, r22, w0, w1, w2, s0, s1, s2, hz, ts)
                                if chi2 > trunc2:
                                    continue
                            rho = a * np.exp(-0.5 * chi2)
                            if rho > RHO_MAX:
                                rho = RHO_MAX
                            out[i - x0, j, k] += np.float32(np.log1p(-rho))
    return out


@numba.njit(parallel=True, cache=True)
def gaussian_params_kernel(means, quats, log_scales, logits, origin, vs, shape, truncation, max_mode, min_alpha,
                           exact_z):
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
            if max_mode:  # slack of local axis k over the voxel: sum_j |R_jk| vs_j / 2 (z kept apart)
                w[g, k] = 0.5 * (abs(r[0, k]) * vs[0] + abs(r[1, k]) * vs[1] + (0.0 if exact_z else abs(r[2, k]) * vs[2]))
        keep[g] = inside
    return keep, m64, rt, inv_sig, alpha, w, lo, hi
