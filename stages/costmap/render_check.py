"""A check of a costmap that needs no ground truth: the scene shows what the robot would touch, and
the costmap says where it may go; on a real scene they must agree.

For each sampled pose, rays leave the robot's axis at heights spread over the body band [h_min,
h_max] (`RenderCheckConfig.ray_heights`), all around (``azimuths``) and within
``max_elevation_deg`` of horizontal; each ray's hit is where its accumulated opacity first
reaches ``min_alpha``, every Gaussian evaluated at its maximum response along that ray
(`navcore.render.ray_hits`: per-ray depth, not a rasterizer's one depth per splat, which read
oblique splats near the camera short and needed a calibrated correction). The nearest hit inside
the body band (from ``floor_guard`` above h_min) gives the pose's visible clearance (horizontal
distance, metres). The band is measured from the floor under the robot (`local_floor`: a plane
through vertical rays' hits around the pose; low hits checked against the floor beneath them),
not from z = 0: trained floors are uneven and thick, and the costmap's floor layer follows them
the same way. The scene is the aligned content (what ingest called floaters is not geometry).
Only Gaussians within ``crop_m`` of the pose whose vertical extent (3 sigma) reaches into the
band and whose opacity is at least ``min_splat_alpha`` take part: what lies wholly below or
above the band can neither be touched nor hide anything the band holds from a ray that starts in
it, and haze and floaters accumulate along a ray into a fog no body would touch (the costmap
ignores them the same way). A pose is blocked by the render when its visible clearance is below
the robot radius, blocked by the costmap when its clearance query says so; the estimated rates are
  FP = costmap-blocked and render-free / render-free,  FN = costmap-free and render-blocked / render-blocked,
the definitions bench-spatial uses against the mesh, each with a 95 % Wilson interval from the
number of poses. What no ray reaches (hidden behind a nearer surface) the estimate cannot know;
bench-real validates it on synthetic scenes against the mesh at the same poses
(stages/costmap/design.md has the figures).

`direct_evidence` is the plainest independent look: the opaque Gaussians whose centres lie inside
the body cylinder at a pose. bench-real reports its FN beside the render check's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class RenderCheckConfig:
    """The render-based costmap check."""

    poses: int = 300
    """Poses sampled per scene (uniform over the supported region of the costmap)."""
    heights: list[float] | None = None
    """Ray origins on the robot's axis, metres above the floor; None: from the body (`ray_heights`)."""
    azimuths: int = 192
    """Rays around the axis per height (1.875 degrees apart)."""
    max_elevation_deg: float = 35.0
    """Rays up to this angle above / below horizontal, at the azimuths' angular step."""
    floor_guard: float = 0.05
    """Hits count from this height above h_min, metres."""
    min_splat_alpha: float = 0.25
    """Splats fainter than this are left out: haze and floaters accumulate along a ray into a fog
    that no body would touch (the costmap ignores them the same way)."""
    min_alpha: float = 0.5
    """A ray hits a surface where its accumulated opacity reaches this."""
    floor_step: float = 0.06
    """The floor under a hit may lie this far above or below the pose's floor plane, metres (the
    costmap's floor layer reaches as far: floor_layer_max)."""
    floor_search: float = 0.15
    """The floor under the robot (`local_floor`) is trusted within this distance of z = 0, metres."""
    bin_m: float = 0.01
    """Depth resolution of the hits, metres."""
    crop_m: float = 1.0
    """Only Gaussians within this horizontal distance of a pose take part, metres: the check asks
    whether a surface lies within the robot radius, and whatever could hide such a surface is
    nearer still, so the crop changes nothing below it."""
    seed: int = 0
    """Pose sampling seed."""

    def ray_heights(self, emb) -> np.ndarray:
        """The rays' origins, metres. The lowest sits r tan(max elevation) above the first height
        hits count from, so the steepest downward rays reach that height at the robot radius and
        no nearer: a rough floor's fringe (its splats' tails, which a grazing ray accumulates into
        an apparent surface several centimetres up) then stays outside the footprint. The highest
        sits as far below h_max, and the ones between are spaced at most 2 r tan(max elevation)
        apart, so that at the robot radius their rays together cover the band."""
        if self.heights is not None:
            return np.asarray(self.heights, np.float64)
        reach = emb.radius * np.tan(np.radians(self.max_elevation_deg))
        lo, hi = emb.h_min + self.floor_guard + reach, emb.h_max - reach
        if hi <= lo:
            return np.array([0.5 * (lo + hi)])
        return np.linspace(lo, hi, int(np.ceil((hi - lo) / (2 * reach))) + 1)

    def elevations(self) -> int:
        """Rows of elevation: the azimuths' angular step over +- max_elevation_deg."""
        return max(1, int(round(2 * self.max_elevation_deg / (360.0 / self.azimuths))))


