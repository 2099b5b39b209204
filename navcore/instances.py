"""The per-scene instance table: object instances that may become ObjectNav goals.

One schema, shared by its writers (the semantics stage: source "model_predicted"; the ground truth
of synthetic scenes: "ground_truth") and its readers (the episodes stage, the asset's labels.json).
All coordinates are in the scene's aligned frame (z up, floor at z = 0), metres.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa

from navcore.labels import GoalVocabulary, as_category, resolve
from navcore.labels.mesh import read_labelled_geometry, transfer
from navcore.labels.shipped import CleaningConfig, LabelReport, class_table, instances_from_gaussians, missing_table_warning

INSTANCE_SCHEMA = pa.schema([
    pa.field("instance_id", pa.int32(), nullable=False),
    pa.field("category", pa.string(), nullable=False),
    pa.field("center_x", pa.float64()), pa.field("center_y", pa.float64()), pa.field("center_z", pa.float64()),
    # axis-aligned box of the instance in the aligned frame (NaN when unknown)
    pa.field("min_x", pa.float64()), pa.field("min_y", pa.float64()), pa.field("min_z", pa.float64()),
    pa.field("max_x", pa.float64()), pa.field("max_y", pa.float64()), pa.field("max_z", pa.float64()),
    pa.field("support", pa.int32()),  # Gaussians (or voted cells) behind the instance
    pa.field("confidence", pa.float32()),
    pa.field("source", pa.string()),  # ground_truth | model_predicted
    pa.field("dataset_class", pa.string()),  # the label set's own class name (ground truth), else null
    pa.field("views", pa.int32()),  # model_predicted: distinct views whose masks voted for it, else null
    pa.field("agreement", pa.float32()),  # model_predicted: mean share of its cells each of those views voted for
])


def transform_labels(labels: list[dict], tf: np.ndarray) -> list[dict]:
    """labels.json entries moved by a 4x4 rigid transform (positions, and boxes as the
    axis-aligned box of their transformed corners)."""
    out = []
    for lab in labels:
        lab = dict(lab)
        lab["position"] = (tf[:3, :3] @ np.asarray(lab["position"]) + tf[:3, 3]).tolist()
        box = lab.get("bounding_box")
        if box:
            c = np.array(np.meshgrid(*zip(box["min"], box["max"]), indexing="ij")).reshape(3, -1).T
            c = c @ tf[:3, :3].T + tf[:3, 3]
            lab["bounding_box"] = {"min": c.min(0).tolist(), "max": c.max(0).tolist()}
        out.append(lab)
    return out


def ground_truth_labels(scene, catalog) -> list[dict]:
    """labels.json entries of a synthetic scene's ground truth, in the aligned frame."""
    src = catalog.dataset("source_synthetic", scene)
    labels = src.read_ground_truth("labels.json")
    if labels is None:
        raise FileNotFoundError(f"scene {scene.scene_id!r}: no ground-truth labels at {src.ground_truth('labels.json')} "
                                "(instance_source=ground_truth needs a synthetic scene)")
    canon_to_source = np.asarray(src.read_ground_truth("transform.json")["canonical_to_source"])
    source_to_aligned = np.asarray(catalog.dataset("alignment", scene).load()["source_to_aligned"])
    labels = labels["labels"]
    return transform_labels(labels, source_to_aligned @ canon_to_source)


def labels_to_table(labels: list[dict], support: dict[int, int] | None = None) -> pa.Table:
    """labels.json entries -> an INSTANCE_SCHEMA table."""
    nan = float("nan")
    cols = {f.name: [] for f in INSTANCE_SCHEMA}
    for lab in labels:
        box = lab.get("bounding_box") or {"min": [nan] * 3, "max": [nan] * 3}
        cols["instance_id"].append(int(lab["instance_id"]))
        cols["category"].append(lab["category"])
        for k, v in zip("xyz", lab["position"]):
            cols[f"center_{k}"].append(float(v))
        for k, lo, hi in zip("xyz", box["min"], box["max"]):
            cols[f"min_{k}"].append(float(lo))
            cols[f"max_{k}"].append(float(hi))
        cols["support"].append(int((support or {}).get(int(lab["instance_id"]), 0)))
        cols["confidence"].append(float(lab.get("confidence", 1.0)))
        cols["source"].append(lab.get("source", "ground_truth"))
        cols["dataset_class"].append(lab.get("dataset_class"))
        cols["views"].append(lab.get("views"))
        cols["agreement"].append(lab.get("agreement"))
    return pa.table(cols, schema=INSTANCE_SCHEMA)


