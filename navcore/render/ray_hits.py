"""Per-ray hit depth: where a ray's accumulated opacity first crosses a threshold.

A rasterizer gives each Gaussian one depth (its centre's) for every pixel it covers, so a splat
seen obliquely near the camera reports the centre's depth on rays that meet its surface much
farther on (or nearer): expected depth reads short beside walls and floors. Here each Gaussian is
evaluated on each ray at its maximum response along that ray (3D Gaussian ray tracing's rule):
for a ray o + t d and a Gaussian (mean mu, rotation R, scales s), in the Gaussian's own scaled
frame m' = R^T (mu - o) / s and d' = R^T d / s,

    t* = (d' . m') / |d'|^2,          D^2 = |m' x d'|^2 / |d'|^2,          alpha = min(0.99, o exp(-D^2 / 2))

(the cross-product form keeps D^2 accurate for the thin discs trained scenes are made of). A hit
counts where alpha >= 1/255 and near <= t* <= far; the ray's transmittance is accumulated front to
back in depth bins of ``bin_m`` (sum of log(1 - alpha) per bin), and the ray's hit depth is the
mean t* of the hits in the first bin where 1 - T reaches ``threshold``, each weighted by its
-log(1 - alpha) (inf where 1 - T never reaches it): a thin surface's depth to well under a bin. Depth is the
distance along the ray (unit directions), not along an optical axis.

Rays come as panoramas: from each centre, a grid of azimuths (A, the full circle, az_j = (j + 1/2)
2 pi / A) by elevations (E, from el_min to el_max, cell centres), z up. Each Gaussian then touches a
rectangle of the grid (its bounding sphere's spherical cap: elevations e +- a, azimuths
+- asin(sin a / cos e), a = asin(radius / distance)), which the CPU kernel walks; the sphere's radius is
gsplat's opacity-aware extent, sqrt(2 ln(255 o)) largest sigmas, beyond which alpha < 1/255, so
the cull is exact. Centres come in groups that share a subset of the Gaussians (e.g. the heights of
one robot pose and the Gaussians around it).

Two implementations that agree to the bin: `panorama_hit_depth_cpu` (numba, parallel over groups,
float64) and `panorama_hit_depth_torch` (PyTorch, every Gaussian of a group against every ray in
chunks, for CUDA; on the CPU it is the independent reference the tests compare with).
"""
from __future__ import annotations

import math

import numba
import numpy as np

ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.99


def ray_gaussians(gs) -> dict:
    """A GaussianScene as this module's arrays: means, world -> local rotations R^T [N, 3, 3],
    inverse scales [N, 3], opacities and the opacity-aware bounding radius (metres), float64."""
    from navcore.gaussians.model import quat_to_rotmat

    q = gs.quats.astype(np.float64)
    q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
    rot = quat_to_rotmat(q).astype(np.float64)
    s = np.maximum(np.exp(gs.log_scales.astype(np.float64)), 1e-7)
    opac = gs.alphas.astype(np.float64)
    ext = np.sqrt(2.0 * np.log(np.maximum(opac * 255.0, 1.0)))
    return {"means": np.ascontiguousarray(gs.means, np.float64),
            "rt": np.ascontiguousarray(rot.transpose(0, 2, 1)), "inv_s": np.ascontiguousarray(1.0 / s),
            "opac": opac, "radius": ext * s.max(1)}


def panorama_dirs(n_az: int, el_min: float, el_max: float, n_el: int) -> np.ndarray:
    """[E, A, 3] unit ray directions (z up) of the panorama grid; angles in radians."""
    az = (np.arange(n_az) + 0.5) * 2 * np.pi / n_az
    el = el_min + (np.arange(n_el) + 0.5) * (el_max - el_min) / n_el
    ce = np.cos(el)[:, None]
    return np.stack(np.broadcast_arrays(ce * np.cos(az)[None], ce * np.sin(az)[None], np.sin(el)[:, None]), -1)


def _check(g: dict, centres, offsets, index, n_az, n_el, el_min, el_max, near, far, bin_m, threshold):
    centres = np.ascontiguousarray(centres, np.float64)
    offsets = np.ascontiguousarray(offsets, np.int64)
    index = np.ascontiguousarray(index, np.int64)
    if centres.ndim != 3 or centres.shape[2] != 3:
        raise ValueError(f"centres must be [groups, centres per group, 3], got {centres.shape}")
    if offsets.shape != (len(centres) + 1,) or offsets[0] != 0 or offsets[-1] != len(index) or np.any(np.diff(offsets) < 0):
        raise ValueError("offsets must be non-decreasing, start at 0 and end at len(index), one per group + 1")
    if len(index) and (index.min() < 0 or index.max() >= len(g["means"])):
        raise ValueError(f"index holds Gaussians outside 0..{len(g['means']) - 1}")
    if not (n_az > 0 and n_el > 0 and -np.pi / 2 <= el_min < el_max <= np.pi / 2):
        raise ValueError("need n_az, n_el > 0 and -pi/2 <= el_min < el_max <= pi/2")
    if not (0 <= near < far and bin_m > 0 and 0 < threshold < 1):
        raise ValueError("need 0 <= near < far, bin_m > 0 and 0 < threshold < 1")
    return centres, offsets, index, int(np.ceil(far / bin_m))


