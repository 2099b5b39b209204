"""The CPU renderer's first pass: the scene prepared once, the cull (blocks, then each mean) and
the EWA projection of the candidates (2D conic, opacity-aware box, SH colour at the view direction)."""
from __future__ import annotations

import math

import numba
import numpy as np

from navcore.gaussians.sh import C0, C1, C2, C3
from navcore.render.cpu_fast.simd import ALPHA_MIN, EXTENT_MAX, SQRT_EPS2D, TILE


def prepare(gs) -> dict:
    """A GaussianScene as the renderer's arrays (computed once per scene)."""
    q = gs.quats.astype(np.float64)
    q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
    w, x, y, z = q.T
    rot = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                    2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                    2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1).reshape(-1, 3, 3)
    s = np.exp(gs.log_scales.astype(np.float64))
    m = rot * s[:, None, :]
    cov = m @ m.transpose(0, 2, 1)
    cov6 = np.stack([cov[:, 0, 0], cov[:, 0, 1], cov[:, 0, 2], cov[:, 1, 1], cov[:, 1, 2], cov[:, 2, 2]], 1)
    opac = 1.0 / (1.0 + np.exp(-gs.opacity_logits.astype(np.float64)))
    # gsplat's opacity-aware footprint extent (sigmas), a function of the opacity alone
    ext = np.minimum(EXTENT_MAX, np.sqrt(2.0 * np.log(np.maximum(opac * 255.0, 1.0))))
    blocks = _blocks(np.asarray(gs.means, np.float64), s.max(1))
    return {"blocks": blocks, "means": np.ascontiguousarray(gs.means, np.float32),
            "cov": np.ascontiguousarray(cov6, np.float32),
            "opacities": opac.astype(np.float32), "ext": ext.astype(np.float32),
            "lmax": np.log(np.maximum(opac * 255.0, 1e-30)).astype(np.float32),
            "smax": s.max(1).astype(np.float32),
            "sh": np.ascontiguousarray(gs.sh, np.float32)}


BLOCK = 256  # Gaussians of a culling block: consecutive in the scene's order
CULL_CHUNK = 32  # blocks a cull worker takes at a time


def _blocks(means: np.ndarray, smax: np.ndarray) -> np.ndarray:
    """[ceil(N / BLOCK), 5] float32 bounding spheres of consecutive runs of BLOCK Gaussians: centre
    (the box's middle), radius (widened by a relative 1e-5 + 1e-6 m for float32 rounding), largest
    standard deviation. Files in the wild are mostly in spatial order (SOG and SPZ writers sort
    along a Morton curve), so most blocks are small."""
    n = len(means)
    nb = (n + BLOCK - 1) // BLOCK
    pad = nb * BLOCK - n
    m = np.concatenate([means, np.repeat(means[-1:], pad, 0)]).reshape(nb, BLOCK, 3)  # padded with the last
    sm = np.concatenate([smax, np.repeat(smax[-1:], pad)]).reshape(nb, BLOCK)
    c = 0.5 * (m.min(1) + m.max(1))
    r = np.sqrt(((m - c[:, None]) ** 2).sum(-1)).max(1)
    r = r * (1 + 1e-5) + 1e-5 * np.abs(c).max(1) + 1e-6
    return np.column_stack([c, r, sm.max(1)]).astype(np.float32)


