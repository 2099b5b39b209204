"""Covering poses for the semantic layer: the camera poses the scene came with, or robot poses on
free costmap cells looking all around."""
from __future__ import annotations

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


def source_camera_poses(cameras: list[dict], to_aligned: np.ndarray) -> np.ndarray:
    """[M, 4, 4] camera -> world (aligned frame, OpenCV axes) from a scene's camera list
    (each {"camera_to_world": 4x4} in the source frame, OpenCV axes) and the source -> aligned transform."""
    return np.stack([to_aligned @ np.asarray(c["camera_to_world"], float) for c in cameras]) if cameras else \
        np.zeros((0, 4, 4))


def yaw_coverage(poses: np.ndarray) -> float:
    """Largest angular gap (radians) between the headings of a pose set (a full circle: 2 pi / n)."""
    y = np.sort(np.mod(poses[:, 2], 2 * math.pi))
    return float(np.max(np.diff(np.concatenate([y, y[:1] + 2 * math.pi]))))
