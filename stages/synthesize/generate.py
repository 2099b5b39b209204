"""Procedural indoor scene -> source 3DGS file + ground truth, deterministic from a seed.

Ground truth kept beside the source (canonical frame = z up, floor at z = 0):
mesh.ply + face_instance.npy (mesh reference for FCL), instance_ids.npy (per Gaussian, in the
order of the source file; 0 structure, -1 floater / stray, >= 1 objects), objects.json (boxes with
categories), labels.json (NavArena labels, source "ground_truth"), transform.json (4x4
canonical -> source, the random rigid motion), cameras.json (capture path), floor.json (room
interiors and doorways).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from navcore.gaussians.formats import write_inria_ply
from navcore.gaussians.model import GaussianScene, quat_to_rotmat, rotmat_to_quat
from navcore.io.datasets import FolderWriter, SyntheticSourceDataset
from stages.synthesize.furnish import furnish
from stages.synthesize.layout import CATEGORIES, Layout, LayoutConfig, Part, make_layout
from stages.synthesize.materials import LookConfig, dress
from stages.synthesize.realism import RealismConfig, add_artefacts, up_rotation
from stages.synthesize.surface import layout_mesh, surface_gaussians, total_area


@dataclass
class SyntheticConfig:
    """Parameters of one procedural scene (the seed comes from the catalog entry)."""

    layout: LayoutConfig = field(default_factory=LayoutConfig)
    num_gaussians: int = 150_000
    """Approximate total number of Gaussians (surfaces + floaters + strays)."""
    flatness: float = 0.1
    """Normal / tangent standard deviation of surface Gaussians (trained 3DGS discs are flat)."""
    floater_fraction: float = 0.01
    """Share of low-opacity floaters inside the rooms."""
    stray_fraction: float = 0.005
    """Share of opaque stray Gaussians in clumps outside the rooms."""
    sh_degree: int = 0
    """SH degree of the written source (higher bands get small noise)."""
    max_tilt_deg: float = 20.0
    """Largest tilt of the random rigid motion applied to the scene."""
    max_offset_m: float = 10.0
    """Largest translation per axis of the random rigid motion."""
    camera_height_m: float = 1.4
    """Height of the capture path cameras."""
    realism: RealismConfig = field(default_factory=RealismConfig)
    """Artefacts of trained reconstructions (reflections, far floaters, noisy floors, haze, sparse
    coverage, any up axis); level none keeps the clean procedural scene."""
    look: LookConfig = field(default_factory=LookConfig)
    """How the scene looks: textured materials, painted details, baked light and a ceiling
    (stages/synthesize/materials.py). Colours and the ceiling only: the geometry of a seed is the same
    either way. The ceiling adds its own Gaussians (at the surfaces' density) to num_gaussians."""


@dataclass
class SyntheticScene:
    gaussians: GaussianScene  # source frame
    instance_ids: np.ndarray  # [N] int32
    layout: Layout
    transform: np.ndarray  # [4, 4] canonical -> source
    cameras: list[dict]
    defects: list[dict] = field(default_factory=list)  # injected blur / hole regions (canonical frame)


def random_rigid_transform(rng: np.random.Generator, max_tilt_deg: float, max_offset_m: float,
                           tilt_deg: float | None = None) -> np.ndarray:
    """Tilt about a random horizontal axis by up to max_tilt_deg (tilt_deg: by exactly that; rng
    draws the same numbers either way), any yaw, any offset."""
    yaw = rng.uniform(-np.pi, np.pi)
    drawn = rng.uniform(0, max_tilt_deg)
    tilt = np.deg2rad(drawn if tilt_deg is None else tilt_deg)
    ax = rng.uniform(0, 2 * np.pi)
    k = np.array([np.cos(ax), np.sin(ax), 0.0])
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    r_tilt = np.eye(3) + np.sin(tilt) * kx + (1 - np.cos(tilt)) * kx @ kx
    c, s = np.cos(yaw), np.sin(yaw)
    r_yaw = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    t = np.eye(4)
    t[:3, :3] = r_tilt @ r_yaw
    t[:3, 3] = rng.uniform(-max_offset_m, max_offset_m, 3)
    return t


def _capture_path(lay: Layout, height: float, rng: np.random.Generator) -> list[dict]:
    """Cameras (OpenCV: x right, y down, z forward; camera -> world) on a loop through each room,
    every 0.5 m, looking along the loop and turned inward by 30 degrees."""
    cams = []
    for (x0, y0, x1, y1) in lay.rooms:
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        rx, ry = 0.3 * (x1 - x0), 0.3 * (y1 - y0)
        n = max(8, int(2 * np.pi * max(rx, ry) / 0.5))
        for th in np.linspace(0, 2 * np.pi, n, endpoint=False):
            pos = np.array([cx + rx * np.cos(th), cy + ry * np.sin(th), height])
            yaw = th + np.pi / 2 + np.deg2rad(30) + rng.normal(0, 0.05)
            fwd = np.array([np.cos(yaw), np.sin(yaw), -0.15])
            fwd /= np.linalg.norm(fwd)
            right = np.cross(fwd, [0, 0, 1.0])
            right /= np.linalg.norm(right)
            down = np.cross(fwd, right)
            c2w = np.eye(4)
            c2w[:3, :3] = np.stack([right, down, fwd], 1)
            c2w[:3, 3] = pos
            cams.append(c2w)
    return cams


def generate_scene(seed: int, cfg: SyntheticConfig) -> SyntheticScene:
    """Build one scene from a seed. Same seed and config -> identical arrays."""
    rng = np.random.default_rng(seed)
    lay = make_layout(rng, cfg.layout)
    n_surface = int(cfg.num_gaussians * (1 - cfg.floater_fraction - cfg.stray_fraction))
    density = n_surface / total_area(lay.parts)
    palette = {o.instance_id: rng.uniform(0.1, 0.9, 3) for o in lay.objects}
    means, quats, scales, alphas, rgb, inst = surface_gaussians(lay.parts, rng, density, palette, cfg.flatness)
    # the ceiling and the furniture's details, each from its own stream and added after everything
    # else: the Gaussians of the layout's own parts, the floaters and the artefacts stay a seed's
    added, details = [], []
    if cfg.look.ceiling:
        parts = ceiling_parts(lay, cfg.layout.wall_thickness_m)
        added.append(surface_gaussians(parts, np.random.default_rng([seed, 3]), density, {}, cfg.flatness))
        lay.parts += parts  # into the ground-truth mesh too
    if cfg.look.furnish:
        details = furnish(lay, np.random.default_rng([seed, 4]))
        drng = np.random.default_rng([seed, 5])
        per = [surface_gaussians([d.part], drng, density, palette, cfg.flatness) for d in details]
        if per:
            added.append(tuple(np.concatenate([g[k] for g in per]) for k in range(6)))
        detail_of = np.concatenate([np.full(len(g[0]), k) for k, g in enumerate(per)]) if per else np.zeros(0, int)
        lay.parts += [d.part for d in details]
    if cfg.look.enabled:  # colours only, from their own stream: the geometry's draws are untouched
        extra = tuple(np.concatenate([g[k] for g in added]) for k in range(6)) if added else None
        pts = means if extra is None else np.concatenate([means, extra[0]])
        q = quats if extra is None else np.concatenate([quats, extra[1]])
        ins = inst if extra is None else np.concatenate([inst, extra[5]])
        of = np.full(len(pts), -1)
        if details:
            of[len(pts) - len(detail_of):] = detail_of
        look = dress(lay, pts, quat_to_rotmat(q)[:, :, 2], ins, np.random.default_rng([seed, 2]), cfg.look,
                     cfg.layout.door_height_m, details, of)
        rgb = look[:len(means)]
        start = len(means)
        for k, g in enumerate(added):
            added[k] = (*g[:4], look[start:start + len(g[0])], g[5])
            start += len(g[0])

    # floaters: low-opacity fuzz inside the rooms (never opaque enough to be an obstacle alone)
    n_fl = int(cfg.num_gaussians * cfg.floater_fraction)
    room = np.array(lay.rooms)[rng.integers(len(lay.rooms), size=n_fl)]
    fl_means = np.stack([rng.uniform(room[:, 0], room[:, 2]), rng.uniform(room[:, 1], room[:, 3]),
                         rng.uniform(0.1, lay.wall_height - 0.1, n_fl)], 1)
    fl_scales = rng.uniform(0.02, 0.1, (n_fl, 3))
    fl_alpha = rng.uniform(0.01, 0.12, n_fl)
    # strays: a few opaque clumps outside the rooms (what DBSCAN must discard)
    n_st = int(cfg.num_gaussians * cfg.stray_fraction)
    lo = np.array(lay.rooms)[:, :2].min(0)
    hi = np.array(lay.rooms)[:, 2:].max(0)
    n_clumps = 4
    centres = []
    for _ in range(n_clumps):
        side = rng.integers(4)
        d = rng.uniform(1.0, 3.0)
        if side == 0:
            c = [rng.uniform(lo[0], hi[0]), lo[1] - d]
        elif side == 1:
            c = [rng.uniform(lo[0], hi[0]), hi[1] + d]
        elif side == 2:
            c = [lo[0] - d, rng.uniform(lo[1], hi[1])]
        else:
            c = [hi[0] + d, rng.uniform(lo[1], hi[1])]
        centres.append(c + [rng.uniform(0.0, 2.5)])
    centres = np.array(centres)
    st_means = centres[rng.integers(n_clumps, size=n_st)] + rng.normal(0, 0.15, (n_st, 3))
    st_scales = rng.uniform(0.01, 0.04, (n_st, 3))
    st_alpha = rng.uniform(0.5, 0.95, n_st)
    noise_q = rng.normal(size=(n_fl + n_st, 4))
    noise_q /= np.linalg.norm(noise_q, axis=1, keepdims=True)

    all_means = np.concatenate([means, fl_means, st_means])
    all_quats = np.concatenate([quats, noise_q])
    all_scales = np.concatenate([scales, fl_scales, st_scales])
    all_alpha = np.concatenate([alphas, fl_alpha, st_alpha])
    all_rgb = np.concatenate([rgb, rng.uniform(0.3, 0.9, (n_fl + n_st, 3))])
    all_inst = np.concatenate([inst, np.full(n_fl + n_st, -1, np.int32)])
    real = cfg.realism.resolved()
    rrng = np.random.default_rng([seed, 1])  # its own stream: level none leaves the scene byte-identical
    up_rot, _ = up_rotation(real.up_axis, rrng)
    g = add_artefacts(dict(means=all_means, quats=all_quats, scales=all_scales, alphas=all_alpha, rgb=all_rgb,
                           inst=all_inst),
                      (all_inst == 0) & (np.abs(all_means[:, 2]) < 0.01),
                      np.array([c[:3, 3] for c in _capture_path(lay, cfg.camera_height_m, np.random.default_rng(0))]),
                      real, rrng, np.asarray(lay.rooms))
    for extra in added:  # after the artefacts, which draw per Gaussian: theirs stay those of a scene without them
        for key, arr in zip(("means", "quats", "scales", "alphas", "rgb", "inst"), extra):
            g[key] = np.concatenate([g[key], arr])
    all_inst, defects = g["inst"], g["defects"]
    canonical = GaussianScene.from_colors(g["means"], g["quats"], g["scales"], g["alphas"], g["rgb"])
    if cfg.sh_degree > 0:
        k = (cfg.sh_degree + 1) ** 2
        sh = np.zeros((len(canonical), k, 3), np.float32)
        sh[:, 0] = canonical.sh[:, 0]
        sh[:, 1:] = rng.normal(0, 0.02, (len(canonical), k - 1, 3))
        canonical.sh = sh
    tilt = None if real.tilt_deg is None else float(rrng.uniform(*real.tilt_deg))
    transform = random_rigid_transform(rng, cfg.max_tilt_deg, cfg.max_offset_m, tilt)
    transform[:3, :3] = up_rot @ transform[:3, :3]  # then the up axis (identity for +z)
    transform[:3, 3] = up_rot @ transform[:3, 3]
    cams = [transform @ c for c in _capture_path(lay, cfg.camera_height_m, rng)]
    cameras = [{"position": c[:3, 3].tolist(), "quat_wxyz": rotmat_to_quat(c[:3, :3]).tolist()} for c in cams]
    return SyntheticScene(canonical.transformed(transform), all_inst, lay, transform, cameras, defects)


def ceiling_parts(lay: Layout, wall_thickness: float) -> list[Part]:
    """A ceiling slab over every room, its underside at the walls' top (structure, instance 0)."""
    t = wall_thickness
    return [Part("box", np.array([(x0 + x1) / 2, (y0 + y1) / 2, lay.wall_height + 0.025]),
                 np.array([x1 - x0 + 2 * t, y1 - y0 + 2 * t, 0.05]), 0.0, 0, skip_top=True, skip_sides=True)
            for x0, y0, x1, y1 in lay.rooms]


def object_records(layout: Layout) -> list[dict]:
    """objects.json entries of a layout's objects (canonical frame): oriented box (centre, size, yaw
    about z) and its axis-aligned bounds."""
    out = []
    for o in layout.objects:
        lo, hi = o.aabb()
        out.append({"instance_id": o.instance_id, "category": o.category, "center": o.center.tolist(),
                    "size": o.size.tolist(), "yaw": float(o.yaw), "aabb_min": lo.tolist(), "aabb_max": hi.tolist()})
    return out


def write_synthetic(out: FolderWriter | str | Path, s: SyntheticScene, name: str) -> None:
    """Write the source file and the ground truth into a folder (the source_synthetic dataset's
    writer, or a plain folder)."""
    out = out if isinstance(out, FolderWriter) else FolderWriter(Path(out))
    gt = SyntheticSourceDataset.GT_DIR
    write_inria_ply(out / SyntheticSourceDataset.SOURCE_FILE, s.gaussians)
    np.save(out / f"{gt}/instance_ids.npy", s.instance_ids)
    mesh, face_inst = layout_mesh(s.layout.parts)
    mesh.export(out / f"{gt}/mesh.ply")
    np.save(out / f"{gt}/face_instance.npy", face_inst)
    objects = object_records(s.layout)
    out.json(f"{gt}/objects.json", {"frame": "canonical", "categories": list(CATEGORIES), "objects": objects})
    labels = [{"instance_id": o["instance_id"], "category": o["category"], "position": o["center"],
               "bounding_box": {"min": o["aabb_min"], "max": o["aabb_max"]}, "confidence": 1.0,
               "source": "ground_truth"} for o in objects]
    out.json(f"{gt}/labels.json", {"schema_version": "1.0", "frame": "canonical", "labels": labels})
    out.json(f"{gt}/transform.json", {"canonical_to_source": s.transform.tolist(),
                                      "source_to_canonical": np.linalg.inv(s.transform).tolist()})
    out.json(f"{gt}/cameras.json", {"frame": "source", "convention": "opencv camera-to-world", "width": 640,
                                    "height": 480, "hfov_deg": 90.0, "poses": s.cameras}, indent=None)
    out.json(f"{gt}/floor.json", {"frame": "canonical", "rooms": s.layout.rooms, "doors": s.layout.doors,
                                  "wall_height": s.layout.wall_height, "name": name})
    if s.defects:  # injected reconstruction defects (synthetic.realism blur_regions / hole_regions)
        out.json(f"{gt}/defects.json", {"frame": "canonical", "regions": s.defects})


def load_ground_truth(src_dir: str | Path) -> dict:
    """Load what write_synthetic wrote (mesh via trimesh)."""
    import trimesh

    src = SyntheticSourceDataset(src_dir)
    return {
        "mesh": trimesh.load(src.ground_truth("mesh.ply"), process=False),
        "face_instance": src.read_ground_truth("face_instance.npy"),
        "instance_ids": src.read_ground_truth("instance_ids.npy"),
        "objects": src.read_ground_truth("objects.json")["objects"],
        "canonical_to_source": np.array(src.read_ground_truth("transform.json")["canonical_to_source"]),
        "floor": src.read_ground_truth("floor.json"),
        "cameras": src.read_ground_truth("cameras.json"),
    }
