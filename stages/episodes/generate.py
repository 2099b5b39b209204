"""Episode generation for one scene and task: samplers, the OMPL expert, rollouts, the validity
filter. Pure core: a costmap, a navigation graph and configs in; rows out (no IO)."""
from __future__ import annotations

import hashlib
import json
import math
import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from navcore.io import jsonio
from navcore.io.episode_schema import quantize_trajectory
from navcore.labels import is_structure
from navcore.nav.actions import ACTION_NAMES, MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT
from navcore.nav.embodiment import Limits
from navcore.nav.geodesic import taut_path
from navcore.nav.oracle import discrete_expert
from navcore.nav.poses import in_region, point_regions, region_distance, relative_waypoints
from stages.episodes.config import DifficultyConfig, EpisodesConfig, PlannerConfig, TaskConfig
from stages.episodes.planner import ScenePlanner, seed_ompl
from stages.episodes.rollout import rollout
from stages.episodes.validity import check_trajectory


def difficulty_of(geodesic: float, cfg: DifficultyConfig) -> int:
    """Index of the difficulty bin of a geodesic distance (metres)."""
    return int(np.searchsorted(np.asarray(cfg.upper), geodesic, side="right").clip(0, len(cfg.upper) - 1))


def habitat_keep_probability(ratio: np.ndarray, threshold: float) -> np.ndarray:
    """Habitat's rule against near-straight episodes: below the threshold ratio (geodesic /
    euclidean) a pair survives with probability 20 (r - 0.98)^2 (threshold <= 0: always)."""
    ratio = np.asarray(ratio, float)
    if threshold <= 0:
        return np.ones_like(ratio)
    return np.where(ratio >= threshold, 1.0, np.minimum(1.0, 20.0 * (ratio - 0.98) ** 2))


def split_names(n: int, splits: dict[str, float]) -> list[str]:
    """Split of each of n episodes: consecutive blocks by the configured shares (rounded so the
    counts add up to n)."""
    names, shares = list(splits), np.asarray(list(splits.values()), float)
    if (shares < 0).any() or shares.sum() <= 0:
        raise ValueError(f"episodes.splits must hold non-negative shares, got {splits}")
    edges = np.round(np.cumsum(shares) / shares.sum() * n).astype(int)
    return [names[int(np.searchsorted(edges, i, side="right"))] for i in range(n)]


def scene_split(scene_id: str, scene_splits: dict[str, float]) -> str | None:
    """The split a whole scene is held out into, or None: a hash of the scene id in [0, 1) against
    the cumulative shares (a scene keeps its split when others are added)."""
    u = int.from_bytes(hashlib.sha256(f"split:{scene_id}".encode()).digest()[:8], "little") / 2**64
    edge = 0.0
    for name, share in scene_splits.items():
        edge += share
        if u < edge:
            return name
    return None


@dataclass
class Goal:
    """What an episode aims at. sources: [k, 2] cells at distance 0 of its field."""

    kind: str                      # position | image | object
    sources: np.ndarray
    xy: np.ndarray | None = None   # position / image goal, metres
    yaw: float | None = None       # image goal heading, radians
    category: str | None = None
    instances: list[dict] = field(default_factory=list)  # object goal set (with view points)
    goals_json: str = ""


@dataclass
class TaskResult:
    episodes: list[dict]
    trajectories: dict[str, list[np.ndarray]]
    rejections: Counter
    cpu_s: float
    wall_s: float
    requested: int
    geodesic_from_expert: int = 0
    expert_fallbacks: int = 0


