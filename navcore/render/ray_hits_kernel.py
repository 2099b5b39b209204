"""The compiled kernel of `navcore.render.ray_hits.panorama_hit_depth_cpu` (see that module for
the rule): per group of centres, each Gaussian walks the rectangle of the panorama grid its
bounding sphere's cap covers, adding -log(1 - alpha) and its t-weighted twin into depth bins; each
ray then takes the first bin where 1 - T reaches the threshold."""
from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, fastmath=False)
def _group(means, rt, inv_s, opac, radius, o, idx, dirs, el_min, d_el, near, far, bin_m, n_bins, log_t, alpha_min,
           alpha_max, acc, out):
    n_el, n_az = dirs.shape[0], dirs.shape[1]
    d_az = 2 * math.pi / n_az
    acc[:] = 0.0
    for i in idx:
        mx, my, mz = means[i, 0] - o[0], means[i, 1] - o[1], means[i, 2] - o[2]
        dist = math.sqrt(mx * mx + my * my + mz * mz)
        r = radius[i]
        if dist - r > far:
            continue
        if dist <= r:
            e0, e1, a_lo, n_a = 0, n_el - 1, 0, n_az
        else:
            a = math.asin(r / dist)
            ec = math.asin(mz / dist)
            e0 = max(0, int(math.floor((ec - a - el_min) / d_el)))
            e1 = min(n_el - 1, int(math.floor((ec + a - el_min) / d_el)))
            if e0 > e1:
                continue
            if abs(ec) + a >= 0.5 * math.pi - 1e-9:
                a_lo, n_a = 0, n_az
            else:
                half = math.asin(min(1.0, math.sin(a) / math.cos(ec)))
                azc = math.atan2(my, mx)
                a_lo = int(math.floor((azc - half) / d_az - 0.5))
                n_a = min(n_az, int(math.floor((azc + half) / d_az - 0.5)) - a_lo + 2)
        # m' = R^T m / s
        lx = (rt[i, 0, 0] * mx + rt[i, 0, 1] * my + rt[i, 0, 2] * mz) * inv_s[i, 0]
        ly = (rt[i, 1, 0] * mx + rt[i, 1, 1] * my + rt[i, 1, 2] * mz) * inv_s[i, 1]
        lz = (rt[i, 2, 0] * mx + rt[i, 2, 1] * my + rt[i, 2, 2] * mz) * inv_s[i, 2]
        op = opac[i]
        for e in range(e0, e1 + 1):
            for k in range(n_a):
                j = (a_lo + k) % n_az
                dx, dy, dz = dirs[e, j, 0], dirs[e, j, 1], dirs[e, j, 2]
                px = (rt[i, 0, 0] * dx + rt[i, 0, 1] * dy + rt[i, 0, 2] * dz) * inv_s[i, 0]
                py = (rt[i, 1, 0] * dx + rt[i, 1, 1] * dy + rt[i, 1, 2] * dz) * inv_s[i, 1]
                pz = (rt[i, 2, 0] * dx + rt[i, 2, 1] * dy + rt[i, 2, 2] * dz) * inv_s[i, 2]
                dd = px * px + py * py + pz * pz
                t = (px * lx + py * ly + pz * lz) / dd
                if t < near or t > far:
                    continue
                cx, cy, cz = ly * pz - lz * py, lz * px - lx * pz, lx * py - ly * px
                alpha = op * math.exp(-0.5 * (cx * cx + cy * cy + cz * cz) / dd)
                if alpha < alpha_min:
                    continue
                b = min(int(t / bin_m), n_bins - 1)
                w = math.log1p(-min(alpha, alpha_max))
                acc[e, j, b, 0] += w
                acc[e, j, b, 1] += w * t
    for e in range(n_el):
        for j in range(n_az):
            s = 0.0
            for b in range(n_bins):
                s += acc[e, j, b, 0]
                if s <= log_t:
                    out[e, j] = acc[e, j, b, 1] / acc[e, j, b, 0]
                    break


@numba.njit(parallel=True, cache=True)
def _panorama(means, rt, inv_s, opac, radius, centres, offsets, index, dirs, el_min, d_el, near, far, bin_m, n_bins,
              log_t, alpha_min, alpha_max, nth):
    n_g, n_c = centres.shape[0], centres.shape[1]
    n_el, n_az = dirs.shape[0], dirs.shape[1]
    out = np.full((n_g, n_c, n_el, n_az), np.inf)
    for w in numba.prange(nth):  # worker w takes groups w, w + nth, ... (groups cost unevenly)
        acc = np.zeros((n_el, n_az, n_bins, 2))
        for gi in range(w, n_g, nth):
            idx = index[offsets[gi]:offsets[gi + 1]]
            for c in range(n_c):
                _group(means, rt, inv_s, opac, radius, centres[gi, c], idx, dirs, el_min, d_el, near, far, bin_m,
                       n_bins, log_t, alpha_min, alpha_max, acc, out[gi, c])
    return out
