"""Niantic .spz (versions 2 and 3): a gzip stream holding a 16-byte header, then per-attribute
arrays: positions (24-bit fixed point), alphas, colours, scales, rotations, SH.

Facts from the nianticlabs/spz reference implementation: colours are f_dc * 0.15 * 255 + 127.5;
scales (log) are (s + 10) * 16; alphas sigmoid * 255; v2 rotations store x, y, z as
(q + 1) * 127.5 with w >= 0 derived; v3 stores the smallest three components (2-bit index of
the largest, then 1 sign + 9 magnitude bits each, magnitude scaled by 1/sqrt2); SH bytes are
(x * 128 + 128), coefficient-major with the colour channel fastest. Data are read as stored
(no RUB -> RDF flip): the alignment stage finds the floor in any frame.
"""
from __future__ import annotations

import gzip
import struct
import zlib
from pathlib import Path

import numpy as np

from stages.gaussians.errors import SceneFormatError
from stages.gaussians.model import GaussianScene

MAGIC = 0x5053474E
COLOR_SCALE = 0.15
_SQRT1_2 = np.float32(0.7071067811865476)
_SH_DIM = {0: 0, 1: 3, 2: 8, 3: 15, 4: 24}


def read_spz(path: str | Path) -> GaussianScene:
    """Read a .spz file (v2 or v3)."""
    path = Path(path)
    try:
        raw = gzip.decompress(path.read_bytes())
    except (OSError, EOFError, zlib.error) as e:
        raise SceneFormatError(path, f".spz is not a valid gzip stream ({e})") from None
    if len(raw) < 16:
        raise SceneFormatError(path, f".spz payload is {len(raw)} bytes, shorter than its 16-byte header")
    magic, version, n, sh_deg, frac, flags, _ = struct.unpack("<IIIBBBB", raw[:16])
    if magic != MAGIC:
        raise SceneFormatError(path, f".spz magic is 0x{magic:08x}, expected 0x{MAGIC:08x} ('NGSP')")
    if version not in (2, 3):
        raise SceneFormatError(path, f".spz version {version} is not supported (2 or 3)")
    if sh_deg not in _SH_DIM:
        raise SceneFormatError(path, f".spz SH degree {sh_deg} is outside 0..4")
    shdim = _SH_DIM[sh_deg]
    rot_bytes = 4 if version >= 3 else 3
    sizes = [("positions", 9), ("alphas", 1), ("colors", 3), ("scales", 3), ("rotations", rot_bytes),
             ("sh", shdim * 3)]
    need = 16 + n * sum(s for _, s in sizes)
    if need > len(raw):
        per = sum(s for _, s in sizes)
        raise SceneFormatError(
            path, f".spz header declares {n:,} Gaussians ({need:,} bytes) but the payload holds {len(raw):,} "
                  f"bytes, room for {(len(raw) - 16) // per:,}")
    buf = np.frombuffer(raw, dtype=np.uint8)
    off = 16
    arrs = {}
    for name, s in sizes:
        arrs[name] = buf[off:off + n * s].reshape(n, s) if s else np.zeros((n, 0), np.uint8)
        off += n * s
    p = arrs["positions"].reshape(n, 3, 3).astype(np.int32)
    fixed = p[..., 0] | (p[..., 1] << 8) | (p[..., 2] << 16)
    fixed = np.where(fixed & 0x800000, fixed | ~0xFFFFFF, fixed)
    means = fixed.astype(np.float32) / float(1 << frac)
    alpha = np.clip(arrs["alphas"][:, 0].astype(np.float64) / 255.0, 1e-6, 1 - 1e-6)
    dc = (arrs["colors"].astype(np.float32) / 255.0 - 0.5) / COLOR_SCALE
    log_scales = arrs["scales"].astype(np.float32) / 16.0 - 10.0
    xyzw = np.zeros((n, 4), dtype=np.float32)
    r = arrs["rotations"]
    if version >= 3:
        comp = r[:, 0].astype(np.uint32) | (r[:, 1].astype(np.uint32) << 8) | (r[:, 2].astype(np.uint32) << 16) \
            | (r[:, 3].astype(np.uint32) << 24)
        largest = (comp >> 30).astype(np.int64)
        sumsq = np.zeros(n, dtype=np.float32)
        rest = comp.copy()
        for i in (3, 2, 1, 0):  # the last-packed component sits in the lowest bits
            active = largest != i
            mag = (rest & 511).astype(np.float32)
            neg = ((rest >> 9) & 1).astype(bool)
            val = _SQRT1_2 * mag / 511.0
            val = np.where(neg, -val, val)
            xyzw[active, i] = val[active]
            sumsq += np.where(active, val * val, 0)
            rest = np.where(active, rest >> 10, rest)
        xyzw[np.arange(n), largest] = np.sqrt(np.clip(1 - sumsq, 0, None))
    else:
        xyz = r.astype(np.float32) / 127.5 - 1.0
        xyzw[:, :3] = xyz
        xyzw[:, 3] = np.sqrt(np.clip(1 - (xyz ** 2).sum(1), 0, None))
    sh = np.zeros((n, shdim + 1, 3), dtype=np.float32)
    sh[:, 0] = dc
    if shdim:
        sh[:, 1:] = (arrs["sh"].reshape(n, shdim, 3).astype(np.float32) - 128.0) / 128.0
    quats = xyzw[:, [3, 0, 1, 2]]
    return GaussianScene(means, quats, log_scales, np.log(alpha / (1 - alpha)), sh)