class EpisodeGenerator:
    """Generates the episodes of one task on one scene's costmap.

    Args:
        costmap: stages.costmap.Costmap of the embodiment. graph: NavGraph of its eligible cells.
        task: TaskConfig. ecfg: EpisodesConfig. pcfg: PlannerConfig. emb: Embodiment.
        scene_path: "{group}/{scene_id}". seed: the (scene, task) stream seed.
        instances: ObjectNav instance table rows (dicts of INSTANCE_SCHEMA), else None.
        views: stages.episodes.views.NearViews of the scene, or None (no blind-view test).
        screened: [ny, nx] bool cells episodes keep out of (the quality layer grown by the
            screening margin: starts, goals, ObjectNav view points and every expert pose), or None.
        goal_views: navcore.render.view_quality.DefectViews of the scene and the largest share
            of blur and hole pixels an ImageNav goal view may have, or None.
    """

    def __init__(self, costmap, graph, task: TaskConfig, ecfg: EpisodesConfig, pcfg: PlannerConfig, emb,
                 scene_path: str, seed: int, instances: list[dict] | None = None, views=None,
                 screened: np.ndarray | None = None, goal_views: tuple | None = None):
        self.cm, self.graph, self.task, self.ecfg, self.emb = costmap, graph, task, ecfg, emb
        self.views = views
        self.screened = screened
        self.goal_views = goal_views
        self.scene_path, self.seed = scene_path, seed
        self.rng = np.random.default_rng(seed)
        self.limits = Limits.of(emb)
        seed_ompl(seed)
        self.planner = ScenePlanner(costmap, pcfg)
        self.instances = instances or []
        self.rejections: Counter = Counter()
        dc = ecfg.difficulty
        if not (len(dc.names) == len(dc.upper) == len(dc.max_steps)):
            raise ValueError("episodes.difficulty: names, upper and max_steps must have the same length")
        lo = np.concatenate([[0.0], dc.upper[:-1]])
        self.bins = [b for b in range(len(dc.upper)) if dc.upper[b] > task.min_geodesic and lo[b] <= task.max_geodesic]

    # ---- goals -------------------------------------------------------------------------------
    def _object_goals(self) -> list[Goal]:
        """One goal set per category: its instances that have view points."""
        t = self.task
        res = self.cm.resolution
        step = max(1, int(round(t.view_point_spacing / res)))
        by_cat: dict[str, list[dict]] = {}
        for inst in self.instances:
            if inst["category"] not in t.categories or is_structure(inst["category"]):
                continue
            c = np.array([inst["center_x"], inst["center_y"]])
            region = success_region(inst, t.success_rule)
            # lattice cells within the success radius of the region that the graph holds
            half = max(region[2] - region[0], region[3] - region[1]) / 2
            r = int(math.ceil((t.success_radius + half) / res)) + 1
            ci, cj = int((c[1] - self.cm.origin[1]) / res), int((c[0] - self.cm.origin[0]) / res)
            ii, jj = np.mgrid[ci - r:ci + r + 1, cj - r:cj + r + 1]
            keep = (ii % step == 0) & (jj % step == 0) & (ii >= 0) & (jj >= 0) & \
                (ii < self.graph.valid.shape[0]) & (jj < self.graph.valid.shape[1])
            cells = np.stack([ii[keep], jj[keep]], 1)
            cells = cells[self.graph.valid[cells[:, 0], cells[:, 1]]]
            xy = self.cm.cell_centers(cells)
            near = region_distance(xy, region[None]) <= t.success_radius - t.view_point_margin
            cells, xy = cells[near], xy[near]
            if self.screened is not None and len(cells):
                clean = ~self.screened[cells[:, 0], cells[:, 1]]
                cells, xy = cells[clean], xy[clean]
                if not len(cells):
                    self.rejections["instance_screened"] += 1
                    continue
            if not len(cells):
                self.rejections["instance_without_view_points"] += 1
                continue
            if len(cells) > t.max_view_points:  # spread around the object: even picks by angle
                order = np.argsort(np.arctan2(*(xy - c).T[::-1]), kind="stable")
                pick = order[np.linspace(0, len(order) - 1, t.max_view_points).round().astype(int)]
                cells, xy = cells[pick], xy[pick]
            yaw = np.arctan2(c[1] - xy[:, 1], c[0] - xy[:, 0])
            by_cat.setdefault(inst["category"], []).append(
                {"instance": inst, "cells": cells, "xy": xy, "yaw": yaw, "centre": c, "region": region,
                 "rule": t.success_rule})
        goals = []
        for cat in sorted(by_cat):
            insts = by_cat[cat]
            goals.append(Goal("object", np.concatenate([v["cells"] for v in insts]), category=cat, instances=insts))
        return goals

    # ---- one episode -------------------------------------------------------------------------
    def _episode(self, goal: Goal, fld, node: int, difficulty_budget: int, bucket: int = -1):
        """Plan, roll out and check one start; returns (episode dict, trajectory arrays) or None.
        bucket: the difficulty the start was drawn for by its grid distance (-1: any); a start whose
        taut geodesic falls into another is rejected, so that the difficulties stay balanced."""
        t, cm = self.task, self.cm
        start_xy = cm.cell_centers(self.graph.cells[node][None])[0]
        start_yaw = self._start_yaw(start_xy)
        if start_yaw is None:
            self.rejections["start_view_blind"] += 1
            return None
        geo = float(fld.node_dist[node])
        path_cells = fld.path_cells(self.graph.cells[node])
        if goal.kind == "object":
            # the goal instance is the one whose view point ends the geodesic
            inst = next(v for v in goal.instances if (v["cells"] == path_cells[-1]).all(1).any())
            k = int(np.flatnonzero((inst["cells"] == path_cells[-1]).all(1))[0])
            goal_xy, goal_yaw = inst["xy"][k], float(inst["yaw"][k])
            goal_poses = np.array([[goal_xy[0], goal_xy[1], goal_yaw]])
        else:
            inst = None
            goal_xy, goal_yaw = goal.xy, goal.yaw
            goal_poses = np.array([[goal.xy[0], goal.xy[1], goal.yaw if goal.yaw is not None else 0.0]])
        euclid = float(np.hypot(*(goal_xy - start_xy)))
        # success regions: the goal, or every instance of the ObjectNav category
        regions = np.ascontiguousarray([v["region"] for v in goal.instances], np.float64) \
            if goal.kind == "object" else point_regions(goal_xy[None])
        if in_region(start_xy[0], start_xy[1], regions, t.success_radius):
            self.rejections["start_in_success_region"] += 1  # trivial: SR 1 without a step (Habitat rejects these)
            return None
        if cm.is_motion_valid(start_xy[0], start_xy[1], goal_xy[0], goal_xy[1]):
            geo = min(geo, euclid)  # in line of sight the geodesic is the straight line
        else:  # the grid path through cell centres, pulled taut in the continuous free space
            taut = taut_path(cm, cm.cell_centers(path_cells))
            geo = min(geo, float(np.hypot(*np.diff(taut, axis=0).T).sum()))
        if bucket >= 0 and difficulty_of(geo, self.ecfg.difficulty) != bucket:
            self.rejections["difficulty_changed_by_taut_geodesic"] += 1
            return None
        best = None
        seed_path = cm.cell_centers(path_cells)
        for _ in range(max(1, self.planner.cfg.attempts)):
            path = self.planner.plan((start_xy[0], start_xy[1], start_yaw), goal_poses, geo, seed_path)
            if path is None:
                continue
            length = float(np.hypot(*np.diff(path, axis=0).T).sum())
            if best is None or length < best[1]:
                best = (path, length)
            if length <= geo * self.planner.cfg.retry_ratio:
                break
        if best is None:
            self.rejections["plan_failed"] += 1
            return None
        path, length = best
        final_yaw = goal_yaw if goal.kind in ("image", "object") else None
        ro = as_stored(rollout(path, start_yaw, final_yaw, self.limits, self.ecfg.dt))
        success = lambda x, y: bool(in_region(x, y, regions, t.success_radius))  # noqa: E731
        tol = math.radians(t.heading_tolerance_deg) if goal.kind == "image" else None
        why = check_trajectory(ro["x"], ro["y"], ro["yaw"], ro["v"], ro["w"], cm, self.emb.radius, self.limits,
                               self.ecfg.dt, success, goal_yaw if goal.kind == "image" else None, tol)
        if why:
            self.rejections[f"invalid_{why}"] += 1
            return None
        if self._screened(cm.cells_of(np.stack([ro["x"], ro["y"]], 1))):
            self.rejections["path_screened"] += 1  # the expert would drive through blur or a hole
            return None
        travelled = float(np.hypot(np.diff(ro["x"]), np.diff(ro["y"])).sum())
        from_expert = travelled < geo - 1e-6
        geo = min(geo, travelled)  # the expert found a shorter valid path than the grid metric
        oracle = None
        if self.ecfg.oracle:
            oracle = discrete_expert(fld.grid, cm, (start_xy[0], start_xy[1], start_yaw), regions, t.success_radius,
                                     goal_yaw if goal.kind == "image" else None,
                                     math.radians(t.heading_tolerance_deg), self.ecfg.actions.forward_step,
                                     self.ecfg.actions.turn, difficulty_budget)
            if oracle is None:
                self.rejections["oracle_failed"] += 1
                return None
            oracle = oracle.tolist()
        return self._row(goal, inst, start_xy, start_yaw, goal_xy, goal_yaw, geo, euclid, ro, travelled,
                         oracle), ro, from_expert

    def _row(self, goal, inst, start_xy, start_yaw, goal_xy, goal_yaw, geo, euclid, ro, travelled, oracle) -> dict:
        dc, t, emb = self.ecfg.difficulty, self.task, self.emb
        b = difficulty_of(geo, dc)
        n = len(ro["x"])
        speed = np.hypot(np.diff(ro["x"]), np.diff(ro["y"])) / self.ecfg.dt
        row = {
            "task_type": t.type, "scene_path": self.scene_path, "embodiment": emb.name,
            "difficulty": dc.names[b], "max_steps": int(dc.max_steps[b]),
            **_pose_cols("start_", start_xy, start_yaw), "start_yaw": start_yaw,
            "goal_type": goal.kind,
            **_pose_cols("goal_", goal_xy, goal_yaw or 0.0), "goal_yaw": goal_yaw if goal_yaw is not None else math.nan,
            "success_radius": t.success_radius,
            "heading_tolerance": math.radians(t.heading_tolerance_deg) if goal.kind == "image" else math.nan,
            "geodesic_distance": geo, "euclidean_distance": euclid, "num_steps": n,
            "total_time": (n - 1) * self.ecfg.dt, "path_length": travelled,
            "avg_speed": travelled / max((n - 1) * self.ecfg.dt, 1e-9), "max_speed": float(speed.max(initial=0.0)),
            "oracle_actions": oracle, "goal_image_path": None, "goal_camera_json": None,
            "goal_object_category": goal.category, "goal_object_id": None,
            "instruction_text": None, "instruction_language": None, "seed": self.seed,
        }
        r = t.success_radius
        if goal.kind == "position":
            row["goals_json"] = json.dumps([{"position": [*map(float, goal_xy), 0.0], "radius": r}])
        elif goal.kind == "image":
            cam = {"position": [float(goal_xy[0]), float(goal_xy[1]), emb.camera_height], "yaw": goal_yaw,
                   "pitch_deg": emb.camera_pitch_deg, "hfov_deg": emb.hfov_deg,
                   "width": emb.image_width, "height": emb.image_height}
            row["goal_camera_json"] = json.dumps(cam)
            row["goals_json"] = json.dumps([{"position": [*map(float, goal_xy), 0.0], "yaw": goal_yaw, "radius": r,
                                             "camera": cam}])
        else:
            row["goal_object_id"] = int(inst["instance"]["instance_id"])
            row["goals_json"] = goal.goals_json
        return row

    def _screened(self, cells: np.ndarray) -> bool:
        """Whether any of these (row, col) cells is screened out (cells off the grid are not)."""
        if self.screened is None or not len(cells):
            return False
        ny, nx = self.screened.shape
        on = (cells[:, 0] >= 0) & (cells[:, 0] < ny) & (cells[:, 1] >= 0) & (cells[:, 1] < nx)
        return bool(self.screened[cells[on, 0], cells[on, 1]].any())

    def _goal_yaw(self, xy: np.ndarray) -> tuple[float | None, str]:
        """An ImageNav goal yaw whose camera sees at least goal_view_min_depth (median over its
        field of view; see TaskConfig), is not blind (`views`) and not mostly blur or holes
        (`goal_views`), from up to goal_view_tries uniform draws; (None, reason) if none: reason
        goal_view_blurred when a draw failed for blur, else goal_view_blocked."""
        t = self.task
        reason = "goal_view_blocked"
        for _ in range(max(1, t.goal_view_tries)):
            yaw = float(self.rng.uniform(-math.pi, math.pi))
            if t.goal_view_min_depth > 0 and \
                    self.cm.fov_depth(xy, yaw, self.emb.hfov_deg, 4 * t.goal_view_min_depth) < t.goal_view_min_depth:
                continue
            if self.views and self.views.blind(xy, yaw):
                continue
            if self.goal_views is not None:
                views, most = self.goal_views
                if views.measure(np.array([[xy[0], xy[1], yaw]])).defect[0] > most:
                    reason = "goal_view_blurred"
                    continue
            return yaw, ""
        return None, reason

    def _start_yaw(self, xy: np.ndarray) -> float | None:
        """A start yaw, uniform; with the blind-view test, the first of up to view_tries draws whose
        camera is not blind; None if none."""
        for _ in range(max(1, self.ecfg.view_tries) if self.views else 1):
            yaw = float(self.rng.uniform(-math.pi, math.pi))
            if not (self.views and self.views.blind(xy, yaw)):
                return yaw
        return None

    # ---- sampling loop -----------------------------------------------------------------------
    def _start_pool(self, fld, goal: Goal) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """Start candidates of one field, per difficulty bin it can fill: (bin, nodes, cumulative
        weights). Starts lie within the geodesic limits; PointNav / ImageNav weight them with
        Habitat's near-straight keep probability: the same distribution as its rejection
        sampling, without the rejected draws. Starts inside the goal's success region are left
        out, and so are the nodes whose geodesic to the goal crosses a screened cell (the taut
        expert may still touch one: checked after the rollout). Without balancing, one pool with
        bin -1."""
        t, dc = self.task, self.ecfg.difficulty
        d = fld.node_dist
        nodes = np.flatnonzero((d >= t.min_geodesic) & (d <= t.max_geodesic))
        if goal.kind == "object" or t.trivial_ratio <= 0:
            w = np.ones(len(nodes))
        else:
            euclid = np.hypot(*(self.cm.cell_centers(self.graph.cells[nodes]) - goal.xy).T)
            w = habitat_keep_probability(d[nodes] / np.maximum(euclid, 1e-9), t.trivial_ratio)
        regions = np.array([v["region"] for v in goal.instances]) if goal.kind == "object" else point_regions(goal.xy[None])
        near = region_distance(self.cm.cell_centers(self.graph.cells[nodes]), regions)
        keep = (w > 0) & (near > t.success_radius)  # no start inside its own success region
        if self.screened is not None:  # nor where the geodesic to the goal crosses a screened cell
            keep &= ~fld.paths_crossing(self.screened)[nodes]
        nodes, w = nodes[keep], w[keep]
        if not dc.balance:
            return [(-1, nodes, np.cumsum(w))] if len(nodes) else []
        b_of = np.searchsorted(np.asarray(dc.upper), d[nodes], side="right")
        return [(b, nodes[b_of == b], np.cumsum(w[b_of == b])) for b in self.bins if (b_of == b).any()]

    def _draw_start(self, pool, produced: int, strict: bool = False) -> tuple[int, int]:
        """A start node and its bin: the target bin is round robin over all bins, falling to the
        next one this goal can fill. Returns (-1, -1) when the pool is empty; strict: (-1, the target
        bin) when this goal cannot fill the target bin (the caller draws another goal, so that a
        scene whose goals mostly lie in the middle still gets its share of far starts)."""
        if not pool:
            return -1, -1
        have = {b: (nodes, cw) for b, nodes, cw in pool}
        order = self.bins if self.ecfg.difficulty.balance else [-1]
        for k in range(len(order)):
            b = order[(produced + k) % len(order)]
            if b in have:
                nodes, cw = have[b]
                i = int(np.searchsorted(cw, self.rng.random() * cw[-1], side="right"))
                return int(nodes[min(i, len(nodes) - 1)]), b
            if strict:
                return -1, b
        return -1, -1

    def generate(self) -> TaskResult:
        t = self.task
        t0, c0 = time.perf_counter(), time.process_time()
        n_req = t.episodes_per_scene
        rows, trajs, from_expert, misses = [], [], 0, 0
        attempts, max_attempts = 0, n_req * self.ecfg.max_attempts_factor
        if t.type == "objectnav":
            goal_sets = self._object_goals()
            for g in goal_sets:
                g.goals_json = jsonio.dumps([_instance_json(v) for v in g.instances])
            fields = {}
            if not goal_sets:
                self.rejections["no_goal_category"] += 1
        elif t.type not in ("pointnav", "imagenav"):
            raise ValueError(f"unknown task type {t.type!r} (pointnav | imagenav | objectnav)")
        while len(rows) < n_req and attempts < max_attempts and len(self.graph.cells):
            if t.type == "objectnav":
                if not goal_sets:
                    break
                goal = goal_sets[len(rows) % len(goal_sets)]
                if goal.category not in fields:
                    f = self.graph.field(goal.sources, t.max_geodesic)
                    fields[goal.category] = (f, self._start_pool(f, goal))
                fld, pool = fields[goal.category]
                per_goal = 1
            else:
                node = int(self.rng.integers(len(self.graph.cells)))
                cell = self.graph.cells[node]
                if self._screened(cell[None]):
                    attempts += 1
                    self.rejections["goal_screened"] += 1
                    continue
                xy = self.cm.cell_centers(cell[None])[0]
                yaw, why = self._goal_yaw(xy) if t.type == "imagenav" else (None, "")
                if t.type == "imagenav" and yaw is None:
                    attempts += 1
                    self.rejections[why] += 1
                    continue
                goal = Goal("image" if t.type == "imagenav" else "position", cell[None], xy=xy, yaw=yaw)
                fld = self.graph.field(goal.sources, t.max_geodesic)
                pool = self._start_pool(fld, goal)
                per_goal = t.starts_per_goal
            for _ in range(per_goal):
                if len(rows) >= n_req or attempts >= max_attempts:
                    break
                attempts += 1
                # a point goal that cannot fill the bin whose turn it is gives way to another goal, up to
                # a bound (then the next bin it can fill): the bins fill evenly where the free space allows
                strict = t.type != "objectnav" and self.ecfg.difficulty.balance and misses < n_req * 2
                node, b = self._draw_start(pool, len(rows), strict)
                if node < 0:
                    misses += b >= 0
                    self.rejections["goal_cannot_fill_bin" if b >= 0 else "no_start_in_range"] += 1
                    break
                budget = self.ecfg.difficulty.max_steps[b] if b >= 0 else max(self.ecfg.difficulty.max_steps)
                out = self._episode(goal, fld, node, budget, b)
                if out is None:
                    continue
                row, ro, fe = out
                rows.append(row)
                trajs.append(ro)
                from_expert += fe
        if len(rows) < n_req and attempts >= max_attempts:
            self.rejections["attempts_exhausted"] += 1
        splits = split_names(len(rows), self.ecfg.splits)
        counters: Counter = Counter()
        for row, split in zip(rows, splits):
            row["split"] = split
            row["episode_id"] = f"{split}_{counters[split]:06d}"
            counters[split] += 1
        traj_cols = _trajectory_columns(rows, trajs, self.ecfg.dt)
        return TaskResult(rows, traj_cols, self.rejections, time.process_time() - c0, time.perf_counter() - t0,
                          n_req, from_expert, self.planner.fallbacks)


