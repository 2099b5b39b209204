"""The navigation environment: an agent moves a disk robot through a scene's costmap and sees
rendered RGB-D.

Actions (any of):
- discrete ids 0 STOP, 1 MOVE_FORWARD (actions.forward_step), 2 TURN_LEFT, 3 TURN_RIGHT (actions.turn);
- {"stop": true} (how STOP is sent in every form);
- waypoints {"waypoints": [{"x", "y", "yaw"}, ...]}: relative moves in the robot frame (ROS: x
  forward, y left, yaw counter-clockwise, metres / radians), applied in order within one step (at
  most MAX_WAYPOINTS); a single flat waypoint {"x", "y", "yaw"} (navarena-server's random agent
  sends this form) is one such move;
- velocity {"v", "w", "dt"}: integrated as x = v dt forward, then yaw = w dt (0 < dt <= MAX_DT).
Every number must be finite: an invalid action (NaN or inf, missing fields, an unknown form)
consumes its step, changes nothing and is recorded (`invalid_actions`, the first message in
`action_error`); the episode goes on.
A translation is checked as a swept disk on the costmap (its exact straight-motion test). A
blocked translation counts as a collision and goes where `dynamics.blocked` says
(navcore.nav.dynamics: truncate, the default: to the last collision-free pose along the path;
stay; slide: along the obstacle, as habitat-sim's allow_sliding); the step's heading change
applies in every mode. Turning in place never collides (the footprint is a disk).

Protocols: "distance" (success as soon as the agent is inside the success region after a step;
STOP only consumes a step) and "explicit_stop" (STOP ends the episode; success only when issued
inside the region). Either way the episode ends after its step budget (max_steps).
"""
from __future__ import annotations

import math
import reprlib
from dataclasses import dataclass, field, fields

import numpy as np

from navcore.eval.episode import Episode
from navcore.nav.actions import MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT, ActionSpace
from navcore.nav.dynamics import BLOCKED_MODES, blocked_motion
from navcore.nav.oracle import geodesic_potential
from navcore.nav.poses import goal_in_robot_frame, wrap_angle

PROTOCOLS = ("distance", "explicit_stop")
MAX_WAYPOINTS = 64
"""Most relative poses one waypoint action may carry."""
MAX_DT = 10.0
"""Longest duration of one velocity command, seconds."""


_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxdict, _REPR.maxlist, _REPR.maxtuple, _REPR.maxstring, _REPR.maxother = 2, 4, 4, 4, 40, 40


def brief(v) -> str:
    """A bounded repr of a value from an agent (a hostile one may be huge or deeply nested)."""
    return _REPR.repr(v)


def _finite(d: dict, key: str, default: float | None) -> float:
    """d[key] (or the default) as a finite float; a ValueError names the key otherwise."""
    if key not in d and default is None:
        raise ValueError(f"action has no {key!r}")
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
        raise ValueError(f"action field {key!r} must be a finite number, got {brief(v)}")
    return float(v)


def _relative_pose(w) -> tuple[float, float, float]:
    if not isinstance(w, dict):
        raise ValueError(f"a waypoint is a map {{x, y, yaw}}, got {brief(w)}")
    return _finite(w, "x", 0.0), _finite(w, "y", 0.0), _finite(w, "yaw", 0.0)


