"""Zarr store of a GaussianScene: one group, one array per attribute, attrs for metadata.

Two kinds of store, read alike by `read_scene_zarr`:
- copy: every attribute as a compressed array;
- reference: the source file's path, format, level, scale and validation limits (the recipe of
  `navcore.gaussians.validate.read_validated`), a checksum of the resulting Gaussians, and only
  the per-Gaussian extras the pipeline adds (e.g. the content mask): the Gaussians themselves are
  read from the source again, so the store costs kilobytes instead of a second copy of the scene.
  A source that changed since (another checksum) or went missing is a clear error naming both.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import zarr

from navcore.gaussians.errors import SceneFormatError
from navcore.gaussians.model import GaussianScene

_FIELDS = ("means", "quats", "log_scales", "opacity_logits", "sh")
_CHUNK_ROWS = 1 << 18


def scene_checksum(scene: GaussianScene) -> str:
    """sha256 over the Gaussians' arrays (little-endian float32, in _FIELDS order)."""
    h = hashlib.sha256()
    for name in _FIELDS:
        h.update(np.ascontiguousarray(getattr(scene, name), "<f4").tobytes())
    return h.hexdigest()


def _array(g, name, arr):
    g.create_array(name, data=arr, chunks=(min(_CHUNK_ROWS, max(len(arr), 1)),) + arr.shape[1:])


def write_scene_zarr(path: str | Path, scene: GaussianScene, attrs: dict | None = None,
                     source: dict | None = None) -> None:
    """Write a scene to a new Zarr group at ``path`` (the caller makes it atomic).

    source: None for a copy; for a reference store, the arguments of read_validated that give
    ``scene`` back: {path, format, level, scale, limits (dict)}.
    """
    g = zarr.open_group(str(path), mode="w")
    if source is None:
        for name in _FIELDS:
            _array(g, name, getattr(scene, name))
        kind = {"store": "copy"}
    else:
        kind = {"store": "reference", "source_ref": {**source, "path": str(source["path"])},
                "checksum": scene_checksum(scene)}
    for name, arr in scene.extras.items():
        _array(g, f"extra_{name}", arr)
    g.attrs.update({"n_gaussians": len(scene), "sh_degree": scene.sh_degree, **kind, **(attrs or {})})


def _from_source(path: Path, attrs: dict) -> GaussianScene:
    from navcore.gaussians.validate import ValidationLimits, read_validated

    ref = attrs["source_ref"]
    sid = attrs.get("scene_id")
    if not Path(ref["path"]).exists():
        raise SceneFormatError(ref["path"], f"the source of the store {path} is gone; restore it or rerun "
                               "ingest (force=true)", sid)
    scene, _ = read_validated(ref["path"], ref["format"], sid, ref.get("level"), ref.get("scale", 1.0),
                              ValidationLimits(**ref.get("limits", {})))
    if len(scene) != attrs["n_gaussians"] or scene_checksum(scene) != attrs["checksum"]:
        raise SceneFormatError(ref["path"], f"the source changed since it was ingested into {path} (checksum); "
                               "rerun ingest (force=true)", sid)
    return scene


def read_scene_zarr(path: str | Path) -> tuple[GaussianScene, dict]:
    """Read a scene written by write_scene_zarr (either kind); returns (scene, attrs)."""
    g = zarr.open_group(str(path), mode="r")
    attrs = dict(g.attrs)
    extras = {k[6:]: np.asarray(g[k][...]) for k in g.array_keys() if k.startswith("extra_")}
    if attrs.get("store") == "reference":
        scene = _from_source(Path(path), attrs)
        scene.extras.update(extras)
        return scene, attrs
    parts = {name: np.asarray(g[name][...]) for name in _FIELDS}
    return GaussianScene(**parts, extras=extras), attrs
