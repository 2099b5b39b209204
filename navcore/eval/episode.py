"""An episode as the environment needs it, read from a row of the canonical episodes table."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from navcore.nav.poses import in_region, object_regions, point_regions, region_distance


@dataclass
class Episode:
    """One evaluation episode (aligned frame, metres, radians)."""

    episode_id: str
    task: str                        # pointnav | imagenav | objectnav
    start: tuple[float, float, float]  # x, y, yaw
    goal_xy: np.ndarray              # [2] the goal position (ObjectNav: nearest view point)
    centres: np.ndarray              # [k, 2] success-region centres (ObjectNav: instance centres)
    success_radius: float
    geodesic: float                  # metres: the optimum SPL divides by
    max_steps: int
    difficulty: str = ""
    goal_yaw: float | None = None    # ImageNav
    heading_tolerance: float = math.radians(30)
    category: str | None = None      # ObjectNav
    goal_sources: np.ndarray | None = None  # [m, 2] positions at distance 0 of the goal's field
    goal_camera: dict | None = None  # ImageNav: camera of the goal view
    reference_path: np.ndarray | None = None  # [n, 2] expert positions (for DTW)
    scene_id: str = ""
    extra: dict = field(default_factory=dict)
    regions: np.ndarray | None = None  # [k, 4] success regions (in_region); None: the centres as points
    shown: "Episode | None" = field(default=None, repr=False, compare=False)
    """The episode whose goal the agent is shown in place of this one's (the decoy check,
    navcore.eval.decoy): its goal image, category or point; success, SPL and every metric stay this
    episode's. None: its own goal."""

    def __post_init__(self):
        self.centres = np.ascontiguousarray(self.centres, np.float64).reshape(-1, 2)
        self.regions = point_regions(self.centres) if self.regions is None else \
            np.ascontiguousarray(self.regions, np.float64).reshape(-1, 4)  # as in_region takes them

    @classmethod
    def from_row(cls, row: dict, reference_path: np.ndarray | None = None) -> "Episode":
        """From a canonical episodes row (a dict; pandas' NaN for missing strings is accepted)."""
        row = {k: (None if isinstance(v, float) and math.isnan(v) and k.endswith(("_json", "category")) else v)
               for k, v in row.items()}
        task = str(row.get("task_type") or row.get("task"))
        goal = np.array([row["goal_position_x"], row["goal_position_y"]], float)
        goals = json.loads(row["goals_json"]) if row.get("goals_json") else []
        if task == "objectnav":
            centres = np.array([g["position"][:2] for g in goals], float)
            regions = object_regions(goals)  # each goal's stored success rule: footprint or centre
            sources = np.array([v["position"][:2] for g in goals for v in g["view_points"]], float)
        else:
            centres, sources, regions = goal[None], goal[None], None
        yaw = row.get("goal_yaw")
        return cls(
            episode_id=row["episode_id"], task=task,
            start=(float(row["start_position_x"]), float(row["start_position_y"]), float(row["start_yaw"])),
            goal_xy=goal, centres=centres, regions=regions, success_radius=float(row["success_radius"]),
            geodesic=float(row["geodesic_distance"]), max_steps=int(row["max_steps"]),
            difficulty=row.get("difficulty", ""),
            goal_yaw=float(yaw) if task == "imagenav" and yaw is not None and not math.isnan(yaw) else None,
            heading_tolerance=float(row["heading_tolerance"]) if task == "imagenav" else math.radians(30),
            category=row.get("goal_object_category") if task == "objectnav" else None, goal_sources=sources,
            goal_camera=json.loads(row["goal_camera_json"]) if row.get("goal_camera_json") else None,
            reference_path=reference_path, scene_id=str(row.get("scene_id", "")))

    @property
    def shown_goal(self) -> "Episode":
        """The episode whose goal the agent sees: `shown`, else this one."""
        return self.shown if self.shown is not None else self

    @property
    def goal_pose(self) -> np.ndarray:
        """[3] (x, y, yaw) of the goal view (heading 0 when the goal has none)."""
        return np.array([self.goal_xy[0], self.goal_xy[1], self.goal_yaw or 0.0], float)

    def in_region(self, x: float, y: float) -> bool:
        return bool(in_region(float(x), float(y), self.regions, self.success_radius))

    def distance_to_goal(self, x: float, y: float) -> float:
        """Planar Euclidean distance to the nearest success region (NE): its point, or the object's
        footprint under the footprint rule (0 on it)."""
        return float(region_distance([[x, y]], self.regions)[0])