def decode_action(action, actions: ActionSpace) -> tuple[bool, list[tuple[float, float, float]]]:
    """(stop?, relative moves [(dx, dy, dyaw)]) of an action in any accepted form; a ValueError
    names what is wrong with a malformed or non-finite one."""
    if isinstance(action, dict):
        if action.get("stop"):
            return True, []
        if "waypoints" in action:
            wps = action["waypoints"]
            if not isinstance(wps, (list, tuple)) or not 1 <= len(wps) <= MAX_WAYPOINTS:
                raise ValueError(f"waypoints must be a list of 1 to {MAX_WAYPOINTS} poses, got {brief(wps)}")
            return False, [_relative_pose(w) for w in wps]
        if "v" in action:
            v, w, dt = (_finite(action, k, d) for k, d in (("v", None), ("w", 0.0), ("dt", 0.05)))
            if not 0.0 < dt <= MAX_DT:
                raise ValueError(f"velocity action dt must be in (0, {MAX_DT}] s, got {dt}")
            return False, [(v * dt, 0.0, w * dt)]
        if {"x", "y", "yaw"} & set(action):  # one flat waypoint (navarena-server's random agent)
            return False, [_relative_pose(action)]
        raise ValueError(f"unknown action {brief(action)}: expected stop, waypoints, x/y/yaw or v/w/dt")
    if isinstance(action, bool) or not isinstance(action, (int, np.integer)):
        raise ValueError(f"unknown action {brief(action)}: a discrete action is an integer 0..3")
    a = int(action)
    if a == STOP:
        return True, []
    if a == MOVE_FORWARD:
        return False, [(actions.forward_step, 0.0, 0.0)]
    if a in (TURN_LEFT, TURN_RIGHT):
        return False, [(0.0, 0.0, actions.turn if a == TURN_LEFT else -actions.turn)]
    raise ValueError(f"unknown discrete action {a} (0 stop, 1 forward, 2 left, 3 right)")


@dataclass
class DynamicsConfig:
    """What the environment does with a blocked translation (navcore.nav.dynamics)."""

    blocked: str = "truncate"
    """truncate (to the last collision-free pose along the swept path) | stay (the pose stays: the
    paper's evaluator and NavArena before this option) | slide (along the obstacle's tangent, as
    habitat-sim's allow_sliding). The collision is counted and the heading change applied in every mode."""
    tolerance: float = 0.005
    """Metres: how close truncate and slide come to the first colliding pose."""


@dataclass
class EnvSettings:
    """The environment's rules and sensors that a run chooses (also fields of EvaluateConfig)."""

    protocol: str = "distance"
    """distance | explicit_stop (see the module docstring)."""
    width: int | None = None
    """Image width, pixels (null = the embodiment's)."""
    height: int | None = None
    """Image height, pixels (null = the embodiment's)."""
    render: bool = True
    """Render RGB-D observations (false: pose and goal only, for metric-only runs)."""
    dynamics: DynamicsConfig = field(default_factory=DynamicsConfig)
    """Blocked moves (evaluate.dynamics.blocked=truncate|stay|slide)."""


@dataclass
class EnvConfig(EnvSettings):
    """EnvSettings plus the dataset's action space (the evaluate stage takes episodes.actions)."""

    actions: ActionSpace = field(default_factory=ActionSpace)

    @classmethod
    def of(cls, settings: EnvSettings, actions: ActionSpace) -> "EnvConfig":
        return cls(**{f.name: getattr(settings, f.name) for f in fields(EnvSettings)}, actions=actions)


