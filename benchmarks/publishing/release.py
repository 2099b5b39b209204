"""The release at scale (issue 45): `navarena release` and `navarena verify-release` on the
2,000-scene simulation's data root, and the projection to the 22 M-episode release.

    python -m benchmarks.publishing.release [--root /tmp/navarena_sim] [--sizes 500,2000] [--docs]

The data root is `python -m benchmarks.scale.bench_scale sim`'s (its overrides, `SIM`, are repeated so
that the release finds every stage done). For each size (the first n generated scenes,
scenes.count=n) a release is built in a subprocess whose peak RSS is polled: the build streams scene
by scene, so its memory must not grow with the number of episodes; then verify-release hashes the
whole folder and re-checks 200 episodes against the maps. Writes data/08_reports/bench_release.{json,md}
and, with --docs, docs/benchmarks/bench_release.md.
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
from pathlib import Path

from benchmarks import machine, run_polled, write_report
from benchmarks.pages import write_page
from benchmarks.scale.bench_scale import RELEASE, RELEASE_SCENES, SIM
from navcore.io.release import read_manifest

PROJECT = Path(__file__).resolve().parents[2]
RELEASE_EPISODES = RELEASE_SCENES * sum(RELEASE.values())


def polled(cmd: list[str], log: Path) -> dict:
    """Run cmd in the project: wall seconds, peak RSS in MB (polled every 0.2 s), exit code."""
    r = run_polled(cmd, log, cwd=PROJECT)
    return {"wall_s": round(r["wall_s"], 2), "peak_rss_mb": round(r["peak_rss_mb"], 1), "exit": r["exit"]}


def folder_bytes(manifest: Path) -> dict:
    rows = read_manifest(manifest)
    by = {}
    for path, (size, _) in rows.items():
        top = path.split("/")[0] if "/" in path else "(top level)"
        by[top] = by.get(top, 0) + size
    return {"files": len(rows) + 1, "bytes": sum(size for size, _ in rows.values()), "by_folder": dict(sorted(by.items()))}


def one_size(root: Path, n: int | None, out: Path, logs: Path) -> dict:
    """Build and verify the release of the first n scenes of the simulation (n None: the default
    dataset's root as it is, the reference of bytes per episode at a real file size)."""
    folder = out / (f"sim-{n}" if n else "default")
    shutil.rmtree(folder, ignore_errors=True)
    over = [*SIM, f"scenes.count={n}"] if n else []
    build = polled([sys.executable, "-m", "navarena", "release", "--root", str(root), "--out", str(folder),
                    "--version", "1.0.0", *over], logs / f"release_{n}.log")
    if build["exit"] or not (folder / "release.json").is_file():
        raise SystemExit(f"release of {n} scenes failed (exit {build['exit']}); see {logs / f'release_{n}.log'}")
    verify = polled([sys.executable, "-m", "navarena", "verify-release", str(folder), "--quiet",
                     "--json", str(logs / f"verify_{n}.json")], logs / f"verify_{n}.log")
    info = json.loads((folder / "release.json").read_text())
    size = folder_bytes(folder / "MANIFEST.tsv")
    eps = sum(n_ for t, s in info["counts"].items() for sp, n_ in s.items() if sp != info["eval_set"]["name"])
    return {"scenes": info["scenes"]["included"], "root": str(root), "episodes": eps, "build": build, "verify": verify,
            "verify_ok": json.loads((logs / f"verify_{n}.json").read_text())["ok"], **size,
            "eval_set": {t: r["selected"] for t, r in info["eval_set"]["per_task"].items()}}


def table_bytes(folder: Path, sample: int = 400) -> dict:
    """Bytes of the episode tables split into Parquet's per-file overhead (footer, schema) and data
    per episode, from a sample of files: the simulation's files hold a handful of episodes each, so
    their bytes per episode are mostly overhead that a release-density file amortises."""
    import pyarrow.parquet as pq

    eps = [rel for rel in read_manifest(folder / "MANIFEST.tsv") if rel.startswith("episodes/")]
    step = max(1, len(eps) // sample)
    footer = data = n = files = 0
    for rel in eps[::step]:
        tr = rel.replace("episodes/", "trajectories/", 1)
        for f in (rel, tr):
            md = pq.read_metadata(folder / f)
            footer += md.serialized_size + 8
            data += (folder / f).stat().st_size - md.serialized_size - 8
            files += 1
        n += pq.read_metadata(folder / rel).num_rows
    return {"footer_bytes_per_file": footer / files, "data_bytes_per_episode": data / n, "files_sampled": files}


def project(big: dict, small: dict, tb: dict, ref: dict) -> dict:
    """The release of RELEASE_SCENES scenes at bench_scale's release density from the measured slopes:
    seconds per scene (linking, reading, writing), hashing throughput, bytes per episode of data plus a
    footer per file (`table_bytes`)."""
    per_scene_build = (big["build"]["wall_s"] - small["build"]["wall_s"]) / (big["scenes"] - small["scenes"])
    per_scene_verify = (big["verify"]["wall_s"] - small["verify"]["wall_s"]) / (big["scenes"] - small["scenes"])
    hash_rate = big["bytes"] / max(big["verify"]["wall_s"], 1e-9)  # bytes/s of verify (I/O and sha256 bound)
    # the navarena layout adds a chunk (episodes + trajectories) every 1,000 episodes of a task
    extra_files = sum(2 * (math.ceil(n / 1000) - 1) for n in RELEASE.values())
    files = round((big["files"] / big["scenes"] + extra_files) * RELEASE_SCENES)
    table_files = RELEASE_SCENES * 2 * len(RELEASE)  # episodes and trajectories a task (one split a scene)
    canonical = tb["data_bytes_per_episode"] * RELEASE_EPISODES + tb["footer_bytes_per_file"] * table_files
    layout = ref["by_folder"].get("navarena", 0) / max(ref["by_folder"]["episodes"] + ref["by_folder"]["trajectories"], 1)
    tables = canonical * (1 + layout)
    assets = big["by_folder"].get("assets", 0) / big["scenes"]
    total = tables + assets * RELEASE_SCENES
    return {"episodes": RELEASE_EPISODES, "scenes": RELEASE_SCENES, "files": files,
            "data_bytes_per_episode": round(tb["data_bytes_per_episode"], 1),
            "footer_bytes_per_file": round(tb["footer_bytes_per_file"]), "layout_ratio": round(layout, 3),
            "table_bytes": round(tables), "asset_bytes_per_scene_sim": round(assets), "bytes": round(total),
            "build_s_per_scene": round(per_scene_build, 4), "verify_s_per_scene": round(per_scene_verify, 4),
            "hash_mb_per_s": round(hash_rate / 1e6, 1),
            "build_hours": round((per_scene_build * RELEASE_SCENES + total / hash_rate) / 3600, 2),
            "verify_hours": round((per_scene_verify * RELEASE_SCENES + total / hash_rate) / 3600, 2)}


def markdown(r: dict) -> str:
    L = [f"# bench-release: the release at scale ({r['machine']})", "",
         "`navarena release` on the 2,000-scene simulation's data root (`python -m benchmarks.scale.bench_scale sim`: "
         "one small room a scene, 4 PointNav + 2 ImageNav episodes; 10 % of the scenes held out), the first n "
         "scenes, then `navarena verify-release` (every file re-hashed, 200 episodes re-checked against the maps); "
         "first the default dataset's release (`make dataset`), the reference of a file's size at 100-200 episodes. "
         "Wall time on this machine, peak RSS of the command's process (polled).", "",
         "| scenes | episodes | files | MB | build (s) | build peak RSS (MB) | verify (s) | verify peak RSS (MB) | verified "
         "| eval set per task |",
         "|---|---|---|---|---|---|---|---|---|---|"]
    for s in [r["reference"], *r["sizes"]]:
        label = " (default dataset)" if s is r["reference"] else ""
        L.append(f"| {s['scenes']:,}{label} | {s['episodes']:,} | {s['files']:,} | {s['bytes'] / 1e6:,.1f} | "
                 f"{s['build']['wall_s']:.1f} | {s['build']['peak_rss_mb']:.0f} | {s['verify']['wall_s']:.1f} | "
                 f"{s['verify']['peak_rss_mb']:.0f} | {'yes' if s['verify_ok'] else 'NO'} | "
                 f"{', '.join(f'{k} {v}' for k, v in s['eval_set'].items())} |")
    big = r["sizes"][-1]
    L += ["", "Bytes by folder of the largest release: " + ", ".join(
        f"{k} {v / 1e6:,.1f} MB" for k, v in big["by_folder"].items()) + ".", ""]
    if r.get("memory_ratio") is not None:
        L += [f"Memory: the build's peak RSS at {r['sizes'][-1]['scenes']:,} scenes is {r['memory_ratio']:.2f}x that at "
              f"{r['sizes'][0]['scenes']:,} ({r['episode_ratio']:.1f}x the episodes): it streams.", ""]
    p = r.get("projection")
    if p:
        L += ["## Projection to the 22 M-episode release", "",
              f"{p['episodes']:,} episodes in {p['scenes']:,} scenes at bench_scale's release density (4,000 PointNav, "
              f"4,000 ImageNav, 2,800 ObjectNav a scene). The tables: {p['data_bytes_per_episode']:,.0f} bytes of data "
              f"an episode with its trajectory and Parquet's footer of {p['footer_bytes_per_file']:,} bytes a file "
              f"(measured on the default dataset's release, whose files hold 100-200 episodes; the simulation's hold "
              f"4-6 and are mostly footer), plus the NavArena layout's copy in its own columns and chunks "
              f"({p['layout_ratio']:.2f}x the canonical tables' bytes): {p['table_bytes'] / 1e9:,.1f} GB, about "
              f"{p['files']:,} files. With the simulation's assets "
              f"({p['asset_bytes_per_scene_sim'] / 1e6:.1f} MB a scene; a real capture's aligned model is 10-300 MB, "
              f"see bench_scale): {p['bytes'] / 1e9:,.1f} GB. Build: {p['build_s_per_scene']:.3f} s a scene "
              f"(linking, reading, writing the evaluation split) plus hashing at {p['hash_mb_per_s']:,.0f} MB/s: "
              f"{p['build_hours']:.2f} h on this machine; verify-release {p['verify_hours']:.2f} h (hashing is I/O "
              "and sha256 bound and runs on every core: `--workers`).", "",
              "The evaluation set is small here because the simulation's rooms are 3.6-4 m across: hard episodes "
              "(6 m and more) barely exist, and the set keeps the paper's 30 / 40 / 30 % proportions, so it is as large "
              "as its scarcest difficulty allows (the card says so). The default dataset's rooms give 83 a task from "
              "its one test scene; 100 test scenes of real size, each with its difficulties balanced "
              "(episodes.difficulty.balance), would fill the 600.", ""]
    return "\n".join(L)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", default="/tmp/navarena_sim")
    ap.add_argument("--sizes", default="500,2000")
    ap.add_argument("--data", default=str(PROJECT / "data"), help="the default dataset's root (make dataset): the "
                                                                  "reference of bytes per episode")
    ap.add_argument("--out", default="/tmp/navarena_release_bench")
    ap.add_argument("--reports", default=str(PROJECT / "data" / "08_reports"))
    ap.add_argument("--docs", action="store_true")
    a = ap.parse_args(argv)
    sizes = [int(x) for x in a.sizes.split(",")]
    logs = Path(a.reports) / "logs"
    ref = one_size(Path(a.data), None, Path(a.out), logs)
    rep = {"machine": machine(), "root": a.root, "reference": ref,
           "sizes": [one_size(Path(a.root), n, Path(a.out), logs) for n in sizes]}
    if len(sizes) > 1:
        small, big = rep["sizes"][0], rep["sizes"][-1]
        rep["memory_ratio"] = big["build"]["peak_rss_mb"] / small["build"]["peak_rss_mb"]
        rep["episode_ratio"] = big["episodes"] / small["episodes"]
        rep["projection"] = project(big, small, table_bytes(Path(a.out) / "default"), ref)
    write_report(a.reports, "bench_release.json", rep)
    md = markdown(rep)
    (Path(a.reports) / "bench_release.md").write_text(md)
    if a.docs:
        write_page("bench_release.md", md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
