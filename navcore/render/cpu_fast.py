"""The CPU renderer: compiled (numba) EWA splatting with gsplat's classic-mode rules.

Same rules as `navcore/render/cpu.py` (the plain-PyTorch reference, which documents them and
was checked against gsplat on an H100), organised so that the work is proportional to what the
camera sees rather than to the scene:

1. cull: blocks of 256 consecutive Gaussians whose bounding sphere lies outside the widened view
   are passed over whole (files in the wild are in spatial order), then a conservative test of
   each remaining mean (near / far plane on the mean depth, gsplat's rule; the image rectangle
   widened by an upper bound on each Gaussian's footprint, from its largest standard deviation),
   so only candidates get the full projection;
2. order: a stable LSD radix sort of the candidates' depth keys (float bits; ties keep the
   Gaussian index order, gsplat's order);
3. project the candidates (EWA with the clamped Jacobian, eps2d, opacity-aware box) in
   parallel, reading them in index order and writing each row at its depth rank, then a counting
   sort into 16x16 tiles, so each tile's list is by depth then index;
4. rasterise: tiles in parallel, front to back with the exclusive stop at T <= 1e-4, a tile
   ending when all its pixels are done. A Gaussian visits only its box inside the tile (outside
   it its alpha is below 1/255 by construction of the box, so gsplat skips those pixels too),
   less the rows at the box's top and bottom whose pixels are all finished (a per-row bitmask;
   a Gaussian whose box is all finished is skipped without reading its render data). A box of a
   few pixels is composited pixel by pixel; a larger one as one branch-free pass per half tile
   (the tile state is laid out by 8-column halves, so the box's rows in a half are contiguous):
   selects and integer sums only, exp as a polynomial, which LLVM turns into SIMD code (AVX2 /
   AVX-512 here). A Gaussian's colour (SH at the view direction) is evaluated when it first
   contributes to a tile: in a real room only about a quarter of the candidates reach a pixel,
   and the SH coefficients are most of the bytes read.

The scene is prepared once (`prepare`): float32 means, the 3D covariances, opacities, SH
coefficients, each Gaussian's largest standard deviation and the culling blocks.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba.core import cgutils
from numba.extending import intrinsic

from navcore.gaussians.model import render_sh_degree
from navcore.gaussians.sh import C0, C1, C2, C3

TILE = 16
ALPHA_MIN = np.float32(1.0 / 255.0)
T_MIN = np.float32(1e-4)
EXTENT_MAX = 3.33  # gsplat's cap on the footprint extent (sigmas)
SQRT_EPS2D = 0.5478  # the cull's bound on sqrt(eps2d) (px): it holds for eps2d <= 0.3, gsplat's default
FAST = {"nnan", "ninf", "nsz", "contract"}
"""The fast-math flags of the rasteriser: no NaN or infinity (validated scenes) and signed zeros
alike, which let LLVM use vector min / max, and multiply-adds fused (10-20% of the frame time);
no reassociation, so that a pixel gets the same operations whether the vector loop or its scalar
remainder computes it, whatever the vector width."""


@intrinsic
def _wide_vectors(typingctx):
    """Lets LLVM vectorise the calling function with 512-bit registers where the CPU has them.

    On CPUs with AVX-512 LLVM prefers 256-bit vectors (the "prefer-256-bit" tuning, against the
    clock drop of the first AVX-512 Xeons); the function attribute "prefer-vector-width"="512"
    (clang's -mprefer-vector-width) lifts it for this function alone. Placed in the rasteriser's
    parallel worker, the compositing loop takes two half-tile rows an iteration: real room 160x120
    58.5 -> 54.8 ms a frame, 640x480 158 -> 135 (2-core Emerald Rapids VM), the same bytes (no
    reassociation: each pixel gets the same operations whatever the width). Without AVX-512 the
    attribute changes nothing. llvmlite's attribute set only takes the attributes it knows, hence
    the plain set.add (it writes the string as given into the function's definition)."""
    def codegen(context, builder, sig, args):
        set.add(builder.function.attributes, '"prefer-vector-width"="512"')
        return context.get_dummy_value()

    return numba.types.none(), codegen


@intrinsic
def _prefetch(typingctx, arr, i):
    """Asks the CPU to bring element i of the C-contiguous array arr (flat index) into the cache
    (llvm.prefetch: read, keep in all levels); no effect on the results. The rasteriser reads
    each tile's render rows at scattered places (a tile's Gaussians are a sparse subset of the
    depth order): fetching the row of the Gaussian PREFETCH_AHEAD places later in the list
    overlaps those misses with the compositing (real room 160x120: rasterisation 31 -> 29 ms,
    640x480 135 -> 130 ms a frame)."""
    def codegen(context, builder, sig, args):
        ary = context.make_array(sig.args[0])(context, builder, args[0])
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
                                            "llvm.prefetch.p0")
        ptr = builder.bitcast(builder.gep(ary.data, [args[1]]), i8p)
        builder.call(fn, [ptr, ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return numba.types.none(arr, i), codegen


PREFETCH_AHEAD = 8  # list entries between a Gaussian's prefetch and its compositing (16: the same)


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


SMALL_SORT = 2048  # fewer candidates than this are ranked by a merge sort (`_depth_ranks`)
CHUNKS = 16  # work split of the sorts (fixed, so that the output does not depend on the thread count)


@numba.njit(cache=True, parallel=True)
def _depths(idx, means, R, t, z):
    """Camera depth of the candidates (the same float32 arithmetic as the projection's)."""
    for j in numba.prange(idx.shape[0]):
        i = idx[j]
        z[j] = R[2, 0] * means[i, 0] + R[2, 1] * means[i, 1] + R[2, 2] * means[i, 2] + t[2]


@numba.njit(cache=True, parallel=True)
def _depth_ranks(z):
    """Each z's position in increasing order (int32); stable (ties keep their order, i.e. the
    Gaussian index order, as gsplat): a parallel LSD radix sort of the float bits (positive floats
    order as their bits), 3 x 11 bits, with a fixed work split so that the result does not depend
    on the thread count; the last pass writes the ranks rather than the permutation. Under
    SMALL_SORT candidates a merge sort (stable too: the same ranks) spares the histograms' fixed
    cost (a near-field test renders tens of candidates)."""
    n = z.shape[0]
    if n < SMALL_SORT:
        rank = np.empty(n, np.int32)
        perm = np.argsort(z, kind="mergesort")
        for k in range(n):
            rank[perm[k]] = k
        return rank
    ka = z.view(np.uint32).copy()
    va = np.empty(n, np.int32)
    for k in numba.prange(n):
        va[k] = k
    kb = np.empty_like(ka)
    vb = np.empty_like(va)
    rank = np.empty(n, np.int32)
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
        last = shift == 22
        for c in numba.prange(CHUNKS):
            lo, hi = c * n // CHUNKS, (c + 1) * n // CHUNKS
            for k in range(lo, hi):
                d = (ka[k] >> shift) & 2047
                q = hist[c, d]
                hist[c, d] = q + 1
                if last:
                    rank[va[k]] = q
                else:
                    kb[q] = ka[k]
                    vb[q] = va[k]
        ka, kb = kb, ka
        va, vb = vb, va
    return rank


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
def _bin(box, data, width, height, nth):
    """Counting sort of the (depth-ordered) rows into tiles: (rows [M], their pixel boxes in the
    tile [M] (`_tile_box`), offsets [tw * th + 1]); each tile's rows stay in ascending order, and
    a row is listed only in the tiles where its pixel box is not empty."""
    tw = (width + TILE - 1) // TILE
    th = (height + TILE - 1) // TILE
    n = box.shape[0]
    nt = tw * th
    counts = np.zeros((CHUNKS, nt), np.int64)
    for wk in numba.prange(nth):  # worker wk: chunks wk, wk + nth, ... (near chunks cross more tiles)
        for c in range(wk, CHUNKS, nth):
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
    for wk in numba.prange(nth):
        for c in range(wk, CHUNKS, nth):
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


@numba.njit(cache=True, inline="always", fastmath=FAST)
def _exp_neg(s):
    """exp(-s) for 0 <= s <= 8 in float32 arithmetic without a library call, so that the pixel loop
    vectorises: a degree-9 Taylor polynomial of exp(-s / 8) (relative error < 2e-8 on the range),
    squared three times (a few ulp in all)."""
    x = s * np.float32(-0.125)
    p = np.float32(1.0 / 362880.0)
    p = p * x + np.float32(1.0 / 40320.0)
    p = p * x + np.float32(1.0 / 5040.0)
    p = p * x + np.float32(1.0 / 720.0)
    p = p * x + np.float32(1.0 / 120.0)
    p = p * x + np.float32(1.0 / 24.0)
    p = p * x + np.float32(1.0 / 6.0)
    p = p * x + np.float32(0.5)
    p = p * x + np.float32(1.0)
    p = p * x + np.float32(1.0)
    p = p * p
    p = p * p
    return p * p


HALF = TILE // 2  # the rasteriser's state is laid out by half tile: q = h * 128 + y * 8 + x - 8 h


@numba.njit(cache=True, inline="always")
def _slot(px, py):
    """Index of tile pixel (px, py) in the rasteriser's half-tile layout."""
    return (px // HALF) * (TILE * HALF) + py * HALF + px % HALF


@numba.njit(cache=True, inline="always")
def _update_done(fs, done, y0, y1):
    """Rows y0..y1 of the finished-pixel bitmask from the finished flags fs."""
    for py in range(y0, y1):
        dm = np.uint32(0)
        for px in range(TILE):
            if fs[_slot(px, py)] != 0:
                dm |= np.uint32(1) << np.uint32(px)
        done[py] = dm


@numba.njit(cache=True, inline="always")
def _unfinished_rows(done, mask, y0, y1):
    """Rows y0..y1 less those at the top and bottom whose pixels in mask are all finished (per the
    bitmask done); empty (y0 == y1) when all are."""
    while y0 < y1 and done[y0] & mask == mask:
        y0 = y0 + 1
    while y1 > y0 and done[y1 - 1] & mask == mask:
        y1 = y1 - 1
    return y0, y1


SMALL_BOX = 16  # boxes of at most this many pixels are composited pixel by pixel


@numba.njit(cache=True, parallel=True, fastmath=FAST)
def _rasterize(rows, pbox, offsets, data, gid, means, sh, deg, feats_in, campos, nf, width, height, out, nth,
               visits=None):
    """out[H, W, nf + 2] = (sum w f, sum w z, sum w) per pixel, front to back per tile; a
    Gaussian's features (`_features`) are evaluated when it first contributes to a tile. With
    visits ([N, 2] uint8, zeroed), visits[i, 0] = 1 for every Gaussian i whose box has an
    unfinished pixel in some tile (its render data read) and visits[i, 1] = 1 for those that
    contribute to a pixel (stores of a constant: no race between tiles); None (the default)
    compiles the loop without them.

    A box of at most SMALL_BOX pixels is composited pixel by pixel. For a larger one the tile's
    pixel state is laid out by half tile (8 columns), row after row, so that the rows of the box in
    one half are one contiguous run: one branch-free pass over it (selects and integer sums only,
    which LLVM vectorises), the pixels outside the box's columns, finished ones and those with
    alpha < 1/255 masked rather than skipped; exp there is `_exp_neg` (a few ulp from the
    library's)."""
    tw = (width + TILE - 1) // TILE
    nt = offsets.shape[0] - 1
    one, zero = np.float32(1.0), np.float32(0.0)
    npx = TILE * TILE
    for wk in numba.prange(nth):  # worker wk: tiles wk, wk + nth, ... (tile costs differ 100-fold)
        _wide_vectors()
        for tt in range(wk, nt, nth):
            ty, tx = tt // tw, tt % tw
            px0, py0 = tx * TILE, ty * TILE
            pw = min(TILE, width - px0)
            ph = min(TILE, height - py0)
            # per-pixel state, in separate arrays (rows of one 2D array defeat LLVM's overlap checks and
            # the loops run scalar): transmittance, 1 once finished (T would drop <= T_MIN), the current
            # Gaussian's weights alpha T, the pixel centres (tile-local), the accumulated channels
            ts = np.ones(npx, np.float32)
            fs = np.zeros(npx, np.float32)
            ws = np.zeros(npx, np.float32)
            xs = np.empty(npx, np.float32)
            ys = np.empty(npx, np.float32)
            acc = np.zeros((nf + 2) * npx, np.float32)
            col = np.empty(nf, np.float32)
            hit_q = np.empty(SMALL_BOX, np.int64)  # a small box's composited pixels and weights
            hit_w = np.empty(SMALL_BOX, np.float32)
            done = np.zeros(TILE, np.uint32)  # per tile row, bit x set once pixel x is finished
            hy0 = np.zeros(2, np.int64)  # per half tile, the box rows of the current Gaussian's pass
            hy1 = np.zeros(2, np.int64)
            for py in range(TILE):
                for px in range(TILE):
                    q = _slot(px, py)
                    xs[q] = np.float32(px + 0.5)
                    ys[q] = np.float32(py + 0.5)
                    if px >= pw or py >= ph:  # outside the image: finished from the start
                        fs[q] = one
                        done[py] |= np.uint32(1) << np.uint32(px)
            left = pw * ph
            k_end = offsets[tt + 1]
            for k in range(offsets[tt], k_end):
                if k + PREFETCH_AHEAD < k_end:
                    j_ahead = rows[k + PREFETCH_AHEAD]
                    _prefetch(data, j_ahead * NDATA)
                    _prefetch(gid, j_ahead)
                # the pixels of its box (alpha < 1/255 outside it); the Gaussian is skipped when all of
                # them are finished (bit tests only: its render data is not read)
                pb = pbox[k]
                qx0 = np.int64(pb & np.uint32(255))
                qx1 = np.int64(pb >> np.uint32(8) & np.uint32(255))
                qy0 = np.int64(pb >> np.uint32(16) & np.uint32(255))
                qy1 = np.int64(pb >> np.uint32(24))
                bm = ((np.uint32(1) << np.uint32(qx1 - qx0)) - np.uint32(1)) << np.uint32(qx0)
                # rows of the box whose pixels are all finished are left out at its top and bottom
                qy0, qy1 = _unfinished_rows(done, bm, qy0, qy1)
                if qy0 == qy1:  # all finished: the Gaussian is hidden
                    continue
                j = rows[k]
                if visits is not None:
                    visits[gid[j], 0] = 1
                u = data[j, U] - np.float32(px0)
                v = data[j, V] - np.float32(py0)
                ca, cb, cc = data[j, CA], data[j, CB], data[j, CC]
                o, z = data[j, OP], data[j, Z]
                lm = data[j, LM]
                ha = np.float32(0.5) * ca
                hc = np.float32(0.5) * cc
                fx0, fx1 = np.float32(qx0), np.float32(qx1)
                nfin = np.int32(0)  # pixels finished by this Gaussian
                nhit = np.int32(0)  # pixels it contributes to
                if (qx1 - qx0) * (qy1 - qy0) <= SMALL_BOX:
                    # a few pixels (most Gaussians at low resolution): one at a time, skipping rather than
                    # masking, cheaper than a vector pass over whole 8-pixel rows
                    m = 0
                    for py in range(qy0, qy1):
                        dy = np.float32(py + 0.5) - v
                        sy = hc * dy * dy
                        for px in range(qx0, qx1):
                            q = _slot(px, py)
                            if fs[q] != zero:
                                continue
                            dx = np.float32(px + 0.5) - u
                            sigma = ha * dx * dx + sy + cb * dx * dy
                            if sigma < zero or sigma > lm:
                                continue
                            alpha = min(np.float32(0.999), o * math.exp(-sigma))
                            if alpha < ALPHA_MIN:
                                continue
                            tp = ts[q]
                            tn = tp * (one - alpha)
                            if tn <= T_MIN:
                                fs[q] = one
                                nfin += 1
                                continue
                            hit_q[m] = q
                            hit_w[m] = alpha * tp
                            m += 1
                            ts[q] = tn
                    if nfin > 0:
                        _update_done(fs, done, qy0, qy1)
                        left -= nfin
                    if m > 0:
                        if visits is not None:
                            visits[gid[j], 1] = 1
                        _features(gid[j], means, sh, deg, feats_in, campos, col)
                        for r in range(m):
                            q = hit_q[r]
                            wq = hit_w[r]
                            for c in range(nf):
                                acc[c * npx + q] += wq * col[c]
                            acc[nf * npx + q] += wq * z
                            acc[(nf + 1) * npx + q] += wq
                    if left == 0:
                        break
                    continue
                for h in range(2):
                    hy0[h] = 0
                    hy1[h] = 0
                for h in range(qx0 // HALF, (qx1 - 1) // HALF + 1):
                    # this half's rows of the box, less those all finished at its top and bottom
                    hm = bm & (np.uint32(255) << np.uint32(h * HALF))
                    a0, a1 = _unfinished_rows(done, hm, qy0, qy1)
                    hy0[h], hy1[h] = a0, a1
                    lo = h * (TILE * HALF) + a0 * HALF
                    n = (a1 - a0) * HALF
                    tr, fr, wr, xr, yr = ts[lo:lo + n], fs[lo:lo + n], ws[lo:lo + n], xs[lo:lo + n], ys[lo:lo + n]
                    for q in range(n):
                        xx = xr[q]
                        dx = xx - u
                        dy = yr[q] - v
                        sigma = ha * dx * dx + hc * dy * dy + cb * dx * dy
                        alpha = min(np.float32(0.999), o * _exp_neg(min(max(sigma, zero), np.float32(8.0))))
                        a = alpha if xx > fx0 else zero
                        a = a if xx < fx1 else zero
                        a = a if fr[q] == zero else zero
                        a = a if sigma >= zero else zero
                        a = a if sigma <= lm else zero
                        a = a if alpha >= ALPHA_MIN else zero
                        tp = tr[q]
                        tn = tp * (one - a)
                        last = tn <= T_MIN  # only where a > 0: T stays above T_MIN otherwise
                        wq = zero if last else a * tp
                        wr[q] = wq
                        tr[q] = tp if last else tn
                        fr[q] = one if last else fr[q]
                        nfin += np.int32(1) if last else np.int32(0)
                        nhit += np.int32(1) if wq > zero else np.int32(0)
                if nfin > 0:
                    _update_done(fs, done, qy0, qy1)
                    left -= nfin
                if nhit > 0:
                    if visits is not None:
                        visits[gid[j], 1] = 1
                    _features(gid[j], means, sh, deg, feats_in, campos, col)
                    for h in range(qx0 // HALF, (qx1 - 1) // HALF + 1):
                        lo = h * (TILE * HALF) + hy0[h] * HALF
                        n = (hy1[h] - hy0[h]) * HALF
                        wr = ws[lo:lo + n]
                        for c in range(nf + 2):
                            cv = col[c] if c < nf else (z if c == nf else one)
                            ac = acc[c * npx + lo:c * npx + lo + n]
                            for q in range(n):
                                ac[q] += wr[q] * cv
                if left == 0:
                    break
            for py in range(ph):
                for px in range(pw):
                    q = _slot(px, py)
                    for c in range(nf + 2):
                        out[py0 + py, px0 + px, c] = acc[c * npx + q]


def render_one(g: dict, viewmat: np.ndarray, K: np.ndarray, width: int, height: int, deg: int,
               near: float = 0.01, far: float = 1e10, eps2d: float = 0.3, features=None, extra=None, visits=None):
    """One camera -> (feats [H, W, C], depth [H, W], alpha [H, W]) float32 numpy arrays; visits
    ([N, 2] uint8, zeroed, optional) gets which Gaussians the rasteriser read and which
    contributed (`_rasterize`; benchmarks.render_cpu's bound on culling).

    The compiled passes do not check their indices, so what they would read out of bounds is
    refused here: deg above the scene's SH degree, features / extra without one row per Gaussian."""
    n = len(g["means"])
    render_sh_degree(deg, g["sh"].shape[1])  # ValueError above the scene's degree
    for name, f in (("features", features), ("extra", extra)):
        if f is not None and (np.ndim(f) != 2 or len(f) != n):
            raise ValueError(f"{name} must be [{n}, C] (one row per Gaussian), got shape {np.shape(f)}")
    if eps2d > SQRT_EPS2D ** 2:
        raise ValueError(f"eps2d={eps2d} exceeds the cull's bound ({SQRT_EPS2D ** 2:.4f}: SQRT_EPS2D)")
    R = np.ascontiguousarray(viewmat[:3, :3], np.float32)
    t = np.ascontiguousarray(viewmat[:3, 3], np.float32)
    fx, fy, cx, cy = (float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    lo_x, hi_x = -(cx / fx + 0.3 * tan_x), (width - cx) / fx + 0.3 * tan_x
    lo_y, hi_y = -(cy / fy + 0.3 * tan_y), (height - cy) / fy + 0.3 * tan_y
    nth = numba.get_num_threads()
    idx = _cull(g["means"], g["smax"], g["opacities"], g["blocks"], R, t, fx, fy, cx, cy, width, height, near, far,
                max(-lo_x, hi_x), max(-lo_y, hi_y), nth)
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
    pos = _depth_ranks(z)
    data = np.empty((len(idx), NDATA), np.float32)
    box = np.empty((len(idx), 4), np.int32)
    gid = np.empty(len(idx), np.int64)
    _project(idx, g["means"], g["cov"], g["opacities"], g["ext"], g["lmax"], R, t, fx, fy, cx, cy, width, height, eps2d,
             lo_x, hi_x, lo_y, hi_y, pos, data, box, gid)
    campos = (-R.T.astype(np.float64) @ t.astype(np.float64)).astype(np.float32)
    rows, pbox, offsets = _bin(box, data, width, height, nth)
    out = np.zeros((height, width, nf + 2), np.float32)
    if visits is not None and (visits.shape != (n, 2) or visits.dtype != np.uint8):
        raise ValueError(f"visits must be a [{n}, 2] uint8 array, got {visits.dtype} {visits.shape}")
    _rasterize(rows, pbox, offsets, data, gid, g["means"], g["sh"], d, feats_in, campos, nf, width, height, out, nth,
               visits)
    alpha = out[..., nf + 1]
    dep = out[..., nf] / np.maximum(alpha, np.float32(1e-10))
    return out[..., :nf], dep, alpha


def render(g: dict, viewmats, Ks, width: int, height: int, sh_degree: int | None = None, near: float = 0.01,
           far: float = 1e10, features=None, extra=None):
    """A batch of cameras, the same contract as `navcore.render.cpu.render` (torch tensors out)."""
    import torch

    deg = render_sh_degree(sh_degree, g["sh"].shape[1])
    outs = [render_one(g, vm, K, width, height, deg, near, far, features=features, extra=extra)
            for vm, K in zip(np.asarray(viewmats, np.float32), np.asarray(Ks, np.float32))]
    rgb, dep, alp = (torch.from_numpy(np.stack([o[k] for o in outs])) for k in range(3))
    return rgb, dep, alp
