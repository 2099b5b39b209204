"""Primitives -> triangle mesh (ground truth) and -> surface Gaussians that look like a trained 3DGS:
flat discs tangent to the surface, stratified (jittered-grid) placement so surfaces are covered
without holes, mild scale and colour noise."""
from __future__ import annotations

import numpy as np
import trimesh

from navcore.gaussians.model import rotmat_to_quat
from stages.synthesize.layout import Part


def _rot_z(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def part_mesh(p: Part) -> trimesh.Trimesh:
    """Closed triangle mesh of one primitive, in the canonical frame."""
    tf = np.eye(4)
    tf[:3, :3] = _rot_z(p.yaw)
    tf[:3, 3] = p.center
    if p.kind == "box":
        return trimesh.creation.box(extents=p.size, transform=tf)
    if p.kind == "cylinder":
        return trimesh.creation.cylinder(radius=p.size[0] / 2, height=p.size[2], sections=32, transform=tf)
    if p.kind == "sphere":
        m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
        m.apply_scale(p.size / 2)
        m.apply_transform(tf)
        return m
    raise ValueError(f"unknown primitive {p.kind!r}")


def layout_mesh(parts: list[Part]) -> tuple[trimesh.Trimesh, np.ndarray]:
    """All primitives as one mesh, plus the instance id of each face."""
    meshes = [part_mesh(p) for p in parts]
    face_inst = np.concatenate([np.full(len(m.faces), p.instance, np.int32) for m, p in zip(meshes, parts)])
    return trimesh.util.concatenate(meshes), face_inst


def _rect_samples(rng, a: float, b: float, density: float):
    """Jittered grid on an a x b rectangle: (u, v) in [0, a] x [0, b] and the cell sizes."""
    na, nb = max(1, int(np.ceil(a * np.sqrt(density)))), max(1, int(np.ceil(b * np.sqrt(density))))
    i, j = np.meshgrid(np.arange(na), np.arange(nb), indexing="ij")
    u = (i.ravel() + rng.random(i.size)) * (a / na)
    v = (j.ravel() + rng.random(j.size)) * (b / nb)
    return u, v, a / na, b / nb


def part_surface_samples(p: Part, rng: np.random.Generator, density: float):
    """Points on the primitive's surface with tangent frames and spacing.

    Returns:
        points [M, 3] m, frames [M, 3, 3] (columns t1, t2, n), spacing [M, 2] m along t1, t2.
    """
    pts, frames, spacing = [], [], []
    rz = _rot_z(p.yaw)
    if p.kind == "box":
        h = p.size / 2
        for axis in range(3):
            for sign in (-1.0, 1.0):
                if axis == 2 and ((sign < 0 and p.skip_bottom) or (sign > 0 and p.skip_top)):
                    continue
                if axis < 2 and p.skip_sides:
                    continue
                ta, tb = [k for k in range(3) if k != axis]
                u, v, da, db = _rect_samples(rng, p.size[ta], p.size[tb], density)
                local = np.zeros((len(u), 3))
                local[:, ta] = u - h[ta]
                local[:, tb] = v - h[tb]
                local[:, axis] = sign * h[axis]
                e = np.eye(3)
                frame = np.stack([e[ta], e[tb], sign * e[axis]], axis=1)
                if np.linalg.det(frame) < 0:
                    frame[:, 1] *= -1
                pts.append(local)
                frames.append(np.broadcast_to(frame, (len(u), 3, 3)))
                spacing.append(np.broadcast_to([da, db], (len(u), 2)))
    elif p.kind == "cylinder":
        r, hgt = p.size[0] / 2, p.size[2]
        u, v, da, db = _rect_samples(rng, 2 * np.pi * r, hgt, density)
        th = u / r
        n = np.stack([np.cos(th), np.sin(th), np.zeros_like(th)], 1)
        t1 = np.stack([-np.sin(th), np.cos(th), np.zeros_like(th)], 1)
        t2 = np.broadcast_to([0.0, 0.0, 1.0], n.shape)
        pts.append(np.concatenate([r * n[:, :2], (v - hgt / 2)[:, None]], 1))
        frames.append(np.stack([t1, t2, n], axis=2))
        spacing.append(np.broadcast_to([da, db], (len(u), 2)))
        for sign in (-1.0, 1.0):
            if sign < 0 and p.skip_bottom:
                continue
            # stratified disc: jittered grid in (r^2, theta)
            u, v, _, _ = _rect_samples(rng, 1.0, 1.0, density * np.pi * r * r)
            rad, th = r * np.sqrt(u), 2 * np.pi * v
            sp = np.sqrt(np.pi * r * r / max(len(u), 1))
            pts.append(np.stack([rad * np.cos(th), rad * np.sin(th), np.full_like(th, sign * hgt / 2)], 1))
            frame = np.array([[1.0, 0, 0], [0, sign, 0], [0, 0, sign]])
            frames.append(np.broadcast_to(frame, (len(u), 3, 3)))
            spacing.append(np.broadcast_to([sp, sp], (len(u), 2)))
    elif p.kind == "sphere":
        a = p.size / 2
        area = 4 * np.pi * (np.prod(a) ** (2 / 3))
        m = max(8, int(area * density))
        k = np.arange(m) + rng.random(m) * 0.5
        z = 1 - 2 * k / m
        th = np.pi * (1 + 5 ** 0.5) * np.arange(m) + rng.random(m) * 0.3
        s = np.sqrt(np.clip(1 - z * z, 0, 1))
        unit = np.stack([s * np.cos(th), s * np.sin(th), z], 1)
        n = unit / a
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        helper = np.where(np.abs(n[:, 2:3]) < 0.9, [[0, 0, 1.0]], [[1.0, 0, 0]])
        t1 = np.cross(helper, n)
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        t2 = np.cross(n, t1)
        sp = np.sqrt(area / m)
        pts.append(unit * a)
        frames.append(np.stack([t1, t2, n], axis=2))
        spacing.append(np.broadcast_to([sp, sp], (m, 2)))
    else:
        raise ValueError(f"unknown primitive {p.kind!r}")
    pts = np.concatenate(pts) @ rz.T + p.center
    frames = np.einsum("ij,mjk->mik", rz, np.concatenate(frames))
    return pts, frames, np.concatenate(spacing)


def surface_gaussians(parts: list[Part], rng: np.random.Generator, density: float, colors: dict[int, np.ndarray],
                      flatness: float = 0.1, color_noise: float = 0.04):
    """Flat surface-aligned Gaussians on every primitive.

    Args:
        density: Gaussians per square metre.
        colors: instance id -> base RGB in [0, 1] (structure parts get colour by surface normal).
        flatness: normal sigma / tangent sigma.
    Returns:
        means [M, 3], quats [M, 4] wxyz, scales [M, 3] m, alphas [M], rgb [M, 3], instance [M] int32.
    """
    out = {k: [] for k in ("means", "quats", "scales", "alphas", "rgb", "inst")}
    for p in parts:
        pts, frames, spacing = part_surface_samples(p, rng, density)
        m = len(pts)
        # random spin about the normal, as trained 3DGS discs have no preferred tangent direction
        ang = rng.uniform(0, 2 * np.pi, m)
        c, s = np.cos(ang), np.sin(ang)
        t1 = frames[:, :, 0] * c[:, None] + frames[:, :, 1] * s[:, None]
        t2 = -frames[:, :, 0] * s[:, None] + frames[:, :, 1] * c[:, None]
        rot = np.stack([t1, t2, frames[:, :, 2]], axis=2)
        sig_t = 0.7 * spacing.max(1) * np.exp(rng.normal(0, 0.15, m))
        sig = np.stack([sig_t, sig_t * np.exp(rng.normal(0, 0.15, m)), sig_t * flatness], 1)
        base = colors.get(p.instance)
        if base is None:  # structure: floor darker than walls
            base = np.where(frames[:, 2:3, 2] > 0.9, [[0.55, 0.45, 0.35]], [[0.85, 0.84, 0.80]])
        rgb = np.clip(np.broadcast_to(base, (m, 3)) + rng.normal(0, color_noise, (m, 3)), 0, 1)
        out["means"].append(pts + frames[:, :, 2] * rng.normal(0, 0.001, (m, 1)))
        out["quats"].append(rotmat_to_quat(rot))
        out["scales"].append(sig)
        out["alphas"].append(rng.uniform(0.6, 0.99, m))
        out["rgb"].append(rgb)
        out["inst"].append(np.full(m, p.instance, np.int32))
    return tuple(np.concatenate(v) for v in out.values())


def total_area(parts: list[Part]) -> float:
    """Sampled surface area of the primitives (m^2), to turn a Gaussian budget into a density."""
    a = 0.0
    for p in parts:
        if p.kind == "box":
            x, y, z = p.size
            a += 2 * x * y - x * y * (int(p.skip_bottom) + int(p.skip_top))
            a += 0.0 if p.skip_sides else 2 * (y * z + x * z)
        elif p.kind == "cylinder":
            r = p.size[0] / 2
            a += 2 * np.pi * r * p.size[2] + np.pi * r * r * (1 if p.skip_bottom else 2)
        else:
            a += 4 * np.pi * (np.prod(p.size / 2) ** (2 / 3))
    return a
