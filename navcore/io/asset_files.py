"""File names of the NavArena V1 scene asset that more than one stage needs."""
from __future__ import annotations

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
