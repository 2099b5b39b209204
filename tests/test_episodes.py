"""Episodes: geodesics, samplers, OMPL experts, rollouts, the validity filter, storage, exports."""
import gzip
import json
import math

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from benchmarks.gpu.render_gpu import psnr
from navcore.gaussians.content import without_splats
from navcore.gaussians.model import GaussianScene
from navcore.io.datasets import AlignedGaussianDataset, CostmapDataset, GaussianDataset
from navcore.nav.actions import MOVE_FORWARD, STOP
from navcore.nav.embodiment import Embodiment, Limits
from navcore.nav.geodesic import NavGraph, max_detour
from navcore.nav.oracle import discrete_expert
from navcore.nav.poses import in_region, integrate, object_regions, point_regions, region_distance, relative_waypoints
from stages.episodes.config import EpisodesConfig, PlannerConfig, TaskConfig
from stages.episodes.generate import EpisodeGenerator, habitat_keep_probability, scene_split, split_names
from stages.episodes.planner import ScenePlanner, seed_ompl
from stages.episodes.rollout import rollout, speed_profile
from stages.episodes.validity import check_trajectory

LIMITS = Limits(0.45, 0.8, 0.25, 0.6)


def cell_of(cm, x, y):
    return np.array([int(y / cm.resolution), int(x / cm.resolution)])


def test_geodesic_open_space_is_euclidean_within_the_neighbourhood_bound(grid_costmap):
    free = np.ones((60, 80), bool)
    free[[0, -1], :] = free[:, [0, -1]] = False
    cm = grid_costmap(free)
    g = NavGraph(cm, ~cm.occupancy)
    src = cell_of(cm, 0.5, 0.5)
    f = g.field(src[None])
    pts = g.cells[::37]
    d = f.at_cells(pts)
    e = np.hypot(*(cm.cell_centers(pts) - cm.cell_centers(src[None])).T)
    assert (d >= e - 1e-9).all() and (d <= e * max_detour(6) + 1e-9).all()
    # an 8-connected graph overstates diagonals (the reason for the any-angle neighbourhood)
    d8 = NavGraph(cm, ~cm.occupancy, radius=1).field(src[None]).at_cells(pts)
    assert (d8 / np.maximum(e, 1e-9)).max() > 1.05


def test_geodesic_through_a_door_matches_the_lower_bound(room_with_door, grid_costmap):
    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    a, b = np.array([1.0, 0.5]), np.array([3.0, 0.5])
    f = g.field(cell_of(cm, *b)[None])
    d = f.at_cells(cell_of(cm, *a)[None])[0]
    ca, cb = cm.cell_centers(np.array([cell_of(cm, *a), cell_of(cm, *b)]))
    # the exact continuous answer: the wall's cells dilated by cm.radius form a convex capsule; the
    # taut path from a to b runs tangent to the disc of its top cell (2.025, 1.975), over the arc,
    # and tangent down to b
    c = np.array([2.025, 1.975])
    da, db = np.hypot(*(ca - c)), np.hypot(*(cb - c))
    ta, tb = math.atan2(*(ca - c)[::-1]), math.atan2(*(cb - c)[::-1])
    arc = 2 * math.pi - (tb - ta) - math.acos(cm.radius / da) - math.acos(cm.radius / db)
    exact = math.sqrt(da**2 - cm.radius**2) + math.sqrt(db**2 - cm.radius**2) + cm.radius * arc
    assert exact <= d <= exact * 1.01
    # the field's path is a chain of valid straight motions whose length is the distance
    path = f.path_xy(cell_of(cm, *a))
    assert cm.are_motions_valid(np.concatenate([path[:-1], path[1:]], 1)).all()
    assert np.hypot(*np.diff(path, axis=0).T).sum() == pytest.approx(d, rel=1e-9)
    # the other room is unreachable without the door
    free = cm.clearance > 0
    free[:, 40] = False
    g2 = NavGraph(grid_costmap(free), ~grid_costmap(free).occupancy)
    assert np.isinf(g2.field(cell_of(cm, *b)[None]).at_cells(cell_of(cm, *a)[None])[0])


def test_multi_source_field_is_the_minimum_of_single_fields(room_with_door):
    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    srcs = np.array([cell_of(cm, 1.0, 1.0), cell_of(cm, 3.5, 2.5)])
    multi = g.field(srcs).node_dist
    single = np.minimum(g.field(srcs[:1]).node_dist, g.field(srcs[1:]).node_dist)
    assert np.allclose(multi, single)


@pytest.mark.parametrize("total", [0.01, 0.1, 0.24, 0.5, 1.0, 3.7, 12.0])
def test_speed_profile_covers_the_distance_within_limits(total):
    v = speed_profile(total, 0.45, 0.25, 0.05)
    assert v.sum() * 0.05 == pytest.approx(total, rel=1e-12)
    assert v.max() <= 0.45 + 1e-12
    assert (np.abs(np.diff(np.concatenate([[0], v, [0]]))) <= 0.25 * 0.05 + 1e-12).all()
    # the fewest steps: one step less cannot cover the distance
    n = len(v) - 1
    k = np.arange(1, n + 1)
    assert np.minimum(0.45, 0.25 * 0.05 * np.minimum(k, n + 1 - k)).sum() * 0.05 < total


