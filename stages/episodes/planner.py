"""Expert planning in SE(2) on a costmap: the scene's exact grid geodesic made taut, with OMPL's
planners as the fallback (or, by key, as the planner).

Key `geodesic` (the default): every episode already has the shortest path of the any-angle grid
graph from its start to its goal (the Dijkstra field its geodesic distance comes from); it is
resampled and string-pulled by the costmap's exact motion test (collision.taut_path, compiled),
which gives a path no longer than the geodesic in well under a millisecond, with no Python call
per check. Should that path fail the motion test anyway, the episode is planned by OMPL with the
`fallback` planner. The OMPL keys plan every episode with OMPL from scratch.

For OMPL, the state validity checker and the motion validator are the costmap's own exact disk tests (one
call per edge instead of OMPL's sampled checks along it). Termination is by iteration count, and
OMPL's random generator is reseeded per scene, so the same inputs give the same paths whatever
machine or worker runs them. Planners are chosen by registry key (config group `planner`).
"""
from __future__ import annotations

import contextlib
import math

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from navcore.registry import Registry
from stages.episodes.config import PlannerConfig

YAW_WEIGHT = 0.01
"""Weight of heading (radians) against position (metres) in the SE(2) metric."""


PLANNERS = Registry("planner", {
    "geodesic": "stages.episodes.planner:GEODESIC",
    "rrtconnect": "ompl.geometric:RRTConnect",
    "rrtstar": "ompl.geometric:RRTstar",
    "informed_rrtstar": "ompl.geometric:InformedRRTstar",
    "bitstar": "ompl.geometric:BITstar",
})
"""OMPL planners by key. Not registered, see design.md: AORRTC (crashes in these bindings) and
PRM* (its solve() checks for solutions on a second thread, which deadlocks on the Python validity
callback)."""
GEODESIC = "taut grid geodesic, OMPL fallback"
"""The `geodesic` key's registry entry (it names no OMPL class; ScenePlanner handles it)."""
ASYMPTOTICALLY_OPTIMAL = frozenset({"rrtstar", "informed_rrtstar", "bitstar"})


@contextlib.contextmanager
def _quiet():
    """Silence OMPL's console output (reseeding after first use logs an error by design)."""
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)
    try:
        yield
    finally:
        ou.setLogLevel(level)


def seed_ompl(seed: int) -> None:
    """Reseed OMPL's seed generator; every OMPL object created afterwards draws from it."""
    with _quiet():
        ou.RNG.setSeed(int(seed) % (2**31 - 1) + 1)


class _DiskMotionValidator(ob.MotionValidator):
    def __init__(self, si, costmap):
        super().__init__(si)
        self._check = costmap.is_motion_valid

    def checkMotion(self, a, b):  # noqa: N802 (OMPL's name)
        return self._check(a.getX(), a.getY(), b.getX(), b.getY())


