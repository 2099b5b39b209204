"""The release folder: its layout, MANIFEST.tsv and release.json, shared by the writer
(`navarena release`, pipeline/release) and the reader (`navarena verify-release`, navarena/).

    README.md                      dataset card (YAML front matter: licence, configs, split sizes)
    MANIFEST.tsv                   path, bytes, sha256 of every other file
    MANIFEST.tsv.sha256            the manifest's own sha256 (`sha256sum -c MANIFEST.tsv.sha256`)
    release.json                   version, code, resolved config and hashes, catalog, seeds, counts, schemas
    croissant.json                 MLCommons Croissant metadata
    LICENSE                        the project's licence
    RELEASE_NOTES.md               what changed since the previous version (with --previous)
    scenes.parquet                 per scene: provenance, licence, screening, content hash, episodes
    plots/*.png                    geodesic distance and steps per task, ObjectNav categories
    episodes/{task}/{split}/{scene_id}.parquet      one row per episode (KEY_COLUMNS + EPISODE_SCHEMA)
    trajectories/{task}/{split}/{scene_id}.parquet  one row per expert step (KEY_COLUMNS + TRAJECTORY_SCHEMA)
    eval_sets/{name}.parquet       the zero-shot evaluation set's listing (also its own split above)
    instances/scene_id={id}/instances.parquet                     ObjectNav instance tables
    goal_images/task=imagenav/scene_id={id}/part-0.parquet        ImageNav goal images (JPEG), when rendered
    assets/{group}/{scene_id}/     NavArena V1 scene assets (manifest.json, aligned model, ROS map nav_map.*)
    navarena/                      the NavArena navigation layout (dataset_meta.json, {group}/{scene_id}/...)
"""
from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path

CARD = "README.md"
MANIFEST = "MANIFEST.tsv"
MANIFEST_DIGEST = "MANIFEST.tsv.sha256"
"""The manifest's own digest, in sha256sum's format: damage to the manifest is named as such."""
RELEASE_JSON = "release.json"
CROISSANT = "croissant.json"
NOTES = "RELEASE_NOTES.md"
SCENES = "scenes.parquet"
MANIFEST_HEADER = "path\tbytes\tsha256"

VERSION = re.compile(r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)")
"""A release version: semantic versioning's MAJOR.MINOR.PATCH."""


def parse_version(v: str) -> tuple[int, int, int]:
    m = VERSION.fullmatch(str(v))
    if not m:
        raise ValueError(f"release version {v!r} is not MAJOR.MINOR.PATCH (e.g. 1.0.0)")
    return tuple(int(x) for x in m.groups())


KEY_COLUMNS = ("task", "split", "scene_id")
"""Columns every episode and trajectory file of a release holds, equal to its path's
`{task}/{split}/{scene_id}`: any reader (pandas, pyarrow, polars, duckdb, `datasets`, which adds no
path columns) gets them from the files themselves. An episode is unique by (task, split, scene_id,
episode_id): episode ids repeat across scenes, and the evaluation set's split repeats test episodes
under its own name; its expert steps join on those four columns. The folders are plain names, not hive `key=value`
partitions: a hive folder beside the same column in the file makes readers disagree on its type."""


def key_fields() -> list:
    """The KEY_COLUMNS' Arrow fields (non-null strings), first in every release table file."""
    import pyarrow as pa

    return [pa.field(k, pa.string(), nullable=False) for k in KEY_COLUMNS]


def with_keys(table, task: str, split: str, scene_id: str):
    """A data root's episode or trajectory table as a release file holds it: its KEY_COLUMNS first."""
    import pyarrow as pa

    table = table.drop_columns([c for c in KEY_COLUMNS if c in table.column_names])
    for i, (field, value) in enumerate(zip(key_fields(), (task, split, scene_id))):
        table = table.add_column(i, field, pa.array([value] * table.num_rows, pa.string()))
    return table


def release_episode_schema():
    """The schema of a release's episode files: KEY_COLUMNS, then EPISODE_SCHEMA less them (its split)."""
    import pyarrow as pa

    from navcore.io.episode_schema import EPISODE_SCHEMA

    return pa.schema(key_fields() + [f for f in EPISODE_SCHEMA if f.name not in KEY_COLUMNS])


def release_trajectory_schema():
    """The schema of a release's trajectory files: KEY_COLUMNS, then TRAJECTORY_SCHEMA."""
    import pyarrow as pa

    from navcore.io.episode_schema import TRAJECTORY_SCHEMA

    return pa.schema(key_fields() + list(TRAJECTORY_SCHEMA))


