"""CPU renderer in plain PyTorch: tile-based EWA splatting with the projection and compositing
rules of gsplat's classic mode (`rasterization(..., rasterize_mode="classic", packed=True)`), so
that its images match gsplat's.

The rules, as gsplat 1.5 applies them:
- projection: camera-frame covariance R Sigma R^T through the Jacobian of the pinhole projection
  at the mean, with x/z and y/z clamped to 1.3 x the half field of view (plus the principal point
  offset); 0.3 px^2 added to the 2D covariance (eps2d); culled when z <= 0.01 m (near plane), the
  2D determinant is not positive, or the opacity is below 1/255;
- footprint: per axis ceil(e sqrt(cov2d_ii)) pixels with e = min(3.33, sqrt(2 ln(255 alpha)))
  (opacity-aware box), binned into 16x16 tiles; a Gaussian touches only the pixels of its tiles;
- order: per tile by depth (camera z), ties by Gaussian index;
- compositing, front to back at pixel centres (u + 0.5, v + 0.5): sigma = 0.5 d^T conic d,
  alpha = min(0.999, opacity exp(-sigma)); skipped when sigma < 0 or alpha < 1/255; the pixel is
  done (exclusive) once the transmittance would drop to <= 1e-4;
- colour: SH evaluated at the direction from the camera centre to the mean, + 0.5, clamped at 0;
- depth: expected depth sum(w z) / sum(w) (gsplat's "ED"; 0 where nothing was hit).
"""
from __future__ import annotations

import math

import numpy as np
import torch

from navcore.gaussians.model import render_sh_degree
from navcore.gaussians.sh import sh_basis

TILE = 16
ALPHA_MIN = 1.0 / 255.0
T_MIN = 1e-4


def quat_to_rotmat(q: torch.Tensor) -> torch.Tensor:
    """[N, 4] (w, x, y, z) -> [N, 3, 3] rotation matrices (quaternions normalised first)."""
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1).reshape(-1, 3, 3)


def project(means, rotmats, scales, opacities, viewmat, K, width: int, height: int,
            near: float = 0.01, far: float = 1e10, eps2d: float = 0.3):
    """EWA projection of N Gaussians into one camera.

    Args:
        means [N, 3], rotmats [N, 3, 3], scales [N, 3] (standard deviations, m), opacities [N];
        viewmat [4, 4] world -> camera (OpenCV axes), K [3, 3].
    Returns:
        means2d [N, 2] px, conics [N, 3] (a, b, c of the inverse 2D covariance), depths [N] m,
        radii [N, 2] int (0 = culled).
    """
    R, t = viewmat[:3, :3], viewmat[:3, 3]
    mc = means @ R.T + t
    m = rotmats * scales[:, None, :]
    cov_c = R @ (m @ m.transpose(1, 2)) @ R.T
    tx, ty, tz = mc.unbind(-1)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    zs = torch.where(tz.abs() > 1e-12, tz, torch.full_like(tz, 1e-12))
    cx_ = zs * torch.clamp(tx / zs, -(cx / fx + 0.3 * tan_x), (width - cx) / fx + 0.3 * tan_x)
    cy_ = zs * torch.clamp(ty / zs, -(cy / fy + 0.3 * tan_y), (height - cy) / fy + 0.3 * tan_y)
    zero = torch.zeros_like(tz)
    J = torch.stack([fx / zs, zero, -fx * cx_ / zs**2, zero, fy / zs, -fy * cy_ / zs**2], -1).reshape(-1, 2, 3)
    cov2d = J @ cov_c @ J.transpose(1, 2)
    a, b, c = cov2d[:, 0, 0] + eps2d, cov2d[:, 0, 1], cov2d[:, 1, 1] + eps2d
    det = a * c - b * b
    ok = (tz > near) & (tz < far) & (det > 0) & (opacities >= ALPHA_MIN)
    det_s = torch.where(det > 0, det, torch.ones_like(det))
    conics = torch.stack([c / det_s, -b / det_s, a / det_s], -1)
    means2d = torch.stack([fx * tx / zs + cx, fy * ty / zs + cy], -1)
    extend = torch.clamp(torch.sqrt(2.0 * torch.log(torch.clamp(opacities / ALPHA_MIN, min=1.0))), max=3.33)
    rx = torch.ceil(extend * torch.sqrt(torch.clamp(a, min=0)))
    ry = torch.ceil(extend * torch.sqrt(torch.clamp(c, min=0)))
    ok &= (rx > 0) & (ry > 0)
    ok &= ~((means2d[:, 0] + rx <= 0) | (means2d[:, 0] - rx >= width) |
            (means2d[:, 1] + ry <= 0) | (means2d[:, 1] - ry >= height))
    radii = torch.stack([rx, ry], -1).to(torch.int64) * ok[:, None]
    return means2d, conics, tz, radii


