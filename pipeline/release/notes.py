"""RELEASE_NOTES.md of a release built with `release.previous`: scenes added, removed and changed (by
the content hash of their files), and episode counts per task and split before and after."""
from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq

from navcore.io.release import SCENES


def release_notes(prev: dict, prev_dir: Path, info: dict, scene_rows: list[dict]) -> str:
    old = {r["scene_id"]: r for r in pq.read_table(Path(prev_dir) / SCENES).to_pylist()}
    new = {r["scene_id"]: r for r in scene_rows}
    added = sorted(set(new) - set(old))
    removed = sorted(set(old) - set(new))
    changed = sorted(s for s in set(new) & set(old) if new[s]["content_sha256"] != old[s]["content_sha256"])
    same = len(set(new) & set(old)) - len(changed)
    L = [f"# {info['name']} {info['version']} (previous: {prev['version']})", "",
         f"Scenes: {len(added)} added, {len(removed)} removed, {len(changed)} changed, {same} unchanged "
         "(by the sha256 of their files).", ""]
    for title, ids, rows in (("Added", added, new), ("Removed", removed, old), ("Changed", changed, new)):
        if ids:
            L += [f"## {title}", ""] + [f"- {rows[s]['name']} ({s}, {rows[s]['group']})" for s in ids] + [""]
    L += ["## Episodes", "", f"| task | split | {prev['version']} | {info['version']} | change |", "|---|---|---|---|---|"]
    tasks = sorted(set(prev["counts"]) | set(info["counts"]))
    for t in tasks:
        splits = sorted(set(prev["counts"].get(t, {})) | set(info["counts"].get(t, {})))
        for sp in splits:
            a, b = prev["counts"].get(t, {}).get(sp, 0), info["counts"].get(t, {}).get(sp, 0)
            L.append(f"| {t} | {sp} | {a:,} | {b:,} | {b - a:+,} |")
    return "\n".join(L) + "\n"
