"""Real spherical harmonics in the 3DGS convention (the basis of the INRIA / gsplat eval_sh) and
the rotation of SH coefficients under a rigid rotation of the scene."""
from __future__ import annotations

import numba
import numpy as np

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
      1.445305721320277, -0.5900435899266435)


def sh_basis(dirs: np.ndarray, degree: int) -> np.ndarray:
    """[N, (degree+1)^2] basis values at unit directions [N, 3] (x, y, z), 3DGS ordering and signs."""
    x, y, z = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    out = [np.full_like(x, C0)]
    if degree >= 1:
        out += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [C2[0] * xy, C2[1] * yz, C2[2] * (2 * zz - xx - yy), C2[3] * xz, C2[4] * (xx - yy)]
    if degree >= 3:
        out += [C3[0] * y * (3 * xx - yy), C3[1] * xy * z, C3[2] * y * (4 * zz - xx - yy),
                C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy), C3[5] * z * (xx - yy),
                C3[6] * x * (xx - 3 * yy)]
    return np.stack(out, 1)


def sh_rotation(rot: np.ndarray, degree: int) -> list[np.ndarray]:
    """Per band l = 1..degree, the (2l+1)x(2l+1) matrix M_l with c'_l = M_l c_l, so that the
    rotated coefficients evaluated at R d equal the original ones at d.

    Each band is closed under rotation, so M_l is found exactly by least squares from sampled
    directions: sum_m c'_m Y_m(n) = sum_m c_m Y_m(R^T n) for all n, i.e. Y_l(N) M_l = Y_l(N R).
    """
    n = np.random.default_rng(0).normal(size=(64, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    a = sh_basis(n, degree)
    b = sh_basis(n @ np.asarray(rot, float), degree)  # rows: R^T n
    mats = []
    for l in range(1, degree + 1):
        s = slice(l * l, (l + 1) * (l + 1))
        m, *_ = np.linalg.lstsq(a[:, s], b[:, s], rcond=None)
        mats.append(m)
    return mats


def rotate_sh(sh: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Rotate [N, K, 3] SH coefficients by the 3x3 rotation ``rot`` (the DC band is invariant)."""
    k = sh.shape[1]
    degree = int(round(np.sqrt(k))) - 1
    if degree == 0:
        return sh
    out = np.array(sh, dtype=sh.dtype, order="C")
    for l, m in enumerate(sh_rotation(rot, degree), start=1):
        _rotate_band(out, np.ascontiguousarray(m, np.float64), l * l)
    return out


@numba.njit(cache=True)
def _rotate_band(sh, m, first):
    """In place: sh[n, first:first+b, c] <- m @ sh[n, first:first+b, c] per Gaussian and channel,
    summed in float64 in order (numpy's einsum took 3.3 of the 4.2 s that 1.5 M degree-3
    Gaussians cost; this gives the same bits)."""
    b = m.shape[0]
    tmp = np.empty(b)
    for n in range(sh.shape[0]):
        for c in range(sh.shape[2]):
            for i in range(b):
                acc = 0.0
                for j in range(b):
                    acc += m[i, j] * np.float64(sh[n, first + j, c])
                tmp[i] = acc
            for i in range(b):
                sh[n, first + i, c] = tmp[i]
