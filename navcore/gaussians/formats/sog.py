"""PlayCanvas SOG version 2: a set of lossless WebP "property images" and a ``meta.json``, either
in a folder, in a zip archive (``.sog``), or as a streamed level-of-detail scene (``lod-meta.json``
listing the ``meta.json`` of many SOG units and a tree saying which unit belongs to which level).

Decoding, per Gaussian i = pixel i of every image (row-major):
- means: 16-bit (means_u high byte, means_l low byte) per axis, lerped between meta ``mins`` and
  ``maxs`` of the log-transformed coordinates, then x = sign(v) (exp|v| - 1).
- quats (RGBA): smallest three components a, b, c = (byte / 255 * 2 - 1) / sqrt2, the alpha byte
  is 252 + index of the largest component in (w, x, y, z), which is positive and derived.
- scales: three indices into the 256-entry ``codebook`` of log-scales.
- sh0: three indices into the 256-entry ``codebook`` of DC coefficients; alpha = opacity * 255.
- shN (optional): labels (16-bit in R, G) index a palette (``shN_centroids``, 64 entries per row,
  one texel per coefficient, RGB = codebook indices of the three channels).
Values are in the source frame (PLY convention), as the other readers.
Levels of a streamed scene: level 0 is the finest; a level's Gaussians are the concatenation of
its units in file-index order.
"""
from __future__ import annotations

import io
import json
import zipfile
import zlib
from pathlib import Path
from typing import Callable

import numpy as np

from navcore.gaussians.errors import SceneFormatError
from navcore.gaussians.formats.limits import check_inflation
from navcore.gaussians.model import GaussianScene
from navcore.paths import PathEscapeError, contained

_SQRT2 = np.sqrt(2.0)
_SH_COEFFS = {0: 0, 1: 3, 2: 8, 3: 15}
# position of the three stored components in (w, x, y, z) for each largest-component index
_QUAT_IDX = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
LOD_META = "lod-meta.json"
META = "meta.json"


def _decode_webp(data: bytes, where: str) -> np.ndarray:
    """[H * W, 4] uint8 RGBA pixels of a lossless WebP image."""
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as im:
            if im.format != "WEBP":
                raise SceneFormatError(where, f"is a {im.format} image, SOG property images are WebP")
            check_inflation(where, 4 * im.size[0] * im.size[1], len(data), f"WebP image of {im.size[0]}x{im.size[1]}")
            return np.asarray(im.convert("RGBA")).reshape(-1, 4)
    except SceneFormatError:
        raise
    except Exception as e:  # PIL raises many types for corrupt data
        raise SceneFormatError(where, f"unreadable WebP image ({e})") from None


def _meta_field(meta: dict, where: str, key: str, sub: str):
    try:
        return meta[key][sub]
    except (KeyError, TypeError):
        raise SceneFormatError(where, f"SOG meta.json lacks '{key}.{sub}'") from None