def write_spz(path: str | Path, scene: GaussianScene, version: int = 3, fractional_bits: int = 12) -> None:
    """Write a .spz file (v2 or v3), quantizing as the reference implementation does."""
    n = len(scene)
    shdim = scene.sh.shape[1] - 1
    deg = {v: k for k, v in _SH_DIM.items()}.get(shdim)
    if deg is None:
        raise ValueError(f"cannot store {shdim + 1} SH coefficients in .spz")
    u8 = lambda x: np.clip(np.round(x), 0, 255).astype(np.uint8)
    fixed = np.round(scene.means.astype(np.float64) * (1 << fractional_bits)).astype(np.int64)
    pos = np.stack([(fixed >> s) & 0xFF for s in (0, 8, 16)], -1).astype(np.uint8).reshape(n, 9)
    alphas = u8(scene.alphas * 255.0)[:, None]
    colors = u8(scene.sh[:, 0] * (COLOR_SCALE * 255.0) + 127.5)
    scales = u8((scene.log_scales + 10.0) * 16.0)
    q = scene.quats.astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    xyzw = q[:, [1, 2, 3, 0]]
    if version >= 3:
        largest = np.argmax(np.abs(xyzw), axis=1)
        negate = xyzw[np.arange(n), largest] < 0
        comp = largest.astype(np.uint64)
        for i in range(4):
            active = largest != i
            negbit = ((xyzw[:, i] < 0) ^ negate).astype(np.uint64)
            mag = np.floor(511.0 * np.abs(xyzw[:, i]) / float(_SQRT1_2) + 0.5).astype(np.uint64)
            comp = np.where(active, (comp << np.uint64(10)) | (negbit << np.uint64(9)) | mag, comp)
        comp = comp.astype(np.uint32)
        rot = np.stack([(comp >> s) & 0xFF for s in (0, 8, 16, 24)], -1).astype(np.uint8)
    else:
        xyzw = np.where(xyzw[:, 3:] < 0, -xyzw, xyzw)
        rot = u8(xyzw[:, :3] * 127.5 + 127.5)
    sh = u8(scene.sh[:, 1:].reshape(n, -1) * 128.0 + 128.0) if shdim else np.zeros((n, 0), np.uint8)
    header = struct.pack("<IIIBBBB", MAGIC, version, n, deg, fractional_bits, 0, 0)
    payload = header + b"".join(a.tobytes() for a in (pos, alphas, colors, scales, rot, sh))
    Path(path).write_bytes(gzip.compress(payload, mtime=0))