def test_rollout_follows_the_path_and_passes_the_filter(room_with_door):
    cm = room_with_door
    path = np.array([[1.0, 0.5], [1.85, 2.1], [2.2, 2.1], [3.0, 0.5]])
    ro = rollout(path, 0.3, 1.0, LIMITS, 0.05)
    assert ro["x"][-1] == pytest.approx(3.0) and ro["y"][-1] == pytest.approx(0.5)
    assert ro["yaw"][-1] == pytest.approx(1.0)
    # rotation and translation never mix, and (v, omega) reproduce the poses
    assert not ((ro["v"] != 0) & (ro["w"] != 0)).any()
    x, y, yaw = integrate(1.0, 0.5, 0.3, ro["v"][:-1], ro["w"][:-1], 0.05)
    assert np.allclose(x, ro["x"]) and np.allclose(yaw, ro["yaw"])
    # relative waypoints compose back into the trajectory
    dx, dy, dyaw = relative_waypoints(ro["x"], ro["y"], ro["yaw"])
    c, s = np.cos(ro["yaw"]), np.sin(ro["yaw"])
    assert np.allclose(ro["x"][:-1] + (c * dx - s * dy)[:-1], ro["x"][1:])
    goal = lambda px, py: math.hypot(px - 3.0, py - 0.5) <= 0.5  # noqa: E731
    args = (cm, cm.radius, LIMITS, 0.05, goal)
    assert check_trajectory(ro["x"], ro["y"], ro["yaw"], ro["v"], ro["w"], *args) is None
    # each corruption is caught with its reason
    bad = {k: v.copy() for k, v in ro.items()}
    bad["x"][len(bad["x"]) // 2] += 0.03
    assert check_trajectory(bad["x"], bad["y"], bad["yaw"], bad["v"], bad["w"], *args) in ("speed", "acceleration")
    fast = rollout(path, 0.3, None, Limits(0.9, 0.8, 0.25, 0.6), 0.05)
    assert check_trajectory(fast["x"], fast["y"], fast["yaw"], fast["v"], fast["w"], *args) == "speed"
    jerk = rollout(path, 0.3, None, Limits(0.45, 0.8, 2.0, 0.6), 0.05)
    assert check_trajectory(jerk["x"], jerk["y"], jerk["yaw"], jerk["v"], jerk["w"], *args) == "acceleration"
    spin = rollout(path, 0.3, None, Limits(0.45, 3.0, 0.25, 20.0), 0.05)
    assert check_trajectory(spin["x"], spin["y"], spin["yaw"], spin["v"], spin["w"], *args) == "heading"
    through_wall = rollout(np.array([[1.0, 0.5], [3.0, 0.5]]), 0.0, None, LIMITS, 0.05)
    assert check_trajectory(through_wall["x"], through_wall["y"], through_wall["yaw"], through_wall["v"],
                            through_wall["w"], *args) == "clearance"
    short = rollout(path[:3], 0.3, None, LIMITS, 0.05)
    assert check_trajectory(short["x"], short["y"], short["yaw"], short["v"], short["w"], *args) == "goal"
    lying = {k: v.copy() for k, v in ro.items()}
    lying["w"][5] *= 1.5
    assert check_trajectory(lying["x"], lying["y"], lying["yaw"], lying["v"], lying["w"], *args) == "controls"


def test_ompl_expert_is_valid_deterministic_and_near_the_geodesic(room_with_door):
    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    a, b = cm.cell_centers(np.array([cell_of(cm, 1.0, 0.5), cell_of(cm, 3.0, 0.5)]))
    geo = g.field(cell_of(cm, 3.0, 0.5)[None]).at_cells(cell_of(cm, 1.0, 0.5)[None])[0]
    paths = []
    for name in ("rrtconnect", "rrtstar"):
        for _ in range(2):
            seed_ompl(7)
            p = ScenePlanner(cm, PlannerConfig(name=name)).plan((a[0], a[1], 0.0), [(b[0], b[1], 0.0)], geo)
            assert p is not None and np.allclose(p[0, :2], a) and np.allclose(p[-1, :2], b)
            assert cm.are_motions_valid(np.concatenate([p[:-1, :2], p[1:, :2]], 1)).all()
            length = np.hypot(*np.diff(p[:, :2], axis=0).T).sum()
            assert geo / max_detour(6) <= length <= geo * 1.25
            paths.append(p)
        assert np.array_equal(paths[-1], paths[-2])  # same seed, same path
    with pytest.raises(ValueError, match="unknown planner"):
        ScenePlanner(cm, PlannerConfig(name="nope"))


def test_geodesic_expert_is_taut_valid_and_falls_back_to_ompl(room_with_door):
    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    a, b = cm.cell_centers(np.array([cell_of(cm, 1.0, 0.5), cell_of(cm, 3.0, 0.5)]))
    f = g.field(cell_of(cm, 3.0, 0.5)[None])
    seed = f.path_xy(cell_of(cm, 1.0, 0.5))
    geo = f.at_cells(cell_of(cm, 1.0, 0.5)[None])[0]
    seed_ompl(7)
    planner = ScenePlanner(cm, PlannerConfig(name="geodesic", merge_turn_deg=0.0))  # the taut path itself
    p = planner.plan((a[0], a[1], 0.0), [(b[0], b[1], 0.0)], geo, seed)
    assert planner.fallbacks == 0 and np.allclose(p[0], a) and np.allclose(p[-1], b)
    assert cm.are_motions_valid(np.concatenate([p[:-1], p[1:]], 1)).all()
    # the same exact continuous shortest path as the geodesic test: tangent, arc over the wall's
    # top, tangent (here between the two cell centres)
    c = np.array([2.025, 1.975])
    da, db = np.hypot(*(a - c)), np.hypot(*(b - c))
    ta, tb = math.atan2(*(a - c)[::-1]), math.atan2(*(b - c)[::-1])
    arc = 2 * math.pi - (tb - ta) - math.acos(cm.radius / da) - math.acos(cm.radius / db)
    exact = math.sqrt(da**2 - cm.radius**2) + math.sqrt(db**2 - cm.radius**2) + cm.radius * arc
    length = np.hypot(*np.diff(p, axis=0).T).sum()
    assert exact * (1 - 1e-3) <= length <= min(geo, exact * 1.005)  # tauter than the grid's path
    # merged corners: fewer stops for the turn-then-drive rollout, still valid, barely longer
    merged = ScenePlanner(cm, PlannerConfig(name="geodesic")).plan((a[0], a[1], 0.0), [(b[0], b[1], 0.0)], geo, seed)
    assert len(merged) < len(p) and cm.are_motions_valid(np.concatenate([merged[:-1], merged[1:]], 1)).all()
    assert length <= np.hypot(*np.diff(merged, axis=0).T).sum() <= length * 1.05
    # in line of sight the path is the straight segment
    c1, c2 = cm.cell_centers(np.array([cell_of(cm, 0.5, 0.5), cell_of(cm, 1.5, 2.5)]))
    straight = g.field(cell_of(cm, 1.5, 2.5)[None]).path_xy(cell_of(cm, 0.5, 0.5))
    assert np.array_equal(planner.plan((*c1, 0.0), [(*c2, 0.0)], None, straight), np.array([c1, c2]))
    # a seed through the wall is not trusted: OMPL (the fallback) plans, and says so
    through = np.array([a, b])
    q = planner.plan((a[0], a[1], 0.0), [(b[0], b[1], 0.0)], geo, through)
    assert planner.fallbacks == 1 and q is not None and np.allclose(q[-1], b)
    assert cm.are_motions_valid(np.concatenate([q[:-1], q[1:]], 1)).all()
    with pytest.raises(ValueError, match="fallback must be an OMPL planner"):
        ScenePlanner(cm, PlannerConfig(name="geodesic", fallback="geodesic"))


def test_discrete_expert_reaches_the_goal_through_the_door(room_with_door):
    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    goal = np.array([3.0, 0.5])
    f = g.field(cell_of(cm, *goal)[None])
    acts = discrete_expert(f.grid, cm, (1.0, 0.5, 0.0), point_regions(goal[None]), 0.5)
    assert acts is not None and acts[-1] == STOP and (acts[:-1] != STOP).all()
    # replaying the actions never collides and ends inside the region
    x, y, yaw = 1.0, 0.5, 0.0
    for a in acts[:-1]:
        if a == MOVE_FORWARD:
            nx_, ny_ = x + 0.25 * math.cos(yaw), y + 0.25 * math.sin(yaw)
            assert cm.is_motion_valid(x, y, nx_, ny_)
            x, y = nx_, ny_
        else:
            yaw += math.radians(15) * (1 if a == 2 else -1)
    assert math.hypot(x - goal[0], y - goal[1]) <= 0.5
    # forward steps: at least the geodesic minus the radius, in 0.25 m steps, and not far more
    d = f.at_cells(cell_of(cm, 1.0, 0.5)[None])[0]
    n_fwd = int((acts == MOVE_FORWARD).sum())
    assert (d - 0.5) / 0.25 <= n_fwd <= (d - 0.5) / 0.25 * 1.3 + 2
    # ImageNav: turns to the goal heading before stopping
    acts2 = discrete_expert(f.grid, cm, (1.0, 0.5, 0.0), point_regions(goal[None]), 0.5, goal_yaw=math.pi)
    yaw = sum(math.radians(15) * (1 if a == 2 else -1 if a == 3 else 0) for a in acts2)
    assert abs((yaw - math.pi + math.pi) % (2 * math.pi) - math.pi) <= math.radians(15) + 1e-9


def test_sampling_rules():
    assert habitat_keep_probability(np.array([1.0]), 1.1)[0] == pytest.approx(20 * 0.02 ** 2)
    assert habitat_keep_probability(np.array([1.1, 1.5]), 1.1).tolist() == [1.0, 1.0]
    assert habitat_keep_probability(np.array([1.0]), 0.0)[0] == 1.0
    s = split_names(10, {"train": 0.8, "val_seen": 0.2})
    assert s.count("train") == 8 and s.count("val_seen") == 2 and s[-1] == "val_seen"
    # whole scenes held out by share, stable per scene id
    ids = [f"{i:08x}" for i in range(2000)]
    held = [scene_split(i, {"val_unseen": 0.1, "test": 0.05}) for i in ids]
    assert abs(held.count("val_unseen") / 2000 - 0.1) < 0.025 and abs(held.count("test") / 2000 - 0.05) < 0.02
    assert held == [scene_split(i, {"val_unseen": 0.1, "test": 0.05}) for i in ids]
    assert scene_split(ids[0], {}) is None


@pytest.mark.parametrize("task", ["pointnav", "imagenav", "objectnav"])
def test_generator_yields_valid_balanced_episodes(task, room_with_door):
    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    ecfg = EpisodesConfig()
    ecfg.difficulty.upper = [2.0, 3.0, 1e9]
    tcfg = TaskConfig(type=task, episodes_per_scene=24, success_radius=0.5 if task == "pointnav" else 1.0)
    inst = [{"instance_id": 4, "category": "chair", "center_x": 3.5, "center_y": 2.5, "center_z": 0.4,
             "min_x": 3.3, "min_y": 2.3, "min_z": 0.0, "max_x": 3.7, "max_y": 2.7, "max_z": 0.8}]
    gen = EpisodeGenerator(cm, g, tcfg, ecfg, PlannerConfig(), Embodiment(radius=cm.radius), "t/scene", 3, inst)
    res = gen.generate()
    assert len(res.episodes) == 24
    diff = [e["difficulty"] for e in res.episodes]
    assert {diff.count(n) for n in ("easy", "medium", "hard")} == {8}
    centres = np.array([[e["goal_position_x"], e["goal_position_y"]] for e in res.episodes]) if task != "objectnav" \
        else np.array([[3.5, 2.5]] * len(res.episodes))
    starts = np.array([[e["start_position_x"], e["start_position_y"]] for e in res.episodes])
    assert (np.hypot(*(starts - centres).T) > tcfg.success_radius).all()  # no start inside its own region
    for e in res.episodes:
        assert 1.0 <= e["geodesic_distance"] <= 30.0 + 1e-6
        assert e["geodesic_distance"] <= e["path_length"] + 1e-6
        assert e["oracle_actions"][-1] == STOP
        if task == "objectnav":
            assert e["goal_object_id"] == 4 and e["goal_object_category"] == "chair"
            goal = json.loads(e["goals_json"])[0]
            assert goal["success_rule"] == "footprint" and goal["footprint"] == {"min": [3.3, 2.3], "max": [3.7, 2.7]}
            vp = np.array([p["position"][:2] for p in goal["view_points"]])  # within the radius of the footprint
            assert (region_distance(vp, np.array([[3.3, 2.3, 3.7, 2.7]])) <= 1.0 - tcfg.view_point_margin + 1e-9).all()
    # same seed, same episodes
    again = EpisodeGenerator(cm, g, tcfg, ecfg, PlannerConfig(), Embodiment(radius=cm.radius), "t/scene", 3, inst)
    assert [e["start_position_x"] for e in again.generate().episodes] == [e["start_position_x"] for e in res.episodes]


# ---- the stage on a generated scene: storage, re-check, determinism, exports ---------------------

def test_every_goal_category_a_generated_scene_holds_gets_objectnav_episodes(episode_run):
    """The new world's furniture and clutter leave every goal object reachable as a goal: each
    category among the scene's ground-truth objects has ObjectNav episodes (the default dataset's
    4 scenes: all 8 categories)."""
    from stages.synthesize.generate import load_ground_truth

    root, _, summary = episode_run
    obj = pd.read_parquet(root / "05_episodes", filters=[("task", "==", "objectnav")])
    names = {r["scene_id"]: r["scene"] for r in summary["results"] if r["stage"] == "synthesize"}
    for sid, name in names.items():
        gt = load_ground_truth(root / "00_sources" / "synthetic" / name)
        held = {o["category"] for o in gt["objects"]}
        got = set(obj.loc[obj["scene_id"] == sid, "goal_object_category"])
        assert held and held <= got, (name, sorted(held - got))


def test_stored_episodes_query_with_pandas_and_pass_the_recheck(episode_run):
    root, _, summary = episode_run
    eps = pd.read_parquet(root / "05_episodes")
    assert set(eps["task"]) == {"pointnav", "imagenav", "objectnav"}
    obj = pd.read_parquet(root / "05_episodes", filters=[("task", "==", "objectnav")])
    assert len(obj) and (obj["goal_type"] == "object").all()
    trajs = pd.read_parquet(root / "06_trajectories")
    sid = obj["scene_id"].iloc[0]
    cm = CostmapDataset(root / "03_costmaps" / f"{sid}.zarr").load("locobot")
    emb = Embodiment()
    for (task, eid), t in trajs.groupby(["task", "episode_id"], observed=True):
        e = eps[(eps["task"] == task) & (eps["episode_id"] == eid)].iloc[0]
        t = t.sort_values("step")
        assert len(t) == e["num_steps"] and t["step"].tolist() == list(range(len(t)))
        centres = np.array([[e["goal_position_x"], e["goal_position_y"]]])
        r = float(e["success_radius"])
        regions = object_regions(json.loads(e["goals_json"])) if task == "objectnav" else point_regions(centres)
        success = lambda x, y: bool(region_distance([[x, y]], regions)[0] <= r + 1e-9)  # noqa: E731
        assert not success(e["start_position_x"], e["start_position_y"]), (task, eid)  # no trivial episode
        why = check_trajectory(t["position_x"].to_numpy(), t["position_y"].to_numpy(), t["yaw"].to_numpy(),
                               t["linear_velocity"].to_numpy(np.float64), t["angular_velocity"].to_numpy(np.float64),
                               cm, emb.radius, Limits.of(emb), 0.05, success,
                               e["goal_yaw"] if task == "imagenav" else None,
                               e["heading_tolerance"] if task == "imagenav" else None)
        assert why is None, (task, eid, why)
        assert e["geodesic_distance"] <= e["path_length"] * (1 + 1e-6)
    # splits by share, ids per split
    pn = eps[eps["task"] == "pointnav"]
    assert (pn["split"] == "train").sum() == round(0.75 * len(pn))
    assert all(eid.startswith(f"{sp}_") for eid, sp in zip(pn["episode_id"], pn["split"]))
    assert summary["results"][-1]["stage"] == "export:finalize"


def test_episode_shards_are_byte_identical_on_rerun_with_workers(episode_run, tmp_path, make_cfg, copy_data_root):
    from pipeline.executor import execute

    root, over, _ = episode_run
    # the finished root less the episodes and what follows them: only the episodes stage runs again
    # (the upstream stages' bytes across worker counts: test_pipeline's test_same_config_same_bytes...)
    copy_data_root(root, tmp_path, "05_episodes", "06_trajectories", "07_eval", "09_assets", "10_exports", "episodes",
                   "objectnav_episodes", "goal_images", "asset", "export*")
    s = execute(make_cfg(tmp_path, *over[:-1], "stages=[episodes]", "executor=local", "executor.n_workers=2",
                         "executor.dashboard=false"))
    status = {r["stage"]: r["status"] for r in s["results"]}
    # stages=[episodes] names both episode stages (PointNav and ImageNav; ObjectNav after semantics)
    assert not s["failures"] and status["episodes"] == status["objectnav_episodes"] == "done"
    assert {r["status"] for r in s["results"] if "episodes" not in r["stage"]} == {"cached"}
    files = sorted(p.relative_to(root) for p in (root / "05_episodes").rglob("*.parquet"))
    files += sorted(p.relative_to(root) for p in (root / "06_trajectories").rglob("*.parquet"))
    assert len(files) == 6
    for f in files:
        assert (root / f).read_bytes() == (tmp_path / f).read_bytes(), f


def test_exports_read_back_equal_to_the_store(episode_run):
    from stages.export.stage import NAVARENA_EPISODE_COLUMNS, NAVARENA_TRAJECTORY_COLUMNS, habitat_position

    root, _, _ = episode_run
    eps = pd.read_parquet(root / "05_episodes")
    trajs = pd.read_parquet(root / "06_trajectories")
    base = next((root / "10_exports" / "navarena" / "navarena").glob("*/*"))
    sid = base.name
    meta = json.loads((base.parent.parent / "dataset_meta.json").read_text())
    assert meta["scene_ids"] == [sid] and set(meta["task_types"]) == {"pointnav", "imagenav", "objectnav"}
    for task in ("pointnav", "imagenav", "objectnav"):
        store = eps[(eps["task"] == task)].reset_index(drop=True)
        info = json.loads((base / task / "meta" / "info.json").read_text())
        assert info["num_episodes"] == len(store) and info["num_chunks"] == math.ceil(len(store) / 8)
        meta_eps = pq.read_table(base / task / "meta" / "episodes.parquet").to_pandas()
        assert list(meta_eps.columns) == NAVARENA_EPISODE_COLUMNS
        chunks = sorted((base / task / "data").iterdir())
        assert len(chunks) == info["num_chunks"]
        ep_chunks = pd.concat([pd.read_parquet(c / "episodes.parquet") for c in chunks], ignore_index=True)
        tr_chunks = pd.concat([pd.read_parquet(c / "trajectories.parquet") for c in chunks], ignore_index=True)
        assert list(tr_chunks.columns) == NAVARENA_TRAJECTORY_COLUMNS
        assert all(tr_chunks[c].dtype == np.float64 for c in ("timestamp", "position_x", "rotation_qw"))  # the spec's
        assert (ep_chunks.groupby("chunk_index").size() <= 8).all()
        for c in ("episode_id", "start_position_x", "goal_position_y", "geodesic_distance", "num_steps", "goals_json"):
            assert ep_chunks[c].tolist() == store[c].tolist() == meta_eps[c].tolist()
        st = trajs[trajs["task"] == task].reset_index(drop=True)
        for c in ("episode_id", "step", "position_x", "rotation_qw", "action_id", "linear_velocity"):
            assert tr_chunks[c].tolist() == st[c].tolist()
    # Habitat: y-up positions map back to ours, per split
    for task in ("pointnav", "objectnav"):
        store = eps[eps["task"] == task]
        n = 0
        for split in store["split"].unique():
            content = json.loads(gzip.decompress(
                (root / "10_exports" / "habitat" / f"{task}_v1" / split / "content" / f"{sid}.json.gz").read_bytes()))
            assert json.loads(gzip.decompress((root / "10_exports" / "habitat" / f"{task}_v1" / split /
                                               f"{split}.json.gz").read_bytes()))["episodes"] == []
            for he in content["episodes"]:
                e = store[store["episode_id"] == he["episode_id"]].iloc[0]
                assert he["start_position"] == pytest.approx(habitat_position(
                    e["start_position_x"], e["start_position_y"], e["start_position_z"]))
                assert he["info"]["geodesic_distance"] == pytest.approx(e["geodesic_distance"])
                if task == "pointnav":
                    assert he["goals"][0]["position"] == pytest.approx(habitat_position(
                        e["goal_position_x"], e["goal_position_y"], 0.0))
                else:
                    goals = content["goals_by_category"][f"{sid}_{he['object_category']}"]
                    assert he["info"]["closest_goal_object_id"] in {g["object_id"] for g in goals}
                    assert all(g["view_points"] for g in goals)
                n += 1
        assert n == len(store)


def test_goal_images_rendered_at_the_goal_camera_and_exported(episode_run, make_cfg):
    from PIL import Image

    from navcore.render import Renderer
    from navcore.render.camera import intrinsics, viewmats
    from pipeline.executor import execute

    root, over, _ = episode_run
    summary = execute(make_cfg(root, *over[:-1], "export.chunk_size=8", "goal_images.enabled=true",
                               "stages=[goal_images,export]"))  # named: its settings changed
    assert not summary["failures"], summary["failures"]
    eps = pd.read_parquet(root / "05_episodes", filters=[("task", "==", "imagenav")])
    sid = str(eps["scene_id"].iloc[0])
    gi = pq.read_table(root / "05_goal_images" / "task=imagenav" / f"scene_id={sid}" / "part-0.parquet").to_pandas()
    assert sorted(gi["episode_id"]) == sorted(eps["episode_id"])
    base = next((root / "10_exports" / "navarena" / "navarena").glob(f"*/{sid}")) / "imagenav"
    meta = pq.read_table(base / "meta" / "episodes.parquet").to_pandas()
    assert (meta["goal_image_path"] == "goal_images/" + meta["episode_id"] + "_goal.jpg").all()
    e = eps.iloc[0]
    img = np.asarray(Image.open(base / f"goal_images/{e['episode_id']}_goal.jpg")).astype(float) / 255
    cam = json.loads(e["goal_camera_json"])
    store = GaussianDataset(root / "01_scenes" / sid / "gaussians.zarr")
    gs, _ = AlignedGaussianDataset(root / "01_scenes" / sid / "alignment.json", store).load()
    # as the robot's camera sees the scene: less the hidden noise
    gs = without_splats(gs, CostmapDataset(root / "03_costmaps" / f"{sid}.zarr").hidden("locobot"))
    ref = Renderer(gs, "cpu").render(viewmats(np.array([[*cam["position"][:2], cam["yaw"]]]), cam["position"][2],
                                              cam["pitch_deg"]),
                                     intrinsics(cam["width"], cam["height"], cam["hfov_deg"])[None],
                                     cam["width"], cam["height"]).rgb[0].numpy()
    assert img.shape == (cam["height"], cam["width"], 3)
    assert psnr(img, ref) > 30  # the JPEG of that very view


def test_trajectories_are_stored_compact_and_lose_nothing_the_checks_need(episode_run):
    """float32 + BYTE_STREAM_SPLIT / delta encodings + binary-grid derived columns: the same rows
    written as before (float64, default encodings) take over 1.5 times the bytes (on the default
    dataset, before / after the whole change: 17.2 KB -> 5.8 KB an episode with its trajectory), and
    the derived columns still agree with the stored poses and controls to their quantum."""
    import io

    import pyarrow as pa

    from navcore.io.episode_schema import TRAJECTORY_QUANTA, TRAJECTORY_SCHEMA

    root = episode_run[0]
    files = sorted((root / "06_trajectories").glob("task=*/scene_id=*/part-0.parquet"))
    stored = plain = 0
    for f in files:
        meta = pq.ParquetFile(f).metadata
        enc = {meta.row_group(0).column(i).path_in_schema: meta.row_group(0).column(i).encodings
               for i in range(meta.num_columns)}
        assert "BYTE_STREAM_SPLIT" in enc["position_x"] and "DELTA_BINARY_PACKED" in enc["step"]
        t = pq.read_table(f)
        assert t.schema.equals(TRAJECTORY_SCHEMA, check_metadata=False)
        buf = io.BytesIO()  # what the same rows took before: float64 poses, default encodings
        pq.write_table(pa.table({c: pc_cast64(t[c]) for c in t.column_names}), buf, compression="zstd")
        stored, plain = stored + f.stat().st_size, plain + buf.tell()
        d = t.to_pandas()
        q = TRAJECTORY_QUANTA["rotation_qz"]
        assert np.abs(d["rotation_qz"] - np.sin(d["yaw"].astype(float) / 2)).max() <= q / 2 + 1e-6
        v = d["linear_velocity"].astype(float)
        assert np.abs(d["linear_velocity_x"] - v * np.cos(d["yaw"].astype(float))).max() <= q / 2 + 1e-6
        for c, step in TRAJECTORY_QUANTA.items():  # on the grid
            assert np.allclose(d[c] / step, np.round(d[c] / step), atol=1e-3), c
    assert stored < plain / 1.5, (stored, plain)


def pc_cast64(col):
    import pyarrow as pa

    return col.cast(pa.float64()) if pa.types.is_floating(col.type) else col


def test_no_start_inside_its_success_region_even_when_the_geodesic_range_allows_it(room_with_door):
    """ImageNav with a 1 m region and starts allowed from 0.2 m: every start near the goal is
    left out (without the rule most of these would start inside and score SR 1 with no step)."""
    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    ecfg = EpisodesConfig()
    ecfg.difficulty.balance = False
    tcfg = TaskConfig(type="imagenav", episodes_per_scene=30, success_radius=1.0, min_geodesic=0.2, max_geodesic=1.6,
                      trivial_ratio=0.0)
    gen = EpisodeGenerator(cm, g, tcfg, ecfg, PlannerConfig(), Embodiment(radius=cm.radius), "t/scene", 5)
    res = gen.generate()
    assert len(res.episodes) >= 10
    d = [math.hypot(e["start_position_x"] - e["goal_position_x"], e["start_position_y"] - e["goal_position_y"])
         for e in res.episodes]
    assert min(d) > 1.0


def test_view_depths_reach_the_first_wall(room_with_door):
    cm = room_with_door  # walls: x in [0, 0.05) and [2.0, 2.05) (door y in [2.0, 2.8)), x in [3.95, 4.0)
    d = cm.view_depths((1.0, 1.0), [0.0, math.pi])
    assert d[0] == pytest.approx(1.0, abs=0.06) and d[1] == pytest.approx(0.95, abs=0.06)
    through = cm.view_depths((1.0, 2.4), [0.0])[0]  # through the door to the far wall
    assert through == pytest.approx(2.95, abs=0.06)
    assert cm.view_depths((1.0, 2.4), [0.0], max_range=1.5)[0] == pytest.approx(1.5)
    diag = cm.view_depths((1.0, 1.0), [math.atan2(-1.0, 1.0)])[0]  # towards (2, 0): the corner, ~1.41 m
    assert diag == pytest.approx(math.sqrt(2) * 0.95, abs=0.1)
    # a camera's view: the median of 9 rays over 90 degrees, the pair at +-22.5 degrees
    assert cm.fov_depth((1.0, 1.0), 0.0, 90.0) == pytest.approx(1.0 / math.cos(math.radians(22.5)), abs=0.06)
    assert cm.fov_depth((1.0, 1.0), 0.0, 90.0, max_range=0.5) == pytest.approx(0.5)


def _view_depths_reference(cm, xy, angles, max_range):
    """view_depths as the array program it was before the numba kernel (2026-12-07): all rays
    stepped together, each stopped by a mask."""
    a = np.asarray(angles, float)
    o, dirs, res = np.asarray(xy, float)[None, :], np.column_stack([np.cos(a), np.sin(a)]), cm.resolution
    ny, nx = cm.clearance.shape
    d, alive = np.zeros(len(a)), np.ones(len(a), bool)
    for _ in range(int(max_range / res) + 2):
        p = o + d[:, None] * dirs
        ix = np.floor((p[:, 0] - cm.origin[0]) / res).astype(np.int64)
        iy = np.floor((p[:, 1] - cm.origin[1]) / res).astype(np.int64)
        inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        c = np.where(inside, cm.clearance[iy.clip(0, ny - 1), ix.clip(0, nx - 1)], 0.0)
        alive &= inside & ~((c >= 0) & (c < res))
        if not alive.any():
            break
        d = np.where(alive, np.minimum(d + np.maximum(c - res, res), max_range), d)
        alive &= d < max_range
    return d


def test_view_depths_equal_the_array_program_bit_for_bit(grid_costmap):
    """The per-ray kernel gives the depths of the array form it replaced, exactly (the searching
    expert's labels, and so the training data, stay the same bytes), on clutter, unsupported cells,
    rays leaving the map and both range limits."""
    rng = np.random.default_rng(3)
    free = rng.random((90, 120)) > 0.04
    free[[0, -1], :40] = False
    cm = grid_costmap(free)
    cm.clearance[rng.random(cm.clearance.shape) < 0.01] = -1.0  # no floor: not an obstacle to the eye
    ny, nx = cm.clearance.shape
    for max_range in (2.0, 10.0):
        for _ in range(200):
            xy = cm.origin + rng.uniform([-0.2, -0.2], [nx * cm.resolution + 0.2, ny * cm.resolution + 0.2])
            angles = rng.uniform(-np.pi, np.pi) + np.linspace(-0.7, 0.7, 31)
            assert np.array_equal(cm.view_depths(xy, angles, max_range=max_range),
                                  _view_depths_reference(cm, xy, angles, max_range))


def test_imagenav_goal_cameras_do_not_face_a_wall_at_arms_length(room_with_door):
    """Every stored goal camera sees at least goal_view_min_depth (median of its field of view);
    with the rule off, random yaws in these 2 m-wide rooms often face a wall closer than that."""
    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    ecfg = EpisodesConfig()
    ecfg.difficulty.balance = False
    emb = Embodiment(radius=cm.radius)
    half = math.radians(emb.hfov_deg) / 2

    def view(e):
        cam = json.loads(e["goal_camera_json"])
        return float(np.median(cm.view_depths(cam["position"][:2], cam["yaw"] + np.linspace(-half, half, 9))))

    depths = {}
    for need in (1.5, 0.0):
        tcfg = TaskConfig(type="imagenav", episodes_per_scene=40, success_radius=0.5, min_geodesic=0.5,
                          max_geodesic=6.0, trivial_ratio=0.0, starts_per_goal=2, goal_view_min_depth=need)
        res = EpisodeGenerator(cm, g, tcfg, ecfg, PlannerConfig(), emb, "t/scene", 7).generate()
        assert len(res.episodes) >= 30
        depths[need] = [view(e) for e in res.episodes]
    assert min(depths[1.5]) >= 1.5
    assert sum(d < 1.5 for d in depths[0.0]) >= 5  # the rule has something to do here


def test_blind_views_benchmark_finds_none_where_the_costmap_knows_every_gaussian(episode_run, tmp_path):
    """benchmarks.dataset.blind_views on the generated scene (no floaters: its costmap is made of all its
    Gaussians): every view it counts is rendered, none is blocked by something the costmap lacks,
    and views facing the walls the costmap knows are not counted as blocked."""
    import benchmarks.dataset.blind_views as bv

    root, _, _ = episode_run
    rep = bv.main(["--root", str(root), "--per-kind", "12", "--out", str(tmp_path)])
    kinds = next(iter(rep["scenes"].values()))["kinds"]
    assert {"pointnav/start", "pointnav/trajectory", "imagenav/goal_view"} <= set(kinds)
    assert all(k["views"] > 0 and k["blocked"] == 0 for k in kinds.values())
    assert (tmp_path / "blind_views.json").exists()


def test_the_splats_hidden_from_the_camera_are_not_the_scenes_structure(episode_run):
    """The costmap hides from the camera only noise floating clear of every obstacle. The generated
    scene is sparse (its noise rule calls half its splats isolated, surfaces included), and its
    ground truth says what each splat is: at most a few of its wall and object splats are hidden."""
    root, _, _ = episode_run
    sid = next((root / "03_costmaps").glob("*.zarr")).stem
    ids = np.load(next((root / "00_sources").glob("synthetic/*/ground_truth/instance_ids.npy")))
    gs, _ = AlignedGaussianDataset(root / "01_scenes" / sid / "alignment.json",
                                   GaussianDataset(root / "01_scenes" / sid / "gaussians.zarr")).load()
    assert len(ids) == len(gs.means)  # nothing dropped at ingest: the same order
    hidden = CostmapDataset(root / "03_costmaps" / f"{sid}.zarr").hidden("locobot")
    assert len(hidden) == len(np.unique(hidden)) and (np.diff(hidden) > 0).all()
    assert (ids[hidden] >= 0).sum() <= 5e-4 * len(ids)  # structure (0) and objects (>= 1)


def _blob_scene(blobs, sigma: float = 0.18):
    """Walls of small Gaussians along room_with_door's walls (x = 0, 2, 4 m and y = 0, 3 m, up to
    2 m high) and large opaque floaters (sigma metres) at the given centres [K, 3]."""
    s = np.linspace(0.0, 1.0, 80)
    zs = np.linspace(0.0, 2.0, 40)
    walls = []
    for x in (0.02, 2.02, 3.98):
        walls += [np.c_[np.full(s.size * zs.size, x), np.repeat(s * 3.0, zs.size), np.tile(zs, s.size)]]
    for y in (0.02, 2.98):
        walls += [np.c_[np.repeat(s * 4.0, zs.size), np.full(s.size * zs.size, y), np.tile(zs, s.size)]]
    wall = np.concatenate(walls)
    wall = wall[~((np.abs(wall[:, 0] - 2.02) < 0.01) & (wall[:, 1] > 2.0) & (wall[:, 1] < 2.8))]  # the door
    blobs = np.asarray(blobs, float).reshape(-1, 3)
    means = np.r_[wall, blobs]
    scales = np.r_[np.full((len(wall), 3), 0.04), np.full((len(blobs), 3), sigma)]
    n = len(means)
    return GaussianScene(means, np.tile([1.0, 0, 0, 0], (n, 1)), np.log(scales),
                         np.full(n, np.log(0.98 / 0.02)), np.zeros((n, 1, 3)))


def test_blind_view_test_known_answers(room_with_door):
    """A floater 0.3 m ahead of the camera: blind; the same place facing away: not; a wall the map
    has at 0.3 m: not blind (a legitimate view), but a floater at the camera in front of a wall at
    0.45 m is; a pose that is not a valid state is refused."""
    from stages.episodes.views import NearViews

    cm = room_with_door
    emb = Embodiment(radius=cm.radius)
    v = NearViews(_blob_scene([[1.6, 1.0, 0.88]], sigma=0.3), cm, emb, 0.5)
    assert v.blind((1.3, 1.0), 0.0)                      # facing the floater
    assert not v.blind((1.3, 1.0), math.pi)              # facing away: the wall at x = 0 is 1.3 m off
    assert not v.blind((0.35, 1.5), math.pi)             # the wall at x = 0, 0.3 m ahead: the map has it
    assert not NearViews(_blob_scene([]), cm, emb, 0.5).blind((1.3, 1.0), 0.0)  # without the floater
    walled = NearViews(_blob_scene([[0.4, 2.5, 0.88]], sigma=0.2), cm, emb, 0.5)
    assert walled.blind((0.5, 2.5), math.pi)             # the floater 0.1 m ahead, the wall 0.45 m
    assert not walled.blind((0.5, 1.5), math.pi)         # 1 m further along the same wall: only the wall
    with pytest.raises(ValueError, match="not a valid state"):
        v.blind((0.02, 1.5), 0.0)


def test_near_field_renders_what_the_whole_scene_renders(room_with_door):
    """The near-field subset (stages.episodes.views.near_field) is exact: at valid states, off the
    cell centres too, the near render of the subset equals the whole scene's to the byte."""
    from navcore.render import cpu_fast
    from navcore.render.camera import embodiment_camera
    from stages.episodes.views import SIZE, near_field

    cm = room_with_door
    emb = Embodiment(radius=cm.radius)
    r = np.random.default_rng(4)
    n = 40000  # Gaussians of every size and orientation in and around the rooms, all >= MIN_SIGMA
    gs = GaussianScene(np.c_[r.uniform(-3, 7, n), r.uniform(-3, 6, n), r.uniform(-2, 4, n)], r.normal(size=(n, 4)),
                       r.uniform(np.log(0.02), np.log(0.3), (n, 3)), r.uniform(-3, 4, n), np.zeros((n, 1, 3)))
    keep = near_field(gs, cm, emb, 0.5)
    assert 0.05 < keep.mean() < 0.9  # it leaves things out, and keeps some
    full, sub = cpu_fast.prepare(gs), cpu_fast.prepare(gs.subset(keep))
    xy = np.c_[r.uniform(0, 4, 3000), r.uniform(0, 3, 3000)]
    xy = xy[cm.are_states_valid(xy)][:300]
    vm, K, w, h = embodiment_camera(emb, np.c_[xy, r.uniform(-np.pi, np.pi, len(xy))], *SIZE)
    covered = 0
    for i in range(len(xy)):
        a = cpu_fast.render_one(full, vm[i], K[i], w, h, 0, far=0.5)
        b = cpu_fast.render_one(sub, vm[i], K[i], w, h, 0, far=0.5)
        assert all(np.array_equal(x, y) for x, y in zip(a, b)), i
        covered += a[2].max() > 0.1
    assert covered > 100  # the near field is not empty in those views


def test_episodes_do_not_start_blind(room_with_door):
    """With floaters at camera height in the rooms, no stored start (nor ImageNav goal camera) is
    blind, checked by an independent near render of the whole scene; without the test some are."""
    from navcore.render import Renderer
    from navcore.render.camera import embodiment_camera
    from stages.episodes.views import NearViews

    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    emb = Embodiment(radius=cm.radius)
    r = np.random.default_rng(1)
    gs = _blob_scene(np.c_[r.uniform(0.4, 3.6, 20), r.uniform(0.4, 2.6, 20), r.uniform(0.75, 1.0, 20)], sigma=0.25)
    ecfg = EpisodesConfig()
    ecfg.difficulty.balance = False
    tcfg = TaskConfig(type="imagenav", episodes_per_scene=30, success_radius=0.5, min_geodesic=0.5,
                      max_geodesic=6.0, trivial_ratio=0.0, starts_per_goal=3)
    ref = Renderer(gs, "torch")  # the plain reference renderer, not the test's compiled one
    half = math.radians(emb.hfov_deg) / 2

    def blind(x, y, yaw):  # covered over half the image nearer than 0.5 m and 0.15 m before the map's obstacles
        far = min(0.5, np.median(cm.view_depths((x, y), yaw + np.linspace(-half, half, 9), max_range=0.65)) - 0.15)
        vm, K, w, h = embodiment_camera(emb, np.array([[x, y, yaw]]), 16, 12)
        return far > 0.05 and np.median(ref.render(vm, K, w, h, far=far).alpha.numpy()) > 0.5

    def yaw(e, p):
        return 2 * math.atan2(e[f"{p}rotation_qz"], e[f"{p}rotation_qw"])

    counts = {}
    for views in (NearViews(gs, cm, emb, 0.5), None):
        gen = EpisodeGenerator(cm, g, tcfg, ecfg, PlannerConfig(), emb, "t/scene", 11, views=views)
        res = gen.generate()
        assert len(res.episodes) >= 20
        counts[views is None] = sum(blind(e["start_position_x"], e["start_position_y"], yaw(e, "start_"))
                                    for e in res.episodes)
        if views is not None:
            assert res.rejections["start_view_blind"] > 0 and views.checks > len(res.episodes)
            assert not any(blind(e["goal_position_x"], e["goal_position_y"], yaw(e, "goal_")) for e in res.episodes)
    assert counts[False] == 0 and counts[True] >= 3


def test_success_regions_footprint_and_centre_known_answers(room_with_door):
    """A 2 x 1 m bed: under the footprint rule its side is reached 1 m from its edge, under the
    paper's centre rule only 1 m from its centre; the stored rule decides in the evaluator."""
    from navcore.eval.episode import Episode
    from stages.episodes.generate import success_region

    bed = {"center_x": 2.0, "center_y": 1.0, "min_x": 1.0, "min_y": 0.5, "max_x": 3.0, "max_y": 1.5}
    fp, c = success_region(bed, "footprint"), success_region(bed, "centre")
    assert fp.tolist() == [1.0, 0.5, 3.0, 1.5] and c.tolist() == [2.0, 1.0, 2.0, 1.0]
    assert success_region({**bed, "min_x": float("nan")}, "footprint").tolist() == c.tolist()  # no box: the centre
    with pytest.raises(ValueError, match="success_rule"):
        success_region(bed, "middle")
    p = (3.9, 1.0)  # 0.9 m from the bed's end, 1.9 m from its centre
    assert in_region(*p, fp[None], 1.0) and not in_region(*p, c[None], 1.0)
    assert region_distance([p, (2.0, 1.2)], fp[None]).tolist() == pytest.approx([0.9, 0.0])
    row = {"episode_id": "e", "task_type": "objectnav", "start_position_x": 0.0, "start_position_y": 0.0, "start_yaw": 0.0,
           "goal_position_x": 3.9, "goal_position_y": 1.0, "success_radius": 1.0, "geodesic_distance": 4.0,
           "max_steps": 500, "heading_tolerance": float("nan"), "goal_yaw": float("nan"), "goal_object_category": "bed"}
    goal = {"object_id": 1, "object_category": "bed", "position": [2.0, 1.0, 0.5], "view_points": [{"position": [3.9, 1.0, 0]}]}
    foot = Episode.from_row({**row, "goals_json": json.dumps([{**goal, "success_rule": "footprint",
                                                                "footprint": {"min": [1.0, 0.5], "max": [3.0, 1.5]}}])})
    paper = Episode.from_row({**row, "goals_json": json.dumps([goal])})  # stored before the rule: the centre
    assert foot.in_region(*p) and foot.distance_to_goal(*p) == pytest.approx(0.9)
    assert not paper.in_region(*p) and paper.distance_to_goal(*p) == pytest.approx(1.9)


# ---- screening: episodes keep out of the quality layer -----------------------------------------

def test_verdict_and_margin_known_answers():
    from navcore.nav.screening import grow, verdict

    assert [verdict(s, 0.9, 0.5) for s in (1.0, 0.9, 0.89, 0.5, 0.49)] == ["pass", "pass", "warn", "warn", "reject"]
    with pytest.raises(ValueError, match="reject_below"):
        verdict(0.7, 0.5, 0.9)
    m = np.zeros((21, 21), bool)
    m[10, 10] = True
    g = grow(m, 0.25, 0.05)  # a disc of 5 cells
    assert g.sum() == (np.hypot(*np.mgrid[-5:6, -5:6]) <= 5).sum() and g[10, 15] and not g[10, 16]
    assert (grow(m, 0.0, 0.05) == m).all()


def test_defect_views_known_answers(room_with_door):
    """DefectViews (navcore.render.view_quality): facing a large opaque blob a metre ahead, the
    view is mostly blur; facing the room's wall of small splats, none; with nothing to render, all
    holes; floor pixels never count as blur."""
    from navcore.render.view_quality import DefectViews

    emb = Embodiment(radius=room_with_door.radius)
    d = DefectViews(_blob_scene([[1.2, 1.5, 1.0]], sigma=0.6), emb, blur_sigma=0.5, blur_angle=0.25)
    r = d.measure(np.array([[0.3, 1.5, 0.0], [1.0, 0.4, -math.pi / 2]]))
    assert r.blur[0] > 0.5 and r.blur[1] == 0.0 and r.hole[1] == 0.0  # "mostly blur"; the wall: neither
    empty = DefectViews(_blob_scene([]).subset(np.zeros(len(_blob_scene([]).means), bool)), emb).measure(
        np.array([[1.0, 1.5, 0.0]]))
    # nothing rendered: the holes are the rows whose rays meet the floor within 0.8 x 8 m (level
    # camera: row v's centre v + 0.5 lies (v + 0.5 - 24) / f below the horizon, f = 32 px)
    assert emb.camera_pitch_deg == 0
    rows = sum(v + 0.5 - 24 > 0 and emb.camera_height * 32 / (v + 0.5 - 24) < 6.4 for v in range(48))
    assert empty.hole[0] == rows / 48 and empty.blur[0] == 0.0 and rows == 20
    x, y = (a.ravel() for a in np.meshgrid(np.arange(2.5, 8, 0.5), np.arange(-2, 5, 0.5)))
    n = len(x)
    floor = GaussianScene(np.c_[x, y, np.zeros(n)], np.tile([1.0, 0, 0, 0], (n, 1)), np.log(np.tile([0.6, 0.6, 0.01], (n, 1))),
                          np.full(n, 4.0), np.zeros((n, 1, 3)))
    lifted = GaussianScene(floor.means + [0, 0, 0.5], floor.quats, floor.log_scales, floor.opacity_logits, floor.sh)
    assert DefectViews(floor, emb, blur_sigma=0.5).measure(np.array([[1.0, 1.5, 0.0]])).blur[0] == 0.0
    assert DefectViews(lifted, emb, blur_sigma=0.5).measure(np.array([[1.0, 1.5, 0.0]])).blur[0] > 0.2


@pytest.mark.parametrize("task", ["pointnav", "imagenav", "objectnav"])
def test_episodes_keep_out_of_screened_cells(task, room_with_door):
    """A screened disc (a flagged region grown by the margin) in the left room, around one of two
    chairs: no start, goal, ObjectNav view point or expert pose lies in it, and the rejections say
    why; without the layer some episodes cross it. The geodesic graph is the costmap's either way."""
    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    yy, xx = np.mgrid[0:cm.clearance.shape[0], 0:cm.clearance.shape[1]]
    screened = np.hypot((xx + 0.5) * cm.resolution - 1.0, (yy + 0.5) * cm.resolution - 0.6) < 1.0
    ecfg = EpisodesConfig()
    ecfg.difficulty.balance = False
    tcfg = TaskConfig(type=task, episodes_per_scene=24, success_radius=0.5 if task == "pointnav" else 1.0,
                      min_geodesic=1.0, max_geodesic=8.0, trivial_ratio=0.0, starts_per_goal=4)
    inst = [{"instance_id": 4, "category": "chair", "center_x": 3.5, "center_y": 2.5, "center_z": 0.4,
             "min_x": 3.3, "min_y": 2.3, "min_z": 0.0, "max_x": 3.7, "max_y": 2.7, "max_z": 0.8},
            {"instance_id": 5, "category": "chair", "center_x": 1.0, "center_y": 0.6, "center_z": 0.4,
             "min_x": 0.9, "min_y": 0.5, "min_z": 0.0, "max_x": 1.1, "max_y": 0.7, "max_z": 0.8}]
    emb = Embodiment(radius=cm.radius)
    touched = {}
    for layer in (screened, None):
        gen = EpisodeGenerator(cm, g, tcfg, ecfg, PlannerConfig(), emb, "t/scene", 5, inst, screened=layer)
        res = gen.generate()
        assert len(res.episodes) == 24, res.rejections
        xy = np.c_[np.concatenate(res.trajectories["position_x"]), np.concatenate(res.trajectories["position_y"])]
        cells = cm.cells_of(xy)
        touched[layer is None] = int(screened[cells[:, 0], cells[:, 1]].sum())
        if layer is not None:
            ends = np.array([[e[f"{p}position_x"], e[f"{p}position_y"]] for e in res.episodes for p in ("start_", "goal_")])
            c = cm.cells_of(ends)
            assert not screened[c[:, 0], c[:, 1]].any()
            if task == "objectnav":  # the chair inside the disc has no view point left
                assert res.rejections["instance_screened"] == 1
                assert {e["goal_object_id"] for e in res.episodes} == {4}
            else:
                assert res.rejections["path_screened"] + res.rejections["goal_screened"] > 0, res.rejections
    assert touched[False] == 0 and touched[True] > 0


def test_imagenav_goal_views_mostly_blur_are_never_produced(room_with_door):
    """Large blobs at camera height in the rooms: every stored ImageNav goal view is at most half
    blur (measured again), the rejections count the blurred draws; without the test some are
    mostly blur."""
    from navcore.render.view_quality import DefectViews

    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    emb = Embodiment(radius=cm.radius)
    r = np.random.default_rng(2)
    gs = _blob_scene(np.c_[r.uniform(0.4, 3.6, 12), r.uniform(0.4, 2.6, 12), r.uniform(0.8, 1.2, 12)], sigma=0.6)
    ecfg = EpisodesConfig()
    ecfg.difficulty.balance = False
    tcfg = TaskConfig(type="imagenav", episodes_per_scene=20, min_geodesic=0.5, max_geodesic=6.0, trivial_ratio=0.0,
                      starts_per_goal=2, goal_view_min_depth=0.0)
    views = DefectViews(gs, emb, blur_sigma=0.5, blur_angle=0.25)
    worst = {}
    for gv in ((views, 0.5), None):
        res = EpisodeGenerator(cm, g, tcfg, ecfg, PlannerConfig(), emb, "t/scene", 7, goal_views=gv).generate()
        assert len(res.episodes) == 20, res.rejections
        poses = np.array([[e["goal_position_x"], e["goal_position_y"], e["goal_yaw"]] for e in res.episodes])
        worst[gv is None] = views.measure(poses).defect.max()
        if gv is not None:
            assert res.rejections["goal_view_blurred"] > 0
    assert worst[False] <= 0.5 < worst[True]


def test_paths_crossing_matches_walking_each_path(room_with_door):
    """DistanceField.paths_crossing (pointer jumping) against walking every node's path and
    sampling its segments densely."""
    cm = room_with_door
    g = NavGraph(cm, ~cm.occupancy)
    f = g.field(g.cells[[5]])
    mask = np.zeros(cm.clearance.shape, bool)
    mask[20:30, 50:55] = True
    fast = f.paths_crossing(mask)
    r = np.random.default_rng(3)
    for node in r.choice(len(g.cells), 300, replace=False):
        path = f.path_cells(g.cells[node]).astype(float)
        pts = [path[:1]] + [a + np.linspace(0, 1, 50)[:, None] * (b - a) for a, b in zip(path[:-1], path[1:])]
        ij = np.rint(np.concatenate(pts)).astype(int)
        assert fast[node] == mask[ij[:, 0], ij[:, 1]].any(), node
    assert 0 < fast.mean() < 1


def _disk_costmap(radius=0.18, res=0.05, n=120):
    """A 6 x 6 m map whose only obstacle is a point at (3, 3): the clearance is the distance to it,
    so the valid region is the outside of a disk of radius + margin."""
    from navcore.nav.costmap import Costmap
    from stages.costmap.build import interpolation_margin

    c = (np.arange(n) + 0.5) * res
    clr = np.hypot(*np.meshgrid(c - 3.0, c - 3.0)).astype(np.float32)
    return Costmap(clr, (0.0, 0.0), res, radius, interpolation_margin(res, radius))


def test_taut_path_wraps_a_disk_like_the_exact_geodesic():
    """Known answer: around a disk of radius R from a start to a goal at distance D from its centre,
    an angle theta apart, the shortest path is tangent, arc, tangent:
    2 sqrt(D^2 - R^2) + R (theta - 2 acos(R / D)). The query's bilinear clearance puts the disk's
    edge between the radius and the radius plus the interpolation margin, so the geodesic lies
    between those two answers. The taut path (a polyline around an arc) lies within 0.3 % of that
    interval and stays valid, the grid graph's path through cell centres does not (issue 46); the
    benchmark's reference (a visibility graph over the valid region's boundary sampled finely)
    lies within it too."""
    from benchmarks.dataset.episodes import VisibilityReference
    from navcore.nav.geodesic import taut_path

    cm = _disk_costmap()
    s, g = np.array([3.0 - 0.575, 3.0 + 0.025]), np.array([3.0 + 0.575, 3.0 + 0.025])  # cell centres
    d = float(np.hypot(0.575, 0.025))
    theta = math.pi - 2 * math.atan2(0.025, 0.575)  # the angle start - centre - goal
    exact = lambda r: 2 * math.sqrt(d * d - r * r) + r * (theta - 2 * math.acos(r / d))  # noqa: E731
    lo, hi = exact(cm.radius) * 0.997, exact(cm.radius + cm.margin) * 1.003
    valid = ~cm.occupancy
    graph = NavGraph(cm, valid, 6)
    fld = graph.field(cm.cells_of(g[None]))
    grid_path = cm.cell_centers(fld.path_cells(cm.cells_of(s[None])[0]))
    taut = taut_path(cm, grid_path)
    length = float(np.hypot(*np.diff(taut, axis=0).T).sum())
    grid_len = float(np.hypot(*np.diff(grid_path, axis=0).T).sum())
    assert np.allclose(grid_path[0], s) and np.allclose(grid_path[-1], g)
    assert np.allclose(taut[0], s) and np.allclose(taut[-1], g)
    assert cm.are_motions_valid(np.concatenate([taut[:-1], taut[1:]], 1)).all()
    assert length <= grid_len and grid_len > hi  # the grid metric is the defect
    assert lo <= length <= hi, (length, lo, hi)
    ref = VisibilityReference(cm, valid).distance(s, g)
    assert lo <= ref <= hi, (ref, lo, hi)


def test_first_episodes_benchmark_watches_the_layouts_paths(episode_run):
    """benchmarks.usage.first_episodes times the outputs a user waits for by the data layout's own
    paths: on a finished root every one of them is found."""
    import pandas as pd

    from benchmarks.usage.first_episodes import episode_counts, patterns

    root = episode_run[0]
    for name, pattern in patterns():
        assert "{" not in pattern and list(root.glob(pattern)), (name, pattern)
    # its episode counts are the rows of the tables a user would read (an empty file counts 0)
    counts = episode_counts(root)
    for task, n in counts.items():
        files = list(root.glob(f"05_episodes/task={task}/scene_id=*/part-0.parquet"))
        assert n == sum(len(pd.read_parquet(f)) for f in files), task
    assert counts["pointnav"] > 0


def test_difficulty_bins_fill_evenly_where_few_goals_reach_the_far_bin(grid_costmap):
    """A long corridor: only goals near its ends have starts in the far bin. A point goal that cannot
    fill the bin whose turn it is gives way to another goal, so the bins still fill evenly (before:
    the draw fell to a nearer bin, and a capture's episodes came out mostly easy)."""
    free = np.zeros((24, 200), bool)  # 10 m x 1.2 m at 0.05 m
    free[2:-2, 2:-2] = True
    cm = grid_costmap(free)
    g = NavGraph(cm, cm.clearance >= cm.radius)
    ecfg = EpisodesConfig()
    ecfg.difficulty.upper = [2.5, 6.5, 1e9]
    tcfg = TaskConfig(type="pointnav", episodes_per_scene=30, success_radius=0.3, starts_per_goal=3)
    res = EpisodeGenerator(cm, g, tcfg, ecfg, PlannerConfig(), Embodiment(radius=cm.radius), "t/corridor", 5).generate()
    diff = [e["difficulty"] for e in res.episodes]
    assert len(diff) == 30 and [diff.count(n) for n in ("easy", "medium", "hard")] == [10, 10, 10], diff
    assert res.rejections["goal_cannot_fill_bin"] > 0  # the goals that could not were passed over
