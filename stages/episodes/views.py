"""Blind camera poses: what the rendered scene puts in front of the camera that the costmap does
not have.

A trained reconstruction holds floaters and blur in the space the costmap calls free (large,
opaque, sparse Gaussians near the capture path: ingest calls them floaters, and the map, built from
the content, drives through them). A start pose inside one gives the agent a first observation of
one colour (docs/benchmarks/bench_blind_views.md: a fifth of the real room's starts). The test casts the
costmap's 9 rays across the field of view (their median free distance D) and
renders the camera with its far plane at min(near_m, D - MAP_MARGIN), so only the Gaussians whose
mean lies nearer than any obstacle the map knows there (about a millisecond on the CPU, whatever
the scene's size); the pose is blind when they cover more than half of the image (median
accumulated opacity above 0.5). A wall at arm's length is a legitimate view and stays; a blob
around the camera in front of that wall does not.
"""
from __future__ import annotations

import math

import numpy as np

from navcore.render.camera import embodiment_camera

COVERED = 0.5  # median accumulated opacity above which the near field hides the view
MAP_MARGIN = 0.15
"""Metres in front of the costmap's obstacles where their own Gaussians may lie (the obstacle layer
is cells, the surfaces are Gaussians with extent, the 9 rays are a sample of the field of view)."""
SIZE = (16, 12)  # the test's image: a blind view is blind at any resolution
MIN_SIGMA = 0.02
"""Gaussians whose largest standard deviation is under this (metres) are left out of the test:
blur and floaters are large Gaussians, and small ones cover a view only where they form a
surface, which the costmap has. On the real room it keeps 228 k of the 1.4 M near-field
Gaussians: the set-up 2.0 -> 0.3 s, a pose 1.04 -> 0.68 ms on one core, and the same decision
for 999 of 1,000 random valid poses (224 blind instead of 225); on the hall for all (51 blind)."""


def near_field(scene, costmap, emb, near_m: float) -> np.ndarray:
    """[N] bool: the Gaussians a camera of emb at a valid state of the costmap can render with its
    far plane at near_m, of at least MIN_SIGMA; the others cannot pass the renderer's cull (their
    mean lies at least near_m deep, or their footprint off the image, for every such camera).

    Bound: a mean the cull keeps lies less than near_m deep and within the image widened by the
    cull's pixel pad (the footprint of a point: 3.33 sqrt(eps2d) + 1 px), so less than near_m
    sqrt(1 + kx^2 + ky^2) from the camera (kx, ky: the tangents of the widened half fields of
    view); the cull widens the image further by its bound on the Gaussian's own extent, 3.33
    standard deviations times sqrt(1 + l^2) per axis (l: the Jacobian's clamp, 1.3 x the tangent
    of the half field of view); a valid state lies within a cell diagonal of a valid cell's centre. The distance to a camera is
    bounded below through the distance transform of the valid cells."""
    from scipy import ndimage

    from navcore.render.cpu_fast import EXTENT_MAX, SQRT_EPS2D

    res = costmap.resolution
    valid = ~costmap.occupancy
    w, h = SIZE
    pad = EXTENT_MAX * SQRT_EPS2D + 1.0
    tx = math.tan(math.radians(emb.hfov_deg) / 2)
    kx = tx * (w / 2 + pad) / (w / 2)
    ky = tx * (h / 2 + pad) / (w / 2)  # square pixels: fy = fx
    reach = near_m * math.sqrt(1 + kx * kx + ky * ky) + res * math.sqrt(2.0)
    lx, ly = 1.3 * tx, 1.3 * tx * h / w
    ext = EXTENT_MAX * math.sqrt(2 + lx * lx + ly * ly)  # x (1 + lx^2, 1 + ly^2, 0)^(1/2) per sigma
    m = np.asarray(scene.means, np.float64)
    smax = np.exp(np.asarray(scene.log_scales, np.float64).max(1))
    ny, nx = valid.shape
    if not valid.any():
        return np.zeros(len(m), bool)
    dist = ndimage.distance_transform_edt(~valid) * res  # cell centre -> the nearest valid cell centre
    cells = np.clip(costmap.cells_of(m), 0, [ny - 1, nx - 1])  # a mean off the map: the nearest edge cell
    c = costmap.cell_centers(cells)
    dh = np.maximum(dist[cells[:, 0], cells[:, 1]] - np.hypot(m[:, 0] - c[:, 0], m[:, 1] - c[:, 1]), 0.0)  # triangle
    dz = m[:, 2] - emb.camera_height
    return (np.hypot(dh, dz) < reach + ext * smax) & (smax >= MIN_SIGMA)


class NearViews:
    """Tests camera poses of one embodiment in one scene.

    Args:
        scene: the Gaussians the robot's camera renders (`navcore.gaussians.content.camera_scene`).
        costmap: the embodiment's costmap (its obstacle layer); tested poses must be valid states.
        emb: the embodiment (camera height, pitch, field of view).
        near_m: the near field, metres.
    """

    def __init__(self, scene, costmap, emb, near_m: float):
        from navcore.render import cpu_fast

        self.cm, self.emb, self.near = costmap, emb, float(near_m)
        keep = near_field(scene, costmap, emb, self.near)
        self.gaussians = int(keep.sum())
        # always the compiled CPU renderer: the decision must not depend on the machine (a GPU
        # worker's gsplat agrees to 80 dB, but a threshold can still flip on a borderline view)
        self._g = cpu_fast.prepare(scene.subset(keep))
        self._render = cpu_fast.render_one
        self.checks = 0

    def blind(self, xy, yaw: float) -> bool:
        """Whether the camera at (x, y, yaw) sees, nearer than the costmap's obstacles and within
        near_m, what covers more than half of its image."""
        if not self.cm.is_state_valid(float(xy[0]), float(xy[1])):
            raise ValueError(f"blind-view test at ({xy[0]:.3f}, {xy[1]:.3f}): not a valid state of the costmap "
                             "(the near field kept only what valid states can see)")
        depth = self.cm.fov_depth(np.asarray(xy, np.float64), yaw, self.emb.hfov_deg, self.near + MAP_MARGIN)
        far = min(self.near, depth - MAP_MARGIN)
        if far <= 0.05:  # an obstacle the map has at arm's length fills the view: a legitimate one
            return False
        self.checks += 1
        vm, K, w, h = embodiment_camera(self.emb, np.array([[xy[0], xy[1], yaw]], np.float64), *SIZE)
        _, _, alpha = self._render(self._g, vm[0], K[0], w, h, 0, far=far)
        return bool(np.median(alpha) > COVERED)
