"""The CPU renderer: compiled (numba) EWA splatting with gsplat's classic-mode rules.

Same rules as `navcore/render/cpu.py` (the plain-PyTorch reference, which documents them and
was checked against gsplat on an H100), organised so that the work is proportional to what the
camera sees rather than to the scene:

1. cull: blocks of 256 consecutive Gaussians whose bounding sphere lies outside the widened view
   are passed over whole (files in the wild are in spatial order), then a conservative test of
   each remaining mean (near / far plane on the mean depth, gsplat's rule; the image rectangle
   widened by an upper bound on each Gaussian's footprint, from its largest standard deviation),
   so only candidates get the full projection;
2. order: a stable LSD radix sort of the candidates' depth keys (float bits; ties keep the
   Gaussian index order, gsplat's order);
3. project the candidates (EWA with the clamped Jacobian, eps2d, opacity-aware box) in
   parallel, reading them in index order and writing each row at its depth rank, then a counting
   sort into 16x16 tiles, so each tile's list is by depth then index;
4. rasterise: tiles in parallel, front to back with the exclusive stop at T <= 1e-4, a tile
   ending when all its pixels are done. A Gaussian visits only its box inside the tile (outside
   it its alpha is below 1/255 by construction of the box, so gsplat skips those pixels too),
   less the rows at the box's top and bottom whose pixels are all finished (a per-row bitmask;
   a Gaussian whose box is all finished is skipped without reading its render data). A box of a
   few pixels is composited pixel by pixel; a larger one as one branch-free pass per half tile
   (the tile state is laid out by 8-column halves, so the box's rows in a half are contiguous):
   selects and integer sums only, exp as a polynomial, which LLVM turns into SIMD code (AVX2 /
   AVX-512 here). A Gaussian's colour (SH at the view direction) is evaluated when it first
   contributes to a tile: in a real room only about a quarter of the candidates reach a pixel,
   and the SH coefficients are most of the bytes read.

The scene is prepared once (`prepare`): float32 means, the 3D covariances, opacities, SH
coefficients, each Gaussian's largest standard deviation and the culling blocks.

Modules, by stage as gsplat separates them: simd (constants, LLVM intrinsics), project (prepare,
cull, projection), binning (depth ranks, tiles), composite (the rasteriser); this package's
render_one / render are the entry points.
"""
from __future__ import annotations

import numba  # noqa: F401 - the entry points' callers expect numba loaded with the package
import numpy as np

from navcore.gaussians.model import render_sh_degree
from navcore.render.cpu_fast.binning import SMALL_SORT, _bin, _depth_ranks, _depths
from navcore.render.cpu_fast.composite import _rasterize
from navcore.render.cpu_fast.project import NDATA, _block_out, _cull, _project, prepare
from navcore.render.cpu_fast.simd import ALPHA_MIN, EXTENT_MAX, SQRT_EPS2D, T_MIN, TILE, _prefetch, _wide_vectors

__all__ = ["ALPHA_MIN", "EXTENT_MAX", "NDATA", "SMALL_SORT", "SQRT_EPS2D", "TILE", "T_MIN", "_bin", "_block_out",
           "_cull", "_depth_ranks", "_depths", "_prefetch", "_project", "_rasterize", "_wide_vectors", "prepare",
           "render", "render_one"]


