"""What a robot's camera sees of a reconstruction's defects: per rendered view, the share of its
pixels that are blur or holes (issue 35, section 4; the screen stage's view cue and the episodes
stage's ImageNav goal-view test), and how many capture cameras see given points
(`DefectViews.coverage`, the screen stage's capture-camera cue).

- blur: an opaque pixel drawn mostly (half its opacity or more) by oversized Gaussians off the
  floor: largest standard deviation at least ``blur_sigma`` metres and (their alpha-weighted
  mean) over the pixel's depth at least ``blur_angle`` radians. A trained reconstruction smears a
  region few captures saw into a few large splats (on the real hall the pink sofas a metre ahead:
  splats of sigma 1.1 m, 28 pixels of a 160-pixel-wide view); the absolute size keeps plain
  surfaces seen up close (a wall of 0.1 m splats at 0.4 m) out, the angle keeps large splats far
  away out. Floor splats (means within FLOOR_Z of z = 0) never count: trained floors are drawn
  with large flat splats that a grazing view stretches, and a smooth floor is no defect.
- holes: a pixel whose accumulated opacity stays below 0.5 although its ray meets the floor
  plane within 80 % of ``far`` (the view looks through the floor of the reconstruction).

Views are rendered up to ``far`` metres (8 m: a splat there is blur only with a sigma of 2 m or
more at the default angle; on the real hall a view costs 11 ms instead of 53 ms on the 2-core
machine, the far side of a 50 m hall no longer sorted into every view). The renders are the
compiled CPU renderer's (`navcore.render.cpu_fast`): the decisions must not depend on the
machine.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navcore.render.camera import embodiment_camera

FLOOR_Z = 0.1
"""Gaussians whose mean lies within this height of the floor (metres, aligned frame) are floor."""
OPAQUE = 0.5
"""Accumulated opacity below which a pixel is a hole."""
GRAZING = 0.05
"""Relative slack of the coverage test's depth comparison (a floor seen at a grazing angle comes
back a little short: its splats' extent along the ray)."""
FLOOR_REACH = 0.8
"""A see-through pixel is a hole where its ray meets the floor within this share of far."""


@dataclass
class ViewDefects:
    """Per view: share of its pixels that are blur and share that are holes; with points, where
    the pixels land on the map (x, y of their surface; a hole pixel where its ray meets the floor
    plane, none for a hole pixel looking up): seen (every opaque pixel and every located hole
    pixel), blur and hole, each [K, 2] over all the views."""

    blur: np.ndarray
    hole: np.ndarray
    seen: np.ndarray | None = None
    blur_xy: np.ndarray | None = None
    hole_xy: np.ndarray | None = None

    @property
    def defect(self) -> np.ndarray:
        return self.blur + self.hole


