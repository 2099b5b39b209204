"""Expert rollouts: a planned polyline -> a discrete-time trajectory at dt that respects the
embodiment's speed, turn-rate and acceleration limits, and the discrete-action expert.

Continuous expert (turn in place, then drive straight, per path segment): each step holds a
constant (v, omega); speed profiles are discrete trapezoids, so |v| <= v_max, |omega| <= w_max and
the change between consecutive steps (from rest at the start, to rest at the end of each motion)
is <= a_max dt. Integrating x += v cos(yaw) dt, y += v sin(yaw) dt, yaw += omega dt from a row
gives the next row exactly, and the robot stays on the planned (validated) segments.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from stages.costmap import kernels as K

# Discrete actions (Habitat's ids): the oracle's and the trajectories' action_id
STOP, MOVE_FORWARD, TURN_LEFT, TURN_RIGHT = 0, 1, 2, 3
ACTION_NAMES = {STOP: "stop", MOVE_FORWARD: "move_forward", TURN_LEFT: "turn_left", TURN_RIGHT: "turn_right"}


def wrap_angle(a):
    """Angle(s) wrapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def speed_profile(total: float, v_max: float, a_max: float, dt: float) -> np.ndarray:
    """Per-step constant speeds covering `total` (>= 0) in the fewest steps.

    Returns [n] speeds v_k in [0, v_max] with sum(v) dt = total, |v_k - v_k-1| <= a_max dt and
    v_1, v_n <= a_max dt (it starts and ends at rest).
    """
    if total <= 1e-12:
        return np.zeros(0)
    dv = a_max * dt
    t_acc = v_max / a_max
    if total >= v_max * t_acc:  # trapezoid: accelerate, cruise, brake
        t = total / v_max + t_acc
    else:  # triangle
        t = 2.0 * math.sqrt(total / a_max)
    n = max(1, int(t / dt) - 2)
    while True:
        k = np.arange(1, n + 1)
        v = np.minimum(v_max, dv * np.minimum(k, n + 1 - k))
        reach = v.sum() * dt
        if reach >= total:
            return v * (total / reach)
        n += 1


@dataclass
class Limits:
    """Kinematic limits of an embodiment (m/s, rad/s, m/s^2, rad/s^2)."""

    v_max: float
    w_max: float
    a_max: float
    alpha_max: float

    @classmethod
    def of(cls, emb) -> "Limits":
        return cls(emb.max_linear_velocity, emb.max_angular_velocity, emb.max_linear_acceleration,
                   emb.max_angular_acceleration)


def rollout(path_xy: np.ndarray, start_yaw: float, final_yaw: float | None, limits: Limits, dt: float) -> dict:
    """Turn-then-drive rollout of a polyline.

    Args:
        path_xy: [M, 2] vertices, metres (the first is the start).
        start_yaw: initial heading, radians. final_yaw: heading to turn to at the end (None: keep).
        limits: kinematic limits. dt: step, seconds.
    Returns:
        dict of arrays over the N+1 rows (row k = state at t = k dt and the control held until
        row k+1; the last row holds zero controls): x, y, yaw [N+1] float64, v, w [N+1] float64
        (m/s, rad/s), phase [N+1] int8 (0 stop, 1 translate, 2 rotate).
    """
    v_parts, w_parts, ph_parts = [], [], []
    yaw = float(start_yaw)

    def turn(delta: float):
        w = speed_profile(abs(delta), limits.w_max, limits.alpha_max, dt) * np.sign(delta)
        v_parts.append(np.zeros_like(w))
        w_parts.append(w)
        ph_parts.append(np.full(len(w), 2, np.int8))

    for a, b in zip(path_xy[:-1], path_xy[1:]):
        d = b - a
        length = math.hypot(d[0], d[1])
        if length < 1e-9:
            continue
        heading = math.atan2(d[1], d[0])
        turn(float(wrap_angle(heading - yaw)))
        yaw = heading
        v = speed_profile(length, limits.v_max, limits.a_max, dt)
        v_parts.append(v)
        w_parts.append(np.zeros_like(v))
        ph_parts.append(np.full(len(v), 1, np.int8))
    if final_yaw is not None:
        turn(float(wrap_angle(final_yaw - yaw)))
    v = np.concatenate(v_parts + [np.zeros(1)])
    w = np.concatenate(w_parts + [np.zeros(1)])
    phase = np.concatenate(ph_parts + [np.zeros(1, np.int8)])
    x, y, th = integrate(path_xy[0, 0], path_xy[0, 1], start_yaw, v[:-1], w[:-1], dt)
    return {"x": x, "y": y, "yaw": th, "v": v, "w": w, "phase": phase}


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
def _potential(dist, ox, oy, res, x, y):
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
def in_region(x, y, centres, radius):
    """Whether (x, y) lies within `radius` (+1e-9) of any of the success-region centres [k, 2]."""
    for k in range(centres.shape[0]):
        if math.hypot(x - centres[k, 0], y - centres[k, 1]) <= radius + 1e-9:
            return True
    return False