@numba.njit(cache=True, inline="always")
def _block_out(blocks, b, R, t, fx, fy, cx, cy, width, height, near, far, kx, ky):
    """Whether no Gaussian of block b can pass `_cull`'s test: its bounding sphere lies beyond the
    near or far plane, or beyond one side of the image widened by the largest footprint bound (the
    per-Gaussian test multiplied by the depth is linear in the mean)."""
    bx, by, bz, r, s = blocks[b, 0], blocks[b, 1], blocks[b, 2], blocks[b, 3], blocks[b, 4]
    x = R[0, 0] * bx + R[0, 1] * by + R[0, 2] * bz + t[0]
    y = R[1, 0] * bx + R[1, 1] * by + R[1, 2] * bz + t[1]
    z = R[2, 0] * bx + R[2, 1] * by + R[2, 2] * bz + t[2]
    if z + r <= near or z - r >= far:
        return True
    pad = EXTENT_MAX * SQRT_EPS2D + 1.0
    ex = EXTENT_MAX * fx * kx * s
    ey = EXTENT_MAX * fy * ky * s
    c = cx + pad  # left: u + rx <= 0  <=>  fx x + (cx + pad) z + ex <= 0
    if fx * x + c * z + r * math.sqrt(fx * fx + c * c) + ex <= 0:
        return True
    c = cx - pad - width  # right: u - rx >= width  <=>  fx x + (cx - pad - width) z - ex >= 0
    if fx * x + c * z - r * math.sqrt(fx * fx + c * c) - ex >= 0:
        return True
    c = cy + pad
    if fy * y + c * z + r * math.sqrt(fy * fy + c * c) + ey <= 0:
        return True
    c = cy - pad - height
    return fy * y + c * z - r * math.sqrt(fy * fy + c * c) - ey >= 0


@numba.njit(cache=True, parallel=True)
def _cull(means, smax, opac, blocks, R, t, fx, fy, cx, cy, width, height, near, far, lim_x, lim_y, nth):
    """The indices (ascending) of the Gaussians that may be visible (a superset of gsplat's
    survivors); blocks wholly outside the view are passed over without reading their Gaussians."""
    n = means.shape[0]
    nb = blocks.shape[0]
    kx = math.sqrt(1.0 + lim_x * lim_x)
    ky = math.sqrt(1.0 + lim_y * lim_y)
    keep = np.zeros(n, np.uint8)
    counts = np.zeros(nb + 1, np.int64)
    nch = (nb + CULL_CHUNK - 1) // CULL_CHUNK
    for wk in numba.prange(nth):  # worker wk: chunks wk, wk + nth, ... (see `_rasterize`)
        for ch in range(wk, nch, nth):
            for b in range(ch * CULL_CHUNK, min(nb, (ch + 1) * CULL_CHUNK)):
                if _block_out(blocks, b, R, t, fx, fy, cx, cy, width, height, near, far, kx, ky):
                    continue
                c = 0
                for i in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
                    if _visible(means, smax, opac, i, R, t, fx, fy, cx, cy, width, height, near, far, kx, ky):
                        keep[i] = 1
                        c += 1
                counts[b + 1] = c
    for b in range(nb):
        counts[b + 1] += counts[b]
    idx = np.empty(counts[nb], np.int64)
    for b in numba.prange(nb):
        k = counts[b]
        if counts[b + 1] == k:
            continue
        for i in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            if keep[i]:
                idx[k] = i
                k += 1
    return idx


@numba.njit(cache=True, inline="always")
def _visible(means, smax, opac, i, R, t, fx, fy, cx, cy, width, height, near, far, kx, ky):
    """Gaussian i's cull test (conservative: gsplat's near / far rule on the mean, the image
    rectangle widened by an upper bound on the footprint from its largest standard deviation)."""
    if opac[i] < ALPHA_MIN:
        return False
    mx, my, mz = means[i, 0], means[i, 1], means[i, 2]
    z = R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz + t[2]
    if z <= near or z >= far:
        return False
    x = R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz + t[0]
    y = R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz + t[1]
    # footprint bound: e sqrt(J Sigma J^T + eps) <= e (sqrt(eps) + |J_row| smax), + 1 for the ceil
    rx = EXTENT_MAX * (SQRT_EPS2D + fx * kx * smax[i] / z) + 1.0
    ry = EXTENT_MAX * (SQRT_EPS2D + fy * ky * smax[i] / z) + 1.0
    u = fx * x / z + cx
    v = fy * y / z + cy
    return not (u + rx <= 0 or u - rx >= width or v + ry <= 0 or v - ry >= height)



