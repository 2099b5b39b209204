"""File names of the NavArena V1 scene asset that more than one stage needs."""
from __future__ import annotations

ALIGNED_FILES = {"ply": "aligned.ply", "spz": "aligned.spz"}
"""asset.aligned_format -> the aligned model's file in the asset."""


def aligned_file(fmt: str) -> str:
    """The aligned model's file name for asset.aligned_format fmt."""
    if fmt not in ALIGNED_FILES:
        raise ValueError(f"asset.aligned_format={fmt!r}; choose one of {', '.join(ALIGNED_FILES)}")
    return ALIGNED_FILES[fmt]
