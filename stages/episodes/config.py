"""Configuration of the episodes stage: one TaskConfig per task (config group `task`), the shared
EpisodesConfig (section `episodes`) and the expert planner (config group `planner`)."""
from __future__ import annotations

from dataclasses import dataclass, field

from navcore.nav.actions import ActionSpace
from navcore.nav.tasks import OBJECTNAV_CATEGORIES


@dataclass
class TaskConfig:
    """One navigation task (conf/task/{name}.yaml; several may be selected: task=[pointnav,objectnav])."""

    type: str = "pointnav"
    """pointnav, imagenav or objectnav."""
    episodes_per_scene: int = 100
    """Episodes to generate per scene (a scene that cannot yield them is reported with reasons)."""
    min_geodesic: float = 1.0
    """Shortest allowed geodesic start-goal distance, metres."""
    max_geodesic: float = 30.0
    """Longest allowed geodesic start-goal distance, metres."""
    success_radius: float = 0.5
    """Success region radius around the goal (ObjectNav: around the nearest instance, see
    success_rule), metres. Paper defaults: PointNav 0.5, ImageNav and ObjectNav 1.0."""
    success_rule: str = "footprint"
    """ObjectNav: what success_radius is measured to: "footprint" (the instance's box on the floor,
    as habitat's ObjectNav measures to the object: a bed or sofa is reached at its side) or
    "centre" (the instance's centre, the paper's rule, for paper-exact evaluation). Each goal in
    goals_json records its rule and footprint; the evaluator and metrics follow the stored rule."""
    heading_tolerance_deg: float = 30.0
    """ImageNav: the expert ends within this heading of the goal yaw (Pose SR criterion), degrees."""
    trivial_ratio: float = 1.1
    """Habitat's rule against near-straight episodes: a pair with geodesic / euclidean below this is
    kept only with probability 20 (r - 0.98)^2 (PointNav and ImageNav; 0 disables)."""
    goal_view_min_depth: float = 1.5
    """ImageNav: the goal camera must look at least this far (metres): the median free distance of
    9 rays across its horizontal field of view, cast on the costmap's obstacle layer. A goal yaw
    facing a wall at arm's length gives an image of one surface that no agent can place; up to
    `goal_view_tries` yaws are drawn, and a goal position where none passes is dropped
    (`goal_view_blocked`). 0 disables."""
    goal_view_tries: int = 8
    """ImageNav: yaws drawn per goal position for `goal_view_min_depth`."""
    starts_per_goal: int = 10
    """Episodes drawn from one goal's distance field (one Dijkstra serves them all)."""
    categories: list[str] = field(default_factory=lambda: list(OBJECTNAV_CATEGORIES))
    """ObjectNav: the categories that may be goals."""
    instance_source: str = "model_predicted"
    """ObjectNav: where instances come from: 'model_predicted' (the semantics stage's instance
    table, the default) or 'ground_truth' (synthetic scenes' labels)."""
    view_point_spacing: float = 0.25
    """ObjectNav: view points are free cells on a lattice of this spacing within the success radius
    of an instance, metres."""
    view_point_margin: float = 0.15
    """ObjectNav: view points lie this far inside the success radius, metres (so that an agent
    moving in 0.25 m steps can stop inside the region, not only on its rim)."""
    max_view_points: int = 32
    """ObjectNav: at most this many view points per instance (spread around it)."""


@dataclass
class DifficultyConfig:
    """Difficulty bins by geodesic distance and their closed-loop step budgets."""

    names: list[str] = field(default_factory=lambda: ["easy", "medium", "hard"])
    """Bin names, in order of distance."""
    upper: list[float] = field(default_factory=lambda: [3.0, 6.0, 1e9])
    """Upper geodesic bound of each bin, metres (a bin is [previous upper, upper))."""
    max_steps: list[int] = field(default_factory=lambda: [500, 1000, 1500])
    """Step budget of each bin in closed-loop evaluation."""
    balance: bool = True
    """Draw starts so that the bins fill evenly (round robin over the bins a goal can reach)."""


