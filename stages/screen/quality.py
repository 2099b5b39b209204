"""The reconstruction-quality layer on the costmap grid: where the robot's camera would look at
blur or through holes (issue 35, section 4).

Four cues:
- blobs (from the Gaussians): opaque splats that are large (largest sigma >= ``blob_sigma_m``)
  and not flat (smallest / largest sigma >= ``blob_flatness``) below ``top_m``. Trained scenes draw
  a surface with thin discs, large ones too on plain walls and floors; a place few views saw is
  filled with round blobs instead. A cell is blurred where the blobs' footprints (alpha x pi
  (2 sigma)^2, summed over ``window_m``) cover at least ``blob_cover`` times the window;
- floor holes (from the Gaussians): cells whose floor splats (within ``floor_search`` of z = 0)
  cover less than ``hole_cover`` of a ``hole_window_m`` window (their 2-sigma footprints x alpha),
  inside the floor's closing by a disc of ``hole_max_m`` / 2 (a gap that wide with floor around
  it is an incomplete reconstruction; the open outside of a building is no hole), in pieces of at
  least ``hole_min_area_m2``;
- views (rendered): the robot's camera on a lattice of valid poses (``view_spacing_m``,
  ``view_yaws`` headings); each view's blur pixels (drawn by splats oversized for the view) and
  hole pixels (`navcore.render.view_quality`) are put where they land on the map, and a cell is
  flagged where they make at least ``view_cell_share`` of what lands there (the real hall's
  smeared sofas, flat splats a metre wide that no shape rule on the splats alone separates from
  its floor);
- unseen (capture cameras, when the scene has them): valid cells whose floor fewer than
  ``camera_min_views`` capture cameras see (in their image, within ``view_range_m``, not behind
  what they render there).
Flagged cells grow by ``margin_m``. `validate` scores a layer against injected regions
(synthetic.realism blur_regions / hole_regions).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from navcore.nav.costmap import lattice_cells
from navcore.nav.screening import disk, grow


@dataclass
class QualityConfig:
    """The reconstruction-quality layer (stage `screen`)."""

    blob_sigma_m: float = 0.1
    """Splats at least this large (largest sigma, metres) ..."""
    blob_flatness: float = 0.3
    """... and at least this round (smallest / largest sigma) are blobs."""
    min_alpha: float = 0.25
    """Fainter splats count for neither Gaussian cue."""
    top_m: float = 2.0
    """Blobs up to this height count (what the robot's camera sees), metres."""
    blob_cover: float = 1.0
    """Blob footprint area per area of the window that flags a cell as blurred (one opaque blob
    of sigma 0.15 m is enough: on the real hall those are the noise splats that block the render
    check's failing poses; 2 keeps only clusters, and misses a third of the injected blur)."""
    window_m: float = 0.5
    """Side of the square window the blobs are summed over, metres."""
    floor_search: float = 0.15
    """Floor splats lie within this height of z = 0, metres."""
    hole_cover: float = 1.0
    """Footprint area of floor splats (x alpha) per area of the window below which a cell has
    no floor."""
    hole_window_m: float = 0.3
    """Side of the square window the floor's cover is summed over, metres."""
    hole_max_m: float = 2.0
    """Widest gap in the floor that is a hole (wider: outside the reconstruction), metres."""
    hole_min_area_m2: float = 0.25
    """Smaller gaps in the floor are left alone (a chair leg's shadow), m^2."""
    views: bool = True
    """Render the robot's camera over the map (the view cue); false: the Gaussian cues only."""
    view_spacing_m: float = 2.0
    """Lattice spacing of the rendered poses, metres."""
    view_yaws: int = 4
    """Headings rendered per lattice pose."""
    view_range_m: float = 8.0
    """Views are rendered up to this far, metres (navcore.render.view_quality)."""
    view_width: int = 64
    """Width of a rendered view, pixels (height: 3/4 of it)."""
    blur_sigma_m: float = 0.5
    """A pixel is blur where its splats' (alpha-weighted) largest sigma is at least this, metres
    (0.3 flagged the worst view of 73 % of the real room's lattice poses, and of 4-13 % on clean
    synthetic scenes: plain surfaces seen up close; 0.5: 24 %, 13 % on the hall, 0-4 % synthetic) ..."""
    blur_angle: float = 0.25
    """... and that sigma over its depth at least this, radians (a 2-sigma footprint of 29 degrees)."""
    view_min_hits: int = 3
    """A cell needs at least this many blur (hole) pixels landing in its window ..."""
    view_cell_share: float = 0.5
    """... and at least this share of the pixels landing there, to be flagged by the views."""
    cameras: bool = True
    """With capture cameras (cameras.json; synthetic scenes' ground truth), flag the cells no
    capture camera saw."""
    camera_min_views: int = 1
    """A cell fewer capture cameras see (within view_range_m, not hidden behind what they
    render) is unseen."""
    camera_heights: list[float] = field(default_factory=lambda: [0.0, 0.5, 1.0])
    """A cell is seen by a capture camera that sees any of these points of its column, metres (the
    floor, the body, the robot's camera)."""
    camera_stride: int = 2
    """Cells' columns are tested at every this many cells (each cell takes its block's answer)."""
    camera_width: int = 64
    """Width of the capture cameras' depth renders, pixels (height: their aspect)."""
    margin_m: float = 0.1
    """Flagged cells grow by this, metres."""


def quality_layers(scene, origin, shape, resolution: float, cfg: QualityConfig) -> dict[str, np.ndarray]:
    """The Gaussian cues: {"blur": [ny, nx] bool, "hole": [ny, nx] bool} on the costmap grid
    (origin, shape (ny, nx), resolution) of the aligned content Gaussians, grown by margin_m."""
    ny, nx = shape
    s = np.sort(scene.scales.astype(np.float64), 1)
    a = scene.alphas
    z = scene.means[:, 2]
    ij = np.floor((scene.means[:, :2] - np.asarray(origin)) / resolution).astype(np.int64)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
    cell_area = resolution * resolution

    def cover(mask, area, window_m):  # footprint area x alpha per area of the window
        grid = np.zeros((ny, nx))
        np.add.at(grid, (ij[mask, 1], ij[mask, 0]), (a * area)[mask])
        return ndimage.uniform_filter(grid, size=max(1, int(round(window_m / resolution))), mode="constant") / cell_area

    blob = inside & (a >= cfg.min_alpha) & (s[:, 2] >= cfg.blob_sigma_m) & (s[:, 0] >= cfg.blob_flatness * s[:, 2]) \
        & (z - 2 * s[:, 2] <= cfg.top_m)
    blur = cover(blob, np.pi * (2 * s[:, 2]) ** 2, cfg.window_m) >= cfg.blob_cover
    floor = inside & (a >= cfg.min_alpha) & (np.abs(z) <= cfg.floor_search)
    has_floor = cover(floor, np.pi * 4 * s[:, 1] * s[:, 2], cfg.hole_window_m) >= cfg.hole_cover
    k = int(np.ceil(cfg.hole_max_m / 2 / resolution))
    closed = ndimage.binary_closing(np.pad(has_floor, k), disk(k))[k:-k or None, k:-k or None]
    hole = _without_small(closed & ~has_floor, cfg.hole_min_area_m2 / cell_area)
    return {"blur": grow(blur, cfg.margin_m, resolution), "hole": grow(hole, cfg.margin_m, resolution)}


def view_layers(views, valid: np.ndarray, origin, resolution: float, cfg: QualityConfig) -> dict:
    """The view cue: {"view_blur", "view_hole": [ny, nx] bool, "poses": [P, 2] xy, "blur", "hole":
    [P] worst-view shares}; views: `navcore.render.view_quality.DefectViews` of the camera scene.

    The lattice's views are rendered and every pixel is put where it lands on the map (its
    surface's x, y; a hole pixel where its ray meets the floor plane); a cell is flagged where at
    least view_min_hits pixels of blur (holes) land and they are at least view_cell_share of the
    pixels landing there."""
    cells = lattice_cells(valid, round(cfg.view_spacing_m / resolution))
    xy = np.asarray(origin) + (cells[:, ::-1] + 0.5) * resolution
    yaws = 2 * np.pi * np.arange(cfg.view_yaws) / cfg.view_yaws
    poses = np.concatenate([np.repeat(xy, len(yaws), 0), np.tile(yaws, len(xy))[:, None]], 1)
    d = views.measure(poses, points=True)
    out = {"poses": xy, "blur": d.blur.reshape(-1, len(yaws)).max(initial=0.0, axis=1),
           "hole": d.hole.reshape(-1, len(yaws)).max(initial=0.0, axis=1)}
    shape = valid.shape

    def count(pts):
        ij = np.floor((pts - np.asarray(origin)) / resolution).astype(np.int64)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < shape[1]) & (ij[:, 1] >= 0) & (ij[:, 1] < shape[0])
        return np.bincount(ij[ok, 1] * shape[1] + ij[ok, 0], minlength=shape[0] * shape[1]).reshape(shape)

    k = max(1, int(round(cfg.window_m / resolution)))  # pixels are pooled over the blobs' window
    seen = ndimage.uniform_filter(count(d.seen).astype(np.float64), k, mode="constant")
    for name, pts in (("view_blur", d.blur_xy), ("view_hole", d.hole_xy)):
        hits = ndimage.uniform_filter(count(pts).astype(np.float64), k, mode="constant")
        flag = (hits * k * k >= cfg.view_min_hits) & (hits >= cfg.view_cell_share * np.maximum(seen, 1e-12))
        out[name] = grow(flag, cfg.margin_m, resolution)
    return out