def _tile_lists(means2d, radii, depths, width: int, height: int):
    """Intersections (tile, Gaussian) sorted by tile, then depth, then Gaussian index.
    Returns (gaussian ids [M], per-tile offsets [n_tiles + 1], tiles_x, tiles_y)."""
    tw, th = math.ceil(width / TILE), math.ceil(height / TILE)
    vis = torch.nonzero(radii[:, 0] > 0).squeeze(1)
    mx, my = means2d[vis, 0] / TILE, means2d[vis, 1] / TILE
    rx, ry = radii[vis, 0] / TILE, radii[vis, 1] / TILE
    x0 = torch.clamp(torch.floor(mx - rx), 0, tw).long()
    x1 = torch.clamp(torch.ceil(mx + rx), 0, tw).long()
    y0 = torch.clamp(torch.floor(my - ry), 0, th).long()
    y1 = torch.clamp(torch.ceil(my + ry), 0, th).long()
    nx, ny = x1 - x0, y1 - y0
    counts = nx * ny
    keep = counts > 0
    vis, x0, y0, nx, counts = vis[keep], x0[keep], y0[keep], nx[keep], counts[keep]
    gid = torch.repeat_interleave(vis, counts)
    start = torch.repeat_interleave(torch.cumsum(counts, 0) - counts, counts)
    k = torch.arange(int(counts.sum()), dtype=torch.int64) - start
    nxr = torch.repeat_interleave(nx, counts)
    tile = (torch.repeat_interleave(y0, counts) + k // nxr) * tw + torch.repeat_interleave(x0, counts) + k % nxr
    # stable sorts, least significant key first: Gaussian index (already ascending), depth, tile
    order = torch.argsort(depths[gid], stable=True)
    order = order[torch.argsort(tile[order], stable=True)]
    gid, tile = gid[order], tile[order]
    offsets = torch.searchsorted(tile, torch.arange(tw * th + 1, dtype=torch.int64))
    return gid, offsets, tw, th


def rasterize(means2d, conics, colors, opacities, depths, radii, width: int, height: int, chunk: int = 2048):
    """Front-to-back compositing of projected Gaussians (see the module rules).

    Args:
        means2d [N, 2], conics [N, 3], colors [N, C], opacities [N], depths [N], radii [N, 2].
    Returns:
        rgb [H, W, C], accumulated depth sum(w z) [H, W], alpha sum(w) [H, W] (float32).
    """
    C = colors.shape[1]
    gid, offsets, tw, th = _tile_lists(means2d, radii, depths, width, height)
    out = torch.zeros(th * TILE, tw * TILE, C + 2)
    feats = torch.cat([colors, depths[:, None], torch.ones_like(depths)[:, None]], 1)  # colour, z, 1
    py, px = torch.meshgrid(torch.arange(TILE, dtype=torch.float32), torch.arange(TILE, dtype=torch.float32),
                            indexing="ij")
    py, px = py.reshape(-1) + 0.5, px.reshape(-1) + 0.5
    counts = (offsets[1:] - offsets[:-1]).tolist()
    for t, n in enumerate(counts):
        if n == 0:
            continue
        ty, tx = divmod(t, tw)
        ux, uy = px + tx * TILE, py + ty * TILE  # [P] pixel centres
        T = torch.ones(TILE * TILE)
        acc = torch.zeros(TILE * TILE, C + 2)
        lo = int(offsets[t])
        for s in range(lo, lo + n, chunk):
            g = gid[s:min(s + chunk, lo + n)]
            dx = ux[:, None] - means2d[g, 0][None]  # [P, K]
            dy = uy[:, None] - means2d[g, 1][None]
            cg = conics[g]
            sigma = 0.5 * (cg[:, 0] * dx * dx + cg[:, 2] * dy * dy) + cg[:, 1] * dx * dy
            alpha = torch.clamp(opacities[g][None] * torch.exp(-sigma), max=0.999)
            alpha = torch.where((sigma >= 0) & (alpha >= ALPHA_MIN), alpha, torch.zeros_like(alpha))
            # transmittance after each Gaussian; a pixel stops (exclusive) at the first that would
            # bring it to <= T_MIN, and skipped Gaussians (alpha 0) do not change it
            t_after = T[:, None] * torch.cumprod(1.0 - alpha, 1)
            live = t_after > T_MIN
            live = torch.cumprod(live.to(torch.float32), 1)  # nothing after the stop
            t_before = torch.cat([T[:, None], t_after[:, :-1]], 1)
            w = alpha * t_before * live
            acc += w @ feats[g]
            stopped = live[:, -1] == 0
            T = torch.where(stopped, torch.zeros_like(T), t_after[:, -1])  # a stopped pixel takes no more
            if bool((T <= T_MIN).all()):
                break
        out[ty * TILE:(ty + 1) * TILE, tx * TILE:(tx + 1) * TILE] = acc.reshape(TILE, TILE, C + 2)
    out = out[:height, :width]
    return out[..., :C], out[..., C], out[..., C + 1]


def render(gs_tensors: dict, viewmats: np.ndarray, Ks: np.ndarray, width: int, height: int,
           sh_degree: int | None = None, near: float = 0.01, far: float = 1e10, features=None, extra=None):
    """Render a batch of cameras.

    Args:
        gs_tensors: dict of torch tensors (see `gaussian_tensors`): means [N, 3], rotmats [N, 3, 3],
            scales [N, 3], opacities [N], sh [N, K, 3].
        viewmats: [B, 4, 4] world -> camera (OpenCV axes). Ks: [B, 3, 3]. width, height: pixels.
        sh_degree: SH degree to evaluate (default: all the scene has).
        features: optional [N, C] per-Gaussian features composited instead of the SH colour (e.g.
            one-hot labels: the rendered channel sums are label weights); rgb is then [B, H, W, C].
        extra: optional [N, C] features composited with the colour in the same pass (rgb is then
            [B, H, W, 3 + C], colour first).
    Returns:
        rgb [B, H, W, 3] float32 in [0, 1] (clamped), depth [B, H, W] expected depth (m, 0 where
        empty), alpha [B, H, W].
    """
    g = gs_tensors
    deg = render_sh_degree(sh_degree, g["sh"].shape[1])
    rgbs, deps, alps = [], [], []
    with torch.no_grad():
        for vm, K in zip(np.asarray(viewmats, np.float32), np.asarray(Ks, np.float32)):
            vm_t, K_t = torch.from_numpy(vm), torch.from_numpy(K)
            means2d, conics, depths, radii = project(g["means"], g["rotmats"], g["scales"], g["opacities"], vm_t,
                                                     K_t, width, height, near, far)
            vis = radii[:, 0] > 0
            colors = torch.zeros(len(depths), 3)
            if features is not None:
                colors = torch.as_tensor(features, dtype=torch.float32)
            elif vis.any():
                campos = -vm_t[:3, :3].T @ vm_t[:3, 3]
                d = g["means"][vis] - campos
                d = d / d.norm(dim=1, keepdim=True).clamp(min=1e-12)
                basis = torch.from_numpy(sh_basis(d.numpy().astype(np.float64), deg).astype(np.float32))
                colors[vis] = torch.clamp((basis[:, :, None] * g["sh"][vis, :(deg + 1) ** 2]).sum(1) + 0.5, min=0.0)
            if extra is not None and features is None:
                colors = torch.cat([colors, torch.as_tensor(extra, dtype=torch.float32)], 1)
            rgb, dsum, alpha = rasterize(means2d, conics, colors, g["opacities"], depths, radii, width, height)
            rgbs.append(rgb)
            deps.append(dsum / alpha.clamp(min=1e-10))
            alps.append(alpha)
    return torch.stack(rgbs), torch.stack(deps), torch.stack(alps)


def gaussian_tensors(gs) -> dict:
    """A GaussianScene as the CPU renderer's torch tensors (computed once per scene)."""
    q = torch.from_numpy(gs.quats)
    return {"means": torch.from_numpy(gs.means), "rotmats": quat_to_rotmat(q),
            "scales": torch.exp(torch.from_numpy(gs.log_scales)),
            "opacities": torch.sigmoid(torch.from_numpy(gs.opacity_logits)), "sh": torch.from_numpy(gs.sh)}
