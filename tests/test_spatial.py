"""Voxelization, alignment, costmap and the query API: known answers, invariants, references."""
import numpy as np
import pytest

from navcore.gaussians import GaussianScene
from navcore.gaussians.content import CONTENT_KEY, content_mask, content_of
from navcore.gaussians.floor import AlignConfig, fit_floor, floor_transform
from navcore.nav.costmap import Costmap
from navcore.nav.embodiment import Embodiment
from navcore.voxels import VoxelGrid, VoxelizeConfig, opacity_field
from stages.costmap.build import CostmapConfig, build_costmap, interpolation_margin


def one_gaussian(alpha=0.8, sigma=(0.1, 0.1, 0.1), mean=(0.0, 0.0, 0.0)):
    a = np.log(alpha / (1 - alpha))
    return GaussianScene(np.array([mean]), np.array([[1.0, 0, 0, 0]]), np.log([sigma]), [a], np.zeros((1, 1, 3)))


def test_single_gaussian_known_answer_center_sampling():
    g = one_gaussian()
    grid = VoxelGrid((-0.5, -0.5, -0.5), (0.1, 0.1, 0.1), (10, 10, 10))
    a = opacity_field(g, grid, VoxelizeConfig(sample="center", device="cpu"))
    c = grid.centers(0)
    xx, yy, zz = np.meshgrid(c, c, c, indexing="ij")
    chi2 = (xx ** 2 + yy ** 2 + zz ** 2) / 0.01
    expect = np.where(chi2 <= 9, 0.8 * np.exp(-chi2 / 2), 0)
    assert np.allclose(a, expect, atol=1e-6)


def test_max_sampling_bounds_center_sampling_and_catches_thin_surfaces():
    # a thin wall (normal sigma 2 mm) halfway between voxel centres: centre sampling misses it
    g = one_gaussian(alpha=0.9, sigma=(0.2, 0.2, 0.002), mean=(0.0, 0.0, 0.0))  # on a voxel face
    grid = VoxelGrid((-0.5, -0.5, -0.5), (0.05, 0.05, 0.05), (20, 20, 20))
    ac = opacity_field(g, grid, VoxelizeConfig(sample="center", device="cpu"))
    am = opacity_field(g, grid, VoxelizeConfig(sample="max", device="cpu"))
    assert (am >= ac - 1e-7).all()
    assert (ac >= 0.5).sum() == 0 and (am >= 0.5).sum() > 0


def test_chunking_and_torch_path_agree(small_scene):
    g = small_scene.gaussians.subset(slice(0, 40_000))
    from navcore.voxels.grid import grid_for_points

    grid = grid_for_points(g.means, 0.1, margin=0.1)
    big = opacity_field(g, grid, VoxelizeConfig(block_voxels=10 ** 9, device="cpu"))
    small = opacity_field(g, grid, VoxelizeConfig(block_voxels=grid.shape[1] * grid.shape[2] * 3, device="cpu"))
    assert np.array_equal(big, small)  # x-blocks change memory, never the bits
    pytest.importorskip("torch")
    tor = opacity_field(g, grid, VoxelizeConfig(), device="torch-cpu")
    # float32 vs float64 only flips voxels sitting on the truncation boundary
    assert np.abs(tor - big).max() < 0.02
    assert ((tor >= 0.5) != (big >= 0.5)).mean() < 1e-3


def test_grid_refuses_absurd_extent():
    from navcore.voxels.grid import grid_for_points

    with pytest.raises(ValueError, match="scene units metres"):
        grid_for_points(np.array([[0, 0, 0], [5000.0, 5000, 500]]), 0.05)


def test_floor_transform_maps_plane_to_z0():
    r = np.random.default_rng(3)
    n = r.normal(size=3)
    n /= np.linalg.norm(n)
    d = 1.7
    t = floor_transform(n, d)
    p = np.cross(n, r.normal(size=(50, 3))) - d * n  # points on the plane
    q = p @ t[:3, :3].T + t[:3, 3]
    assert np.allclose(q[:, 2], 0, atol=1e-9)
    assert np.allclose(t[:3, :3] @ n, [0, 0, 1])