def decode_sog(meta: dict, load: Callable[[str], bytes], where: str) -> GaussianScene:
    """One SOG unit from its parsed meta.json and a loader of its image files (by name)."""
    version = meta.get("version")
    if version != 2:
        raise SceneFormatError(where, f"SOG meta.json version {version!r} is not supported (2)")
    n = meta.get("count")
    if not isinstance(n, int) or n < 0:
        raise SceneFormatError(where, f"SOG meta.json 'count' is {n!r}, expected a non-negative integer")

    def image(key: str, k: int = 0) -> np.ndarray:
        files = _meta_field(meta, where, key, "files")
        if len(files) <= k:
            raise SceneFormatError(where, f"SOG meta.json '{key}.files' lists {len(files)} files, need {k + 1}")
        px = _decode_webp(load(files[k]), f"{where}: {files[k]}")
        if len(px) < n:
            raise SceneFormatError(where, f"SOG image {files[k]} has {len(px):,} pixels for {n:,} Gaussians")
        return px[:n]

    def codebook(key: str) -> np.ndarray:
        cb = np.asarray(_meta_field(meta, where, key, "codebook"), dtype=np.float32)
        if cb.shape != (256,):
            raise SceneFormatError(where, f"SOG '{key}.codebook' has {cb.size} entries, expected 256")
        return cb

    lo, hi = image("means", 0).astype(np.uint32), image("means", 1).astype(np.uint32)
    mins = np.asarray(_meta_field(meta, where, "means", "mins"), np.float64)
    maxs = np.asarray(_meta_field(meta, where, "means", "maxs"), np.float64)
    if mins.shape != (3,) or maxs.shape != (3,):
        raise SceneFormatError(where, "SOG 'means.mins' / 'means.maxs' must hold 3 numbers each")
    v = (lo[:, :3] | (hi[:, :3] << 8)).astype(np.float64) / 65535.0
    span = np.where(maxs - mins != 0, maxs - mins, 1.0)
    t = mins + span * v
    means = np.sign(t) * np.expm1(np.abs(t))

    q = image("quats").astype(np.float64)
    tag = q[:, 3].astype(np.int64)
    bad = (tag < 252) | (tag > 255)
    largest = np.clip(tag - 252, 0, 3)
    abc = (q[:, :3] / 255.0 * 2.0 - 1.0) / _SQRT2
    quats = np.zeros((n, 4))
    np.put_along_axis(quats, _QUAT_IDX[largest], abc, axis=1)
    quats[np.arange(n), largest] = np.sqrt(np.clip(1.0 - (abc ** 2).sum(1), 0.0, None))
    quats[bad] = (1.0, 0.0, 0.0, 0.0)  # as the reference reader: identity for an invalid tag

    log_scales = codebook("scales")[image("scales")[:, :3]]
    sh0 = image("sh0")
    dc = codebook("sh0")[sh0[:, :3]]
    alpha = np.clip(sh0[:, 3].astype(np.float64) / 255.0, 1e-6, 1 - 1e-6)

    shn = meta.get("shN")
    bands = int(shn.get("bands", 0)) if shn else 0
    k = _SH_COEFFS.get(bands)
    if k is None:
        raise SceneFormatError(where, f"SOG 'shN.bands' is {bands}, expected 0..3")
    sh = np.zeros((n, k + 1, 3), np.float32)
    sh[:, 0] = dc
    if k:
        cb = codebook("shN")
        files = _meta_field(meta, where, "shN", "files")
        cen = _decode_webp(load(files[0]), f"{where}: {files[0]}")  # [rows * 64 * k, 4]
        labels = image("shN", 1)
        lab = labels[:, 0].astype(np.int64) | (labels[:, 1].astype(np.int64) << 8)
        palette_n = int(shn.get("count", 0))
        if len(cen) < palette_n * k:
            raise SceneFormatError(where, f"SOG shN_centroids holds {len(cen) // k:,} entries, meta says {palette_n:,}")
        palette = cb[cen[:palette_n * k, :3].reshape(palette_n, k, 3)]  # [P, k, 3]
        ok = lab < palette_n
        sh[ok, 1:] = palette[lab[ok]]
    return GaussianScene(means, quats, log_scales, np.log(alpha / (1 - alpha)), sh)


def _read_json(data: bytes, where: str) -> dict:
    try:
        meta = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise SceneFormatError(where, f"not valid JSON ({e})") from None
    if not isinstance(meta, dict):
        raise SceneFormatError(where, "JSON document is not an object")
    return meta


def _inside(folder: Path, name, where) -> Path:
    """folder / name of a file a SOG meta names; a name leading out of the folder is a format error."""
    try:
        return contained(folder, name, str(where))
    except PathEscapeError as e:
        raise SceneFormatError(where, str(e).split(": ", 1)[1]) from None


def _read_folder_unit(meta_path: Path) -> GaussianScene:
    folder = meta_path.parent

    def load(name: str) -> bytes:
        p = _inside(folder, name, meta_path)
        if not p.is_file():
            raise SceneFormatError(meta_path, f"SOG image {name} is missing (expected at {p})")
        return p.read_bytes()

    return decode_sog(_read_json(meta_path.read_bytes(), str(meta_path)), load, str(meta_path))


