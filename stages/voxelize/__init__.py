"""Opacity-field voxelization of 3D Gaussians (DESIGN.md, spatial layer, eq. 1-2)."""
from stages.voxelize.grid import VoxelGrid, grid_for_points
from stages.voxelize.field import VoxelizeConfig, opacity_field, column_max_opacity

__all__ = ["VoxelGrid", "grid_for_points", "VoxelizeConfig", "opacity_field", "column_max_opacity"]