def aligned_scene(sc):
    n, d, _ = fit_floor(sc.gaussians, AlignConfig())
    return n, d, floor_transform(n, d)


def test_alignment_recovers_ground_truth(small_scene):
    n, d, t = aligned_scene(small_scene)
    up = small_scene.transform[:3, :3] @ [0, 0, 1.0]
    assert np.degrees(np.arccos(np.clip(n @ up, -1, 1))) < 0.5
    rooms = np.asarray(small_scene.layout.rooms)
    pts = np.array([[r[0], r[1], 0.0] for r in rooms] + [[r[2], r[3], 0.0] for r in rooms])
    m = t @ small_scene.transform
    assert np.abs((pts @ m[:3, :3].T + m[:3, 3])[:, 2]).max() < 0.01


@pytest.mark.parametrize("seed", [302, 303])
def test_alignment_converges_on_trained_like_gaussians(seed):
    """synthetic.realism.level=trained (structure splats turned up to 45 deg, leaning one way, thick;
    the scene tilted 1-2 deg): the aligned floor within 0.1 deg of the truth (issue 46; the two-pass
    refinement before it left these seeds 0.13 and 2.5 deg off)."""
    from stages.synthesize.generate import SyntheticConfig, generate_scene
    from stages.synthesize.realism import RealismConfig

    sc = generate_scene(seed, SyntheticConfig(num_gaussians=150_000, realism=RealismConfig(level="trained")))
    g = sc.gaussians
    g.extras[CONTENT_KEY] = content_mask(g.means)[0]
    n, _, info = fit_floor(content_of(g), AlignConfig())
    up = sc.transform[:3, :3] @ [0, 0, 1.0]
    assert np.degrees(np.arccos(np.clip(n @ up, -1, 1))) < 0.1
    assert info["refinement"]["converged"]


def test_floor_refinement_converges_from_a_tilted_start_known_answer():
    """A 16 x 6 m floor 3 cm thick with wall feet and furniture bases in a 15 cm band: from a start
    1.3 deg off (17 cm across the hall, more than the old 5 cm band held) the refinement lands
    within 0.01 deg of the floor's plane, and it stops on its own (converged, bounded passes)."""
    from navcore.gaussians.floor import refine_floor_plane

    r = np.random.default_rng(0)
    floor = np.c_[r.uniform(0, 16, 60_000), r.uniform(0, 6, 60_000), r.normal(0, 0.01, 60_000)]
    walls = np.c_[r.uniform(0, 16, 8_000), r.choice([0.0, 6.0], 8_000), r.uniform(0, 0.3, 8_000)]
    bases = np.c_[r.uniform(2, 5, 6_000), r.uniform(1, 2, 6_000), r.uniform(0.03, 0.15, 6_000)]
    p = np.concatenate([floor, walls, bases])
    tilt = np.radians(0.4)  # the true floor, tilted in the source frame
    rot = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    p = p @ rot.T
    truth = rot @ [0, 0, 1.0]
    start = np.array([np.sin(np.radians(1.3)), 0.0, np.cos(np.radians(1.3))])
    start = start @ rot.T  # 1.3 deg off along the hall's length
    cell = np.unique(np.floor(p[:, :2] / 0.25).astype(np.int64), axis=0, return_inverse=True)[1].reshape(-1)
    d0 = -float(start @ p[:60_000].mean(0))
    n, d, info = refine_floor_plane(p, np.ones(len(p)), np.ones(len(p), bool), cell, start, d0, AlignConfig())
    assert np.degrees(np.arccos(np.clip(n @ truth, -1, 1))) < 0.01
    assert info["converged"] and info["passes"] < AlignConfig().refine_max_passes
    assert abs(d + float(truth @ p[:60_000].mean(0))) < 0.003


def wall_costmap(radius=0.2, res=0.05):
    """Clearance of a single wall along x = 0 on a 4 m x 4 m map (cells x >= 0 free)."""
    nx = ny = 80
    xs = -1.0 + (np.arange(nx) + 0.5) * res
    clr = np.tile(np.maximum(xs, 0.0), (ny, 1)).astype(np.float32)
    return Costmap(clr, (-1.0, -1.0), res, radius, interpolation_margin(res, radius))


