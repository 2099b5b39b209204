"""The files outside the data root that a scene's outputs were made from, and whether they still are.

A real scene's outputs come from its source (the file, or every file of a folder layout: a SOG
folder, a streamed LOD scene, an .npy folder) and, from the semantics stage on, from the label
files its catalog entry names (`labels.classes` / `mesh_classes` given as files, `labels.mesh` and
the side files its reader takes). Every marker of a stage at or after the one that reads them
records them as {path: [bytes, mtime_ns, sha256]} (`record`), hashed once before the stage runs
and checked again after it (a file that changed while it was read fails the task).

Before a marker is trusted (`problem`), its files are checked: by default a stat each (bytes and
mtime as recorded: unchanged; otherwise the file is hashed, and the same sha256, a file touched
or copied back, is unchanged too); with `verify=checksum` every file is hashed (once per process
and file version). A file replaced with other bytes, truncated, deleted, added to or removed from
a folder layout makes the marker stale: that stage of that scene is recomputed, and so is every
later stage of the scene (their markers record the same file) and nothing else; the run summary
names the file with its old and new sha256. Markers written before sources were recorded carry
none and are trusted as before (the canonical store still refuses a source whose Gaussians
changed, see navcore.gaussians.store)."""
from __future__ import annotations

import contextlib
import os
from pathlib import Path

from navcore.gaussians.formats import source_files
from navcore.io.release import sha256_file
from pipeline.graph import downstream

_SHA: dict[tuple, str] = {}
_LISTED: dict[str, list[str]] | None = None
"""While a run's client checks its tasks (`one_listing_a_run`): the files of each folder-layout
source, listed once (a finished run's resume checks every (stage, scene): one listing a scene, not
one a stage). Elsewhere (a worker that serves many runs) every call lists afresh."""


@contextlib.contextmanager
def one_listing_a_run():
    global _LISTED
    _LISTED = {}
    try:
        yield
    finally:
        _LISTED = None


def sha256_of(path: str | Path, st: os.stat_result | None = None) -> str:
    """sha256 of a file, computed once per process and file version (path, bytes, mtime, ctime,
    inode: ctime changes with any write, even one that restores the mtime)."""
    st = st or os.stat(path)
    key = (str(path), st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino)
    if key not in _SHA:
        _SHA[key] = sha256_file(path)
    return _SHA[key]


def label_files(spec) -> list[Path]:
    """The files a catalog entry's labels (navcore.labels.shipped.LabelSpec) are read from: class
    tables given as files, the labelled mesh and the side files its reader takes (ScanNet segs /
    aggregation json, Replica's info_semantic.json); those that exist, sorted."""
    from navcore.labels import BUILTIN
    from navcore.labels.mesh import side_files

    out = [spec.path(t) for t in (spec.classes, spec.mesh_classes) if t and t not in BUILTIN]
    if spec.mesh:
        out += [spec.path(spec.mesh), *side_files(spec.path(spec.mesh))]
    return sorted({p.resolve() for p in out if p.is_file()})


def files(stage: str, scene) -> list[str]:
    """The outside files a (stage, scene)'s outputs depend on (absolute paths, sorted)."""
    out: list[Path] = []
    if not scene.synthetic and stage in downstream("ingest"):
        path = Path(scene.path)
        listed = None if _LISTED is None else _LISTED.get(str(path))
        if listed is None:
            listed = [str(p) for p in source_files(path)[1]] if path.exists() else [str(path)]
            if _LISTED is not None and path.exists():
                _LISTED[str(path)] = listed
        out += [Path(p) for p in listed]
    if scene.labels is not None and stage in downstream("semantics"):
        out += label_files(scene.labels)
    return sorted({str(Path(p).absolute()) for p in out})


def record(paths: list[str], verify: str = "size", known: dict | None = None) -> dict[str, list]:
    """{path: [bytes, mtime_ns, sha256]} of the files now. `known`: records of the same files made
    earlier in the run (the upstream markers'): a file whose bytes and mtime match one is not
    hashed again unless verify=checksum. A missing file is left out (the stage reading it fails
    naming it); another OSError (a file that cannot be read) is raised."""
    out = {}
    for p in paths:
        try:
            st = os.stat(p)
        except FileNotFoundError:  # the stage that reads it fails with its own message (file not found)
            continue
        k = (known or {}).get(p)
        if verify != "checksum" and k and k[0] == st.st_size and k[1] == st.st_mtime_ns:
            out[p] = [st.st_size, st.st_mtime_ns, k[2]]
        else:
            out[p] = [st.st_size, st.st_mtime_ns, sha256_of(p, st)]
    return out


def problem(recorded: dict | None, now: list[str], verify: str = "size") -> dict | None:
    """Why a marker's recorded outside files are no longer what its outputs were made from (the
    first found): {"file", "old_sha256", "new_sha256" (None: gone), "message"}; None when they are
    (or the marker records none, or verify=none)."""
    if recorded is None or verify == "none":
        return None
    for p, (size, mtime, digest) in sorted(recorded.items()):
        gone = {"file": p, "old_sha256": digest, "new_sha256": None}
        try:
            st = os.stat(p)
        except FileNotFoundError:
            return {**gone, "message": f"{p} was deleted since the last run (it had sha256 {digest[:16]})"}
        except OSError as e:
            return {**gone, "message": f"{p} cannot be read ({e.strerror}); it had sha256 {digest[:16]}"}
        if verify == "checksum" or st.st_size != size or st.st_mtime_ns != mtime:
            try:
                new = sha256_of(p, st)
            except OSError as e:
                return {**gone, "message": f"{p} cannot be read ({e.strerror}); it had sha256 {digest[:16]}"}
            if new != digest:
                return {"file": p, "old_sha256": digest, "new_sha256": new,
                        "message": f"{p} changed since the last run: sha256 {digest[:16]} -> {new[:16]}, "
                                   f"{size} -> {st.st_size} bytes"}
        if p not in now:
            return {**gone, "message": f"{p} is no longer one of the scene's files (the catalog entry changed)"}
    for p in sorted(set(now) - set(recorded)):
        return {"file": p, "old_sha256": None, "new_sha256": None,
                "message": f"{p} was added to the scene's files since the last run"}
    return None


def restat(recorded: dict) -> dict | None:
    """A record whose files `problem` found unchanged, with the bytes and mtime they have now, when
    any differs (a file touched or copied back): written into the marker so that later runs need a
    stat again, not a hash; None when nothing differs."""
    now = {}
    for p, (size, mtime, digest) in recorded.items():
        try:
            st = os.stat(p)
        except OSError:
            return None
        now[p] = [st.st_size, st.st_mtime_ns, digest]
    return now if now != recorded else None
