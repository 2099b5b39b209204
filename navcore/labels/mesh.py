"""Labelled geometry beside the splats (`labels.mesh`), transferred to the Gaussians.

Readers (PLY through trimesh's parser, which keeps every element property):
- ScanNet: `<scene>_vh_clean_2.labels.ply` (vertex `label`: NYU40 raw id) with, in its folder,
  `<scene>_vh_clean_2.0.010000.segs.json` (`segIndices` per vertex) and
  `<scene>.aggregation.json` / `<scene>_vh_clean.aggregation.json` (`segGroups`: objectId, raw
  category `label`, segments): instance = objectId + 1, class = the group's raw category; vertices
  in no group keep the NYU40 class of `label` and no instance.
- Replica / habitat: `mesh_semantic.ply` (face `object_id`, polygons) with `info_semantic.json`
  beside it (`objects`: id, class_id / class_name; `classes`: id, name).
- Any PLY mesh or point cloud with per-vertex class ids (`label`, `class`, `semantic`,
  `category_id`) and instance ids (`instance`, `instance_id`, `objectId`, `object_id`); class ids
  named by `labels.mesh_classes` (or `labels.classes`).

Transfer (`transfer`): each Gaussian centre takes the labels of its nearest surface point (open3d
RaycastingScene closest-point query on the triangles; the triangle's nearest vertex for vertex
labels) or, for a point cloud, of its nearest point (open3d NearestNeighborSearch), when that is
within `max_distance`; farther Gaussians stay unlabelled (counted in the report).
"""
from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from navcore.labels import LabelSet, builtin

CLASS_PROPS = ("label", "class", "semantic", "category_id", "semantic_id")
INSTANCE_PROPS = ("instance", "instance_id", "objectid", "object_id")


@dataclass
class LabelledGeometry:
    """Vertices [V, 3]; triangles [F, 3] (None: a point cloud); per-vertex or per-triangle
    class index (into `names`, -1 none) and instance id (-1 none)."""

    vertices: np.ndarray
    triangles: np.ndarray | None
    segment: np.ndarray
    instance: np.ndarray
    names: LabelSet
    per_face: bool = False
    kind: str = "ply"


def _ply_raw(path: Path) -> dict:
    from navcore.optional import require

    trimesh = require("trimesh", "reading a labelled mesh")

    try:
        data = path.read_bytes()
        m = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
    except Exception as e:  # noqa: BLE001 - any parser error is a bad file
        raise ValueError(f"{path}: not a readable PLY mesh / point cloud ({type(e).__name__}: {e})") from None
    raw = getattr(m, "metadata", {}).get("_ply_raw")
    if not raw or "vertex" not in raw:
        raise ValueError(f"{path}: PLY has no vertex element")
    return raw


def _col(element: dict, names) -> np.ndarray | None:
    props = {k.lower(): k for k in element["data"]}
    for n in names:
        if n in props:
            return np.asarray(element["data"][props[n]]).reshape(-1)
    return None


