"""A scene's capture cameras (cameras.json beside the source, or the synthetic ground truth):
where the scene was filmed from. Semantics renders from them; align uses them as evidence of the
up direction and of the floor (cameras are above the floor, their up vectors point up)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from navcore.gaussians.model import quat_to_rotmat

CAMERA_FILE = "cameras.json"


def intrinsics(width: int, height: int, hfov_deg: float) -> np.ndarray:
    """[3, 3] float32 pinhole intrinsics for a horizontal field of view."""
    f = (width / 2) / math.tan(math.radians(hfov_deg) / 2)
    return np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]], np.float32)


def read_cameras(path: Path, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """A scene's cameras.json -> cameras_from_json."""
    try:
        return cameras_from_json(json.loads(Path(path).read_text()), width, height)
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{path}: not a camera list this stage reads ({type(e).__name__}: {e})") from None


def cameras_from_json(data, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Capture cameras -> (camera -> world [M, 4, 4] in the source frame, OpenCV axes; intrinsics
    [M, 3, 3] for a width x height render of the same field of view).

    Two layouts: ours (synthetic scenes: {hfov_deg, poses: [{position, quat_wxyz}]}) and the INRIA
    3DGS training output's cameras.json ([{width, height, position, rotation (camera -> world,
    3x3), fx, fy}, ...])."""
    c2w, ks = [], []
    if isinstance(data, dict):
        k = intrinsics(width, height, data["hfov_deg"])
        for p in data["poses"]:
            m = np.eye(4)
            q = np.asarray(p["quat_wxyz"], float)
            m[:3, :3], m[:3, 3] = quat_to_rotmat(q / np.linalg.norm(q)), p["position"]
            c2w.append(m)
            ks.append(k)
    else:
        for c in data:
            m = np.eye(4)
            m[:3, :3], m[:3, 3] = np.asarray(c["rotation"], float), c["position"]
            c2w.append(m)
            ks.append(np.array([[c["fx"] * width / c["width"], 0, width / 2],
                                [0, c["fy"] * height / c["height"], height / 2], [0, 0, 1]], np.float32))
    if not c2w:
        raise ValueError("no cameras")
    return np.stack(c2w), np.stack(ks).astype(np.float32)


def camera_file(scene, catalog) -> Path | None:
    """The scene's capture cameras: ground_truth/cameras.json of synthetic scenes; for others a
    cameras.json next to the source file or up to two folders above it (INRIA output layout:
    model/cameras.json, model/point_cloud/iteration_N/point_cloud.ply)."""
    if scene.synthetic:
        p = catalog.dataset("source_synthetic", scene).ground_truth(CAMERA_FILE)
        return p if p.exists() else None
    src = Path(scene.path)
    for d in dict.fromkeys([src if src.is_dir() else src.parent, *list(src.parents)[:3]]):
        if (d / CAMERA_FILE).exists():
            return d / CAMERA_FILE
    return None
