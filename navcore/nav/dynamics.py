"""What a blocked translation does: the one rule of the closed-loop environment (every action form,
the gym and batched environments) for a move whose swept disk meets an obstacle.

Modes (`evaluate.dynamics.blocked`):
- "truncate" (default): the robot advances to the last collision-free pose along the straight
  swept path (to within `tolerance`), as a real robot that drives until its bumper touches;
- "stay": the pose stays (the rule of earlier versions and of the paper's evaluator);
- "slide": truncate, then the rest of the displacement projected onto the obstacle's tangent
  (the remaining motion less its component into the obstacle, along the clearance field's
  gradient at the contact), itself truncated: habitat-sim's `allow_sliding`.
Every mode counts the collision; the heading change of the step applies in every mode (turning in
place never collides: the footprint is a disk).
"""
from __future__ import annotations

import math

import numpy as np

BLOCKED_MODES = ("truncate", "stay", "slide")


def truncate_motion(costmap, x0: float, y0: float, x1: float, y1: float, tolerance: float = 0.005) -> tuple[float, float]:
    """The farthest pose (x0, y0) + f (x1 - x0, y1 - y0), f in [0, 1], whose straight motion from
    (x0, y0) is valid, found by bisection to within `tolerance` metres (a motion's prefix of a valid
    motion is valid, so validity along the segment is one interval from the start)."""
    if costmap.is_motion_valid(x0, y0, x1, y1):
        return x1, y1
    length = math.hypot(x1 - x0, y1 - y0)
    lo, hi = 0.0, 1.0
    while (hi - lo) * length > tolerance:
        mid = 0.5 * (lo + hi)
        if costmap.is_motion_valid(x0, y0, x0 + mid * (x1 - x0), y0 + mid * (y1 - y0)):
            lo = mid
        else:
            hi = mid
    return x0 + lo * (x1 - x0), y0 + lo * (y1 - y0)


def obstacle_normal(costmap, x: float, y: float) -> np.ndarray:
    """Unit vector away from the nearest obstacle at (x, y): the clearance field's gradient
    (central differences, half a cell apart); zeros where the field is flat."""
    h = 0.5 * costmap.resolution
    c = costmap.clearance_at(np.array([[x + h, y], [x - h, y], [x, y + h], [x, y - h]], np.float64))
    g = np.array([c[0] - c[1], c[2] - c[3]], np.float64)
    n = float(np.hypot(*g))
    return g / n if n > 1e-12 else np.zeros(2)


def blocked_motion(costmap, x0: float, y0: float, x1: float, y1: float, mode: str = "truncate",
                   tolerance: float = 0.005) -> list[tuple[float, float]]:
    """Where a blocked translation from (x0, y0) towards (x1, y1) goes under `mode` (module doc):
    the poses it passes through after the start, in order (empty: it stays). Each leg is a valid
    straight motion of the costmap."""
    if mode not in BLOCKED_MODES:
        raise ValueError(f"evaluate.dynamics.blocked={mode!r}; choose one of {', '.join(BLOCKED_MODES)}")
    if mode == "stay":
        return []
    cx, cy = truncate_motion(costmap, x0, y0, x1, y1, tolerance)
    legs = [(cx, cy)] if math.hypot(cx - x0, cy - y0) > 0 else []
    if mode == "slide":
        rest = np.array([x1 - cx, y1 - cy])
        n = obstacle_normal(costmap, cx, cy)
        into = float(rest @ n)
        tangent = rest - into * n if into < 0 else rest
        if float(np.hypot(*tangent)) > tolerance:
            sx, sy = truncate_motion(costmap, cx, cy, cx + tangent[0], cy + tangent[1], tolerance)
            if math.hypot(sx - cx, sy - cy) > 0:
                legs.append((sx, sy))
    return legs
