"""Completion markers: data/_markers/{stage}/{scene_id}.json, written last (after all outputs),
holding the config hash, outputs, counts, timing and a manifest of the outputs' files. A (stage,
scene) is done when its marker exists with the current hash and its outputs are still what the
manifest says: every file present with its recorded size (a stat per file, so that resuming
thousands of scenes stays a matter of seconds), and with `verify=checksum` also its sha256."""
from __future__ import annotations

import json
import os
from pathlib import Path

from navcore.io import jsonio
from navcore.io.atomic import TEMP_PREFIXES, write_text_atomic
from navcore.io.release import sha256_file

VERIFY = ("size", "checksum", "none")
"""How a marker's outputs are checked before the marker is trusted: file sizes (default),
sizes and sha256 (reads every output), or not at all."""


def read_marker(path: Path) -> dict | None:
    try:
        return json.loads(Path(path).read_text())
    except (FileNotFoundError, json.JSONDecodeError, UnicodeDecodeError):
        return None


def write_marker(path: Path, payload: dict) -> None:
    write_text_atomic(path, jsonio.dumps(payload, indent=1, sort_keys=True, default=str))


def _files(path: Path):
    """The files of one output (itself, or those under a folder; temporaries left out), sorted."""
    if path.is_file():
        yield path
        return
    for dirpath, dirnames, filenames in os.walk(path):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith(TEMP_PREFIXES))
        for f in sorted(filenames):
            if not f.startswith(TEMP_PREFIXES):
                yield Path(dirpath) / f


def output_manifest(outputs: list[str], root: Path) -> dict[str, list]:
    """{path relative to the data root: [size, sha256]} of every file of the outputs. Outputs
    outside the data root (a user's export folder) are keyed by their absolute path."""
    root = Path(root).resolve()
    out = {}
    for o in outputs:
        for f in _files(Path(o)):
            p = f.resolve()
            key = str(p.relative_to(root)) if p.is_relative_to(root) else str(p)
            out[key] = [p.stat().st_size, sha256_file(p)]
    return dict(sorted(out.items()))


def manifest_problem(manifest: dict | None, root: Path, verify: str = "size") -> str | None:
    """Why a marker's outputs are not what it recorded (the first file found), or None."""
    if verify not in VERIFY:
        raise ValueError(f"markers verify={verify!r}; choose one of {VERIFY}")
    if verify == "none" or manifest is None:
        return None
    root = Path(root)
    for key, (size, digest) in manifest.items():
        p = Path(key) if os.path.isabs(key) else root / key
        try:
            st = p.stat()
        except OSError:
            return f"{key} is missing"
        if st.st_size != size:
            return f"{key} has {st.st_size} bytes, the marker recorded {size}"
        if verify == "checksum" and sha256_file(p) != digest:
            return f"{key} changed (sha256 differs from the marker's)"
    return None
