"""An ObjectNav (and ImageNav) expert a student can imitate: search until the goal has been in view,
then go. ImageNav's success region is the disk around the goal image's position: the expert has
found it once its camera has seen that place (not necessarily from the goal image's heading).

The geodesic oracle (navcore.nav.oracle) knows where every instance of the category is and never
searches. A policy that sees only its camera cannot tell where to go while no instance has been in
view, so imitating that oracle teaches it nothing there (the trained ObjectNav baseline turned in
place; navcore/baselines/design.md). This expert's actions depend only on what its camera has seen
along the trajectory, which a recurrent policy also has:

- **Seeing.** At each pose, rays across the camera's horizontal field of view are traced on the
  costmap's obstacle layer (`Costmap.view_depths`) up to `max_range`; every cell a ray crosses is
  seen. The goal is found once a seen point lies in a success region (within the success radius
  of an instance's footprint or centre): the camera has seen where stopping succeeds.
- **Searching.** Until then, it drives to the nearest cell not yet seen (geodesic distance over
  the navigation graph, at least `min_hop` away), with the same discrete moves as the oracle, and
  picks the next such cell when it gets within `reach` of it (the cells around it count as seen)
  or can make no progress towards it.
- **Going.** Once found, its action is the geodesic oracle's (which stops inside the region).

ImageNav (`goal_view`): a glimpse of the floor where the goal image was taken says nothing a policy
can recognise: the image shows what the goal camera faces, not where it stands. So with a goal
view, found means the camera now sees at least `overlap` of what the goal image shows: the points
where the goal camera's rays meet an obstacle (its walls and furniture), each visible when it lies
in the field of view, within range, and no obstacle stands in front of it. The student then learns
to search until its view looks like the goal image, and to go from there.

Deterministic: the same poses give the same actions.
"""
from __future__ import annotations

import math

import numpy as np

from navcore.nav.actions import STOP
from navcore.nav.oracle import DiscreteOracle
from navcore.nav.poses import point_regions, region_distance


