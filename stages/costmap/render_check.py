"""A check of a costmap that needs no ground truth: the scene renders what the agent sees, and the
costmap says where it may go; on a real scene they must agree.

For each sampled pose the robot's surroundings are rendered (depth and opacity, ``n_dirs`` cameras
of 360 / n_dirs degrees each, at ``heights`` spread over the body band, rays within
``max_elevation_deg`` of horizontal); pixels that hit a surface (accumulated opacity >=
``min_alpha``) are back-projected, and the nearest one inside the body band gives the visible
clearance (horizontal distance, metres). Splats centred below the band (from ``floor_guard``
above h_min: the floor, its reflections, what the body steps over) are not rendered, steep rays are
left out and hits count from the same height: a renderer's expected depth of a large floor splat
is its centre's depth, which back-projects above the floor, and a floor splat centred next to a
low camera covers its whole image at that one short depth (trained halls' floors are made of
such 5-15 cm splats, scattered a few centimetres in height). The heights are spaced so that at the
robot radius the cameras' vertical fields of view together cover the band.
Expected depth reads splats seen obliquely near the camera short (the splats' centre depths, not the
ray's hit): by up to about two splat sigmas at 10 cm from a wall. The visible clearance is therefore
corrected by ``bias_sigmas`` times the median largest sigma of the opaque splats around the pose
(1.2, calibrated on synthetic seeds 100-101 against the mesh; bench-real validates it on others),
which makes it right near the robot radius, where the verdict is decided. A pose is blocked by the
render when its visible clearance is below the robot radius, blocked by the costmap when its
clearance query says so; the estimated rates are
  FP = costmap-blocked and render-free / render-free,  FN = costmap-free and render-blocked / render-blocked,
the definitions bench-spatial uses against the mesh. What a camera cannot see (closer than the
near plane, hidden behind a nearer surface) the estimate cannot know; bench-real validates it on
synthetic scenes against the mesh reference at the same poses.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class RenderCheckConfig:
    """The render-based costmap check."""

    poses: int = 300
    """Poses sampled per scene (uniform over the supported region of the costmap)."""
    n_dirs: int = 4
    """Cameras around each pose (each covers 360 / n_dirs degrees horizontally)."""
    heights: list[float] = field(default_factory=lambda: [0.15, 0.4, 0.65, 0.9])
    """Camera heights as fractions of the body band [h_min, h_max]."""
    width: int = 48
    """Image width, pixels (per camera)."""
    max_elevation_deg: float = 35.0
    """Rays up to this angle above / below horizontal (sets the image height)."""
    floor_guard: float = 0.05
    """Hits count from this height above h_min, metres."""
    min_splat_alpha: float = 0.25
    """Splats fainter than this are left out of the check's renders: haze and floaters accumulate
    along a ray into a fog that no body would touch (the costmap ignores them the same way)."""
    bias_sigmas: float = 1.2
    """Correction of the expected-depth bias, in median splat sigmas around the pose."""
    min_alpha: float = 0.5
    """A pixel sees a surface when its accumulated opacity reaches this."""
    crop_m: float = 1.0
    """Only Gaussians within this horizontal distance of a pose are rendered for it, metres: the
    check asks whether a surface lies within the robot radius, and whatever could hide such a
    surface is nearer still, so the crop changes nothing below it (and makes the CPU renderer fast)."""
    seed: int = 0
    """Pose sampling seed."""


def pose_cameras(xy: np.ndarray, emb, cfg: RenderCheckConfig) -> tuple[np.ndarray, np.ndarray, int]:
    """Camera -> world [P * H * D, 4, 4], intrinsics [3, 3] and image height for poses xy [P, 2]
    (pose-major)."""
    from navcore.render.camera import camera_to_world, intrinsics

    hs = [emb.h_min + f * (emb.h_max - emb.h_min) for f in cfg.heights]
    yaws = 2 * np.pi * np.arange(cfg.n_dirs) / cfg.n_dirs
    c2w = np.stack([camera_to_world(x, y, yaw, h) for x, y in xy for h in hs for yaw in yaws])
    k = intrinsics(cfg.width, 1, 360.0 / cfg.n_dirs)
    height = 2 * int(np.ceil(k[0, 0] * np.tan(np.radians(cfg.max_elevation_deg))))
    k[1, 2] = height / 2
    return c2w, k, height


def visible_clearance(scene, xy: np.ndarray, emb, cfg: RenderCheckConfig, backend: str = "auto") -> np.ndarray:
    """[P] horizontal distance (metres) from each pose to the nearest rendered surface inside the
    body band, bias-corrected (inf where none is seen within crop_m).

    Args:
        scene: the renderable GaussianScene (aligned frame).
        xy: [P, 2] poses, metres.
    """
    from scipy.spatial import cKDTree

    from navcore.render import Renderer

    c2w, k, height = pose_cameras(xy, emb, cfg)
    per_pose = len(cfg.heights) * cfg.n_dirs
    u = (np.arange(cfg.width) + 0.5 - k[0, 2]) / k[0, 0]
    v = (np.arange(height) + 0.5 - k[1, 2]) / k[1, 1]
    rays = np.stack(np.broadcast_arrays(u[None, :], v[:, None], np.ones((1, 1))), -1)  # [H, W, 3] camera, z = 1
    out = np.full(len(c2w), np.inf)
    tree = cKDTree(scene.means[:, :2])
    alphas = scene.alphas
    z = scene.means[:, 2]
    for i, near in enumerate(tree.query_ball_point(xy, cfg.crop_m)):
        if not near:
            continue
        cams = c2w[i * per_pose:(i + 1) * per_pose]
        views = np.linalg.inv(cams).astype(np.float32)
        b0 = i * per_pose
        near = np.sort(near)
        keep = (alphas[near] >= cfg.min_splat_alpha) & (z[near] >= emb.h_min + cfg.floor_guard)
        local = scene.subset(near[keep])
        if not len(local):
            continue
        opaque = local.alphas >= cfg.min_alpha
        bias = cfg.bias_sigmas * float(np.median(local.scales[opaque].max(1))) if opaque.any() else 0.0
        r = Renderer(local, backend).render(views, np.repeat(k[None], len(cams), 0), cfg.width, height)
        depth = r.depth.detach().cpu().numpy().astype(np.float64)  # [B, H, W] along the optical axis
        hit = r.alpha.detach().cpu().numpy() >= cfg.min_alpha
        pts = rays[None] * depth[..., None]  # camera frame
        world = np.einsum("bij,bhwj->bhwi", cams[:, :3, :3], pts) + cams[:, None, None, :3, 3]
        horiz = np.linalg.norm(world[..., :2] - cams[:, None, None, :2, 3], axis=-1)
        inband = hit & (depth > 0) & (world[..., 2] >= emb.h_min + cfg.floor_guard) & (world[..., 2] <= emb.h_max)
        out[b0:b0 + len(cams)] = np.where(inband, horiz, np.inf).reshape(len(cams), -1).min(1) + bias
    return out.reshape(len(xy), per_pose).min(1)


def sample_poses(costmap, n: int, seed: int) -> np.ndarray:
    """[n, 2] positions uniform over the supported cells of a costmap (query.Costmap)."""
    rng = np.random.default_rng(seed)
    cells = np.argwhere(costmap.clearance >= 0)
    pick = cells[rng.choice(len(cells), n, replace=len(cells) < n)]
    return costmap.cell_centers(pick) + rng.uniform(-0.5, 0.5, (n, 2)) * costmap.resolution


def estimate_rates(costmap_blocked: np.ndarray, render_blocked: np.ndarray) -> dict:
    """Estimated FP / FN rates of the costmap against the render (and the counts)."""
    free, blocked = ~render_blocked, render_blocked
    return {"fp_est": float((costmap_blocked & free).sum() / max(free.sum(), 1)),
            "fn_est": float((~costmap_blocked & blocked).sum() / max(blocked.sum(), 1)),
            "render_free": int(free.sum()), "render_blocked": int(blocked.sum()),
            "costmap_blocked": int(costmap_blocked.sum()), "poses": int(len(render_blocked))}


def check_costmap(scene, costmap, emb, cfg: RenderCheckConfig, xy: np.ndarray | None = None,
                  backend: str = "auto") -> dict:
    """Compare a costmap with what the scene renders at sampled (or given) poses."""
    xy = sample_poses(costmap, cfg.poses, cfg.seed) if xy is None else xy
    vis = visible_clearance(scene, xy, emb, cfg, backend)
    blocked_render = vis < emb.radius
    blocked_map = ~costmap.are_states_valid(xy)
    return {**estimate_rates(blocked_map, blocked_render), "visible_clearance": vis, "xy": xy,
            "costmap_blocked_mask": blocked_map, "render_blocked_mask": blocked_render}