def test_state_queries_known_answer():
    cm = wall_costmap()
    thr = cm.radius + cm.margin
    assert cm.is_state_valid(thr + 0.001, 1.0) and not cm.is_state_valid(thr - 0.001, 1.0)
    assert not cm.is_state_valid(-5.0, 0.0)  # off the map
    xy = np.random.default_rng(0).uniform(-0.9, 2.9, (2000, 2))
    batch = cm.are_states_valid(xy)
    single = np.array([cm.is_state_valid(x, y) for x, y in xy])
    assert np.array_equal(batch, single)
    assert np.array_equal(batch, xy[:, 0] >= thr)  # linear field: bilinear interpolation is exact


def test_motion_queries_exact_against_dense_sampling():
    r = np.random.default_rng(1)
    clr = r.uniform(0, 1, (30, 30)).astype(np.float32)
    cm = Costmap(clr, (0.0, 0.0), 0.1, 0.3, 0.0)
    seg = np.concatenate([r.uniform(0.1, 2.9, (3000, 2)), r.uniform(0.1, 2.9, (3000, 2))], 1)
    seg[:, 2:] = seg[:, :2] + (seg[:, 2:] - seg[:, :2]) * 0.2
    fast = cm.are_motions_valid(seg)
    t = np.linspace(0, 1, 4001)
    dense = np.array([(cm.clearance_at(s[:2] + (s[2:] - s[:2]) * t[:, None]) >= 0.3).all() for s in seg])
    # the exact check may only be stricter than sampling, and rarely (minima between samples)
    assert not (fast & ~dense).any()
    assert (~fast & dense).mean() < 0.01
    single = np.array([cm.is_motion_valid(*s) for s in seg[:300]])
    assert np.array_equal(single, fast[:300])


@pytest.fixture(scope="module")
def fcl_states(small_scene):
    """The small scene aligned, 1500 states in its rooms (aligned frame) and FCL's verdict on each
    against the ground-truth mesh."""
    pytest.importorskip("fcl")
    from benchmarks.map.spatial import FclReference, sample_queries
    from stages.synthesize.surface import layout_mesh

    _, _, t = aligned_scene(small_scene)
    can_to_al = t @ small_scene.transform
    rooms = np.asarray(small_scene.layout.rooms)
    states_c, _ = sample_queries(rooms, np.random.default_rng(5), 1500, 0)
    states = (np.c_[states_c, np.zeros(len(states_c))] @ can_to_al[:3, :3].T + can_to_al[:3, 3])[:, :2]
    ref = FclReference(layout_mesh(small_scene.layout.parts)[0], Embodiment(), np.linalg.inv(can_to_al))
    hit = np.array([ref.state(x, y) for x, y in states])
    return small_scene.gaussians.transformed(t), states, hit


# state FP bound per map resolution on the small scene (measured 3.4 / 3.5 / 6.8 %); the old
# support bug (issue 49) put 95 % of the free states at 0.02 m in collision
COSTMAP_FP_BOUND = {0.02: 0.05, 0.05: 0.05, 0.10: 0.09}


def test_costmap_agrees_with_fcl_at_every_resolution(fcl_states):
    """End-to-end at 0.02, 0.05 and 0.10 m: 0 false negatives against the mesh, a bounded FP rate,
    and the supported and free areas the same across resolutions within a few percent (only the
    grid's own quantisation may move them)."""
    scene, states, hit = fcl_states
    emb = Embodiment()
    areas = {}
    for res, bound in COSTMAP_FP_BOUND.items():
        layers, info = build_costmap(scene, emb, CostmapConfig(resolution=res), VoxelizeConfig())
        assert info["free_area_m2"] > 10 and layers.support.any()
        ours_valid = Costmap.from_layers(layers).are_states_valid(states)
        assert not (ours_valid & hit).any(), res  # never accept a colliding pose
        fp = (~ours_valid & ~hit).sum() / (~hit).sum()
        assert fp <= bound, (res, fp)  # and rarely reject a free one
        areas[res] = info["supported_area_m2"], info["free_area_m2"]
    sup = np.array([a[0] for a in areas.values()])
    free = np.array([a[1] for a in areas.values()])
    assert sup.max() / sup.min() < 1.03, areas
    assert free.max() / free.min() < 1.05, areas