def success_region(inst: dict, rule: str) -> np.ndarray:
    """[4] success region of an instance-table row: its footprint (the box on the floor) under
    rule "footprint" when the box is known, else its centre (the paper's rule, "centre")."""
    if rule not in ("footprint", "centre"):
        raise ValueError(f"task.success_rule={rule!r}; choose footprint | centre")
    box = [inst.get(k) for k in ("min_x", "min_y", "max_x", "max_y")]
    if rule == "footprint" and all(v is not None and math.isfinite(v) for v in box):
        return np.array(box, np.float64)
    return np.array([inst["center_x"], inst["center_y"], inst["center_x"], inst["center_y"]], np.float64)


def as_stored(ro: dict) -> dict:
    """A rollout with its poses and controls rounded to their stored precision (float32): every
    check, length and oracle below sees exactly what the trajectory table will hold."""
    return {**ro, **{k: np.asarray(ro[k], np.float32).astype(np.float64) for k in ("x", "y", "yaw", "v", "w")}}


_ACTION_NAME_ARRAY = np.array([ACTION_NAMES[k] for k in sorted(ACTION_NAMES)], object)


def _pose_cols(prefix: str, xy, yaw: float) -> dict:
    return {f"{prefix}position_x": float(xy[0]), f"{prefix}position_y": float(xy[1]), f"{prefix}position_z": 0.0,
            f"{prefix}rotation_qx": 0.0, f"{prefix}rotation_qy": 0.0,
            f"{prefix}rotation_qz": math.sin(yaw / 2), f"{prefix}rotation_qw": math.cos(yaw / 2)}


