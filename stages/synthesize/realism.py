"""Artefacts of trained reconstructions, added to procedural scenes so the spatial stages are
measured on what real scenes look like (each a knob; ``level`` sets them all at once):

- reflections: surface Gaussians within ``reflection_depth`` above the floor mirrored below it,
  fainter (a shiny floor is rendered by a mirrored room seen through it), under the glossy share
  ``reflection_coverage`` of the floor (1 m tiles), whose own Gaussians fade to
  ``reflection_floor_alpha`` of their opacity (the fit explains the shine by the room below);
  ``mirror_walls`` wall mirrors copy the room in front of them behind the wall (a room behind the
  wall, outside the layout). The ground truth (layout, mesh) is unchanged;
- far floaters: large Gaussians 10-300 m away (sky, background, optimisation debris);
- floor noise: floor Gaussians thick (less flat), scattered in height and slightly tilted in patches;
- haze: large low-opacity Gaussians hugging surfaces;
- sparse coverage: surfaces thinned with their distance from the capture path;
- up axis: the scene's up direction before the random tilt (+-x, +-y, +-z; "random" from the seed);
- trained splats: the structure's splats turned by up to ``splat_scatter_deg`` from their surface
  and thickened up to ``splat_thickness`` of their width, the scene tilted by ``tilt_deg``;
- defects (for screening): ``blur_regions`` discs of ``defect_radius_m`` inside rooms whose
  Gaussians (up to 2.5 m) are blurred: 3x their largest scale, isotropic (at most 0.4 m), 70 % of
  the region's mean colour, as a fit leaves a place few views saw; ``hole_regions`` discs whose
  Gaussians are removed, floor included (an incomplete reconstruction). The regions are returned
  as ground truth (``defects``: kind, canonical centre, radius).
Levels (``none`` / ``moderate`` / ``heavy`` / ``trained``) are the presets in LEVELS; a knob set
explicitly wins.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

LEVELS = {
    "none": dict(reflection_fraction=0.0, far_floater_fraction=0.0, floor_noise_m=0.0, haze_fraction=0.0,
                 sparse_distance_m=0.0, up_axis="+z"),
    "moderate": dict(reflection_fraction=0.3, far_floater_fraction=0.02, floor_noise_m=0.01, haze_fraction=0.01,
                     sparse_distance_m=3.0, up_axis="random"),
    "heavy": dict(reflection_fraction=0.6, far_floater_fraction=0.05, floor_noise_m=0.02, haze_fraction=0.03,
                  sparse_distance_m=1.5, up_axis="random"),
    # trained Gaussians (issue 46): moderate's artefacts, and splats whose rotations scatter up to
    # 45 deg from their surface with a thickness of up to half their width, in a scene tilted 1-2
    # deg in its source frame (as a capture's frame is off level by a little, not by 20 deg)
    "trained": dict(reflection_fraction=0.3, far_floater_fraction=0.02, floor_noise_m=0.01, haze_fraction=0.01,
                    sparse_distance_m=3.0, up_axis="random", splat_scatter_deg=45.0, splat_thickness=0.5,
                    tilt_deg=[1.0, 2.0]),
}
AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}


@dataclass
class RealismConfig:
    """Reconstruction artefacts of the procedural scenes (README: realistic synthetic scenes)."""

    level: str = "none"
    """Preset of every knob below: none | moderate | heavy | trained (knobs set explicitly override it)."""
    reflection_fraction: float | None = None
    """Share of the surface Gaussians within reflection_depth above the floor mirrored below it."""
    reflection_depth: float = 1.5
    """Height above the floor whose surfaces are mirrored, metres."""
    reflection_alpha: float = 0.5
    """Opacity factor of the mirrored Gaussians."""
    reflection_coverage: float = 1.0
    """Share of the floor that is glossy (1 m tiles drawn at random; 1 = all of it): reflections
    appear under glossy tiles only."""
    reflection_floor_alpha: float = 1.0
    """Opacity factor of the floor's own Gaussians on glossy tiles (1 = unchanged)."""
    mirror_walls: int = 0
    """Wall mirrors (1.5-3 m wide, 0.3-2.2 m high) on the layout's outer walls, each copying the
    room within reflection_depth in front of it behind the wall (opacity x reflection_alpha)."""
    far_floater_fraction: float | None = None
    """Share of extra Gaussians placed 10-300 m away (large, opaque or not)."""
    floor_noise_m: float | None = None
    """Height noise of the floor Gaussians (sigma, metres); they also get 4x thicker."""
    haze_fraction: float | None = None
    """Share of extra large (0.1-0.3 m), faint (alpha 0.03-0.2) Gaussians within 0.1 m of surfaces."""
    sparse_distance_m: float | None = None
    """Surfaces farther than this from the capture path are thinned: keep probability
    exp(-(d - this) / this); 0 keeps everything."""
    up_axis: str | None = None
    """Up direction of the written scene before the random tilt: +x, -x, +y, -y, +z, -z or random."""
    splat_scatter_deg: float | None = None
    """The structure's splats (floor, walls, ceiling) turned by up to this angle about an axis in
    their plane, leaning towards one horizontal direction of the scene more than the others,
    degrees: a trained floor splat's normal lies tens of degrees from vertical, and their mean is
    off the surface's (0 = exact)."""
    splat_thickness: float | None = None
    """The structure's splats get a smallest scale of up to this share of their middle one (drawn
    uniformly per splat; 0 keeps the generator's flatness)."""
    tilt_deg: list[float] | None = None
    """[lo, hi]: the scene's tilt in its source frame drawn from this range, degrees, instead of up
    to synthetic.max_tilt_deg (null = that)."""
    blur_regions: int = 0
    """Blurred regions (discs of defect_radius_m inside rooms, up to 2.5 m high): their Gaussians
    grow to 3x their largest scale, isotropic (at most 0.4 m), and take 70 % of the region's mean
    colour."""
    hole_regions: int = 0
    """Regions whose Gaussians are removed, floor included (incomplete reconstruction)."""
    defect_radius_m: float = 0.8
    """Radius of the blurred and hole regions, metres."""

    def resolved(self) -> "RealismConfig":
        """A copy with every None knob taken from the level's preset."""
        if self.level not in LEVELS:
            raise ValueError(f"synthetic.realism.level={self.level!r}; choose {' | '.join(LEVELS)}")
        preset = LEVELS[self.level]
        vals = {f.name: getattr(self, f.name) for f in fields(self)}
        vals.update({k: v for k, v in preset.items() if vals[k] is None})
        return RealismConfig(**vals)


