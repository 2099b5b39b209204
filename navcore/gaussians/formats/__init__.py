"""Readers and writers of the 3DGS file formats found in the wild.

``read_gaussians(path, fmt=None)`` dispatches on the format name or the file name:

| format           | reader                      | writer                   |
| ---------------- | --------------------------- | ------------------------ |
| inria_ply        | INRIA binary/ascii PLY, SH 0-3 | write_inria_ply       |
| supersplat_ply   | SuperSplat compressed PLY   | -                        |
| splat            | antimatter15 .splat         | write_splat (also NavArena compressed.splat) |
| spz              | Niantic .spz (v2, v3, v4)   | write_spz                |
| sog              | PlayCanvas SOG v2: .sog zip, folder with meta.json, streamed lod-meta.json | write_sog, write_sog_lod |
| npy_folder       | SceneSplat / InteriorGS .npy folder | write_npy_folder |
"""
from __future__ import annotations

from pathlib import Path

from navcore.gaussians.errors import SceneFileNotFoundError, SceneFormatError
from navcore.gaussians.formats.npy_folder import read_npy_folder, write_npy_folder  # noqa: F401 (public API)
from navcore.gaussians.formats.ply import read_ply, write_inria_ply
from navcore.gaussians.formats.sog import LOD_META, META, read_sog, write_sog, write_sog_lod
from navcore.gaussians.formats.splat import read_splat, write_splat
from navcore.gaussians.formats.spz import read_spz, write_spz
from navcore.registry import Registry

READERS = Registry("format", {
    "ply": "navcore.gaussians.formats.ply:read_ply",  # INRIA or SuperSplat: the header tells
    "inria_ply": "navcore.gaussians.formats.ply:read_ply",
    "supersplat_ply": "navcore.gaussians.formats.ply:read_ply",
    "splat": "navcore.gaussians.formats.splat:read_splat",
    "spz": "navcore.gaussians.formats.spz:read_spz",
    "sog": "navcore.gaussians.formats.sog:read_sog",
    "npy_folder": "navcore.gaussians.formats.npy_folder:read_npy_folder",
})
"""format name -> reader(path, level=None) of a GaussianScene."""
FORMATS = tuple(k for k in READERS if k != "ply")
FOLDER_FORMATS = ("sog", "npy_folder")
"""Formats whose source may be a folder (SOG: a folder with meta.json / lod-meta.json)."""


def detect_format(path: str | Path) -> str:
    """Format name from the path: a folder holding lod-meta.json or meta.json is SOG, another
    folder an .npy folder; otherwise the file name decides."""
    p = Path(path)
    if p.is_dir():
        return "sog" if (p / LOD_META).is_file() or (p / META).is_file() else "npy_folder"
    name = p.name.lower()
    if name.endswith(".sog") or name in (LOD_META, META):
        return "sog"
    if name.endswith(".ply"):
        return "ply"  # INRIA or SuperSplat: the header tells
    if name.endswith(".splat"):
        return "splat"
    if name.endswith(".spz"):
        return "spz"
    raise SceneFormatError(p, "cannot tell the 3DGS format from the name; expected .ply, .splat, .spz, .sog, "
                                "lod-meta.json / meta.json (SOG) or an .npy folder")


def source_files(path: str | Path) -> tuple[Path, list[Path]]:
    """(the folder, the files) that make up the scene at path: the file itself, or every file under
    a folder layout's folder (a SOG folder or streamed LOD scene, given by its meta.json /
    lod-meta.json or the folder; an npy folder)."""
    path = Path(path)
    folder = path.parent if path.name in (LOD_META, META) else path
    if folder.is_dir():
        return folder, sorted(p for p in folder.rglob("*") if p.is_file())
    return path.parent, [path]


def read_gaussians(path: str | Path, fmt: str | None = None, level: int | None = None):
    """Read a 3DGS file into a GaussianScene (unvalidated: see navcore.gaussians.validate).

    Args:
        path: file or folder.
        fmt: one of FORMATS, "ply" (either PLY flavour) or None to detect from the name.
        level: level of detail of a streamed SOG (0 = finest; None = the finest whose files are
            all present); other formats have one level and ignore it.
    """
    p = Path(path)
    if not p.exists():
        raise SceneFileNotFoundError(p)
    fmt = fmt or detect_format(p)
    if fmt not in READERS:
        raise SceneFormatError(p, f"unknown format {fmt!r}; known: {', '.join(FORMATS)}")
    if p.is_dir() and fmt not in FOLDER_FORMATS:
        raise SceneFormatError(p, f"is a folder, but {fmt} is a single-file format")
    try:
        return READERS[fmt](p, level=level)
    except OSError as e:  # unreadable, a folder where a file belongs, vanished mid-read, ...
        raise SceneFormatError(getattr(e, "filename", None) or p, f"cannot be read ({e.strerror or e})") from None


__all__ = [
    "FORMATS", "detect_format", "read_gaussians", "read_ply", "write_inria_ply", "read_splat", "write_splat",
    "read_spz", "write_spz", "read_sog", "write_sog", "write_sog_lod", "read_npy_folder", "write_npy_folder",
]