def panorama_hit_depth_cpu(g: dict, centres, offsets, index, n_az: int, n_el: int, el_min: float, el_max: float,
                           near: float, far: float, bin_m: float = 0.01, threshold: float = 0.5) -> np.ndarray:
    """[G, C, E, A] hit depth (metres along the ray; inf: none) of the panoramas from centres
    [G, C, 3], group k seeing the Gaussians index[offsets[k]:offsets[k + 1]] of g (`ray_gaussians`)."""
    centres, offsets, index, n_bins = _check(g, centres, offsets, index, n_az, n_el, el_min, el_max, near, far,
                                             bin_m, threshold)
    dirs = panorama_dirs(n_az, el_min, el_max, n_el)
    return _panorama(g["means"], g["rt"], g["inv_s"], g["opac"], g["radius"], centres, offsets, index, dirs,
                     el_min, (el_max - el_min) / n_el, near, far, bin_m, n_bins, math.log1p(-threshold),
                     numba.get_num_threads())


@numba.njit(cache=True, fastmath=False)
def _group(means, rt, inv_s, opac, radius, o, idx, dirs, el_min, d_el, near, far, bin_m, n_bins, log_t, acc, out):
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
                if alpha < ALPHA_MIN:
                    continue
                b = min(int(t / bin_m), n_bins - 1)
                w = math.log1p(-min(alpha, ALPHA_MAX))
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
              log_t, nth):
    n_g, n_c = centres.shape[0], centres.shape[1]
    n_el, n_az = dirs.shape[0], dirs.shape[1]
    out = np.full((n_g, n_c, n_el, n_az), np.inf)
    for w in numba.prange(nth):  # worker w takes groups w, w + nth, ... (groups cost unevenly)
        acc = np.zeros((n_el, n_az, n_bins, 2))
        for gi in range(w, n_g, nth):
            idx = index[offsets[gi]:offsets[gi + 1]]
            for c in range(n_c):
                _group(means, rt, inv_s, opac, radius, centres[gi, c], idx, dirs, el_min, d_el, near, far, bin_m,
                       n_bins, log_t, acc, out[gi, c])
    return out


def panorama_hit_depth_torch(g: dict, centres, offsets, index, n_az: int, n_el: int, el_min: float, el_max: float,
                             near: float, far: float, bin_m: float = 0.01, threshold: float = 0.5,
                             device: str = "cuda", dtype=None, chunk: int = 4096) -> np.ndarray:
    """The same as `panorama_hit_depth_cpu`, every Gaussian of a group against every ray in
    chunks of ``chunk`` Gaussians (PyTorch; float32 on CUDA, float64 on the CPU by default)."""
    import torch

    centres, offsets, index, n_bins = _check(g, centres, offsets, index, n_az, n_el, el_min, el_max, near, far,
                                             bin_m, threshold)
    dtype = dtype or (torch.float64 if device == "cpu" else torch.float32)
    tt = lambda a: torch.as_tensor(np.asarray(a), device=device, dtype=dtype)  # noqa: E731
    dirs = tt(panorama_dirs(n_az, el_min, el_max, n_el).reshape(-1, 3))  # [R, 3]
    n_r = len(dirs)
    means, rt, inv_s, opac = tt(g["means"]), tt(g["rt"]), tt(g["inv_s"]), tt(g["opac"])
    log_t = math.log1p(-threshold)
    n_g, n_c = centres.shape[:2]
    out = np.full((n_g, n_c, n_r), np.inf)
    cen = tt(centres)
    for gi in range(n_g):
        idx = torch.as_tensor(index[offsets[gi]:offsets[gi + 1]], device=device)
        acc = torch.zeros(n_c * n_r * n_bins, device=device, dtype=dtype)
        acc_t = torch.zeros_like(acc)
        for s in range(0, len(idx), chunk):
            k = idx[s:s + chunk]
            d_loc = torch.einsum("nij,rj->rni", rt[k], dirs) * inv_s[k][None]  # [R, n, 3]
            dd = (d_loc * d_loc).sum(-1)
            for c in range(n_c):
                m_loc = torch.einsum("nij,nj->ni", rt[k], means[k] - cen[gi, c]) * inv_s[k]  # [n, 3]
                t = (d_loc * m_loc[None]).sum(-1) / dd
                d2 = torch.linalg.cross(m_loc[None].expand_as(d_loc), d_loc).square().sum(-1) / dd
                alpha = opac[k][None] * torch.exp(-0.5 * d2)
                ok = (alpha >= ALPHA_MIN) & (t >= near) & (t <= far)
                b = torch.clamp((t / bin_m).floor(), max=n_bins - 1).long()
                flat = (c * n_r + torch.arange(n_r, device=device)[:, None]) * n_bins + b
                w = torch.log1p(-alpha[ok].clamp(max=ALPHA_MAX))
                acc.index_add_(0, flat[ok], w)
                acc_t.index_add_(0, flat[ok], w * t[ok])
        acc, acc_t = acc.view(n_c, n_r, n_bins), acc_t.view(n_c, n_r, n_bins)
        cum = acc.cumsum(-1) <= log_t
        b = cum.to(torch.uint8).argmax(-1, keepdim=True)
        depth = (acc_t.gather(-1, b) / acc.gather(-1, b).clamp(max=-1e-300 if dtype == torch.float64 else -1e-30))[..., 0]
        out[gi] = torch.where(cum.any(-1), depth, torch.full((), float("inf"), device=device, dtype=dtype)).cpu().numpy()
    return out.reshape(n_g, n_c, n_el, n_az)
