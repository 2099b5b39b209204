"""Poses and angles: angle wrapping, integration of (v, omega) controls, relative waypoints."""
from __future__ import annotations

import math

import numba
import numpy as np


def wrap_angle(a):
    """Angle(s) wrapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def integrate(x0: float, y0: float, yaw0: float, v: np.ndarray, w: np.ndarray, dt: float):
    """Poses [N+1] from per-step (v, omega) held for dt each (turn-then-drive steps are exact:
    no step both moves and turns)."""
    yaw = yaw0 + np.concatenate([[0.0], np.cumsum(w * dt)])
    x = x0 + np.concatenate([[0.0], np.cumsum(v * np.cos(yaw[:-1]) * dt)])
    y = y0 + np.concatenate([[0.0], np.cumsum(v * np.sin(yaw[:-1]) * dt)])
    return x, y, yaw


def relative_waypoints(x: np.ndarray, y: np.ndarray, yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-row pose change to the next row in the row's robot frame (x forward, y left, yaw
    counter-clockwise; the last row gets zeros): (dx, dy, dyaw), metres and radians."""
    ddx, ddy = np.diff(x, append=x[-1]), np.diff(y, append=y[-1])
    c, s = np.cos(yaw), np.sin(yaw)
    return c * ddx + s * ddy, -s * ddx + c * ddy, wrap_angle(np.diff(yaw, append=yaw[-1]))


@numba.njit(cache=True)
def in_region(x, y, centres, radius):
    """Whether (x, y) lies within `radius` (+1e-9) of any of the success-region centres [k, 2]."""
    for k in range(centres.shape[0]):
        if math.hypot(x - centres[k, 0], y - centres[k, 1]) <= radius + 1e-9:
            return True
    return False