def table_to_labels(table: pa.Table) -> list[dict]:
    """An INSTANCE_SCHEMA table -> labels.json entries (inverse of labels_to_table; NaN box = null)."""
    out = []
    for r in table.to_pylist():
        lo, hi = [r[f"min_{k}"] for k in "xyz"], [r[f"max_{k}"] for k in "xyz"]
        box = None if any(np.isnan(lo + hi)) else {"min": lo, "max": hi}
        out.append({"instance_id": r["instance_id"], "category": r["category"],
                    "position": [r[f"center_{k}"] for k in "xyz"], "bounding_box": box,
                    "confidence": r["confidence"], "source": r["source"], "dataset_class": r.get("dataset_class"),
                    **{k: r[k] for k in ("views", "agreement") if r.get(k) is not None}})
    return out


def ground_truth_instances(scene, catalog) -> pa.Table:
    """The instance table of a synthetic scene from its ground truth (support = its Gaussians)."""
    ids = catalog.dataset("source_synthetic", scene).read_ground_truth("instance_ids.npy", np.zeros(0, int))
    u, c = np.unique(ids[ids > 0], return_counts=True)
    return labels_to_table(ground_truth_labels(scene, catalog), dict(zip(u.tolist(), c.tolist())))


def load_instances(scene, catalog, source: str) -> pa.Table:
    """A scene's instance table: 'ground_truth' (synthetic scenes) or 'model_predicted' (written by
    the semantics stage to the `instances` dataset)."""
    if source == "ground_truth":
        return ground_truth_instances(scene, catalog)
    if source == "model_predicted":
        ds = catalog.dataset("instances", scene)
        if not ds.exists():
            raise FileNotFoundError(f"scene {scene.scene_id!r}: no predicted instance table at {ds.path}; run the "
                                    "semantics stage or set task.objectnav.instance_source=ground_truth")
        table = ds.load()
        return table.cast(INSTANCE_SCHEMA) if "dataset_class" in table.column_names else _with_dataset_class(table)
    raise ValueError(f"unknown instance source {source!r} (ground_truth | model_predicted)")


def _with_dataset_class(table: pa.Table) -> pa.Table:
    """A table written before the dataset_class column existed, in today's schema."""
    return table.append_column("dataset_class", pa.nulls(len(table), pa.string())).cast(INSTANCE_SCHEMA)


# ---- ground truth shipped with real datasets ------------------------------------------------------

LABEL_FILE = "labels.json"


def label_file_for(source_path: str | Path) -> Path | None:
    """A labels.json shipped beside a scene: in its folder (npy or SOG folder) or next to its file."""
    p = Path(source_path)
    folder = p if p.is_dir() else p.parent
    return folder / LABEL_FILE if (folder / LABEL_FILE).is_file() else None


def _corners(box) -> np.ndarray:
    """[K, 3] points of a box given as {min, max}, a list of {x, y, z} or a list of [x, y, z]."""
    if isinstance(box, dict) and "min" in box:
        return np.array([box["min"], box["max"]], float)
    return np.array([[c["x"], c["y"], c["z"]] if isinstance(c, dict) else c for c in box], float)


def read_label_file(path: str | Path, vocab: GoalVocabulary | None = None) -> list[dict]:
    """labels.json entries (source frame) from NavArena's layout ({labels: [{instance_id, category,
    position, bounding_box {min, max}}]}) or InteriorGS's (a list of {ins_id, label, bounding_box:
    eight corners as {x, y, z}}); categories through the goal vocabulary, source ground_truth."""
    vocab = vocab or GoalVocabulary()
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: unreadable labels file ({e})") from None
    items = data.get("labels", []) if isinstance(data, dict) else data
    out = []
    for k, it in enumerate(items):
        try:
            name = it.get("category", it.get("label", it.get("name")))
            box = it.get("bounding_box") or it.get("bbox")
            pts = _corners(box) if box else None
            pos = it.get("position") or (pts.mean(0).tolist() if pts is not None else None)
            if name is None or pos is None:
                raise KeyError("category/label and position/bounding_box")
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise ValueError(f"{path}: label entry {k} is not one this reader knows ({e})") from None
        raw_id = it.get("instance_id", it.get("ins_id", it.get("id", k + 1)))
        iid = int(raw_id) if str(raw_id).lstrip("-").isdigit() else k + 1
        out.append({"instance_id": iid, "category": vocab.category_of(name), "dataset_class": as_category(name),
                    "position": list(map(float, pos)),
                    "bounding_box": None if pts is None else {"min": pts.min(0).tolist(), "max": pts.max(0).tolist()},
                    "confidence": 1.0, "source": "ground_truth"})
    return out


