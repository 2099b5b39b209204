"""Where a scene's content is: the dense part of the Gaussians, as opposed to floaters.

Trained reconstructions put Gaussians hundreds of metres away (sky, background, optimisation
debris); min / max or fixed percentiles of the centres then size grids and maps by them. Content
is found from density instead:
1. Bin the centres into ``cell`` cubes (a hash of the occupied cells only, so a 600 m spread costs
   nothing) and count the Gaussians per cell.
2. A cell is dense when it holds at least ``max(min_count, rel_density * D)`` Gaussians, D the
   count of the cell the median Gaussian lives in (density is relative: scenes trained at any
   Gaussian budget behave the same).
3. Dense cells are grouped into 26-connected components; the components holding at least
   ``min_component_fraction`` of the largest one's Gaussians are content, all other Gaussians are
   floaters.
The mask is kept beside the Gaussians (extra ``content``): geometry stages (voxelize, align,
costmap) use the content only, while the renderable model stays as given, less the floaters and
isolated splats the costmap hides from the robot's camera (``camera_scene``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from navcore.gaussians.model import GaussianScene

CONTENT_KEY = "content"


@dataclass
class ContentConfig:
    """Content (as opposed to floaters) from the density of Gaussian centres."""

    cell: float = 0.5
    """Edge of the density cells, metres."""
    rel_density: float = 0.005
    """A cell is dense with at least this share of the count of the median Gaussian's cell."""
    min_count: int = 3
    """... and at least this many Gaussians."""
    min_component_fraction: float = 0.01
    """Components of dense cells with fewer Gaussians than this share of the largest one are floaters."""


def cell_components(cells: np.ndarray) -> tuple[int, np.ndarray]:
    """26-connected components of a set of integer cells.

    Args:
        cells: [C, 3] int64 unique cell indices.
    Returns:
        (number of components, [C] label of each cell).
    """
    c = len(cells)
    if c == 0:
        return 0, np.zeros(0, np.int64)
    k = cells - cells.min(0) + 1
    dims = k.max(0) + 2
    lin = (k[:, 0] * dims[1] + k[:, 1]) * dims[2] + k[:, 2]
    order = np.argsort(lin)
    sorted_lin = lin[order]
    rows, cols = [], []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                if (dx, dy, dz) <= (0, 0, 0):  # each neighbour pair once
                    continue
                nl = lin + (dx * dims[1] + dy) * dims[2] + dz
                pos = np.minimum(np.searchsorted(sorted_lin, nl), c - 1)
                hit = sorted_lin[pos] == nl
                rows.append(np.nonzero(hit)[0])
                cols.append(order[pos[hit]])
    r, q = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r), np.int8), (r, q)), shape=(c, c))
    return connected_components(graph, directed=False)


def unique_rows(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """np.unique(keys, axis=0, return_inverse=True, return_counts=True) of [N, 3] int64 cells,
    through one int64 per row when the box allows (the same lexicographic order; numpy sorts
    rows as opaque records, 3 s for 1.5 M Gaussians)."""
    if not len(keys):
        return keys.reshape(0, 3), np.zeros(0, np.int64), np.zeros(0, np.int64)
    lo = keys.min(0)
    dims = keys.max(0) - lo + 1
    if float(dims[0]) * float(dims[1]) * float(dims[2]) >= 2.0**62:
        cells, inv, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        return cells, inv.reshape(-1), counts
    k = keys - lo
    lin = (k[:, 0] * dims[1] + k[:, 1]) * dims[2] + k[:, 2]
    u, inv, counts = np.unique(lin, return_inverse=True, return_counts=True)
    cells = np.stack([u // (dims[1] * dims[2]), (u // dims[2]) % dims[1], u % dims[2]], 1) + lo
    return cells, inv.reshape(-1), counts


def content_mask(means: np.ndarray, cfg: ContentConfig | None = None) -> tuple[np.ndarray, dict]:
    """Content Gaussians of a scene.

    Args:
        means: [N, 3] centres, metres.
    Returns:
        ([N] bool, True = content; info with counts and the content box).
    """
    cfg = cfg or ContentConfig()
    n = len(means)
    keys = np.floor(means.astype(np.float64) / cfg.cell).astype(np.int64)
    cells, inv, counts = unique_rows(keys)
    threshold = max(float(cfg.min_count), cfg.rel_density * float(np.median(counts[inv])))
    dense = np.nonzero(counts >= threshold)[0]
    n_comp, labels = cell_components(cells[dense])
    mass = np.bincount(labels, weights=counts[dense], minlength=n_comp)
    keep_comp = mass >= cfg.min_component_fraction * mass.max() if n_comp else np.zeros(0, bool)
    cell_ok = np.zeros(len(cells), bool)
    cell_ok[dense[keep_comp[labels]]] = True
    mask = cell_ok[inv]
    if not mask.any():  # nothing dense: every Gaussian is content (tiny scenes)
        mask[:] = True
    lo, hi = means[mask].min(0), means[mask].max(0)
    info = {"cell_m": cfg.cell, "dense_threshold": round(threshold, 2), "cells": int(len(cells)),
            "dense_cells": int(len(dense)), "components": int(n_comp), "content_components": int(keep_comp.sum()),
            "content": int(mask.sum()), "floaters": int(n - mask.sum()),
            "content_box_min": lo.round(3).tolist(), "content_box_max": hi.round(3).tolist(),
            "content_box_m": (hi - lo).round(3).tolist(),
            "all_box_m": (means.max(0) - means.min(0)).round(3).tolist() if n else [0, 0, 0]}
    return mask, info


def content_mask_of(scene: GaussianScene) -> np.ndarray:
    """[N] bool: the scene's content mask (all True when none is stored)."""
    mask = scene.extras.get(CONTENT_KEY)
    return np.ones(len(scene.means), bool) if mask is None else np.asarray(mask).astype(bool)


def content_of(scene: GaussianScene) -> GaussianScene:
    """The content Gaussians of a scene (all of them when no mask is stored)."""
    mask = content_mask_of(scene)
    return scene if mask.all() else scene.subset(mask)


def without_splats(scene: GaussianScene, indices: np.ndarray) -> GaussianScene:
    """The scene less the Gaussians at these indices (itself when there are none)."""
    if not len(indices):
        return scene
    keep = np.ones(len(scene.means), bool)
    keep[indices] = False
    return scene.subset(keep)


def camera_scene(catalog, scene, embodiment: str, loaded: tuple | None = None, **load_kw) -> tuple[GaussianScene, dict]:
    """The aligned scene as an embodiment's camera sees it: all Gaussians but the noise splats its
    costmap hid (floaters and isolated splats in the space its body may occupy, which the robot
    drives through: `stages.costmap.build.hidden_splats`). Every renderer of the pipeline loads
    scenes through this.

    Args:
        catalog: the pipeline's catalog (its "aligned" and "costmaps" datasets).
        scene: the catalog's scene entry.
        loaded: the aligned dataset's (scene, attrs) when the caller has loaded it already.
        load_kw: passed to the aligned dataset's load (view_dependent).
    """
    gs, attrs = loaded or catalog.dataset("aligned", scene).load(**load_kw)
    hidden = catalog.dataset("costmaps", scene).hidden(embodiment)
    if not len(hidden):
        return gs, attrs
    return without_splats(gs, hidden), {**attrs, "hidden_splats": int(len(hidden))}
