"""The CPU renderer's ordering: depth ranks of the candidates (stable LSD radix sort, a merge sort
for small sets) and their binning into 16x16 tiles (a counting sort: each tile's list by depth
then index)."""
from __future__ import annotations

import math

import numba
import numpy as np

from navcore.render.cpu_fast.project import RX, RY, U, V
from navcore.render.cpu_fast.simd import TILE

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


