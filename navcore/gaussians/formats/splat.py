"""antimatter15 .splat (also the NavArena V1 ``compressed.splat``): 32 bytes a Gaussian, no header.

Layout: x, y, z float32; scale_x..z float32 (metres, exp of the log-scales); r, g, b, a uint8
(rgb = clip((0.5 + SH_C0 * f_dc) * 255), a = sigmoid(opacity) * 255); rot_0..3 uint8 = q * 128 + 128
with q = (w, x, y, z). Writers sort by volume x opacity, descending, as the viewers expect.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from navcore.gaussians.errors import SceneFormatError
from navcore.gaussians.model import SH_C0, GaussianScene

SPLAT_DTYPE = np.dtype([("pos", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rot", "u1", 4)])
assert SPLAT_DTYPE.itemsize == 32


def read_splat(path: str | Path, level: int | None = None) -> GaussianScene:
    """Read an antimatter15 .splat file."""
    path = Path(path)
    size = os.path.getsize(path)
    if size % 32:
        raise SceneFormatError(
            path, f".splat size {size:,} bytes is not a multiple of 32 ({size // 32:,} whole splats and "
                  f"{size % 32} stray bytes): truncated or not a .splat file")
    d = np.fromfile(path, dtype=SPLAT_DTYPE)
    q = (d["rot"].astype(np.float32) - 128.0) / 128.0
    rgba = d["rgba"].astype(np.float64) / 255.0
    alpha = np.clip(rgba[:, 3], 1e-4, 1 - 1e-4)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_scales = np.log(d["scale"].astype(np.float64))
    sh = ((rgba[:, :3] - 0.5) / SH_C0).astype(np.float32)[:, None, :]
    return GaussianScene(d["pos"], q, log_scales, np.log(alpha / (1 - alpha)), sh)


def splat_records(scene: GaussianScene) -> np.ndarray:
    """The 32-byte records of a scene, sorted by volume x opacity (descending, stable)."""
    n = len(scene)
    rec = np.zeros(n, dtype=SPLAT_DTYPE)
    rec["pos"] = scene.means
    scales = np.exp(scene.log_scales.astype(np.float64))
    rec["scale"] = scales
    rgb = np.clip((0.5 + SH_C0 * scene.sh[:, 0].astype(np.float64)) * 255.0, 0, 255)
    alpha = scene.alphas
    rec["rgba"][:, :3] = np.round(rgb)
    rec["rgba"][:, 3] = np.round(np.clip(alpha * 255.0, 0, 255))
    rec["rot"] = np.clip(np.round(scene.quats.astype(np.float64) * 128.0 + 128.0), 0, 255)
    order = np.argsort(-(scales.prod(axis=1) * alpha), kind="stable")
    return rec[order]


def write_splat(path: str | Path, scene: GaussianScene) -> None:
    """Write an antimatter15 .splat / NavArena compressed.splat file."""
    splat_records(scene).tofile(path)
