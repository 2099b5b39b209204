"""How level an aligned floor is, measured independently of the aligner (issue 46).

On an aligned scene (floor at z = 0, +z up) the floor slab is the opaque content Gaussians
(opacity >= 0.5) within ``slab_m`` of z = 0, and its floor layer (``floor_points``) those within
3 cm of the density peak of their 1 m cell (furniture bases and wall feet left out; cells where that
peak covers less than 30 % of the cell, or stands 6 cm off the plane through all peaks, are not
floor). Three measures of that layer:
- ``tilt_deg``: the least-squares plane through the median heights of the layer's 0.5 m cells
  (the floor's surface, however thick its layer), with a 95 % bootstrap interval over the cells;
- ``ransac_tilt_deg``: open3d's RANSAC plane (segment_plane, 1 cm threshold) through the layer's
  points, the cross-check that shares no code with the aligner (on a 6 m floor of 2 cm noise it
  moves by about 0.1 deg with its threshold: a coarse check);
- ``spread_3x3_m``: the floor's extent (2nd-98th percentile of the slab in x and y) cut 3 x 3, the
  median height of the slab in each cell, max minus min: what a robot at either end of the room
  meets (a 0.6 deg tilt across a 15.7 m hall is 16 cm).

    python -m benchmarks.map.floor_level SOURCE [SOURCE ...]   # a real source through content + align
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from navcore.io import jsonio

SLAB_M = 0.15
"""Half-height of the slab around z = 0 that the measures take, metres."""


def _tilt(n: np.ndarray) -> float:
    return float(np.degrees(np.arccos(min(abs(float(n[2])) / float(np.linalg.norm(n)), 1.0))))


def cell_groups(p: np.ndarray, cell_m: float) -> list[np.ndarray]:
    """Indices of the points of each cell_m x cell_m cell of the plane (cells in sorted order)."""
    c = np.unique(np.floor(p[:, :2] / cell_m).astype(np.int64), axis=0, return_inverse=True)[1].reshape(-1)
    order = np.argsort(c, kind="stable")
    return np.split(order, np.nonzero(np.diff(c[order]))[0] + 1)


def median_plane(p: np.ndarray, cell_m: float = 0.5, min_points: int = 20, boot: int = 300,
                 seed: int = 0) -> tuple[np.ndarray, int, list[float]]:
    """Least-squares plane z = a x + b y + c through the median heights of the floor points' cells
    (cells of at least min_points): the floor's surface, whatever the thickness of its layer.
    Returns (a, b, c), the cells used, and the 95 % bootstrap interval of its tilt over the cells
    (degrees). The cell medians are robust already; a re-cut of cells off the plane made the
    tilt jump on the room's slightly bowl-shaped floor (0.02 -> 0.24 deg), so there is none."""
    q = np.array([[*p[idx, :2].mean(0), np.median(p[idx, 2])] for idx in cell_groups(p, cell_m)
                  if len(idx) >= min_points])
    fit = lambda s: np.linalg.lstsq(np.c_[s[:, :2], np.ones(len(s))], s[:, 2], rcond=None)[0]  # noqa: E731
    rng = np.random.default_rng(seed)
    ts = [_tilt(np.array([-a, -b, 1.0])) for a, b, _ in (fit(q[rng.integers(0, len(q), len(q))]) for _ in range(boot))]
    return fit(q), len(q), np.percentile(ts, [2.5, 97.5]).round(4).tolist()


