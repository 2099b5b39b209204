"""Catalogs: which scenes exist (id, group, path, format) and where each logical dataset lives.

A catalog YAML has ``scenes:`` (explicit entries; relative paths are relative to the catalog
file's folder) and/or ``synthetic:`` (a generated range of
procedural scenes, under the project's licence unless it names another), and may override
entries of the shared layout (navcore/io/layout.yaml) under
``layout:``. Each layout entry is a path template and a dataset type (navcore/io/datasets.py);
stage code asks ``catalog.dataset("costmaps", scene)`` and loads or saves through it, never
building or opening paths itself. ``catalog.path`` is for the pipeline's own files (markers,
run summaries) and for walking the roots of partitioned datasets.
"""
from __future__ import annotations

import hashlib
import os
import re
import string
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import yaml

from navcore.gaussians.formats import detect_format
from navcore.io.atomic import TEMP_PREFIXES
from navcore.io.datasets import TYPES, Dataset
from navcore.io.licences import PROJECT_LICENSE
from navcore.labels.shipped import LabelSpec
from navcore.paths import usable_path

LAYOUT_FILE = resources.files("navcore.io") / "layout.yaml"
"""The shared data layout, package data of navcore: logical dataset -> path template and type (a
catalog may override entries under ``layout:``)."""


SAFE_COMPONENT = re.compile(r"[A-Za-z0-9][A-Za-z0-9._=-]{0,127}")
"""What a value substituted into a path template may be: one plain path component (no separator,
no '..', no leading dot), so that a catalog cannot steer a write outside the data root."""


def safe_component(value, what: str, where) -> str:
    v = str(value)
    if not SAFE_COMPONENT.fullmatch(v) or ".." in v:
        raise ValueError(f"{where}: {what} {v!r} is not a plain name (letters, digits, '.', '_', '-', '='; no "
                         f"'/' or '..'): it is used in output paths")
    return v


PROVENANCE = ("license", "source_url", "attribution")
"""Catalog entry keys of a scene's provenance (strings or absent): what a release says of it."""


def provenance(entry: dict, where: str) -> dict:
    """The provenance keys of a catalog entry, checked to be strings."""
    out = {}
    for k in PROVENANCE:
        v = entry.get(k)
        if v is not None and not isinstance(v, str):
            raise ValueError(f"{where}: {k} must be a string (an SPDX id such as CC-BY-4.0, or free text), got {v!r}")
        out[k] = v.strip() if isinstance(v, str) and v.strip() else None
    return out


MAX_SYNTHETIC = 1_000_000
"""The most procedural scenes one catalog may ask for (a typo of a few digits would otherwise
enumerate billions of scene ids before anything runs)."""


def read_catalog(path: Path) -> dict:
    """A catalog file's YAML (the safe loader: no tags that build Python objects), a mapping; any
    problem is a ValueError naming the file."""
    try:
        text = path.read_text()
    except UnicodeDecodeError as e:
        raise ValueError(f"catalog {path}: not UTF-8 text ({e})") from None
    except OSError as e:
        raise ValueError(f"catalog {path}: cannot be read ({e.strerror or e})") from None
    try:
        spec = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise ValueError(f"catalog {path}: not valid YAML ({' '.join(str(e).split())})") from None
    if spec is None:
        return {}
    if not isinstance(spec, dict):
        raise ValueError(f"catalog {path}: must be a mapping with scenes: and / or synthetic:, got {type(spec).__name__}")
    return spec


def _placeholders(template: str, file=LAYOUT_FILE) -> set[str]:
    """The {fields} a path template names (a malformed template is a ValueError naming the file)."""
    try:
        return {n for _, n, _, _ in string.Formatter().parse(template) if n is not None}
    except ValueError as e:
        raise ValueError(f"catalog {file}: layout template {template!r} is malformed ({e})") from None


def _typed(spec: dict, key: str, kind: type, file: Path):
    v = spec.get(key)
    if v is not None and not isinstance(v, kind):
        raise ValueError(f"catalog {file}: {key} must be a {kind.__name__}, got {type(v).__name__}")
    return v


def outside_paths(folder: Path, name: str, paths: dict) -> list[dict]:
    """The paths of a catalog entry that lead out of the catalog's folder (absolute, or through
    '..'), resolved: a run lists them in its summary, so that whoever runs a catalog someone else
    wrote sees which files outside it the run reads. Built-in class-table keys are no paths."""
    from navcore.labels import BUILTIN

    out = []
    for key, written in paths.items():
        if not written or not isinstance(written, str) or written in BUILTIN:
            continue
        resolved = (folder / written).resolve()
        if not resolved.is_relative_to(folder.resolve()):
            out.append({"scene": name, "key": key, "written": written, "resolved": str(resolved)})
    return out


