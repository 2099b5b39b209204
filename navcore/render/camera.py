"""Cameras: from a robot pose in SE(2) and the embodiment to the extrinsics and intrinsics every
renderer takes.

Convention (one for the whole project):
- World: the scene's aligned frame (z up, metres, floor z = 0).
- Robot pose (x, y, yaw): position on the floor, heading counter-clockwise about +z from +x.
- Camera: at (x, y, camera_height), looking along the heading, pitched by camera_pitch_deg
  (positive looks up), no roll. Camera axes are OpenCV's (x right, y down, z forward), which is
  what gsplat and the CPU renderer take: `viewmat` is the 4x4 world -> camera transform.
- Intrinsics: square pixels, fx = fy = (width / 2) / tan(hfov / 2), principal point at the image
  centre (width / 2, height / 2); pixel (u, v) has its centre at (u + 0.5, v + 0.5).
"""
from __future__ import annotations

import math

import numpy as np

from navcore.gaussians.cameras import intrinsics  # the pinhole of a field of view lives with the capture cameras

__all__ = ["camera_to_world", "embodiment_camera", "intrinsics", "viewmats"]


def camera_to_world(x: float, y: float, yaw: float, height: float, pitch_deg: float = 0.0) -> np.ndarray:
    """4x4 camera -> world transform (OpenCV camera axes) of a robot pose."""
    p = math.radians(pitch_deg)
    f = np.array([math.cos(p) * math.cos(yaw), math.cos(p) * math.sin(yaw), math.sin(p)])  # forward (z)
    r = np.array([math.sin(yaw), -math.cos(yaw), 0.0])  # right (x)
    d = np.cross(f, r)  # down (y): x cross y = z
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = r, d, f
    m[:3, 3] = (x, y, height)
    return m


def viewmats(poses: np.ndarray, height: float, pitch_deg: float = 0.0) -> np.ndarray:
    """[B, 3] robot poses (x, y, yaw) -> [B, 4, 4] float32 world -> camera transforms."""
    out = np.empty((len(poses), 4, 4))
    for i, (x, y, yaw) in enumerate(np.asarray(poses, float).reshape(-1, 3)):
        out[i] = np.linalg.inv(camera_to_world(x, y, yaw, height, pitch_deg))
    return out.astype(np.float32)


def embodiment_camera(emb, poses: np.ndarray, width: int | None = None, height: int | None = None):
    """(viewmats [B, 4, 4], Ks [B, 3, 3], width, height) of an embodiment's camera at poses [B, 3]."""
    w, h = int(width or emb.image_width), int(height or emb.image_height)
    vm = viewmats(poses, emb.camera_height, emb.camera_pitch_deg)
    k = np.repeat(intrinsics(w, h, emb.hfov_deg)[None], len(vm), 0)
    return vm, k, w, h