@numba.njit(cache=True, inline="always")
def _sh_channel(sh, i, c, dx, dy, dz, deg):
    """max(SH(i) channel c at the unit direction (dx, dy, dz) + 0.5, 0) (3DGS basis), rounded to
    float32 after each degree's terms."""
    v = np.float32(C0 * sh[i, 0, c] + (-C1 * dy * sh[i, 1, c] + C1 * dz * sh[i, 2, c] - C1 * dx * sh[i, 3, c])
                   if deg >= 1 else C0 * sh[i, 0, c])
    if deg >= 2:
        xx, yy, zz, xy, yz, xz = dx * dx, dy * dy, dz * dz, dx * dy, dy * dz, dx * dz
        v = np.float32(v + (C2[0] * xy * sh[i, 4, c] + C2[1] * yz * sh[i, 5, c] + C2[2] * (2 * zz - xx - yy) * sh[i, 6, c]
                            + C2[3] * xz * sh[i, 7, c] + C2[4] * (xx - yy) * sh[i, 8, c]))
        if deg >= 3:
            v = np.float32(v + (C3[0] * dy * (3 * xx - yy) * sh[i, 9, c] + C3[1] * xy * dz * sh[i, 10, c]
                                + C3[2] * dy * (4 * zz - xx - yy) * sh[i, 11, c]
                                + C3[3] * dz * (2 * zz - 3 * xx - 3 * yy) * sh[i, 12, c]
                                + C3[4] * dx * (4 * zz - xx - yy) * sh[i, 13, c] + C3[5] * dz * (xx - yy) * sh[i, 14, c]
                                + C3[6] * dx * (xx - 3 * yy) * sh[i, 15, c]))
    return max(v + np.float32(0.5), np.float32(0.0))


# per-row render data: u, v, rx, ry (px), conic a, b, c, opacity, depth, ln(255 opacity) (alpha >=
# 1/255 iff sigma <= it)
U, V, RX, RY, CA, CB, CC, OP, Z, LM = range(10)
NDATA = 10