def up_rotation(axis: str, rng: np.random.Generator) -> tuple[np.ndarray, str]:
    """Rotation taking +z to the named axis (random: one of the six from rng), and the axis name."""
    if axis == "random":
        axis = list(AXES)[int(rng.integers(6))]
    if axis not in AXES:
        raise ValueError(f"synthetic.realism.up_axis={axis!r}; choose one of {', '.join(AXES)} or random")
    k, sgn = AXES[axis]
    target = np.zeros(3)
    target[k] = sgn
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(z, target), float(z @ target)
    if np.linalg.norm(v) < 1e-12:
        return (np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])), axis
    kx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + kx + kx @ kx / (1 + c), axis


def add_artefacts(g: dict, floor_mask: np.ndarray, cams_xyz: np.ndarray, cfg: RealismConfig,
                  rng: np.random.Generator, rooms: np.ndarray | None = None) -> dict:
    """Apply the artefacts to canonical-frame arrays (z up, floor z = 0).

    Args:
        g: means [N, 3], quats [N, 4] wxyz, scales [N, 3] m, alphas [N], rgb [N, 3], inst [N] int32.
        floor_mask: [N] bool, the floor's surface Gaussians.
        cams_xyz: [C, 3] capture positions.
        rooms: [R, 4] room boxes x0, y0, x1, y1 (wall mirrors go on their bounding box).
    Returns:
        the new arrays (added Gaussians have instance -1).
    """
    g = {k: np.array(v, copy=True) for k, v in g.items()}
    n = len(g["means"])
    if cfg.splat_scatter_deg or cfg.splat_thickness:
        s_ = np.nonzero(g["inst"] == 0)[0]  # the structure: floor, walls, ceiling
        if cfg.splat_scatter_deg:  # about an axis in the splat's plane: its normal turns by the angle
            q = g["quats"][s_]
            w, x, y, z = q.T
            rot = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], 1),
                            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], 1),
                            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1)], 1)
            k = np.argmin(g["scales"][s_], axis=1)
            normal = rot[np.arange(len(s_)), :, k]
            # towards one side more than the other, as a fit leans splats towards where they were
            # seen from: their mean normal is off the surface's by a few degrees
            lean = np.r_[rng.normal(size=2), 0.0]
            axis = np.cross(normal, lean / np.linalg.norm(lean) + 0.7 * rng.normal(size=(len(s_), 3)))
            axis /= np.linalg.norm(axis, axis=1, keepdims=True)
            half = np.radians(rng.uniform(0, cfg.splat_scatter_deg, len(s_))) / 2
            turn = np.c_[np.cos(half), axis * np.sin(half)[:, None]]
            g["quats"][s_] = _quat_mul(turn, g["quats"][s_])
        if cfg.splat_thickness:
            sc = g["scales"][s_]
            mid = np.sort(sc, axis=1)[:, 1]
            k = np.argmin(sc, axis=1)
            sc[np.arange(len(s_)), k] = np.maximum(sc[np.arange(len(s_)), k], rng.uniform(0, cfg.splat_thickness,
                                                                                         len(s_)) * mid)
            g["scales"][s_] = sc
    if cfg.floor_noise_m:
        f = np.nonzero(floor_mask)[0]
        g["means"][f, 2] += rng.normal(0, cfg.floor_noise_m, len(f))
        g["scales"][f, 2] = np.maximum(g["scales"][f, 2] * 4.0, cfg.floor_noise_m)
    if cfg.sparse_distance_m:
        from scipy.spatial import cKDTree

        d = cKDTree(cams_xyz[:, :2]).query(g["means"][:, :2])[0]
        keep = rng.random(n) < np.exp(-np.maximum(d - cfg.sparse_distance_m, 0) / cfg.sparse_distance_m)
        g = {k: v[keep] for k, v in g.items()}
        floor_mask = floor_mask[keep]
        n = len(g["means"])
    extra = []
    if cfg.reflection_fraction:
        z = g["means"][:, 2]
        cand = np.nonzero((z > 0.02) & (z < cfg.reflection_depth))[0]
        pick = cand[rng.random(len(cand)) < cfg.reflection_fraction]
        if cfg.reflection_coverage < 1.0 or cfg.reflection_floor_alpha != 1.0:
            # glossy 1 m tiles; drawn only when asked, so that the presets' scenes stay as they were
            tiles = np.floor(g["means"][:, :2]).astype(np.int64)
            keys, inv = np.unique(tiles, axis=0, return_inverse=True)
            glossy = (rng.random(len(keys)) < cfg.reflection_coverage)[inv.reshape(-1)]
            pick = pick[glossy[pick]]
            g["alphas"][floor_mask & glossy] *= cfg.reflection_floor_alpha
        extra.append(_mirrored(g, pick, 2, 0.0, cfg.reflection_alpha))
    if cfg.mirror_walls and rooms is not None and len(rooms):
        lo_b, hi_b = np.asarray(rooms)[:, :2].min(0), np.asarray(rooms)[:, 2:].max(0)
        for _ in range(cfg.mirror_walls):
            axis, side = int(rng.integers(2)), int(rng.integers(2))  # a wall x = const or y = const
            wall = (lo_b, hi_b)[side][axis]
            other = 1 - axis
            width = rng.uniform(1.5, 3.0)
            c = rng.uniform(lo_b[other] + width / 2, max(hi_b[other] - width / 2, lo_b[other] + width / 2))
            p = g["means"]
            into_room = (p[:, axis] - wall) * (1.0 if side == 0 else -1.0)  # distance in front of the mirror
            inside = (into_room > 0.03) & (into_room < cfg.reflection_depth) & (np.abs(p[:, other] - c) < width / 2) & \
                (p[:, 2] > 0.3) & (p[:, 2] < 2.2)  # the room in front of it, not the wall itself
            extra.append(_mirrored(g, np.nonzero(inside)[0], axis, wall, cfg.reflection_alpha))
    lo, hi = g["means"].min(0), g["means"].max(0)
    if cfg.far_floater_fraction:
        k = int(n * cfg.far_floater_fraction)
        dirs = rng.normal(size=(k, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        m = (lo + hi) / 2 + dirs * rng.uniform(10, 300, (k, 1))
        extra.append((m, _random_quats(rng, k), rng.uniform(0.2, 3.0, (k, 3)), rng.uniform(0.05, 0.95, k),
                      rng.uniform(0.3, 0.9, (k, 3))))
    if cfg.haze_fraction:
        k = int(n * cfg.haze_fraction)
        base = g["means"][rng.integers(n, size=k)]
        m = base + rng.normal(0, 0.05, (k, 3))
        extra.append((m, _random_quats(rng, k), rng.uniform(0.1, 0.3, (k, 3)), rng.uniform(0.03, 0.2, k),
                      rng.uniform(0.3, 0.9, (k, 3))))
    for m, q, s, a, c in extra:
        g["means"] = np.concatenate([g["means"], m])
        g["quats"] = np.concatenate([g["quats"], q])
        g["scales"] = np.concatenate([g["scales"], s])
        g["alphas"] = np.concatenate([g["alphas"], a])
        g["rgb"] = np.concatenate([g["rgb"], c])
        g["inst"] = np.concatenate([g["inst"], np.full(len(m), -1, np.int32)])
    g["defects"] = _defects(g, cfg, rng, rooms) if (cfg.blur_regions or cfg.hole_regions) else []
    return g


DEFECT_TOP_M = 2.5  # the defect regions reach this high


def _defects(g: dict, cfg: RealismConfig, rng: np.random.Generator, rooms: np.ndarray | None) -> list[dict]:
    """Blur and remove Gaussians in discs inside the rooms (in place); the regions' ground truth."""
    if rooms is None or not len(rooms):
        raise ValueError("synthetic.realism blur_regions / hole_regions need the layout's rooms")
    rooms = np.asarray(rooms, np.float64)
    r = cfg.defect_radius_m
    area = np.maximum((rooms[:, 2] - rooms[:, 0]) * (rooms[:, 3] - rooms[:, 1]), 1e-9)
    out, drop = [], np.zeros(len(g["means"]), bool)
    for kind in ["blur"] * cfg.blur_regions + ["hole"] * cfg.hole_regions:
        box = rooms[rng.choice(len(rooms), p=area / area.sum())]
        lo, hi = box[:2] + np.minimum(r, (box[2:] - box[:2]) / 2), box[2:] - np.minimum(r, (box[2:] - box[:2]) / 2)
        c = rng.uniform(lo, np.maximum(hi, lo))
        inside = (np.hypot(*(g["means"][:, :2] - c).T) < r) & (g["means"][:, 2] < DEFECT_TOP_M)
        if kind == "hole":
            drop |= inside
        elif inside.any():
            big = np.minimum(3.0 * g["scales"][inside].max(1), 0.4)
            g["scales"][inside] = big[:, None]
            g["rgb"][inside] = 0.3 * g["rgb"][inside] + 0.7 * g["rgb"][inside].mean(0)
        out.append({"kind": kind, "center": [float(c[0]), float(c[1])], "radius": float(r)})
    for k in ("means", "quats", "scales", "alphas", "rgb", "inst"):
        g[k] = g[k][~drop]
    return out


def _mirrored(g: dict, idx: np.ndarray, axis: int, plane: float, alpha_factor: float) -> tuple:
    """Gaussians idx mirrored across the plane x[axis] = plane, fainter and darker: (means, quats,
    scales, alphas, rgb). The rotation R becomes M R M (M the reflection), a proper rotation: the
    quaternion keeps its w and its component along the axis and negates the other two."""
    m = g["means"][idx].copy()
    m[:, axis] = 2 * plane - m[:, axis]
    sign = -np.ones(4)
    sign[0] = sign[1 + axis] = 1.0
    return m, g["quats"][idx] * sign, g["scales"][idx], g["alphas"][idx] * alpha_factor, g["rgb"][idx] * 0.8


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products a * b of [K, 4] wxyz quaternions (b turned by a)."""
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b.T
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], 1)


def _random_quats(rng: np.random.Generator, k: int) -> np.ndarray:
    q = rng.normal(size=(k, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)