def _read_zip(path: Path) -> GaussianScene:
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as e:
        raise SceneFormatError(path, f".sog is not a valid zip archive ({e})") from None
    with zf:
        names = set(zf.namelist())
        if META not in names:
            raise SceneFormatError(path, f".sog archive holds no {META} (entries: {', '.join(sorted(names)[:8])})")

        def load(name: str) -> bytes:
            if name not in names:
                raise SceneFormatError(path, f".sog archive lacks {name}")
            info = zf.getinfo(name)
            check_inflation(path, info.file_size, info.compress_size, f".sog member {name}")
            try:
                return zf.read(name)
            except (zipfile.BadZipFile, zlib.error, OSError, EOFError, NotImplementedError) as e:
                raise SceneFormatError(path, f".sog member {name} is unreadable ({e})") from None

        return decode_sog(_read_json(load(META), f"{path}: {META}"), load, str(path))


def lod_levels(lod_meta_path: Path) -> tuple[dict, dict[int, list[int]]]:
    """Parsed lod-meta.json and, per level, the file indices of its units (sorted)."""
    meta = _read_json(lod_meta_path.read_bytes(), str(lod_meta_path))
    filenames = meta.get("filenames")
    n_levels = meta.get("lodLevels")
    if not isinstance(filenames, list) or not isinstance(n_levels, int) or n_levels <= 0 \
            or not isinstance(meta.get("tree"), dict):
        raise SceneFormatError(lod_meta_path, "lod-meta.json needs 'lodLevels' (> 0), 'filenames' and 'tree'")
    levels: dict[int, set[int]] = {}
    stack = [meta["tree"]]
    while stack:
        node = stack.pop()
        if not isinstance(node, dict):
            raise SceneFormatError(lod_meta_path, "lod-meta.json tree holds a node that is not an object")
        for key, ref in (node.get("lods") or {}).items():
            try:
                level, f = int(key), int(ref["file"])
            except (ValueError, TypeError, KeyError):
                raise SceneFormatError(lod_meta_path, f"lod-meta.json has an invalid level reference {key}: {ref}") from None
            if not 0 <= level < n_levels or not 0 <= f < len(filenames):
                raise SceneFormatError(lod_meta_path, f"lod-meta.json level reference {key}: {ref} is out of range")
            levels.setdefault(level, set()).add(f)
        stack.extend(node.get("children") or [])
    return meta, {k: sorted(v) for k, v in sorted(levels.items())}


def _read_lod(path: Path, level: int | None) -> GaussianScene:
    meta, levels = lod_levels(path)
    folder = path.parent
    files = {f: _inside(folder, meta["filenames"][f], path) for fs in levels.values() for f in fs}
    missing = {lv: [meta["filenames"][f] for f in fs if not files[f].is_file()] for lv, fs in levels.items()}
    if level is None:
        complete = [lv for lv in levels if not missing[lv]]
        if not complete:
            first = ", ".join(f"level {lv}: {', '.join(m[:3])}{' ...' if len(m) > 3 else ''}" for lv, m in missing.items())
            raise SceneFormatError(path, f"no level of this streamed SOG has all its files ({first})")
        level = complete[0]  # level 0 is the finest
    elif level not in levels:
        raise SceneFormatError(path, f"streamed SOG has no level {level} (levels: {sorted(levels)})")
    elif missing[level]:
        m = missing[level]
        have = [lv for lv in levels if not missing[lv]]
        raise SceneFormatError(path, f"level {level} lacks {len(m)} of its {len(levels[level])} files "
                                     f"({', '.join(m[:5])}{' ...' if len(m) > 5 else ''}); complete levels: {have}")
    parts = [_read_folder_unit(files[f]) for f in levels[level]]
    return concat_scenes(parts)