def test_ground_projection_covers_the_same_area_on_any_map_grid():
    """ground_on_map: a 0.05 m ground mask drawn onto 0.02, 0.05 and 0.10 m maps covers the same
    area up to one map cell around its border (known answer: a 1.0 x 0.5 m block)."""
    from stages.costmap.build import ground_on_map

    ground = np.zeros((40, 30), bool)  # [nx_s, ny_s] at 0.05 m: 2.0 x 1.5 m
    ground[10:30, 10:20] = True  # x 0.5-1.5 m, y 0.5-1.0 m
    for res in (0.02, 0.025, 0.05, 0.10):
        shape = (int(round(1.5 / res)), int(round(2.0 / res)))
        m = ground_on_map(ground, 0.05, res, shape)
        assert m.shape == shape
        area = m.sum() * res * res
        assert abs(area - 0.5) <= 2 * (1.0 + 0.5) * res + 1e-9, (res, area)
        ys, xs = np.nonzero(m)
        # the covered cells' centres lie within one map cell of the block
        assert ((xs + 0.5) * res).min() > 0.5 - res and ((xs + 0.5) * res).max() < 1.5 + res
        assert ((ys + 0.5) * res).min() > 0.5 - res and ((ys + 0.5) * res).max() < 1.0 + res
    assert np.array_equal(ground_on_map(ground, 0.05, 0.05, (30, 40)), ground.T)


@pytest.mark.gpu
def test_cuda_voxelizer_matches_numba(small_scene):
    torch = pytest.importorskip("torch")
    if not torch.cuda.is_available():
        pytest.skip("no CUDA device")
    from navcore.voxels.grid import grid_for_points

    g = small_scene.gaussians
    grid = grid_for_points(g.means, 0.05, margin=0.1)
    cpu = opacity_field(g, grid, VoxelizeConfig(), device="cpu")
    gpu = opacity_field(g, grid, VoxelizeConfig(), device="cuda")
    assert np.abs(gpu - cpu).max() < 0.02
    assert ((gpu >= 0.5) != (cpu >= 0.5)).mean() < 1e-3


def test_free_components_are_ranked_by_size():
    from stages.costmap.build import free_components

    free = np.zeros((10, 12), bool)
    free[1:3, 1:3] = True  # 4 cells, seen first
    free[5:9, 4:10] = True  # 24 cells
    free[1:3, 8:11] = True  # 6 cells
    lab = free_components(free)
    assert lab[6, 5] == 1 and lab[1, 9] == 2 and lab[1, 1] == 3 and (lab[~free] == 0).all()
    cm = Costmap(np.ones((10, 12), np.float32), (0.0, 0.0), 0.1, 0.1, 0.0, lab)
    assert list(cm.component_at(np.array([[0.55, 0.65], [0.15, 0.15], [-1.0, 0.0]]))) == [1, 3, 0]


def test_voxel_dbscan_gives_sklearns_labels():
    from sklearn.cluster import DBSCAN

    from navcore.voxels.cluster import voxel_dbscan

    rng = np.random.default_rng(3)
    contested = 0  # border points in reach of core points of two clusters (order decides)
    for eps, ms, density in [(0.15 / 0.05, 4, 0.05), (1.0, 2, 0.3), (1.5, 5, 0.2), (2.0, 1, 0.02), (2.5, 7, 0.1),
                             (1.5, 6, 0.15), (2.0, 9, 0.08)]:
        idx = np.argwhere(rng.random((24, 20, 10)) < density)
        db = DBSCAN(eps=eps, min_samples=ms).fit(idx.astype(np.float32))
        got = voxel_dbscan(idx, eps, ms)
        assert np.array_equal(got, db.labels_), (eps, ms)
        core = np.zeros(len(idx), bool)
        core[db.core_sample_indices_] = True
        d2 = ((idx[:, None] - idx[None]) ** 2).sum(-1)
        for i in np.flatnonzero(~core):
            contested += len(set(db.labels_[core & (d2[i] <= eps * eps)])) > 1
    assert contested > 0
    assert len(voxel_dbscan(np.zeros((0, 3), int), 2.0, 3)) == 0