def scene_id_for(dataset: str, name: str, taken: set[str] | None = None) -> str:
    """NavArena scene id: first 8 hex chars of sha256("{dataset}:{name}"), 12 on collision."""
    h = hashlib.sha256(f"{dataset}:{name}".encode()).hexdigest()
    return h[:12] if taken and h[:8] in taken else h[:8]


@dataclass(frozen=True)
class SceneEntry:
    scene_id: str
    name: str
    group: str
    path: str  # source file / folder ("" for synthetic until generated)
    format: str  # inria_ply, supersplat_ply, ply, splat, spz, sog, npy_folder, synthetic
    seed: int | None = None
    num_gaussians: int | None = None
    labels: LabelSpec | None = None  # the entry's `labels:` (class table, labelled mesh; navcore.labels.shipped)
    license: str | None = None  # SPDX id or free text (navcore.io.licences); None: unknown
    source_url: str | None = None  # where the capture was published
    attribution: str | None = None  # whom to credit, as the source asks

    @property
    def synthetic(self) -> bool:
        return self.format == "synthetic"


class Catalog:
    """Scenes of one catalog file plus the data layout rooted at ``root``."""

    def __init__(self, catalog_file: str | Path, root: str | Path, synthetic_count: int | None = None,
                 synthetic_num_gaussians: int | None = None):
        self.file = Path(catalog_file)
        if not self.file.exists():
            raise FileNotFoundError(f"catalog {self.file} does not exist (scenes.catalog=...)")
        spec = read_catalog(self.file)
        self.root = Path(root).resolve()
        self.layout = dict(yaml.safe_load(LAYOUT_FILE.read_text()))
        layout = _typed(spec, "layout", dict, self.file) or {}
        layout = dict(layout)
        for k, v in layout.items():  # an entry keeps its kind: a dataset {path, type} or a folder (a string)
            was = self.layout.get(k)
            if isinstance(was, dict) and isinstance(v, str):  # a dataset's path alone: its type stays
                v = layout[k] = {**was, "path": v}
            ok = isinstance(v, str) if isinstance(was, str) else (
                isinstance(v, dict) and isinstance(v.get("path"), str) and isinstance(v.get("type"), str) and v["type"] in TYPES and
                (was is None or v.get("type") == was.get("type")))
            if ok:  # and names only the placeholders its default names (any of the layout's, for a new one)
                allowed = _placeholders(was if isinstance(was, str) else was["path"]) if was is not None else \
                    set().union(*(_placeholders(x if isinstance(x, str) else x["path"]) for x in self.layout.values()))
                if "scene_id" in allowed:  # a per-scene entry may name any of the scene's fields
                    allowed |= {"group", "name"}
                extra = _placeholders(v if isinstance(v, str) else v["path"], self.file) - allowed
                if extra:
                    raise ValueError(f"catalog {self.file}: layout entry {k!r} names the unknown placeholder(s) "
                                     f"{sorted(extra)}; it may use {sorted(allowed)}")
            if not ok:
                want = "a folder template (a string)" if isinstance(was, str) else "a path template or a mapping {path, type}"
                raise ValueError(f"catalog {self.file}: layout entry {k!r} must be {want}"
                                 f"{' of type ' + repr(was['type']) if isinstance(was, dict) else ''}, got {v!r}")
        self.layout.update(layout)
        self.scenes: list[SceneEntry] = []
        self.outside: list[dict] = []  # paths of entries that lead out of the catalog's folder (`outside_paths`)
        taken: set[str] = set()
        for i, e in enumerate(_typed(spec, "scenes", list, self.file) or []):
            where = f"catalog {self.file}, scene entry {i + 1}"
            try:
                self._add_entry(e, where, taken)
            except (TypeError, KeyError, AttributeError, OverflowError) as err:  # a value of the wrong type
                raise ValueError(f"{where}: {type(err).__name__}: {err}") from None
        syn = _typed(spec, "synthetic", dict, self.file)
        if syn:
            self._add_synthetic(dict(syn), synthetic_count, synthetic_num_gaussians)

    def _add_entry(self, e, where: str, taken: set[str]) -> None:
        if not isinstance(e, dict):
            raise ValueError(f"{where}: must be a mapping with name and path, got {type(e).__name__}")
        for key in ("name", "path"):
            if not isinstance(e.get(key), str) or not e[key].strip():
                raise ValueError(f"{where}: '{key}' must be a non-empty string (got {e.get(key)!r})")
        for key in ("group", "id", "format"):
            if e.get(key) is not None and not isinstance(e[key], str):
                raise ValueError(f"{where}: '{key}' must be a string (got {e[key]!r})")
        where = f"catalog {self.file}, scene {e['name']!r}"
        usable_path(e["path"], f"{where}: path")
        group = safe_component(e.get("group", "default"), "group", self.file)
        sid = safe_component(e.get("id") or scene_id_for(group, e["name"], taken), "id", self.file)
        path = Path(e["path"])
        if not path.is_absolute():
            path = (self.file.parent / path).resolve()  # relative to the catalog file's folder
        try:
            fmt = e.get("format") or detect_format(path)  # left out: the path tells
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
        labels = LabelSpec.from_entry(e.get("labels"), self.file.parent, where)
        self.outside += outside_paths(self.file.parent, e["name"], {"path": e["path"], **{
            f"labels.{k}": getattr(labels, k) for k in ("classes", "mesh", "mesh_classes") if labels is not None}})
        self.scenes.append(SceneEntry(sid, e["name"], group, str(path), fmt, labels=labels, **provenance(e, where)))
        taken.add(sid)

    def _add_synthetic(self, syn: dict, count: int | None, num_gaussians: int | None) -> None:
        if count is not None:
            syn["count"] = count
        if num_gaussians is not None:
            syn["num_gaussians"] = num_gaussians
        where = f"catalog {self.file}, synthetic"
        for key, lo, hi in (("count", 0, MAX_SYNTHETIC), ("first_seed", 0, 2**31), ("num_gaussians", 1, 10**9)):
            v = syn.get(key)
            if v is not None and (not isinstance(v, int) or isinstance(v, bool) or not lo <= v <= hi):
                raise ValueError(f"{where}: {key} must be an integer in {lo}..{hi:,} (got {v!r})")
        for key in ("prefix", "group", "license", "source_url", "attribution"):
            if syn.get(key) is not None and not isinstance(syn[key], str):
                raise ValueError(f"{where}: {key} must be a string (got {syn[key]!r})")
        taken = {s.scene_id for s in self.scenes}
        for k in range(int(syn.get("count") or 0)):
            seed = int(syn.get("first_seed") or 0) + k
            name = safe_component(f"{syn.get('prefix', 'synth')}_{seed:04d}", "synthetic prefix", self.file)
            group = safe_component(syn.get("group", "synthetic"), "group", self.file)
            sid = scene_id_for(group, name, taken)
            taken.add(sid)
            self.scenes.append(SceneEntry(
                sid, name, group, "", "synthetic", seed, syn.get("num_gaussians"),
                license=str(syn.get("license") or PROJECT_LICENSE), source_url=syn.get("source_url"),
                attribution=syn.get("attribution") or f"NavArena procedural scene generator, seed {seed}"))

    @classmethod
    def for_root(cls, root: str | Path) -> "Catalog":
        """The layout of an existing data root without a catalog file (readers of a finished
        dataset: scenes are found from what is on disk, see scene_ids)."""
        cat = cls.__new__(cls)
        cat.file, cat.root = LAYOUT_FILE, Path(root).resolve()
        if not cat.root.is_dir():
            raise FileNotFoundError(f"data root {cat.root} does not exist")
        cat.layout = dict(yaml.safe_load(LAYOUT_FILE.read_text()))
        cat.scenes = []
        return cat

    def scene_ids(self, dataset: str = "episodes", **extra) -> list[str]:
        """Scene ids for which `dataset` exists on disk (any value of its other fields), sorted."""
        template, _ = self._entry(dataset)
        free = [n for _, n, _, _ in string.Formatter().parse(template) if n and n not in ("root",) and n not in extra]
        found = self.find(dataset, **extra)
        pos = free.index("scene_id")
        return sorted({k.split("/")[pos] for k in found})

    def scene(self, scene_id: str) -> SceneEntry:
        """The catalog entry of a scene id, or a bare entry (id only) for a root without a catalog."""
        for s in self.scenes:
            if s.scene_id == scene_id:
                return s
        return SceneEntry(safe_component(scene_id, "scene id", self.file), scene_id, "default", "", "")

    def _entry(self, dataset: str) -> tuple[str, str | None]:
        if dataset not in self.layout:
            raise KeyError(f"dataset {dataset!r} is not in the layout ({', '.join(self.layout)})")
        e = self.layout[dataset]
        return (e, None) if isinstance(e, str) else (e["path"], e["type"])

    def _fields(self, scene: SceneEntry | None, extra: dict) -> dict:
        """Values of a path template's placeholders: the root, a scene's id / group / name, extras."""
        fields = {"root": str(self.root), **extra}
        if scene is not None:
            fields.update(scene_id=scene.scene_id, group=scene.group, name=scene.name)
        return fields

    def path(self, dataset: str, scene: SceneEntry | None = None, **extra) -> Path:
        """Resolve a logical dataset name to a path: always inside the data root (a layout entry
        or a field that would lead elsewhere is refused: the pipeline writes only there)."""
        template, _ = self._entry(dataset)
        fields = self._fields(scene, extra)
        used = {n for _, n, _, _ in string.Formatter().parse(template) if n}
        for k in sorted(used & set(fields) - {"root"}):
            safe_component(fields[k], f"{k} of dataset {dataset!r}", self.file)
        try:
            p = Path(template.format(**fields))
        except KeyError as e:
            raise KeyError(f"dataset {dataset!r} ({template}) needs the field {e.args[0]!r}") from None
        # lexical (a data root may hold symlinks to other disks): the fields are plain names, so
        # only the template itself could lead out
        if not Path(os.path.normpath(p)).is_relative_to(self.root):
            raise ValueError(f"layout entry {dataset!r} ({template}) resolves to {p}, outside the data root "
                             f"{self.root}")
        return p

    def dataset(self, dataset: str, scene: SceneEntry | None = None, **extra) -> Dataset:
        """The typed dataset (load / save / writing) of a logical name, for one scene (and task,
        run, ... where its path template has them)."""
        _, kind = self._entry(dataset)
        if kind is None:
            raise KeyError(f"{dataset!r} is a folder of datasets, not a dataset; use catalog.path")
        if kind not in TYPES:
            raise ValueError(f"layout: dataset {dataset!r} has unknown type {kind!r} ({', '.join(TYPES)})")
        base = self.layout[dataset].get("base")  # a dataset derived on read from another one
        kwargs = {"base": self.dataset(base, scene, **extra)} if base else {}
        return TYPES[kind](self.path(dataset, scene, **extra), **kwargs)

    def find(self, dataset: str, scene: SceneEntry | None = None, **extra) -> dict[str, Dataset]:
        """The existing datasets of a name whose path fields other than the given ones vary
        (e.g. every task of one scene's episodes), keyed by the varying fields' values joined
        with "/" (in the template's order), sorted."""
        template, _ = self._entry(dataset)
        fields = self._fields(scene, extra)
        free = list(dict.fromkeys(n for _, n, _, _ in string.Formatter().parse(template) if n and n not in fields))
        pattern = template.format(**{**{n: "*" for n in free}, **fields})
        anchor = Path(pattern.split("*")[0]).parent if "*" in pattern else Path(pattern).parent
        found = {}
        regex = re.escape(pattern).replace(re.escape("*"), "([^/]+)")
        for p in sorted(anchor.glob(str(Path(pattern).relative_to(anchor)))):
            m = re.fullmatch(regex, str(p))
            # an atomic write in progress (another process's .tmp-*, or the .old-* it swaps out) is
            # no dataset yet: a dataset-level step listing a folder while a shard writes into it
            if m and not any(g.startswith(TEMP_PREFIXES) for g in m.groups()):
                values = dict(zip(free, m.groups()))
                found["/".join(m.groups())] = self.dataset(dataset, scene, **extra, **values)
        return found

    def select(self, shard: int = 0, num_shards: int = 1, ids: list[str] | None = None,
               limit: int | None = None) -> list[SceneEntry]:
        """Shard k of n: a disjoint, deterministic slice (by scene id order), optionally filtered."""
        if not 0 <= shard < num_shards:
            raise ValueError(f"shard {shard} is outside 0..{num_shards - 1}")
        scenes = sorted(self.scenes, key=lambda s: s.scene_id)
        if ids:
            scenes = [s for s in scenes if s.scene_id in ids or s.name in ids]
        scenes = scenes[shard::num_shards]
        return scenes[:limit] if limit else scenes


def open_catalog(cfg, project_root: Path | None = None) -> tuple[Catalog, list[SceneEntry], Path]:
    """A run's catalog, its selected scenes and the catalog file, from a config with `data_root`
    and the `scenes` section (file, count, num_gaussians, shard, num_shards, ids, limit). Relative
    paths are the working directory's; a catalog file not found there is looked up under
    `project_root` (the pipeline's checkout, where catalogs/ lives)."""
    root = Path(cfg.data_root)
    if not root.is_absolute():
        root = Path.cwd() / root
    cat_file = Path(cfg.scenes.catalog)
    if not cat_file.is_absolute():
        here = Path.cwd() / cat_file
        cat_file = here if here.exists() or project_root is None else Path(project_root) / cat_file
    catalog = Catalog(cat_file, root, cfg.scenes.count, cfg.scenes.num_gaussians)
    return catalog, catalog.select(cfg.scenes.shard, cfg.scenes.num_shards, cfg.scenes.ids, cfg.scenes.limit), cat_file
