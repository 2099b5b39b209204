"""Stage `asset`: the NavArena V1 scene asset directory (NAVARENA_FORMATS.md section 1) of the
main embodiment: manifest.json, the original (source.ply, or its own files under source/:
asset.source), aligned.ply (or aligned.spz: asset.aligned_format), nav_map.pgm + nav_map.yaml (ROS
map_server), nav_mask.png, labels.json (the semantics stage's predicted instances, or the ground
truth of synthetic scenes: asset.labels; aligned frame), compressed.splat, costmap_topdown.png and
floor_side_view.png (the chosen floor over the Gaussian density); manifest.json also holds the
metric-scale evidence (floor-to-ceiling height, narrowest doorway-like gaps)."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from navcore.gaussians.formats import source_files, write_inria_ply, write_splat, write_spz
from navcore.gaussians.formats.ply import is_inria_ply
from navcore.instances import ground_truth_labels, load_instances, table_to_labels
from navcore.io.asset_files import COMPRESSED_SOURCES, aligned_file, write_pgm
from navcore.io.map_picture import topdown_picture
from navcore.io.stamps import build_time

NORMALIZER_VERSION = "navarena-0.1"


def asset_labels(scene, cfg, catalog) -> list[dict] | None:
    """labels.json entries of the asset (None: no labels.json)."""
    src = cfg.asset.labels
    if src == "model_predicted":
        return table_to_labels(load_instances(scene, catalog, src)) if cfg.semantics.enabled else None
    if src == "ground_truth":
        return ground_truth_labels(scene, catalog) if scene.synthetic else None
    if src == "none":
        return None
    raise ValueError(f"asset.labels={src!r}; choose model_predicted | ground_truth | none")


def compressed_source(report: dict) -> bool:
    """Whether the scene's original (the ingest report's source and format) is a compressed
    format (SPZ, SOG, .splat, SuperSplat's PLY): its asset then keeps the aligned model as SPZ
    under asset.aligned_format=auto, not as a PLY 6-13x the original."""
    fmt = report["format"]
    if fmt == "ply":  # either flavour: the header tells
        return not is_inria_ply(Path(report["source"]))
    return fmt in COMPRESSED_SOURCES


def asset_source(tmp, mode: str, report: dict, catalog, scene) -> tuple[str | None, list[str]]:
    """The asset's copy of the original (asset.source; report: the ingest report): (files.source_ply,
    the files that hold the original, relative to the asset)."""
    original = Path(report["source"])
    if mode == "none":
        return None, []
    if mode == "reference" and is_inria_ply(original):
        return tmp.reference("source.ply", original), ["source.ply"]
    if mode == "reference":
        folder, paths = source_files(original)
        return None, [tmp.reference(str(Path("source") / p.relative_to(folder)), p) for p in paths]
    if mode == "convert":
        write_inria_ply(tmp / "source.ply", catalog.dataset("scene", scene).load()[0])
        return "source.ply", ["source.ply"]
    raise ValueError(f"asset.source={mode!r}; choose reference | convert | none")


def aligned_from_source(cfg, report: dict, source_ply: str | None, catalog, scene, store_attrs: dict) -> dict:
    """The manifest's recipe of the aligned model under asset.aligned_format=source: the asset's
    link to the original (relative path), how ingest read it and the checksum of the Gaussians that
    gives (`navcore.io.asset_files.load_aligned`): a reference store's own (`store_attrs`, the
    aligned scene's attrs), else computed from a copy store's Gaussians."""
    import dataclasses

    from omegaconf import OmegaConf

    from navcore.gaussians.formats import source_files
    from navcore.gaussians.store import scene_checksum

    original = Path(report["source"])
    if source_ply:
        rel = source_ply
    else:
        folder, _ = source_files(original)
        rel = str(Path("source") / original.relative_to(folder))
    icfg = OmegaConf.to_object(cfg.ingest)
    checksum = store_attrs.get("checksum") or scene_checksum(catalog.dataset("scene", scene).load()[0])
    return {"path": rel, "format": report["format"], "level": icfg.lod_level, "scale": icfg.scale,
            "limits": dataclasses.asdict(icfg.limits), "checksum": checksum}


def run(scene, cfg, catalog) -> dict:
    out = catalog.dataset("asset", scene)
    aligned, aattrs = catalog.dataset("aligned", scene).load()
    t = np.asarray(aattrs["source_to_aligned"])
    emb = cfg.embodiment.name
    layers, eattrs, root_attrs = catalog.dataset("costmaps", scene).load_layers(emb)
    occ, sup, raw, comp = (layers[k] for k in ("occ", "support", "raw", "components"))
    res, origin = float(eattrs["resolution"]), list(eattrs["origin"])
    steps = []
    for stage in ("ingest", "voxelize", "align", "costmap"):
        m = catalog.dataset("markers", scene, stage=stage).load_or()
        if m is not None:
            steps.append({"name": stage, "status": "done", "duration_s": m.get("duration_s")})
    labels_file = None
    report = catalog.dataset("ingest_report", scene).load()
    with out.writing() as tmp:
        aligned_name = aligned_file(cfg.asset.aligned_format, compressed_source(report))
        if aligned_name is None and cfg.asset.source != "reference":
            raise ValueError(f"asset.aligned_format=source needs asset.source=reference (the asset's link to the "
                             f"original), not {cfg.asset.source!r}")
        files = {"source_ply": None, "aligned_ply": aligned_name if aligned_name and aligned_name.endswith(".ply") else None,
                 "aligned": aligned_name, "nav_map": "nav_map.pgm",
                 "nav_map_config": "nav_map.yaml", "nav_mask": "nav_mask.png", "labels": None, "structure": None,
                 "compressed_ply": None}
        files["source_ply"], original_files = asset_source(tmp, cfg.asset.source, report, catalog, scene)
        from_source = None
        if aligned_name is None:  # the original (linked above) read as ingest read it, then moved
            from_source = aligned_from_source(cfg, report, files["source_ply"], catalog, scene, aattrs)
        elif aligned_name.endswith(".spz"):
            write_spz(tmp / aligned_name, aligned, version=4)
        else:
            write_inria_ply(tmp / aligned_name, aligned)
        write_pgm(tmp / "nav_map.pgm", occ)
        tmp.text("nav_map.yaml",
            "image: nav_map.pgm\n" f"resolution: {res}\n" f"origin: [{origin[0]}, {origin[1]}, 0.0]\n"
            "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n")
        tmp.image("nav_mask.png", np.where(sup, 255, 0).astype(np.uint8)[::-1])
        pic = catalog.dataset("costmap_picture", scene)  # the costmap stage's (costmaps made before it: drawn here)
        if pic.exists():
            shutil.copyfile(pic.path, tmp / "costmap_topdown.png")
        else:
            tmp.image("costmap_topdown.png", topdown_picture(raw, sup, occ, comp, res, emb))
        side = catalog.dataset("floor_side_view", scene)
        if side.exists():  # the floor the align stage chose, over the Gaussian density
            shutil.copyfile(side.path, tmp / "floor_side_view.png")
        if cfg.asset.write_compressed_splat:
            write_splat(tmp / "compressed.splat", aligned)
            files["compressed_ply"] = "compressed.splat"
        labels = asset_labels(scene, cfg, catalog)
        if labels is not None:
            tmp.json("labels.json", {"schema_version": "1.0", "labels": labels})
            files["labels"] = labels_file = "labels.json"
        now = build_time()
        manifest = {
            "schema_version": "1.0", "scene_id": scene.scene_id,
            "source": {"dataset": scene.group, "subset": None, "original_id": scene.name,
                       "original_name": scene.name, "url": None, "license": None,
                       "format": report["format"], "files": original_files},
            "files": files,
            "map_info": {"resolution": res, "origin": [origin[0], origin[1], 0.0],
                         "size": [int(occ.shape[1]), int(occ.shape[0])]},
            "nav_region": {"area_m2": float((~occ).sum() * res * res), "method": "opacity_field_costmap",
                           "params": {"embodiment": emb, "radius": float(eattrs["radius"]),
                                      "h_min": float(eattrs["h_min"]), "h_max": float(eattrs["h_max"]),
                                      "tau_occ": float(cfg.voxelize.tau_occ)}},
            "processing": {"normalizer_version": NORMALIZER_VERSION, "processed_at": now, "normalized": True,
                           "extrinsic_matrix": t.tolist(), "steps": steps},
            **({"aligned_from_source": from_source} if from_source else {}),
            "scale": dict(root_attrs.get("scale", {})),  # metric sanity: floor-to-ceiling, doorway-like gaps
            "tags": [scene.group], "created_at": now, "updated_at": now,
        }
        tmp.json("manifest.json", manifest)
    return {"outputs": [str(out.path)], "labels": labels_file is not None}
