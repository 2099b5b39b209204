"""The discrete-action oracle: greedy descent of the geodesic distance field with swept-disk
moves. The stored expert's action sequences and the closed-loop oracle agent both use it."""
from __future__ import annotations

import math

import numba
import numpy as np

from navcore.nav.actions import MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT
from navcore.nav.collision import segment_clear
from navcore.nav.poses import in_region


@numba.njit(cache=True)
def geodesic_potential(dist, ox, oy, res, x, y):
    """Geodesic distance at a continuous point: the best of the 3x3 cells around it (their
    distance plus the straight hop to their centre), inf when none is reachable."""
    ny, nx = dist.shape
    i, j = int(math.floor((y - oy) / res)), int(math.floor((x - ox) / res))
    best = np.inf
    for di in range(-1, 2):
        for dj in range(-1, 2):
            ci, cj = i + di, j + dj
            if 0 <= ci < ny and 0 <= cj < nx and dist[ci, cj] < np.inf:
                d = dist[ci, cj] + math.hypot(ox + (cj + 0.5) * res - x, oy + (ci + 0.5) * res - y)
                if d < best:
                    best = d
    return best


@numba.njit(cache=True)
def oracle_action(x, y, yaw, dist, clearance, ox, oy, res, thr, regions, radius, goal_yaw, yaw_tol,
                  forward, turn):
    """The discrete oracle's next action from a pose.

    Greedy on the geodesic field: among the headings yaw + k turn (k = -n..n, a full circle), take
    the one whose forward step (a valid swept-disk motion) lowers the geodesic distance most; turn
    one step towards it, or move forward when it is straight ahead. Inside the success region:
    STOP (ImageNav: first turn to within yaw_tol of goal_yaw; goal_yaw NaN = no heading goal).
    Returns an action id, or -1 when no move makes progress (stuck).
    """
    if in_region(x, y, regions, radius):
        if goal_yaw != goal_yaw:  # NaN
            return STOP
        e = (goal_yaw - yaw + math.pi) % (2 * math.pi) - math.pi
        if abs(e) <= yaw_tol:
            return STOP
        return TURN_LEFT if e > 0 else TURN_RIGHT
    d0 = geodesic_potential(dist, ox, oy, res, x, y)
    n = int(round(math.pi / turn))
    best_k, best_d = 0, d0 - 1e-4
    for a in range(2 * n):
        k = (a + 1) // 2 * (1 if a % 2 == 1 else -1)  # 0, 1, -1, 2, -2, ... (straight ahead first)
        h = yaw + k * turn
        x1, y1 = x + forward * math.cos(h), y + forward * math.sin(h)
        d = geodesic_potential(dist, ox, oy, res, x1, y1)
        if d < best_d - 1e-9 and segment_clear(clearance, (x - ox) / res - 0.5, (y - oy) / res - 0.5,
                                           (x1 - ox) / res - 0.5, (y1 - oy) / res - 0.5, thr):
            best_k, best_d = k, d
    if best_d >= d0 - 1e-4:
        return -1
    if best_k == 0:
        return MOVE_FORWARD
    return TURN_LEFT if best_k > 0 else TURN_RIGHT


@numba.njit(cache=True)
def oracle_rollout(x, y, yaw, dist, clearance, ox, oy, res, thr, regions, radius, goal_yaw, yaw_tol,
                    forward, turn, max_steps):
    out = np.empty(max_steps, np.int8)
    for s in range(max_steps):
        a = oracle_action(x, y, yaw, dist, clearance, ox, oy, res, thr, regions, radius, goal_yaw, yaw_tol,
                          forward, turn)
        if a < 0:
            return out[:0]
        out[s] = a
        if a == STOP:
            return out[:s + 1]
        if a == MOVE_FORWARD:
            x += forward * math.cos(yaw)
            y += forward * math.sin(yaw)
        else:
            yaw += turn if a == TURN_LEFT else -turn
    return out[:0]


class DiscreteOracle:
    """The discrete-action oracle of one episode (see oracle_action): the stored expert's action
    sequence and the closed-loop oracle agent both go through it.

    Args:
        dist_grid: [ny, nx] geodesic distance to the goal (set), metres, inf where unreachable.
        costmap: Costmap (moves are its swept-disk motions).
        regions: [k, 4] success regions (navcore.nav.poses.in_region; PointNav / ImageNav: the goal
            point; ObjectNav: the category's instances, centres or footprints), radius: metres.
        goal_yaw: ImageNav: turn to within heading_tolerance / 2 of it before stopping.
        forward: metres per MOVE_FORWARD. turn: radians per TURN_*.
    """

    def __init__(self, dist_grid: np.ndarray, costmap, regions: np.ndarray, radius: float,
                 goal_yaw: float | None = None, heading_tolerance: float = math.radians(30),
                 forward: float = 0.25, turn: float = math.radians(15)):
        self._args = (dist_grid, costmap.clearance, costmap.origin[0], costmap.origin[1], costmap.resolution,
                      costmap.radius + costmap.margin, np.ascontiguousarray(regions, np.float64).reshape(-1, 4),
                      float(radius), math.nan if goal_yaw is None else float(goal_yaw), heading_tolerance / 2,
                      float(forward), float(turn))

    def action(self, x: float, y: float, yaw: float) -> int:
        """The next action id from a pose, or -1 when no move makes progress."""
        return int(oracle_action(float(x), float(y), float(yaw), *self._args))

    def episode(self, start, max_steps: int = 1500) -> np.ndarray | None:
        """[n] int8 action ids from `start` (x, y, yaw) ending with STOP, or None when stuck or
        over budget."""
        acts = oracle_rollout(float(start[0]), float(start[1]), float(start[2]), *self._args, int(max_steps))
        return acts if len(acts) else None


def discrete_expert(dist_grid: np.ndarray, costmap, start, regions: np.ndarray, radius: float,
                    goal_yaw: float | None = None, heading_tolerance: float = math.radians(30),
                    forward: float = 0.25, turn: float = math.radians(15), max_steps: int = 1500) -> np.ndarray | None:
    """The discrete-action oracle's whole episode from `start` (x, y, yaw): [n] int8 action ids
    ending with STOP, or None when stuck or over budget (see DiscreteOracle for the arguments)."""
    return DiscreteOracle(dist_grid, costmap, regions, radius, goal_yaw, heading_tolerance, forward,
                          turn).episode(start, max_steps)
