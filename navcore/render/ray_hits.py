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

Two implementations that agree to rounding: `panorama_hit_depth_cpu` (numba, parallel over groups,
float64; its kernel in ray_hits_kernel.py, imported on first use so that the CUDA path needs no
numba) and `panorama_hit_depth_torch` (PyTorch, every Gaussian of a group against every ray in
chunks, for CUDA; on the CPU it is the independent reference the tests compare with).
"""
from __future__ import annotations

import math

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
    import numba

    from navcore.render.ray_hits_kernel import _panorama

    dirs = panorama_dirs(n_az, el_min, el_max, n_el)
    return _panorama(g["means"], g["rt"], g["inv_s"], g["opac"], g["radius"], centres, offsets, index, dirs,
                     el_min, (el_max - el_min) / n_el, near, far, bin_m, n_bins, math.log1p(-threshold), ALPHA_MIN,
                     ALPHA_MAX, numba.get_num_threads())


def panorama_hit_depth_torch(g: dict, centres, offsets, index, n_az: int, n_el: int, el_min: float, el_max: float,
                             near: float, far: float, bin_m: float = 0.01, threshold: float = 0.5,
                             device: str = "cuda", dtype=None, cull: bool = True, chunk: int = 4096,
                             max_bins: int = 1 << 27) -> np.ndarray:
    """The same as `panorama_hit_depth_cpu` in PyTorch (float32 on CUDA, float64 on the CPU by
    default). cull=True: each Gaussian against the rays of its cap's rectangle only (the CPU
    kernel's rule, as (Gaussian, ray) pair lists, chunk x 1024 pairs a pass, as many groups at once
    as max_bins depth bins hold); cull=False: every Gaussian of a group against every ray,
    ``chunk`` Gaussians at a time (the brute-force reference the tests compare with)."""
    import torch

    centres, offsets, index, n_bins = _check(g, centres, offsets, index, n_az, n_el, el_min, el_max, near, far,
                                             bin_m, threshold)
    dtype = dtype or (torch.float64 if device == "cpu" else torch.float32)
    tt = lambda a: torch.as_tensor(np.asarray(a), device=device, dtype=dtype)  # noqa: E731
    dirs = tt(panorama_dirs(n_az, el_min, el_max, n_el).reshape(-1, 3))  # [R, 3]
    n_r = len(dirs)
    means, rt, inv_s, opac, radius = tt(g["means"]), tt(g["rt"]), tt(g["inv_s"]), tt(g["opac"]), tt(g["radius"])
    n_g, n_c = centres.shape[:2]
    out = np.full((n_g, n_c, n_r), np.inf)
    cen = tt(centres)
    per_group = n_c * n_r * n_bins
    step = 1 if not cull else max(1, max_bins // per_group)
    for g0 in range(0, n_g, step):
        g1 = min(n_g, g0 + step)
        acc = torch.zeros((g1 - g0) * per_group, device=device, dtype=dtype)
        acc_t = torch.zeros_like(acc)

        def add(gauss, origin, slot, ray):  # hits of Gaussians on rays from origins, into bins of (slot, ray)
            d_loc = torch.einsum("pij,pj->pi", rt[gauss], dirs[ray]) * inv_s[gauss]
            m_loc = torch.einsum("pij,pj->pi", rt[gauss], means[gauss] - origin) * inv_s[gauss]
            dd = (d_loc * d_loc).sum(-1)
            t = (d_loc * m_loc).sum(-1) / dd
            alpha = opac[gauss] * torch.exp(-0.5 * torch.linalg.cross(m_loc, d_loc).square().sum(-1) / dd)
            ok = (alpha >= ALPHA_MIN) & (t >= near) & (t <= far)
            b = torch.clamp((t[ok] / bin_m).floor(), max=n_bins - 1).long()
            flat = (slot[ok] * n_r + ray[ok]) * n_bins + b
            w = torch.log1p(-alpha[ok].clamp(max=ALPHA_MAX))
            acc.index_add_(0, flat, w)
            acc_t.index_add_(0, flat, w * t[ok])

        idx = torch.as_tensor(index[offsets[g0]:offsets[g1]], device=device)
        grp = torch.as_tensor(np.repeat(np.arange(g1 - g0), np.diff(offsets[g0:g1 + 1])), device=device)
        if not cull:
            rays = torch.arange(n_r, device=device)
            for s in range(0, len(idx), chunk):
                for c in range(n_c):
                    gg, rr = torch.meshgrid(idx[s:s + chunk], rays, indexing="ij")
                    slot = torch.full((gg.numel(),), c, device=device)
                    add(gg.reshape(-1), cen[g0, c][None], slot, rr.reshape(-1))
        elif len(idx):
            # each (centre, Gaussian)'s rectangle of the grid, as in the CPU kernel; cells [C, n]
            org = cen[g0:g1][grp].transpose(0, 1)  # [C, n, 3] the centre each cell's rays leave
            m = means[idx][None] - org
            dist = m.norm(dim=-1)
            r = radius[idx][None].expand_as(dist)
            inside = dist <= r
            a = torch.asin(torch.clamp(r / dist.clamp(min=1e-12), max=1.0))
            ec = torch.asin(torch.clamp(m[..., 2] / dist.clamp(min=1e-12), -1.0, 1.0))
            d_el = (el_max - el_min) / n_el
            e0 = torch.where(inside, 0, torch.floor((ec - a - el_min) / d_el).clamp(min=0).long())
            e1 = torch.where(inside, n_el - 1, torch.floor((ec + a - el_min) / d_el).clamp(max=n_el - 1).long())
            full = inside | (ec.abs() + a >= 0.5 * math.pi - 1e-9)
            half = torch.asin(torch.clamp(torch.sin(a) / torch.cos(ec).clamp(min=1e-12), max=1.0))
            azc = torch.atan2(m[..., 1], m[..., 0])
            d_az = 2 * math.pi / n_az
            lo_j = torch.floor((azc - half) / d_az - 0.5).long()
            a_lo = torch.where(full, 0, lo_j).reshape(-1)
            n_a = torch.where(full, n_az, torch.clamp(torch.floor((azc + half) / d_az - 0.5).long() - lo_j + 2,
                                                      max=n_az)).reshape(-1)
            count = (torch.clamp(e1 - e0 + 1, min=0) * (dist - r <= far)).reshape(-1) * n_a
            e0 = e0.reshape(-1)
            starts = torch.cumsum(count, 0) - count
            total, n = int(count.sum()), len(idx)
            for s in range(0, total, max(1, chunk * 1024)):
                q = torch.arange(s, min(total, s + chunk * 1024), device=device)
                cell = torch.searchsorted(starts, q, right=True) - 1
                local = q - starts[cell]
                na = n_a[cell]
                ray = (e0[cell] + local // na) * n_az + torch.remainder(a_lo[cell] + local % na, n_az)
                c, i = cell // n, cell % n
                add(idx[i], org[c, i], grp[i] * n_c + c, ray)
        acc, acc_t = acc.view(g1 - g0, n_c, n_r, n_bins), acc_t.view(g1 - g0, n_c, n_r, n_bins)
        cum = acc.cumsum(-1) <= math.log1p(-threshold)
        b = cum.to(torch.uint8).argmax(-1, keepdim=True)
        depth = (acc_t.gather(-1, b) / acc.gather(-1, b).clamp(max=-1e-300 if dtype == torch.float64 else -1e-30))[..., 0]
        out[g0:g1] = torch.where(cum.any(-1), depth, torch.full((), float("inf"), device=device, dtype=dtype)).cpu().numpy()
    return out.reshape(n_g, n_c, n_el, n_az)