def _without_small(mask: np.ndarray, min_cells: float) -> np.ndarray:
    labels, n = ndimage.label(mask)
    if not n:
        return mask
    sizes = np.bincount(labels.ravel())
    keep = sizes >= min_cells
    keep[0] = False
    return keep[labels]


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


def camera_layer(views, c2w: np.ndarray, Ks: np.ndarray, width: int, height: int, valid: np.ndarray, origin,
                 resolution: float, cfg: QualityConfig) -> tuple[np.ndarray, np.ndarray]:
    """The capture-camera cue: ([ny, nx] bool unseen valid cells, grown by margin_m; [ny, nx] int32
    how many capture cameras see each cell's column (the most over camera_heights), -1 off the
    valid cells). views: `navcore.render.view_quality.DefectViews` of the camera scene (its far
    plane is the range)."""
    k = max(1, int(cfg.camera_stride))
    ny, nx = valid.shape
    blocks = np.zeros(((ny + k - 1) // k, (nx + k - 1) // k), bool)
    vi = np.argwhere(valid)
    blocks[vi[:, 0] // k, vi[:, 1] // k] = True
    bi = np.argwhere(blocks)
    centre = np.minimum(bi * k + k // 2, [ny - 1, nx - 1])  # the block's middle cell
    xy = np.asarray(origin) + (centre[:, ::-1] + 0.5) * resolution
    hs = np.asarray(cfg.camera_heights, np.float64)
    pts = np.c_[np.repeat(xy, len(hs), 0), np.tile(hs, len(xy))]
    seen = views.coverage(c2w, Ks, width, height, pts).reshape(-1, len(hs)).max(1)
    per_block = np.full(blocks.shape, -1, np.int32)
    per_block[bi[:, 0], bi[:, 1]] = seen
    count = np.where(valid, np.repeat(np.repeat(per_block, k, 0), k, 1)[:ny, :nx], -1).astype(np.int32)
    unseen = _without_small(valid & (count >= 0) & (count < cfg.camera_min_views),
                            cfg.hole_min_area_m2 / resolution ** 2)
    return grow(unseen, cfg.margin_m, resolution), count


def screen_layers(content, camera, valid: np.ndarray, origin, resolution: float, emb, cfg: QualityConfig,
                  cameras: tuple | None = None) -> dict:
    """Every cue on one costmap grid: {"blur", "hole", "view_blur", "view_hole", "flagged": [ny, nx]
    bool, "view": the view cue's poses and shares (None without views), "views": views rendered}.

    Args:
        content: the aligned content Gaussians (floaters out: the Gaussian cues).
        camera: what the robot's camera renders (`navcore.gaussians.content.camera_scene`).
        valid: [ny, nx] bool, the main embodiment's valid states (where views are rendered).
        cameras: the capture cameras (camera -> world [M, 4, 4] in the aligned frame, Ks [M, 3, 3],
            width, height), or None: no "unseen" cue.
    """
    from navcore.render.view_quality import DefectViews

    layers = quality_layers(content, origin, valid.shape, resolution, cfg)
    view, rendered = None, 0
    use_views, use_cameras = cfg.views and valid.any(), cfg.cameras and cameras is not None and valid.any()
    views = DefectViews(camera, emb, cfg.view_width, cfg.view_width * 3 // 4, cfg.blur_angle, cfg.blur_sigma_m,
                        cfg.view_range_m) if use_views or use_cameras else None  # one prepared scene for both
    layers["view_blur"] = layers["view_hole"] = layers["unseen"] = np.zeros(valid.shape, bool)
    if use_views:
        view = view_layers(views, valid, origin, resolution, cfg)
        layers["view_blur"], layers["view_hole"] = view.pop("view_blur"), view.pop("view_hole")
        rendered = views.views
    if use_cameras:
        layers["unseen"], layers["camera_views"] = camera_layer(views, *cameras, valid, origin, resolution, cfg)
    layers["flagged"] = layers["blur"] | layers["hole"] | layers["view_blur"] | layers["view_hole"] | layers["unseen"]
    return {**layers, "view": view, "views": rendered}


def scene_score(layers: dict, valid: np.ndarray, resolution: float) -> dict:
    """The scene's quality score, the share of its valid cells no cue flags, and each cue's share
    of them."""
    n = max(int(valid.sum()), 1)
    out = {"score": round(1.0 - float((layers["flagged"] & valid).sum()) / n, 4),
           "valid_area_m2": round(float(valid.sum()) * resolution ** 2, 2)}
    for k in ("blur", "hole", "view_blur", "view_hole", "unseen"):
        out[f"{k}_share"] = round(float((layers[k] & valid).sum()) / n, 4)
    return out