def test_max_bound_is_conservative_and_tight_on_tall_voxels():
    """A_v >= the true max of rho inside every voxel (dense sampling), on 1 cm x 1 cm x 5 cm
    voxels, for a flat Gaussian tilted inside a vertical plane (the case where bounding each
    local axis separately leaks the voxel's height into horizontal directions)."""
    from navcore.gaussians.model import quat_to_rotmat, rotmat_to_quat

    ang = np.radians(40)
    t1 = np.array([np.cos(ang), 0, np.sin(ang)])  # tangent tilted in the x-z plane
    n = np.array([0, 1.0, 0])
    rot = np.stack([t1, np.cross(n, t1), n], 1)
    q = rotmat_to_quat(rot)[None]
    sig = np.array([0.03, 0.02, 0.002])
    g = GaussianScene(np.array([[0.003, 0.001, 0.012]]), q, np.log(sig)[None], [np.log(0.9 / 0.1)], np.zeros((1, 1, 3)))
    grid = VoxelGrid((-0.2, -0.05, -0.2), (0.01, 0.01, 0.05), (40, 10, 8))
    a = opacity_field(g, grid, VoxelizeConfig(sample="max", device="cpu"))
    # dense samples inside each voxel
    r = quat_to_rotmat(q.astype(float))[0]
    sub = (np.arange(6) + 0.5) / 6 - 0.5
    ox, oy, oz = np.meshgrid(sub * 0.01, sub * 0.01, sub * 0.05, indexing="ij")
    offs = np.stack([ox.ravel(), oy.ravel(), oz.ravel()], 1)
    cx, cy, cz = (grid.centers(k) for k in range(3))
    centres = np.stack(np.meshgrid(cx, cy, cz, indexing="ij"), -1)
    pts = centres[..., None, :] + offs  # [nx, ny, nz, S, 3]
    loc = (pts - g.means[0]) @ r / sig
    chi2 = (loc ** 2).sum(-1)
    dense = np.where(chi2 <= 9, 0.9 * np.exp(-chi2 / 2), 0).max(-1)
    assert (a >= dense - 1e-6).all()
    # and tighter than bounding each local axis by the whole voxel box
    w_box = 0.5 * np.abs(r).T @ np.array([0.01, 0.01, 0.05])
    d = (centres - g.means[0]) @ r
    chi_box = ((np.maximum(np.abs(d) - w_box, 0) / sig) ** 2).sum(-1)
    box = np.where(chi_box <= 9, 0.9 * np.exp(-chi_box / 2), 0)
    assert (a <= box + 1e-6).all() and ((box >= 0.5).sum() > (a >= 0.5).sum())


def test_margin_formula_of_the_design_note_is_the_code(project_root):
    """The formula stated in stages/costmap/design.md is the one interpolation_margin computes."""
    note = (project_root / "stages" / "costmap" / "design.md").read_text()
    line = next(s.strip() for s in note.splitlines() if s.strip().startswith("margin = "))
    expr, rho_expr = line.removeprefix("margin = ").split(",  rho = ")
    for h, r in [(0.05, 0.18), (0.05, 0.4), (0.02, 0.1), (0.1, 0.12)]:
        env = {"sqrt": np.sqrt, "max": max, "h": h, "r": r}
        env["rho"] = eval(rho_expr, env)  # noqa: S307 - our own design note
        assert eval(expr, env) == pytest.approx(interpolation_margin(h, r), rel=1e-12)


