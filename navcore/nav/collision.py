"""Numba kernels of the costmap queries (state and motion validity of a disk footprint).

Queries read the clearance field F [ny, nx] (metres, -1 where unsupported) and interpolate it
bilinearly between cell centres. A state (x, y) is valid when F(x, y) >= thr (thr = r + margin);
a straight motion is valid when F >= thr along the whole segment, checked exactly: on each
bilinear patch the segment's F is a quadratic in t, whose minimum is taken analytically.
"""
from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _field(f, u, v):
    """Bilinear F at patch coordinates (u, v) (cell centre (j, i) at u = j, v = i); -1 outside."""
    ny, nx = f.shape
    if not (u >= 0.0 and v >= 0.0 and u <= nx - 1 and v <= ny - 1):
        return -1.0
    j = min(int(u), nx - 2) if nx > 1 else 0
    i = min(int(v), ny - 2) if ny > 1 else 0
    fu = u - j
    fv = v - i
    a = f[i, j]
    b = f[i, j + 1] if nx > 1 else a
    c = f[i + 1, j] if ny > 1 else a
    d = f[i + 1, j + 1] if (nx > 1 and ny > 1) else a
    return a + (b - a) * fu + (c - a) * fv + (a - b - c + d) * fu * fv


@numba.njit(cache=True)
def state_valid(f, ox, oy, inv_res, thr, x, y):
    return _field(f, (x - ox) * inv_res - 0.5, (y - oy) * inv_res - 0.5) >= thr


def _states_valid(f, ox, oy, inv_res, thr, xy):
    n = xy.shape[0]
    out = np.empty(n, dtype=np.bool_)
    for k in numba.prange(n):
        out[k] = _field(f, (xy[k, 0] - ox) * inv_res - 0.5, (xy[k, 1] - oy) * inv_res - 0.5) >= thr
    return out


@numba.njit(cache=True)
def clearance_at(f, ox, oy, inv_res, xy):
    n = xy.shape[0]
    out = np.empty(n, dtype=np.float64)
    for k in range(n):
        out[k] = _field(f, (xy[k, 0] - ox) * inv_res - 0.5, (xy[k, 1] - oy) * inv_res - 0.5)
    return out


@numba.njit(cache=True, inline="always")
def _first_crossing(c0, dc):
    """Parameter t of the first integer crossing of c0 + t dc, and the t between crossings
    (2.0, i.e. never within [0, 1], when dc == 0)."""
    if dc > 0:
        return (np.floor(c0) + 1.0 - c0) / dc, 1.0 / dc
    if dc < 0:
        return (np.ceil(c0) - 1.0 - c0) / dc, -1.0 / dc
    return 2.0, 2.0


@numba.njit(cache=True)
def segment_clear(f, u0, v0, u1, v1, thr):
    """Whether F >= thr along the segment between patch coordinates (u0, v0) and (u1, v1)."""
    ny, nx = f.shape
    # both end points and everything between must lie inside the map
    if min(u0, u1) < 0.0 or min(v0, v1) < 0.0 or max(u0, u1) > nx - 1 or max(v0, v1) > ny - 1:
        return False
    du = u1 - u0
    dv = v1 - v0
    # walk the breakpoints where u or v crosses an integer (patch borders), in increasing t
    tu, tu_step = _first_crossing(u0, du)
    tv, tv_step = _first_crossing(v0, dv)
    ta = 0.0
    while ta < 1.0:
        tb = min(tu, tv, 1.0)
        tm = 0.5 * (ta + tb)
        um = u0 + tm * du
        vm = v0 + tm * dv
        j = min(int(um), nx - 2) if nx > 1 else 0
        i = min(int(vm), ny - 2) if ny > 1 else 0
        a = f[i, j]
        b = f[i, j + 1] if nx > 1 else a
        c = f[i + 1, j] if ny > 1 else a
        d = f[i + 1, j + 1] if (nx > 1 and ny > 1) else a
        # F(t) = a + (b-a) fu + (c-a) fv + e fu fv with fu = pu + du t, fv = pv + dv t
        e = a - b - c + d
        pu = u0 - j
        pv = v0 - i
        c2 = e * du * dv
        c1 = (b - a) * du + (c - a) * dv + e * (pu * dv + pv * du)
        c0 = a + (b - a) * pu + (c - a) * pv + e * pu * pv
        fa = c0 + c1 * ta + c2 * ta * ta
        fb = c0 + c1 * tb + c2 * tb * tb
        m = min(fa, fb)
        if c2 > 0.0:
            tv_ = -c1 / (2.0 * c2)
            if ta < tv_ < tb:
                m = min(m, c0 + c1 * tv_ + c2 * tv_ * tv_)
        if m < thr:
            return False
        ta = tb
        if tb == tu:
            tu += tu_step
        if tb == tv:
            tv += tv_step
    return True


