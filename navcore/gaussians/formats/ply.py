"""PLY: INRIA 3DGS layout (SH degree 0-3) and the SuperSplat compressed layout.

The header is parsed here (not by a generic PLY library) so that a header that lies about
its vertex count is caught before any data is read, with a message that says by how much.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from navcore.gaussians.errors import SceneFormatError
from navcore.gaussians.model import SH_C0, GaussianScene

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_MAX_HEADER_BYTES = 1 << 20
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_REST = re.compile(r"f_rest_[0-9]{1,3}")


@dataclass
class PlyElement:
    name: str
    count: int
    properties: list[tuple[str, str]]  # (name, numpy type code)

    def dtype(self, endian: str) -> np.dtype:
        return np.dtype([(n, endian + t) for n, t in self.properties])


def parse_header(path: Path) -> tuple[str, list[PlyElement], int]:
    """Return (format, elements, header length in bytes) of a PLY file."""
    with open(path, "rb") as f:
        head = f.read(_MAX_HEADER_BYTES)
    if not head.startswith(b"ply"):
        raise SceneFormatError(path, "not a PLY file (missing 'ply' magic)")
    end = head.find(b"end_header")
    if end < 0:
        raise SceneFormatError(path, "PLY header has no 'end_header' line (truncated or not a PLY)")
    nl = head.find(b"\n", end)
    header_len = nl + 1 if nl >= 0 else len(head)
    fmt = None
    elements: list[PlyElement] = []
    for raw in head[:end].decode("ascii", errors="replace").splitlines():
        tok = raw.strip().split()
        if not tok or tok[0] in ("ply", "comment", "obj_info"):
            continue
        if tok[0] == "format":
            fmt = tok[1] if len(tok) > 1 else None
        elif tok[0] == "element":
            try:
                if len(tok) != 3 or not _NAME.fullmatch(tok[1]) or not tok[2].isdigit():
                    raise ValueError
                count = int(tok[2])
            except (IndexError, ValueError):
                raise SceneFormatError(path, f"bad PLY element line {raw!r}") from None
            if count < 0:
                raise SceneFormatError(path, f"PLY header declares a negative count in {raw!r}")
            elements.append(PlyElement(tok[1], count, []))
        elif tok[0] == "property":
            if not elements:
                raise SceneFormatError(path, f"PLY property before any element: {raw!r}")
            if len(tok) > 1 and tok[1] == "list":
                raise SceneFormatError(path, f"PLY list property {tok[-1]!r} is not a 3DGS attribute (mesh PLY?)")
            if len(tok) != 3 or not _NAME.fullmatch(tok[2]):
                raise SceneFormatError(path, f"bad PLY property line {raw!r}")
            if tok[1] not in _PLY_TYPES:
                raise SceneFormatError(path, f"unknown PLY property type {tok[1]!r}")
            if any(n == tok[2] for n, _ in elements[-1].properties):
                raise SceneFormatError(path, f"PLY element {elements[-1].name!r} declares property {tok[2]!r} twice")
            elements[-1].properties.append((tok[2], _PLY_TYPES[tok[1]]))
        else:
            raise SceneFormatError(path, f"unknown PLY header line {raw!r}")
    if fmt not in ("binary_little_endian", "binary_big_endian", "ascii"):
        raise SceneFormatError(path, f"unsupported PLY format {fmt!r}")
    return fmt, elements, header_len


INRIA_REQUIRED = ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
                  "rot_0", "rot_1", "rot_2", "rot_3")


def is_inria_ply(path: str | Path) -> bool:
    """Whether a file is a 3DGS PLY in the INRIA layout, binary little endian (one vertex element
    holding at least the INRIA properties): what the V1 asset's source.ply must be."""
    try:
        fmt, elements, _ = parse_header(Path(path))
    except (OSError, SceneFormatError):
        return False
    return (fmt == "binary_little_endian" and [e.name for e in elements] == ["vertex"]
            and set(INRIA_REQUIRED) <= {name for name, _ in elements[0].properties})