def test_margin_keeps_the_query_kernel_from_accepting_poses_closer_than_the_radius():
    """Worst case for bilinear interpolation of a distance field: isolated point obstacles (convex
    corners). The kernel's interpolated clearance never accepts (>= r + margin) a point whose true
    distance is below r; without the margin it would (the bound is needed, not vacuous)."""
    rng = np.random.default_rng(3)
    needed = 0
    for res, radius in [(0.05, 0.18), (0.05, 0.3), (0.1, 0.2), (0.05, 0.12)]:
        n = 60
        obstacles = rng.uniform(0.5, n * res - 0.5, (12, 2))
        centres = (np.arange(n) + 0.5) * res
        gx, gy = np.meshgrid(centres, centres)
        cells = np.stack([gx.ravel(), gy.ravel()], 1)
        dist = np.min(np.linalg.norm(cells[:, None] - obstacles[None], axis=2), 1).reshape(n, n)
        cm = Costmap(dist, (0.0, 0.0), res, radius, interpolation_margin(res, radius))
        pts = rng.uniform(res, (n - 1) * res, (300_000, 2))
        true = np.min(np.linalg.norm(pts[:, None] - obstacles[None], axis=2), 1)
        interp = cm.clearance_at(pts)
        assert not (cm.are_states_valid(pts) & (true < radius)).any()
        assert not ((interp >= radius + cm.margin) & (true < radius)).any()
        needed += int(((interp >= radius) & (true < radius)).sum())
    assert needed > 0


def _noise_scene():
    """Gaussians around a 3 x 3 m room walled 0.3 m deep on every side (see _walled_layers)."""
    rows = [  # centre, sigma (x, y, z), noise?
        ((1.5, 1.5, 0.88), (0.2, 0.2, 0.2), True),   # 0: a floater at the camera: hidden
        ((1.5, 1.5, 2.0), (0.1, 0.1, 0.1), True),    # 1: above the body band by more than 2 sigma
        ((1.5, 1.5, 1.2), (0.2, 0.2, 0.2), True),    # 2: above it, but reaching into it: hidden
        ((1.5, 1.5, 0.5), (0.1, 0.1, 0.1), False),   # 3: not noise (the map counted it)
        ((0.05, 0.05, 0.5), (0.01, 0.01, 0.01), True),  # 4: inside the wall
        ((0.45, 1.5, 0.5), (0.02, 0.02, 0.02), True),  # 5: 0.05 m from free space, clear of the wall: hidden
        ((0.45, 1.5, 0.5), (0.08, 0.08, 0.08), True),  # 6: the same place, its 2 sigma touch the wall: kept
        ((-5.0, 1.5, 0.5), (0.5, 0.5, 0.5), True),   # 7: off the map
        ((1.5, 1.5, 0.0), (0.3, 0.3, 0.01), True),   # 8: flat on the floor, under h_min
    ]
    a = np.log(0.9 / 0.1)
    g = GaussianScene(np.array([r[0] for r in rows]), np.tile([1.0, 0, 0, 0], (len(rows), 1)),
                      np.log([r[1] for r in rows]), np.full(len(rows), a), np.zeros((len(rows), 1, 3)))
    return g, np.array([r[2] for r in rows])


def _walled_layers():
    """The layers of a 3 x 3 m map whose cells closer than 0.3 m to its edge are obstacles
    (clearance and occupancy as build_costmap makes them, at the map resolution)."""
    from scipy import ndimage

    from stages.costmap.build import CostmapLayers, interpolation_margin

    res, n, emb = 0.05, 60, Embodiment()
    c = (np.arange(n) + 0.5) * res
    wall = (np.minimum(c, 3.0 - c)[:, None] < 0.3) | (np.minimum(c, 3.0 - c)[None] < 0.3)
    clearance = np.clip(ndimage.distance_transform_edt(~wall) * res - 0.5 * res, 0, None).astype(np.float32)
    margin = interpolation_margin(res, emb.radius)
    occ = clearance < emb.radius + margin
    return CostmapLayers((0.0, 0.0), res, wall, np.ones_like(wall), occ, clearance, (~occ).astype(np.int32),
                         emb.radius, margin)


def test_hidden_splats_known_answer():
    """Noise splats floating clear of obstacles whose 2-sigma extent meets the body space over free
    cells are hidden: the others (above the band, under it, in or touching the wall, counted by
    the map, off the map) stay."""
    from stages.costmap.build import hidden_splats

    g, noise = _noise_scene()
    assert hidden_splats(g, noise, _walled_layers(), Embodiment(), 2.0).tolist() == [0, 2, 5]
    assert hidden_splats(g, np.zeros(len(noise), bool), _walled_layers(), Embodiment(), 2.0).tolist() == []


