"""Zarr store of a GaussianScene (one group, one array per attribute, attrs for metadata)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import zarr

from navcore.gaussians.model import GaussianScene

_FIELDS = ("means", "quats", "log_scales", "opacity_logits", "sh")
_CHUNK_ROWS = 1 << 18


def write_scene_zarr(path: str | Path, scene: GaussianScene, attrs: dict | None = None) -> None:
    """Write a scene to a new Zarr group at ``path`` (the caller makes it atomic)."""
    g = zarr.open_group(str(path), mode="w")
    for name in _FIELDS:
        arr = getattr(scene, name)
        g.create_array(name, data=arr, chunks=(min(_CHUNK_ROWS, max(len(arr), 1)),) + arr.shape[1:])
    for name, arr in scene.extras.items():
        g.create_array(f"extra_{name}", data=arr, chunks=(min(_CHUNK_ROWS, max(len(arr), 1)),) + arr.shape[1:])
    g.attrs.update({"n_gaussians": len(scene), "sh_degree": scene.sh_degree, **(attrs or {})})


def read_scene_zarr(path: str | Path) -> tuple[GaussianScene, dict]:
    """Read a scene written by write_scene_zarr; returns (scene, attrs)."""
    g = zarr.open_group(str(path), mode="r")
    parts = {name: np.asarray(g[name][...]) for name in _FIELDS}
    extras = {k[6:]: np.asarray(g[k][...]) for k in g.array_keys() if k.startswith("extra_")}
    return GaussianScene(**parts, extras=extras), dict(g.attrs)