def read_elements(path: Path) -> dict[str, np.ndarray]:
    fmt, elements, header_len = parse_header(path)
    size = os.path.getsize(path)
    out: dict[str, np.ndarray] = {}
    if fmt == "ascii":
        with open(path, "rb") as f:
            f.seek(header_len)
            lines = f.read().decode("ascii", errors="replace").split("\n")
        pos = 0
        for el in elements:
            rows = [ln for ln in lines[pos:pos + el.count] if ln.strip()]
            if len(rows) < el.count:
                raise SceneFormatError(
                    path, f"PLY header declares {el.count:,} {el.name} rows but the file holds {len(rows):,}")
            data = np.loadtxt(rows, dtype=np.float64, ndmin=2)
            arr = np.zeros(el.count, dtype=el.dtype("<"))
            for j, (n, _) in enumerate(el.properties):
                arr[n] = data[:, j]
            out[el.name] = arr
            pos += el.count
        return out
    endian = "<" if fmt == "binary_little_endian" else ">"
    offset = header_len
    for el in elements:
        dt = el.dtype(endian)
        need = el.count * dt.itemsize
        have = size - offset
        if need > have:
            raise SceneFormatError(
                path,
                f"PLY header declares {el.count:,} {el.name} rows ({need:,} bytes) but the file holds "
                f"{max(have, 0):,} bytes after the header, room for {max(have, 0) // max(dt.itemsize, 1):,} "
                f"(truncated file or lying header)")
        out[el.name] = np.fromfile(path, dtype=dt, count=el.count, offset=offset)
        offset += need
    return out


def _require(path: Path, arr: np.ndarray, names: list[str], what: str) -> None:
    missing = [n for n in names if n not in arr.dtype.names]
    if missing:
        raise SceneFormatError(path, f"{what} lacks required properties: {', '.join(missing)}")


def read_ply(path: str | Path, level: int | None = None) -> GaussianScene:
    """Read an INRIA 3DGS PLY (any SH degree 0-3, extra properties ignored) or a SuperSplat
    compressed PLY (detected by its 'chunk' element and packed_* properties)."""
    path = Path(path)
    els = read_elements(path)
    if "vertex" not in els:
        raise SceneFormatError(path, "PLY has no 'vertex' element")
    v = els["vertex"]
    if "chunk" in els and "packed_position" in (v.dtype.names or ()):
        return _decode_supersplat(path, els["chunk"], v, els.get("sh"))
    _require(path, v, ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                       "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"], "INRIA 3DGS PLY vertex")
    n = len(v)
    rest = sorted((p for p in v.dtype.names if _REST.fullmatch(p)), key=lambda s: int(s[7:]))
    if len(rest) not in (0, 9, 24, 45):
        raise SceneFormatError(path, f"{len(rest)} f_rest_* properties; expected 0, 9, 24 or 45 (SH degree 0-3)")
    k = len(rest) // 3 + 1
    sh = np.zeros((n, k, 3), dtype=np.float32)
    for c in range(3):
        sh[:, 0, c] = v[f"f_dc_{c}"]
        for j in range(k - 1):  # INRIA stores f_rest channel-major: R coeffs, then G, then B
            sh[:, j + 1, c] = v[rest[c * (k - 1) + j]]
    f = lambda *names: np.stack([v[a].astype(np.float32) for a in names], axis=1)
    return GaussianScene(
        means=f("x", "y", "z"), quats=f("rot_0", "rot_1", "rot_2", "rot_3"),
        log_scales=f("scale_0", "scale_1", "scale_2"), opacity_logits=v["opacity"].astype(np.float32), sh=sh)


def _unpack_unorm(v: np.ndarray, shift: int, bits: int) -> np.ndarray:
    return ((v >> shift) & ((1 << bits) - 1)).astype(np.float32) / float((1 << bits) - 1)


