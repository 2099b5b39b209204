"""Bounds on what a file may make a reader allocate: a compressed stream or image may not
declare more than MAX_INFLATION times its own size (real 3DGS files inflate 1-10x; a
decompression bomb or a lying header far more), so a hostile file cannot blow the worker's memory."""
from __future__ import annotations

from navcore.gaussians.errors import SceneFormatError

MAX_INFLATION = 256
SLACK = 1 << 16
"""Bytes any stream may declare whatever its size (tiny streams of constant data)."""


def check_inflation(where, declared: int, stored: int, what: str) -> None:
    """Raise SceneFormatError when `declared` bytes (or pixels x 4) from `stored` bytes exceed the bound."""
    if declared < 0 or declared > MAX_INFLATION * max(stored, 0) + SLACK:
        raise SceneFormatError(where, f"{what} declares {declared:,} bytes from {stored:,} stored (more than "
                                      f"{MAX_INFLATION}x: a decompression bomb or a lying header)")