@numba.njit(cache=True)
def motion_valid(f, ox, oy, inv_res, thr, x0, y0, x1, y1):
    return segment_clear(f, (x0 - ox) * inv_res - 0.5, (y0 - oy) * inv_res - 0.5,
                   (x1 - ox) * inv_res - 0.5, (y1 - oy) * inv_res - 0.5, thr)


def _motions_valid(f, ox, oy, inv_res, thr, seg):
    n = seg.shape[0]
    out = np.empty(n, dtype=np.bool_)
    for k in numba.prange(n):
        out[k] = segment_clear(f, (seg[k, 0] - ox) * inv_res - 0.5, (seg[k, 1] - oy) * inv_res - 0.5,
                         (seg[k, 2] - ox) * inv_res - 0.5, (seg[k, 3] - oy) * inv_res - 0.5, thr)
    return out


@numba.njit(cache=True)
def ray_depths(clear, ox, oy, res, res_c, x, y, cos_a, sin_a, max_range):
    """Costmap.view_depths' sphere tracing, one ray at a time (the same arithmetic as the array form
    it replaced, so the same depths): per ray, step by the clearance less a cell (at least a cell)
    until a cell with clearance in [0, res) (an obstacle), the map's edge or max_range. res_c: the
    cell size in the clearance's dtype, in which the step is computed (as the array form did)."""
    ny, nx = clear.shape
    n = cos_a.shape[0]
    out = np.zeros(n)
    for k in range(n):
        d = 0.0
        for _ in range(int(max_range / res) + 2):
            ix = int(np.floor((x + d * cos_a[k] - ox) / res))
            iy = int(np.floor((y + d * sin_a[k] - oy) / res))
            if ix < 0 or ix >= nx or iy < 0 or iy >= ny:
                break
            c = clear[iy, ix]
            if c >= 0 and c < res_c:
                break
            d = min(d + max(c - res_c, res_c), max_range)
            if d >= max_range:
                break
        out[k] = d
    return out


# Batched queries in two builds: threaded for large batches, serial for small ones (waking the
# thread pool costs up to milliseconds when it has gone idle between calls).
states_valid = numba.njit(cache=True, parallel=True)(_states_valid)
states_valid_serial = numba.njit(cache=True)(_states_valid)
motions_valid = numba.njit(cache=True, parallel=True)(_motions_valid)
motions_valid_serial = numba.njit(cache=True)(_motions_valid)


@numba.njit(cache=True)
def taut_path(f, ox, oy, inv_res, thr, xy, step):
    """Shorten a valid polyline into a taut one (string pulling).

    The polyline [M, 2] (metres) is resampled at most `step` apart along its segments; from each
    kept point the path jumps to the farthest resampled point ahead that it sees by a valid
    straight motion (scanning forward to the first that it does not), so corners slide up to the
    obstacles while every kept segment is a checked valid motion (a start that sees the end
    directly gives the straight segment). First and last points are kept.
    Returns [K, 2] (K >= 2 unless M < 2).
    """
    m = xy.shape[0]
    if m < 2:
        return xy.copy()
    if segment_clear(f, (xy[0, 0] - ox) * inv_res - 0.5, (xy[0, 1] - oy) * inv_res - 0.5,
                     (xy[m - 1, 0] - ox) * inv_res - 0.5, (xy[m - 1, 1] - oy) * inv_res - 0.5, thr):
        out = np.empty((2, 2))  # in line of sight: the straight segment
        out[0] = xy[0]
        out[1] = xy[m - 1]
        return out
    counts = np.empty(m - 1, np.int64)
    total = 1
    for i in range(m - 1):
        counts[i] = max(1, int(math.ceil(math.hypot(xy[i + 1, 0] - xy[i, 0], xy[i + 1, 1] - xy[i, 1]) / step)))
        total += counts[i]
    dense = np.empty((total, 2))
    k = 0
    for i in range(m - 1):
        for s in range(counts[i]):
            t = s / counts[i]
            dense[k, 0] = xy[i, 0] + t * (xy[i + 1, 0] - xy[i, 0])
            dense[k, 1] = xy[i, 1] + t * (xy[i + 1, 1] - xy[i, 1])
            k += 1
    dense[k] = xy[m - 1]
    u = (dense[:, 0] - ox) * inv_res - 0.5
    v = (dense[:, 1] - oy) * inv_res - 0.5
    out = np.empty((total, 2))
    out[0] = dense[0]
    n = 1
    i = 0
    while i < total - 1:
        best = i + 1
        j = i + 2
        while j < total and segment_clear(f, u[i], v[i], u[j], v[j], thr):
            best = j
            j += 1
        out[n] = dense[best]
        n += 1
        i = best
    return out[:n]


