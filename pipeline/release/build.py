"""Assemble a release folder from a finished data root, without recomputing anything.

Scene by scene (memory does not grow with the number of episodes: one scene's tables at a time,
statistics kept as sums and fixed-bin histograms): episodes and trajectories partitioned by task,
split and scene (episode files written without the split column their folder names, so that
pandas and pyarrow read the folder as one table; a scene's trajectory file hard linked when it holds
one split, else split into one file a split), the zero-shot evaluation set as its own split, ObjectNav instance tables, ImageNav goal
images, the V1 scene assets and the NavArena navigation layout (hard links). Then the scene table,
plots, release.json, the dataset card, croissant.json, and last MANIFEST.tsv (and its own digest) with every file's
sha256 (hashed on several threads). The folder is written under a temporary name and renamed when
complete: a killed build leaves no half release.
"""
from __future__ import annotations

import datetime as dt
import hashlib
import json
import os
import shutil
import subprocess
from collections import defaultdict
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from omegaconf import OmegaConf

from navcore.io import jsonio
from navcore.io.atomic import atomic_path
from navcore.io.licences import PROJECT_LICENSE, redistributable
from navcore.io.release import (
    CARD,
    KEY_COLUMNS,
    MANIFEST,
    MANIFEST_DIGEST,
    NOTES,
    RELEASE_JSON,
    SCENES,
    episodes_file,
    parse_version,
    read_manifest,
    read_release_json,
    release_episode_schema,
    release_trajectory_schema,
    schema_fields,
    sha256_file,
    trajectories_file,
    walk_files,
    with_keys,
    write_manifest,
)
from navcore.io.stamps import build_time
from navcore.nav.eval_set import build_listing
from pipeline.graph import DEFAULT_STAGES, closure, config_hashes
from pipeline.markers import read_marker
from pipeline.release.stats import Stats
from pipeline.tasks import current

PROJECT_ROOT = Path(__file__).resolve().parents[2]


class ReleaseError(RuntimeError):
    """The data root cannot be released as asked (the message names every scene and stage)."""


def code_version() -> dict:
    """The code that builds the release: the package version and, in a git checkout, the commit and
    whether tracked files had uncommitted changes."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        pkg = version("navarena")
    except PackageNotFoundError:
        pkg = None
    out = {"package": pkg, "commit": None, "dirty": None}
    try:
        out["commit"] = subprocess.run(["git", "rev-parse", "HEAD"], cwd=PROJECT_ROOT, capture_output=True, text=True,
                                       check=True).stdout.strip()
        out["dirty"] = bool(subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=PROJECT_ROOT,
                                           capture_output=True, text=True, check=True).stdout.strip())
    except (OSError, subprocess.CalledProcessError):
        pass
    return out


def not_done(cfg, catalog, scenes) -> list[str]:
    """Why each selected (scene, stage) of the default graph is not finished with this config."""
    hashes = config_hashes(cfg)
    verify = cfg.get("verify", "size")
    problems = []
    for scene in scenes:
        for st in closure(list(DEFAULT_STAGES)):
            h = hashes.of(st.name, scene)
            if current(st.name, scene, catalog, h, False, verify) is not None:
                continue
            m = read_marker(catalog.path("markers", scene, stage=st.name))
            why = ("never finished" if m is None else
                   f"made with another config (marker {m.get('config_hash')}, this config {h}): pass the overrides "
                   "the root was made with" if m.get("config_hash") != h else "its outputs changed since its marker")
            problems.append(f"{scene.name} ({scene.scene_id}) stage {st.name}: {why}")
    return problems


def link_or_copy(src: Path, dst: Path, copy: bool = False) -> str:
    """dst as a hard link to src (no second copy of the bytes), a copy where links cannot be made
    or when `copy` (release.copy_files: an independent release)."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    if copy:
        shutil.copyfile(src, dst)
        return "copy"
    try:
        os.link(src, dst)
        return "link"
    except OSError:
        shutil.copyfile(src, dst)
        return "copy"


