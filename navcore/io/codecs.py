"""Codecs of the project's Zarr grids, chosen per kind of array by measurement (issue 46: a large
sparse scene's voxel and costmap grids grow with its floor area, not with its Gaussians).

Only codecs of the Zarr v3 specification (Blosc, Zstd), so that any Zarr v3 reader opens the
stores; readers need nothing new, as every array names its codecs in its metadata (stores written
before keep working). Measured on the real hall (wangsha_hall, voxel grid 1284 x 278 x 683 bool,
2.6 % occupied; bytes of the array, then on disk with 4 KiB blocks, then the write):

| V (bool), chunks 32 x 64 x 64 | bytes | on disk | files | write |
| --- | --- | --- | --- | --- |
| Zstd level 0 (zarr's default, before) | 1,331,907 | 2,760,704 | 2,255 | 0.8 s |
| Blosc zstd 5, bitshuffle | 752,099 | 2,519,040 | 2,255 | 1.0 s |
| the same in shards of one x-slab of chunks | 789,664 | 839,680 | 65 | 0.8 s |
| Blosc zstd 9, bitshuffle, sharded | 692,457 | 733,184 | 65 | 7.9 s |
| numcodecs PackBits + Zstd 9 (not in the v3 spec) | 733,978 | 2,519,040 | 2,255 | 1.3 s |

bitshuffle packs a bool array's bits as PackBits would; shards keep the small chunks (empty ones
are not stored) in one file per slab. Costmap layers of generated scenes (291 x 256, bytes):
clearance float32 Zstd 0 71,023, Zstd 9 68,317, Zstd 19 64,044, Blosc shuffle 78,793 (the float
distances' low bytes are noise; Zstd 19 writes a whole map in milliseconds); components int32
Zstd 0 2,818, Blosc zstd 9 shuffle 1,478; the bool layers 1.2-2.4 KB either way.
"""
from __future__ import annotations

import math

import numpy as np


def array_codecs(dtype) -> dict:
    """Keyword arguments of zarr's create_array for a grid of this dtype."""
    from zarr.codecs import BloscCodec, ZstdCodec

    dt = np.dtype(dtype)
    if dt == np.bool_ or dt.itemsize == 1:
        return {"compressors": [BloscCodec(cname="zstd", clevel=5, shuffle="bitshuffle")]}
    if dt.kind == "f":
        return {"compressors": [ZstdCodec(level=19)]}
    return {"compressors": [BloscCodec(cname="zstd", clevel=9, shuffle="shuffle")]}


def slab_shards(shape: tuple[int, ...], chunks: tuple[int, ...]) -> tuple[int, ...]:
    """Shards of one slab of chunks along the first axis, spanning the others whole (rounded up
    to whole chunks): one file per slab instead of one per chunk."""
    return (chunks[0],) + tuple(c * math.ceil(s / c) for s, c in zip(shape[1:], chunks[1:]))
