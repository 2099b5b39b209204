"""croissant.json: MLCommons Croissant metadata of a release, built with the `mlcroissant` package
(so it validates by construction; `mlcroissant validate --jsonld croissant.json` re-checks it).

Files: the top-level documents as FileObjects with their sha256 (MANIFEST.tsv carries the sha256 of
every other file), the partitioned tables as FileSets. Record sets: one per task of episodes and
one per task of trajectories, one field per column of the release's files (navcore/io/episode_schema.py;
the oracle action list as an integer array), and split and scene_id from each file's folders."""
from __future__ import annotations

import datetime as dt
from pathlib import Path

import pyarrow as pa

from navcore.io.release import CARD, CROISSANT, RELEASE_JSON, SCENES, release_episode_schema, release_trajectory_schema, sha256_file
from pipeline.release.card import citation


def _data_type(t: pa.DataType):
    import mlcroissant as mlc

    if pa.types.is_list(t):
        t = t.value_type
    if pa.types.is_string(t):
        return mlc.DataType.TEXT
    if pa.types.is_floating(t):
        return mlc.DataType.FLOAT
    if pa.types.is_integer(t):
        return mlc.DataType.INTEGER
    if pa.types.is_boolean(t):
        return mlc.DataType.BOOL
    raise TypeError(f"no Croissant data type for {t}")


def _fields(record: str, file_set: str, schema: pa.Schema) -> list:
    import mlcroissant as mlc

    out = []
    for f in schema:
        arr = pa.types.is_list(f.type)
        out.append(mlc.Field(id=f"{record}/{f.name}", name=f.name, data_types=[_data_type(f.type)],
                             is_array=arr or None, array_shape="-1" if arr else None,
                             source=mlc.Source(file_set=file_set, extract=mlc.Extract(column=f.name))))
    return out


def metadata(root: Path, info: dict, rcfg):
    import mlcroissant as mlc

    docs = []
    for name, fmt in ((CARD, "text/markdown"), (RELEASE_JSON, "application/json"), (SCENES, "application/x-parquet")):
        if (root / name).exists():  # not MANIFEST.tsv: it is written after this file, its hash cannot be here
            docs.append(mlc.FileObject(id=name, name=name, content_url=name, encoding_formats=[fmt],
                                       sha256=sha256_file(root / name)))
    sets, records = [], []
    for task in info["counts"]:
        for kind, schema in (("episodes", release_episode_schema()), ("trajectories", release_trajectory_schema())):
            fs = f"{task}-{kind}-files"
            sets.append(mlc.FileSet(id=fs, name=fs, includes=[f"{kind}/{task}/*/*.parquet"],
                                    encoding_formats=["application/x-parquet"]))
            rid = task if kind == "episodes" else f"{task}_trajectories"
            records.append(mlc.RecordSet(id=rid, name=rid, fields=_fields(rid, fs, schema),
                                         description=f"{task} {kind}: one record per {'episode' if kind == 'episodes' else 'expert step'}"))
    created = dt.datetime.fromisoformat(info["created"])
    licenses = sorted({r for r in info.get("licenses", [])}) or [info["licence"]]
    return mlc.Metadata(
        name=f"{rcfg.name}-{info['version']}", version=info["version"],
        description=(f"Goal-directed navigation episodes (PointNav, ImageNav, ObjectNav) with expert trajectories from "
                     f"3D Gaussian Splatting scenes; see {CARD}."),
        url=rcfg.homepage or None, license=[f"https://spdx.org/licenses/{x}.html" for x in licenses],
        cite_as=citation(info, rcfg), date_published=created, date_created=created,
        keywords=["embodied AI", "navigation", "3D Gaussian Splatting"],
        distribution=docs + sets, record_sets=records)


def write_croissant(root: Path, info: dict, stats, rcfg) -> None:
    import json

    from navcore.io import jsonio

    md = metadata(root, info, rcfg)
    errors = md.issues.errors
    if errors:
        raise ValueError(f"croissant.json would not validate: {sorted(errors)}")
    (root / CROISSANT).write_text(jsonio.dumps(json.loads(json.dumps(md.to_json(), default=str)), indent=1))
