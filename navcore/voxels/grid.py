"""Axis-aligned voxel grids."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class VoxelGrid:
    """Voxel (i, j, k) spans origin + [i, i+1) * voxel_size along each axis.

    Attributes:
        origin: (x, y, z) of the grid's minimum corner, metres.
        voxel_size: (dx, dy, dz) metres (may differ per axis).
        shape: (nx, ny, nz) voxels.
    """

    origin: tuple[float, float, float]
    voxel_size: tuple[float, float, float]
    shape: tuple[int, int, int]

    @property
    def n_voxels(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    def centers(self, axis: int) -> np.ndarray:
        """Centres of the voxels along one axis, metres."""
        return self.origin[axis] + (np.arange(self.shape[axis]) + 0.5) * self.voxel_size[axis]

    def as_dict(self) -> dict:
        return {"origin": list(map(float, self.origin)), "voxel_size": list(map(float, self.voxel_size)),
                "shape": list(map(int, self.shape))}


def grid_for_points(points: np.ndarray, voxel_size, margin: float = 0.0, lo_q: float = 0.0, hi_q: float = 100.0,
                    max_voxels: int = 2_000_000_000) -> VoxelGrid:
    """Smallest grid covering the points (between the lo_q and hi_q percentiles per axis, so far
    outliers do not blow up the grid) plus a margin, aligned to multiples of the voxel size.

    Raises ValueError if the grid would exceed max_voxels (wrong units or resolution).
    """
    vs = np.broadcast_to(np.asarray(voxel_size, dtype=np.float64), (3,))
    if lo_q > 0 or hi_q < 100:
        lo, hi = np.percentile(points, [lo_q, hi_q], axis=0)
    else:
        lo, hi = points.min(0), points.max(0)
    lo = np.floor((lo - margin) / vs) * vs
    hi = np.ceil((hi + margin) / vs) * vs
    shape = np.maximum(np.round((hi - lo) / vs).astype(np.int64), 1)
    n = int(np.prod(shape))
    if n > max_voxels:
        ext = " x ".join(f"{v:.2f}" for v in (hi - lo))
        size = " x ".join(f"{v:g}" for v in vs)
        raise ValueError(
            f"a {size} m voxel grid over this scene's extent ({ext} m) would need {n:,} voxels "
            f"(limit {max_voxels:,}); are the scene units metres? otherwise use a coarser resolution")
    return VoxelGrid(tuple(lo.tolist()), tuple(vs.tolist()), tuple(int(s) for s in shape))
