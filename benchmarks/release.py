"""The release at scale (issue 45): `navarena release` and `navarena verify-release` on the
2,000-scene simulation's data root, and the projection to the 22 M-episode release.

    python -m benchmarks.release [--root /tmp/navarena_sim] [--sizes 500,2000] [--docs]

The data root is `python -m benchmarks.bench_scale sim`'s (its overrides, `SIM`, are repeated so
that the release finds every stage done). For each size (the first n generated scenes,
scenes.count=n) a release is built in a subprocess whose peak RSS is polled: the build streams scene
by scene, so its memory must not grow with the number of episodes; then verify-release hashes the
whole folder and re-checks 200 episodes against the maps. Writes data/08_reports/bench_release.{json,md}
and, with --docs, docs/bench_release.md.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

from benchmarks import machine, write_report
from benchmarks.bench_scale import RELEASE, RELEASE_SCENES, SIM
from benchmarks.pages import write_page

PROJECT = Path(__file__).resolve().parent.parent
RELEASE_EPISODES = RELEASE_SCENES * sum(RELEASE.values())


def polled(cmd: list[str], log: Path) -> dict:
    """Run cmd; wall seconds, peak RSS of the process (polled every 0.2 s), exit code."""
    import psutil

    log.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with open(log, "w") as f:
        p = subprocess.Popen(cmd, cwd=PROJECT, stdout=f, stderr=subprocess.STDOUT)
        proc, peak = psutil.Process(p.pid), 0
        while p.poll() is None:
            try:
                peak = max(peak, proc.memory_info().rss)
            except psutil.Error:
                pass
            time.sleep(0.2)
    return {"wall_s": round(time.perf_counter() - t0, 2), "peak_rss_mb": round(peak / 2**20, 1), "exit": p.returncode}


def folder_bytes(manifest: Path) -> dict:
    rows = [line.split("\t") for line in manifest.read_text().splitlines()[1:]]
    by = {}
    for path, size, _ in rows:
        top = path.split("/")[0] if "/" in path else "(top level)"
        by[top] = by.get(top, 0) + int(size)
    return {"files": len(rows) + 1, "bytes": sum(int(r[1]) for r in rows), "by_folder": dict(sorted(by.items()))}


def one_size(root: Path, n: int, out: Path, logs: Path) -> dict:
    folder = out / f"sim-{n}"
    shutil.rmtree(folder, ignore_errors=True)
    build = polled([sys.executable, "-m", "pipeline", "release", "--root", str(root), "--out", str(folder),
                    "--version", "1.0.0", *SIM, f"scenes.count={n}"], logs / f"release_{n}.log")
    if build["exit"]:
        raise SystemExit(f"release of {n} scenes failed; see {logs / f'release_{n}.log'}")
    verify = polled([sys.executable, "-m", "pipeline", "verify-release", str(folder), "--quiet",
                     "--json", str(logs / f"verify_{n}.json")], logs / f"verify_{n}.log")
    info = json.loads((folder / "release.json").read_text())
    size = folder_bytes(folder / "MANIFEST.tsv")
    eps = sum(n_ for t, s in info["counts"].items() for sp, n_ in s.items() if sp != info["eval_set"]["name"])
    return {"scenes": n, "episodes": eps, "build": build, "verify": verify,
            "verify_ok": json.loads((logs / f"verify_{n}.json").read_text())["ok"], **size,
            "eval_set": {t: r["selected"] for t, r in info["eval_set"]["per_task"].items()}}


def project(big: dict, small: dict) -> dict:
    """The 22 M-episode release from the measured slopes (seconds per scene and per byte)."""
    per_scene_build = (big["build"]["wall_s"] - small["build"]["wall_s"]) / (big["scenes"] - small["scenes"])
    per_scene_verify = (big["verify"]["wall_s"] - small["verify"]["wall_s"]) / (big["scenes"] - small["scenes"])
    episode_bytes = sum(v for k, v in big["by_folder"].items() if k in ("episodes", "trajectories")) / big["episodes"]
    other_per_scene = (big["bytes"] - episode_bytes * big["episodes"]) / big["scenes"]
    files_per_scene = big["files"] / big["scenes"]
    hash_rate = big["bytes"] / max(big["verify"]["wall_s"], 1e-9)  # bytes/s of verify (I/O and sha256 bound)
    rel_bytes = episode_bytes * RELEASE_EPISODES + other_per_scene * RELEASE_SCENES
    return {"episodes": RELEASE_EPISODES, "scenes": RELEASE_SCENES,
            "bytes_per_episode": round(episode_bytes, 1), "episode_bytes": round(episode_bytes * RELEASE_EPISODES),
            "note": ("the simulation's scenes are small rooms with a handful of episodes: the projection scales its "
                     "per-episode bytes to the release density and keeps its per-scene overhead; a real scene's "
                     "asset (its aligned model) is far larger, see bench_scale's storage table"),
            "files": round(files_per_scene * RELEASE_SCENES), "build_s_per_scene": round(per_scene_build, 4),
            "verify_s_per_scene": round(per_scene_verify, 4), "hash_mb_per_s": round(hash_rate / 1e6, 1),
            "episode_bytes_hash_hours": round(episode_bytes * RELEASE_EPISODES / hash_rate / 3600, 2),
            "release_bytes_without_models": round(rel_bytes)}


def markdown(r: dict) -> str:
    L = [f"# bench-release: the release at scale ({r['machine']})", "",
         "`navarena release` on the 2,000-scene simulation's data root (`python -m benchmarks.bench_scale sim`: "
         "one small room a scene, 4 PointNav + 2 ImageNav episodes; 10 % of the scenes held out), the first n "
         "scenes, then `navarena verify-release` (every file re-hashed, 200 episodes re-checked against the maps). "
         "Wall time on this machine, peak RSS of the command's process (polled).", "",
         "| scenes | episodes | files | MB | build (s) | build peak RSS (MB) | verify (s) | verify peak RSS (MB) | verified "
         "| eval set per task |",
         "|---|---|---|---|---|---|---|---|---|---|"]
    for s in r["sizes"]:
        L.append(f"| {s['scenes']:,} | {s['episodes']:,} | {s['files']:,} | {s['bytes'] / 1e6:,.1f} | "
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
              f"{p['episodes']:,} episodes in {p['scenes']:,} scenes (bench_scale's release density): about "
              f"{p['files']:,} files; episode and trajectory tables {p['episode_bytes'] / 1e9:,.1f} GB at "
              f"{p['bytes_per_episode']:,.0f} bytes an episode; the build at {p['build_s_per_scene']:.3f} s a scene "
              f"of linking and reading plus hashing, verify-release at {p['hash_mb_per_s']:,.0f} MB/s: "
              f"{p['episode_bytes_hash_hours']:.2f} h for the tables on this machine. {p['note']}.", ""]
    return "\n".join(L)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", default="/tmp/navarena_sim")
    ap.add_argument("--sizes", default="500,2000")
    ap.add_argument("--out", default="/tmp/navarena_release_bench")
    ap.add_argument("--reports", default=str(PROJECT / "data" / "08_reports"))
    ap.add_argument("--docs", action="store_true")
    a = ap.parse_args(argv)
    sizes = [int(x) for x in a.sizes.split(",")]
    logs = Path(a.reports) / "logs"
    rep = {"machine": machine(), "root": a.root, "sizes": [one_size(Path(a.root), n, Path(a.out), logs) for n in sizes]}
    if len(sizes) > 1:
        small, big = rep["sizes"][0], rep["sizes"][-1]
        rep["memory_ratio"] = big["build"]["peak_rss_mb"] / small["build"]["peak_rss_mb"]
        rep["episode_ratio"] = big["episodes"] / small["episodes"]
        rep["projection"] = project(big, small)
    write_report(a.reports, "bench_release.json", rep)
    md = markdown(rep)
    (Path(a.reports) / "bench_release.md").write_text(md)
    if a.docs:
        write_page("bench_release.md", md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
