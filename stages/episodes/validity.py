"""The validity filter of expert trajectories, independent of the planner and the rollout: it
looks only at the stored rows (poses and controls) and the costmap."""
from __future__ import annotations

import numpy as np

from navcore.nav.embodiment import Limits
from navcore.nav.poses import integrate, wrap_angle

# Slack for float round-off in the checks (relative to the limits), and the pose tolerance of
# the control-consistency check, metres / radians (controls are stored as float32: integrating
# them over a thousand steps drifts by ~1e-5). Poses are stored as float32 too: the limits
# checks add the largest error that rounding can put into differences of stored poses.
_SLACK = 1e-6
_POSE_TOL = 1e-4


def float32_rounding(*arrays) -> float:
    """Largest float32 rounding error of any value of the arrays (half an ulp at their largest
    magnitude)."""
    m = max((float(np.abs(a).max()) for a in arrays if len(a)), default=0.0)
    return float(np.spacing(np.float32(m))) / 2

REASONS = ("clearance", "collision", "goal", "heading", "speed", "acceleration", "controls")


def check_trajectory(x, y, yaw, v, w, costmap, radius: float, limits: Limits, dt: float, success,
                     goal_yaw: float | None = None, heading_tolerance: float | None = None) -> str | None:
    """Why a trajectory is invalid, or None when it passes every check.

    Args:
        x, y, yaw: [N+1] poses, metres / radians. v, w: [N+1] controls held after each row.
        costmap: Costmap. radius: the agent radius, metres. limits: kinematic limits. dt: step, s.
        success: (x, y) -> bool, the goal's success region.
        goal_yaw, heading_tolerance: ImageNav's heading criterion (radians), or None.
    Returns:
        one of REASONS: clearance (a state closer than the radius to an obstacle or off the
        supported region), collision (a segment between states is not a valid motion), goal (the
        final state is outside the success region, or facing away for ImageNav), heading (a
        heading change above w_max dt), speed (above v_max), acceleration (speed or turn-rate
        change above the limits, from and to rest), controls (the stored controls do not
        reproduce the stored poses).
    """
    xy = np.stack([x, y], 1)
    if (costmap.clearance_at(xy) < radius).any():
        return "clearance"
    if len(xy) > 1 and not costmap.are_motions_valid(np.concatenate([xy[:-1], xy[1:]], 1)).all():
        return "collision"
    if not success(float(x[-1]), float(y[-1])):
        return "goal"
    if goal_yaw is not None and abs(wrap_angle(goal_yaw - yaw[-1])) > heading_tolerance:
        return "goal"
    # a difference of two stored values is off by at most 2 e; a planar step by 2 sqrt2 e
    e_pos, e_yaw = float32_rounding(x, y), float32_rounding(yaw)
    dyaw = wrap_angle(np.diff(yaw))
    if (np.abs(dyaw) > limits.w_max * dt * (1 + _SLACK) + 2 * e_yaw).any():
        return "heading"
    speed = np.hypot(np.diff(x), np.diff(y)) / dt
    if (speed > limits.v_max * (1 + _SLACK) + 2 * np.sqrt(2) * e_pos / dt).any():
        return "speed"
    rest = np.zeros(1)
    acc = np.abs(np.diff(np.concatenate([rest, speed, rest]))) / dt
    ang = np.abs(np.diff(np.concatenate([rest, dyaw / dt, rest]))) / dt
    if (acc > limits.a_max * (1 + _SLACK) + 4 * np.sqrt(2) * e_pos / dt**2).any() or \
            (ang > limits.alpha_max * (1 + _SLACK) + 4 * e_yaw / dt**2).any():
        return "acceleration"
    xi, yi, ti = integrate(x[0], y[0], yaw[0], np.asarray(v)[:-1], np.asarray(w)[:-1], dt)
    if max(np.abs(xi - x).max(), np.abs(yi - y).max(), np.abs(wrap_angle(ti - yaw)).max()) > _POSE_TOL:
        return "controls"
    return None
