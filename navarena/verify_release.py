"""`navarena verify-release DIR`: check a downloaded release before trusting it.

    navarena verify-release releases/navarena-v1.0.0 [--sample 200] [--workers 8] [--json report.json]

1. Files: the manifest's own digest (MANIFEST.tsv.sha256), every file of MANIFEST.tsv present with
   its bytes and sha256 (hashed on several threads, with a progress display), no file the manifest
   does not list. The content checks below skip the files found damaged here.
2. Tables: every episodes / trajectories Parquet file has the schema release.json records, its hive
   partition agrees with its rows (task_type, split), and the row counts per task and split equal
   the card's (README.md front matter) and release.json's.
3. Scenes: every episode's scene asset is there (assets/{group}/{scene_id}/ with manifest.json
   and its ROS map).
4. Episodes: a sample (--sample N, 0 = all) re-checked against the shipped maps: start and goal
   valid, the stored geodesic distance within tolerance of a recomputation on the map, the expert
   trajectory collision-free.

Exit 0 only when everything holds; otherwise the report names every file and problem (exit 1). A
file that cannot be read is a problem of that file, never a crash.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections import defaultdict
from concurrent.futures import ThreadPoolExecutor, as_completed
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from navcore.io.release import (
    CARD,
    KEY_COLUMNS,
    MANIFEST,
    MANIFEST_DIGEST,
    RELEASE_JSON,
    read_card_front_matter,
    read_manifest,
    read_manifest_digest,
    schema_fields,
    sha256_file,
    table_keys,
    walk_files,
)

GEODESIC_TOLERANCE = 0.03
"""Relative tolerance of a stored geodesic against its recomputation on the shipped ROS map (the map
is the costmap's occupancy at cell centres, coarser than the clearance the episodes were made on):
the grid path over the map's free cells, pulled taut. On the default release's 1,200 episodes the
recomputation is within 1.7 % (p99 1.1 %); plus GEODESIC_CELLS cells for short episodes."""
GEODESIC_CELLS = 2.0


class Report:
    def __init__(self):
        self.problems: list[dict] = []
        self.checked: dict[str, int] = defaultdict(int)
        self.damaged: set[str] = set()
        """Files whose bytes differ from the manifest: the content checks skip them."""

    def bad(self, kind: str, path: str, what: str) -> None:
        self.problems.append({"check": kind, "file": path, "problem": what})

    @contextmanager
    def reading(self, kind: str, path: str):
        """A check of one file: whatever reading it raises is a problem of that file."""
        try:
            yield
        except Exception as e:  # noqa: BLE001 - a damaged file is a finding to report, never a crash
            self.bad(kind, path, f"unreadable ({type(e).__name__}: {str(e).splitlines()[0][:200] if str(e) else ''})")

    @property
    def ok(self) -> bool:
        return not self.problems


def check_manifest_digest(root: Path, report: Report) -> bool:
    """Whether MANIFEST.tsv matches MANIFEST.tsv.sha256 (releases made before the digest have none:
    True). A digest that cannot be read is reported here."""
    if not (root / MANIFEST_DIGEST).is_file():
        return True
    try:
        want = read_manifest_digest(root / MANIFEST_DIGEST)
    except (OSError, ValueError) as e:
        report.bad("files", MANIFEST_DIGEST, f"cannot be read: {e}")
        return True
    report.checked["files"] += 1
    return sha256_file(root / MANIFEST) == want


def check_files(root: Path, report: Report, workers: int, quiet: bool) -> dict[str, tuple[int, str]]:
    from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TimeRemainingColumn, TransferSpeedColumn

    digest_ok = check_manifest_digest(root, report)
    try:
        manifest = read_manifest(root / MANIFEST)
    except (OSError, ValueError) as e:
        report.bad("files", MANIFEST, f"cannot be read: {e}")
        report.damaged.add(MANIFEST)
        return {}
    on_disk = set(walk_files(root)) - {MANIFEST, MANIFEST_DIGEST}
    for rel in sorted(set(manifest) - on_disk):
        report.bad("files", rel, "missing (listed in MANIFEST.tsv)")
        report.damaged.add(rel)
    for rel in sorted(on_disk - set(manifest)):
        report.bad("files", rel, "unexpected (not in MANIFEST.tsv)")
    todo = []
    for rel in sorted(set(manifest) & on_disk):
        size = (root / rel).stat().st_size
        if size != manifest[rel][0]:
            report.bad("files", rel, f"{size} bytes, the manifest says {manifest[rel][0]} (truncated or replaced)")
            report.damaged.add(rel)
        else:
            todo.append(rel)
    total = sum(manifest[r][0] for r in todo)
    with Progress(TextColumn("verify-release sha256"), BarColumn(), DownloadColumn(), TransferSpeedColumn(),
                  TimeRemainingColumn(), disable=quiet) as progress:
        bar = progress.add_task("hash", total=total)
        with ThreadPoolExecutor(workers) as pool:
            futures = {pool.submit(sha256_file, root / rel): rel for rel in todo}
            for fut in as_completed(futures):
                rel = futures[fut]
                try:
                    digest = fut.result()
                except OSError as e:
                    report.bad("files", rel, f"cannot be read: {e}")
                    digest = None
                if digest != manifest[rel][1]:
                    if digest is not None:
                        report.bad("files", rel, "sha256 differs from the manifest (the bytes changed)")
                    report.damaged.add(rel)
                progress.advance(bar, manifest[rel][0])
    if not digest_ok:  # every file agreeing with the manifest points at the digest file
        files_ok = not any(p["check"] == "files" for p in report.problems)
        report.bad("files", MANIFEST_DIGEST if files_ok else MANIFEST,
                   f"{MANIFEST}'s sha256 differs from {MANIFEST_DIGEST}: " +
                   ("every file matches the manifest, so the digest file is the damaged one" if files_ok else
                    "the manifest is damaged (or replaced), so the findings above may name good files"))
    report.checked["files"] += len(manifest)
    return manifest


def _check_table(path: Path, name: str, kind: str, expected: dict, report: Report, counts: dict, files: dict) -> None:
    import pyarrow.parquet as pq

    keys = table_keys(name)
    if keys is None:
        report.bad("tables", name, f"not a {kind} file of the layout {kind}/<task>/<split>/<scene_id>.parquet")
        return
    schema = pq.read_schema(path)
    meta = pq.read_metadata(path)
    got = [tuple(f) for f in schema_fields(schema)]
    if got != expected.get(kind):
        diff = sorted(set(got) ^ set(expected.get(kind, [])))[:4]
        report.bad("tables", name, f"schema differs from release.json's {kind} schema (e.g. {diff})")
        return
    report.checked[f"{kind} files"] += 1
    checks = {**{c: c for c in KEY_COLUMNS}, **({"task_type": "task"} if kind == "episodes" else {})}
    t = pq.read_table(path, columns=list(checks))
    for col, key in checks.items():  # the key columns (and an episode's task_type) must say what the path says
        wrong = {str(v) for v in t[col].to_pylist()} - {keys[key]}
        if wrong:
            report.bad("tables", name, f"rows of {col} {sorted(wrong)[:3]} in the file of {key} {keys[key]!r}")
    if kind == "episodes":
        counts[(keys["task"], keys["split"])] += meta.num_rows
        files[(keys["task"], keys["split"])].append(name)


def check_tables(root: Path, info: dict, report: Report) -> dict[tuple[str, str], list[str]]:
    """Schemas, partitions and counts; returns {(task, split): episode files}."""

    try:
        expected = {k: [tuple(f) for f in v] for k, v in info["schemas"].items()}
    except (KeyError, TypeError, AttributeError) as e:
        report.bad("tables", RELEASE_JSON, f"no table schemas ({type(e).__name__}: {e})")
        return {}
    counts: dict[tuple[str, str], int] = defaultdict(int)
    files: dict[tuple[str, str], list[str]] = defaultdict(list)
    for kind in ("episodes", "trajectories"):
        folder = root / kind
        for rel in (walk_files(folder) if folder.is_dir() else []):
            name = f"{kind}/{rel}"
            if name in report.damaged:
                continue
            with report.reading("tables", name):
                _check_table(folder / rel, name, kind, expected, report, counts, files)
    card = {}
    if CARD not in report.damaged:
        try:
            fm = read_card_front_matter(root / CARD)
            card = {(c["config_name"], s["name"]): s["num_examples"] for c in fm.get("dataset_info", [])
                    for s in c["splits"]}
        except Exception as e:  # noqa: BLE001 - YAML, types, keys: a damaged card is a finding
            report.bad("tables", CARD, f"front matter unreadable ({type(e).__name__}: {e})")
    try:
        recorded = {(t, sp): n for t, s in info.get("counts", {}).items() for sp, n in s.items()}
    except (AttributeError, TypeError):
        report.bad("tables", RELEASE_JSON, "its counts are not {task: {split: n}}")
        recorded = {}
    for key in sorted(set(counts) | set(card) | set(recorded), key=str):
        n, c, r = counts.get(key, 0), card.get(key), recorded.get(key)
        if c != n or r != n:
            report.bad("tables", f"episodes/{key[0]}/{key[1]}",
                       f"{n} episodes in the files, the card says {c}, release.json {r}")
    return files


def check_assets(root: Path, files: dict, report: Report) -> None:
    import pyarrow.parquet as pq

    seen = set()
    for names in files.values():
        for name in names:
            scene_paths = []
            with report.reading("scenes", name):
                scene_paths = set(pq.read_table(root / name, columns=["scene_path"])["scene_path"].to_pylist())
            for sp in scene_paths:
                if sp in seen:
                    continue
                seen.add(sp)
                asset = root / "assets" / sp
                missing = [f for f in ("manifest.json", "nav_map.yaml", "nav_map.pgm") if not (asset / f).is_file()]
                if missing:
                    report.bad("scenes", name, f"scene asset assets/{sp} lacks {', '.join(missing)}")
    report.checked["scene assets"] = len(seen)


def corners_free(occ: np.ndarray, origin, res: float, xy: np.ndarray) -> np.ndarray:
    """Whether each point has a free cell centre among the four around it: a pose valid on the
    costmap the episodes were made on always has one (its clearance interpolates between them), so
    a pose without any lies in an obstacle on the shipped map."""
    u = (xy[:, 0] - origin[0]) / res - 0.5
    v = (xy[:, 1] - origin[1]) / res - 0.5
    j0, i0 = np.floor(u).astype(int), np.floor(v).astype(int)
    ny, nx = occ.shape
    ok = np.zeros(len(xy), bool)
    for di in (0, 1):
        for dj in (0, 1):
            i, j = i0 + di, j0 + dj
            inside = (i >= 0) & (i < ny) & (j >= 0) & (j < nx)
            ok[inside] |= ~occ[i[inside], j[inside]]
    return ok


DEFAULT_NEIGHBOURHOOD = 6
"""The geodesic graph's neighbourhood where release.json does not say (the episodes stage's default)."""


class SceneMap:
    """A released scene's ROS map with a geodesic graph over its free cells (built on first use)."""

    def __init__(self, asset: Path, radius: float | None = None, neighbourhood: int = DEFAULT_NEIGHBOURHOOD):
        """radius: the embodiment's (release.json's config; None where it does not say), for the
        upper bound of check_geodesic; neighbourhood: the episodes' geodesic graph's."""
        from navcore.io.asset_files import read_nav_map

        self.occ, self.origin, self.res = read_nav_map(asset)
        self.radius, self.neighbourhood = radius, neighbourhood
        self._graphs: dict[str, object] = {}

    def graph(self, kind: str = "cells"):
        """The graph over the map's free cells with motions judged cell by cell (kind "cells":
        Costmap.from_occupancy) or on a clearance rebuilt with the robot's radius ("radius":
        Costmap.from_inflated_map)."""
        if kind not in self._graphs:
            from navcore.nav.costmap import Costmap
            from navcore.nav.geodesic import NavGraph

            cm = Costmap.from_occupancy(self.occ, self.origin, self.res) if kind == "cells" else \
                Costmap.from_inflated_map(self.occ, self.origin, self.res, self.radius)
            self._graphs[kind] = NavGraph(cm, ~self.occ, self.neighbourhood)
        return self._graphs[kind]

    def check_geodesic(self, start, goals: list, stored: float) -> str | None:
        """What is wrong with an episode's stored geodesic, or None. A binary map holds less than the
        clearance the episodes were planned on, so it bounds their geodesic from both sides: cell by
        cell it lets a motion through a pinch the robot does not fit (the shortest the map allows),
        and the clearance rebuilt from it with the robot's radius refuses some passages the stored
        one allowed (the longest; inf where it disconnects). On the 500-scene simulation's release,
        3 of 3,004 episodes were longer than cell by cell allows, and 8 longer than the rebuilt
        clearance allows, none outside both."""
        tol = GEODESIC_TOLERANCE * stored + GEODESIC_CELLS * self.res
        low = self.geodesic(start, goals)
        if abs(low - stored) <= tol:
            return None
        if stored < low - tol or self.radius is None:
            return f"stored geodesic {stored:.3f} m, recomputed on the map {low:.3f} m (tolerance {tol:.3f} m)"
        high = self.geodesic(start, goals, "radius")
        if stored <= high + tol:
            return None
        return (f"stored geodesic {stored:.3f} m, recomputed on the map {low:.3f} m cell by cell and {high:.3f} m with "
                f"the robot's radius (tolerance {tol:.3f} m)")

    def nearest_free(self, xy) -> tuple[int, int] | None:
        """The free cell centre nearest to xy among the 3 x 3 around its cell."""
        j = int(math.floor((xy[0] - self.origin[0]) / self.res))
        i = int(math.floor((xy[1] - self.origin[1]) / self.res))
        best = None
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                a, b = i + di, j + dj
                if 0 <= a < self.occ.shape[0] and 0 <= b < self.occ.shape[1] and not self.occ[a, b]:
                    c = (self.origin[0] + (b + 0.5) * self.res, self.origin[1] + (a + 0.5) * self.res)
                    d = math.hypot(c[0] - xy[0], c[1] - xy[1])
                    if best is None or d < best[0]:
                        best = (d, (a, b))
        return None if best is None else best[1]

    def geodesic(self, start, goals: list, kind: str = "cells") -> float:
        s = self.nearest_free(start)
        cells = [c for c in (self.nearest_free(g) for g in goals) if c is not None]
        if s is None or not cells:
            return math.inf
        from navcore.nav.geodesic import taut_path

        field = self.graph(kind).field(np.asarray(sorted(set(cells))))
        if not np.isfinite(field.at_cells(np.asarray([s]))[0]):
            return math.inf
        # the grid path pulled taut on the map, from the episode's own start and to its nearest goal
        # where the step to them is valid on the map (a grid path bends at cell centres: up to 1.5 %
        # too long)
        path = field.path_xy(s)
        cm = self.graph(kind).costmap
        a = np.asarray(start, float)
        g = np.asarray(min(goals, key=lambda p: math.hypot(p[0] - path[-1][0], p[1] - path[-1][1])), float)
        if cm.is_motion_valid(*a, *path[0]):
            path = np.vstack([a, path])
        if cm.is_motion_valid(*path[-1], *g):
            path = np.vstack([path, g])
        taut = taut_path(cm, path) if len(path) > 2 else path
        return float(np.linalg.norm(np.diff(taut, axis=0), axis=1).sum())


