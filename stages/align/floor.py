"""Find the floor plane among the occupied voxels and the rigid motion that puts it at z = 0.

1. open3d RANSAC extracts up to ``max_planes`` dominant planes from occupied voxel centres.
2. Each plane is oriented so that most occupied mass lies on its positive side; planes with more
   than ``max_below_fraction`` of the mass below are rejected (a floor has nothing under it).
   With ``up_hint`` set, planes tilted more than ``max_tilt_deg`` from it are rejected too.
3. Indoor scenes are thinnest along gravity (a storey is ~2.5 m, rooms are wider): among the
   candidates whose extent along their normal is within 15 % of the thinnest, the floor is the
   one with the most occupied voxels 0.05 to 1.2 m above it (furniture stands on floors, not
   under ceilings). ``up_hint`` overrides this for scenes where it fails (one long corridor).
4. Refinement: a least-squares plane through the opaque Gaussian centres near the RANSAC plane
   (floor Gaussians sit on the surface, so this is far more precise than voxel centres).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class AlignConfig:
    """Parameters of the floor alignment."""

    voxel_size: float = 0.05
    """Resolution of the opacity field the plane is fitted to (metres)."""
    distance_threshold: float = 0.06
    """RANSAC inlier distance, metres."""
    ransac_iterations: int = 1000
    """RANSAC iterations per plane."""
    ransac_max_points: int = 40_000
    """RANSAC runs on a seeded random subset of at most this many occupied voxels."""
    max_planes: int = 6
    """Planes extracted before choosing the floor."""
    min_plane_fraction: float = 0.03
    """Smallest plane considered, as a fraction of the occupied voxels."""
    max_below_fraction: float = 0.1
    """Largest share of occupied voxels allowed more than 0.1 m below a floor candidate."""
    up_hint: list[float] | None = None
    """Approximate up direction in the source frame (e.g. [0, 0, 1]); null = any."""
    max_tilt_deg: float = 45.0
    """With up_hint: largest angle between a floor candidate's normal and the hint."""
    refine_band: float = 0.05
    """Gaussians within this distance of the RANSAC plane feed the refinement, metres."""
    refine_min_alpha: float = 0.5
    """Only Gaussians at least this opaque feed the refinement."""
    seed: int = 0
    """RANSAC seed (open3d's global generator)."""


def _plane_svd(points: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    w = np.ones(len(points)) if weights is None else weights
    c = (points * w[:, None]).sum(0) / w.sum()
    q = (points - c) * np.sqrt(w)[:, None]
    _, _, vt = np.linalg.svd(q, full_matrices=False)
    n = vt[-1]
    return n, -float(n @ c)


def fit_floor(occupied: np.ndarray, means: np.ndarray, alphas: np.ndarray, cfg: AlignConfig) -> tuple[np.ndarray, float, dict]:
    """Floor plane n . p + d = 0 (unit n pointing up into the room).

    Args:
        occupied: [M, 3] centres of occupied voxels (source frame, metres).
        means, alphas: [N, 3], [N] Gaussian centres and opacities for the refinement.
    Returns:
        (n [3], d, info) with info on the candidates.
    """
    import open3d as o3d

    if len(occupied) < 3:
        raise ValueError(f"only {len(occupied)} occupied voxels: nothing to fit a floor to")
    o3d.utility.random.seed(int(cfg.seed))
    sub = occupied
    if len(occupied) > cfg.ransac_max_points:
        pick = np.random.default_rng(cfg.seed).choice(len(occupied), cfg.ransac_max_points, replace=False)
        sub = occupied[np.sort(pick)]
    remaining = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(sub.astype(np.float64)))
    hint = None if cfg.up_hint is None else np.asarray(cfg.up_hint, float) / np.linalg.norm(cfg.up_hint)
    candidates = []
    for _ in range(cfg.max_planes):
        if len(remaining.points) < max(3, cfg.min_plane_fraction * len(sub)):
            break
        model, inl = remaining.segment_plane(cfg.distance_threshold, 3, cfg.ransac_iterations)
        if len(inl) < cfg.min_plane_fraction * len(sub):
            break
        n = np.asarray(model[:3], float)
        d = float(model[3]) / np.linalg.norm(n)
        n = n / np.linalg.norm(n)
        sd = occupied @ n + d
        if (sd < -0.1).sum() > (sd > 0.1).sum():
            n, d, sd = -n, -d, -sd
        below = float((sd < -0.1).mean())
        thickness = float(np.percentile(sd, 99.5))
        band = int(((sd > 0.05) & (sd < 1.2)).sum())
        tilt = None if hint is None else float(np.degrees(np.arccos(np.clip(n @ hint, -1, 1))))
        ok = below <= cfg.max_below_fraction and (tilt is None or tilt <= cfg.max_tilt_deg)
        candidates.append({"normal": n.tolist(), "d": d, "inliers": len(inl), "below_fraction": below,
                           "band_count": band, "thickness_m": thickness, "tilt_to_hint_deg": tilt, "eligible": ok})
        remaining = remaining.select_by_index(inl, invert=True)
    eligible = [c for c in candidates if c["eligible"]]
    if not eligible:
        raise ValueError(f"no floor plane found among {len(candidates)} RANSAC planes "
                         f"(none has < {cfg.max_below_fraction:.0%} of the mass below it"
                         + (f" within {cfg.max_tilt_deg} deg of up_hint" if hint is not None else "") + ")")
    # indoors the scene is thinnest along gravity: keep the planes across the thinnest extent
    # (floor and ceiling), then the one with furniture next to it
    thin = min(c["thickness_m"] for c in eligible)
    across = [c for c in eligible if c["thickness_m"] <= 1.15 * thin]
    best = max(across, key=lambda c: c["band_count"])
    n, d = np.asarray(best["normal"]), best["d"]
    # refinement on opaque Gaussian centres near the plane, twice with a shrinking band
    band = cfg.refine_band
    for _ in range(2):
        sd = means @ n + d
        sel = (np.abs(sd) < band) & (alphas >= cfg.refine_min_alpha)
        if sel.sum() < 100:
            break
        n2, d2 = _plane_svd(means[sel].astype(np.float64), alphas[sel])
        if n2 @ n < 0:
            n2, d2 = -n2, -d2
        n, d = n2, d2
        res = np.abs(means[sel] @ n + d)
        band = max(3.0 * float(np.median(res)) * 1.4826, 0.01)
    info = {"candidates": candidates, "chosen": candidates.index(best), "normal": n.tolist(), "d": float(d)}
    return n, float(d), info


def floor_transform(n: np.ndarray, d: float) -> np.ndarray:
    """Rigid 4x4 (source -> aligned) rotating n onto +z by the smallest rotation and moving the
    plane n . p + d = 0 to z = 0."""
    n = np.asarray(n, float) / np.linalg.norm(n)
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(n, z)
    s, c = np.linalg.norm(v), float(n @ z)
    if s < 1e-12:
        r = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        k = v / s
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        r = np.eye(3) + s * kx + (1 - c) * kx @ kx
    t = np.eye(4)
    t[:3, :3] = r
    t[2, 3] = d  # a plane point p0 = -d n maps to R p0 = -d z; shift by +d
    return t