def _instance_json(v: dict) -> dict:
    inst = v["instance"]
    return {"object_id": int(inst["instance_id"]), "object_category": inst["category"],
            "position": [inst["center_x"], inst["center_y"], inst["center_z"]],
            "bounding_box": {"min": [inst["min_x"], inst["min_y"], inst["min_z"]],
                             "max": [inst["max_x"], inst["max_y"], inst["max_z"]]},
            "success_rule": v["rule"],
            **({"footprint": {"min": [float(v["region"][0]), float(v["region"][1])],
                              "max": [float(v["region"][2]), float(v["region"][3])]}} if v["rule"] == "footprint" else {}),
            "view_points": [{"position": [float(x), float(y), 0.0], "yaw": float(w)}
                            for (x, y), w in zip(v["xy"], v["yaw"])]}


def _trajectory_columns(rows: list[dict], trajs: list[dict], dt: float) -> dict[str, list[np.ndarray]]:
    """Per-step columns of all expert rollouts (TRAJECTORY_SCHEMA order), as lists of arrays."""
    cols: dict[str, list[np.ndarray]] = {}
    for row, ro in zip(rows, trajs):
        n = len(ro["x"])
        v, w, yaw = ro["v"], ro["w"], ro["yaw"]
        action = np.where(ro["phase"] == 1, MOVE_FORWARD,
                          np.where(ro["phase"] == 2, np.where(w > 0, TURN_LEFT, TURN_RIGHT), STOP)).astype(np.int8)
        dx, dy, dyaw = relative_waypoints(ro["x"], ro["y"], yaw)
        part = {
            "episode_id": np.full(n, row["episode_id"], object), "step": np.arange(n, dtype=np.int32),
            "timestamp": np.arange(n) * dt, "position_x": ro["x"], "position_y": ro["y"], "position_z": np.zeros(n),
            "rotation_qx": np.zeros(n), "rotation_qy": np.zeros(n), "rotation_qz": np.sin(yaw / 2),
            "rotation_qw": np.cos(yaw / 2), "yaw": yaw,
            "action": _ACTION_NAME_ARRAY[action], "action_id": action,
            "linear_velocity": v, "angular_velocity": w,
            "linear_velocity_x": v * np.cos(yaw), "linear_velocity_y": v * np.sin(yaw),
            "linear_acceleration": np.diff(v, prepend=0.0) / dt, "angular_acceleration": np.diff(w, prepend=0.0) / dt,
            "curvature": np.where(v > 0, w / np.where(v > 0, v, 1.0), 0.0),
            "dx": dx, "dy": dy, "dyaw": dyaw,
            "phase": np.array(["stop", "translate", "rotate"], object)[ro["phase"]],
        }
        for k, a in quantize_trajectory(part).items():
            cols.setdefault(k, []).append(a)
    return cols