def _decode_supersplat(path: Path, chunk: np.ndarray, v: np.ndarray, sh_el: np.ndarray | None) -> GaussianScene:
    _require(path, chunk, ["min_x", "min_y", "min_z", "max_x", "max_y", "max_z", "min_scale_x", "min_scale_y",
                           "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z"], "SuperSplat chunk element")
    _require(path, v, ["packed_position", "packed_rotation", "packed_scale", "packed_color"], "SuperSplat vertex")
    n = len(v)
    if len(chunk) * 256 < n:
        raise SceneFormatError(path, f"SuperSplat PLY has {len(chunk)} chunks for {n:,} splats (need {-(-n // 256)})")
    ci = np.arange(n) // 256  # 256 splats per chunk, in order
    ch = chunk[ci]
    lerp = lambda lo, hi, t: ch[lo] + (ch[hi] - ch[lo]) * t
    pp = v["packed_position"].astype(np.uint32)
    means = np.stack([
        lerp("min_x", "max_x", _unpack_unorm(pp, 21, 11)),
        lerp("min_y", "max_y", _unpack_unorm(pp, 11, 10)),
        lerp("min_z", "max_z", _unpack_unorm(pp, 0, 11))], 1)
    ps = v["packed_scale"].astype(np.uint32)
    log_scales = np.stack([
        lerp("min_scale_x", "max_scale_x", _unpack_unorm(ps, 21, 11)),
        lerp("min_scale_y", "max_scale_y", _unpack_unorm(ps, 11, 10)),
        lerp("min_scale_z", "max_scale_z", _unpack_unorm(ps, 0, 11))], 1)
    # rotation: 2 bits index of the largest component, then three 10-bit components in
    # [-1/sqrt2, 1/sqrt2]; the largest is recovered from unit norm. Order (w, x, y, z).
    pr = v["packed_rotation"].astype(np.uint32)
    norm = np.sqrt(2.0)
    abc = np.stack([(_unpack_unorm(pr, s, 10) - 0.5) * norm for s in (20, 10, 0)], 1)
    m = np.sqrt(np.clip(1.0 - (abc ** 2).sum(1), 0.0, None))
    mode = (pr >> 30).astype(np.int64)
    quats = np.empty((n, 4), dtype=np.float32)
    for largest in range(4):
        sel = mode == largest
        others = [i for i in range(4) if i != largest]
        quats[sel, largest] = m[sel]
        quats[np.ix_(sel, others)] = abc[sel]
    pc = v["packed_color"].astype(np.uint32)
    rgb = np.stack([_unpack_unorm(pc, s, 8) for s in (24, 16, 8)], 1)
    if "min_r" in chunk.dtype.names:
        rgb = np.stack([lerp(f"min_{c}", f"max_{c}", rgb[:, i]) for i, c in enumerate("rgb")], 1)
    alpha = np.clip(_unpack_unorm(pc, 0, 8), 1e-6, 1 - 1e-6)
    k = 1
    rest = None
    if sh_el is not None and len(sh_el) == n:
        names = sorted((p for p in sh_el.dtype.names if _REST.fullmatch(p)), key=lambda s: int(s[7:]))
        if len(names) in (9, 24, 45):
            k = len(names) // 3 + 1
            # uint8 -> [-4, 4) as in SuperSplat: (x / 256 - 0.5) * 8, channel-major like INRIA
            rest = (np.stack([sh_el[p] for p in names], 1).astype(np.float32) + 0.5) / 256 * 8 - 4
    sh = np.zeros((n, k, 3), dtype=np.float32)
    sh[:, 0] = (rgb - 0.5) / SH_C0
    if rest is not None:
        for c in range(3):
            sh[:, 1:, c] = rest[:, c * (k - 1):(c + 1) * (k - 1)]
    return GaussianScene(means, quats, log_scales, np.log(alpha / (1 - alpha)), sh)


def write_inria_ply(path: str | Path, scene: GaussianScene, extra: dict[str, np.ndarray] | None = None) -> None:
    """Write the INRIA binary little-endian layout (x y z nx ny nz f_dc f_rest opacity scale rot).

    Args:
        extra: additional per-vertex float32 properties appended after rot_3.
    """
    n, k = len(scene), scene.sh.shape[1]
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(3 * (k - 1))]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    extra = extra or {}
    names += list(extra)
    data = np.zeros((n, len(names)), dtype="<f4")
    data[:, 0:3] = scene.means
    data[:, 6:9] = scene.sh[:, 0]
    col = 9
    for c in range(3):
        data[:, col:col + k - 1] = scene.sh[:, 1:, c]
        col += k - 1
    data[:, col] = scene.opacity_logits
    data[:, col + 1:col + 4] = scene.log_scales
    data[:, col + 4:col + 8] = scene.quats
    for j, arr in enumerate(extra.values()):
        data[:, col + 8 + j] = arr
    header = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {n}\n"
    header += "".join(f"property float {p}\n" for p in names) + "end_header\n"
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(data.tobytes())
