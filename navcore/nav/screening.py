"""Scene and region screening shared by the stages: growing a flagged layer by a margin, and a
scene's verdict from its quality score (stage `screen` writes the layer and the score, the
episodes stage keeps out of the layer and gives the verdict)."""
from __future__ import annotations

import numpy as np
from scipy import ndimage

VERDICTS = ("pass", "warn", "reject")


def disk(k: int) -> np.ndarray:
    """[2k+1, 2k+1] bool disc of radius k cells."""
    return np.hypot(*np.mgrid[-k:k + 1, -k:k + 1]) <= k


def grow(mask: np.ndarray, margin_m: float, resolution: float) -> np.ndarray:
    """The mask grown by a disc of margin_m (metres)."""
    k = int(np.ceil(margin_m / resolution - 1e-9))
    return ndimage.binary_dilation(mask, disk(k)) if k > 0 and mask.any() else np.asarray(mask, bool)


def verdict(score: float, warn_below: float, reject_below: float) -> str:
    """pass, warn (score below warn_below) or reject (below reject_below)."""
    if not 0 <= reject_below <= warn_below <= 1:
        raise ValueError(f"screen: need 0 <= reject_below ({reject_below}) <= warn_below ({warn_below}) <= 1")
    return "reject" if score < reject_below else "warn" if score < warn_below else "pass"
