"""Canonical Gaussian scene: the single in-memory representation every stage uses.

Conventions (see design.md beside this file):
- means in metres, quaternions (w, x, y, z) normalized, log-scales (natural log of the
  standard deviations in metres), opacity logits (alpha = sigmoid(logit)).
- sh [N, K, 3] spherical-harmonic coefficients, K = (degree + 1)^2, sh[:, 0] is the DC term
  (INRIA f_dc); colour = 0.5 + SH_C0 * sh[:, 0].
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SH_C0 = 0.28209479177387814


def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """Rotation matrices from unit quaternions.

    Args:
        q: [..., 4] (w, x, y, z), normalized.
    Returns:
        [..., 3, 3] rotation matrices (float of q's dtype).
    """
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty(q.shape[:-1] + (3, 3), dtype=q.dtype)
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def axis_sigmas(quats: np.ndarray, log_scales: np.ndarray) -> np.ndarray:
    """[N, 3] float64 standard deviations of Gaussians along the world x, y, z axes (the square
    roots of their covariances' diagonals), from quaternions [N, 4] (normalised here) and log
    scales [N, 3]."""
    q = np.asarray(quats, np.float64)
    rot = quat_to_rotmat(q / np.linalg.norm(q, axis=1, keepdims=True))
    return np.sqrt(np.einsum("nij,nj->ni", rot ** 2, np.exp(2.0 * np.asarray(log_scales, np.float64))))


def rotmat_to_quat(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z), w >= 0, from rotation matrices [..., 3, 3] (Shepperd's method)."""
    r = np.asarray(r, dtype=np.float64)
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    tr = m00 + m11 + m22
    cands = np.stack(
        [
            np.stack([1 + tr, r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1),
            np.stack([r[..., 2, 1] - r[..., 1, 2], 1 + m00 - m11 - m22, r[..., 0, 1] + r[..., 1, 0], r[..., 0, 2] + r[..., 2, 0]], -1),
            np.stack([r[..., 0, 2] - r[..., 2, 0], r[..., 0, 1] + r[..., 1, 0], 1 - m00 + m11 - m22, r[..., 1, 2] + r[..., 2, 1]], -1),
            np.stack([r[..., 1, 0] - r[..., 0, 1], r[..., 0, 2] + r[..., 2, 0], r[..., 1, 2] + r[..., 2, 1], 1 - m00 - m11 + m22], -1),
        ],
        -2,
    )  # [..., 4 candidates, 4]
    best = np.argmax(np.stack([tr, m00, m11, m22], -1), axis=-1)
    q = np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of (w, x, y, z) quaternions, broadcasting."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        -1,
    )


def sh_degree_for_coeffs(k: int) -> int:
    """SH degree d with (d + 1)^2 == k coefficients per channel; ValueError otherwise."""
    d = int(round(np.sqrt(k))) - 1
    if (d + 1) ** 2 != k or d < 0:
        raise ValueError(f"{k} SH coefficients per channel is not (degree + 1)^2")
    return d


def render_sh_degree(requested: int | None, k: int) -> int:
    """The SH degree a renderer evaluates for a scene with k coefficients per channel: all it has
    when requested is None, else requested, which must lie in 0..the scene's degree (a higher one
    would read coefficients the scene does not have)."""
    have = sh_degree_for_coeffs(k)
    if requested is None:
        return have
    if not 0 <= int(requested) <= have:
        raise ValueError(f"sh_degree={requested} asked for a scene with SH degree {have} ({k} coefficient(s) per "
                         f"channel): use 0..{have} or None")
    return int(requested)


@dataclass
class GaussianScene:
    """A set of 3D Gaussians in one frame.

    Attributes:
        means: [N, 3] float32 centres, metres.
        quats: [N, 4] float32 (w, x, y, z), unit norm.
        log_scales: [N, 3] float32 natural log of the standard deviations (metres).
        opacity_logits: [N] float32; alpha = sigmoid(logit).
        sh: [N, K, 3] float32 SH coefficients, K = (degree + 1)^2; sh[:, 0] is the DC term.
        extras: optional per-Gaussian arrays carried along (e.g. "instance_id" [N] int32).
    """

    means: np.ndarray
    quats: np.ndarray
    log_scales: np.ndarray
    opacity_logits: np.ndarray
    sh: np.ndarray
    extras: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self):
        self.means = np.ascontiguousarray(self.means, dtype=np.float32)
        self.quats = np.ascontiguousarray(self.quats, dtype=np.float32)
        self.log_scales = np.ascontiguousarray(self.log_scales, dtype=np.float32)
        self.opacity_logits = np.ascontiguousarray(self.opacity_logits, dtype=np.float32).reshape(-1)
        self.sh = np.ascontiguousarray(self.sh, dtype=np.float32)
        n = len(self.means)
        shapes = {
            "means": (self.means.shape, (n, 3)),
            "quats": (self.quats.shape, (n, 4)),
            "log_scales": (self.log_scales.shape, (n, 3)),
            "opacity_logits": (self.opacity_logits.shape, (n,)),
        }
        for name, (got, want) in shapes.items():
            if got != want:
                raise ValueError(f"GaussianScene.{name} has shape {got}, expected {want}")
        if self.sh.ndim != 3 or self.sh.shape[0] != n or self.sh.shape[2] != 3:
            raise ValueError(f"GaussianScene.sh has shape {self.sh.shape}, expected [N, K, 3]")
        sh_degree_for_coeffs(self.sh.shape[1])
        for k, v in self.extras.items():
            if len(v) != n:
                raise ValueError(f"GaussianScene.extras[{k!r}] has {len(v)} rows, expected {n}")

    def __len__(self) -> int:
        return len(self.means)

    @property
    def sh_degree(self) -> int:
        return sh_degree_for_coeffs(self.sh.shape[1])

    @property
    def scales(self) -> np.ndarray:
        """[N, 3] standard deviations in metres."""
        return np.exp(self.log_scales)

    @property
    def alphas(self) -> np.ndarray:
        """[N] opacities in [0, 1]."""
        return 1.0 / (1.0 + np.exp(-self.opacity_logits.astype(np.float64)))

    @property
    def colors(self) -> np.ndarray:
        """[N, 3] base RGB in [0, 1] from the SH DC term."""
        return np.clip(0.5 + SH_C0 * self.sh[:, 0], 0.0, 1.0)

    def subset(self, keep: np.ndarray) -> "GaussianScene":
        """A new scene holding the rows selected by a boolean mask or index array."""
        return GaussianScene(
            self.means[keep], self.quats[keep], self.log_scales[keep], self.opacity_logits[keep], self.sh[keep],
            {k: v[keep] for k, v in self.extras.items()},
        )

    def transformed(self, transform: np.ndarray) -> "GaussianScene":
        """Apply a rigid 4x4 transform (no scaling) to positions and orientations."""
        t = np.asarray(transform, dtype=np.float64)
        rot = t[:3, :3]
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
            raise ValueError("transform is not a proper rigid motion (rotation part not orthonormal)")
        means = self.means.astype(np.float64) @ rot.T + t[:3, 3]
        q_rot = rotmat_to_quat(rot)
        quats = quat_multiply(q_rot[None], self.quats.astype(np.float64))
        quats /= np.linalg.norm(quats, axis=1, keepdims=True)
        from navcore.gaussians.sh import rotate_sh  # view-dependent colour turns with the scene

        return GaussianScene(means, quats, self.log_scales, self.opacity_logits, rotate_sh(self.sh, rot),
                             dict(self.extras))

    @staticmethod
    def from_colors(means, quats, scales, alphas, colors, extras=None) -> "GaussianScene":
        """Build from activated values: scales in metres, alphas in (0, 1), colours RGB in [0, 1]."""
        alphas = np.clip(np.asarray(alphas, dtype=np.float64), 1e-6, 1 - 1e-6)
        sh = ((np.asarray(colors, dtype=np.float32) - 0.5) / SH_C0)[:, None, :]
        return GaussianScene(
            means, quats, np.log(np.asarray(scales, dtype=np.float64)), np.log(alphas / (1 - alphas)), sh, extras or {}
        )