def goal_points(row: dict) -> list:
    if row["goal_type"] == "object":
        return [v["position"][:2] for g in json.loads(row["goals_json"]) for v in g.get("view_points", [])]
    return [(row["goal_position_x"], row["goal_position_y"])]


def map_settings(info: dict) -> tuple[float | None, int]:
    """(the embodiment's radius, the geodesic graph's neighbourhood) of the release's resolved config
    (release.json); (None, DEFAULT_NEIGHBOURHOOD) where it does not say (an older or damaged release.json)."""
    cfg = info.get("config") if isinstance(info.get("config"), dict) else {}
    emb, eps = cfg.get("embodiment"), cfg.get("episodes")
    radius = emb.get("radius") if isinstance(emb, dict) else None
    hood = eps.get("geodesic_neighbourhood") if isinstance(eps, dict) else None
    ok = isinstance(radius, (int, float)) and not isinstance(radius, bool) and 0 < radius < 10
    hood_ok = isinstance(hood, int) and not isinstance(hood, bool) and 0 < hood <= 32
    return (float(radius) if ok else None), (hood if hood_ok else DEFAULT_NEIGHBOURHOOD)


def check_episodes(root: Path, files: dict, sample: int, seed: int, report: Report,
                   settings: tuple[float | None, int]) -> None:
    """Re-check `sample` episodes (0 = all), drawn evenly over the episode files; files and scene
    maps already found damaged are skipped (their damage is reported). settings: map_settings."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    names = sorted(n for ns in files.values() for n in ns)
    rows = []
    for name in names:
        with report.reading("episodes", name):
            rows += [(name, e) for e in pq.read_table(root / name, columns=["episode_id"])["episode_id"].to_pylist()]
    if sample and len(rows) > sample:
        pick = np.random.default_rng(seed).choice(len(rows), sample, replace=False)
        rows = [rows[k] for k in sorted(pick)]
    by_file: dict[str, list[str]] = defaultdict(list)
    for name, e in rows:
        by_file[name].append(e)
    maps: dict[str, SceneMap | None] = {}
    for name, ids in by_file.items():
        ep, tr = [], None
        with report.reading("episodes", name):
            t = pq.read_table(root / name)
            ep = t.filter(pc.is_in(t["episode_id"], value_set=pa.array(ids))).to_pylist()
        tr_name = name.replace("episodes/", "trajectories/", 1)
        if tr_name not in report.damaged and (root / tr_name).is_file():
            with report.reading("episodes", tr_name):
                tr = pq.read_table(root / tr_name, columns=["episode_id", "position_x", "position_y"])
        for row in ep:
            where = f"{name} episode {row['episode_id']}"
            sp = row["scene_path"]
            if sp not in maps:
                maps[sp] = None
                asset = f"assets/{sp}"
                if not any(d.startswith(asset + "/") for d in report.damaged):  # else reported already
                    with report.reading("episodes", f"{asset}/nav_map.*"):
                        maps[sp] = SceneMap(root / "assets" / sp, *settings)
            if maps[sp] is None:
                continue
            with report.reading("episodes", where):
                _check_episode(row, maps[sp], tr, tr_name, name in report.damaged or tr_name in report.damaged,
                               where, report)


def _check_episode(row: dict, sm: "SceneMap", tr, tr_name: str, tr_damaged: bool, where: str, report: Report) -> None:
    import pyarrow.compute as pc

    start = np.array([[row["start_position_x"], row["start_position_y"]]])
    goals = goal_points(row)
    if not corners_free(sm.occ, sm.origin, sm.res, start)[0]:
        report.bad("episodes", where, f"start ({start[0][0]:.3f}, {start[0][1]:.3f}) lies in an obstacle of the map")
    if not goals or not corners_free(sm.occ, sm.origin, sm.res, np.asarray(goals, float)).any():
        report.bad("episodes", where, "no goal position lies in free space of the map")
    problem = sm.check_geodesic(start[0], goals, float(row["geodesic_distance"]))
    if problem:
        report.bad("episodes", where, problem)
    if tr is None:
        if not tr_damaged:
            report.bad("episodes", where, f"no trajectory file {tr_name}")
    else:
        mine = tr.filter(pc.equal(tr["episode_id"], row["episode_id"]))
        xy = np.stack([mine["position_x"].to_numpy(), mine["position_y"].to_numpy()], 1).astype(float)
        if len(xy) != row["num_steps"]:
            report.bad("episodes", where, f"{len(xy)} trajectory rows, num_steps says {row['num_steps']}")
        bad = np.flatnonzero(~corners_free(sm.occ, sm.origin, sm.res, xy)) if len(xy) else []
        if len(bad):
            report.bad("episodes", where, f"expert trajectory in collision at {len(bad)} step(s), first at step {bad[0]}")
    report.checked["episodes re-checked"] += 1


def verify(root: Path, sample: int = 200, workers: int = 0, seed: int = 0, quiet: bool = False) -> Report:
    root = Path(root)
    report = Report()
    for required in (MANIFEST, RELEASE_JSON, CARD):
        if not (root / required).is_file():
            report.bad("files", required, "missing: not a release folder (or an incomplete download)")
    if not report.ok:
        return report
    check_files(root, report, workers or os.cpu_count() or 2, quiet)
    if RELEASE_JSON in report.damaged or MANIFEST in report.damaged:
        return report  # its schemas and counts cannot be trusted: the file checks said what is wrong
    try:
        info = json.loads((root / RELEASE_JSON).read_text())
        if not isinstance(info, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError) as e:
        report.bad("files", RELEASE_JSON, f"unreadable: {e}")
        return report
    if info.get("manifest_digest") and not (root / MANIFEST_DIGEST).is_file():
        report.bad("files", MANIFEST_DIGEST, "missing (release.json says the release has it)")
    files = check_tables(root, info, report)
    check_assets(root, files, report)
    check_episodes(root, files, sample, seed, report, map_settings(info))
    return report


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="navarena verify-release", description=__doc__.split("\n\n")[0])
    ap.add_argument("folder")
    ap.add_argument("--sample", type=int, default=200, help="episodes re-checked against the maps (0 = all)")
    ap.add_argument("--workers", type=int, default=0, help="hashing threads (0 = cores)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the episode sample")
    ap.add_argument("--json", help="also write the report here")
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args(argv)
    report = verify(Path(a.folder), a.sample, a.workers, a.seed, a.quiet)
    if a.json:
        Path(a.json).write_text(json.dumps({"ok": report.ok, "checked": report.checked, "problems": report.problems},
                                           indent=1))
    checked = ", ".join(f"{v:,} {k}" for k, v in report.checked.items())
    if report.ok:
        print(f"verify-release: OK ({checked})")
        return 0
    print(f"verify-release: {len(report.problems)} problem(s) in {a.folder} (checked {checked}):", file=sys.stderr)
    for p in report.problems:
        print(f"  [{p['check']}] {p['file']}: {p['problem']}", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
