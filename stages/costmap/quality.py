"""A reconstruction-quality layer on the costmap grid (issue 35, section 4; not yet read by the
episodes stage): where the robot's camera would look at blur or through holes.

Two cues, both from the Gaussians alone (no rendering):
- blur: "blobs", opaque splats that are large (largest sigma >= ``blob_sigma_m``) and not flat
  (smallest / largest sigma >= ``blob_flatness``) below ``top_m``. Trained scenes draw a surface
  with thin discs, large ones too on plain walls and floors; a place few views saw is filled with
  round blobs instead. A cell is blurred where the blobs' footprints (alpha x pi (2 sigma)^2,
  spread over ``window_m``) cover at least ``blob_cover`` of the area;
- holes: gaps in the floor: cells where the summed opacity of the Gaussians within
  ``floor_search`` of z = 0 over ``hole_window_m`` is below ``hole_alpha`` per square metre, inside
  the floor's closing by a disc of ``hole_max_m`` / 2 (gaps up to that wide with floor around
  them: an incomplete reconstruction; the open outside of a building is no hole).
Flagged cells grow by ``margin_m``. `validate` scores a layer against injected regions
(synthetic.realism blur_regions / hole_regions).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage


@dataclass
class QualityConfig:
    """The reconstruction-quality layer."""

    blob_sigma_m: float = 0.1
    """Splats at least this large (largest sigma, metres) ..."""
    blob_flatness: float = 0.3
    """... and at least this round (smallest / largest sigma) are blobs."""
    min_alpha: float = 0.25
    """Fainter splats count for neither cue."""
    top_m: float = 2.0
    """Blobs up to this height count (what the robot's camera sees), metres."""
    blob_cover: float = 1.0
    """Blob footprint area per area of the window that flags a cell as blurred."""
    floor_search: float = 0.15
    """Floor splats lie within this height of z = 0, metres."""
    hole_alpha: float = 20.0
    """Summed opacity of floor splats per square metre below which a cell has no floor."""
    hole_window_m: float = 0.2
    """Side of the square window the floor's opacity is summed over, metres."""
    hole_max_m: float = 2.0
    """Widest gap in the floor that is a hole (wider: outside the reconstruction), metres."""
    window_m: float = 0.5
    """Side of the square window both cues are summed over, metres."""
    margin_m: float = 0.1
    """Flagged cells grow by this, metres."""


def quality_layers(scene, origin, shape, resolution: float, cfg: QualityConfig) -> dict[str, np.ndarray]:
    """{"blur": [ny, nx] bool, "hole": [ny, nx] bool, "flagged": either} on the costmap grid
    (origin, shape (ny, nx), resolution) of the aligned content Gaussians."""
    ny, nx = shape
    s = np.sort(scene.scales.astype(np.float64), 1)
    a = scene.alphas
    z = scene.means[:, 2]
    ij = np.floor((scene.means[:, :2] - np.asarray(origin)) / resolution).astype(np.int64)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
    win = max(1, int(round(cfg.window_m / resolution)))
    cell_area = resolution * resolution

    def density(mask, weight, size=win):  # per square metre over the window
        grid = np.zeros((ny, nx))
        np.add.at(grid, (ij[mask, 1], ij[mask, 0]), weight[mask])
        return ndimage.uniform_filter(grid, size=size, mode="constant") / cell_area

    blob = inside & (a >= cfg.min_alpha) & (s[:, 2] >= cfg.blob_sigma_m) & (s[:, 0] >= cfg.blob_flatness * s[:, 2]) \
        & (z - 2 * s[:, 2] <= cfg.top_m)
    blur = density(blob, a * np.pi * (2 * s[:, 2]) ** 2) >= cfg.blob_cover
    floor = inside & (a >= cfg.min_alpha) & (np.abs(z) <= cfg.floor_search)
    has_floor = density(floor, a, max(1, int(round(cfg.hole_window_m / resolution)))) >= cfg.hole_alpha
    k = int(np.ceil(cfg.hole_max_m / 2 / resolution))
    closed = ndimage.binary_closing(np.pad(has_floor, k), _disk(k))[k:-k or None, k:-k or None]
    hole = closed & ~has_floor
    grow = int(np.ceil(cfg.margin_m / resolution))
    if grow:
        blur, hole = ndimage.binary_dilation(blur, _disk(grow)), ndimage.binary_dilation(hole, _disk(grow))
    return {"blur": blur, "hole": hole, "flagged": blur | hole}


def _disk(k: int) -> np.ndarray:
    return np.hypot(*np.mgrid[-k:k + 1, -k:k + 1]) <= k


def validate(flagged: np.ndarray, origin, resolution: float, regions: list[dict], where: np.ndarray,
             slack_m: float = 0.3) -> dict:
    """Recall: share of the cells inside the regions (and ``where``) that are flagged; precision:
    share of the flagged cells (in ``where``) within a region's radius + slack_m. regions: the
    ground truth's discs (centre, radius) in the layer's frame."""
    ny, nx = flagged.shape
    yy, xx = np.mgrid[0:ny, 0:nx]
    cx, cy = origin[0] + (xx + 0.5) * resolution, origin[1] + (yy + 0.5) * resolution
    truth, near = np.zeros_like(flagged), np.zeros_like(flagged)
    for r in regions:
        d = np.hypot(cx - r["center"][0], cy - r["center"][1])
        truth |= d < r["radius"]
        near |= d < r["radius"] + slack_m
    t, f = truth & where, flagged & where
    return {"recall": float((f & t).sum() / max(t.sum(), 1)), "precision": float((f & near).sum() / max(f.sum(), 1)),
            "truth_cells": int(t.sum()), "flagged_cells": int(f.sum())}