def episodes_file(task: str, split: str, scene_id: str) -> str:
    return f"episodes/{task}/{split}/{scene_id}.parquet"


def trajectories_file(task: str, split: str, scene_id: str) -> str:
    return f"trajectories/{task}/{split}/{scene_id}.parquet"


def table_keys(rel: str) -> dict[str, str] | None:
    """{task, split, scene_id} of a release table file's path (`episodes/...` or `trajectories/...`,
    relative to the release), None when the path is not one."""
    parts = Path(rel).parts
    if len(parts) != 4 or parts[0] not in ("episodes", "trajectories") or not parts[3].endswith(".parquet"):
        return None
    return {"task": parts[1], "split": parts[2], "scene_id": parts[3][:-len(".parquet")]}


def type_name(t) -> str:
    """A column type as release.json records it (a list's item field name left out: Parquet
    writers name it `element`, pyarrow `item`)."""
    import pyarrow as pa

    if pa.types.is_list(t) or pa.types.is_large_list(t):
        return f"list<{type_name(t.value_type)}>"
    return str(t)


def schema_fields(schema) -> list[list[str]]:
    """[[name, type_name], ...] of a pyarrow schema."""
    return [[f.name, type_name(f.type)] for f in schema]


def sha256_file(path: str | Path, chunk: int = 1 << 22) -> str:
    """sha256 (hex) of a file's bytes, read in chunks: the one file digest of the project (release manifests, shipped
    models and checkpoints, the pipeline's source checks)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def write_manifest(path: Path, rows: dict[str, tuple[int, str]]) -> None:
    """MANIFEST.tsv: a header, then one line per file (relative POSIX path, bytes, sha256), sorted;
    and beside it MANIFEST.tsv.sha256, the manifest's own digest."""
    path = Path(path)
    lines = [MANIFEST_HEADER] + [f"{p}\t{b}\t{h}" for p, (b, h) in sorted(rows.items())]
    path.write_text("\n".join(lines) + "\n")
    path.with_name(path.name + ".sha256").write_text(f"{sha256_file(path)}  {path.name}\n")


def read_manifest_digest(path: Path) -> str:
    """The sha256 recorded in MANIFEST.tsv.sha256; ValueError when it is not one."""
    text = Path(path).read_text(errors="replace").strip()
    m = re.fullmatch(r"([0-9a-f]{64})  " + re.escape(MANIFEST), text)
    if not m:
        raise ValueError(f"{path}: not '<sha256>  {MANIFEST}'")
    return m.group(1)


def read_manifest(path: Path) -> dict[str, tuple[int, str]]:
    """Inverse of write_manifest; a malformed line raises ValueError naming it."""
    text = Path(path).read_text()
    lines = text.splitlines()
    if not lines or lines[0] != MANIFEST_HEADER:
        raise ValueError(f"{path}: the first line is not the header {MANIFEST_HEADER!r}")
    out = {}
    for i, line in enumerate(lines[1:], 2):
        parts = line.split("\t")
        if len(parts) != 3 or not parts[1].isdigit() or not re.fullmatch(r"[0-9a-f]{64}", parts[2]):
            raise ValueError(f"{path}, line {i}: not 'path<TAB>bytes<TAB>sha256': {line[:120]!r}")
        if not safe_relative(parts[0]):
            raise ValueError(f"{path}, line {i}: path {parts[0]!r} leads outside the release folder")
        out[parts[0]] = (int(parts[1]), parts[2])
    return out


def safe_relative(p: str) -> bool:
    """A manifest path that stays inside the folder: relative, no '..' component, no backslash."""
    return bool(p) and not p.startswith("/") and "\\" not in p and ".." not in p.split("/")


def walk_files(root: Path) -> list[str]:
    """Every file under root as a relative POSIX path, sorted (symbolic links count as files)."""
    out = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames.sort()
        for f in filenames:
            out.append((Path(dirpath) / f).relative_to(root).as_posix())
    return sorted(out)


def read_card_front_matter(path: Path) -> dict:
    """The YAML front matter of a dataset card (between the first two '---' lines), safely loaded."""
    import yaml

    text = Path(path).read_text()
    if not text.startswith("---\n"):
        raise ValueError(f"{path}: no YAML front matter (the card must start with '---')")
    end = text.find("\n---\n", 4)
    if end < 0:
        raise ValueError(f"{path}: the YAML front matter is not closed by a '---' line")
    return yaml.safe_load(text[4:end]) or {}


def read_release_json(root: Path) -> dict:
    return json.loads((Path(root) / RELEASE_JSON).read_text())
