"""Niantic .spz, every version: v2 / v3 (a gzip stream holding a 16-byte header and the attribute
arrays) and v4 (a 32-byte plaintext header "NGSP", optional extension records, a table of
contents and one ZSTD stream per attribute).

Facts from the nianticlabs/spz reference implementation: attributes in the order positions
(24-bit fixed point, ``fractional_bits``), alphas (sigmoid * 255), colours (f_dc * 0.15 * 255 +
127.5), scales (log, (s + 10) * 16), rotations, SH ((x * 128 + 128), coefficient-major with the
colour channel fastest). v2 rotations store x, y, z as (q + 1) * 127.5 with w >= 0 derived; v3 and
v4 store the smallest three components (2-bit index of the largest, then 1 sign + 9 magnitude bits
each, magnitude scaled by 1/sqrt2). v4 header: magic, version, numPoints (u32), shDegree,
fractionalBits, flags, numStreams (u8), tocByteOffset (u32), 12 reserved bytes; the TOC holds
(compressed, uncompressed) u64 sizes per stream; empty attributes (SH of degree 0) have no stream.
Data are read as stored (no RUB -> RDF flip): the alignment stage finds the floor in any frame.
"""
from __future__ import annotations

import gzip
import struct
import zlib
from pathlib import Path

import numpy as np

from navcore.gaussians.errors import SceneFormatError
from navcore.gaussians.formats.limits import check_inflation
from navcore.gaussians.model import GaussianScene

MAGIC = 0x5053474E
COLOR_SCALE = 0.15
_SQRT1_2 = np.float32(0.7071067811865476)
_SH_DIM = {0: 0, 1: 3, 2: 8, 3: 15, 4: 24}
_V4_HEADER = struct.Struct("<IIIBBBBI12s")  # 32 bytes
_LEGACY_HEADER = struct.Struct("<IIIBBBB")  # 16 bytes
VERSIONS = (2, 3, 4)


def _attribute_sizes(version: int, shdim: int) -> list[tuple[str, int]]:
    """(name, bytes per Gaussian) in stream order."""
    return [("positions", 9), ("alphas", 1), ("colors", 3), ("scales", 3), ("rotations", 4 if version >= 3 else 3),
            ("sh", shdim * 3)]


def _check_header(path, magic, version, sh_deg) -> int:
    if magic != MAGIC:
        raise SceneFormatError(path, f".spz magic is 0x{magic:08x}, expected 0x{MAGIC:08x} ('NGSP')")
    if version not in VERSIONS:
        raise SceneFormatError(path, f".spz version {version} is not supported ({', '.join(map(str, VERSIONS))})")
    if sh_deg not in _SH_DIM:
        raise SceneFormatError(path, f".spz SH degree {sh_deg} is outside 0..4")
    return _SH_DIM[sh_deg]


def _inflate(path: Path, data: bytes) -> bytes:
    """The gzip payload, decompressed no further than its header's count allows (a stream that
    inflates past that, or declares more than MAX_INFLATION x the file, is refused)."""
    d = zlib.decompressobj(16 + zlib.MAX_WBITS)
    try:
        head = d.decompress(data, _LEGACY_HEADER.size)
        if len(head) < _LEGACY_HEADER.size:
            return head + d.flush()
        magic, version, n, sh_deg, _frac, _flags, _ = _LEGACY_HEADER.unpack_from(head)
        shdim = _check_header(path, magic, version, sh_deg)
        need = _LEGACY_HEADER.size + n * sum(s for _, s in _attribute_sizes(version, shdim))
        check_inflation(path, need, len(data), ".spz gzip stream")
        body = d.decompress(d.unconsumed_tail, need - len(head) + 1)
    except (OSError, EOFError, zlib.error) as e:
        raise SceneFormatError(path, f".spz (v2/v3) is not a valid gzip stream ({e})") from None
    if len(head) + len(body) > need:
        raise SceneFormatError(path, f".spz gzip stream inflates past the {need:,} bytes its header declares "
                                     f"({n:,} Gaussians)")
    return head + body


def _read_legacy(path: Path, data: bytes) -> tuple[int, int, int, int, dict]:
    raw = _inflate(path, data)
    if len(raw) < _LEGACY_HEADER.size:
        raise SceneFormatError(path, f".spz payload is {len(raw)} bytes, shorter than its 16-byte header")
    magic, version, n, sh_deg, frac, _flags, _ = _LEGACY_HEADER.unpack_from(raw)
    shdim = _check_header(path, magic, version, sh_deg)
    if version == 4:
        raise SceneFormatError(path, ".spz declares version 4 inside a gzip stream (v4 files are not gzipped)")
    sizes = _attribute_sizes(version, shdim)
    per = sum(s for _, s in sizes)
    need = _LEGACY_HEADER.size + n * per
    if need > len(raw):
        raise SceneFormatError(
            path, f".spz header declares {n:,} Gaussians ({need:,} bytes) but the payload holds {len(raw):,} "
                  f"bytes, room for {(len(raw) - 16) // per:,}")
    buf = np.frombuffer(raw, dtype=np.uint8)
    off = _LEGACY_HEADER.size
    arrs = {}
    for name, s in sizes:
        arrs[name] = buf[off:off + n * s].reshape(n, s)
        off += n * s
    return version, n, shdim, frac, arrs


