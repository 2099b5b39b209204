"""Property-based fuzzing (hypothesis) of every 3DGS reader through `read_validated`, the path
ingest takes: small valid files written by our writers are truncated, bit-flipped (header and
payload), given lying or huge counts, poisoned with NaN / inf / 1e30 / denormals / zero
quaternions, emptied, replaced by a folder, or made into decompression bombs. Every case must end
in a SceneFormatError naming the file or in a validated scene (finite, unit quaternions); anything
else is a crash, a case over the time limit a hang, and a case whose peak traced allocation
exceeds ALLOC_PER_BYTE x the input's size + ALLOC_BASE a memory blow-up.

    PYTHONPATH=tests python -m faults.fuzz_readers --cases 10000   # -> data/08_reports/fuzz_readers.json
"""
from __future__ import annotations

import argparse
import gzip
import json
import math
import re
import shutil
import signal
import struct
import time
import tracemalloc
import zipfile
import zlib
from pathlib import Path

import numpy as np

ALLOC_BASE = 64 << 20
"""Memory any case may allocate whatever its size (bytes)."""
ALLOC_PER_BYTE = 64
"""Memory a case may allocate per byte of input (decoded arrays are a few times the file)."""
TIME_LIMIT_S = 10.0
"""A case that takes longer is a hang."""

KINDS = ("inria_ply", "supersplat_ply", "splat", "spz_v2", "spz_v3", "spz_v4", "sog", "sog_lod", "npy_folder")
"""Seed files: one per reader and layout."""
READER_OF = {"inria_ply": "ply", "supersplat_ply": "ply", "splat": "splat", "spz_v2": "spz", "spz_v3": "spz",
             "spz_v4": "spz", "sog": "sog", "sog_lod": "sog", "npy_folder": "npy_folder"}


class Hang(Exception):
    pass


def small_scene(n: int, deg: int, seed: int):
    from navcore.gaussians.model import GaussianScene

    r = np.random.default_rng(seed)
    q = r.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return GaussianScene(r.uniform(-3, 3, (n, 3)), q, r.uniform(-5, -1, (n, 3)), r.uniform(-3, 3, n),
                         r.normal(0, 0.5, (n, (deg + 1) ** 2, 3)))


