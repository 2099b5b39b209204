"""The CPU renderer's compositing: tiles in parallel, front to back, the exclusive stop at
T <= 1e-4; per half tile branch-free passes that LLVM vectorises (see the package doc)."""
from __future__ import annotations

import math

import numba
import numpy as np

from navcore.render.cpu_fast.project import CA, CB, CC, LM, NDATA, OP, U, V, Z, _features
from navcore.render.cpu_fast.simd import ALPHA_MIN, FAST, PREFETCH_AHEAD, T_MIN, TILE, _prefetch, _wide_vectors


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