def _read_v4(path: Path, data: bytes) -> tuple[int, int, int, int, dict]:
    import zstandard

    if len(data) < _V4_HEADER.size:
        raise SceneFormatError(path, f".spz v4 file is {len(data)} bytes, shorter than its 32-byte header")
    magic, version, n, sh_deg, frac, _flags, n_streams, toc, _ = _V4_HEADER.unpack_from(data)
    shdim = _check_header(path, magic, version, sh_deg)
    if version != 4:
        raise SceneFormatError(path, f".spz starts with a plaintext 'NGSP' header (v4 layout) but declares "
                                     f"version {version}")
    sizes = [(k, s) for k, s in _attribute_sizes(version, shdim) if s]
    if n_streams != len(sizes):
        raise SceneFormatError(path, f".spz v4 header declares {n_streams} streams; SH degree {sh_deg} needs "
                                     f"{len(sizes)} ({', '.join(k for k, _ in sizes)})")
    toc_end = toc + 16 * n_streams
    if toc < _V4_HEADER.size or toc_end > len(data):
        raise SceneFormatError(path, f".spz v4 table of contents at byte {toc:,} (+{16 * n_streams}) lies outside "
                                     f"the file ({len(data):,} bytes)")
    entries = np.frombuffer(data, dtype="<u8", count=2 * n_streams, offset=toc).reshape(n_streams, 2)
    off = toc_end
    arrs = {}
    dctx = zstandard.ZstdDecompressor()
    for (name, s), (csize, usize) in zip(sizes, entries.tolist()):
        if usize != n * s:
            raise SceneFormatError(path, f".spz v4 stream '{name}' holds {usize:,} bytes; {n:,} Gaussians need "
                                         f"{n * s:,}")
        check_inflation(path, usize, csize, f".spz v4 stream '{name}'")
        if off + csize > len(data):
            raise SceneFormatError(path, f".spz v4 stream '{name}' ({csize:,} bytes at {off:,}) runs past the end "
                                         f"of the file ({len(data):,} bytes): truncated?")
        try:
            # a frame header that states its size makes zstd allocate that size first: check it
            declared = zstandard.frame_content_size(data[off:off + csize])
            if declared not in (-1, usize):
                raise SceneFormatError(path, f".spz v4 stream '{name}' frame declares {declared:,} bytes, the table of "
                                             f"contents {usize:,}")
            raw = dctx.decompress(data[off:off + csize], max_output_size=usize)
        except zstandard.ZstdError as e:
            raise SceneFormatError(path, f".spz v4 stream '{name}' is not valid ZSTD ({e})") from None
        if len(raw) != usize:
            raise SceneFormatError(path, f".spz v4 stream '{name}' decompressed to {len(raw):,} bytes, "
                                         f"expected {usize:,}")
        arrs[name] = np.frombuffer(raw, dtype=np.uint8).reshape(n, s)
        off += csize
    if off != len(data):
        raise SceneFormatError(path, f".spz v4 streams end at byte {off:,} but the file has {len(data):,} bytes")
    arrs.setdefault("sh", np.zeros((n, 0), np.uint8))
    return version, n, shdim, frac, arrs


def read_spz(path: str | Path, level: int | None = None) -> GaussianScene:
    """Read a .spz file of any version (the first bytes tell the layout: gzip or plaintext NGSP)."""
    path = Path(path)
    data = path.read_bytes()
    if data[:4] == struct.pack("<I", MAGIC):
        version, n, shdim, frac, arrs = _read_v4(path, data)
    elif data[:2] == b"\x1f\x8b":
        version, n, shdim, frac, arrs = _read_legacy(path, data)
    else:
        raise SceneFormatError(path, f".spz starts with bytes {data[:4].hex()}: neither a gzip stream (v2/v3) nor "
                                     f"a plaintext 'NGSP' header (v4)")
    return _decode(arrs, version, n, shdim, frac)


def _decode(arrs: dict, version: int, n: int, shdim: int, frac: int) -> GaussianScene:
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


def _encode(scene: GaussianScene, version: int, fractional_bits: int) -> list[np.ndarray]:
    """The attribute arrays [N, bytes] in stream order."""
    n = len(scene)
    shdim = scene.sh.shape[1] - 1
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
    return [pos, alphas, colors, scales, rot, sh]


def write_spz(path: str | Path, scene: GaussianScene, version: int = 4, fractional_bits: int = 12) -> None:
    """Write a .spz file (v2, v3 or v4), quantizing as the reference implementation does."""
    if version not in VERSIONS:
        raise ValueError(f"cannot write .spz version {version} (known: {VERSIONS})")
    shdim = scene.sh.shape[1] - 1
    deg = {v: k for k, v in _SH_DIM.items()}.get(shdim)
    if deg is None:
        raise ValueError(f"cannot store {shdim + 1} SH coefficients in .spz")
    arrays = _encode(scene, version, fractional_bits)
    if version < 4:
        header = _LEGACY_HEADER.pack(MAGIC, version, len(scene), deg, fractional_bits, 0, 0)
        payload = header + b"".join(a.tobytes() for a in arrays)
        Path(path).write_bytes(gzip.compress(payload, mtime=0))
        return
    import zstandard

    cctx = zstandard.ZstdCompressor(level=12)
    streams = [(a.nbytes, cctx.compress(a.tobytes())) for a in arrays if a.size]
    header = _V4_HEADER.pack(MAGIC, 4, len(scene), deg, fractional_bits, 0, len(streams), _V4_HEADER.size, bytes(12))
    toc = np.array([(len(c), u) for u, c in streams], dtype="<u8").tobytes()
    Path(path).write_bytes(header + toc + b"".join(c for _, c in streams))
