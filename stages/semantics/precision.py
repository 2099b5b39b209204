"""Semantic precision against ground truth (the paper's valid-centre rate, and recall).

A predicted centre is valid when it lies inside the ground-truth region of an object of the
predicted category: the object's oriented box (objects.json of synthetic scenes: centre, size,
yaw about z, canonical frame). Recall: the share of ground-truth objects of the prompted
categories with at least one valid centre of their category inside.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from navcore.io.datasets import SyntheticSourceDataset


def inside_objects(points: np.ndarray, objects: list[dict], tol: float = 0.0) -> np.ndarray:
    """[M, K] bool: point m inside the oriented box of object k (grown by tol metres)."""
    p = np.asarray(points, float).reshape(-1, 3)
    out = np.zeros((len(p), len(objects)), bool)
    for k, o in enumerate(objects):
        c, s, yaw = np.asarray(o["center"]), np.asarray(o["size"]), o.get("yaw", 0.0)
        d = p - c
        ca, sa = np.cos(yaw), np.sin(yaw)
        local = np.column_stack([ca * d[:, 0] + sa * d[:, 1], -sa * d[:, 0] + ca * d[:, 1], d[:, 2]])
        out[:, k] = np.all(np.abs(local) <= s / 2 + tol, 1)
    return out


def score(pred: list[dict], objects: list[dict], categories: list[str], to_canonical: np.ndarray) -> dict:
    """Valid-centre and recall counts of predicted labels (labels.json entries, aligned frame)
    against ground-truth objects (canonical frame; `to_canonical` 4x4 aligned -> canonical)."""
    gt = [o for o in objects if o["category"] in categories]
    pos = np.array([p["position"] for p in pred], float).reshape(-1, 3)
    pos = pos @ to_canonical[:3, :3].T + to_canonical[:3, 3]
    inside = inside_objects(pos, gt)
    same = np.array([[p["category"] == o["category"] for o in gt] for p in pred], bool).reshape(len(pred), len(gt))
    hit = inside & same
    return {"predicted": len(pred), "valid": int(hit.any(1).sum()), "objects": len(gt),
            "found": int(hit.any(0).sum()), "invalid": [p for p, h in zip(pred, hit.any(1)) if not h]}


def ground_truth_objects(source_dir: Path) -> tuple[list[dict], np.ndarray]:
    """(objects.json objects, canonical -> source 4x4) of a synthetic scene's source folder."""
    src = SyntheticSourceDataset(source_dir)
    return (src.read_ground_truth("objects.json")["objects"],
            np.asarray(src.read_ground_truth("transform.json")["canonical_to_source"]))
