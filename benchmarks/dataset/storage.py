"""Bytes stored per scene against its source file, and per episode.

    python -m benchmarks.dataset.storage data

Counts unique inodes (a hard link to the source costs nothing; an asset's link whose original was
replaced since is a copy, and is named). Per scene: the bytes of each stage's outputs (scene
store, asset, voxels, costmaps, screen layer, semantics), the scene folder (canonical Gaussian
store, alignment, reports) plus the asset, then with voxels and costmaps; per
episode: the episodes and trajectories tables over the number of episodes. Prints a table and
JSON.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def tree_bytes(paths, seen: set) -> int:
    tot = 0
    for p in paths:
        if not p.exists():
            continue
        for f in ([p] if p.is_file() else sorted(q for q in p.rglob("*") if q.is_file())):
            st = f.stat()
            if (st.st_dev, st.st_ino) not in seen:
                seen.add((st.st_dev, st.st_ino))
                tot += st.st_size
    return tot


def unlinked_source_files(asset: Path, source_inodes: set) -> list[str]:
    """The asset's links to its original (source.ply, source/...) that are no longer the original's
    files: it was replaced since (re-downloaded, re-provisioned), so the link keeps the old copy and
    costs its bytes; `stages=[asset] force=true` links the current files."""
    files = [asset / "source.ply"] + sorted(q for q in (asset / "source").rglob("*") if q.is_file())
    return [str(f.relative_to(asset)) for f in files
            if f.is_file() and not f.is_symlink() and (f.stat().st_dev, f.stat().st_ino) not in source_inodes]


def measure(root: Path, scene_ids: set[str] | None = None) -> dict:
    """Bytes of each scene of the root (of `scene_ids` only, where given: a root may also hold other
    catalogs' scenes) and of its episode tables."""
    import pyarrow.parquet as pq

    from navcore.gaussians.formats import source_files

    scenes = []
    for rep in sorted((root / "01_scenes").glob("*/ingest.json")):
        ing = json.loads(rep.read_text())
        sid, seen = ing["scene_id"], set()
        if scene_ids is not None and sid not in scene_ids:
            continue
        src = tree_bytes(source_files(ing["source"])[1], seen)  # counted first: links to it are free
        asset = root / "09_assets" / ing["group"] / sid
        stale = unlinked_source_files(asset, seen)
        per_stage = {name: tree_bytes(paths, seen) for name, paths in (
            ("ingest (scene store)", [root / "01_scenes" / sid]), ("asset", [asset]),
            ("voxelize", [root / "02_voxels" / f"{sid}.zarr"]), ("costmap", [root / "03_costmaps" / f"{sid}.zarr"]),
            ("screen", [root / "03_costmaps" / "screen" / f"{sid}.zarr"]),
            ("semantics", [root / "04_semantics" / sid]))}
        store = per_stage["ingest (scene store)"] + per_stage["asset"]
        maps = per_stage["voxelize"] + per_stage["costmap"] + per_stage["screen"]
        scenes.append({"scene_id": sid, "scene": ing.get("name", sid), "source_bytes": src,
                       "store_and_asset_bytes": store, "maps_bytes": maps, "bytes_per_stage": per_stage,
                       "ratio": store / src if src else None, "ratio_with_maps": (store + maps) / src if src else None,
                       "ratio_all": sum(per_stage.values()) / src if src else None,
                       "unlinked_source_files": stale})
    parts = sorted(d for top in ("05_episodes", "06_trajectories") for d in (root / top).glob("task=*/scene_id=*")
                   if scene_ids is None or d.name.split("=", 1)[1] in scene_ids)
    n = sum(pq.read_metadata(d / "part-0.parquet").num_rows for d in parts
            if d.parent.parent.name == "05_episodes" and (d / "part-0.parquet").is_file())
    tables = tree_bytes(parts, set())
    return {"scenes": scenes, "episodes": n, "bytes_per_episode": tables / n if n else None}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", type=Path, nargs="?", default=Path("data"))
    rep = measure(ap.parse_args(argv).data)
    for s in rep["scenes"]:
        print(f"{s['scene_id']}: source {s['source_bytes'] / 1e6:.1f} MB, scene store + asset "
              f"{s['store_and_asset_bytes'] / 1e6:.1f} MB ({s['ratio']:.2f}x), with voxels and costmaps "
              f"{s['ratio_with_maps']:.2f}x, everything {s['ratio_all']:.2f}x; per stage (MB): "
              + ", ".join(f"{k} {v / 1e6:.2f}" for k, v in s["bytes_per_stage"].items()))
        if s["unlinked_source_files"]:
            print(f"  warning: {len(s['unlinked_source_files'])} of the asset's links to its original are copies now "
                  f"(the original was replaced since): `stages=[asset] force=true` links the current files")
    if rep["episodes"]:
        print(f"{rep['episodes']} episodes: {rep['bytes_per_episode'] / 1e3:.2f} KB an episode with its trajectory")
    print(json.dumps(rep, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
