"""Costmap construction (DESIGN.md spatial layer, steps 3-5).

For an embodiment with radius r and body interval [h_min, h_max] above the floor:
- Floor layer: trained floors are thick, noisy and slightly uneven. A local floor height field
  (median height of the flat, horizontal Gaussians near z = 0 per ``floor_cell``) and its local
  spread give a floor layer per cell; Gaussians whose centre lies in it or below it (reflections
  under a shiny floor) are floor, never obstacles: a real obstacle rises above the floor and
  has Gaussians there.
- Faint Gaussians (opacity below ``min_obstacle_alpha``) are haze: trained scenes put large
  low-opacity Gaussians in front of surfaces to explain view-dependent colour, and many of them
  together would reach tau_occ in open air. A surface is made of opaque Gaussians.
- Isolated Gaussians (fewer than ``outlier_min_neighbours`` other non-floor centres within
  their own radius, max(``outlier_radius``, ``outlier_sigmas`` x their largest sigma), an exact
  k-d tree count) are reconstruction noise hovering over sparse floors, not objects. Everything
  else that reaches the body band is an obstacle.
- M_raw: a column is an obstacle when any voxel of it whose z-extent meets the body interval
  is occupied (A >= tau_occ) by the non-floor Gaussians. The body band is voxelized at a finer xy resolution
  (``raw_resolution``) than the stored map so obstacle boundaries are known to ~1 cm.
- M_sup: DBSCAN on the occupied voxels of the whole aligned field drops isolated clusters; the
  alpha shape (Delaunay triangles with circumradius <= alpha_radius) of the remaining voxels'
  ground projection is the supported domain.
- clearance: Euclidean distance from each map cell centre to the nearest obstacle (EDT on the
  fine raw grid), in metres; unsupported cells hold -1.
- M_occ = (clearance < r + margin) OR NOT M_sup, i.e. Dilate(M_raw, disk(r)) OR NOT M_sup with
  the dilation done exactly by the distance transform.
``margin`` bounds the error of bilinear interpolation of the clearance between cell centres
(h^2 (1 + sqrt2 h / rho) / (8 rho) with rho = max(r - h / sqrt2, h), h the map resolution; see
interpolation_margin), so the continuous query ``clearance(p) >= r + margin`` never accepts a
pose closer than r to an obstacle cell.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.spatial import Delaunay

from navcore.gaussians.model import GaussianScene
from navcore.nav.embodiment import Embodiment
from navcore.voxels import VoxelGrid, VoxelizeConfig, column_max_opacity, opacity_field
from navcore.voxels.cluster import voxel_dbscan
from stages.costmap.kernels import rasterize_triangles


@dataclass
class CostmapConfig:
    """Parameters of the costmap stage."""

    resolution: float = 0.05
    """Stored map cell size, metres."""
    raw_resolution: float = 0.005
    """Target xy cell size of the body-band voxelization that locates obstacle boundaries, metres
    (rounded so that an odd number of fine cells spans one map cell: 11 per 5 cm cell). The fast
    setting 0.01 (5 per cell) runs the fine pass 3-4x faster for under a point more state / motion
    FP against the mesh, FN 0 at all (the measurements: stages/costmap/design.md)."""
    z_resolution: float = 0.05
    """Voxel height in the body band, metres (evidence=voxel)."""
    evidence: str = "voxel"
    """How the body band's Gaussians make an obstacle column: voxel (a voxel of z_resolution whose
    accumulated opacity reaches tau_occ) | column (the opacity the whole band accumulates along the
    column, each Gaussian counted once at its largest density there: a table leg of a few
    half-transparent splats stacked up blocks, where no single 5 cm voxel of it reached tau_occ) |
    surface (evidence and place apart, each margin counted once: a Gaussian of the band (within
    surface_band_sigmas) is an obstacle when the band's Gaussians in its column of cell_evidence_size gather opacity
    1 - prod(1 - alpha) >= tau_occ, and the obstacle is where it is, its centre grown by
    surface_reach_sigmas standard deviations and at least surface_min_reach, not the extent its
    density and its neighbours' tails reach past the surface; with noise_dense_count, the sparse
    models' mode: docs/benchmarks/bench_density.md)."""
    surface_reach_sigmas: float = 0.0
    """evidence=surface: an obstacle Gaussian's footprint is its ellipsoid at this many standard
    deviations (0: its centre alone, grown by surface_min_reach)."""
    surface_flat_ratio: float = 0.0
    """evidence=surface: with surface_reach_sigmas, only the flat Gaussians (smallest / largest standard
    deviation below this ratio: a surfel, which stands for the patch of surface it spans) reach their
    ellipsoid; the others keep the smallest reach (0: every Gaussian reaches its ellipsoid). Big flat
    splats make the walls of some captures, big round ones the fuzz around a dense model's objects."""
    surface_reach_spacing: float = 0.0
    """evidence=surface: the smallest reach is this share of the obstacle splats' median spacing (the
    distance to their outlier_min_neighbours-th nearest), in place of surface_min_reach (0: that)."""
    surface_band_sigmas: float = 2.0
    """evidence=surface: a Gaussian is of the body band when its centre lies within this many of its z
    standard deviations of it (a 6 cm object's side splats, centred 3.5 cm up, reach a band from 5 cm)."""
    surface_min_reach: float = 0.01
    """evidence=surface: the footprint reaches at least this far from the centre along every axis,
    metres (what a centre can be off its surface; it joins splats a few cm apart)."""
    margin_xy: float = 0.5
    """Map border around the scene's Gaussians, metres."""
    extent_quantile: float = 0.1
    """Percentile (and 100 minus it) of Gaussian centres that bounds the map, so far strays do not."""
    dbscan_eps: float = 0.15
    """DBSCAN neighbourhood radius on occupied voxel centres, metres."""
    dbscan_min_samples: int = 4
    """DBSCAN core-point threshold."""
    min_cluster_fraction: float = 0.02
    """Clusters smaller than this share of the largest are dropped from the support."""
    alpha_radius: float = 0.3
    """Alpha-shape radius: Delaunay triangles with a larger circumradius are not supported, metres."""
    support_resolution: float = 0.05
    """Voxel size of the full-height field used for DBSCAN and the alpha shape, metres (the
    support needs no finer detail, and DBSCAN cost grows fast with resolution)."""
    support_z_min: float = -0.3
    """Occupied voxels below this height are ignored for the support, metres."""
    support_z_max: float = 3.0
    """Occupied voxels above this height are ignored for the support, metres."""
    floor_cell: float = 0.5
    """Cell of the local floor height field, metres."""
    floor_flat_ratio: float = 0.8
    """Gaussians define the local floor when their smallest scale is below this share of the middle one
    (and their normal is within 20 deg of vertical)."""
    floor_search: float = 0.15
    """Flat horizontal Gaussians within this height of z = 0 define the local floor, metres."""
    floor_max_step: float = 0.025
    """Largest height step between two neighbouring floor cells, metres. The local floor is the
    cells reached from the level floor (|height| <= this) through steps no larger; a flat
    horizontal surface standing higher (a platform, a low bed base, a sofa's underside where the
    floor under it is hidden) is not floor, however wide: its cells take the aligned floor's
    height, so it stays an obstacle. Without it a 0.8 m platform 6 cm high was floor, all its cells
    free (a 6 cm rise is above a body starting at 0.05 m)."""
    floor_layer_min: float = 0.03
    """Smallest half-thickness of the floor layer, metres. 0.02 held while trained floors came out
    tilted: a 0.67 deg tilt across a 0.5 m floor cell widened each cell's spread. Level (issue 46),
    the real hall's blurred floor streaks 4-10 cm up stood above a 2 cm layer and blocked free
    poses (render-check FP 1.8 -> 7.8 %); 0.03 took it to 4.8 % with its FN unchanged, the
    generated scenes' FP / FN unchanged (0.05 m, 3 x 1 M: none 1.99 %, moderate 2.25 %, FN 0), and
    the trained-scan room's FP / FN against the scan unchanged (8.1 % / 0.51 %)."""
    floor_layer_max: float = 0.06
    """Largest half-thickness of the floor layer (2.5 local spreads, clipped to [min, max]), metres:
    anything whose centre is higher is a potential obstacle."""
    outlier_radius: float = 0.1
    """Smallest radius of the isolated-Gaussian test, metres (0 disables it)."""
    outlier_sigmas: float = 2.0
    """A Gaussian's own radius of the isolated test is max(outlier_radius, outlier_sigmas x its
    largest standard deviation), at most outlier_radius_max: a sparse hall's thin objects (a
    rope, a pole, a sign) are made of few elongated splats spaced about their own length apart, a
    fixed 0.1 m finds none of their neighbours (0 keeps the fixed radius)."""
    outlier_radius_max: float = 0.5
    """Largest radius of the isolated test, metres."""
    outlier_floor_clearance: float = 0.1
    """Gaussians centred less than this above the floor layer's top keep the fixed outlier_radius,
    metres: a trained floor's blurred texture is made of long streak splats lying a few
    centimetres above it, which the size-aware radius would turn into obstacles."""
    outlier_density: float = 0.0
    """The isolated test's smallest radius grows with the scene's sparseness: at least this many
    times the median distance from a candidate to its outlier_min_neighbours-th nearest candidate
    (0 = the fixed outlier_radius). A pruned model of a room (81 k Gaussians where training gave
    600 k) spaces its surface splats 6 cm apart at the median, and a fixed 0.1 m found too few
    neighbours around a chair leg (docs/benchmarks/bench_density.md)."""
    cell_evidence: bool = False
    """Also gather the body band's opacity over the columns of cells of cell_evidence_size: a cell whose Gaussians together
    reach tau_occ holds an obstacle even where no fine cell of it did alone (a 6 cm cube of six splats
    of opacity 0.45: none reaches 0.5, together 0.97), placed at the fine cells those splats reach with
    at least cell_evidence_floor."""
    cell_evidence_size: float = 0.1
    """Side of the cells whose columns gather that evidence, metres (whatever the map's resolution)."""
    cell_evidence_share: float = 0.1
    """A fine cell of such a cell holds the obstacle when its own evidence is at least this share of the
    largest within cell_evidence_size of it."""
    cell_evidence_floor: float = 0.05
    """...and at least this opacity."""
    footprint_max_sigma: float = 0.0
    """Largest standard deviation a Gaussian's footprint on the obstacle grid is drawn with, metres
    (0 = its own): a large blob's density reaches past the surface it stands for, and that reach
    was counted as obstacle before the robot's radius was added on top (0 keeps the full extent)."""
    outlier_min_neighbours: int = 4
    """Non-floor Gaussians with fewer other centres within their radius are noise, not obstacles."""
    noise_dense_count: int = 0
    """The isolated test calls a Gaussian noise only where the model is dense around it: at least this
    many Gaussians of any kind (floor and itself included) within noise_dense_radius; where fewer, it stays an
    obstacle candidate (0: noise wherever isolated). Floor streaks and floaters hover over well
    reconstructed floors; in a sparse region a real low obstacle (a 5 cm object by a wall) is itself
    a few opaque splats too far apart for the test (trained ScanNet 3DGS: the isolated splats on the
    scan's surfaces had a median 41 Gaussians within 0.2 m, the ones more than 0.1 m from it 72)."""
    noise_dense_radius: float = 0.2
    """The radius of noise_dense_count, metres."""
    min_obstacle_alpha: float = 0.25
    """Gaussians with a lower opacity are never obstacles (haze of trained scenes; 0 keeps all).
    At synthetic.realism.level=moderate (1 M Gaussians) haze alone puts about a third of the free
    poses in collision without it (bench-spatial's realism table)."""
    hide_noise: bool = True
    """Hide from the robot's camera the floaters and isolated splats (opacity >= min_obstacle_alpha)
    that float clear of obstacles and whose extent meets the space its body may occupy
    (`hidden_splats`; stored per embodiment and left out by every renderer of the pipeline; the V1
    asset and the semantics stage keep all Gaussians)."""
    hide_noise_sigma: float = 2.0
    """That extent, in standard deviations along each axis."""
    extra_margin: float = 0.0
    """Added to the interpolation margin, metres (a safety buffer beyond the exact bound)."""
    embodiments: list[str] = field(default_factory=list)
    """Further embodiments (navcore/conf/embodiment/*.yaml names) to build maps for besides the main one."""


@dataclass
class CostmapLayers:
    """The layers of one embodiment's costmap. Arrays are [ny, nx] (row = y), cell (i, j) has
    centre origin + ((j + 0.5) res, (i + 0.5) res)."""

    origin: tuple[float, float]
    resolution: float
    raw: np.ndarray  # bool, body-band obstacle in the cell (any fine cell)
    support: np.ndarray  # bool
    occ: np.ndarray  # bool
    clearance: np.ndarray  # float32 metres; -1 where unsupported
    components: np.ndarray  # int32 label of each free cell's 8-connected free component (0 = occupied),
    # 1 = the largest; others are islands (a blocked room, the hollow inside of a tall cabinet)
    radius: float
    margin: float

    @property
    def shape(self) -> tuple[int, int]:
        return self.occ.shape


def interpolation_margin(res: float, radius: float) -> float:
    """Upper bound of the overestimate of bilinear interpolation of a Euclidean distance field
    at points closer than ``radius`` to an obstacle.

    The error is h^2 / 8 (fu-weighted f_xx(xi1) + fv-weighted f_yy(xi2)) <= h^2 / 8 (f_xx(xi1) +
    f_yy(xi2)) for two points of the patch. For the distance to the nearest obstacle point,
    f_xx = sin^2(theta) / rho and f_yy = cos^2(theta) / rho (theta the direction to it), and
    across a patch at distance >= rho the direction turns by at most sqrt2 h / rho, so the sum
    is <= (1 + sqrt2 h / rho) / rho. Only convex obstacle corners make the interpolation
    overestimate; the distance to a set is a minimum of such point distances and inherits the
    bound. rho >= radius - h / sqrt2 for a patch containing a point at distance < radius.
    """
    rho = max(radius - res / np.sqrt(2.0), res)
    return res * res * (1.0 + np.sqrt(2.0) * res / rho) / (8.0 * rho)


def supersample_factor(res: float, raw_res: float) -> int:
    """Odd number of fine cells per map cell, so map cell centres fall on fine cell centres."""
    s = max(1, int(round(res / raw_res)))
    return s if s % 2 == 1 else s + 1


def floor_layer(scene: GaussianScene, cfg: CostmapConfig) -> tuple[np.ndarray, np.ndarray, dict]:
    """[N] bool: Gaussians of the floor layer or below it (never obstacles), [N] the floor layer's
    top under each Gaussian (metres), and a summary.

    The local floor height is the median height of the flat, horizontal Gaussians within
    ``floor_search`` of z = 0 in each ``floor_cell`` (their main mode, `floor_mode`), kept where
    the cell is reached from the level floor through steps of at most ``floor_max_step``
    (3x3-cell median-filtered; 0 where none or not reached), the half-thickness 2.5 x their local
    robust spread about that mode, clipped to the configured range."""
    from navcore.gaussians.surfaces import horizontal_surfaces

    z = scene.means[:, 2].astype(np.float64)
    info_off = 0
    near = horizontal_surfaces(scene, cfg.floor_flat_ratio, 20.0) & (np.abs(z) < cfg.floor_search)
    cell = np.floor(scene.means[:, :2] / cfg.floor_cell).astype(np.int64)
    lo = cell.min(0)
    shape = tuple(cell.max(0) - lo + 1)
    idx = cell - lo
    height, spread = np.zeros(shape), np.full(shape, np.nan)
    if near.any():
        lin = np.ravel_multi_index(idx[near].T, shape)
        order = np.lexsort((z[near], lin))
        lin_s, z_s = lin[order], z[near][order]
        starts = np.r_[0, np.nonzero(np.diff(lin_s))[0] + 1]
        counts = np.diff(np.r_[starts, len(lin_s)])
        # the floor's own mode and spread: an obstacle's flat top in the same cell (a platform, a
        # sofa's underside 5-8 cm up beside the floor) is a second mode; the plain median and MAD
        # mixed both, and the layer thickened over that very obstacle
        med, mad = zip(*(floor_mode(z_s[a:a + c], cfg.floor_max_step) for a, c in zip(starts, counts)))
        med, mad = np.array(med), np.array(mad)
        ok = counts >= 5
        height.flat[lin_s[starts][ok]] = med[ok]
        spread.flat[lin_s[starts][ok]] = 1.4826 * mad[ok]
        off = ~reached_by_steps(height, np.isfinite(spread), cfg.floor_max_step)
        height[off], spread[off] = 0.0, np.nan
        info_off = int(off.sum())
        height = ndimage.median_filter(height, size=3, mode="nearest")
    typical = float(np.nanmedian(spread)) if np.isfinite(spread).any() else 0.0
    spread = np.where(np.isfinite(spread), spread, typical)
    half = np.clip(2.5 * spread, cfg.floor_layer_min, cfg.floor_layer_max)
    top = height[idx[:, 0], idx[:, 1]] + half[idx[:, 0], idx[:, 1]]
    mask = z <= top
    info = {"floor_gaussians": int((mask & (z >= -cfg.floor_search)).sum()), "below_floor": int((z < -cfg.floor_search).sum()),
            "floor_height_p5_p95_m": np.percentile(height[height != 0], [5, 95]).round(3).tolist()
            if (height != 0).any() else [0.0, 0.0],
            "floor_half_thickness_median_m": round(float(np.median(half)), 4),
            "raised_cells_not_floor": info_off}
    return mask, top, info


def floor_mode(z: np.ndarray, step: float, iterations: int = 4) -> tuple[float, float]:
    """(mode, MAD) of one floor cell's heights: from the median, the median of the heights within
    `step` of the last estimate, a few times (mean shift with a flat window, by medians: it goes to
    the cell's main mode and leaves a second one `step` away alone); the MAD of those within 2
    `step` of it."""
    m = float(np.median(z))
    for _ in range(iterations):
        near = z[np.abs(z - m) <= step]
        if not len(near):
            break
        m = float(np.median(near))
    d = np.abs(z - m)
    near = d[d <= 2.0 * step]
    return m, float(np.median(near if len(near) else d))  # none near: an even split of two modes


def reached_by_steps(height: np.ndarray, known: np.ndarray, max_step: float) -> np.ndarray:
    """[H, W] bool: the `known` cells reached from the level ones (|height| <= max_step) through
    8-neighbours whose heights differ by at most max_step (breadth-first)."""
    from collections import deque

    reached = known & (np.abs(height) <= max_step)
    queue = deque(map(tuple, np.argwhere(reached)))
    h, w = height.shape
    while queue:
        i, j = queue.popleft()
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                a, b = i + di, j + dj
                if 0 <= a < h and 0 <= b < w and known[a, b] and not reached[a, b] \
                        and abs(height[a, b] - height[i, j]) <= max_step:
                    reached[a, b] = True
                    queue.append((a, b))
    return reached


def obstacle_candidates(scene: GaussianScene, cfg: CostmapConfig) -> tuple[np.ndarray, dict]:
    """[N] bool: Gaussians that may be obstacles (not floor, not faint, not isolated noise), and a summary."""
    cand, _, info = obstacle_classes(scene, cfg)
    return cand, info


def obstacle_classes(scene: GaussianScene, cfg: CostmapConfig) -> tuple[np.ndarray, np.ndarray, dict]:
    """([N] obstacle candidates, [N] isolated noise: opaque enough, not floor, too few neighbours;
    a summary)."""
    floor, top, info = floor_layer(scene, cfg)
    faint = scene.alphas < cfg.min_obstacle_alpha
    cand = ~floor & ~faint
    isolated = np.zeros(len(cand), bool)
    info["faint_dropped"] = int((faint & ~floor).sum())
    if cfg.outlier_radius > 0 and cand.sum() > cfg.outlier_min_neighbours:
        idx = np.nonzero(cand)[0]
        base = max(cfg.outlier_radius, cfg.outlier_density * neighbour_spacing(scene.means[idx], cfg.outlier_min_neighbours)
                   if cfg.outlier_density > 0 else 0.0)
        info["outlier_radius_m"] = round(float(base), 4)
        radius = np.clip(cfg.outlier_sigmas * scene.scales[idx].max(1), base, max(base, cfg.outlier_radius_max))
        # near the floor, long splats are the floor's own streaks (trained floors' blurred texture)
        radius[scene.means[idx, 2] - top[idx] < cfg.outlier_floor_clearance] = base
        isolated[idx] = isolated_points(scene.means[idx], radius, cfg.outlier_min_neighbours)
        if cfg.noise_dense_count > 0 and isolated.any():
            from scipy.spatial import cKDTree

            alone = np.nonzero(isolated)[0]
            around = cKDTree(scene.means).query_ball_point(scene.means[alone], cfg.noise_dense_radius, return_length=True)
            sparse = alone[around < cfg.noise_dense_count]
            isolated[sparse] = False
            info["isolated_kept_sparse"] = len(sparse)
        cand &= ~isolated
        info["isolated_dropped"] = int(isolated.sum())
    return cand, isolated, info


def hidden_splats(scene: GaussianScene, noise: np.ndarray, layers: "CostmapLayers", emb: Embodiment,
                  k_sigma: float) -> np.ndarray:
    """Indices of the noise Gaussians (floaters, isolated splats: what the map left out) that float
    clear of every obstacle and reach the space the robot's body may occupy: the map's clearance at
    their centre's cell is at least their k_sigma extent across (per axis, from the covariance)
    plus half a cell diagonal, and that extent meets the body band [h_min, h_max] within radius +
    extent + half a cell diagonal of a free cell's centre. The robot drives through them, so its
    camera must not see them: a camera that passes through a 0.3 m opaque floater sees nothing
    else (docs/benchmarks/bench_blind_views.md). The clearance test keeps surface splats that a sparse
    scene's isolated rule calls noise (stages/costmap/design.md).

    Args:
        scene: all Gaussians of the aligned scene (the indices are into it).
        noise: [N] bool, the Gaussians the map treats as noise.
    """
    from navcore.gaussians.model import axis_sigmas

    idx = np.nonzero(noise)[0]
    free = ~layers.occ
    if not len(idx) or not free.any():
        return np.zeros(0, np.int64)
    sd = axis_sigmas(scene.quats[idx], scene.log_scales[idx])
    m = scene.means[idx].astype(np.float64)
    res = layers.resolution
    dist = ndimage.distance_transform_edt(~free) * res  # cell centre -> the nearest free cell centre
    j = np.floor((m[:, 0] - layers.origin[0]) / res).astype(np.int64)
    i = np.floor((m[:, 1] - layers.origin[1]) / res).astype(np.int64)
    inside = (i >= 0) & (j >= 0) & (i < free.shape[0]) & (j < free.shape[1])
    d = np.full(len(idx), np.inf)
    d[inside] = dist[i[inside], j[inside]]
    c = np.full(len(idx), -1.0)
    c[inside] = layers.clearance[i[inside], j[inside]]
    half = res / np.sqrt(2.0)  # a centre lies within this of its cell's centre
    sxy = k_sigma * np.maximum(sd[:, 0], sd[:, 1])
    # floating: its extent touches no obstacle (a surface splat the noise rule missed, on a wall
    # next to free space, stays); reaching: its extent meets the body band within the radius of a
    # free cell
    floating = c >= sxy + half
    reach = d <= emb.radius + sxy + half
    hit = floating & reach & (m[:, 2] + k_sigma * sd[:, 2] >= emb.h_min) & (m[:, 2] - k_sigma * sd[:, 2] <= emb.h_max)
    return idx[hit].astype(np.int64)


def neighbour_spacing(points: np.ndarray, k: int, sample: int = 50_000) -> float:
    """Median distance from a point to its k-th nearest other point (on an evenly strided sample of
    at most `sample` points, against all of them): the scene's surface spacing."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, np.float64)
    if len(pts) <= k:
        return 0.0
    probe = pts[::max(1, len(pts) // sample)]
    d, _ = cKDTree(pts).query(probe, k=k + 1)
    return float(np.median(d[:, -1]))


def isolated_points(points: np.ndarray, radius, min_neighbours: int) -> np.ndarray:
    """[N] bool: points with fewer than ``min_neighbours`` other points within ``radius`` (a scalar
    or one per point; exact: a k-d tree query of the min_neighbours + 1 nearest within the
    smallest radius, then a count within their own radius for the points that query left alone)."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, np.float64)
    if len(pts) == 0:
        return np.zeros(0, bool)
    radius = np.broadcast_to(np.asarray(radius, np.float64), (len(pts),))
    tree = cKDTree(pts)
    d, _ = tree.query(pts, k=min_neighbours + 1, distance_upper_bound=float(radius.min()))
    alone = ~np.isfinite(d.reshape(len(pts), -1)[:, -1])  # the farthest of the k is beyond the radius
    wider = np.flatnonzero(alone & (radius > radius.min()))
    if len(wider):
        alone[wider] = tree.query_ball_point(pts[wider], radius[wider], return_length=True) < min_neighbours + 1
    return alone


def map_extent(scene: GaussianScene, cfg: CostmapConfig) -> tuple[tuple[float, float], tuple[int, int]]:
    """Map origin (x, y) and shape (ny, nx) covering the scene's (content) Gaussians plus a margin."""
    q = cfg.extent_quantile
    lo, hi = np.percentile(scene.means[:, :2], [q, 100 - q], axis=0)
    res = cfg.resolution
    lo = np.floor((lo - cfg.margin_xy) / res) * res
    hi = np.ceil((hi + cfg.margin_xy) / res) * res
    n = np.maximum(np.round((hi - lo) / res).astype(int), 1)
    return (float(lo[0]), float(lo[1])), (int(n[1]), int(n[0]))


def raw_obstacles_fine(scene: GaussianScene, origin, shape, s: int, emb: Embodiment, cfg: CostmapConfig,
                       vcfg: VoxelizeConfig) -> np.ndarray:
    """Fine [ny*s, nx*s] bool: body-band obstacle per fine cell (voxel z-layers start at h_min)."""
    res_f = cfg.resolution / s
    if cfg.evidence == "surface":
        return surface_obstacles_fine(scene, origin, shape, s, emb, cfg, vcfg)
    if cfg.evidence == "column":  # one voxel spans the band: each Gaussian's largest density over it, once
        dz, nz = emb.h_max - emb.h_min, 1
    elif cfg.evidence == "voxel":
        dz, nz = cfg.z_resolution, max(1, int(np.ceil((emb.h_max - emb.h_min) / cfg.z_resolution - 1e-9)))
    else:
        raise ValueError(f"costmap.evidence={cfg.evidence!r}; choose voxel | column | surface")
    grid = VoxelGrid((origin[0], origin[1], emb.h_min), (res_f, res_f, dz), (shape[1] * s, shape[0] * s, nz))
    if cfg.footprint_max_sigma > 0:
        scene = GaussianScene(scene.means, scene.quats, np.minimum(scene.log_scales, np.float32(np.log(cfg.footprint_max_sigma))),
                              scene.opacity_logits, scene.sh[:, :1])
    a = column_max_opacity(scene, grid, vcfg)  # [nx_f, ny_f]
    fine = a >= vcfg.tau_occ
    if cfg.cell_evidence:
        # the same evidence gathered over each map cell's whole column (each Gaussian once, at its largest
        # density in the cell): a cell whose few half-transparent splats reach tau_occ together holds an
        # obstacle, located at the fine cells where those splats' own density is (> cell_evidence_floor)
        size = cfg.cell_evidence_size
        nxf, nyf = a.shape
        held = np.zeros_like(fine)
        for shift in (0.0, 0.5 * size):  # two grids, the second offset by half a cell: an object on a cell
            # boundary gathers its splats whole in one of them
            nc = (int(np.ceil(nxf * res_f / size)) + 1, int(np.ceil(nyf * res_f / size)) + 1)
            coarse = VoxelGrid((origin[0] - shift, origin[1] - shift, emb.h_min), (size, size, emb.h_max - emb.h_min),
                               (nc[0], nc[1], 1))
            cell = column_max_opacity(scene, coarse, vcfg) >= vcfg.tau_occ  # [ncx, ncy]
            ix = np.minimum(((np.arange(nxf) + 0.5) * res_f + shift) / size, nc[0] - 1).astype(np.int64)
            iy = np.minimum(((np.arange(nyf) + 0.5) * res_f + shift) / size, nc[1] - 1).astype(np.int64)
            held |= cell[np.ix_(ix, iy)]
        # placed where those splats are: the fine cells holding at least cell_evidence_share of the largest
        # evidence within the cell's reach (their cores, not the fringe their densities taper off in)
        peak = ndimage.maximum_filter(a, size=int(np.ceil(size / res_f)) | 1, mode="nearest")
        fine |= held & (a >= cfg.cell_evidence_share * peak) & (a >= cfg.cell_evidence_floor)
    return fine.T


def surface_admitted(scene: GaussianScene, emb: Embodiment, size: float, tau: float, band_sigmas: float) -> np.ndarray:
    """[N] bool: Gaussians of the body band (their centre within band_sigmas z standard deviations of
    it) whose column of `size` cells (in either of two grids, the second offset by half a cell, so
    that an object on a cell boundary is gathered whole in one) gathers 1 - prod(1 - alpha) >= tau
    over the band's Gaussians: the evidence of evidence=surface, each Gaussian counted once with its
    own opacity, wherever its tails reach."""
    from navcore.gaussians.model import axis_sigmas

    m = scene.means.astype(np.float64)
    sz = band_sigmas * axis_sigmas(scene.quats, scene.log_scales)[:, 2] if band_sigmas > 0 else 0.0
    band = np.nonzero((m[:, 2] + sz >= emb.h_min) & (m[:, 2] - sz <= emb.h_max))[0]
    ok = np.zeros(len(m), bool)
    if not len(band):
        return ok
    log_clear = np.log1p(-np.clip(scene.alphas[band].astype(np.float64), 0.0, 1.0 - 1e-6))
    for shift in (0.0, 0.5 * size):
        c = np.floor((m[band, :2] + shift) / size).astype(np.int64)
        c -= c.min(0)
        lin = c[:, 0] * (int(c[:, 1].max()) + 1) + c[:, 1]
        ok[band] |= -np.expm1(np.bincount(lin, weights=log_clear)[lin]) >= tau
    return ok


def surface_obstacles_fine(scene: GaussianScene, origin, shape, s: int, emb: Embodiment, cfg: CostmapConfig,
                           vcfg: VoxelizeConfig) -> np.ndarray:
    """Fine [ny*s, nx*s] bool of evidence=surface: the footprints (ellipsoids at surface_reach_sigmas,
    each axis at least surface_min_reach) of the surface_admitted Gaussians, rasterized exactly on the
    fine cells (the voxel kernel with opacity 1 and a one-sigma support)."""
    from dataclasses import replace

    g = scene.subset(surface_admitted(scene, emb, cfg.cell_evidence_size, vcfg.tau_occ, cfg.surface_band_sigmas))
    if cfg.surface_reach_sigmas > 0:
        log_reach = g.log_scales.astype(np.float64) + np.log(cfg.surface_reach_sigmas)
        if cfg.surface_flat_ratio > 0:
            ls = g.log_scales.astype(np.float64)
            round_ = ls.min(1) - ls.max(1) >= np.log(cfg.surface_flat_ratio)
            log_reach[round_] = -np.inf
    else:
        log_reach = np.full(g.log_scales.shape, -np.inf)
    reach = cfg.surface_min_reach
    if cfg.surface_reach_spacing > 0 and len(g.means) > cfg.outlier_min_neighbours:
        reach = cfg.surface_reach_spacing * neighbour_spacing(g.means, cfg.outlier_min_neighbours)
    log_reach = np.maximum(log_reach, np.log(max(reach, 1e-4)))
    foot = GaussianScene(g.means, g.quats, log_reach.astype(np.float32), np.full(len(g.means), 20.0, np.float32),
                         g.sh[:, :1])
    res_f = cfg.resolution / s
    grid = VoxelGrid((origin[0], origin[1], emb.h_min), (res_f, res_f, emb.h_max - emb.h_min), (shape[1] * s, shape[0] * s, 1))
    a = column_max_opacity(foot, grid, replace(vcfg, truncation=1.0, min_alpha=1e-6))
    return (a > 0.1).T  # inside a footprint the density is at least exp(-1/2); outside it, none


def support_mask(scene: GaussianScene, origin, shape, cfg: CostmapConfig, vcfg: VoxelizeConfig) -> tuple[np.ndarray, dict]:
    """M_sup [ny, nx] from DBSCAN + alpha shape of the aligned occupied voxels."""
    res = cfg.support_resolution
    nz = max(1, int(np.ceil((cfg.support_z_max - cfg.support_z_min) / res)))
    extent_xy = (shape[1] * cfg.resolution, shape[0] * cfg.resolution)
    nxy = (int(np.ceil(extent_xy[0] / res)), int(np.ceil(extent_xy[1] / res)))
    grid = VoxelGrid((origin[0], origin[1], cfg.support_z_min), (res, res, res), (nxy[0], nxy[1], nz))
    occ = opacity_field(scene, grid, vcfg) >= vcfg.tau_occ
    idx = np.argwhere(occ)  # (ix, iy, iz), lexicographic: deterministic
    info = {"occupied_voxels": int(len(idx))}
    sup = np.zeros(shape, dtype=bool)
    if len(idx) < 3:
        return sup, info
    labels = voxel_dbscan(idx, cfg.dbscan_eps / res, cfg.dbscan_min_samples)  # = sklearn's DBSCAN
    counts = np.bincount(labels[labels >= 0]) if (labels >= 0).any() else np.zeros(0, int)
    if len(counts) == 0:
        return sup, info
    keep_lab = np.nonzero(counts >= cfg.min_cluster_fraction * counts.max())[0]
    kept = idx[np.isin(labels, keep_lab)]
    info.update(clusters=int(len(counts)), kept_clusters=int(len(keep_lab)), dropped_voxels=int(len(idx) - len(kept)))
    ground = np.zeros(nxy, bool)
    ground[kept[:, 0], kept[:, 1]] = True
    sup |= ground_on_map(ground, res, cfg.resolution, shape)
    # the alpha shape of the projection's edge cells (those with a 4-neighbour outside it): a
    # Delaunay triangle of all cells whose vertices are edge cells is one of the edge cells'
    # (removing points keeps a triangle's empty circle empty), and the triangles with an inner
    # vertex lie among the ground squares already set; 25 k triangles instead of 932 k for the real hall
    edge = ground & ~ndimage.binary_erosion(ground, structure=[[0, 1, 0], [1, 1, 1], [0, 1, 0]], border_value=0)
    pts = (np.argwhere(edge) + 0.5) * res
    if len(pts) >= 3:
        tri = Delaunay(pts)
        p = pts[tri.simplices]  # [T, 3, 2]
        a = np.linalg.norm(p[:, 1] - p[:, 2], axis=1)
        b = np.linalg.norm(p[:, 0] - p[:, 2], axis=1)
        c = np.linalg.norm(p[:, 0] - p[:, 1], axis=1)
        cross = np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                       - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
        with np.errstate(divide="ignore", invalid="ignore"):
            circ = a * b * c / (2.0 * cross)
        keep = np.isfinite(circ) & (circ <= cfg.alpha_radius)
        rasterize_triangles(np.ascontiguousarray(p[keep] / cfg.resolution - 0.5), sup)
        info["alpha_triangles"] = int(keep.sum())
    return sup, info


def ground_on_map(ground: np.ndarray, res_s: float, res: float, shape: tuple[int, int]) -> np.ndarray:
    """[ny, nx] map cells covered by the ground projection ``ground`` ([nx_s, ny_s] squares of
    side ``res_s``, sharing the map's origin), whatever the two cell sizes: a map cell is covered
    when its centre lies in a ground square (map cells no larger than the squares) or when it
    holds the centre of one (larger map cells). Marking only the map cell under each square's
    centre, right when the sizes are equal, leaves all but one in (res_s / res)^2 of a finer
    map's cells out (issue 49: at 0.02 m the support kept 19 of 114 m2)."""
    ny, nx = shape
    if res <= res_s * (1 + 1e-9):
        ix = np.minimum(((np.arange(nx) + 0.5) * res / res_s).astype(np.int64), ground.shape[0] - 1)
        iy = np.minimum(((np.arange(ny) + 0.5) * res / res_s).astype(np.int64), ground.shape[1] - 1)
        return ground[np.ix_(ix, iy)].T.copy()
    out = np.zeros(shape, bool)
    cells = np.argwhere(ground)
    mc = np.minimum(((cells + 0.5) * res_s / res).astype(np.int64), [nx - 1, ny - 1])
    out[mc[:, 1], mc[:, 0]] = True
    return out


def free_components(free: np.ndarray) -> np.ndarray:
    """8-connected components of free cells, relabelled by decreasing size (ties: first cell in
    row-major order), so label 1 is the largest. 0 marks occupied cells."""
    lab, n = ndimage.label(free, structure=np.ones((3, 3)))
    if n == 0:
        return lab.astype(np.int32)
    sizes = np.bincount(lab.ravel())[1:]
    order = np.lexsort((np.arange(n), -sizes))  # stable: size desc, then label (first seen)
    remap = np.zeros(n + 1, np.int32)
    remap[order + 1] = np.arange(1, n + 1, dtype=np.int32)
    return remap[lab]


def build_costmap(scene: GaussianScene, emb: Embodiment, cfg: CostmapConfig, vcfg: VoxelizeConfig,
                  support: tuple[np.ndarray, dict] | None = None, extent=None,
                  candidates: tuple[np.ndarray, dict] | None = None) -> tuple[CostmapLayers, dict]:
    """All layers of one embodiment's costmap from aligned Gaussians (z up, floor at z = 0).

    Args:
        support: a precomputed (M_sup, info) for this extent (shared between embodiments).
        extent: a precomputed map_extent.
        candidates: precomputed obstacle_candidates of the scene (shared between embodiments).
    """
    origin, shape = extent or map_extent(scene, cfg)
    s = supersample_factor(cfg.resolution, cfg.raw_resolution)
    cand, finfo = candidates if candidates is not None else obstacle_candidates(scene, cfg)
    fine = raw_obstacles_fine(scene.subset(cand), origin, shape, s, emb, cfg, vcfg)
    res_f = cfg.resolution / s
    if fine.any():
        dist_f = ndimage.distance_transform_edt(~fine) * res_f
    else:
        dist_f = np.full(fine.shape, np.inf)
    c = s // 2
    # distance from a map cell centre to the nearest obstacle fine cell's centre, minus half its
    # diagonal: the obstacle may reach the cell's nearest corner. Half a side (before issue 62) let
    # poses up to 0.21 fine cells inside the exact disk go free (0.6 mm at 0.02 m, measured)
    clearance = np.clip(dist_f[c::s, c::s] - res_f / np.sqrt(2.0), 0.0, 1e3).astype(np.float32)
    raw = fine.reshape(shape[0], s, shape[1], s).any(axis=(1, 3))
    sup, sinfo = support if support is not None else support_mask(scene, origin, shape, cfg, vcfg)
    clearance[~sup] = -1.0
    margin = interpolation_margin(cfg.resolution, emb.radius) + cfg.extra_margin
    occ = (clearance < emb.radius + margin) | ~sup
    free = ~occ
    components = free_components(free)
    n_comp = int(components.max())
    layers = CostmapLayers(origin, cfg.resolution, raw, sup, occ, clearance, components, emb.radius, margin)
    info = {"shape": list(shape), "origin": list(origin), "supersample": s, "margin_m": float(margin),
            "free_cells": int(free.sum()), "free_area_m2": float(free.sum() * cfg.resolution ** 2),
            "main_component_area_m2": float((components == 1).sum() * cfg.resolution ** 2),
            "supported_area_m2": float(sup.sum() * cfg.resolution ** 2), "free_components": int(n_comp),
            "support": sinfo, "floor": finfo}
    return layers, info


GAP_WIDTHS = tuple(np.arange(0.3, 2.05, 0.05))
"""Required widths tried by doorway_gaps, metres."""


def doorway_gaps(clearance: np.ndarray, res: float, min_area_m2: float = 2.0,
                 widths=GAP_WIDTHS) -> list[float]:
    """Widths (metres) of the narrowest doorway-like gaps: growing the required width w, the
    supported free space {clearance >= w / 2} splits into more regions of at least min_area_m2 at
    each width that closes a passage between two such regions. Returns the widths at which the
    count of such regions grew (narrowest first); empty for a single open space."""
    out, prev = [], None
    min_cells = min_area_m2 / (res * res)
    for w in widths:
        lab, n = ndimage.label(clearance >= w / 2)
        big = int((np.bincount(lab.ravel())[1:] >= min_cells).sum()) if n else 0
        if prev is not None and big > prev:
            out.append(round(float(w), 2))
        prev = big
    return out


SCALE_PLAUSIBLE = {"floor_to_ceiling_m": (1.8, 20.0), "narrowest_gap_m": (0.45, 5.0)}


def scale_warnings(floor_to_ceiling: float | None, gaps: list[float]) -> list[str]:
    """Warnings when a scene's measures are implausible for metres (wrong units: ingest.scale)."""
    out = []
    lo, hi = SCALE_PLAUSIBLE["floor_to_ceiling_m"]
    if floor_to_ceiling is not None and not lo <= floor_to_ceiling <= hi:
        out.append(f"floor-to-ceiling height {floor_to_ceiling:.2f} m is outside {lo}-{hi} m: are the scene's units "
                   f"metres? (ingest.scale fixes them)")
    lo, hi = SCALE_PLAUSIBLE["narrowest_gap_m"]
    if gaps and max(gaps) < lo:  # narrow passages exist (between cases, furniture); no door at all does not
        out.append(f"every doorway-like gap is narrower than {lo} m (widest {max(gaps):.2f} m): are the scene's "
                   f"units metres? (ingest.scale fixes them)")
    return out
