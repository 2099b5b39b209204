"""Opacity-field voxelization of 3D Gaussians (DESIGN.md, spatial layer, eq. 1-2)."""
from navcore.voxels.field import VoxelizeConfig, column_max_opacity, opacity_field
from navcore.voxels.grid import VoxelGrid, grid_for_points

__all__ = ["VoxelGrid", "grid_for_points", "VoxelizeConfig", "opacity_field", "column_max_opacity"]