def render_one(g: dict, viewmat: np.ndarray, K: np.ndarray, width: int, height: int, deg: int,
               near: float = 0.01, far: float = 1e10, eps2d: float = 0.3, features=None, extra=None, visits=None):
    """One camera -> (feats [H, W, C], depth [H, W], alpha [H, W]) float32 numpy arrays; visits
    ([N, 2] uint8, zeroed, optional) gets which Gaussians the rasteriser read and which
    contributed (`_rasterize`; benchmarks.scale.render_cpu's bound on culling).

    The compiled passes do not check their indices, so what they would read out of bounds is
    refused here: deg above the scene's SH degree, features / extra without one row per Gaussian."""
    n = len(g["means"])
    render_sh_degree(deg, g["sh"].shape[1])  # ValueError above the scene's degree
    for name, f in (("features", features), ("extra", extra)):
        if f is not None and (np.ndim(f) != 2 or len(f) != n):
            raise ValueError(f"{name} must be [{n}, C] (one row per Gaussian), got shape {np.shape(f)}")
    if eps2d > SQRT_EPS2D ** 2:
        raise ValueError(f"eps2d={eps2d} exceeds the cull's bound ({SQRT_EPS2D ** 2:.4f}: SQRT_EPS2D)")
    R = np.ascontiguousarray(viewmat[:3, :3], np.float32)
    t = np.ascontiguousarray(viewmat[:3, 3], np.float32)
    fx, fy, cx, cy = (float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    lo_x, hi_x = -(cx / fx + 0.3 * tan_x), (width - cx) / fx + 0.3 * tan_x
    lo_y, hi_y = -(cy / fy + 0.3 * tan_y), (height - cy) / fy + 0.3 * tan_y
    nth = numba.get_num_threads()
    idx = _cull(g["means"], g["smax"], g["opacities"], g["blocks"], R, t, fx, fy, cx, cy, width, height, near, far,
                max(-lo_x, hi_x), max(-lo_y, hi_y), nth)
    if features is not None:
        feats_in, d = np.ascontiguousarray(features, np.float32), -1
    elif extra is not None:
        feats_in, d = np.ascontiguousarray(extra, np.float32), deg
    else:
        feats_in, d = np.zeros((n, 0), np.float32), deg
    nf = feats_in.shape[1] + (3 if d >= 0 else 0)
    # depth ranks first (stable: ties keep the index order, as gsplat), so that the projection
    # writes each row at its place front to back
    z = np.empty(len(idx), np.float32)
    _depths(idx, g["means"], R, t, z)
    pos = _depth_ranks(z)
    data = np.empty((len(idx), NDATA), np.float32)
    box = np.empty((len(idx), 4), np.int32)
    gid = np.empty(len(idx), np.int64)
    _project(idx, g["means"], g["cov"], g["opacities"], g["ext"], g["lmax"], R, t, fx, fy, cx, cy, width, height, eps2d,
             lo_x, hi_x, lo_y, hi_y, pos, data, box, gid)
    campos = (-R.T.astype(np.float64) @ t.astype(np.float64)).astype(np.float32)
    rows, pbox, offsets = _bin(box, data, width, height, nth)
    out = np.zeros((height, width, nf + 2), np.float32)
    if visits is not None and (visits.shape != (n, 2) or visits.dtype != np.uint8):
        raise ValueError(f"visits must be a [{n}, 2] uint8 array, got {visits.dtype} {visits.shape}")
    _rasterize(rows, pbox, offsets, data, gid, g["means"], g["sh"], d, feats_in, campos, nf, width, height, out, nth,
               visits)
    alpha = out[..., nf + 1]
    dep = out[..., nf] / np.maximum(alpha, np.float32(1e-10))
    return out[..., :nf], dep, alpha


def render(g: dict, viewmats, Ks, width: int, height: int, sh_degree: int | None = None, near: float = 0.01,
           far: float = 1e10, features=None, extra=None):
    """A batch of cameras, the same contract as `navcore.render.cpu.render` (torch tensors out)."""
    import torch

    deg = render_sh_degree(sh_degree, g["sh"].shape[1])
    outs = [render_one(g, vm, K, width, height, deg, near, far, features=features, extra=extra)
            for vm, K in zip(np.asarray(viewmats, np.float32), np.asarray(Ks, np.float32))]
    rgb, dep, alp = (torch.from_numpy(np.stack([o[k] for o in outs])) for k in range(3))
    return rgb, dep, alp
