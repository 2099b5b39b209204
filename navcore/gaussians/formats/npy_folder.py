"""SceneSplat / InteriorGS ``.npy`` folders: coord.npy [N, 3] metres, color.npy [N, 3] (uint8 0-255,
or float in [0, 1]), opacity.npy [N] or [N, 1] (activated, 0-1), quat.npy [N, 4] (w, x, y, z),
scale.npy [N, 3] (activated, metres). SceneSplat's per-Gaussian labels, when shipped (instance.npy,
segment.npy [N] int), are carried along as extras "instance" and "segment"; other files in the
folder (lang_feat.npy, ...) are ignored."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from navcore.gaussians.errors import SceneFormatError
from navcore.gaussians.model import GaussianScene

REQUIRED = ("coord", "color", "opacity", "quat", "scale")
LABELS = ("instance", "segment")


def load_npy(path: Path) -> np.ndarray:
    """One .npy array, its header checked before anything is allocated: no object arrays, and
    the shape must fit in the bytes the file holds (a lying shape would otherwise make numpy
    allocate what it claims)."""
    fmt = np.lib.format
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            version = fmt.read_magic(f)
            width = 2 if version == (1, 0) else 4
            header_len = int.from_bytes(f.read(width), "little")
            if header_len > min(size, 1 << 16):  # numpy would allocate the length it reads first
                raise SceneFormatError(path, f".npy header claims {header_len:,} bytes (file: {size:,})")
            f.seek(-width, 1)
            read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
            shape, fortran, dtype = read_header(f)
            if dtype.hasobject:
                raise SceneFormatError(path, "is an object (pickled) .npy array; only numeric arrays are read")
            count = int(np.prod(shape, dtype=object))
            have = size - f.tell()
            if count * dtype.itemsize > have:
                raise SceneFormatError(path, f".npy header declares shape {shape} ({count * dtype.itemsize:,} bytes) but "
                                             f"the file holds {have:,} bytes of data (truncated or lying header)")
            arr = np.fromfile(f, dtype=dtype, count=count)
    except SceneFormatError:
        raise
    except Exception as e:  # noqa: BLE001 - numpy's header parser raises many types for corrupt headers
        raise SceneFormatError(path, f"unreadable .npy ({type(e).__name__}: {e})") from None
    return arr.reshape(shape, order="F" if fortran else "C")


def read_npy_folder(path: str | Path, level: int | None = None) -> GaussianScene:
    """Read a SceneSplat-style folder of .npy arrays."""
    path = Path(path)
    missing = [f"{k}.npy" for k in REQUIRED if not (path / f"{k}.npy").exists()]
    if missing:
        raise SceneFormatError(path, f".npy folder lacks {', '.join(missing)}")
    arrs = {k: load_npy(path / f"{k}.npy") for k in REQUIRED}
    n = len(arrs["coord"])
    want = {"coord": (n, 3), "color": (n, 3), "quat": (n, 4), "scale": (n, 3)}
    for k, shape in want.items():
        if arrs[k].shape != shape:
            raise SceneFormatError(path / f"{k}.npy", f"shape {arrs[k].shape}, expected {shape} (N from coord.npy)")
    op = arrs["opacity"].reshape(-1)
    if op.shape != (n,):
        raise SceneFormatError(path / "opacity.npy", f"holds {op.size} values, expected {n}")
    color = arrs["color"].astype(np.float64)
    if arrs["color"].dtype == np.uint8 or color.max(initial=0) > 1.0 + 1e-6:
        color = color / 255.0
    extras = {}
    for k in LABELS:
        if (path / f"{k}.npy").exists():
            a = load_npy(path / f"{k}.npy").reshape(-1)
            if a.shape != (n,) or not np.issubdtype(a.dtype, np.integer):
                raise SceneFormatError(path / f"{k}.npy", f"holds {a.size} {a.dtype} values, expected {n} integers")
            extras[k] = a.astype(np.int32)
    with np.errstate(divide="ignore", invalid="ignore"):
        return GaussianScene.from_colors(arrs["coord"], arrs["quat"], arrs["scale"], op, color, extras)


def write_npy_folder(path: str | Path, scene: GaussianScene) -> None:
    """Write a SceneSplat-style folder (colour as uint8)."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    np.save(path / "coord.npy", scene.means)
    np.save(path / "color.npy", np.round(scene.colors * 255).astype(np.uint8))
    np.save(path / "opacity.npy", scene.alphas.astype(np.float32)[:, None])
    np.save(path / "quat.npy", scene.quats)
    np.save(path / "scale.npy", scene.scales.astype(np.float32))
    for k in LABELS:
        if k in scene.extras:
            np.save(path / f"{k}.npy", scene.extras[k].astype(np.int32))