def test_hidden_splats_use_the_rotated_extent():
    """A needle 0.05 m from free space: lying along x its 2-sigma extent (0.6 m) reaches the wall,
    turned upright it floats clear of it (the extent is per axis, from the covariance)."""
    from stages.costmap.build import hidden_splats

    a = np.log(0.9 / 0.1)
    s = np.log([[0.3, 0.01, 0.01]])
    lying = GaussianScene(np.array([[0.45, 1.5, 0.5]]), np.array([[1.0, 0, 0, 0]]), s, [a], np.zeros((1, 1, 3)))
    q = [np.cos(np.pi / 4), 0.0, np.sin(np.pi / 4), 0.0]  # 90 degrees about y: the long axis along z
    upright = GaussianScene(np.array([[0.45, 1.5, 0.5]]), np.array([q]), s, [a], np.zeros((1, 1, 3)))
    emb = Embodiment()
    assert hidden_splats(lying, np.array([True]), _walled_layers(), emb, 2.0).tolist() == []
    assert hidden_splats(upright, np.array([True]), _walled_layers(), emb, 2.0).tolist() == [0]


def test_camera_scene_leaves_out_the_stored_hidden_splats(tmp_path):
    """The costmap store's hidden indices round-trip, and camera_scene renders without them: a
    floater 0.25 m in front of the camera fills its view (median depth 0.36 m) in the whole scene
    and is gone from the camera's (the wall behind it at 2 m)."""
    from navcore.gaussians.content import camera_scene
    from navcore.io.datasets import CostmapDataset
    from navcore.render import Renderer
    from navcore.render.camera import embodiment_camera

    a = np.log(0.99 / 0.01)
    ys, zs = np.meshgrid(np.linspace(0.0, 3.0, 61), np.linspace(0.0, 2.0, 41))
    wall = np.c_[np.full(ys.size, 3.5), ys.ravel(), zs.ravel()]
    means = np.r_[wall, [[1.75, 1.5, 0.88]]]
    n = len(means)
    scales = np.r_[np.tile([0.01, 0.06, 0.06], (len(wall), 1)), [[0.3, 0.3, 0.3]]]
    gs = GaussianScene(means, np.tile([1.0, 0, 0, 0], (n, 1)), np.log(scales), np.full(n, a), np.zeros((n, 1, 3)))
    emb = Embodiment()
    store = CostmapDataset(tmp_path / "cm.zarr")
    with store.writing() as root:
        store.write_layers(root, emb, _walled_layers(), {}, hidden=np.array([n - 1]))

    class Catalog:  # the two datasets camera_scene reads
        def dataset(self, name, scene):
            return store if name == "costmaps" else type("A", (), {"load": lambda self, **kw: (gs, {})})()

    seen, attrs = camera_scene(Catalog(), None, emb.name)
    assert store.hidden(emb.name).tolist() == [n - 1] and len(seen.means) == n - 1 and attrs["hidden_splats"] == 1
    vm, k, w, h = embodiment_camera(emb, np.array([[1.5, 1.5, 0.0]]), 40, 30)
    full = np.median(Renderer(gs, "cpu").render(vm, k, w, h).depth.numpy())
    cam = np.median(Renderer(seen, "cpu").render(vm, k, w, h).depth.numpy())
    assert full < 0.5 and abs(cam - 2.0) < 0.05


def test_bench_spatial_costmap_overrides_are_typed_and_checked():
    """bench-spatial --costmap K=V: each value typed by CostmapConfig's schema; an unknown
    field, a missing '=', a value not of its type and --docs with a non-default setting are refused."""
    from benchmarks.map.spatial import costmap_overrides, main

    assert costmap_overrides(["evidence=surface", "noise_dense_count=30", "cell_evidence=true", "surface_min_reach=0.02"]) \
        == {"evidence": "surface", "noise_dense_count": 30, "cell_evidence": True, "surface_min_reach": 0.02}
    assert CostmapConfig(**costmap_overrides(["noise_dense_count=30"])).noise_dense_count == 30
    for bad in (["nonsense=1"], ["evidence"], ["noise_dense_count=abc"]):
        with pytest.raises(SystemExit, match="CostmapConfig field"):
            costmap_overrides(bad)
    with pytest.raises(SystemExit, match="not the default"):
        main(["--costmap", "evidence=surface", "--docs"])
