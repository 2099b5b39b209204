"""The per-scene instance table: object instances that may become ObjectNav goals.

One schema, shared by its writers (the semantics stage: source "model_predicted"; the ground truth
of synthetic scenes: "ground_truth") and its readers (the episodes stage, the asset's labels.json).
All coordinates are in the scene's aligned frame (z up, floor at z = 0), metres.
"""
from __future__ import annotations

import json

import numpy as np
import pyarrow as pa

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
    gt = catalog.path("source_synthetic", scene) / "ground_truth"
    if not (gt / "labels.json").exists():
        raise FileNotFoundError(f"scene {scene.scene_id!r}: no ground-truth labels at {gt / 'labels.json'} "
                                "(instance_source=ground_truth needs a synthetic scene)")
    canon_to_source = np.asarray(json.loads((gt / "transform.json").read_text())["canonical_to_source"])
    source_to_aligned = np.asarray(json.loads(catalog.path("alignment", scene).read_text())["source_to_aligned"])
    labels = json.loads((gt / "labels.json").read_text())["labels"]
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
    return pa.table(cols, schema=INSTANCE_SCHEMA)


def table_to_labels(table: pa.Table) -> list[dict]:
    """An INSTANCE_SCHEMA table -> labels.json entries (inverse of labels_to_table; NaN box = null)."""
    out = []
    for r in table.to_pylist():
        lo, hi = [r[f"min_{k}"] for k in "xyz"], [r[f"max_{k}"] for k in "xyz"]
        box = None if any(np.isnan(lo + hi)) else {"min": lo, "max": hi}
        out.append({"instance_id": r["instance_id"], "category": r["category"],
                    "position": [r[f"center_{k}"] for k in "xyz"], "bounding_box": box,
                    "confidence": r["confidence"], "source": r["source"]})
    return out


def ground_truth_instances(scene, catalog) -> pa.Table:
    """The instance table of a synthetic scene from its ground truth (support = its Gaussians)."""
    gt = catalog.path("source_synthetic", scene) / "ground_truth"
    ids = np.load(gt / "instance_ids.npy") if (gt / "instance_ids.npy").exists() else np.zeros(0, int)
    u, c = np.unique(ids[ids > 0], return_counts=True)
    return labels_to_table(ground_truth_labels(scene, catalog), dict(zip(u.tolist(), c.tolist())))


def load_instances(scene, catalog, source: str) -> pa.Table:
    """A scene's instance table: 'ground_truth' (synthetic scenes) or 'model_predicted' (written by
    the semantics stage to the `instances` dataset)."""
    if source == "ground_truth":
        return ground_truth_instances(scene, catalog)
    if source == "model_predicted":
        import pyarrow.parquet as pq

        path = catalog.path("instances", scene)
        if not path.exists():
            raise FileNotFoundError(f"scene {scene.scene_id!r}: no predicted instance table at {path}; run the "
                                    "semantics stage or set task.objectnav.instance_source=ground_truth")
        return pq.read_table(path, schema=INSTANCE_SCHEMA)
    raise ValueError(f"unknown instance source {source!r} (ground_truth | model_predicted)")