def local_gaussians(scene, xy: np.ndarray, crop: float, z_lo: float, z_hi: float,
                    min_alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """(offsets [P + 1], index [M]): per pose, the Gaussians within ``crop`` horizontally whose
    vertical 3-sigma extent meets [z_lo, z_hi] and whose opacity is at least min_alpha (CSR)."""
    from scipy.spatial import cKDTree

    from navcore.gaussians.model import axis_sigmas

    sz = axis_sigmas(scene.quats, scene.log_scales)[:, 2]
    z = scene.means[:, 2]
    cand = np.flatnonzero((scene.alphas >= min_alpha) & (z + 3 * sz >= z_lo) & (z - 3 * sz <= z_hi))
    lists = cKDTree(scene.means[cand, :2]).query_ball_point(np.asarray(xy, float), crop) if len(cand) else \
        [[] for _ in range(len(xy))]
    index = [cand[np.sort(np.asarray(n, np.int64))] for n in lists]
    offsets = np.concatenate([[0], np.cumsum([len(i) for i in index])]).astype(np.int64)
    return offsets, (np.concatenate(index) if index else np.zeros(0, np.int64)).astype(np.int64)


def hit_backend(backend: str = "auto") -> str:
    """'cpu' (numba) or 'cuda' (PyTorch on the GPU); auto: CUDA when torch sees one."""
    if backend not in ("auto", "cpu", "cuda"):
        raise ValueError(f"render check backend {backend!r}: choose auto, cpu or cuda")
    if backend == "auto":
        import torch

        return "cuda" if torch.cuda.is_available() else "cpu"
    return backend


def _hit_depth(backend: str, scene, centres, offsets, index, *args) -> np.ndarray:
    """`panorama_hit_depth_*` on the rows of the scene that index uses (their arrays built and,
    for CUDA, moved once, not the whole scene's)."""
    from navcore.render.ray_hits import panorama_hit_depth_cpu, panorama_hit_depth_torch, ray_gaussians

    rows, local = np.unique(index, return_inverse=True)
    g = ray_gaussians(scene.subset(rows))
    f = panorama_hit_depth_cpu if hit_backend(backend) == "cpu" else panorama_hit_depth_torch
    return f(g, centres, offsets, local.reshape(-1).astype(np.int64), *args)


def _down_depth(backend: str, scene, centres, offsets, index, far: float, cfg: RenderCheckConfig) -> np.ndarray:
    """[G, C] hit depth of the rays cast straight down from centres [G, C, 3] (`_hit_depth`)."""
    return _hit_depth(backend, scene, centres, offsets, index, 1, 1, -np.pi / 2, -np.pi / 2 + 1e-3, 0.0, far,
                      cfg.bin_m, cfg.min_alpha)[:, :, 0, 0]


VERIFY = 32  # low hits whose floor is looked at per pose and round
FLOOR_RINGS = ((0.0, 1), (0.15, 6), (0.3, 12), (0.45, 18))  # (radius m, points) of the floor's vertical rays


def local_floor(scene, xy: np.ndarray, emb, cfg: RenderCheckConfig, backend: str = "auto") -> np.ndarray:
    """[P, 3] the floor around each pose as a plane z = a + b (x - x0) + c (y - y0): vertical rays
    cast down from floor_search + h_min at the pose and on rings of 0.15, 0.3 and 0.45 m, each
    ray's hit (accumulated opacity min_alpha) kept when within floor_search of z = 0 (not a table
    top, not a hole), then a least-squares plane refitted twice without the hits more than 3 cm
    off it (a box on the floor, a pile of splats); the median height with fewer than 6 hits, and 0
    with none. Trained floors are uneven and thick (a hall's floor rises and sinks 10 cm where its
    splats pile up); the body band is measured from the floor under the robot, as the costmap's
    floor layer follows its local floor."""

    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    pts = np.concatenate([r * np.c_[np.cos(2 * np.pi * np.arange(n) / n), np.sin(2 * np.pi * np.arange(n) / n)]
                          for r, n in FLOOR_RINGS])
    top = cfg.floor_search + emb.h_min
    offsets, index = local_gaussians(scene, xy, FLOOR_RINGS[-1][0] + 0.3, -2 * cfg.floor_search, top,
                                     cfg.min_splat_alpha)
    centres = np.concatenate([xy[:, None, :] + pts[None], np.full((len(xy), len(pts), 1), top)], 2)
    z = top - _down_depth(backend, scene, centres, offsets, index, top + 2 * cfg.floor_search, cfg)  # -inf: no hit
    out = np.zeros((len(xy), 3))
    design = np.c_[np.ones(len(pts)), pts]
    for i in range(len(xy)):
        ok = np.abs(z[i]) <= cfg.floor_search
        if ok.sum() >= 6:
            coef = np.linalg.lstsq(design[ok], z[i, ok], rcond=None)[0]
            for _ in range(2):  # refitted without the hits 3 cm off the plane
                ok &= np.abs(design @ coef - z[i]) <= 0.03
                coef = np.linalg.lstsq(design[ok], z[i, ok], rcond=None)[0]
            out[i] = coef
        elif ok.any():
            out[i, 0] = np.median(z[i, ok])
    return out


def floor_height(floor: np.ndarray, xy: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Height of the floor planes ([P, 3], `local_floor`) of poses xy [P, 2] at points q [P, ..., 2]."""
    d = q - xy.reshape((len(xy),) + (1,) * (q.ndim - 2) + (2,))
    f = floor.reshape((len(floor),) + (1,) * (q.ndim - 2) + (3,))
    return f[..., 0] + f[..., 1] * d[..., 0] + f[..., 2] * d[..., 1]


def visible_clearance(scene, xy: np.ndarray, emb, cfg: RenderCheckConfig, backend: str = "auto",
                      floor: np.ndarray | None = None) -> np.ndarray:
    """[P] horizontal distance (metres) from each pose to the nearest hit inside the body band
    above the floor under it (inf where none is seen within crop_m).

    Args:
        scene: the renderable GaussianScene (aligned frame).
        xy: [P, 2] poses, metres.
        backend: auto, cpu (numba) or cuda (PyTorch).
        floor: [P, 3] the floor plane around each pose (None: `local_floor`).
    """
    from navcore.render.ray_hits import panorama_dirs

    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    floor = local_floor(scene, xy, emb, cfg, backend) if floor is None else np.asarray(floor, np.float64)
    hs = cfg.ray_heights(emb)
    centres = np.concatenate([np.repeat(xy[:, None, :], len(hs), 1), floor[:, None, :1] + hs[None, :, None]], 2)
    offsets, index = local_gaussians(scene, xy, cfg.crop_m, emb.h_min + cfg.floor_guard - cfg.floor_search,
                                     emb.h_max + cfg.floor_search, cfg.min_splat_alpha)
    el = np.radians(cfg.max_elevation_deg)
    n_el = cfg.elevations()
    far = cfg.crop_m / np.cos(el) + cfg.bin_m
    depth = _hit_depth(backend, scene, centres, offsets, index, cfg.azimuths, n_el, -el, el, 0.0, far,
                       cfg.bin_m, cfg.min_alpha)
    dirs = panorama_dirs(cfg.azimuths, -el, el, n_el)  # [E, A, 3]
    hit = np.isfinite(depth)
    t = np.where(hit, depth, 0.0)
    pts = (centres[:, :, None, None, :] + t[..., None] * dirs[None, None]).reshape(len(xy), -1, 3)
    zf = pts[..., 2] - floor_height(floor, xy, pts[..., :2])
    horiz = (t * np.hypot(dirs[..., 0], dirs[..., 1])[None, None]).reshape(len(xy), -1)
    hit = hit.reshape(len(xy), -1)
    lo = emb.h_min + cfg.floor_guard
    sure = hit & (zf >= lo + cfg.floor_step) & (zf <= emb.h_max)
    vis = np.where(sure, horiz, np.inf).min(1)
    # hits that a floor risen by up to floor_step under them would put below the band: the floor
    # at each (vertical ray at the hit, within floor_step of the plane) decides, nearest first
    maybe = hit & (zf >= lo - cfg.floor_step) & ~sure & (zf <= emb.h_max) & (horiz < np.minimum(vis, emb.radius + 0.05)[:, None])
    todo = [np.flatnonzero(m)[np.argsort(horiz[i, m], kind="stable")] for i, m in enumerate(maybe)]
    offsets, index = local_gaussians(scene, xy, emb.radius + 0.4, -2 * cfg.floor_search, emb.h_max + cfg.floor_search,
                                     cfg.min_splat_alpha)
    for r in range(0, max((len(c) for c in todo), default=0), VERIFY):
        rows = [i for i, c in enumerate(todo) if len(c) > r and horiz[i, c[r]] < vis[i]]
        if not rows:
            break
        batch = np.array([np.resize(todo[i][r:r + VERIFY], VERIFY) for i in rows])  # [k, VERIFY] ray ids (padded)
        p = np.take_along_axis(pts[rows], batch[..., None], 1)  # [k, VERIFY, 3] hit points
        sub_off = np.concatenate([[0], np.cumsum(np.diff(offsets)[rows])])
        sub_idx = np.concatenate([index[offsets[i]:offsets[i + 1]] for i in rows])
        dv = _down_depth(backend, scene, p, sub_off, sub_idx, emb.h_max + 3 * cfg.floor_search, cfg)
        plane = floor_height(floor[rows], xy[rows], p[..., :2])
        under = np.where(np.isfinite(dv), p[..., 2] - dv, plane)  # no floor below: a hole, the plane holds
        local = np.clip(under, plane - cfg.floor_step, plane + cfg.floor_step)
        ok = p[..., 2] - local >= lo
        for k, i in enumerate(rows):
            n = min(VERIFY, len(todo[i]) - r)
            first = np.flatnonzero(ok[k, :n])
            if len(first):
                vis[i] = min(vis[i], horiz[i, batch[k, first[0]]])
    return vis


def direct_evidence(scene, xy: np.ndarray, emb, cfg: RenderCheckConfig, floor: np.ndarray | None = None) -> np.ndarray:
    """[P] number of opaque Gaussians (opacity >= min_alpha) centred inside the body cylinder at each
    pose (radius emb.radius, from h_min + floor_guard to h_max above the floor under the robot:
    ``floor`` planes [P, 3] from `local_floor`, or z = 0)."""
    from scipy.spatial import cKDTree

    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    floor = np.zeros((len(xy), 3)) if floor is None else np.asarray(floor, np.float64)
    sel = np.flatnonzero(scene.alphas >= cfg.min_alpha)
    if not len(sel):
        return np.zeros(len(xy), np.int64)
    out = np.zeros(len(xy), np.int64)
    for i, n in enumerate(cKDTree(scene.means[sel, :2]).query_ball_point(xy, emb.radius)):
        m = scene.means[sel[n]]
        z = m[:, 2] - floor_height(floor[i:i + 1], xy[i:i + 1], m[None, :, :2])[0]
        out[i] = int(((z >= emb.h_min + cfg.floor_guard) & (z <= emb.h_max)).sum())
    return out


def sample_poses(costmap, n: int, seed: int) -> np.ndarray:
    """[n, 2] positions uniform over the supported cells of a costmap (query.Costmap)."""
    rng = np.random.default_rng(seed)
    cells = np.argwhere(costmap.clearance >= 0)
    pick = cells[rng.choice(len(cells), n, replace=len(cells) < n)]
    return costmap.cell_centers(pick) + rng.uniform(-0.5, 0.5, (n, 2)) * costmap.resolution


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion k / n ((0, 1) when n = 0: nothing is known)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (max(0.0, c - h), min(1.0, c + h))


def estimate_rates(costmap_blocked: np.ndarray, render_blocked: np.ndarray) -> dict:
    """Estimated FP / FN rates of the costmap against the render, their 95 % intervals and the counts."""
    free, blocked = ~render_blocked, render_blocked
    fp, fn = int((costmap_blocked & free).sum()), int((~costmap_blocked & blocked).sum())
    return {"fp_est": fp / max(int(free.sum()), 1), "fn_est": fn / max(int(blocked.sum()), 1),
            "fp_ci95": wilson(fp, int(free.sum())), "fn_ci95": wilson(fn, int(blocked.sum())),
            "render_free": int(free.sum()), "render_blocked": int(blocked.sum()),
            "costmap_blocked": int(costmap_blocked.sum()), "poses": int(len(render_blocked))}


def check_costmap(scene, costmap, emb, cfg: RenderCheckConfig, xy: np.ndarray | None = None,
                  backend: str = "auto", noise: np.ndarray | None = None) -> dict:
    """Compare a costmap with what the scene shows at sampled (or given) poses: the render check's
    rates, and the direct evidence's (``direct``: the same rates with "blocked" meaning an opaque
    Gaussian centred in the body cylinder). With ``noise`` ([N] bool, the Gaussians the costmap
    judged noise: `stages.costmap.build.obstacle_classes`), ``fn_noise_only`` counts the poses the
    render blocks and the costmap accepts that the render would accept without those Gaussians:
    the estimate's FN that is a disagreement about noise (floating blobs, blur), not about a
    surface the costmap missed."""
    xy = sample_poses(costmap, cfg.poses, cfg.seed) if xy is None else xy
    floor = local_floor(scene, xy, emb, cfg, backend)
    vis = visible_clearance(scene, xy, emb, cfg, backend, floor)
    blocked_render = vis < emb.radius
    blocked_map = ~costmap.are_states_valid(xy)
    blocked_direct = direct_evidence(scene, xy, emb, cfg, floor) > 0
    out = {**estimate_rates(blocked_map, blocked_render), "visible_clearance": vis, "xy": xy, "floor": floor,
           "direct": estimate_rates(blocked_map, blocked_direct),
           "costmap_blocked_mask": blocked_map, "render_blocked_mask": blocked_render,
           "direct_blocked_mask": blocked_direct}
    if noise is not None:
        fn = np.flatnonzero(blocked_render & ~blocked_map)
        clean = visible_clearance(scene.subset(~np.asarray(noise, bool)), xy[fn], emb, cfg, backend, floor[fn]) if \
            len(fn) else np.zeros(0)
        out["fn_noise_only"] = int((clean >= emb.radius).sum())
    return out