def write_supersplat(path: Path, scene) -> None:
    """A minimal SuperSplat compressed PLY (one chunk per 256 splats, packed vertex words)."""
    n = len(scene)
    nc = -(-n // 256)
    lo, hi = scene.means.min(0), scene.means.max(0) + 1e-3
    slo, shi = scene.log_scales.min(0), scene.log_scales.max(0) + 1e-3
    chunk = np.zeros((nc, 12), "<f4")
    chunk[:, 0:3], chunk[:, 3:6], chunk[:, 6:9], chunk[:, 9:12] = lo, hi, slo, shi
    t = (scene.means - lo) / (hi - lo)
    pos = ((t[:, 0] * 2047).astype(np.uint32) << 21) | ((t[:, 1] * 1023).astype(np.uint32) << 11) | \
        (t[:, 2] * 2047).astype(np.uint32)
    ts = (scene.log_scales - slo) / (shi - slo)
    sc = ((ts[:, 0] * 2047).astype(np.uint32) << 21) | ((ts[:, 1] * 1023).astype(np.uint32) << 11) | \
        (ts[:, 2] * 2047).astype(np.uint32)
    rot = (np.arange(n, dtype=np.uint32) % 4 << 30) | np.uint32(0x1FF << 20 | 0x1FF << 10 | 0x1FF)
    col = np.full(n, 0x80808080, np.uint32)
    head = ["ply", "format binary_little_endian 1.0", f"element chunk {nc}"]
    head += [f"property float {p}" for p in ("min_x", "min_y", "min_z", "max_x", "max_y", "max_z", "min_scale_x",
                                             "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z")]
    head += [f"element vertex {n}"] + [f"property uint {p}" for p in ("packed_position", "packed_rotation",
                                                                       "packed_scale", "packed_color")]
    head += ["end_header", ""]
    with open(path, "wb") as f:
        f.write("\n".join(head).encode())
        f.write(chunk.tobytes())
        f.write(np.stack([pos, rot, sc, col], 1).astype("<u4").tobytes())


def make_seed(kind: str, folder: Path) -> Path:
    """Write the valid seed file (or folder) of one kind; returns what read_validated reads."""
    from navcore.gaussians.formats import write_inria_ply, write_npy_folder, write_sog, write_sog_lod, write_splat, write_spz

    folder.mkdir(parents=True, exist_ok=True)
    s = small_scene(40, {"inria_ply": 3, "spz_v4": 2, "sog": 1}.get(kind, 0), zlib.crc32(kind.encode()) % 1000)
    if kind == "inria_ply":
        write_inria_ply(folder / "s.ply", s)
        return folder / "s.ply"
    if kind == "supersplat_ply":
        write_supersplat(folder / "s.compressed.ply", s)
        return folder / "s.compressed.ply"
    if kind == "splat":
        write_splat(folder / "s.splat", s)
        return folder / "s.splat"
    if kind.startswith("spz_v"):
        write_spz(folder / "s.spz", s, version=int(kind[-1]))
        return folder / "s.spz"
    if kind == "sog":
        write_sog(folder / "s.sog", s)
        return folder / "s.sog"
    if kind == "sog_lod":
        return write_sog_lod(folder / "lod", [[s.subset(np.arange(20)), s.subset(np.arange(20, 40))]])
    if kind == "npy_folder":
        write_npy_folder(folder / "npy", s)
        return folder / "npy"
    raise ValueError(kind)


# ---- mutations ------------------------------------------------------------------------------
# A case: (member, op, args). member indexes the files of the seed (a folder's files, a zip's
# members, a gzip stream's payload); op one of OPS, applied to that member's bytes.

OPS = ("truncate", "flip_header", "flip_payload", "overwrite", "lying_count", "poison_floats", "empty",
       "directory", "bomb", "duplicate_tail")
POISON = (math.nan, math.inf, -math.inf, 1e30, -1e30, 1e-42, 0.0, -0.0, 3.4e38)


def _lie(data: bytes, value: int) -> bytes:
    """Replace one count the format states: a PLY 'element X N', a JSON integer, or the 32-bit
    count after an SPZ magic / in a .npy header's shape."""
    m = list(re.finditer(rb"element (\w+) (\d+)", data[:4096]))
    if m:
        g = m[value % len(m)]
        return data[:g.start(2)] + str(value).encode() + data[g.end(2):]
    m = list(re.finditer(rb"(?<=[:\[(, ])(\d+)(?=[,\])}\s])", data[:8192]))
    if m and (data[:1] in (b"{", b"[") or data[:6] == b"\x93NUMPY"):
        g = m[value % len(m)]
        return data[:g.start()] + str(value).encode() + data[g.end():]
    if data[:4] == b"NGSP" and len(data) >= 12:  # v4 header: magic, version, count
        return data[:8] + struct.pack("<I", value & 0xFFFFFFFF) + data[12:]
    if len(data) >= 8:
        return data[:4] + struct.pack("<I", value & 0xFFFFFFFF) + data[8:]
    return data


def mutate(data: bytes, op: str, a: int, b: int, poison: float, header: int, compressed: bool = False) -> bytes | None:
    """The member's new bytes (None: replace the member by a directory). compressed: the member is
    stored compressed (a gzip payload, a zip member), so a bomb inflates to 4-256 MB; appended to
    a plain file it adds 1-4 MB (a big file, not a bomb)."""
    n = len(data)
    if op == "truncate":
        return data[: a % (n + 1)]
    if op in ("flip_header", "flip_payload", "overwrite"):
        if n == 0:
            return data
        lo, hi = (0, min(header, n)) if op == "flip_header" else (min(header, n - 1), n)
        out = bytearray(data)
        rng = np.random.default_rng(a)
        for _ in range(1 + b % 8):
            i = int(rng.integers(lo, max(hi, lo + 1)))
            if op == "overwrite":
                out[i] = int(rng.integers(256))
            else:
                out[i] ^= 1 << int(rng.integers(8))
        return bytes(out)
    if op == "lying_count":
        value = [0, 1, 2**31 - 1, 2**32 - 1, 2**63 - 1, 10**12, a % 1000, -1][b % 8]
        return _lie(data, value if value >= 0 else a)
    if op == "poison_floats":
        out = bytearray(data)
        rng = np.random.default_rng(a)
        for _ in range(1 + b % 16):
            if n >= header + 4:
                i = int(rng.integers(header, n - 3)) & ~3
                out[i:i + 4] = struct.pack("<f", poison)
        return bytes(out)
    if op == "empty":
        return b""
    if op == "directory":
        return None
    if op == "bomb":  # a stream that inflates to far more than its size: the payload, then zeros
        return data + bytes((1 << (22 + a % 7)) if compressed else (a % 4 + 1) << 20)  # 4-256 MB inflated
    if op == "duplicate_tail":
        return data + data[header:][: a % (n + 1)]
    raise ValueError(op)


def members(path: Path) -> list[tuple[str, Path]]:
    """The mutable members of a seed: ("file", p) for plain files, ("gzip", p) for a gzip stream
    (mutated inside), ("zip:<name>", p) for a zip member."""
    if path.is_dir():
        return [("file", p) for p in sorted(path.rglob("*")) if p.is_file()]
    if path.name == "lod-meta.json":
        return [("file", p) for p in sorted(path.parent.rglob("*")) if p.is_file()]
    data = path.read_bytes()
    if data[:2] == b"\x1f\x8b":
        return [("gzip", path)]
    if data[:2] == b"PK":
        with zipfile.ZipFile(path) as zf:
            return [(f"zip:{n}", path) for n in zf.namelist()]
    return [("file", path)]


def apply_case(seed: Path, work: Path, member: int, op: str, a: int, b: int, poison: float) -> Path:
    """Copy the seed to `work` and apply one mutation; returns the path to read."""
    if work.exists():
        shutil.rmtree(work)
    if seed.is_dir():
        shutil.copytree(seed, work / seed.name)
        target = work / seed.name
    elif seed.name == "lod-meta.json":
        shutil.copytree(seed.parent, work / seed.parent.name)
        target = work / seed.parent.name / seed.name
    else:
        work.mkdir(parents=True)
        shutil.copy2(seed, work / seed.name)
        target = work / seed.name
    mem = members(target)
    kind, p = mem[member % len(mem)]
    if kind == "file":
        raw = p.read_bytes()
        new = mutate(raw, op, a, b, poison, _header_len(raw))
        _put(p, new)
    elif kind == "gzip":
        raw = gzip.decompress(p.read_bytes())
        new = mutate(raw, op, a, b, poison, 16, compressed=True)
        _put(p, None if new is None else gzip.compress(new, compresslevel=1, mtime=0))  # level 1: bombs are fast to build
    else:
        name = kind[4:]
        with zipfile.ZipFile(p) as zf:
            files = {n: zf.read(n) for n in zf.namelist()}
        new = mutate(files[name], op, a, b, poison, _header_len(files[name]), compressed=True)
        if new is None:
            del files[name]
        else:
            files[name] = new
        with zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
            for n, d in files.items():
                zf.writestr(zipfile.ZipInfo(n, date_time=(1980, 1, 1, 0, 0, 0)), d)
    return target


def _put(p: Path, data: bytes | None) -> None:
    if data is None:
        p.unlink()
        p.mkdir()
    else:
        p.write_bytes(data)


def _header_len(raw: bytes) -> int:
    i = raw.find(b"end_header\n")
    if i >= 0:
        return i + 11
    if raw[:6] == b"\x93NUMPY" and len(raw) > 10:
        return 10 + int.from_bytes(raw[8:10], "little")
    if raw[:4] == b"NGSP":
        return 32
    return min(len(raw), 64)


# ---- one case -------------------------------------------------------------------------------

def _alarm(signum, frame):
    raise Hang()


def run_case(path: Path, reader: str) -> tuple[str, str]:
    """(outcome, detail): outcome rejected | accepted | crash | hang | memory."""
    from navcore.gaussians.errors import SceneFormatError
    from navcore.gaussians.validate import read_validated

    files = path.parent.rglob("*") if path.name == "lod-meta.json" else [path] if path.is_file() else \
        path.rglob("*") if path.is_dir() else []
    size = sum(p.stat().st_size for p in files if p.is_file())
    budget = ALLOC_BASE + ALLOC_PER_BYTE * size
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, TIME_LIMIT_S)
    tracemalloc.start()
    try:
        scene, _ = read_validated(path, reader, scene_id="fuzz")
        outcome, detail = "accepted", ""
        if not (np.isfinite(scene.means).all() and np.isfinite(scene.log_scales).all()
                and np.allclose(np.linalg.norm(scene.quats, axis=1), 1, atol=1e-3)
                and np.isfinite(scene.opacity_logits).all() and np.isfinite(scene.sh).all()):
            outcome, detail = "crash", "validated scene holds non-finite values or non-unit quaternions"
    except SceneFormatError as e:
        outcome, detail = "rejected", str(e)
        if "fuzz" not in detail:
            outcome, detail = "crash", f"SceneFormatError without the scene's name: {detail}"
    except Hang:
        outcome, detail = "hang", f"over {TIME_LIMIT_S} s"
    except MemoryError as e:
        outcome, detail = "memory", f"MemoryError {e}"
    except Exception as e:  # noqa: BLE001 - what fuzzing is for
        outcome, detail = "crash", f"{type(e).__name__}: {e}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    if outcome in ("accepted", "rejected") and peak > budget:
        outcome, detail = "memory", f"peak {peak:,} bytes for {size:,} bytes of input"
    return outcome, detail


