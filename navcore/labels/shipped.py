"""Ground-truth labels a real dataset ships, read as it ships them, into the instance table.

Three shapes of labels, in this order of preference for a scene:
1. per-Gaussian class and instance ids (SceneSplat / SceneSplat++ `segment.npy` / `instance.npy`,
   carried by the npy_folder reader as extras "segment" / "instance"), with the class table of
   the label set they use (the catalog entry's `labels.classes`, else a classes.txt shipped in
   the folder);
2. labelled geometry in the splat's frame (`labels.mesh`: a ScanNet `*_vh_clean_2.labels.ply`
   with its segs / aggregation json, a Replica / habitat `mesh_semantic.ply` with its
   info_semantic.json, or a point cloud / mesh PLY with per-vertex class and instance ids),
   transferred to the Gaussians by the nearest surface point within a distance bound (mesh.py);
3. a labels.json beside the scene (InteriorGS or NavArena layout: one box per instance).

Per-Gaussian labels become instances (`instances_from_gaussians`) after the cleaning real labels
need: an instance keeps its largest spatial cluster (floaters and far fragments dropped, counted);
tiny and mostly transparent instances are dropped with a reason, and so are instances whose box
lies below the floor or above the ceiling. Categories go through the goal vocabulary
(navcore.labels.GoalVocabulary); the report says how many instances of each goal category came
from which dataset class.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from navcore.labels import GoalVocabulary, LabelSet, as_category, is_structure, normalise, read_table, resolve
from navcore.paths import usable_path

CLASS_NAME_FILES = ("classes.txt", "class_names.txt")
SPEC_KEYS = ("classes", "id_offset", "ignore", "mesh", "mesh_classes", "max_distance", "goal_map")


@dataclass(frozen=True)
class LabelSpec:
    """A catalog entry's `labels:` mapping (see the module doc and README "Labels").

    Attributes:
        classes: class table of the per-Gaussian segment ids: a built-in key or a names file.
        id_offset / ignore: override the table's id of its first name and its ignore values.
        mesh: labelled mesh or point cloud in the splat's source frame.
        mesh_classes: class table of the mesh's class ids (default: `classes`; ScanNet and Replica
            meshes name their classes themselves).
        max_distance: metres; Gaussians farther than this from the labelled surface stay unlabelled.
        goal_map: extra lines of the goal mapping table (dataset class -> goal category).
        base: folder that relative paths are relative to (the catalog file's).
    """

    classes: str | None = None
    id_offset: int | None = None
    ignore: tuple[int, ...] | None = None
    mesh: str | None = None
    mesh_classes: str | None = None
    max_distance: float = 0.05
    goal_map: tuple[tuple[str, str], ...] = ()
    base: str = ""

    @classmethod
    def from_entry(cls, spec: dict | None, base: Path, where: str) -> "LabelSpec | None":
        """The spec of a catalog entry's `labels:` (None when it has none)."""
        if not spec:
            return None
        if not isinstance(spec, dict):
            raise ValueError(f"{where}: labels must be a mapping with keys {', '.join(SPEC_KEYS)}")
        unknown = sorted(set(spec) - set(SPEC_KEYS))
        if unknown:
            raise ValueError(f"{where}: unknown labels key(s) {unknown}; known: {', '.join(SPEC_KEYS)}")
        for key in ("classes", "mesh", "mesh_classes"):
            v = spec.get(key)
            if v is not None and (not isinstance(v, str) or not v.strip()):
                raise ValueError(f"{where}: labels.{key} must be a file name or a table key, got {v!r}")
            if v is not None:
                usable_path(v, f"{where}: labels.{key}")
        ints = lambda v: isinstance(v, int) and not isinstance(v, bool) and abs(v) < 2**31  # noqa: E731
        if spec.get("id_offset") is not None and not ints(spec["id_offset"]):
            raise ValueError(f"{where}: labels.id_offset must be an integer, got {spec['id_offset']!r}")
        ignore = spec.get("ignore")
        if ignore is not None and (not isinstance(ignore, list) or not all(ints(i) for i in ignore)):
            raise ValueError(f"{where}: labels.ignore must be a list of integer ids, got {ignore!r}")
        dist = spec.get("max_distance", 0.05)
        if not isinstance(dist, (int, float)) or isinstance(dist, bool) or not 0 < dist <= 10:
            raise ValueError(f"{where}: labels.max_distance must be metres in (0, 10], got {dist!r}")
        gm = spec.get("goal_map") or {}
        if not isinstance(gm, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in gm.items()):
            raise ValueError(f"{where}: labels.goal_map must map dataset class names to goal categories (strings)")
        return cls(classes=spec.get("classes"), id_offset=spec.get("id_offset"),
                   ignore=tuple(ignore) if ignore is not None else None,
                   mesh=spec.get("mesh"), mesh_classes=spec.get("mesh_classes"), max_distance=float(dist),
                   goal_map=tuple(sorted(gm.items())), base=str(base))

    def path(self, p: str) -> Path:
        q = Path(p)
        return q if q.is_absolute() or not self.base else Path(self.base) / q

    def as_dict(self) -> dict:
        """JSON-able form (hashed into the scene's stage hashes)."""
        return {"classes": self.classes, "id_offset": self.id_offset, "ignore": self.ignore, "mesh": self.mesh,
                "mesh_classes": self.mesh_classes, "max_distance": self.max_distance, "goal_map": dict(self.goal_map)}


@dataclass
class CleaningConfig:
    """Instance cleaning of shipped per-Gaussian labels (semantics.labels)."""

    cluster_eps: float = 0.15
    """Metres: an instance's Gaussians within this of one another (or within 4 x their median
    nearest-neighbour spacing, if larger) form one spatial cluster; the largest cluster is the
    instance, the rest (floaters, far fragments) is dropped and counted."""
    min_gaussians: int = 20
    """Instances with fewer Gaussians (after the cluster) are dropped (`tiny`)."""
    min_extent: float = 0.08
    """Metres: instances whose largest box side is under this are dropped (`tiny`)."""
    min_opaque_fraction: float = 0.2
    """Instances whose share of Gaussians with opacity >= 0.1 is under this are dropped
    (`mostly_unobserved`: a 3DGS fit leaves what no camera saw transparent)."""
    floor_margin: float = 0.1
    """Metres: an instance whose box top is this far below the floor, or whose box bottom is this
    far above the ceiling, is dropped (`below_floor` / `above_ceiling`)."""


@dataclass
class LabelReport:
    """What reading a scene's labels did (stored in the semantics stage's result)."""

    origin: str = ""
    label_set: str = ""
    gaussians: int = 0
    unlabelled: int = 0
    fragment_gaussians: int = 0
    dropped: dict[str, list[dict]] = field(default_factory=dict)
    goal_mapping: dict[str, dict[str, int]] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    transfer: dict = field(default_factory=dict)

    def count_goal(self, vocab: GoalVocabulary, name: str) -> None:
        """One instance of dataset class `name` in the goal mapping (when it maps to a goal)."""
        goal = vocab.goal_of(name)
        if goal is not None:
            m = self.goal_mapping.setdefault(goal, {})
            m[normalise(name)] = m.get(normalise(name), 0) + 1

    def as_dict(self) -> dict:
        return {"origin": self.origin, "label_set": self.label_set, "gaussians": self.gaussians,
                "unlabelled_gaussians": self.unlabelled, "fragment_gaussians": self.fragment_gaussians,
                "dropped": {k: v for k, v in sorted(self.dropped.items())},
                "dropped_counts": {k: len(v) for k, v in sorted(self.dropped.items())},
                "goal_mapping": self.goal_mapping, **({"transfer": self.transfer} if self.transfer else {})}


def folder_class_table(folder: Path) -> LabelSet | None:
    """A class table shipped in a SceneSplat folder (classes.txt / class_names.txt), if any."""
    for name in CLASS_NAME_FILES:
        if (folder / name).is_file():
            return read_table(folder / name)
    return None


def class_table(spec: LabelSpec | None, folder: Path | None) -> LabelSet | None:
    """The class table of a scene's per-Gaussian segment ids: the catalog entry's, else the folder's."""
    if spec is not None and spec.classes:
        return resolve(spec.classes, Path(spec.base) if spec.base else None, spec.id_offset, spec.ignore)
    table = folder_class_table(folder) if folder is not None and folder.is_dir() else None
    return table.with_ids(spec.id_offset, spec.ignore) if table is not None and spec is not None else table


def largest_cluster(points: np.ndarray, eps: float, spacing_factor: float = 4.0) -> np.ndarray:
    """Bool mask of the largest connected cluster of `points` (single linkage: two points closer
    than max(eps, spacing_factor x the median nearest-neighbour spacing of the points) are
    connected, so that a sparsely sampled object is not cut up), the first in index order on a tie."""
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    from navcore.optional import require

    radius_neighbors_graph = require("sklearn.neighbors", "grouping labelled points into instances").radius_neighbors_graph

    if len(points) <= 2:
        return np.ones(len(points), bool)
    spacing = float(np.median(cKDTree(points).query(points, k=2)[0][:, 1]))
    g = radius_neighbors_graph(points, max(eps, spacing_factor * spacing), mode="connectivity", include_self=False)
    _, comp = connected_components(g, directed=False)
    counts = np.bincount(comp)
    return comp == int(np.argmax(counts))


def instances_from_gaussians(means: np.ndarray, opacity: np.ndarray, instance: np.ndarray, segment: np.ndarray,
                             names, vocab: GoalVocabulary, cleaning: CleaningConfig, ceiling: float | None,
                             report: LabelReport) -> tuple[list[dict], dict[int, int]]:
    """labels.json entries (aligned frame, source ground_truth) from per-Gaussian labels.

    Args:
        means: [N, 3] centres in the aligned frame (floor z = 0). opacity: [N] activated.
        instance: [N] instance id (< 0: none). segment: [N] class id (per `names`).
        names: a LabelSet (class id -> name), or None (names become class_{id}; a warning says so).
        vocab: the goal vocabulary. cleaning: CleaningConfig. ceiling: floor-to-ceiling height, m.
        report: filled in (dropped instances by reason, fragments, the goal mapping).
    Returns:
        (entries with `dataset_class` and the box of the kept cluster's 2nd-98th percentiles,
        support = Gaussians per kept instance id).
    """
    labels, support = [], {}
    ok = instance >= 0
    report.gaussians = int(len(instance))
    order = np.argsort(instance[ok], kind="stable")
    ids, starts = np.unique(instance[ok][order], return_index=True)
    rows = np.flatnonzero(ok)[order]
    bounds = list(starts[1:]) + [len(rows)]
    for iid, s, e in zip(ids.tolist(), starts.tolist(), bounds):
        sel = rows[s:e]
        seg = segment[sel]
        valid = seg[seg >= 0]
        if names is not None and len(valid):  # vote among the ids the table names: an instance whose
            # Gaussians mostly carry an ignored id (NYU40's 0) takes the class its others name
            ids_, counts = np.unique(valid, return_counts=True)
            named = np.array([names.lookup(int(i)) is not None for i in ids_])
            valid = np.repeat(ids_[named], counts[named])
        name = None
        if len(valid):
            cls = int(np.bincount(valid).argmax())
            name = (names.lookup(cls) if names is not None else f"class_{cls}")
        if name is None:
            report.dropped.setdefault("no_class", []).append({"instance_id": iid})
            continue
        entry = {"instance_id": iid, "dataset_class": name}
        if is_structure(name):  # never a goal: kept in the table as it is, no cleaning needed
            keep = sel
        else:
            keep = sel[largest_cluster(means[sel].astype(np.float64), cleaning.cluster_eps)]
            report.fragment_gaussians += int(len(sel) - len(keep))
            if len(sel) != len(keep):
                entry["fragment_gaussians"] = int(len(sel) - len(keep))
        pts = means[keep].astype(np.float64)
        lo, hi = np.percentile(pts, [2, 98], axis=0)
        why = None
        if not is_structure(name):
            if len(keep) < cleaning.min_gaussians or float((hi - lo).max()) < cleaning.min_extent:
                why = "tiny"
            elif float((opacity[keep] >= 0.1).mean()) < cleaning.min_opaque_fraction:
                why = "mostly_unobserved"
            elif hi[2] < -cleaning.floor_margin:
                why = "below_floor"
            elif ceiling is not None and lo[2] > ceiling + cleaning.floor_margin:
                why = "above_ceiling"
        if why:
            report.dropped.setdefault(why, []).append({**entry, "gaussians": int(len(keep))})
            continue
        cat = vocab.category_of(name)
        labels.append({"instance_id": iid, "category": cat, "dataset_class": as_category(name),
                       "position": ((lo + hi) / 2).tolist(), "bounding_box": {"min": lo.tolist(), "max": hi.tolist()},
                       "confidence": 1.0, "source": "ground_truth"})
        support[iid] = int(len(keep))
        report.count_goal(vocab, name)
    report.unlabelled = int((~ok).sum())
    return labels, support


def missing_table_warning(scene, folder: Path) -> str:
    """The run-summary warning of per-Gaussian class ids without a class table."""
    return (f"scene {scene.scene_id} ({scene.name}): {folder / 'segment.npy'} holds class ids but no class table was "
            f"found: instances are named class_<id> and none can be an ObjectNav goal; ship {folder / 'classes.txt'} "
            f"(one name per line, line k = id k) or set labels.classes in the catalog entry (built-in: nyu40, scannet20, "
            f"scannet200, scannetpp100, s3dis, mpcat40, or a path)")


def read_json(path: Path) -> dict | list:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: unreadable JSON ({e})") from None