@numba.njit(cache=True)
def _turn(p, k):
    """Turning angle of polyline p at vertex k (radians)."""
    ux, uy = p[k, 0] - p[k - 1, 0], p[k, 1] - p[k - 1, 1]
    vx, vy = p[k + 1, 0] - p[k, 0], p[k + 1, 1] - p[k, 1]
    return abs(math.atan2(ux * vy - uy * vx, ux * vx + uy * vy))


@numba.njit(cache=True)
def relax_path(f, ox, oy, inv_res, thr, xy, step0, step_min, sweeps, tol, splits, min_turn):
    """Pull a valid polyline's bends onto the shortest nearby valid positions (pattern search).

    Each interior vertex in turn tries eight moves of ``step0`` (then of half as much, down to
    ``step_min``) and takes the first that shortens its two segments while both stay valid
    motions; a vertex whose neighbours see each other and that turns the path is dropped. When a
    sweep shortens the path by less than ``tol`` (metres), the segments next to a bend of more
    than ``min_turn`` radians are split at their midpoints (at most ``splits`` times), so that the
    bends can follow a rounded clearance boundary (the shortest path wraps around the disk of a
    wall's end); at most ``sweeps`` sweeps in all. End points stay.
    Returns [K, 2], no longer than the input, every segment a valid motion.
    """
    cap = xy.shape[0] * (2 ** splits) + 2
    p = np.empty((cap, 2))
    n = xy.shape[0]
    p[:n] = xy
    dx = np.array([1.0, -1.0, 0.0, 0.0, 0.7071067811865476, 0.7071067811865476, -0.7071067811865476,
                   -0.7071067811865476])
    dy = np.array([0.0, 0.0, 1.0, -1.0, 0.7071067811865476, -0.7071067811865476, 0.7071067811865476,
                   -0.7071067811865476])
    done_splits = 0
    for _ in range(sweeps):
        gain = 0.0
        k = 1
        while k < n - 1:
            ax, ay, bx, by = p[k - 1, 0], p[k - 1, 1], p[k + 1, 0], p[k + 1, 1]
            vx, vy = p[k, 0], p[k, 1]
            cur = math.hypot(vx - ax, vy - ay) + math.hypot(bx - vx, by - vy)
            s = step0
            while s >= step_min:
                moved = False
                for d in range(8):
                    wx, wy = vx + s * dx[d], vy + s * dy[d]
                    new = math.hypot(wx - ax, wy - ay) + math.hypot(bx - wx, by - wy)
                    if new < cur - 1e-12 and motion_valid(f, ox, oy, inv_res, thr, ax, ay, wx, wy) \
                            and motion_valid(f, ox, oy, inv_res, thr, wx, wy, bx, by):
                        gain += cur - new
                        vx, vy, cur = wx, wy, new
                        moved = True
                        break
                if not moved:
                    s *= 0.5
            p[k, 0], p[k, 1] = vx, vy
            straight = math.hypot(bx - ax, by - ay)
            if cur - straight > 1e-9 and motion_valid(f, ox, oy, inv_res, thr, ax, ay, bx, by):
                gain += cur - straight  # the bend is not needed
                for j in range(k, n - 1):
                    p[j] = p[j + 1]
                n -= 1
                continue
            k += 1
        if gain < tol:
            if done_splits >= splits or n <= 2:
                break
            done_splits += 1
            q = np.empty((cap, 2))
            m = 0
            for i in range(n - 1):
                q[m] = p[i]
                m += 1
                if (i > 0 and _turn(p, i) > min_turn) or (i + 1 < n - 1 and _turn(p, i + 1) > min_turn):
                    q[m, 0] = 0.5 * (p[i, 0] + p[i + 1, 0])
                    q[m, 1] = 0.5 * (p[i, 1] + p[i + 1, 1])
                    m += 1
            q[m] = p[n - 1]
            n = m + 1
            p = q
    return p[:n].copy()
