"""The CPU renderer: compiled (numba) EWA splatting with gsplat's classic-mode rules.

Same rules as `navcore/render/cpu.py` (the plain-PyTorch reference, which documents them and
was checked against gsplat on an H100), organised so that the work is proportional to what the
camera sees rather than to the scene:

1. cull: one pass over the means with a conservative test (near / far plane on the mean depth,
   gsplat's rule; the image rectangle widened by an upper bound on each Gaussian's footprint,
   from its largest standard deviation), so only candidates get the full projection;
2. order: a stable LSD radix sort of the candidates' depth keys (float bits; ties keep the
   Gaussian index order, gsplat's order);
3. project the candidates (EWA with the clamped Jacobian, eps2d, opacity-aware box) in
   parallel, reading them in index order and writing each row at its depth rank, then a counting
   sort into 16x16 tiles, so each tile's list is by depth then index;
4. rasterise: tiles in parallel, each Gaussian visiting only the pixels of its box inside the
   tile (outside the box its alpha is below 1/255 by construction of the box, so gsplat skips
   them too), and within a row only the span where alpha >= 1/255; a per-row bitmask of finished
   pixels skips a whole span once all its pixels are done; front to back with the exclusive stop
   at T <= 1e-4, a tile ending when all its pixels are done. A Gaussian's colour (SH at the view
   direction) is evaluated when it first contributes to a tile: in a real room only about a
   quarter of the candidates reach a pixel, and the SH coefficients are most of the bytes read.

The scene is prepared once (`prepare`): float32 means, the 3D covariances, opacities, SH
coefficients and each Gaussian's largest standard deviation.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from navcore.gaussians.sh import C0, C1, C2, C3

TILE = 16
ALPHA_MIN = np.float32(1.0 / 255.0)
T_MIN = np.float32(1e-4)
EXTENT_MAX = 3.33  # gsplat's cap on the footprint extent (sigmas)


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
    return {"means": np.ascontiguousarray(gs.means, np.float32),
            "cov": np.ascontiguousarray(cov6, np.float32),
            "opacities": opac.astype(np.float32), "ext": ext.astype(np.float32),
            "lmax": np.log(np.maximum(opac * 255.0, 1e-30)).astype(np.float32),
            "smax": s.max(1).astype(np.float32),
            "sh": np.ascontiguousarray(gs.sh, np.float32)}


@numba.njit(cache=True, parallel=True)
def _cull(means, smax, opac, R, t, fx, fy, cx, cy, width, height, near, far, lim_x, lim_y, keep):
    """keep[i] = 1 when Gaussian i may be visible (a superset of gsplat's survivors)."""
    n = means.shape[0]
    kx = math.sqrt(1.0 + lim_x * lim_x)
    ky = math.sqrt(1.0 + lim_y * lim_y)
    for i in numba.prange(n):
        keep[i] = 0
        if opac[i] < ALPHA_MIN:
            continue
        mx, my, mz = means[i, 0], means[i, 1], means[i, 2]
        z = R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz + t[2]
        if z <= near or z >= far:
            continue
        x = R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz + t[0]
        y = R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz + t[1]
        # footprint bound: e sqrt(J Sigma J^T + eps) <= e (sqrt(eps) + |J_row| smax), + 1 for the ceil
        rx = EXTENT_MAX * (0.5478 + fx * kx * smax[i] / z) + 1.0
        ry = EXTENT_MAX * (0.5478 + fy * ky * smax[i] / z) + 1.0
        u = fx * x / z + cx
        v = fy * y / z + cy
        if u + rx <= 0 or u - rx >= width or v + ry <= 0 or v - ry >= height:
            continue
        keep[i] = 1


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


SMALL_BOX = 6  # rasterise boxes at most this many pixels wide without solving for the row spans

CHUNKS = 16  # work split of the sorts (fixed, so that the output does not depend on the thread count)


@numba.njit(cache=True, parallel=True)
def _depths(idx, means, R, t, z):
    """Camera depth of the candidates (the same float32 arithmetic as the projection's)."""
    for j in numba.prange(idx.shape[0]):
        i = idx[j]
        z[j] = R[2, 0] * means[i, 0] + R[2, 1] * means[i, 1] + R[2, 2] * means[i, 2] + t[2]


@numba.njit(cache=True, parallel=True)
def _depth_order(z):
    """Positions of z in increasing order; stable (ties keep their order, i.e. the Gaussian index
    order, as gsplat): a parallel LSD radix sort of the float bits (positive floats order as their
    bits), 3 x 11 bits, with a fixed work split so that the result does not depend on the thread
    count."""
    n = z.shape[0]
    ka = z.view(np.uint32).copy()
    va = np.arange(n).astype(np.int32)
    kb = np.empty_like(ka)
    vb = np.empty_like(va)
    hist = np.zeros((CHUNKS, 2048), np.int64)
    for shift in (0, 11, 22):
        for c in numba.prange(CHUNKS):
            lo, hi = c * n // CHUNKS, (c + 1) * n // CHUNKS
            for d in range(2048):
                hist[c, d] = 0
            for k in range(lo, hi):
                hist[c, (ka[k] >> shift) & 2047] += 1
        total = 0
        for d in range(2048):
            for c in range(CHUNKS):
                h = hist[c, d]
                hist[c, d] = total
                total += h
        for c in numba.prange(CHUNKS):
            lo, hi = c * n // CHUNKS, (c + 1) * n // CHUNKS
            for k in range(lo, hi):
                d = (ka[k] >> shift) & 2047
                q = hist[c, d]
                hist[c, d] = q + 1
                kb[q] = ka[k]
                vb[q] = va[k]
        ka, kb = kb, ka
        va, vb = vb, va
    return va


@numba.njit(cache=True, inline="always")
def _tile_box(data, k, px0, py0, pw, ph):
    """Row k's pixel box in the tile at (px0, py0) of pw x ph pixels, tile-local and packed in a
    uint32 as x0 | x1 << 8 | y0 << 16 | y1 << 24 (pixels x0 <= x < x1, y0 <= y < y1 whose centre
    lies in the footprint: alpha < 1/255 outside it); 0 when empty."""
    u, v, rx, ry = data[k, U], data[k, V], data[k, RX], data[k, RY]
    x0 = max(0, int(math.floor(u - rx - 0.5)) - px0)
    x1 = min(pw, int(math.ceil(u + rx + 0.5)) - px0)
    y0 = max(0, int(math.floor(v - ry - 0.5)) - py0)
    y1 = min(ph, int(math.ceil(v + ry + 0.5)) - py0)
    if x1 <= x0 or y1 <= y0:
        return np.uint32(0)
    return np.uint32(x0) | np.uint32(x1) << np.uint32(8) | np.uint32(y0) << np.uint32(16) | np.uint32(y1) << np.uint32(24)


@numba.njit(cache=True, parallel=True)
def _bin(box, data, width, height):
    """Counting sort of the (depth-ordered) rows into tiles: (rows [M], their pixel boxes in the
    tile [M] (`_tile_box`), offsets [tw * th + 1]); each tile's rows stay in ascending order, and
    a row is listed only in the tiles where its pixel box is not empty."""
    tw = (width + TILE - 1) // TILE
    th = (height + TILE - 1) // TILE
    n = box.shape[0]
    nt = tw * th
    counts = np.zeros((CHUNKS, nt), np.int64)
    for c in numba.prange(CHUNKS):
        for k in range(c * n // CHUNKS, (c + 1) * n // CHUNKS):
            for ty in range(box[k, 2], box[k, 3]):
                for tx in range(box[k, 0], box[k, 1]):
                    if _tile_box(data, k, tx * TILE, ty * TILE, min(TILE, width - tx * TILE),
                                 min(TILE, height - ty * TILE)):
                        counts[c, ty * tw + tx] += 1
    offsets = np.empty(nt + 1, np.int64)
    total = 0
    for tt in range(nt):
        offsets[tt] = total
        for c in range(CHUNKS):
            h = counts[c, tt]
            counts[c, tt] = total
            total += h
    offsets[nt] = total
    rows = np.empty(total, np.int32)
    pbox = np.empty(total, np.uint32)
    for c in numba.prange(CHUNKS):
        for k in range(c * n // CHUNKS, (c + 1) * n // CHUNKS):
            for ty in range(box[k, 2], box[k, 3]):
                for tx in range(box[k, 0], box[k, 1]):
                    pb = _tile_box(data, k, tx * TILE, ty * TILE, min(TILE, width - tx * TILE), min(TILE, height - ty * TILE))
                    if pb:
                        tt = ty * tw + tx
                        rows[counts[c, tt]] = k
                        pbox[counts[c, tt]] = pb
                        counts[c, tt] += 1
    return rows, pbox, offsets


@numba.njit(cache=True, parallel=True)
def _rasterize(rows, pbox, offsets, data, gid, means, sh, deg, feats_in, campos, nf, width, height, out):
    """out[H, W, nf + 2] = (sum w f, sum w z, sum w) per pixel, front to back per tile; a
    Gaussian's features (`_features`) are evaluated when it first contributes to a tile."""
    tw = (width + TILE - 1) // TILE
    nt = offsets.shape[0] - 1
    for tt in numba.prange(nt):
        ty, tx = tt // tw, tt % tw
        px0, py0 = tx * TILE, ty * TILE
        pw = min(TILE, width - px0)
        ph = min(TILE, height - py0)
        T = np.ones(TILE * TILE, np.float32)
        acc = np.zeros((TILE * TILE, nf + 2), np.float32)
        col = np.empty(nf, np.float32)
        hit_p = np.empty(TILE * TILE, np.int32)  # the current Gaussian's composited pixels and weights
        hit_w = np.empty(TILE * TILE, np.float32)
        done = np.zeros(TILE, np.uint32)  # per tile row, bit x set once pixel x is finished
        left = pw * ph
        for k in range(offsets[tt], offsets[tt + 1]):
            # the pixels of its box (alpha < 1/255 outside it); the Gaussian is skipped when all of
            # them are finished (bit tests only: its render data is not read)
            pb = pbox[k]
            qx0 = px0 + int(pb & np.uint32(255))
            qx1 = px0 + int(pb >> np.uint32(8) & np.uint32(255))
            qy0 = py0 + int(pb >> np.uint32(16) & np.uint32(255))
            qy1 = py0 + int(pb >> np.uint32(24))
            bm = ((np.uint32(1) << np.uint32(qx1 - qx0)) - np.uint32(1)) << np.uint32(qx0 - px0)
            hidden = True
            for py in range(qy0, qy1):
                if done[py - py0] & bm != bm:
                    hidden = False
                    break
            if hidden:
                continue
            j = rows[k]
            u, v = data[j, U], data[j, V]
            ca, cb, cc = data[j, CA], data[j, CB], data[j, CC]
            o, z = data[j, OP], data[j, Z]
            lm = data[j, LM]
            # per row, only the span where sigma <= ln(255 o), i.e. alpha >= 1/255 (widened by a
            # rounding margin)
            ha = np.float32(0.5) * ca
            hc = np.float32(0.5) * cc
            small = (qx1 - qx0) <= SMALL_BOX
            m = 0
            for py in range(qy0, qy1):
                dm = done[py - py0]
                if dm & bm == bm:
                    continue
                dy = np.float32(py + 0.5) - v
                sy = hc * dy * dy
                if small:  # a few pixels: test them all (cheaper than solving for the span)
                    r0, r1 = qx0, qx1
                else:
                    bq = cb * dy
                    disc = bq * bq - np.float32(4.0) * ha * (sy - lm)
                    if disc < 0 or ha <= 0:
                        continue
                    sq = math.sqrt(disc)
                    r0 = max(qx0, int(math.floor(u + (-bq - sq) / (np.float32(2.0) * ha) - np.float32(0.501))))
                    r1 = min(qx1, int(math.ceil(u + (-bq + sq) / (np.float32(2.0) * ha) - np.float32(0.499))) + 1)
                    if r1 <= r0:
                        continue
                    span = ((np.uint32(1) << np.uint32(r1 - r0)) - np.uint32(1)) << np.uint32(r0 - px0)
                    if dm & span == span:  # every pixel of the span finished: nothing to composite
                        continue
                rowp = (py - py0) * TILE - px0
                for px in range(r0, r1):
                    p = rowp + px
                    if dm >> np.uint32(px - px0) & np.uint32(1):
                        continue
                    dx = np.float32(px + 0.5) - u
                    sigma = ha * dx * dx + sy + cb * dx * dy
                    if sigma < 0 or sigma > lm:
                        continue
                    alpha = min(np.float32(0.999), o * math.exp(-sigma))
                    if alpha < ALPHA_MIN:
                        continue
                    tp = T[p]
                    tn = tp * (np.float32(1.0) - alpha)
                    if tn <= T_MIN:
                        dm |= np.uint32(1) << np.uint32(px - px0)
                        left -= 1
                        continue
                    hit_p[m] = p
                    hit_w[m] = alpha * tp
                    m += 1
                    T[p] = tn
                done[py - py0] = dm
            if m > 0:
                _features(gid[j], means, sh, deg, feats_in, campos, col)
                for q in range(m):
                    p = hit_p[q]
                    wgt = hit_w[q]
                    for c in range(nf):
                        acc[p, c] += wgt * col[c]
                    acc[p, nf] += wgt * z
                    acc[p, nf + 1] += wgt
            if left == 0:
                break
        for py in range(ph):
            for px in range(pw):
                p = py * TILE + px
                for c in range(nf + 2):
                    out[py0 + py, px0 + px, c] = acc[p, c]


def render_one(g: dict, viewmat: np.ndarray, K: np.ndarray, width: int, height: int, deg: int,
               near: float = 0.01, far: float = 1e10, eps2d: float = 0.3, features=None, extra=None):
    """One camera -> (feats [H, W, C], depth [H, W], alpha [H, W]) float32 numpy arrays."""
    R = np.ascontiguousarray(viewmat[:3, :3], np.float32)
    t = np.ascontiguousarray(viewmat[:3, 3], np.float32)
    fx, fy, cx, cy = (float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    lo_x, hi_x = -(cx / fx + 0.3 * tan_x), (width - cx) / fx + 0.3 * tan_x
    lo_y, hi_y = -(cy / fy + 0.3 * tan_y), (height - cy) / fy + 0.3 * tan_y
    n = len(g["means"])
    keep = np.empty(n, np.uint8)
    _cull(g["means"], g["smax"], g["opacities"], R, t, fx, fy, cx, cy, width, height, near, far,
          max(-lo_x, hi_x), max(-lo_y, hi_y), keep)
    idx = np.flatnonzero(keep)
    if features is not None:
        feats_in, d = np.ascontiguousarray(features, np.float32), -1
    elif extra is not None:
        feats_in, d = np.ascontiguousarray(extra, np.float32), deg
    else:
        feats_in, d = np.zeros((n, 0), np.float32), deg
    nf = feats_in.shape[1] + (3 if d >= 0 else 0)
    # depth ranks first (stable: ties keep the index order, as gsplat), so that the projection
    # writes each row at its place front to back
    z = np.empty(len(idx), np.float32)
    _depths(idx, g["means"], R, t, z)
    pos = np.empty(len(idx), np.int32)
    pos[_depth_order(z)] = np.arange(len(idx), dtype=np.int32)
    data = np.empty((len(idx), NDATA), np.float32)
    box = np.empty((len(idx), 4), np.int32)
    gid = np.empty(len(idx), np.int64)
    _project(idx, g["means"], g["cov"], g["opacities"], g["ext"], g["lmax"], R, t, fx, fy, cx, cy, width, height, eps2d,
             lo_x, hi_x, lo_y, hi_y, pos, data, box, gid)
    campos = (-R.T.astype(np.float64) @ t.astype(np.float64)).astype(np.float32)
    rows, pbox, offsets = _bin(box, data, width, height)
    out = np.zeros((height, width, nf + 2), np.float32)
    with numba.parallel_chunksize(1):  # tiles one at a time: a static split left one thread the costly half
        _rasterize(rows, pbox, offsets, data, gid, g["means"], g["sh"], d, feats_in, campos, nf, width, height, out)
    alpha = out[..., nf + 1]
    dep = out[..., nf] / np.maximum(alpha, np.float32(1e-10))
    return out[..., :nf], dep, alpha


def render(g: dict, viewmats, Ks, width: int, height: int, sh_degree: int | None = None, near: float = 0.01,
           far: float = 1e10, features=None, extra=None):
    """A batch of cameras, the same contract as `navcore.render.cpu.render` (torch tensors out)."""
    import torch

    deg = int(round(math.sqrt(g["sh"].shape[1]))) - 1 if sh_degree is None else int(sh_degree)
    outs = [render_one(g, vm, K, width, height, deg, near, far, features=features, extra=extra)
            for vm, K in zip(np.asarray(viewmats, np.float32), np.asarray(Ks, np.float32))]
    rgb, dep, alp = (torch.from_numpy(np.stack([o[k] for o in outs])) for k in range(3))
    return rgb, dep, alp