class SearchingExpert:
    """The search-then-go expert of one ObjectNav episode (see the module docstring).

    Args:
        graph: the scene's NavGraph (its costmap is the one moves and rays use).
        goal: the episode's geodesic oracle (DiscreteOracle), used once the goal has been seen.
        regions, radius: the episode's success regions [k, 4] and success radius (metres).
        hfov_deg: the camera's horizontal field of view. max_range: how far it sees (metres).
        forward, turn: the action space (metres, radians), as the oracle's.
        goal_view: ImageNav's goal camera (x, y, yaw): found once `overlap` of the surface it sees is
            in view (module docstring); None, or overlap 0: once a success region has been seen.
    """

    def __init__(self, graph, goal: DiscreteOracle, regions: np.ndarray, radius: float, hfov_deg: float,
                 max_range: float = 5.0, forward: float = 0.25, turn: float = math.radians(15), rays: int = 31,
                 min_hop: float = 1.0, reach: float = 0.5, horizon: float = 6.0,
                 goal_view: tuple[float, float, float] | None = None, overlap: float = 0.5):
        self.graph, self.costmap, self.goal = graph, graph.costmap, goal
        self.regions, self.radius = np.asarray(regions, np.float64).reshape(-1, 4), float(radius)
        self.half_fov, self.max_range, self.rays = math.radians(hfov_deg) / 2, float(max_range), int(rays)
        self.forward, self.turn = float(forward), float(turn)
        self.min_hop, self.reach, self.horizon = float(min_hop), float(reach), float(horizon)
        self.seen = np.zeros(self.costmap.clearance.shape, bool)
        self.found = False
        self.target: np.ndarray | None = None  # (x, y) of the cell being driven to
        self._to_target: DiscreteOracle | None = None
        res = self.costmap.resolution
        self._steps = np.arange(0.0, self.max_range + res, res / 2)  # samples along a ray
        self.overlap = float(overlap)
        self.goal_points = None if goal_view is None or self.overlap <= 0 else self._surface(*goal_view)

    def _rays(self, x: float, y: float, yaw: float) -> tuple[np.ndarray, np.ndarray]:
        """The camera's rays at (x, y, yaw): their angles and free depths on the obstacle layer."""
        angles = yaw + np.linspace(-self.half_fov, self.half_fov, self.rays)
        return angles, self.costmap.view_depths((x, y), angles, max_range=self.max_range)

    def _surface(self, x: float, y: float, yaw: float) -> np.ndarray:
        """[K, 2] the points a camera at (x, y, yaw) sees on the obstacle layer: where its rays end
        on an obstacle (all ray ends when fewer than a quarter of them hit one: an open view)."""
        angles, depth = self._rays(x, y, yaw)
        hit = depth < self.max_range - 1e-6
        if hit.sum() < max(1, len(angles) // 4):
            hit[:] = True
        return np.array([x, y])[None] + depth[hit, None] * np.column_stack([np.cos(angles[hit]), np.sin(angles[hit])])

    def visible(self, x: float, y: float, yaw: float, pts: np.ndarray, tol: float = 0.15) -> np.ndarray:
        """[K] whether each point is in view of the camera at (x, y, yaw): inside its horizontal
        field of view, within range, and nothing on the obstacle layer in front of it (a ray towards
        it runs at least its distance less `tol`)."""
        d = np.hypot(pts[:, 0] - x, pts[:, 1] - y)
        ang = np.arctan2(pts[:, 1] - y, pts[:, 0] - x)
        off = np.abs((ang - yaw + np.pi) % (2 * np.pi) - np.pi)
        cand = (off <= self.half_fov) & (d <= self.max_range + tol)
        out = np.zeros(len(pts), bool)
        if cand.any():
            free = self.costmap.view_depths((x, y), ang[cand], max_range=self.max_range + tol)
            out[cand] = free >= d[cand] - tol
        return out

    # ------------------------------------------------------------------ seeing
    def look(self, x: float, y: float, yaw: float) -> None:
        """Mark what the camera at (x, y, yaw) sees; set `found` when it sees a success region (with a
        goal view: `overlap` of the goal image's surface)."""
        angles, depth = self._rays(x, y, yaw)
        dirs = np.column_stack([np.cos(angles), np.sin(angles)])
        keep = self._steps[None, :] <= depth[:, None]
        pts = (np.array([x, y])[None, None, :] + self._steps[None, :, None] * dirs[:, None, :])[keep]
        self._mark(pts)
        if self.found:
            return
        if self.goal_points is not None:  # ImageNav: the goal image's surface in view
            self.found = bool(self.visible(x, y, yaw, self.goal_points).mean() >= self.overlap)
        elif len(self.regions) and (region_distance(pts, self.regions) <= self.radius).any():
            self.found = True

    def _mark(self, pts: np.ndarray) -> None:
        cells = self.costmap.cells_of(pts)
        ny, nx = self.seen.shape
        ok = (cells[:, 0] >= 0) & (cells[:, 0] < ny) & (cells[:, 1] >= 0) & (cells[:, 1] < nx)
        self.seen[cells[ok, 0], cells[ok, 1]] = True

    def _mark_disk(self, xy: np.ndarray, r: float) -> None:
        res = self.costmap.resolution
        g = np.arange(-r, r + res, res)
        gx, gy = np.meshgrid(g, g)
        inside = gx ** 2 + gy ** 2 <= r * r
        self._mark(np.column_stack([gx[inside] + xy[0], gy[inside] + xy[1]]))

    # ------------------------------------------------------------------ searching
    def _pick(self, x: float, y: float) -> bool:
        """The nearest unseen valid cell at least min_hop away (within `horizon` first, then
        anywhere) as the next target; False when none is reachable."""
        cell = self.costmap.cells_of(np.array([[x, y]]))
        if self.graph.index[cell[0, 0], cell[0, 1]] < 0:
            return False
        # bounded searches first: the nearest unseen cell is mostly just past min_hop, and a search
        # bounded at a limit finds the same nearest cell (the same distances, the same first of equals)
        # as an unbounded one whenever it finds one at all, at a fraction of the cost (area ~ limit^2)
        for limit in sorted({min(self.min_hop + 1.0, self.horizon), self.horizon}) + [np.inf]:
            d = self.graph.field(cell, limit=limit).grid
            cand = np.where(self.graph.valid & ~self.seen & (d >= self.min_hop) & np.isfinite(d), d, np.inf)
            k = int(np.argmin(cand))
            if np.isfinite(cand.flat[k]):
                tgt = np.unravel_index(k, cand.shape)
                field = self.graph.field(np.array([tgt]), limit=float(cand.flat[k]) + 2.0)
                self.target = self.costmap.cell_centers(np.array([tgt]))[0]
                self._to_target = DiscreteOracle(field.grid, self.costmap, point_regions(self.target[None]),
                                                 self.reach, None, forward=self.forward, turn=self.turn)
                return True
        return False

    def action(self, x: float, y: float, yaw: float) -> int:
        """Look from the pose, then the next action id (-1 when the goal oracle is stuck)."""
        self.look(x, y, yaw)
        for _ in range(4):
            if self.found:
                break
            if self.target is None and not self._pick(x, y):
                self.found = True  # nothing left to search: go (the oracle knows the way)
                break
            a = self._to_target.action(x, y, yaw)
            if a not in (STOP, -1):
                return a
            self._mark_disk(self.target, self.reach + self.min_hop / 2)  # reached, or no way on: next
            self.target = self._to_target = None
        return self.goal.action(x, y, yaw)