def case_strategy():
    from hypothesis import strategies as st

    return st.tuples(st.integers(0, 63), st.sampled_from(OPS), st.integers(0, 2**32 - 1), st.integers(0, 2**16),
                     st.sampled_from(POISON))


def fuzz_kind(kind: str, cases: int, seed: int, work: Path, log=None) -> dict:
    """Run `cases` hypothesis-drawn mutations of one seed kind; returns counts and the failing cases."""
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hseed

    src = make_seed(kind, work / "seed" / kind)
    tally = Tally(kind, log)

    @hseed(seed)
    @settings(max_examples=cases, database=None, deadline=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(case_strategy())
    def one(case):
        member, op, a, b, poison = case
        path = apply_case(src, work / "case", member, op, a, b, poison)
        t0 = time.perf_counter()
        tally.add(list(case), *run_case(path, READER_OF[kind]), t0)

    one()
    return tally.report()


class Tally:
    """Outcomes of one kind's fuzz cases: counts, and the cases that were not accepted or rejected
    (each logged as it happens; the first 50 kept)."""

    def __init__(self, kind: str, log=None):
        self.kind, self.log, self.counts, self.bad = kind, log, {}, []

    def add(self, case: list, outcome: str, detail: str, t0: float) -> None:
        self.counts[outcome] = self.counts.get(outcome, 0) + 1
        if outcome not in ("accepted", "rejected"):
            self.bad.append({"case": case, "outcome": outcome, "detail": detail[:300],
                             "seconds": round(time.perf_counter() - t0, 3)})
            if self.log:
                self.log(self.kind, self.bad[-1])

    def report(self) -> dict:
        return {"cases": sum(self.counts.values()),
                **{k: self.counts.get(k, 0) for k in ("accepted", "rejected", "crash", "hang", "memory")},
                "failures": self.bad[:50]}


def cap_address_space(gb: float) -> None:
    """Cap this process's address space, so that an allocation a hostile file asks for fails here
    as a MemoryError (counted) instead of taking the machine; 0: no cap."""
    if gb > 0:
        import resource

        cap = int(gb * (1 << 30))
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))