@dataclass
class PlannerConfig:
    """The expert planner (conf/planner/{key}.yaml)."""

    name: str = "geodesic"
    """Registry key: geodesic (the episode's grid geodesic made taut, OMPL `fallback` when that
    fails), or an OMPL planner for every episode: rrtconnect (feasible, fast), rrtstar,
    informed_rrtstar, bitstar (asymptotically optimal)."""
    merge_turn_deg: float = 60.0
    """geodesic: two consecutive turns the same way that add up to less than this become one corner
    (outside the bend, when valid): the rollout stops and turns at every vertex (0 = keep the taut path)."""
    fallback: str = "rrtconnect"
    """geodesic: the OMPL planner of an episode whose taut geodesic fails the motion test."""
    max_iterations: int = 20000
    """Termination: planner loop iterations per query (deterministic, unlike a time budget)."""
    range: float = 0.0
    """Tree extension step, metres (0 = OMPL's default from the space extent)."""
    cost_tolerance: float = 0.02
    """Asymptotically optimal planners stop once the path is within this fraction of the geodesic."""
    simplify: bool = True
    """Shorten the path with OMPL's PathSimplifier (vertex reduction, rope shortcutting)."""
    resample_step: float = 0.1
    """Shortening (geodesic's string pulling, OMPL's second shortcut pass): the path is resampled at
    this spacing before shortcuts, so that its corners can move up to the obstacles, metres."""
    attempts: int = 3
    """Plan up to this many times while the path is longer than retry_ratio x the geodesic; keep
    the shortest (a feasible planner may pick a long way round an obstacle)."""
    retry_ratio: float = 1.05
    """See attempts."""


@dataclass
class EpisodesConfig:
    """The episodes stage."""

    seed: int = 0
    """Base seed; each (scene, task) derives its own stream from it."""
    splits: dict[str, float] = field(default_factory=lambda: {"train": 1.0})
    """Share of each scene's episodes per split (train, val_seen, val_unseen, test), in order."""
    scene_splits: dict[str, float] = field(default_factory=lambda: {"val_unseen": 0.05, "test": 0.05})
    """Shares of whole scenes held out into one split ({} holds none out); a scene is assigned by a
    hash of its id (stable as the scene set grows), and all its episodes get that split. Other
    scenes use `splits`. The default holds 5 % of the scenes out for validation and 5 % for the
    test split, from which the release draws its zero-shot evaluation set (release.eval_set: as
    the paper, on scenes never seen in training); of the four default scenes, one is val_unseen
    and one test."""
    components: str = "largest"
    """Free components episodes may use: 'largest' (the main one) or 'all' (every component of at
    least min_island_area_m2; start and goal always share one)."""
    min_island_area_m2: float = 2.0
    """Smallest free component that may hold episodes, m^2."""
    geodesic_neighbourhood: int = 6
    """Radius R (cells) of the any-angle grid graph for geodesics; R = 6 overstates a straight
    distance by at most 0.34 % (1 = 8-connected: 8.2 %)."""
    dt: float = 0.05
    """Expert rollout time step, seconds (20 Hz)."""
    actions: ActionSpace = field(default_factory=ActionSpace)
    """Step sizes of the discrete actions (the oracle's stored actions; evaluate uses the same)."""
    oracle: bool = True
    """Also store the discrete-action expert's action sequence per episode."""
    max_attempts_factor: int = 20
    """A task stops sampling after episodes_per_scene times this many candidates."""
    view_near_m: float = 0.5
    """Blind views (stages/episodes/views.py): a start pose, and an ImageNav goal pose, whose
    camera has more than half its image covered by Gaussians nearer than this (metres) and nearer
    than the costmap's obstacles in its field of view (a floater or blur in free space) is
    redrawn; 0 disables."""
    view_tries: int = 2
    """Start yaws drawn per start position for `view_near_m`; a position where none passes is
    dropped (`start_view_blind`). On the real room a fifth of the first yaws are blind; a second
    yaw rescues a fifth of those, two more another seventh, while 60 % are blind all round (inside
    a floater): each further try costs one more test there."""
    difficulty: DifficultyConfig = field(default_factory=DifficultyConfig)
