"""Gaussians as pieces of surface: a flat Gaussian (smallest axis well below the other two) has
its smallest axis as normal."""
from __future__ import annotations

import numpy as np

from navcore.gaussians.model import GaussianScene, quat_to_rotmat


def surface_normals(scene: GaussianScene, flat_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """([N, 3] unit normal = smallest axis of each Gaussian, [N] bool flat)."""
    s = np.sort(scene.log_scales, axis=1)
    flat = s[:, 0] < s[:, 1] + np.log(flat_ratio)
    rot = quat_to_rotmat(scene.quats.astype(np.float64))
    k = np.argmin(scene.log_scales, axis=1)
    return np.take_along_axis(rot, k[:, None, None], axis=2)[..., 0], flat


def horizontal_surfaces(scene: GaussianScene, flat_ratio: float, tol_deg: float) -> np.ndarray:
    """[N] bool: flat Gaussians whose normal is within tol_deg of vertical (aligned frame: floor,
    ceiling, table tops)."""
    normals, flat = surface_normals(scene, flat_ratio)
    return flat & (np.abs(normals[:, 2]) > np.cos(np.radians(tol_deg)))
