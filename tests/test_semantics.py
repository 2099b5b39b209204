"""Semantic lifting core: back-projection, voting rules, instances from multi-view masks."""
import math
import re

import numpy as np
import pytest

from navcore.render.camera import camera_to_world, intrinsics
from stages.semantics.lifting import LiftingConfig, back_project, lift, vote

W, H = 160, 120


def test_back_projection_known_answer():
    K = intrinsics(W, H, 90)
    c2w = camera_to_world(1.0, 2.0, 0.0, 0.5)  # at (1, 2, 0.5) looking along +x
    depth = np.full((H, W), 2.0)
    p = back_project(depth, K, c2w, np.array([[H // 2 - 1, W // 2 - 1]]))  # pixel centre 0.5 px off axis
    f = K[0, 0]
    assert p[0] == pytest.approx([1.0 + 2.0, 2.0 + 0.5 / f * 2.0, 0.5 + 0.5 / f * 2.0])


def test_voting_majority_support_and_ties():
    cfg = LiftingConfig(delta_vote=1.0, min_support=3, support="points")
    pts = np.array([[0.1, 0.1, 0.1]] * 5 + [[1.5, 0.1, 0.1]] * 4 + [[2.5, 0.1, 0.1]] * 2, float)
    labs = np.array([1, 1, 1, 2, 2] + [1, 1, 2, 2] + [3, 3])
    cells = vote(pts, labs, cfg)
    assert cells[(0, 0, 0)] == (1, 5, pytest.approx(0.6))
    assert (1, 0, 0) not in cells  # a tie
    assert (2, 0, 0) not in cells  # too little support
    assert (1, 0, 0) in vote(pts, labs, LiftingConfig(delta_vote=1.0, min_support=3, exclude_ties=False,
                                                      support="points"))
    # votes per view: one frame's many points are one vote; the majority of frames wins
    frames = np.array([0, 0, 0, 1, 2] + [0, 0, 1, 2] + [4, 5])
    views = vote(pts, labs, LiftingConfig(delta_vote=1.0, min_support=3), frames)
    assert views[(0, 0, 0)] == (2, 3, pytest.approx(2 / 3))  # label 1 from frame 0 only, label 2 from 1 and 2
    assert views[(1, 0, 0)] == (2, 3, pytest.approx(2 / 3))  # a tie in points, not in views
    assert (2, 0, 0) not in views  # two views


def box_points(centre, size, n, rng):
    """Points on the surface of an axis-aligned box."""
    p = rng.uniform(-0.5, 0.5, (n, 3))
    ax = rng.integers(3, size=n)
    p[np.arange(n), ax] = np.sign(p[np.arange(n), ax]) * 0.5
    return np.asarray(centre) + p * np.asarray(size)


def synthetic_frames(points, labels, poses, K):
    """Depth and per-label masks by z-buffered point splats (a stand-in renderer)."""
    frames = []
    for (x, y, yaw) in poses:
        c2w = camera_to_world(x, y, yaw, 0.6)
        w2c = np.linalg.inv(c2w)
        pc = points @ w2c[:3, :3].T + w2c[:3, 3]
        ok = pc[:, 2] > 0.1
        u = np.floor(K[0, 0] * pc[ok, 0] / pc[ok, 2] + K[0, 2]).astype(int)
        v = np.floor(K[1, 1] * pc[ok, 1] / pc[ok, 2] + K[1, 2]).astype(int)
        z, lab = pc[ok, 2], labels[ok]
        inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        depth = np.full((H, W), np.inf)
        labimg = np.zeros((H, W), int)
        for uu, vv, zz, ll in zip(u[inside], v[inside], z[inside], lab[inside]):
            for du in (0, 1):  # 2x2 splats: no holes at this density
                for dv in (0, 1):
                    a, b = min(vv + dv, H - 1), min(uu + du, W - 1)
                    if zz < depth[a, b]:
                        depth[a, b], labimg[a, b] = zz, ll
        depth[np.isinf(depth)] = 0
        frames.append((depth, K, c2w, {k: labimg == k for k in (1, 2)}))
    return frames


def test_lifting_finds_each_object_once_at_its_centre():
    rng = np.random.default_rng(0)
    chair = box_points((2.0, 0.0, 0.4), (0.5, 0.5, 0.8), 4000, rng)
    table = box_points((2.5, 1.5, 0.35), (1.0, 0.6, 0.7), 6000, rng)
    floor = np.column_stack([rng.uniform(0, 4, 8000), rng.uniform(-1, 3, 8000), np.zeros(8000)])
    means = np.concatenate([chair, table, floor])
    labels = np.concatenate([np.full(4000, 1), np.full(6000, 2), np.zeros(8000, int)])
    K = intrinsics(W, H, 90)
    # around the objects, so that every side face is seen and links the front and back faces
    poses = [(0.0, 0.5, a) for a in np.linspace(-0.6, 0.9, 6)] + [(4.5, 0.5, math.pi + a) for a in (-0.4, 0.0, 0.4)]
    poses += [(2.0, -1.6, math.pi / 2 + a) for a in (-0.4, 0.0, 0.4)] + [(2.5, 3.2, -math.pi / 2 + a) for a in (-0.3, 0.0, 0.3)]
    found = lift(synthetic_frames(means, labels, poses, K), means, LiftingConfig())
    by = {}
    for f in found:
        by.setdefault(f["label"], []).append(f)
    assert set(by) == {1, 2} and len(by[1]) == 1 and len(by[2]) == 1
    assert np.hypot(*(by[1][0]["center"][:2] - (2.0, 0.0))) < 0.2
    assert np.hypot(*(by[2][0]["center"][:2] - (2.5, 1.5))) < 0.25
    assert all(0.5 < f["confidence"] <= 1.0 for f in found)


def test_corruption_model_rates_and_effects():
    from stages.semantics.segmenters import Corruption, corrupt

    imap = np.zeros((60, 80), int)
    imap[10:30, 10:30] = 1
    imap[35:55, 40:70] = 2
    cats = {1: "chair", 2: "table"}
    prompts = ["chair", "table", "bed"]
    rng = np.random.default_rng(0)
    clean = corrupt(imap, cats, prompts, Corruption(), rng)
    assert np.array_equal(clean["chair"][0][0], imap == 1) and clean["bed"] == []
    n, missed, confused, grown = 2000, 0, 0, 0
    for _ in range(n):
        m = corrupt(imap, cats, prompts, Corruption(bleed_px=3, miss_rate=0.2, confusion_rate=0.1), rng)
        masks = [(p, mk) for p, lst in m.items() for mk, _ in lst]
        chair = [(p, mk) for p, mk in masks if mk[20, 20]]
        missed += not chair
        confused += bool(chair) and chair[0][0] != "chair"
        grown += bool(chair) and chair[0][1].sum() != (imap == 1).sum()
    assert abs(missed / n - 0.2) < 0.03 and abs(confused / (n - missed) - 0.1) < 0.03 and grown == n - missed
    blobs = [len(corrupt(np.zeros((60, 80), int), cats, prompts, Corruption(fp_blobs=1.5), rng)["bed"])
             for _ in range(600)]
    assert abs(np.mean(blobs) - 1.5 / 3) < 0.1  # Poisson(1.5) blobs spread over 3 prompts


def test_oracle_segmenter_masks_follow_instance_labels():
    from navcore.gaussians.model import GaussianScene
    from navcore.gaussians.sh import C0
    from navcore.render import Renderer
    from navcore.render.camera import viewmats
    from stages.semantics.segmenters import OracleSegmenter

    rng = np.random.default_rng(1)
    a = box_points((2.0, 0.6, 0.6), (0.4, 0.4, 0.4), 3000, rng)
    b = box_points((2.0, -0.6, 0.6), (0.4, 0.4, 0.4), 3000, rng)
    means = np.concatenate([a, b])
    n = len(means)
    gs = GaussianScene(means, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), np.log(0.02)),
                       np.full(n, 3.0), np.full((n, 1, 3), 0.2 / C0))
    ids = np.concatenate([np.full(3000, 5), np.full(3000, 9)])
    seg = OracleSegmenter(Renderer(gs, "cpu"), ids, {5: "chair", 9: "table"})
    vm = viewmats(np.array([[0.0, 0.0, 0.0]]), 0.6)[0]
    K = intrinsics(W, H, 90)
    out = seg.segment(np.zeros((H, W, 3), np.uint8), ["chair", "table"], {"viewmat": vm, "K": K})
    chair, table = out["chair"][0][0], out["table"][0][0]
    # the chair (+y) is on the image's left, the table on its right; they do not overlap
    cols = np.arange(W)
    assert cols[chair.any(0)].mean() < W / 2 < cols[table.any(0)].mean() and not (chair & table).any()


def test_free_space_poses_cover_the_free_cells(room_with_door):
    from stages.semantics.poses import free_space_poses, yaw_coverage

    cm = room_with_door
    valid = ~cm.occupancy
    poses = free_space_poses(cm, valid, spacing=1.0, yaw_step_deg=45)
    pts = np.unique(poses[:, :2], axis=0)
    assert cm.are_states_valid(pts).all()
    assert len(poses) == 8 * len(pts) and yaw_coverage(poses[:8]) == pytest.approx(math.pi / 4)
    # every valid cell is within ~a block diagonal of a pose, and no two poses are closer than 0.5 m
    cells = cm.cell_centers(np.argwhere(valid))
    nearest = np.min(np.hypot(cells[:, None, 0] - pts[None, :, 0], cells[:, None, 1] - pts[None, :, 1]), 1)
    assert nearest.max() <= 1.5
    d = np.hypot(pts[:, None, 0] - pts[None, :, 0], pts[:, None, 1] - pts[None, :, 1]) + np.eye(len(pts)) * 9
    assert d.min() >= 0.5
    assert np.array_equal(poses, free_space_poses(cm, valid, spacing=1.0, yaw_step_deg=45))


# ---- the stage on a generated scene ---------------------------------------------------------------

@pytest.fixture(scope="module")
def semantics_run(tmp_path_factory, make_cfg):
    from pipeline.executor import execute

    root = tmp_path_factory.mktemp("semantics")
    over = ["stages=[asset]", "semantics.max_views=24"]
    summary = execute(make_cfg(root, *over))
    assert not summary["failures"], summary["failures"]
    return root, over, summary


def test_stage_predicts_valid_instances_into_the_table_and_the_asset(semantics_run):
    import json

    import pyarrow.parquet as pq

    from navcore.instances import INSTANCE_SCHEMA, table_to_labels
    from stages.semantics.precision import ground_truth_objects, score

    root, _, summary = semantics_run
    sid = summary["results"][0]["scene_id"]
    table = pq.read_table(root / "04_semantics" / sid / "instances.parquet")
    assert table.schema.equals(INSTANCE_SCHEMA) and set(table.column("source").to_pylist()) == {"model_predicted"}
    labels = table_to_labels(table)
    src = next((root / "00_sources" / "synthetic").iterdir())
    objects, c2s = ground_truth_objects(src)
    s2a = np.asarray(json.loads((root / "01_scenes" / sid / "alignment.json").read_text())["source_to_aligned"])
    r = score(labels, objects, [o["category"] for o in objects], np.linalg.inv(s2a @ c2s))
    # moderate corruption (the default), 24 of the 30 capture views of a 30 k-Gaussian two-room scene:
    # the centres are valid, more than half of the objects found
    assert r["predicted"] and r["valid"] >= 0.9 * r["predicted"] and r["found"] >= 0.5 * r["objects"], r
    marker = json.loads((root / "_markers" / "semantics" / f"{sid}.json").read_text())["info"]
    assert marker["poses"] == "source" and marker["views"] == 24 and marker["instances"] == len(labels)
    asset = next((root / "09_assets" / "synthetic").iterdir())
    assert json.loads((asset / "labels.json").read_text())["labels"] == labels


def test_stage_is_deterministic_and_reads_its_config(semantics_run, tmp_path, make_cfg):
    import json
    import shutil

    import pyarrow.parquet as pq

    from pipeline.executor import execute

    root, over, summary = semantics_run
    sid = summary["results"][0]["scene_id"]
    first = (root / "04_semantics" / sid / "instances.parquet").read_bytes()
    execute(make_cfg(root, *over, "stages=[semantics]", "force=true"))
    assert (root / "04_semantics" / sid / "instances.parquet").read_bytes() == first
    # free-space poses instead of the capture cameras: another table, from free-space views
    copy = tmp_path / "d"
    shutil.copytree(root, copy)
    s = execute(make_cfg(copy, *over, "stages=[semantics]", "semantics.poses=free_space", "semantics.spacing=2.0",
                         "semantics.yaw_step_deg=90"))
    info = next(r for r in s["results"] if r["stage"] == "semantics")
    marker = json.loads((copy / "_markers" / "semantics" / f"{sid}.json").read_text())["info"]
    assert info["status"] == "done" and marker["poses"] == "free_space" and marker["views"] <= 40
    # without per-Gaussian ground truth the oracle cannot serve the scene: an empty table, a
    # shortfall in the run summary, not a failure (the scene's other tasks go on)
    next((copy / "00_sources" / "synthetic").iterdir()).joinpath("ground_truth", "instance_ids.npy").unlink()
    s = execute(make_cfg(copy, *over, "stages=[semantics]", "force=true"))
    assert [r["stage"] for r in s["shortfalls"]] == ["semantics"] and not s["failures"]
    assert "ground truth" in s["shortfalls"][0]["shortfall"][0]["reason"]
    assert pq.read_table(copy / "04_semantics" / sid / "instances.parquet").num_rows == 0
    # no ObjectNav asked for: nothing fell short (the reason stays in the stage's result)
    s = execute(make_cfg(copy, *over, "stages=[semantics]", "force=true", "task=[pointnav]"))
    sem = next(r for r in s["results"] if r["stage"] == "semantics")
    assert not s["shortfalls"] and not s["failures"] and sem["status"] == "done"


def test_cameras_in_both_layouts():
    from navcore.gaussians.cameras import cameras_from_json

    r = np.array([[math.cos(0.8), -math.sin(0.8), 0], [math.sin(0.8), math.cos(0.8), 0], [0, 0, 1]])  # about z
    ours = {"hfov_deg": 90.0, "poses": [{"position": [1, 2, 3], "quat_wxyz": [math.cos(0.4), 0, 0, math.sin(0.4)]}]}
    c2w, k = cameras_from_json(ours, 320, 240)
    assert np.allclose(c2w[0, :3, :3], r) and np.allclose(c2w[0, :3, 3], [1, 2, 3]) and k[0, 0, 0] == 160
    inria = [{"id": 0, "img_name": "a", "width": 1000, "height": 800, "position": [4, 5, 6],
              "rotation": r.tolist(), "fx": 500.0, "fy": 510.0}]
    c2w, k = cameras_from_json(inria, 320, 240)
    assert np.allclose(c2w[0, :3, :3], r) and np.allclose(c2w[0, :3, 3], [4, 5, 6])
    assert np.allclose(k[0], [[160, 0, 160], [0, 153, 120], [0, 0, 1]])


def test_instance_table_round_trip_and_oracle_levels():
    from navcore.instances import labels_to_table, table_to_labels
    from stages.semantics.config import OracleConfig

    labels = [{"instance_id": 1, "category": "chair", "position": [1.0, 2.0, 0.4],
               "bounding_box": {"min": [0.8, 1.8, 0.0], "max": [1.2, 2.2, 0.8]}, "confidence": 0.75,
               "source": "model_predicted", "dataset_class": None},
              {"instance_id": 2, "category": "bed", "position": [3.0, 1.0, 0.5], "bounding_box": None,
               "confidence": 1.0, "source": "ground_truth", "dataset_class": "double_bed"}]
    assert table_to_labels(labels_to_table(labels)) == labels
    assert OracleConfig(level="heavy").corruption().miss_rate == 0.3
    assert OracleConfig(level="heavy", miss_rate=0.5).corruption().bleed_px == 6
    with pytest.raises(ValueError, match="oracle.level"):
        OracleConfig(level="extreme").corruption()


def test_dense_clouds_are_clustered_on_voxel_representatives():
    """Above dbscan_max_points a category's points are clustered one per delta_down voxel, weighted:
    the same objects as point-by-point clustering, within a centimetre (and memory bounded)."""
    from stages.semantics.lifting import LiftingConfig, cluster

    rng = np.random.default_rng(3)
    a = box_points((0.0, 0.0, 0.5), (0.6, 0.6, 0.6), 30_000, rng)
    b = box_points((2.0, 0.5, 0.4), (0.8, 0.4, 0.5), 30_000, rng)
    stray = rng.uniform(-3, 3, (40, 3)) + (0, 0, 5)  # sparse noise far above
    xyz = np.concatenate([a, b, stray])
    exact = cluster(xyz, LiftingConfig(dbscan_max_points=10**9))
    fast = cluster(xyz, LiftingConfig(dbscan_max_points=1_000))
    for labels in (exact, fast):
        found = sorted(set(labels[:30_000])) + sorted(set(labels[30_000:60_000]))
        assert len(found) == 2 and found[0] != found[1] and -1 not in found  # each box one cluster
        assert (labels[60_000:] == -1).all()  # the sparse strays are noise
    for lo, hi in ((0, 30_000), (30_000, 60_000)):
        assert np.allclose(xyz[lo:hi][exact[lo:hi] >= 0].mean(0), xyz[lo:hi][fast[lo:hi] >= 0].mean(0), atol=0.01)


def test_instances_that_stay_on_the_floor_are_dropped_when_asked():
    """lifting.min_top_m (the detector sets 0.25 m): a labelled patch of floor is no object."""
    from stages.semantics.lifting import LiftingConfig, lift

    rng = np.random.default_rng(4)
    chair = box_points((2.0, 0.0, 0.4), (0.5, 0.5, 0.8), 4000, rng)
    patch = np.column_stack([rng.uniform(0.5, 1.5, 4000), rng.uniform(1.5, 2.5, 4000), rng.uniform(0, 0.1, 4000)])
    floor = np.column_stack([rng.uniform(0, 4, 8000), rng.uniform(-1, 3, 8000), np.zeros(8000)])
    means = np.concatenate([chair, patch, floor])
    labels = np.concatenate([np.full(4000, 1), np.full(4000, 2), np.zeros(8000, int)])
    K = intrinsics(W, H, 90)
    poses = [(0.0, 0.5, a) for a in np.linspace(-0.6, 0.9, 6)] + [(4.5, 0.5, math.pi + a) for a in (-0.4, 0.0, 0.4)]
    frames = list(synthetic_frames(means, labels, poses, K))
    every = {f["label"] for f in lift(frames, means, LiftingConfig())}
    kept = {f["label"] for f in lift(frames, means, LiftingConfig(min_top_m=0.25))}
    assert every == {1, 2} and kept == {1}
    # min_top_m=0 is off: lifted in a frame whose floor lies 2 m below z = 0 (a scene's source frame, as
    # bench-semantics lifts), every instance stays (a top below 0 dropped them all, 2026-11-27 to 12-02)
    down = np.array([0.0, 0.0, -2.0])
    low = [(d, k, np.vstack([c[:3], c[3:]]) + np.pad(down[:, None], ((0, 1), (3, 0))), m) for d, k, c, m in frames]
    assert {f["label"] for f in lift(low, means + down, LiftingConfig())} == {1, 2}


def test_semantics_logs_its_views_and_the_console_counts_them(episode_run, tmp_path):
    """The semantics stage writes views done / total while it runs (_progress/semantics: run bookkeeping
    beside _markers, outside the stage's outputs, since it holds the writer's pid), and the
    run console's watcher turns such a log into views done, total and views/s."""
    from rich.console import Console
    from rich.progress import Progress

    from navcore.io.progress_log import ProgressLog, read_log
    from pipeline.episode_progress import EpisodeWatcher

    root = episode_run[0]
    logs = sorted((root / "_progress" / "semantics").glob("*.jsonl"))
    assert logs and not list((root / "04_semantics").rglob("*.jsonl"))
    for log in logs:
        header, items = read_log(log)
        assert header["total"] > 0 and header["segmenter"] and sum(it["views"] for it in items) == header["total"]
    folder = tmp_path / "_progress"
    a, b = ProgressLog(folder / "a.jsonl"), ProgressLog(folder / "b.jsonl")
    a.start(10, scene="a")
    b.start(6, scene="b")
    for n in (4, 4):
        a.item(views=n)
    b.item(views=6)
    console_file = open(tmp_path / "console.txt", "w")
    progress = Progress(console=Console(file=console_file, width=200))  # a file: no terminal
    w = EpisodeWatcher(progress, folder, since=0, log_each=False, name="semantics views", count="views",
                       rate="views", unit="views", log_every_s=0)
    w.poll()
    task = progress.tasks[0]
    assert (task.description, task.total, task.completed, task.fields["unit"]) == ("semantics views", 16, 14, "views")
    console_file.flush()  # without a terminal the watcher prints a plain line: done / total, rate, time left
    assert re.search(r"semantics views: 14/16 \([\d,.]+ views/s\), about \d+ s left", (tmp_path / "console.txt").read_text())
    a.item(views=2)
    w.poll()
    assert progress.tasks[0].completed == 16 and w.steps == 16


def test_coverage_views_see_every_wall_of_a_room_with_few_views():
    """Known answer: a 6 x 4 m room's walls (0.2 m surface voxels up to 2.5 m) from a lattice of
    candidates every 0.5 m and 30 deg: the greedy coverage set sees every voxel twice from distinct
    directions with a handful of views, deterministically."""
    from stages.semantics.poses import coverage_poses, surface_targets

    cell = 0.2
    xs, ys, zs = np.arange(0.1, 6.0, cell), np.arange(0.1, 4.0, cell), np.arange(0.1, 2.5, cell)
    walls = [(x, y, z) for z in zs for x in xs for y in (0.0, 4.0)] + [(x, y, z) for z in zs for y in ys for x in (0.0, 6.0)]
    targets = surface_targets(np.asarray(walls), np.ones(len(walls)), cell, 0.1, 2.5)
    g = np.arange(0.75, 5.3, 0.5)
    h = np.arange(0.75, 3.3, 0.5)
    yaws = np.deg2rad(np.arange(0, 360, 30))
    cand = np.array([(x, y, a) for x in g for y in h for a in yaws])
    picked, rep = coverage_poses(cand, targets, 1.0, 0.0, 90.0, k=2, max_range=8.0, cell=cell, min_gain=0.0)
    assert rep["coverage"] == 1.0 and rep["coverage_2"] == 1.0  # every wall voxel, twice
    assert 4 <= len(picked) <= 12 < len(cand) // 20
    again, _ = coverage_poses(cand, targets, 1.0, 0.0, 90.0, k=2, max_range=8.0, cell=cell, min_gain=0.0)
    assert np.array_equal(picked, again)
    # occlusion: on the camera's axis a voxel 1 m behind a nearer one is hidden, one beside them is not
    from navcore.render.camera import camera_to_world, intrinsics
    from stages.semantics.poses import visible_targets

    pts = np.array([[2.0, 0.0, 1.0], [3.0, 0.0, 1.0], [3.0, 1.0, 1.0]])
    vis = visible_targets(pts, camera_to_world(0.0, 0.0, 0.0, 1.0), intrinsics(64, 48, 90.0), 64, 48, 8.0, cell)
    assert vis.tolist() == [0, 2]


def test_coverage_wanting_fewer_sightings_than_the_lifting_votes_is_refused():
    """A surface seen k times cannot gather min_support votes: the run says so, naming the scene
    and both keys, before any view is rendered."""
    import dataclasses
    from types import SimpleNamespace

    from stages.semantics.config import CoverageConfig, SemanticsConfig
    from stages.semantics.stage import covering_cameras

    scene = SimpleNamespace(scene_id="abc123", name="my_flat")
    scfg = SemanticsConfig(poses="free_space", view_selection="coverage", coverage=CoverageConfig(k=2))
    assert scfg.lifting.min_support == 3 and CoverageConfig().k >= 3  # the defaults agree
    with pytest.raises(ValueError, match=r"my_flat.*coverage\.k=2.*min_support=3"):
        covering_cameras(scene, None, scfg, None, np.eye(4))
    with pytest.raises(ValueError, match="min_support=2"):  # and the lifting's side of the same rule
        covering_cameras(scene, None, dataclasses.replace(scfg, coverage=CoverageConfig(k=1),
                                                          lifting=dataclasses.replace(scfg.lifting, min_support=2)),
                         None, np.eye(4))


def test_a_long_semantics_task_says_its_size_time_and_fast_path_before_it_starts(tmp_path):
    """A scene with thousands of views to segment gets a line before its first view: the view count,
    the minutes it takes on a CPU at the segmenter's seen rate, and the overrides that cut it; the
    run's console prints it once; a short task says nothing."""
    from types import SimpleNamespace

    from rich.console import Console
    from rich.progress import Progress

    from navcore.io.progress_log import ProgressLog
    from pipeline.episode_progress import EpisodeWatcher
    from stages.semantics.stage import long_run_hint

    scene = SimpleNamespace(name="apartment")
    hint = long_run_hint(scene, 7980, SimpleNamespace(segmenter="detector", view_selection="grid"))
    assert "7,980 views" in hint and "about 53 min" in hint and "semantics.view_selection=coverage" in hint
    assert "semantics.max_views=N" in hint
    assert long_run_hint(scene, 200, SimpleNamespace(segmenter="detector", view_selection="grid")) == ""
    assert long_run_hint(scene, 7980, SimpleNamespace(segmenter="oracle", view_selection="grid")) == ""
    log = ProgressLog(tmp_path / "p" / "a.jsonl")
    log.start(7980, scene="apartment", hint=hint)
    log.item(views=16)
    out = tmp_path / "console.txt"
    with open(out, "w") as f:
        w = EpisodeWatcher(Progress(console=Console(file=f, width=300)), tmp_path / "p", since=0, log_each=False,
                           name="semantics views", count="views", rate="views", unit="views")
        w.poll()
        log.item(views=16)
        w.poll()
    assert out.read_text().count("7,980 views for the detector segmenter") == 1
