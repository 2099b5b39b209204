"""DBSCAN of voxels: the same labels as scikit-learn's DBSCAN on integer points, in linear time.

On a voxel grid the eps-neighbourhood of a point is a fixed set of integer offsets, so neighbour
counts and the connectivity of core points are lookups in a dense index grid instead of tree
queries (scikit-learn took 13 s of the fungi room's costmap, 1 core; this takes well under one).

Labels follow scikit-learn exactly: a point is core when at least min_samples points (itself
included) lie within distance eps; core points within eps of each other share a cluster; clusters
are numbered in the order of their first core point; a non-core point within eps of a core point
is a border point of the lowest-numbered such cluster (the one sklearn's expansion reaches it
from first), else noise (-1).
"""
from __future__ import annotations

import numba
import numpy as np


def ball_offsets(eps: float) -> np.ndarray:
    """[K, 3] integer offsets o with |o| <= eps (the origin included), lexicographic order."""
    r = int(np.floor(eps))
    g = np.mgrid[-r:r + 1, -r:r + 1, -r:r + 1].reshape(3, -1).T
    return np.ascontiguousarray(g[(g ** 2).sum(1) <= eps * eps], dtype=np.int64)


@numba.njit(cache=True)
def _find(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@numba.njit(cache=True)
def _dbscan(pts, grid, offsets, min_samples):
    n = pts.shape[0]
    sx, sy, sz = grid.shape
    k = offsets.shape[0]
    core = np.zeros(n, np.bool_)
    for i in range(n):
        c = 0
        for o in range(k):
            x, y, z = pts[i, 0] + offsets[o, 0], pts[i, 1] + offsets[o, 1], pts[i, 2] + offsets[o, 2]
            if 0 <= x < sx and 0 <= y < sy and 0 <= z < sz and grid[x, y, z] >= 0:
                c += 1
        core[i] = c >= min_samples
    parent = np.arange(n)
    for i in range(n):
        if not core[i]:
            continue
        for o in range(k):
            x, y, z = pts[i, 0] + offsets[o, 0], pts[i, 1] + offsets[o, 1], pts[i, 2] + offsets[o, 2]
            if 0 <= x < sx and 0 <= y < sy and 0 <= z < sz:
                j = grid[x, y, z]
                if j > i and core[j]:
                    a, b = _find(parent, i), _find(parent, j)
                    if a != b:
                        if a < b:
                            parent[b] = a
                        else:
                            parent[a] = b
    labels = np.full(n, -1, np.int64)
    root_label = np.full(n, -1, np.int64)
    nxt = 0
    for i in range(n):  # clusters numbered by their first core point
        if core[i]:
            r = _find(parent, i)
            if root_label[r] < 0:
                root_label[r] = nxt
                nxt += 1
            labels[i] = root_label[r]
    for i in range(n):  # border points: the lowest-numbered cluster with a core point in reach
        if core[i]:
            continue
        best = -1
        for o in range(k):
            x, y, z = pts[i, 0] + offsets[o, 0], pts[i, 1] + offsets[o, 1], pts[i, 2] + offsets[o, 2]
            if 0 <= x < sx and 0 <= y < sy and 0 <= z < sz:
                j = grid[x, y, z]
                if j >= 0 and core[j] and (best < 0 or labels[j] < best):
                    best = labels[j]
        labels[i] = best
    return labels


def voxel_dbscan(points: np.ndarray, eps: float, min_samples: int) -> np.ndarray:
    """[N] int64 cluster labels (-1 = noise) of distinct [N, 3] integer points, as
    sklearn.cluster.DBSCAN(eps, min_samples).fit_predict(points) gives (see module docstring)."""
    pts = np.asarray(points)
    if len(pts) == 0:
        return np.zeros(0, np.int64)
    pts = pts.astype(np.int64) - pts.min(0).astype(np.int64)
    grid = np.full(tuple(pts.max(0) + 1), -1, np.int64)
    grid[pts[:, 0], pts[:, 1], pts[:, 2]] = np.arange(len(pts))
    if (grid >= 0).sum() != len(pts):
        raise ValueError("voxel_dbscan needs distinct points")
    return _dbscan(np.ascontiguousarray(pts), grid, ball_offsets(float(eps)), int(min_samples))
