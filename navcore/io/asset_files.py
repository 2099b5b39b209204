"""File names of the NavArena V1 scene asset that more than one stage needs."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from navcore.paths import contained

ALIGNED_FILES = {"ply": "aligned.ply", "spz": "aligned.spz", "source": None}
"""asset.aligned_format -> the aligned model's file in the asset (source: none, the asset's link to
the original and the manifest's extrinsic matrix give it: `load_aligned`)."""
COMPRESSED_SOURCES = ("spz", "sog", "splat", "supersplat_ply")
"""Source formats whose asset keeps the aligned model as SPZ under asset.aligned_format=auto."""


def aligned_file(fmt: str, compressed_source: bool = False) -> str | None:
    """The aligned model's file name for asset.aligned_format fmt (auto: SPZ for a compressed
    source, an INRIA PLY otherwise; source: None)."""
    if fmt == "auto":
        fmt = "spz" if compressed_source else "ply"
    if fmt not in ALIGNED_FILES:
        raise ValueError(f"asset.aligned_format={fmt!r}; choose auto or one of {', '.join(ALIGNED_FILES)}")
    return ALIGNED_FILES[fmt]


def _manifest(asset_dir) -> tuple[Path, Path, dict]:
    folder = Path(asset_dir)
    man = folder / "manifest.json"
    if not man.is_file():
        raise FileNotFoundError(f"{folder}: no manifest.json (not a NavArena V1 asset folder)")
    return folder, man, json.loads(man.read_text())


def keeps_aligned_file(asset_dir) -> bool:
    """Whether a V1 asset folder keeps an aligned model file (False for asset.aligned_format=source,
    whose model is the original and its extrinsic matrix: `load_aligned`)."""
    return not _manifest(asset_dir)[2].get("aligned_from_source")


def aligned_model(asset_dir) -> Path:
    """The aligned model's file of a V1 asset folder (aligned.ply or aligned.spz), as its manifest
    names it; NavArena's readers (`navcore.gaussians.formats.read_gaussians`) load either. An asset
    made with asset.aligned_format=source has none: `load_aligned` reads its model."""
    folder, man, manifest = _manifest(asset_dir)
    files = manifest.get("files", {})
    name = files.get("aligned") or files.get("aligned_ply")
    if not name and manifest.get("aligned_from_source"):
        raise FileNotFoundError(f"{man}: the asset keeps no aligned model file (asset.aligned_format=source: "
                                "the original and its extrinsic matrix; navcore.io.asset_files.load_aligned reads it)")
    if not name or not contained(folder, name, f"{man}: files.aligned").is_file():
        raise FileNotFoundError(f"{man}: files.aligned names {name!r}, which is not in the folder")
    return folder / name


def load_aligned(asset_dir):
    """The aligned model (GaussianScene, z up, floor at z = 0) of a V1 asset folder: its aligned
    file, or, for an asset made with asset.aligned_format=source, its copy of the original read as
    ingest read it (format, level of detail, scale, validation: the manifest's aligned_from_source,
    checked against the checksum recorded there) and moved by processing.extrinsic_matrix, which
    also turns the view-dependent colour. The same Gaussians as the pipeline's aligned scene, to
    the bit, at no bytes beyond the original."""
    import numpy as np

    folder, man, manifest = _manifest(asset_dir)
    src = manifest.get("aligned_from_source")
    if not src:
        from navcore.gaussians.formats import read_gaussians

        return read_gaussians(aligned_model(folder))
    from navcore.gaussians.errors import SceneFormatError
    from navcore.gaussians.store import scene_checksum
    from navcore.gaussians.validate import ValidationLimits, read_validated

    path = contained(folder, src["path"], f"{man}: aligned_from_source.path")
    scene, _ = read_validated(path, src["format"], manifest.get("scene_id"), src.get("level"), src.get("scale", 1.0),
                              ValidationLimits(**src.get("limits", {})))
    if scene_checksum(scene) != src["checksum"]:
        raise SceneFormatError(path, f"not the original the asset {folder} was made from (checksum of its Gaussians); "
                               "re-run the asset stage (stages=[asset] force=true)", manifest.get("scene_id"))
    return scene.transformed(np.asarray(manifest["processing"]["extrinsic_matrix"], np.float64))


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