def gaussian_labels(scene, aligned, source_to_aligned: np.ndarray, report: LabelReport | None = None):
    """Per-Gaussian ground-truth labels of a real scene: SceneSplat instance / segment arrays
    (extras of the aligned Gaussians) with their class table, else the catalog entry's labelled
    mesh transferred to the Gaussians; None when the scene ships neither.

    Returns:
        (instance [N], segment [N], class table or None) and `report` filled in (origin, label
        set, transfer figures, a warning when the class table is missing).
    """
    report = report if report is not None else LabelReport()
    spec = getattr(scene, "labels", None)
    folder = Path(scene.path) if Path(scene.path).is_dir() else Path(scene.path).parent
    if "instance" in aligned.extras and "segment" in aligned.extras:
        names = class_table(spec, folder)
        if names is None:
            report.warnings.append(missing_table_warning(scene, folder))
        report.origin = "scenesplat instance.npy / segment.npy"
        report.label_set = names.name if names is not None else "none (class_<id>)"
        return aligned.extras["instance"], aligned.extras["segment"], names
    if spec is not None and spec.mesh:
        mesh_path = spec.path(spec.mesh)
        classes = resolve(spec.mesh_classes or spec.classes, Path(spec.base) if spec.base else None) \
            if (spec.mesh_classes or spec.classes) else None
        geom = read_labelled_geometry(mesh_path, classes)
        geom.vertices = geom.vertices @ source_to_aligned[:3, :3].T + source_to_aligned[:3, 3]
        seg, ins, dist = transfer(geom, aligned.means, spec.max_distance)
        report.origin, report.label_set = f"{mesh_path} ({geom.kind})", geom.names.name
        report.transfer = {"max_distance_m": spec.max_distance, "beyond_bound": int((dist > spec.max_distance).sum()),
                           "median_distance_m": round(float(np.median(dist)), 4) if len(dist) else None}
        return ins, seg, geom.names
    return None


def shipped_instances(scene, aligned, source_to_aligned: np.ndarray, vocab: GoalVocabulary | None = None,
                      cleaning: CleaningConfig | None = None, ceiling: float | None = None
                      ) -> tuple[pa.Table, str, LabelReport] | None:
    """The instance table (source ground_truth, aligned frame) from labels a real scene ships, in
    this order: per-Gaussian labels (`gaussian_labels`: SceneSplat arrays, or the catalog entry's
    labelled mesh or point cloud), a labels.json beside the scene; None when there are none
    (synthetic scenes use their own truth).

    Args:
        scene: the catalog entry (its `labels` LabelSpec, if any). aligned: the aligned Gaussians.
        source_to_aligned: [4, 4]. vocab: goal vocabulary. cleaning: instance cleaning.
        ceiling: floor-to-ceiling height of the aligned scene, metres (None: no ceiling test).
    Returns:
        (table, where the labels came from, LabelReport).
    """
    if scene.synthetic:
        return None
    vocab, cleaning = vocab or GoalVocabulary(), cleaning or CleaningConfig()
    report = LabelReport()
    per_gaussian = gaussian_labels(scene, aligned, source_to_aligned, report)
    if per_gaussian is not None:
        ins, seg, names = per_gaussian
        labels, support = instances_from_gaussians(aligned.means, aligned.alphas, ins, seg, names, vocab, cleaning, ceiling, report)
        return labels_to_table(labels, support), report.origin, report
    f = label_file_for(scene.path)
    if f is None:
        return None
    report.origin = str(f)
    labels = read_label_file(f, vocab)
    for lab in labels:
        report.count_goal(vocab, lab["dataset_class"])
    return labels_to_table(transform_labels(labels, source_to_aligned)), str(f), report