class Builder:
    """One release build: a temporary folder filled scene by scene (see the module docstring)."""

    def __init__(self, cfg, catalog, tmp: Path, previous: Path | None):
        self.cfg, self.catalog, self.tmp, self.previous = cfg, catalog, tmp, previous
        self.rcfg = cfg.release
        self.links = {"link": 0, "copy": 0, "written": 0}
        self.stats = Stats()
        self.scene_rows: list[dict] = []
        self.scene_files: dict[str, list[str]] = defaultdict(list)

    # -- files -------------------------------------------------------------------------------------
    def link(self, rel: str, src: Path, scene_id: str | None = None) -> None:
        self.links[link_or_copy(Path(src), self.tmp / rel, bool(self.rcfg.copy_files))] += 1
        if scene_id:
            self.scene_files[scene_id].append(rel)

    def write_table(self, rel: str, table: pa.Table, scene_id: str | None = None, **options) -> None:
        p = self.tmp / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, p, **({"compression": "zstd"} | options))
        self.links["written"] += 1
        if scene_id:
            self.scene_files[scene_id].append(rel)

    # -- one scene ---------------------------------------------------------------------------------
    def write_split(self, task: str, split: str, sid: str, episodes: pa.Table, trajectories: pa.Table) -> None:
        """One split's episodes of a (task, scene) and their expert steps (the split's rows of the
        scene's `trajectories`), each file with its KEY_COLUMNS (navcore.io.release)."""
        from navcore.io.episode_schema import TRAJECTORY_WRITE

        self.write_table(episodes_file(task, split, sid), with_keys(episodes, task, split, sid), sid)
        steps = trajectories.filter(pc.is_in(trajectories["episode_id"], value_set=episodes["episode_id"]))
        options = {**TRAJECTORY_WRITE, "use_dictionary": [*TRAJECTORY_WRITE["use_dictionary"], *KEY_COLUMNS]}
        self.write_table(trajectories_file(task, split, sid), with_keys(steps, task, split, sid), sid, **options)

    def add_scene(self, scene, eval_ids: dict[str, set[str]], redistributable: bool = True) -> None:
        cat, sid = self.catalog, scene.scene_id
        counts = {}
        for task, ds in cat.find("episodes", scene).items():
            ep = ds.load()
            tr = cat.dataset("trajectories", scene, task=task).load()
            for split in sorted(set(ep["split"].to_pylist())):
                part = ep.filter(pc.equal(ep["split"], split))
                self.write_split(task, split, sid, part, tr)
                self.stats.add(task, split, scene.group, part)
                counts[f"{task}/{split}"] = part.num_rows
            chosen = eval_ids.get(task)
            if chosen:
                name = self.rcfg.eval_set.name
                part = ep.filter(pc.is_in(ep["episode_id"], value_set=pa.array(sorted(chosen))))
                self.write_split(task, name, sid, part, tr)
                self.stats.add(task, name, scene.group, part, total=False)
                counts[f"{task}/{name}"] = part.num_rows
        inst = cat.dataset("instances", scene)
        if inst.exists():
            self.link(f"instances/scene_id={sid}/instances.parquet", inst.path, sid)
        for task, gi in cat.find("goal_images", scene).items():
            self.link(f"goal_images/task={task}/scene_id={sid}/part-0.parquet", gi.path, sid)
        asset = cat.dataset("asset", scene).path
        for rel in walk_files(asset):
            self.link(f"assets/{scene.group}/{sid}/{rel}", asset / rel, sid)
        export = cat.dataset("export_scene", scene, export_name=self.cfg.export.dataset_name).path
        if export.is_dir():
            for rel in walk_files(export):
                self.link(f"navarena/{scene.group}/{sid}/{rel}", export / rel, sid)
        marker = read_marker(cat.path("markers", scene, stage="episodes")) or {}
        screening = (marker.get("info") or {}).get("screening") or {}
        sem = (read_marker(cat.path("markers", scene, stage="semantics")) or {}).get("info") or {}
        self.scene_rows.append({
            "scene_id": sid, "name": scene.name, "group": scene.group, "format": scene.format,
            "license": scene.license, "redistributable": redistributable, "source_url": scene.source_url, "attribution": scene.attribution,
            "screening_verdict": screening.get("verdict"), "screening_score": screening.get("score"),
            "episodes_kept": screening.get("kept"), "episodes": json.dumps(counts, sort_keys=True),
            "goal_segmenter": sem.get("segmenter"), "goal_instances": sem.get("instances")})

    # -- dataset-level files -----------------------------------------------------------------------
    def navarena_meta(self, created: str) -> None:
        metas = [json.loads((self.tmp / "navarena" / r["group"] / r["scene_id"] / "scene_meta.json").read_text())
                 for r in self.scene_rows if (self.tmp / "navarena" / r["group"] / r["scene_id"] / "scene_meta.json").exists()]
        if not metas:
            return
        from stages.export.stage import FORMAT_VERSION  # the layout's version, defined once

        meta = {"dataset_name": self.rcfg.name, "format_version": FORMAT_VERSION, "created_date": created,
                "updated_date": created, "scene_ids": [m["scene_id"] for m in metas],
                "scene_paths": [m["scene_path"] for m in metas],
                "task_types": sorted({t for m in metas for t in m["task_types"]})}
        (self.tmp / "navarena" / "dataset_meta.json").write_text(jsonio.dumps(meta, indent=1))

    def hash_all(self, skip: set[str] = frozenset()) -> dict[str, tuple[int, str]]:
        files = [f for f in walk_files(self.tmp) if f not in skip]
        workers = int(self.rcfg.workers) or os.cpu_count() or 2

        def one(rel):
            p = self.tmp / rel
            return rel, (p.stat().st_size, sha256_file(p))

        with ThreadPoolExecutor(workers) as pool:  # hashlib releases the GIL on large blocks
            return dict(pool.map(one, files))

    def reuse_previous(self, manifest: dict[str, tuple[int, str]]) -> int:
        """Files whose bytes equal the previous release's at the same path become hard links to it
        (none in a copied release: release.copy_files)."""
        if self.previous is None or self.rcfg.copy_files:
            return 0
        old = read_manifest(self.previous / MANIFEST)
        reused = 0
        for rel, (size, digest) in manifest.items():
            if old.get(rel) == (size, digest) and rel not in (CARD, RELEASE_JSON, NOTES):
                dst = self.tmp / rel
                if os.stat(dst).st_ino == os.stat(self.previous / rel).st_ino:
                    reused += 1
                    continue
                tmp_name = dst.with_name(f".reuse-{dst.name}")
                try:
                    os.link(self.previous / rel, tmp_name)
                    os.replace(tmp_name, dst)
                    reused += 1
                except OSError:
                    tmp_name.unlink(missing_ok=True)
        return reused