def floor_points(means: np.ndarray, alphas: np.ndarray, slab_m: float = SLAB_M, cell_m: float = 1.0,
                 keep_m: float = 0.03, raised_m: float = 0.06, min_cover: float = 0.3) -> np.ndarray:
    """The floor layer of an aligned scene: the opaque Gaussians within ``slab_m`` of z = 0, and of
    them, in each ``cell_m`` cell, those within ``keep_m`` of the cell's density peak (1 cm bins,
    smoothed): the bases of furniture and the feet of walls that the slab also holds stay out.
    Only cells whose peak covers ``min_cover`` of their tenth-size sub-cells count (where the floor
    was not reconstructed, the slab holds only the feet of furniture), and not those whose peak lies
    more than ``raised_m`` off the plane through the peaks (platforms, plinths)."""
    from scipy.ndimage import gaussian_filter1d

    p = means[(alphas >= 0.5) & (np.abs(means[:, 2]) < slab_m)].astype(np.float64)
    if not len(p):
        return p
    bins = np.arange(-slab_m, slab_m + 0.01, 0.01)
    cells = []  # (members, peak x, y, z)
    for idx in cell_groups(p, cell_m):
        if len(idx) < 30:
            continue
        h = gaussian_filter1d(np.histogram(p[idx, 2], bins)[0].astype(float), 1.0)
        mode = 0.5 * (bins[h.argmax()] + bins[h.argmax() + 1])
        idx = idx[np.abs(p[idx, 2] - mode) <= keep_m]
        sub = np.unique(np.floor(p[idx, :2] / (0.1 * cell_m)).astype(np.int64), axis=0)
        if len(sub) >= min_cover * 100:  # a floor covers its cell; the feet of a display case do not
            cells.append((idx, *p[idx, :2].mean(0), mode))
    if len(cells) < 3:
        return p[np.concatenate([c[0] for c in cells])] if cells else p[:0]
    # a cell whose peak stands off the plane through all the peaks by more than raised_m is a
    # platform or a row of plinths, not floor (the plane is free to tilt: a tilted floor stays)
    q = np.array([c[1:] for c in cells])
    keep_c = np.ones(len(q), bool)
    for _ in range(5):
        a_, *_ = np.linalg.lstsq(np.c_[q[keep_c, :2], np.ones(keep_c.sum())], q[keep_c, 2], rcond=None)
        off = np.abs(np.c_[q[:, :2], np.ones(len(q))] @ a_ - q[:, 2])
        keep_c = off <= raised_m
    return p[np.concatenate([c[0] for c, k in zip(cells, keep_c) if k])]


def floor_level(means: np.ndarray, alphas: np.ndarray, slab_m: float = SLAB_M, cell_m: float = 0.5,
                seed: int = 0) -> dict:
    """The three measures of the aligned floor (module doc) from aligned content Gaussians."""
    import open3d as o3d

    p = floor_points(means, alphas, slab_m)
    if len(p) < 100:
        return {"floor_gaussians": int(len(p))}
    coef, cells, ci = median_plane(p, cell_m, seed=seed)
    rng = np.random.default_rng(seed)
    sub = p[np.sort(rng.choice(len(p), min(len(p), 300_000), replace=False))]
    o3d.utility.random.seed(seed)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(sub))
    plane, inl = pcd.segment_plane(distance_threshold=0.01, ransac_n=3, num_iterations=2000)
    lo, hi = np.percentile(p[:, :2], [2, 98], axis=0)
    edges = [np.linspace(lo[i], hi[i], 4) for i in range(2)]
    ix = np.clip(np.searchsorted(edges[0], p[:, 0]) - 1, 0, 2)
    iy = np.clip(np.searchsorted(edges[1], p[:, 1]) - 1, 0, 2)
    med = [float(np.median(p[(ix == a) & (iy == b), 2])) for a in range(3) for b in range(3)
           if ((ix == a) & (iy == b)).sum() >= 50]
    return {"floor_gaussians": int(len(p)), "tilt_deg": _tilt(np.array([-coef[0], -coef[1], 1.0])),
            "height_at_centre_m": float(coef @ [*p[:, :2].mean(0), 1.0]), "plane_cells": cells, "tilt_ci95_deg": ci,
            "ransac_tilt_deg": _tilt(np.asarray(plane[:3])), "ransac_inliers": int(len(inl)),
            "cell_medians_m": [round(m, 4) for m in med], "spread_3x3_m": float(max(med) - min(med)) if med else None,
            "extent_m": [float(hi[0] - lo[0]), float(hi[1] - lo[1])]}


def align_source(path: str):
    """A real source through the pipeline's content mask and floor fit: the aligned content."""
    from navcore.gaussians.content import CONTENT_KEY, content_mask, content_of
    from navcore.gaussians.floor import AlignConfig, fit_floor, floor_transform
    from navcore.gaussians.formats import read_gaussians

    g = read_gaussians(path)
    g = g[0] if isinstance(g, tuple) else g
    g.extras[CONTENT_KEY] = content_mask(g.means)[0]
    c = content_of(g)
    n, d, info = fit_floor(c, AlignConfig())
    return c.transformed(floor_transform(n, d)), info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sources", nargs="+")
    args = ap.parse_args(argv)
    for s in args.sources:
        al, _ = align_source(s)
        print(s, jsonio.dumps(floor_level(al.means, al.alphas)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
