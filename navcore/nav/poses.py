"""Poses and angles: angle wrapping, integration of (v, omega) controls, relative waypoints."""
from __future__ import annotations

import math

import numba
import numpy as np


def wrap_angle(a):
    """Angle(s) wrapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def goal_in_robot_frame(x: float, y: float, yaw: float, goal_xy) -> tuple[float, float]:
    """The goal's position (forward, left) in metres in the frame of a robot at (x, y, yaw)."""
    dxw, dyw = float(goal_xy[0]) - x, float(goal_xy[1]) - y
    c, s = math.cos(yaw), math.sin(yaw)
    return c * dxw + s * dyw, -s * dxw + c * dyw


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
def in_region(x, y, regions, radius):
    """Whether (x, y) lies within `radius` (+1e-9) of any success region [k, 4] (xmin, ymin, xmax,
    ymax: a goal point is a box of size zero, an object's footprint its box on the floor)."""
    for k in range(regions.shape[0]):
        dx = max(regions[k, 0] - x, 0.0, x - regions[k, 2])
        dy = max(regions[k, 1] - y, 0.0, y - regions[k, 3])
        if math.hypot(dx, dy) <= radius + 1e-9:
            return True
    return False


def point_regions(xy) -> np.ndarray:
    """Success regions [k, 4] of goal points [k, 2] (boxes of size zero)."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    return np.ascontiguousarray(np.concatenate([xy, xy], 1))


def region_distance(xy, regions: np.ndarray) -> np.ndarray:
    """Planar distance of points [n, 2] to the nearest of the regions [k, 4] (0 inside a box): [n]."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    r = np.asarray(regions, np.float64).reshape(-1, 4)
    if not len(r):
        return np.full(len(xy), np.inf)
    dx = np.maximum.reduce([r[None, :, 0] - xy[:, None, 0], np.zeros((len(xy), len(r))), xy[:, None, 0] - r[None, :, 2]])
    dy = np.maximum.reduce([r[None, :, 1] - xy[:, None, 1], np.zeros((len(xy), len(r))), xy[:, None, 1] - r[None, :, 3]])
    return np.hypot(dx, dy).min(1)


def object_regions(goals: list[dict]) -> np.ndarray:
    """Success regions [k, 4] of an ObjectNav episode's goal instances (goals_json entries): the
    footprint box on the floor where the entry's success_rule is "footprint", else the centre
    (the paper's rule; entries written before the rule existed)."""
    out = []
    for g in goals:
        fp = g.get("footprint") if g.get("success_rule") == "footprint" else None
        if fp is not None:
            out.append([*fp["min"][:2], *fp["max"][:2]])
        else:
            out.append([*g["position"][:2], *g["position"][:2]])
    return np.ascontiguousarray(np.asarray(out, np.float64).reshape(-1, 4))