def scene_content_hashes(manifest: dict[str, tuple[int, str]], scene_files: dict[str, list[str]]) -> dict[str, str]:
    """Per scene: sha256 over its files' paths and hashes (what release notes compare)."""
    out = {}
    for sid, files in scene_files.items():
        h = hashlib.sha256()
        for rel in sorted(set(files)):
            h.update(f"{rel}\t{manifest[rel][1]}\n".encode())
        out[sid] = h.hexdigest()
    return out


def build_release(cfg, out: Path | None = None, console=None) -> dict:
    """Build the release of cfg's data root and scenes (cfg.release); returns its summary."""
    from rich.console import Console

    from navcore.io.catalog import open_catalog
    from pipeline.release import card, croissant, notes

    console = console or Console()
    t0 = dt.datetime.now(dt.timezone.utc)
    rcfg = cfg.release
    parse_version(rcfg.version)
    catalog, scenes, cat_file = open_catalog(cfg, PROJECT_ROOT)
    if not catalog.root.is_dir():
        raise ReleaseError(f"data root {catalog.root} does not exist")
    out = Path(out or rcfg.out or catalog.path("releases") / f"{rcfg.name}-v{rcfg.version}").resolve()
    previous = Path(rcfg.previous).resolve() if rcfg.previous else None
    if previous is not None:
        if not (previous / RELEASE_JSON).is_file():
            raise ReleaseError(f"release.previous={previous}: not a release folder (no {RELEASE_JSON})")
        prev_version = read_release_json(previous)["version"]
        if parse_version(rcfg.version) <= parse_version(prev_version):
            raise ReleaseError(f"release.version {rcfg.version} is not higher than the previous release's {prev_version}")
    if out == previous:
        raise ReleaseError(f"the release folder {out} is the previous release's")
    if not scenes:
        raise ReleaseError(f"no scenes selected from {cat_file}")
    problems = not_done(cfg, catalog, scenes)
    if problems:
        raise ReleaseError(f"the data root {catalog.root} is not finished for {len({p.split(' stage ')[0] for p in problems})} "
                           f"of {len(scenes)} selected scene(s); run `make dataset` (with the same overrides) first, or "
                           "leave those scenes out (scenes.ids=[...]):\n  " + "\n  ".join(problems))
    extra = tuple(rcfg.extra_licenses)
    included, excluded = [], []
    for s in sorted(scenes, key=lambda s: s.scene_id):
        ok, why = redistributable(s.license, extra)
        if ok or not rcfg.public:
            included.append((s, ok))
        else:
            excluded.append({"scene_id": s.scene_id, "name": s.name, "group": s.group, "license": s.license,
                             "source_url": s.source_url, "reason": why})
    if not included:
        raise ReleaseError(f"every selected scene is left out of a public release ({len(excluded)}: "
                           f"{'; '.join(e['name'] + ': ' + e['reason'] for e in excluded[:5])}); "
                           "release.public=false builds an internal release")
    es = OmegaConf.to_object(rcfg.eval_set)
    chosen, eval_report, eval_table = build_listing(catalog, [s for s, _ in included], es)
    eval_ids: dict[str, dict[str, set[str]]] = defaultdict(dict)
    for (sid, task), g in chosen.groupby(["scene_id", "task"]):
        eval_ids[sid][task] = set(g["episode_id"])
    created = build_time()
    console.print(f"[bold]release[/] {rcfg.name} {rcfg.version}: {len(included)} scene(s) of {len(scenes)} "
                  f"({len(excluded)} left out) from {catalog.root} -> {out}")
    with atomic_path(out) as tmp:
        tmp.mkdir()
        b = Builder(cfg, catalog, tmp, previous)
        for s, ok in included:
            b.add_scene(s, eval_ids.get(s.scene_id, {}), ok)
        eval_dir = tmp / "eval_sets"
        eval_dir.mkdir()
        pq.write_table(eval_table, eval_dir / f"{es.name}.parquet", compression="zstd")
        # the data root gets the same listing, so that `evaluate.split=<name>` runs exactly this set
        catalog.dataset("eval_set", eval_set=es.name).save(eval_table)
        b.navarena_meta(created)
        shutil.copyfile(PROJECT_ROOT / "LICENSE", tmp / "LICENSE")
        plots = b.stats.plots(tmp / "plots")
        data_manifest = b.hash_all()
        content = scene_content_hashes(data_manifest, b.scene_files)
        for row in b.scene_rows:
            row["content_sha256"] = content.get(row["scene_id"])
        scenes_table = pa.Table.from_pylist(b.scene_rows, schema=card.SCENES_SCHEMA)
        pq.write_table(scenes_table, tmp / SCENES, compression="zstd")
        hashes = config_hashes(cfg)
        resolved = OmegaConf.to_container(cfg, resolve=True)
        resolved_text = json.dumps(resolved, sort_keys=True, default=str)
        info = {
            "name": rcfg.name, "version": rcfg.version, "created": created, "public": bool(rcfg.public),
            "code": code_version(),
            "config": resolved, "config_sha256": hashlib.sha256(resolved_text.encode()).hexdigest(),
            "stage_hashes": dict(hashes), "captured_stage_hashes": hashes.captured,
            "catalog": {"file": str(cat_file), "sha256": sha256_file(cat_file), "text": Path(cat_file).read_text()},
            "seeds": {"episodes": int(cfg.episodes.seed), "evaluate": int(cfg.evaluate.seed), "eval_set": int(es.seed),
                      "streams": "each (scene, task) draws from sha256('{seed}:{scene_id}:{task}'): navcore/seeds.py"},
            "scenes": {"included": len(included), "excluded": excluded},
            "counts": b.stats.counts(),
            "eval_set": {"name": es.name, "size": es.size, "proportions": es.proportions,
                         "from_splits": list(es.from_splits), "per_task": eval_report},
            "schemas": {"episodes": schema_fields(release_episode_schema()),
                        "trajectories": schema_fields(release_trajectory_schema())},
            "key_columns": list(KEY_COLUMNS),  # in every episode and trajectory file, equal to its path's
            "previous": None,
            "licence": PROJECT_LICENSE,
            "manifest_digest": MANIFEST_DIGEST,
            "licenses": sorted({s.license for s, _ in included if s.license and " " not in s.license} | {PROJECT_LICENSE}),
        }
        release_notes = None
        if previous is not None:
            prev = read_release_json(previous)
            info["previous"] = {"version": prev["version"], "folder": str(previous)}
            release_notes = notes.release_notes(prev, previous, info, b.scene_rows)
            (tmp / NOTES).write_text(release_notes)
        (tmp / RELEASE_JSON).write_text(jsonio.dumps(info, indent=1, sort_keys=True))
        card.write_card(tmp / CARD, info, b.stats, b.scene_rows, plots, rcfg)
        croissant.write_croissant(tmp, info, b.stats, rcfg)
        manifest = {**data_manifest, **{k: v for k, v in b.hash_all(skip=set(data_manifest)).items()}}
        reused = b.reuse_previous(manifest)
        write_manifest(tmp / MANIFEST, manifest)
        summary = {"folder": str(out), "version": rcfg.version, "scenes": len(included), "excluded": len(excluded),
                   "files": len(manifest) + 2, "bytes": sum(v[0] for v in manifest.values()),
                   "hard_links": b.links["link"], "copies": b.links["copy"], "written": b.links["written"],
                   "reused_from_previous": reused, "episodes": b.stats.total_episodes(),
                   "seconds": round((dt.datetime.now(dt.timezone.utc) - t0).total_seconds(), 2)}
    console.print(f"release written: {out} ({summary['files']} files, {summary['bytes'] / 1e6:.1f} MB, "
                  f"{summary['hard_links']} hard links, {summary['episodes']} episodes)")
    return summary