def concat_scenes(parts: list[GaussianScene]) -> GaussianScene:
    """One scene holding the Gaussians of all parts in order (SH padded to the highest degree)."""
    k = max(p.sh.shape[1] for p in parts)
    sh = [np.pad(p.sh, ((0, 0), (0, k - p.sh.shape[1]), (0, 0))) for p in parts]
    cat = lambda f: np.concatenate([getattr(p, f) for p in parts])
    return GaussianScene(cat("means"), cat("quats"), cat("log_scales"), cat("opacity_logits"), np.concatenate(sh))


def sog_entry(path: Path) -> Path:
    """The file a SOG path points at: a .sog archive, a meta.json or a lod-meta.json (a folder
    holding either is accepted)."""
    if path.is_dir():
        for name in (LOD_META, META):
            if (path / name).is_file():
                return path / name
        raise SceneFormatError(path, f"folder holds neither {LOD_META} nor {META}: not a SOG scene")
    return path


def read_sog(path: str | Path, level: int | None = None) -> GaussianScene:
    """Read a SOG scene: ``.sog`` zip, a SOG folder / meta.json, or a streamed ``lod-meta.json``.

    Args:
        level: level of a streamed scene (0 = finest); None = the finest whose files are all present.
    """
    path = sog_entry(Path(path))
    if path.name == LOD_META:
        return _read_lod(path, level)
    if path.suffix.lower() == ".sog":
        return _read_zip(path)
    return _read_folder_unit(path)


# ---------------------------------------------------------------------------------------------- writer

def _texture_shape(n: int) -> tuple[int, int]:
    w = max(4, int(np.ceil(np.sqrt(n) / 4) * 4))
    h = max(4, int(np.ceil(n / w / 4) * 4))
    return w, h


def _encode_webp(px: np.ndarray, w: int, h: int) -> bytes:
    """Lossless WebP of [n, 4] uint8 pixels laid out row-major on a w x h image."""
    from PIL import Image

    img = np.zeros((w * h, 4), np.uint8)
    img[:len(px)] = px
    buf = io.BytesIO()
    # exact: keep RGB under transparent pixels (the quats' alpha is data, not coverage)
    Image.fromarray(img.reshape(h, w, 4), "RGBA").save(buf, "WEBP", lossless=True, quality=100, method=0, exact=True)
    return buf.getvalue()


