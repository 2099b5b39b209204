"""Compare the stored outputs of two data roots byte for byte.

    python -m benchmarks.dataset.compare_data /tmp/before /tmp/after

The pipeline's own bookkeeping (_markers, _runs, _hydra, _submit, _locks, _progress) is left out; each root's absolute path
(recorded where a stage names its source file) is normalised, and so are the stage durations that
asset manifests copy from the markers. Time stamps must be pinned with SOURCE_DATE_EPOCH in both
runs. Prints a JSON report; exits 1 when any file differs or exists on one side only.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import re
import sys
from pathlib import Path

BOOKKEEPING = ("_markers", "_runs", "_hydra", "_submit", "_locks", "_progress")


def digests(root: Path) -> dict[str, str]:
    out = {}
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root)
        if not p.is_file() or rel.parts[0] in BOOKKEEPING:
            continue
        data = p.read_bytes().replace(str(root).encode(), b"<ROOT>")
        if p.name == "manifest.json":
            data = re.sub(rb'"duration_s": [0-9.eE+-]+', b'"duration_s": null', data)
        out[str(rel)] = hashlib.sha256(data).hexdigest()
    return out


def compare(a: Path, b: Path) -> dict:
    da, db = digests(a.resolve()), digests(b.resolve())
    return {"files": [len(da), len(db)], "only_first": sorted(set(da) - set(db)),
            "only_second": sorted(set(db) - set(da)),
            "differing": sorted(k for k in set(da) & set(db) if da[k] != db[k])}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("first", type=Path)
    ap.add_argument("second", type=Path)
    args = ap.parse_args(argv)
    rep = compare(args.first, args.second)
    print(json.dumps(rep, indent=1))
    return 1 if rep["only_first"] or rep["only_second"] or rep["differing"] else 0


if __name__ == "__main__":
    sys.exit(main())