def main(argv=None) -> dict:
    from benchmarks import machine, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=10_000, help="cases per seed kind")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--work", default="/tmp/navarena_fuzz")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--merge", nargs="+", type=Path,
                    help="instead of fuzzing: fuzz_readers.json files, later ones replacing earlier kinds")
    ap.add_argument("--address-space-gb", type=float, default=16.0,
                    help="cap this process's address space, so that an allocation a hostile file asks "
                         "for fails here as a MemoryError (counted) instead of taking the machine")
    args = ap.parse_args(argv)
    cap_address_space(args.address_space_gb)
    rep = {"machine": machine(), "cases_per_kind": args.cases, "kinds": {}}
    t0 = time.perf_counter()
    if args.merge:
        for f in args.merge:
            r = json.loads(Path(f).read_text())
            rep["kinds"].update(r["kinds"])
            rep.setdefault("merged_from", []).append({"file": str(f), "kinds": list(r["kinds"])})
    for kind in ([] if args.merge else args.kinds.split(",")):
        t = time.perf_counter()
        r = fuzz_kind(kind, args.cases, args.seed, Path(args.work) / kind,
                      log=lambda k, f: print(json.dumps({"kind": k, **f}), flush=True))
        r["seconds"] = round(time.perf_counter() - t, 1)
        rep["kinds"][kind] = r
        print(kind, {k: v for k, v in r.items() if k != "failures"}, flush=True)
    readers: dict[str, int] = {}
    for kind, r in rep["kinds"].items():
        readers[READER_OF[kind]] = readers.get(READER_OF[kind], 0) + r["cases"]
    rep["cases_per_reader"] = readers
    rep["fuzz_cases"] = sum(r["cases"] for r in rep["kinds"].values())
    rep["fuzz_crashes"] = sum(r["crash"] + r["memory"] for r in rep["kinds"].values())
    rep["fuzz_hangs"] = sum(r["hang"] for r in rep["kinds"].values())
    rep["seconds"] = round(time.perf_counter() - t0, 1)
    write_report(args.out, "fuzz_readers.json", rep)
    return rep


if __name__ == "__main__":
    main()
