"""File names of the NavArena V1 scene asset that more than one stage needs."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from navcore.io.paths import contained

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
    if not name or not contained(folder, name, f"{man}: files.aligned").is_file():
        raise FileNotFoundError(f"{man}: files.aligned names {name!r}, which is not in the folder")
    return folder / name


def write_pgm(path: Path, occ: np.ndarray) -> None:
    """ROS map_server PGM (P5): 0 occupied, 255 free; rows flipped so the first row is max y."""
    img = np.where(occ, 0, 255).astype(np.uint8)[::-1]
    h, w = img.shape
    Path(path).write_bytes(f"P5\n{w} {h}\n255\n".encode() + img.tobytes())


def read_pgm(path: Path) -> np.ndarray:
    """Inverse of write_pgm: [ny, nx] bool occupancy, row = y ascending."""
    data = Path(path).read_bytes()
    parts = data.split(maxsplit=4)
    if len(parts) < 5 or parts[0] != b"P5":
        raise ValueError(f"{path}: not a binary PGM (P5) map")
    w, h = int(parts[1]), int(parts[2])
    if len(parts[4]) < w * h:
        raise ValueError(f"{path}: {len(parts[4])} bytes of pixels, the header says {w} x {h}")
    img = np.frombuffer(parts[4][: w * h], dtype=np.uint8).reshape(h, w)
    return (img[::-1] < 128)


def read_nav_map(asset_dir) -> tuple[np.ndarray, tuple[float, float], float]:
    """A V1 asset's ROS map: (occupancy [ny, nx] bool, row = y ascending; origin (x, y) of the
    minimum corner, metres; resolution, metres), from nav_map.yaml and the PGM it names."""
    import yaml

    folder = Path(asset_dir)
    spec = yaml.safe_load((folder / "nav_map.yaml").read_text())
    image = contained(folder, str(spec["image"]), f"{folder / 'nav_map.yaml'}: image")
    return read_pgm(image), (float(spec["origin"][0]), float(spec["origin"][1])), float(spec["resolution"])