class DefectViews:
    """Renders views of one scene and measures their defects.

    Args:
        scene: the Gaussians the camera renders (`navcore.gaussians.content.camera_scene`).
        emb: the embodiment (camera height, pitch, field of view).
        width, height: the test image (the share barely depends on it: at 64 x 48 and 160 x 120
            the blur-and-hole share of 240 lattice views per real scene differs by 0.7 / 0.3
            points on average, 5.8 / 3.8 at most, and the "mostly defect" decision agrees on
            99.4 / 99.6 % of them, room / hall).
        blur_angle (radians), blur_sigma (metres), far (metres): see the module doc.
    """

    def __init__(self, scene, emb, width: int = 64, height: int = 48, blur_angle: float = 0.25,
                 blur_sigma: float = 0.5, far: float = 8.0):
        from navcore.render import cpu_fast

        self.emb, self.size, self.blur_angle = emb, (int(width), int(height)), float(blur_angle)
        self.blur_sigma, self.far = float(blur_sigma), float(far)
        self._g = cpu_fast.prepare(scene)
        sigma = np.exp(np.asarray(scene.log_scales, np.float64).max(1))
        big = (sigma >= self.blur_sigma) & (np.abs(np.asarray(scene.means)[:, 2]) > FLOOR_Z)  # floor splats never blur
        self._feats = np.c_[big, big * sigma].astype(np.float32)  # per pixel: their opacity, x their sigma
        self._render = cpu_fast.render_one
        self.views = 0

    def coverage(self, c2w: np.ndarray, Ks: np.ndarray, width: int, height: int, points: np.ndarray,
                 tolerance: float = 0.1) -> np.ndarray:
        """[N] how many of the cameras (capture cameras: c2w [M, 4, 4] camera -> world, OpenCV
        axes; Ks [M, 3, 3] for a width x height image) see each point [N, 3] (aligned frame):
        inside the image, in front of the camera and no farther than far, and not behind what the
        camera renders there (the point's depth at most its pixel's rendered depth (1 + GRAZING) +
        tolerance; a pixel the scene leaves see-through hides nothing)."""
        pts = np.asarray(points, np.float64).reshape(-1, 3)
        seen = np.zeros(len(pts), np.int32)
        for m in range(len(c2w)):
            vm = np.linalg.inv(np.asarray(c2w[m], np.float64))
            _, depth, alpha = self._render(self._g, vm.astype(np.float32), Ks[m], width, height, 0, far=self.far)
            cam = pts @ vm[:3, :3].T + vm[:3, 3]
            z = cam[:, 2]
            front = (z > 0.05) & (z <= self.far)
            u = np.floor(Ks[m][0, 0] * cam[:, 0] / np.where(front, z, 1) + Ks[m][0, 2]).astype(np.int64)
            v = np.floor(Ks[m][1, 1] * cam[:, 1] / np.where(front, z, 1) + Ks[m][1, 2]).astype(np.int64)
            inside = front & (u >= 0) & (u < width) & (v >= 0) & (v < height)
            i = np.flatnonzero(inside)
            d, a = depth[v[i], u[i]], alpha[v[i], u[i]]
            seen[i[(a < OPAQUE) | (z[i] <= d * (1 + GRAZING) + tolerance)]] += 1
        return seen

    def measure(self, poses: np.ndarray, points: bool = False) -> ViewDefects:
        """poses [P, 3] (x, y, yaw) -> the defect shares of their views (and, with points, where
        their pixels land)."""
        poses = np.asarray(poses, np.float64).reshape(-1, 3)
        vm, K, w, h = embodiment_camera(self.emb, poses, *self.size)
        blur, hole = np.zeros(len(poses)), np.zeros(len(poses))
        seen, bxy, hxy = [], [], []
        u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        for p in range(len(poses)):
            feats, depth, alpha = self._render(self._g, vm[p], K[p], w, h, 0, far=self.far, features=self._feats)
            self.views += 1
            opaque = alpha >= OPAQUE
            sigma = feats[..., 1] / np.maximum(feats[..., 0], 1e-6)  # the big splats' mean sigma
            bad = opaque & (feats[..., 0] >= 0.5 * alpha) & (sigma / np.maximum(depth, 1e-3) >= self.blur_angle)
            c2w = np.linalg.inv(vm[p].astype(np.float64))
            rays = np.stack([(u - K[p][0, 2]) / K[p][0, 0], (v - K[p][1, 2]) / K[p][1, 1], np.ones_like(u)], -1)
            rays = rays @ c2w[:3, :3].T  # world directions, camera z = 1 (t: the camera depth)
            o = c2w[:3, 3]
            t_floor = -o[2] / np.where(rays[..., 2] < -1e-6, rays[..., 2], np.nan)  # rays down to z = 0
            gap = ~opaque & (np.nan_to_num(t_floor, nan=np.inf) < FLOOR_REACH * self.far)
            blur[p], hole[p] = float(bad.mean()), float(gap.mean())
            if points:
                surf = o + rays * depth[..., None]
                floor_hit = o[:2] + rays[..., :2] * np.nan_to_num(t_floor)[..., None]
                seen += [surf[opaque][:, :2], floor_hit[gap]]
                bxy.append(surf[bad][:, :2])
                hxy.append(floor_hit[gap])
        if not points:
            return ViewDefects(blur, hole)
        cat = lambda a: np.concatenate(a) if a else np.zeros((0, 2))  # noqa: E731
        return ViewDefects(blur, hole, cat(seen), cat(bxy), cat(hxy))