@numba.njit(cache=True, parallel=True)
def _project(idx, means, cov, opac, ext, lmax, R, t, fx, fy, cx, cy, width, height, eps2d,
             lim_lo_x, lim_hi_x, lim_lo_y, lim_hi_y, pos, data, box, gid):
    """EWA projection of the candidates idx into row r = pos[j] of data (see U..LM), box[r] =
    (x0, x1, y0, y1), the tile range (x1 = x0 when culled), and gid[r] = idx[j]. Reading in index
    order and writing each row at its depth rank leaves the rows depth-ordered without a gather.
    The colour is not evaluated here: the rasteriser does it for the Gaussians that contribute."""
    tw = (width + TILE - 1) // TILE
    th = (height + TILE - 1) // TILE
    for j in numba.prange(idx.shape[0]):
        i = idx[j]
        r = pos[j]
        gid[r] = i
        box[r, 0] = 0
        box[r, 1] = 0
        box[r, 2] = 0
        box[r, 3] = 0
        mx, my, mz = means[i, 0], means[i, 1], means[i, 2]
        x = R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz + t[0]
        y = R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz + t[1]
        z = R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz + t[2]
        # camera-frame covariance V = R Sigma R^T
        s00, s01, s02, s11, s12, s22 = cov[i, 0], cov[i, 1], cov[i, 2], cov[i, 3], cov[i, 4], cov[i, 5]
        a0 = R[0, 0] * s00 + R[0, 1] * s01 + R[0, 2] * s02
        a1 = R[0, 0] * s01 + R[0, 1] * s11 + R[0, 2] * s12
        a2 = R[0, 0] * s02 + R[0, 1] * s12 + R[0, 2] * s22
        b0 = R[1, 0] * s00 + R[1, 1] * s01 + R[1, 2] * s02
        b1 = R[1, 0] * s01 + R[1, 1] * s11 + R[1, 2] * s12
        b2 = R[1, 0] * s02 + R[1, 1] * s12 + R[1, 2] * s22
        c0 = R[2, 0] * s00 + R[2, 1] * s01 + R[2, 2] * s02
        c1 = R[2, 0] * s01 + R[2, 1] * s11 + R[2, 2] * s12
        c2 = R[2, 0] * s02 + R[2, 1] * s12 + R[2, 2] * s22
        v00 = a0 * R[0, 0] + a1 * R[0, 1] + a2 * R[0, 2]
        v01 = a0 * R[1, 0] + a1 * R[1, 1] + a2 * R[1, 2]
        v02 = a0 * R[2, 0] + a1 * R[2, 1] + a2 * R[2, 2]
        v11 = b0 * R[1, 0] + b1 * R[1, 1] + b2 * R[1, 2]
        v12 = b0 * R[2, 0] + b1 * R[2, 1] + b2 * R[2, 2]
        v22 = c0 * R[2, 0] + c1 * R[2, 1] + c2 * R[2, 2]
        # Jacobian of the pinhole at the clamped mean; cov2d = J V J^T + eps2d
        txz = min(max(x / z, lim_lo_x), lim_hi_x) * z
        tyz = min(max(y / z, lim_lo_y), lim_hi_y) * z
        j00 = fx / z
        j02 = -fx * txz / (z * z)
        j11 = fy / z
        j12 = -fy * tyz / (z * z)
        ca = j00 * (j00 * v00 + j02 * v02) + j02 * (j00 * v02 + j02 * v22) + eps2d
        cb = j00 * (j11 * v01 + j12 * v02) + j02 * (j11 * v12 + j12 * v22)
        cc = j11 * (j11 * v11 + j12 * v12) + j12 * (j11 * v12 + j12 * v22) + eps2d
        det = ca * cc - cb * cb
        if not det > 0:
            continue
        rx = math.ceil(ext[i] * math.sqrt(max(ca, 0.0)))
        ry = math.ceil(ext[i] * math.sqrt(max(cc, 0.0)))
        u = fx * x / z + cx
        v = fy * y / z + cy
        if rx <= 0 or ry <= 0 or u + rx <= 0 or u - rx >= width or v + ry <= 0 or v - ry >= height:
            continue
        x0 = min(max(int(math.floor((u - rx) / TILE)), 0), tw)
        x1 = min(max(int(math.ceil((u + rx) / TILE)), 0), tw)
        y0 = min(max(int(math.floor((v - ry) / TILE)), 0), th)
        y1 = min(max(int(math.ceil((v + ry) / TILE)), 0), th)
        if x1 <= x0 or y1 <= y0:
            continue
        box[r, 0], box[r, 1], box[r, 2], box[r, 3] = x0, x1, y0, y1
        data[r, U], data[r, V], data[r, RX], data[r, RY] = u, v, rx, ry
        data[r, CA], data[r, CB], data[r, CC] = cc / det, -cb / det, ca / det
        data[r, OP], data[r, Z], data[r, LM] = opac[i], z, lmax[i]


@numba.njit(cache=True, inline="always")
def _features(i, means, sh, deg, feats_in, campos, col):
    """col = Gaussian i's composited features: the SH colour at the view direction (deg >= 0) then
    feats_in[i]."""
    k0 = 0
    if deg >= 0:
        dx, dy, dz = means[i, 0] - campos[0], means[i, 1] - campos[1], means[i, 2] - campos[2]
        nrm = max(math.sqrt(dx * dx + dy * dy + dz * dz), 1e-12)
        ux, uy, uz = dx / nrm, dy / nrm, dz / nrm
        for c in range(3):
            col[c] = _sh_channel(sh, i, c, ux, uy, uz, deg)
        k0 = 3
    for k in range(k0, col.shape[0]):
        col[k] = feats_in[i, k - k0]


