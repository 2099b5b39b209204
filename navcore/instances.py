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
        return ds.load(schema=INSTANCE_SCHEMA)
    raise ValueError(f"unknown instance source {source!r} (ground_truth | model_predicted)")


# ---- ground truth shipped with real datasets ------------------------------------------------------

LABEL_FILE = "labels.json"
SCENESPLAT_LABELS = ("instance.npy", "segment.npy")
CLASS_NAME_FILES = ("classes.txt", "class_names.txt")
CATEGORY_ALIASES = {  # keys: lower case, spaces
    "couch": "sofa", "sofa chair": "chair", "armchair": "chair", "office chair": "chair", "tv": "tv_monitor",
    "television": "tv_monitor", "monitor": "tv_monitor", "tv monitor": "tv_monitor", "potted plant": "plant",
    "potted_plant": "plant", "flowerpot": "plant", "dining table": "table", "desk": "table", "coffee table": "table",
    "cupboard": "cabinet", "wardrobe": "cabinet", "kitchen cabinet": "cabinet", "toilet seat": "toilet",
}


def canonical_category(name: str) -> str:
    """A dataset's class name in our vocabulary (lower case, aliases such as couch -> sofa)."""
    n = " ".join(str(name).strip().lower().replace("-", " ").replace("_", " ").split())
    return CATEGORY_ALIASES.get(n, n.replace(" ", "_"))


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


def read_label_file(path: str | Path) -> list[dict]:
    """labels.json entries (source frame) from NavArena's layout ({labels: [{instance_id, category,
    position, bounding_box {min, max}}]}) or InteriorGS's (a list of {ins_id, label, bounding_box:
    eight corners as {x, y, z}}); categories mapped by canonical_category, source ground_truth."""
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
        out.append({"instance_id": iid, "category": canonical_category(name), "position": list(map(float, pos)),
                    "bounding_box": None if pts is None else {"min": pts.min(0).tolist(), "max": pts.max(0).tolist()},
                    "confidence": 1.0, "source": "ground_truth"})
    return out


def class_names(folder: Path) -> list[str] | None:
    """Class names of a SceneSplat folder's segment.npy (one per line in classes.txt), if shipped."""
    for name in CLASS_NAME_FILES:
        if (folder / name).is_file():
            return [ln.strip() for ln in (folder / name).read_text().splitlines() if ln.strip()]
    return None


def labels_from_gaussians(means: np.ndarray, instance: np.ndarray, segment: np.ndarray,
                          names: list[str] | None) -> tuple[list[dict], dict[int, int]]:
    """Instance table entries from per-Gaussian labels (SceneSplat instance.npy / segment.npy).

    Args:
        means: [N, 3] centres (aligned frame).
        instance: [N] instance id per Gaussian (< 0: none).
        segment: [N] class index per Gaussian (the instance's category is its majority class).
        names: class index -> name (None: "class_{k}").
    Returns:
        (labels.json entries with the box of the 2nd-98th percentile of the centres, support per id).
    """
    labels, support = [], {}
    ok = instance >= 0
    for iid in np.unique(instance[ok]):
        sel = instance == iid
        cls = int(np.bincount(segment[sel][segment[sel] >= 0]).argmax()) if (segment[sel] >= 0).any() else -1
        if cls < 0:
            continue
        name = names[cls] if names is not None and cls < len(names) else f"class_{cls}"
        pts = means[sel].astype(np.float64)
        lo, hi = np.percentile(pts, [2, 98], axis=0)
        labels.append({"instance_id": int(iid), "category": canonical_category(name),
                       "position": ((lo + hi) / 2).tolist(), "bounding_box": {"min": lo.tolist(), "max": hi.tolist()},
                       "confidence": 1.0, "source": "ground_truth"})
        support[int(iid)] = int(sel.sum())
    return labels, support


def shipped_instances(scene, aligned, source_to_aligned: np.ndarray) -> tuple[pa.Table, str] | None:
    """The instance table (source ground_truth, aligned frame) from labels a real scene ships:
    SceneSplat per-Gaussian instance / segment arrays (extras of the aligned Gaussians), else a
    labels.json beside the scene; None when there are none (synthetic scenes use their own truth).

    Returns:
        (table, where the labels came from).
    """
    if scene.synthetic:
        return None
    if "instance" in aligned.extras and "segment" in aligned.extras:
        labels, support = labels_from_gaussians(aligned.means, aligned.extras["instance"], aligned.extras["segment"],
                                                class_names(Path(scene.path)))
        return labels_to_table(labels, support), "scenesplat instance.npy / segment.npy"
    f = label_file_for(scene.path)
    if f is None:
        return None
    return labels_to_table(transform_labels(read_label_file(f), source_to_aligned)), str(f)