class SceneContext:
    """What every environment of one scene shares: costmap, navigation graph, renderer, fields."""

    def __init__(self, costmap, graph, emb, gaussians=None, backend: str = "auto"):
        self.costmap, self.graph, self.emb = costmap, graph, emb
        self.renderer = None
        if gaussians is not None:
            from navcore.render import Renderer

            self.renderer = Renderer(gaussians, backend)
        self._fields: dict[str, object] = {}
        self.max_fields = 256

    @classmethod
    def from_catalog(cls, catalog, scene, emb, components: str, min_island_area_m2: float, neighbourhood: int,
                     render: bool = True, renderer: str = "auto") -> "SceneContext":
        """A data root's scene as every evaluation sees it: the stored costmap of the embodiment, the
        geodesic graph over the cells its episodes may use (navcore.nav.geodesic.eligible_cells, with
        the episodes config's `components` and `min_island_area_m2`) and, with render, the aligned
        scene less the splats the costmap hid from the camera, on `renderer` (auto | cpu | gsplat).
        The one constructor both the pipeline's evaluate stage and NavDataset use."""
        from types import SimpleNamespace

        from navcore.gaussians.content import camera_scene
        from navcore.nav.geodesic import NavGraph, eligible_cells

        cm = catalog.dataset("costmaps", scene).load(emb.name)
        rules = SimpleNamespace(components=components, min_island_area_m2=min_island_area_m2)
        graph = NavGraph(cm, eligible_cells(cm, rules), neighbourhood)
        gs = camera_scene(catalog, scene, emb.name)[0] if render else None
        return cls(cm, graph, emb, gs, renderer)

    def field(self, ep: Episode):
        """Geodesic distance field to the episode's goal (set), cached per goal set (its goal_sources):
        a scene's episodes share a few (an ObjectNav category's instances, the goals PointNav and
        ImageNav episodes are drawn to), so a run computes one Dijkstra search per goal set, not one
        per episode."""
        src = np.asarray(ep.goal_sources)
        key = (src.shape, src.dtype.str, src.tobytes())  # the sources as stored: no rounding to cells for a hit
        if key in self._fields:
            self._fields[key] = self._fields.pop(key)  # most recently used last
        else:
            cells = self.costmap.cells_of(src)
            cells = cells[self.graph.index[cells[:, 0], cells[:, 1]] >= 0]
            if len(self._fields) >= self.max_fields:  # bounded: drop the least recently used
                self._fields.pop(next(iter(self._fields)))
            self._fields[key] = self.graph.field(cells)
        return self._fields[key]

    def render(self, poses: np.ndarray, width: int, height: int, on_device: bool = False):
        """RGB uint8 [B, H, W, 3] and depth float32 [B, H, W] at robot poses [B, 3]: numpy arrays,
        or (on_device) torch tensors left on the renderer's device for GPU-side policies."""
        import torch

        from navcore.render.camera import embodiment_camera

        vm, k, w, h = embodiment_camera(self.emb, poses, width, height)
        out = self.renderer.render(vm, k, w, h)
        rgb = (out.rgb * 255.0 + 0.5).clamp(0, 255).to(torch.uint8)
        if on_device:
            return rgb, out.depth
        return rgb.cpu().numpy(), out.depth.cpu().numpy().astype(np.float32)


class EpisodeState:
    """Book-keeping of one running episode (what the metrics read)."""

    def __init__(self, ep: Episode):
        self.ep = ep
        self.x, self.y, self.yaw = ep.start
        self.steps = 0
        self.moves = 0          # attempted translations
        self.collisions = 0     # rejected translations
        self.collided_actions = 0  # policy actions with at least one rejected translation
        self.invalid_actions = 0  # actions that could not be decoded (each consumed its step)
        self.action_error = ""    # the first of their messages
        self.path_length = 0.0
        self.positions = [(self.x, self.y)]
        self.ever_in_region = False  # inside the region after some action (the start never counts)
        self.stopped = False
        self.stop_in_region = False
        self.done = False
        self.success = False
        self.end_reason = ""
        self.field = None  # the goal set's distance field (SceneContext.field), looked up once

    @property
    def pose(self) -> np.ndarray:
        return np.array([self.x, self.y, self.yaw], np.float32)

    def fail(self) -> None:
        """End the episode as a failure of the agent (it raised, timed out or broke the protocol)."""
        self.done, self.success, self.end_reason = True, False, "agent_error"


