"""File names of the NavArena V1 scene asset that more than one stage needs."""
from __future__ import annotations

import json
from pathlib import Path

ALIGNED_FILES = {"ply": "aligned.ply", "spz": "aligned.spz"}
"""asset.aligned_format -> the aligned model's file in the asset."""
COMPRESSED_SOURCES = ("spz", "sog", "splat", "supersplat_ply")
"""Source formats whose asset keeps the aligned model as SPZ under asset.aligned_format=auto."""


def aligned_file(fmt: str, compressed_source: bool = False) -> str:
    """The aligned model's file name for asset.aligned_format fmt (auto: SPZ for a compressed
    source, an INRIA PLY otherwise)."""
    if fmt == "auto":
        fmt = "spz" if compressed_source else "ply"
    if fmt not in ALIGNED_FILES:
        raise ValueError(f"asset.aligned_format={fmt!r}; choose auto or one of {', '.join(ALIGNED_FILES)}")
    return ALIGNED_FILES[fmt]


def aligned_model(asset_dir) -> Path:
    """The aligned model's file of a V1 asset folder (aligned.ply or aligned.spz), as its manifest
    names it; NavArena's readers (`navcore.gaussians.formats.read_gaussians`) load either."""
    folder = Path(asset_dir)
    man = folder / "manifest.json"
    if not man.is_file():
        raise FileNotFoundError(f"{folder}: no manifest.json (not a NavArena V1 asset folder)")
    files = json.loads(man.read_text()).get("files", {})
    name = files.get("aligned") or files.get("aligned_ply")
    if not name or not (folder / name).is_file():
        raise FileNotFoundError(f"{man}: files.aligned names {name!r}, which is not in the folder")
    return folder / name