@numba.njit(cache=True)
def oracle_action(x, y, yaw, dist, clearance, ox, oy, res, thr, centres, radius, goal_yaw, yaw_tol,
                  forward, turn):
    """The discrete oracle's next action from a pose.

    Greedy on the geodesic field: among the headings yaw + k turn (k = -n..n, a full circle), take
    the one whose forward step (a valid swept-disk motion) lowers the geodesic distance most; turn
    one step towards it, or move forward when it is straight ahead. Inside the success region:
    STOP (ImageNav: first turn to within yaw_tol of goal_yaw; goal_yaw NaN = no heading goal).
    Returns an action id, or -1 when no move makes progress (stuck).
    """
    if in_region(x, y, centres, radius):
        if goal_yaw != goal_yaw:  # NaN
            return STOP
        e = (goal_yaw - yaw + math.pi) % (2 * math.pi) - math.pi
        if abs(e) <= yaw_tol:
            return STOP
        return TURN_LEFT if e > 0 else TURN_RIGHT
    d0 = _potential(dist, ox, oy, res, x, y)
    n = int(round(math.pi / turn))
    best_k, best_d = 0, d0 - 1e-4
    for a in range(2 * n):
        k = (a + 1) // 2 * (1 if a % 2 == 1 else -1)  # 0, 1, -1, 2, -2, ... (straight ahead first)
        h = yaw + k * turn
        x1, y1 = x + forward * math.cos(h), y + forward * math.sin(h)
        d = _potential(dist, ox, oy, res, x1, y1)
        if d < best_d - 1e-9 and K._motion(clearance, (x - ox) / res - 0.5, (y - oy) / res - 0.5,
                                           (x1 - ox) / res - 0.5, (y1 - oy) / res - 0.5, thr):
            best_k, best_d = k, d
    if best_d >= d0 - 1e-4:
        return -1
    if best_k == 0:
        return MOVE_FORWARD
    return TURN_LEFT if best_k > 0 else TURN_RIGHT


@numba.njit(cache=True)
def _oracle_rollout(x, y, yaw, dist, clearance, ox, oy, res, thr, centres, radius, goal_yaw, yaw_tol,
                    forward, turn, max_steps):
    out = np.empty(max_steps, np.int8)
    for s in range(max_steps):
        a = oracle_action(x, y, yaw, dist, clearance, ox, oy, res, thr, centres, radius, goal_yaw, yaw_tol,
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
        centres: [k, 2] success-region centres (PointNav / ImageNav: the goal; ObjectNav: the
            category's instance centres), radius: their radius, metres.
        goal_yaw: ImageNav: turn to within heading_tolerance / 2 of it before stopping.
        forward: metres per MOVE_FORWARD. turn: radians per TURN_*.
    """

    def __init__(self, dist_grid: np.ndarray, costmap, centres: np.ndarray, radius: float,
                 goal_yaw: float | None = None, heading_tolerance: float = math.radians(30),
                 forward: float = 0.25, turn: float = math.radians(15)):
        self._args = (dist_grid, costmap.clearance, costmap.origin[0], costmap.origin[1], costmap.resolution,
                      costmap.radius + costmap.margin, np.ascontiguousarray(centres, np.float64).reshape(-1, 2),
                      float(radius), math.nan if goal_yaw is None else float(goal_yaw), heading_tolerance / 2,
                      float(forward), float(turn))

    def action(self, x: float, y: float, yaw: float) -> int:
        """The next action id from a pose, or -1 when no move makes progress."""
        return int(oracle_action(float(x), float(y), float(yaw), *self._args))

    def episode(self, start, max_steps: int = 1500) -> np.ndarray | None:
        """[n] int8 action ids from `start` (x, y, yaw) ending with STOP, or None when stuck or
        over budget."""
        acts = _oracle_rollout(float(start[0]), float(start[1]), float(start[2]), *self._args, int(max_steps))
        return acts if len(acts) else None


def discrete_expert(dist_grid: np.ndarray, costmap, start, centres: np.ndarray, radius: float,
                    goal_yaw: float | None = None, heading_tolerance: float = math.radians(30),
                    forward: float = 0.25, turn: float = math.radians(15), max_steps: int = 1500) -> np.ndarray | None:
    """The discrete-action oracle's whole episode from `start` (x, y, yaw): [n] int8 action ids
    ending with STOP, or None when stuck or over budget (see DiscreteOracle for the arguments)."""
    return DiscreteOracle(dist_grid, costmap, centres, radius, goal_yaw, heading_tolerance, forward,
                          turn).episode(start, max_steps)
