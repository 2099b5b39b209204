"""The CPU renderer's constants (gsplat's rules) and its low-level helpers: wide vectors and
software prefetch as LLVM intrinsics."""
from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba.core import cgutils
from numba.extending import intrinsic

TILE = 16
ALPHA_MIN = np.float32(1.0 / 255.0)
T_MIN = np.float32(1e-4)
EXTENT_MAX = 3.33  # gsplat's cap on the footprint extent (sigmas)
SQRT_EPS2D = 0.5478  # the cull's bound on sqrt(eps2d) (px): it holds for eps2d <= 0.3, gsplat's default
FAST = {"nnan", "ninf", "nsz", "contract"}
"""The fast-math flags of the rasteriser: no NaN or infinity (validated scenes) and signed zeros
alike, which let LLVM use vector min / max, and multiply-adds fused (10-20% of the frame time);
no reassociation, so that a pixel gets the same operations whether the vector loop or its scalar
remainder computes it, whatever the vector width."""


@intrinsic
def _wide_vectors(typingctx):
    """Lets LLVM vectorise the calling function with 512-bit registers where the CPU has them.

    On CPUs with AVX-512 LLVM prefers 256-bit vectors (the "prefer-256-bit" tuning, against the
    clock drop of the first AVX-512 Xeons); the function attribute "prefer-vector-width"="512"
    (clang's -mprefer-vector-width) lifts it for this function alone. Placed in the rasteriser's
    parallel worker, the compositing loop takes two half-tile rows an iteration: real room 160x120
    58.5 -> 54.8 ms a frame, 640x480 158 -> 135 (2-core Emerald Rapids VM), the same bytes (no
    reassociation: each pixel gets the same operations whatever the width). Without AVX-512 the
    attribute changes nothing. llvmlite's attribute set only takes the attributes it knows, hence
    the plain set.add (it writes the string as given into the function's definition)."""
    def codegen(context, builder, sig, args):
        set.add(builder.function.attributes, '"prefer-vector-width"="512"')
        return context.get_dummy_value()

    return numba.types.none(), codegen


@intrinsic
def _prefetch(typingctx, arr, i):
    """Asks the CPU to bring element i of the C-contiguous array arr (flat index) into the cache
    (llvm.prefetch: read, keep in all levels); no effect on the results. The rasteriser reads
    each tile's render rows at scattered places (a tile's Gaussians are a sparse subset of the
    depth order): fetching the row of the Gaussian PREFETCH_AHEAD places later in the list
    overlaps those misses with the compositing (real room 160x120: rasterisation 31 -> 29 ms,
    640x480 135 -> 130 ms a frame)."""
    def codegen(context, builder, sig, args):
        ary = context.make_array(sig.args[0])(context, builder, args[0])
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
                                            "llvm.prefetch.p0")
        ptr = builder.bitcast(builder.gep(ary.data, [args[1]]), i8p)
        builder.call(fn, [ptr, ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return numba.types.none(arr, i), codegen


PREFETCH_AHEAD = 8  # list entries between a Gaussian's prefetch and its compositing (16: the same)

