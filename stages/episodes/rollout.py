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

import numpy as np

from navcore.nav.embodiment import Limits
from navcore.nav.poses import integrate, wrap_angle


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
