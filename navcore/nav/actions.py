"""The discrete actions (Habitat's ids): the oracle's, the trajectories' ``action_id`` and the
evaluation's."""
from __future__ import annotations

import math
from dataclasses import dataclass

STOP, MOVE_FORWARD, TURN_LEFT, TURN_RIGHT = 0, 1, 2, 3
ACTION_NAMES = {STOP: "stop", MOVE_FORWARD: "move_forward", TURN_LEFT: "turn_left", TURN_RIGHT: "turn_right"}


@dataclass(frozen=True)
class ActionSpace:
    """Step sizes of the discrete actions: the stored oracle action sequences and the evaluation
    both use these (section ``episodes.actions``), so they cannot disagree."""

    forward_step: float = 0.25
    """MOVE_FORWARD distance, metres."""
    turn_angle_deg: float = 15.0
    """TURN_LEFT / TURN_RIGHT angle, degrees."""

    @property
    def turn(self) -> float:
        """TURN_LEFT / TURN_RIGHT angle, radians."""
        return math.radians(self.turn_angle_deg)