class NavEnv:
    """One episode at a time: reset(episode) -> observation; step(action) -> (observation, info)."""

    def __init__(self, ctx: SceneContext, cfg: EnvConfig | None = None):
        self.ctx, self.cfg = ctx, cfg or EnvConfig()
        if self.cfg.protocol not in PROTOCOLS:
            raise ValueError(f"unknown protocol {self.cfg.protocol!r}; choose one of {PROTOCOLS}")
        if self.cfg.dynamics.blocked not in BLOCKED_MODES:
            raise ValueError(f"evaluate.dynamics.blocked={self.cfg.dynamics.blocked!r}; choose one of {BLOCKED_MODES}")
        self.w = int(self.cfg.width or ctx.emb.image_width)
        self.h = int(self.cfg.height or ctx.emb.image_height)
        self.turn = self.cfg.actions.turn
        self.state: EpisodeState | None = None
        self._goal_image = None

    # ---- API ---------------------------------------------------------------------------------
    def reset(self, ep: Episode) -> dict:
        self.state = EpisodeState(ep)
        self._goal_image = None
        if ep.task == "imagenav" and self.cfg.render and self.ctx.renderer is not None:
            self._goal_image = self.ctx.render(ep.shown_goal.goal_pose[None], self.w, self.h)[0][0]
        return self._observe()

    def step(self, action) -> tuple[dict, dict]:
        s = self.state
        if s is None or s.done:
            raise RuntimeError("step() after the episode ended; call reset(episode)")
        self.apply(action)
        obs = self._observe()
        return obs, self.info()

    # ---- pieces shared with the batched environment -------------------------------------------
    def apply(self, action) -> None:
        """Apply one action to the running episode (no rendering)."""
        s = self.state
        s.steps += 1
        try:
            stop, moves = self._decode(action)
        except ValueError as e:  # a refused action: its step is spent, nothing moves, the error is kept
            s.invalid_actions += 1
            s.action_error = s.action_error or f"step {s.steps}: {e}"
            stop, moves = False, []
        if stop:
            s.stopped = True
            s.stop_in_region = s.ep.in_region(s.x, s.y)
            if self.cfg.protocol == "explicit_stop":
                s.done, s.success, s.end_reason = True, s.stop_in_region, "stop"
        before = s.collisions
        for dx, dy, dyaw in moves:
            self._move(dx, dy, dyaw)
        s.collided_actions += s.collisions > before
        inside = s.ep.in_region(s.x, s.y)
        s.ever_in_region |= inside
        if not s.done and self.cfg.protocol == "distance" and inside:
            s.done, s.success, s.end_reason = True, True, "entered"
        if not s.done and s.steps >= s.ep.max_steps:
            s.done, s.end_reason = True, "budget"

    def info(self) -> dict:
        s = self.state
        return {"episode_id": s.ep.episode_id, "steps": s.steps, "collisions": s.collisions,
                "done": s.done, "success": s.success, "end_reason": s.end_reason,
                "distance_to_goal": self.geodesic_to_goal(), "pose": s.pose}

    def geodesic_to_goal(self) -> float:
        """Geodesic distance from the current pose to the goal (set), metres (every step's info asks:
        the episode keeps its goal set's field from the first call)."""
        s = self.state
        if s.field is None:
            s.field = self.ctx.field(s.ep)
        cm = self.ctx.costmap
        return float(geodesic_potential(s.field.grid, cm.origin[0], cm.origin[1], cm.resolution, s.x, s.y))

    def _decode(self, action) -> tuple[bool, list[tuple[float, float, float]]]:
        return decode_action(action, self.cfg.actions)

    def _move(self, dx: float, dy: float, dyaw: float) -> None:
        s = self.state
        if dx or dy:
            c, sn = math.cos(s.yaw), math.sin(s.yaw)
            nx, ny = s.x + c * dx - sn * dy, s.y + sn * dx + c * dy
            s.moves += 1
            if self.ctx.costmap.is_motion_valid(s.x, s.y, nx, ny):
                legs = [(nx, ny)]
            else:  # blocked: counted, and the translation goes where the dynamics say
                s.collisions += 1
                legs = blocked_motion(self.ctx.costmap, s.x, s.y, nx, ny, self.cfg.dynamics.blocked,
                                      self.cfg.dynamics.tolerance)
            for lx, ly in legs:
                s.path_length += math.hypot(lx - s.x, ly - s.y)
                s.x, s.y = float(lx), float(ly)
                s.positions.append((s.x, s.y))
        s.yaw = float(wrap_angle(s.yaw + dyaw))

    def goal_observation(self) -> dict:
        s = self.state
        ep = s.ep.shown_goal  # the goal the agent is shown (another episode's in the decoy check)
        if ep.task == "objectnav":
            return {"goal_category": ep.category}
        if ep.task == "imagenav":
            return {"goal_image": self._goal_image} if self._goal_image is not None else {}
        gx, gy = goal_in_robot_frame(s.x, s.y, s.yaw, ep.goal_xy)
        return {"pointgoal": np.array([math.hypot(gx, gy), math.atan2(gy, gx)], np.float32),
                "pointgoal_xy": np.array([gx, gy], np.float32)}

    def _observe(self) -> dict:
        obs = {"pose": self.state.pose, **self.goal_observation()}
        if self.cfg.render and self.ctx.renderer is not None:
            rgb, depth = self.ctx.render(self.state.pose[None].astype(np.float64), self.w, self.h)
            obs["rgb"], obs["depth"] = rgb[0], depth[0]
        return obs