class ScenePlanner:
    """OMPL planning context for one costmap: space, validity, planner and simplifier.

    Create it after seed_ompl(seed) for reproducible paths. Not thread-safe.
    """

    def __init__(self, costmap, cfg: PlannerConfig):
        for key in (cfg.name, cfg.fallback):
            if key not in PLANNERS:
                raise ValueError(f"unknown planner {key!r}; registered: {', '.join(PLANNERS)}")
        self.seeded = cfg.name == "geodesic"
        ompl_key = cfg.fallback if self.seeded else cfg.name
        if ompl_key == "geodesic":
            raise ValueError("planner.fallback must be an OMPL planner, not 'geodesic'")
        cls, self.optimizing = PLANNERS[ompl_key], ompl_key in ASYMPTOTICALLY_OPTIMAL
        self.cfg = cfg
        self.fallbacks = 0  # seeded paths that failed the motion test and went to OMPL
        self.costmap = costmap
        ny, nx = costmap.clearance.shape
        self.space = ob.SE2StateSpace()
        b = ob.RealVectorBounds(2)
        b.setLow(0, costmap.origin[0])
        b.setHigh(0, costmap.origin[0] + nx * costmap.resolution)
        b.setLow(1, costmap.origin[1])
        b.setHigh(1, costmap.origin[1] + ny * costmap.resolution)
        self.space.setBounds(b)
        # a disk robot: heading is free along the path (the rollout turns in place), so path
        # cost and nearest neighbours are about position; keep a trace of heading in the metric
        self.space.setSubspaceWeight(1, YAW_WEIGHT)
        self.si = ob.SpaceInformation(self.space)
        valid = costmap.is_state_valid
        self.si.setStateValidityChecker(lambda s: valid(s.getX(), s.getY()))
        self._mv = _DiskMotionValidator(self.si, costmap)
        self.si.setMotionValidator(self._mv)
        self.si.setup()
        self.planner = cls(self.si)
        if cfg.range > 0 and hasattr(self.planner, "setRange"):
            self.planner.setRange(cfg.range)
        self.simplifier = og.PathSimplifier(self.si)
        self._setup_done = False
        self._keep = []  # keeps OMPL states and goals alive while a problem definition refers to them

    def _state(self, x: float, y: float, yaw: float):
        s = self.space.allocState()
        s.setX(float(x))
        s.setY(float(y))
        s.setYaw(float(math.atan2(math.sin(yaw), math.cos(yaw))))
        self._keep.append(s)
        return s

    def _ptc(self, pdef, iterations: int):
        limit = _iterations(iterations)
        if self.optimizing:
            return limit
        return ob.plannerOrTerminationCondition(limit, ob.exactSolnPlannerTerminationCondition(pdef))

    def plan(self, start, goals, reference_length: float | None = None,
             geodesic_path: np.ndarray | None = None) -> np.ndarray | None:
        """Plan from a start pose to the nearest reachable of one or more goal poses.

        Args:
            start: (x, y, yaw) metres / radians.
            goals: [G, 3] goal poses (any one ends the path).
            reference_length: geodesic distance (metres); optimizing planners stop once within
                cost_tolerance of it.
            geodesic_path: [M, 2] the grid geodesic from the start to a goal (metres), used by
                the `geodesic` key; OMPL plans when it is None or its taut path is not valid.
        Returns:
            [M, 2] (x, y) path vertices from start to a goal, or None if none was found.
        """
        if self.seeded and geodesic_path is not None and len(geodesic_path) >= 2:
            path = merge_corners(self.costmap, self.costmap.taut_path(geodesic_path, self.cfg.resample_step),
                                 math.radians(self.cfg.merge_turn_deg))
            if self.costmap.are_motions_valid(np.concatenate([path[:-1], path[1:]], 1)).all():
                return path
            self.fallbacks += 1
        self._keep = []
        pdef = ob.ProblemDefinition(self.si)
        pdef.addStartState(self._state(*start))
        goals = np.asarray(goals, float).reshape(-1, 3)
        if len(goals) == 1:
            pdef.setGoalState(self._state(*goals[0]))
        else:
            gs = ob.GoalStates(self.si)
            for g in goals:
                gs.addState(self._state(*g))
            self._keep.append(gs)
            pdef.setGoal(gs)
        obj = ob.PathLengthOptimizationObjective(self.si)
        if self.optimizing and reference_length is not None:
            # SE(2) path length also counts heading change (weighted by YAW_WEIGHT): allow a turn
            obj.setCostThreshold(ob.Cost(reference_length * (1 + self.cfg.cost_tolerance) + YAW_WEIGHT * math.pi))
        pdef.setOptimizationObjective(obj)
        self.planner.clear()
        self.planner.setProblemDefinition(pdef)
        if not self._setup_done:
            with _quiet():  # it reports the range it picked at debug level
                self.planner.setup()
            self._setup_done = True
        with _quiet():
            status = self.planner.solve(self._ptc(pdef, self.cfg.max_iterations))
        if not pdef.hasExactSolution() or "Exact" not in str(status):
            return None
        path = pdef.getSolutionPath()
        if self.cfg.simplify:
            self.simplifier.reduceVertices(path)
            self.simplifier.ropeShortcutPath(path)
            # shortcuts only ever remove vertices; to let corners slide towards the obstacles
            # (a taut path), resample the path densely and shortcut again
            n = int(path.length() / self.cfg.resample_step) + 2
            path.interpolate(n)
            self.simplifier.ropeShortcutPath(path)
            self.simplifier.reduceVertices(path, 0, 0, 0.33)
            self.simplifier.collapseCloseVertices(path)
        return np.array([(s.getX(), s.getY()) for s in path.getStates()], float)


def _turn(a, b, c) -> float:
    """Signed heading change at b of the polyline a -> b -> c, radians."""
    h1 = math.atan2(b[1] - a[1], b[0] - a[0])
    h2 = math.atan2(c[1] - b[1], c[0] - b[0])
    return (h2 - h1 + math.pi) % (2 * math.pi) - math.pi


def merge_corners(costmap, path: np.ndarray, max_turn: float, slack: float = 1e-3) -> np.ndarray:
    """Fewer vertices for a turn-then-drive robot: a taut path bends around a (disk-dilated)
    corner in several small turns, each of which the rollout pays with a stop, a turn and a
    restart. Two consecutive turns the same way, together under `max_turn`, become one corner at
    the intersection of the segments before and after them, when both new segments are valid
    motions (with `slack` metres to spare); the corner lies outside the bend, away from the obstacle."""
    if max_turn <= 0:
        return path
    p = [np.asarray(path[0], float)]
    for k in range(1, len(path) - 1):  # a vertex without a turn costs a stop for nothing
        if abs(_turn(p[-1], path[k], path[k + 1])) > 1e-6:
            p.append(np.asarray(path[k], float))
    p.append(np.asarray(path[-1], float))
    changed = True
    while changed and len(p) >= 4:
        changed = False
        for i in range(1, len(p) - 2):
            t1, t2 = _turn(p[i - 1], p[i], p[i + 1]), _turn(p[i], p[i + 1], p[i + 2])
            if t1 * t2 <= 0 or abs(t1) + abs(t2) > max_turn:
                continue
            d1, d2 = p[i] - p[i - 1], p[i + 2] - p[i + 1]
            den = d1[0] * d2[1] - d1[1] * d2[0]
            if abs(den) < 1e-12:
                continue
            w = p[i + 1] - p[i - 1]
            x = p[i - 1] + d1 * ((w[0] * d2[1] - w[1] * d2[0]) / den)
            seg = np.array([[*p[i - 1], *x], [*x, *p[i + 2]]])
            if costmap.are_motions_valid(seg, slack).all():
                p[i:i + 2] = [x]
                changed = True
                break
    return np.array(p)


def _iterations(n: int):
    count = [0]

    def done() -> bool:
        count[0] += 1
        return count[0] > n

    return ob.PlannerTerminationCondition(done)
