"""Gravity alignment: up axis and floor plane from the Gaussians (and capture cameras) -> rigid transform to z up, floor at z = 0."""
from navcore.gaussians.floor import AlignConfig, axis_name, fit_floor, floor_transform

__all__ = ["AlignConfig", "axis_name", "fit_floor", "floor_transform"]