def _triangulate(faces) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangulation of polygon index lists: (triangles [F, 3], source face of each)."""
    tris, src = [], []
    for k, f in enumerate(faces):
        f = np.asarray(f).reshape(-1)
        for j in range(1, len(f) - 1):
            tris.append((f[0], f[j], f[j + 1]))
            src.append(k)
    return np.asarray(tris, np.int64).reshape(-1, 3), np.asarray(src, np.int64)


def _per_value(values: np.ndarray, fn, dtype=np.int64) -> np.ndarray:
    """fn applied once per distinct value of `values` (ids repeat over many vertices / faces)."""
    u, inv = np.unique(np.asarray(values).reshape(-1), return_inverse=True)
    return np.array([fn(v) for v in u.tolist()], dtype=dtype)[inv]


def _names_from(values: list[str]) -> tuple[LabelSet, dict[str, int]]:
    uniq = sorted(set(values))
    return LabelSet("mesh", tuple(uniq)), {n: i for i, n in enumerate(uniq)}


def _scannet_side_files(path: Path) -> tuple[Path | None, Path | None]:
    stem = re.sub(r"_vh_clean_2(\.labels)?$", "", path.name[:-len(".ply")])
    folder = path.parent
    segs = sorted(folder.glob(f"{stem}_vh_clean_2*.segs.json"))
    agg = [p for p in (folder / f"{stem}.aggregation.json", folder / f"{stem}_vh_clean.aggregation.json") if p.is_file()]
    return (segs[0] if segs else None), (agg[0] if agg else None)


def side_files(path: Path) -> list[Path]:
    """The files beside a labelled mesh that its reader also takes (those that exist)."""
    path = Path(path)
    out = [p for p in _scannet_side_files(path) if p is not None] if path.name.endswith(".ply") else []
    info = path.parent / "info_semantic.json"
    return out + ([info] if info.is_file() else [])


def read_labelled_geometry(path: str | Path, classes: LabelSet | None = None) -> LabelledGeometry:
    """A labelled mesh / point cloud (module doc), in its own frame. A malformed file (or side
    file) is a ValueError naming it."""
    path = Path(path)
    try:
        geom = _read_labelled_geometry(path, classes)
        n = len(geom.triangles) if geom.per_face else len(geom.vertices)
        if geom.per_face and not n:
            raise ValueError(f"{path}: labels per face, but the mesh has no faces")
        if not len(geom.vertices) or not np.isfinite(geom.vertices).all():
            raise ValueError(f"{path}: no vertices, or vertices that are not finite numbers")
        if len(geom.segment) != n or len(geom.instance) != n:
            raise ValueError(f"{path}: {len(geom.segment)} class and {len(geom.instance)} instance ids for its {n} "
                             f"{'faces' if geom.per_face else 'vertices'}")
        return geom
    except FileNotFoundError:
        raise
    except ValueError as e:
        if str(path.parent) in str(e):
            raise
        raise ValueError(f"{path} (or a side file beside it): malformed labels ({e})") from None
    except (KeyError, TypeError, AttributeError, IndexError, OverflowError, RecursionError) as e:
        raise ValueError(f"{path} (or a side file beside it): malformed labels ({type(e).__name__}: {e})") from None


def _read_labelled_geometry(path: Path, classes: LabelSet | None) -> LabelledGeometry:
    from navcore.labels.shipped import read_json

    if not path.is_file():
        raise FileNotFoundError(f"labels.mesh: {path} does not exist")
    raw = _ply_raw(path)
    v = raw["vertex"]["data"]
    try:
        verts = np.column_stack([np.asarray(v[k]).reshape(-1) for k in ("x", "y", "z")]).astype(np.float64)
    except KeyError:
        raise ValueError(f"{path}: PLY vertices lack x / y / z") from None
    tris, src = (None, None)
    if "face" in raw and len(raw["face"]["data"]):
        fdata = raw["face"]["data"]
        key = next((k for k in fdata if k.lower() in ("vertex_indices", "vertex_index")), None)
        if key is not None:
            tris, src = _triangulate(fdata[key])
            if len(tris) and (tris.max() >= len(verts) or tris.min() < 0):
                raise ValueError(f"{path}: a face indexes past the {len(verts)} vertices")
    # Replica / habitat: per-face object ids named by info_semantic.json
    info = path.parent / "info_semantic.json"
    face_obj = _col(raw["face"], ("object_id",)) if "face" in raw and tris is not None else None
    if face_obj is not None and info.is_file():
        meta = read_json(info)
        cls_name = {int(c["id"]): str(c["name"]) for c in meta.get("classes", [])}
        obj_cls = {}
        for o in meta.get("objects", []):
            n = o.get("class_name") or cls_name.get(int(o.get("class_id", -1)))
            if n:
                obj_cls[int(o["id"])] = str(n)
        names, index = _names_from(list(obj_cls.values()))
        seg_face = _per_value(face_obj, lambda o: index.get(obj_cls.get(int(o), ""), -1))
        inst_face = np.where(seg_face >= 0, face_obj.astype(np.int64), -1)
        return LabelledGeometry(verts, tris, seg_face[src], inst_face[src], names, per_face=True, kind="replica")
    # ScanNet: segments grouped into objects by the aggregation file
    segs, agg = _scannet_side_files(path) if path.name.endswith(".ply") else (None, None)
    if segs is not None and agg is not None:
        seg_idx = np.asarray(read_json(segs)["segIndices"], np.int64)
        if len(seg_idx) != len(verts):
            raise ValueError(f"{segs}: {len(seg_idx)} segment indices for the {len(verts)} vertices of {path}")
        groups = read_json(agg).get("segGroups", [])
        names, index = _names_from([str(g["label"]) for g in groups])
        seg_to = {}
        for g in groups:
            for s in g["segments"]:
                seg_to[int(s)] = (index[str(g["label"])], int(g.get("objectId", g.get("id"))) + 1)
        segment = _per_value(seg_idx, lambda s: seg_to.get(int(s), (-1, -1))[0])
        instance = _per_value(seg_idx, lambda s: seg_to.get(int(s), (-1, -1))[1])
        nyu = _col(raw["vertex"], ("label",))
        if nyu is not None:  # vertices in no group: their NYU40 class, no instance
            table = builtin("nyu40")
            name_of = lambda c: table.lookup(int(c) - 1) if c > 0 else None  # noqa: E731
            free = segment < 0
            missing = sorted({n for c in np.unique(nyu[free]).tolist() if (n := name_of(c))} - set(index))
            if missing:
                names = LabelSet("mesh", names.names + tuple(missing))
                index.update({n: len(index) + i for i, n in enumerate(missing)})
            segment = np.where(free, _per_value(nyu, lambda c: index.get(name_of(c), -1)), segment)
        return LabelledGeometry(verts, tris, segment, instance, names, kind="scannet")
    # generic: per-vertex class / instance ids
    cls = _col(raw["vertex"], CLASS_PROPS)
    ins = _col(raw["vertex"], INSTANCE_PROPS)
    if cls is None and ins is None:
        raise ValueError(f"{path}: no per-vertex class ({', '.join(CLASS_PROPS)}) or instance "
                         f"({', '.join(INSTANCE_PROPS)}) property, and no ScanNet / Replica side files")
    if classes is None:
        raise ValueError(f"{path}: per-vertex class ids need a class table: set labels.mesh_classes (or labels.classes)")
    cls = np.full(len(verts), -1) if cls is None else cls.astype(np.int64)
    segment = _per_value(cls, lambda c: -1 if (n := classes.lookup(int(c))) is None else classes.names.index(n))
    names = LabelSet(classes.name, classes.names, 0, (), classes.source)
    return LabelledGeometry(verts, tris, segment, (np.full(len(verts), -1) if ins is None else ins.astype(np.int64)),
                            names)


def transfer(geom: LabelledGeometry, points: np.ndarray, max_distance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Labels of the nearest labelled surface point per query point.

    Returns:
        (segment [N] class index into geom.names or -1, instance [N] or -1, distance [N] metres).
        Points farther than max_distance get -1 for both.
    """
    from navcore.optional import require

    o3d = require("open3d", "transferring labels from a mesh")

    q = np.ascontiguousarray(points, np.float32)
    if geom.triangles is not None and len(geom.triangles):
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(geom.vertices.astype(np.float32)),
                            o3d.core.Tensor(geom.triangles.astype(np.uint32)))
        ans = scene.compute_closest_points(o3d.core.Tensor(q))
        hit = ans["points"].numpy().astype(np.float64)
        tri = ans["primitive_ids"].numpy().astype(np.int64)
        dist = np.linalg.norm(hit - q, axis=1)
        if geom.per_face:
            seg, ins = geom.segment[tri], geom.instance[tri]
        else:  # the triangle's vertex nearest to the closest point
            corners = geom.triangles[tri]
            d = np.linalg.norm(geom.vertices[corners] - hit[:, None, :], axis=2)
            vid = corners[np.arange(len(q)), d.argmin(1)]
            seg, ins = geom.segment[vid], geom.instance[vid]
    else:
        nns = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(geom.vertices.astype(np.float32)))
        nns.knn_index()
        idx, d2 = nns.knn_search(o3d.core.Tensor(q), 1)
        vid = idx.numpy()[:, 0].astype(np.int64)
        dist = np.sqrt(d2.numpy()[:, 0].astype(np.float64))
        seg, ins = geom.segment[vid], geom.instance[vid]
    far = dist > max_distance
    return np.where(far, -1, seg), np.where(far, -1, ins), dist
