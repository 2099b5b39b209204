"""Validation of a freshly read scene: drop unusable Gaussians, count them by reason, and refuse
scenes with nothing usable left. Never raises for a recoverable problem."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from navcore.gaussians.errors import SceneFileNotFoundError, SceneFormatError
from navcore.gaussians.model import GaussianScene


@dataclass
class ValidationLimits:
    """What counts as a usable Gaussian."""

    max_scale_extent_ratio: float = 1.0
    """Gaussians with a standard deviation larger than this times the scene's robust extent (the
    diagonal of the 1st-99th percentile box of the centres) are dropped as absurd."""
    max_log_scale: float = 20.0
    """Log-scales above this (sigma > 4.8e8 in scene units) are absurd whatever the extent."""
    min_quat_norm: float = 1e-6
    """Quaternions with a smaller norm are 'zero quaternions' and dropped."""


@dataclass
class ValidationReport:
    n_input: int
    n_kept: int
    dropped: dict[str, int] = field(default_factory=dict)
    renormalized_quats: int = 0

    def as_dict(self) -> dict:
        return {"n_input": self.n_input, "n_kept": self.n_kept, "dropped": dict(self.dropped),
                "renormalized_quats": self.renormalized_quats}

    def summary(self) -> str:
        parts = [f"{v:,} {k.replace('_', ' ')}" for k, v in self.dropped.items() if v]
        return f"kept {self.n_kept:,}/{self.n_input:,}" + (f" (dropped {', '.join(parts)})" if parts else "")


def sanitize(scene: GaussianScene, path, scene_id: str | None = None,
             limits: ValidationLimits | None = None) -> tuple[GaussianScene, ValidationReport]:
    """Drop non-finite, zero-quaternion and absurd-scale Gaussians; normalize quaternions.

    Returns:
        (clean scene, report). Raises SceneFormatError if the scene is empty or nothing survives.
    """
    lim = limits or ValidationLimits()
    n = len(scene)
    if n == 0:
        raise SceneFormatError(path, "scene holds no Gaussians", scene_id)
    finite = (np.isfinite(scene.means).all(1) & np.isfinite(scene.quats).all(1)
              & np.isfinite(scene.log_scales).all(1) & np.isfinite(scene.opacity_logits)
              & np.isfinite(scene.sh.reshape(n, -1)).all(1))
    qn = np.linalg.norm(scene.quats.astype(np.float64), axis=1)
    zero_q = finite & (qn < lim.min_quat_norm)
    ok = finite & ~zero_q
    if ok.any():
        lo, hi = np.percentile(scene.means[ok], [1, 99], axis=0)
        extent = max(float(np.linalg.norm(hi - lo)), 1e-6)
    else:
        extent = np.inf
    max_log = min(lim.max_log_scale, np.log(lim.max_scale_extent_ratio * extent))
    with np.errstate(invalid="ignore"):
        absurd = ok & (scene.log_scales.max(1) > max_log)
    keep = finite & ~zero_q & ~absurd
    report = ValidationReport(n, int(keep.sum()), {
        "non_finite": int((~finite).sum()), "zero_quaternion": int(zero_q.sum()), "absurd_scale": int(absurd.sum())})
    if report.n_kept == 0:
        raise SceneFormatError(path, f"no usable Gaussians: {report.summary()}", scene_id)
    clean = scene.subset(keep) if report.n_kept < n else scene
    qk = qn[keep]
    report.renormalized_quats = int((np.abs(qk - 1.0) > 1e-3).sum())
    # in float64: a norm above float32's range (components near 3.4e38) would turn into inf
    clean.quats = (clean.quats.astype(np.float64) / qk[:, None]).astype(np.float32)
    return clean, report


def read_validated(path, fmt: str | None, scene_id: str | None = None, level: int | None = None,
                   scale: float = 1.0, limits: ValidationLimits | None = None):
    """Read a source scene, bring it to metres (``scale``) and validate it: (clean scene, report).
    The one definition of a scene's canonical Gaussians, used by ingest and by a store that refers
    to its source instead of copying it."""
    from navcore.gaussians.formats import read_gaussians

    try:
        raw = read_gaussians(path, fmt, level=level)
    except SceneFileNotFoundError as e:
        raise SceneFileNotFoundError(e.path, scene_id) from None
    except SceneFormatError as e:
        raise SceneFormatError(e.path, e.problem, scene_id) from None
    if scale != 1.0:  # the source's units -> metres
        if not scale > 0:
            raise ValueError(f"ingest.scale={scale} must be positive")
        raw.means *= np.float32(scale)
        raw.log_scales += np.float32(np.log(scale))
    return sanitize(raw, path, scene_id, limits)
