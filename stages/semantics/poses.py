"""Covering poses for the semantic layer: the camera poses the scene came with, or robot poses on
free costmap cells looking all around, or (the default) the fewest of those that see the scene's
surfaces: `coverage_poses`."""
from __future__ import annotations

import heapq
import math

import numpy as np

from navcore.nav.costmap import lattice_cells


def free_space_poses(costmap, valid: np.ndarray, spacing: float = 1.0, yaw_step_deg: float = 45.0,
                     min_separation: float | None = None) -> np.ndarray:
    """[M, 3] robot poses (x, y, yaw) covering the free space: one position per `spacing` x `spacing`
    block of valid cells (the valid cell nearest the block's centre; blocks without one are
    skipped), each with headings every `yaw_step_deg`; positions closer than `min_separation`
    (default spacing / 2) to an earlier one are thinned out. Deterministic."""
    cells = lattice_cells(valid, round(spacing / costmap.resolution))
    if not len(cells):
        return np.zeros((0, 3))
    picks = costmap.cell_centers(cells)
    sep = spacing / 2 if min_separation is None else min_separation
    kept: list[np.ndarray] = []
    for p in picks:  # thin positions that fell close to one already kept (across block borders)
        if all(np.hypot(*(p - q)) >= sep for q in kept):
            kept.append(p)
    yaws = np.deg2rad(np.arange(0.0, 360.0, yaw_step_deg))
    pts = np.asarray(kept)
    return np.column_stack([np.repeat(pts, len(yaws), 0), np.tile(yaws, len(pts))])


def yaw_coverage(poses: np.ndarray) -> float:
    """Largest angular gap (radians) between the headings of a pose set (a full circle: 2 pi / n)."""
    y = np.sort(np.mod(poses[:, 2], 2 * math.pi))
    return float(np.max(np.diff(np.concatenate([y, y[:1] + 2 * math.pi]))))


def surface_targets(means: np.ndarray, alphas: np.ndarray, cell: float = 0.2, z_min: float = 0.1, z_max: float = 2.5,
                    min_alpha: float = 0.5) -> np.ndarray:
    """[T, 3] centres of the `cell`-sized voxels holding an opaque Gaussian (alpha >= min_alpha)
    between z_min and z_max above the floor (aligned frame: floor z = 0): what views must see."""
    keep = (alphas >= min_alpha) & (means[:, 2] >= z_min) & (means[:, 2] <= z_max)
    cells = np.unique(np.floor(means[keep] / cell).astype(np.int64), axis=0)
    return (cells + 0.5) * cell


def visible_targets(targets: np.ndarray, c2w: np.ndarray, K: np.ndarray, width: int, height: int,
                    max_range: float, cell: float) -> np.ndarray:
    """Indices of the targets a camera sees: in its frame within max_range, not hidden behind a
    nearer target in a z-buffer at the camera's (width, height), to within one cell's diagonal."""
    w2c = np.linalg.inv(c2w)
    p = targets @ w2c[:3, :3].T + w2c[:3, 3]
    z = p[:, 2]
    front = (z > 0.1) & (np.linalg.norm(p, axis=1) <= max_range)
    idx = np.flatnonzero(front)
    u = np.floor(K[0, 0] * p[idx, 0] / z[idx] + K[0, 2]).astype(np.int64)
    v = np.floor(K[1, 1] * p[idx, 1] / z[idx] + K[1, 2]).astype(np.int64)
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    idx, pix, depth = idx[inside], v[inside] * width + u[inside], z[idx[inside]]
    zbuf = np.full(width * height, np.inf)
    np.minimum.at(zbuf, pix, depth)
    return idx[depth <= zbuf[pix] + cell * math.sqrt(3)]


def coverage_poses(candidates: np.ndarray, targets: np.ndarray, cam_height: float, pitch_deg: float, hfov_deg: float,
                   k: int = 2, sectors: int = 8,
                   max_range: float = 4.0, cell: float = 0.2, min_gain: float = 0.002,
                   grid: tuple[int, int] = (64, 48)) -> tuple[np.ndarray, dict]:
    """The fewest of `candidates` [M, 3] (x, y, yaw) that see the `targets` [T, 3] (surface_targets),
    chosen greedily: each pick adds the most target sightings still wanted, where a target wants `k`
    sightings from distinct directions (its bearing from the camera in one of `sectors` sectors),
    which multi-view lifting needs. Stops when the best pick would add under `min_gain` of the
    targets' k x T wanted sightings. The views' camera is at cam_height with pitch_deg and hfov_deg;
    visibility is tested in a z-buffer of `grid` pixels.
    Lazy greedy (the gain of a view never grows as others are picked): deterministic, ties to the
    earlier candidate. Returns (the picked candidates in candidate order, a report)."""
    if not len(candidates) or not len(targets):
        return candidates[:0], {"candidates": len(candidates), "targets": len(targets), "views": 0, "coverage": 0.0}
    from navcore.render.camera import camera_to_world, intrinsics

    gw, gh = grid
    K = intrinsics(gw, gh, hfov_deg)
    from scipy.spatial import cKDTree

    tree = cKDTree(targets[:, :2])
    near: dict[tuple[float, float], np.ndarray] = {}  # per position: the targets within range (its yaws share them)
    seen_by: list[tuple[np.ndarray, np.ndarray]] = []
    for x, y, yaw in candidates:
        if (x, y) not in near:
            near[(x, y)] = np.asarray(sorted(tree.query_ball_point((x, y), max_range)), np.int64)
        idx = near[(x, y)]
        vis = idx[visible_targets(targets[idx], camera_to_world(x, y, yaw, cam_height, pitch_deg), K, gw, gh,
                                  max_range, cell)]
        bearing = np.arctan2(targets[vis, 1] - y, targets[vis, 0] - x)
        sector = (np.floor((bearing + math.pi) / (2 * math.pi) * sectors).astype(np.int64) % sectors)
        seen_by.append((vis, (1 << sector).astype(np.int64)))
    count = np.zeros(len(targets), np.int64)
    bits = np.zeros(len(targets), np.int64)

    def gain(i: int) -> int:
        vis, bit = seen_by[i]
        return int(np.count_nonzero((count[vis] < k) & ((bits[vis] & bit) == 0)))

    heap = [(-len(v), i) for i, (v, _) in enumerate(seen_by)]
    heapq.heapify(heap)
    wanted = k * len(targets)
    floor_gain = max(1.0, min_gain * wanted)
    picked: list[int] = []
    while heap:
        neg, i = heapq.heappop(heap)
        g = gain(i)
        if heap and g < -heap[0][0]:  # stale bound: put it back with its current gain
            heapq.heappush(heap, (-g, i))
            continue
        if g < floor_gain:
            break
        vis, bit = seen_by[i]
        new = (count[vis] < k) & ((bits[vis] & bit) == 0)
        count[vis[new]] += 1
        bits[vis[new]] |= bit[new]
        picked.append(i)
    picked.sort()
    report = {"candidates": len(candidates), "targets": len(targets), "views": len(picked),
              "coverage": round(float(np.count_nonzero(count > 0)) / len(targets), 4),
              f"coverage_{k}": round(float(np.count_nonzero(count >= k)) / len(targets), 4),
              "seen_by_some_candidate": round(float(len(np.unique(np.concatenate([v for v, _ in seen_by])))) / len(targets), 4)}
    return candidates[picked], report