def _codebook(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """256-entry codebook (quantiles of the values) and each value's nearest entry index."""
    v = values.reshape(-1).astype(np.float64)
    cb = np.unique(np.quantile(v, np.linspace(0, 1, 256)).astype(np.float32)).astype(np.float64)
    cb = np.concatenate([cb, np.full(256 - len(cb), cb[-1])])
    mid = (cb[1:] + cb[:-1]) / 2
    idx = np.searchsorted(mid, v).astype(np.uint8)
    return cb.astype(np.float32), idx.reshape(values.shape)


def encode_sog(scene: GaussianScene) -> tuple[dict, dict[str, bytes]]:
    """meta.json dict and the image files of one SOG unit."""
    n = len(scene)
    w, h = _texture_shape(n)
    files: dict[str, bytes] = {}
    px = lambda cols: np.concatenate([cols, np.full((n, 4 - cols.shape[1]), 255, np.uint8)], 1)
    t = np.sign(scene.means.astype(np.float64)) * np.log1p(np.abs(scene.means.astype(np.float64)))
    mins, maxs = t.min(0) if n else np.zeros(3), t.max(0) if n else np.zeros(3)
    span = np.where(maxs - mins > 0, maxs - mins, 1.0)
    q16 = np.round((t - mins) / span * 65535.0).astype(np.uint32)
    files["means_l.webp"] = _encode_webp(px((q16 & 0xFF).astype(np.uint8)), w, h)
    files["means_u.webp"] = _encode_webp(px((q16 >> 8).astype(np.uint8)), w, h)

    q = scene.quats.astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    largest = np.argmax(np.abs(q), axis=1)
    q = np.where(q[np.arange(n), largest][:, None] < 0, -q, q)
    abc = np.take_along_axis(q, _QUAT_IDX[largest], axis=1)
    qb = np.round((abc * _SQRT2 + 1.0) / 2.0 * 255.0).clip(0, 255).astype(np.uint8)
    files["quats.webp"] = _encode_webp(np.concatenate([qb, (252 + largest)[:, None].astype(np.uint8)], 1), w, h)

    s_cb, s_idx = _codebook(scene.log_scales)
    files["scales.webp"] = _encode_webp(px(s_idx), w, h)
    c_cb, c_idx = _codebook(scene.sh[:, 0])
    op = np.round(scene.alphas * 255.0).clip(0, 255).astype(np.uint8)
    files["sh0.webp"] = _encode_webp(np.concatenate([c_idx, op[:, None]], 1), w, h)
    meta = {"version": 2, "asset": {"generator": "navarena"}, "count": n,
            "means": {"mins": mins.tolist(), "maxs": maxs.tolist(), "files": ["means_l.webp", "means_u.webp"]},
            "scales": {"codebook": s_cb.tolist(), "files": ["scales.webp"]},
            "quats": {"files": ["quats.webp"]},
            "sh0": {"codebook": c_cb.tolist(), "files": ["sh0.webp"]}}
    k = scene.sh.shape[1] - 1
    if k:
        bands = {v: b for b, v in _SH_COEFFS.items()}.get(k)
        if bands is None:
            raise ValueError(f"SOG stores SH bands 1-3, not {k} rest coefficients")
        r_cb, r_idx = _codebook(scene.sh[:, 1:])  # [n, k, 3] codebook indices
        palette, labels = np.unique(r_idx.reshape(n, -1), axis=0, return_inverse=True)
        if len(palette) > 65536:
            raise ValueError(f"{len(palette):,} distinct SH rows exceed the 65,536-entry SOG palette")
        labels = labels.reshape(-1).astype(np.uint32)
        rows = int(np.ceil(len(palette) / 64))
        cen = np.zeros((rows * 64, k, 3), np.uint8)
        cen[:len(palette)] = palette.reshape(-1, k, 3)
        cen_px = np.concatenate([cen.reshape(-1, 3), np.full((rows * 64 * k, 1), 255, np.uint8)], 1)
        files["shN_centroids.webp"] = _encode_webp(cen_px, 64 * k, rows)
        lab = np.stack([labels & 0xFF, labels >> 8], 1).astype(np.uint8)
        files["shN_labels.webp"] = _encode_webp(px(lab), w, h)
        meta["shN"] = {"count": int(len(palette)), "bands": bands, "codebook": r_cb.tolist(),
                       "files": ["shN_centroids.webp", "shN_labels.webp"]}
    return meta, files


def write_sog(path: str | Path, scene: GaussianScene) -> None:
    """Write a SOG v2 unit: a ``.sog`` zip when the path ends so, otherwise a folder with meta.json.
    Codebooks are quantiles of the values (the reference writer uses k-means; readers do not care)."""
    path = Path(path)
    meta, files = encode_sog(scene)
    files = {META: json.dumps(meta).encode(), **files}
    if path.suffix.lower() == ".sog":
        with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:
            for name, data in files.items():
                zf.writestr(zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0)), data)
        return
    path.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        (path / name).write_bytes(data)


def write_sog_lod(folder: str | Path, levels: list[list[GaussianScene]]) -> Path:
    """Write a streamed SOG: ``levels[L]`` lists the units of level L (0 = finest), each written to
    ``{L}_{k}/``; the tree has one leaf per unit. Returns the lod-meta.json path."""
    folder = Path(folder)
    filenames, leaves = [], []
    for lv, units in enumerate(levels):
        for k, unit in enumerate(units):
            name = f"{lv}_{k}/{META}"
            write_sog(folder / f"{lv}_{k}", unit)
            leaves.append({"lods": {str(lv): {"file": len(filenames), "offset": 0, "count": len(unit)}}})
            filenames.append(name)
    meta = {"lodLevels": len(levels), "environment": None, "filenames": filenames, "tree": {"children": leaves}}
    (folder / LOD_META).write_text(json.dumps(meta))
    return folder / LOD_META
