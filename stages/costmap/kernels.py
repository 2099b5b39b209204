"""Numba kernel of the costmap build: triangle rasterization (the alpha-shape support)."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def rasterize_triangles(tris, out):
    """Set out[y, x] = True for integer points (x, y) inside any triangle tris[T, 3, 2]."""
    ny, nx = out.shape
    for t in range(tris.shape[0]):
        x0, y0 = tris[t, 0, 0], tris[t, 0, 1]
        x1, y1 = tris[t, 1, 0], tris[t, 1, 1]
        x2, y2 = tris[t, 2, 0], tris[t, 2, 1]
        den = (y1 - y2) * (x0 - x2) + (x2 - x1) * (y0 - y2)
        if den == 0.0:
            continue
        xa = max(int(np.ceil(min(x0, x1, x2))), 0)
        xb = min(int(np.floor(max(x0, x1, x2))), nx - 1)
        ya = max(int(np.ceil(min(y0, y1, y2))), 0)
        yb = min(int(np.floor(max(y0, y1, y2))), ny - 1)
        for y in range(ya, yb + 1):
            for x in range(xa, xb + 1):
                l0 = ((y1 - y2) * (x - x2) + (x2 - x1) * (y - y2)) / den
                l1 = ((y2 - y0) * (x - x2) + (x0 - x2) * (y - y2)) / den
                if l0 >= -1e-9 and l1 >= -1e-9 and 1.0 - l0 - l1 >= -1e-9:
                    out[y, x] = True
