"""Stage `screen`: per scene, the reconstruction-quality layer on the main embodiment's costmap
grid (stages/screen/quality.py) -> 03_costmaps/screen/{scene_id}.zarr, its top-down picture, and
the scene's quality score (the episodes stage gives the verdict and keeps episodes out of the
flagged cells)."""
from __future__ import annotations

import numpy as np
from omegaconf import OmegaConf

from navcore.gaussians.cameras import camera_file, read_cameras
from navcore.gaussians.content import camera_scene, content_of
from navcore.io.map_picture import FRAME_NOTE, annotated
from stages.screen.quality import QualityConfig, scene_score, screen_layers

# top-down picture colours: outside the supported map, obstacles, blobs, holes, view flags, unseen (free cells white)
_OUTSIDE, _OBSTACLE, _BLUR, _HOLE, _VIEW, _UNSEEN = \
    (230, 190, 190), (60, 60, 60), (255, 0, 255), (80, 120, 255), (255, 150, 0), (220, 200, 0)


def picture(layers: dict, support: np.ndarray, valid: np.ndarray, view: dict | None, origin, resolution: float) -> np.ndarray:
    """[ny, nx, 3] uint8, north up: obstacles dark, blobs magenta, floor holes blue, cells flagged
    by the rendered views orange, cells no capture camera saw yellow (valid cells only); the
    lattice poses as green dots, black where their worst view is mostly blur."""
    img = np.full(support.shape + (3,), 255, np.uint8)
    img[~support] = _OUTSIDE
    img[support & ~valid] = _OBSTACLE
    img[layers["unseen"] & valid] = _UNSEEN
    img[layers["view_blur"] & valid] = _VIEW
    img[layers["view_hole"] & valid] = _VIEW
    img[layers["hole"] & valid] = _HOLE
    img[layers["blur"] & valid] = _BLUR
    if view is not None and len(view["poses"]):
        cells = np.floor((view["poses"] - np.asarray(origin)) / resolution).astype(int)
        for (j, i), b in zip(cells, view["blur"]):
            img[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2] = (0, 0, 0) if b >= 0.5 else (0, 160, 0)
    return img[::-1]


SCREEN_LEGEND = [((255, 255, 255), "valid cell, nothing flagged"),
                 (_OBSTACLE, "obstacle or within the robot's radius (not a valid cell)"),
                 (_OUTSIDE, "unsupported: no floor seen"),
                 (_BLUR, "blob: floor under a blurry blob (episodes avoid it)"),
                 (_HOLE, "floor hole (episodes avoid it)"),
                 (_VIEW, "rendered views from here mostly blur or holes (avoided)"),
                 (_UNSEEN, "no capture camera saw it (scenes with cameras)"),
                 ((0, 160, 0), "dot: a pose whose views were rendered, its worst view fine"),
                 ((0, 0, 0), "black dot: a pose whose worst view is mostly blur")]


def screen_picture(layers: dict, support, valid, view, origin, resolution: float, verdict_note: str) -> np.ndarray:
    """The screening picture: `picture` enlarged, a scale bar, its legend and what a verdict means."""
    return annotated(picture(layers, support, valid, view, origin, resolution), resolution, SCREEN_LEGEND,
                     note=f"{verdict_note}\n{FRAME_NOTE}")


def run(scene, cfg, catalog) -> dict:
    qcfg: QualityConfig = OmegaConf.to_object(cfg.screen.layer)
    emb = OmegaConf.to_object(cfg.embodiment)
    costmaps = catalog.dataset("costmaps", scene)
    cm = costmaps.load(emb.name)
    raw, _, _ = costmaps.load_layers(emb.name)
    support = np.asarray(raw["support"], bool)
    valid = ~cm.occupancy & support
    aligned = catalog.dataset("aligned", scene).load(view_dependent=False)
    content = content_of(aligned[0])
    camera, _ = camera_scene(catalog, scene, emb.name, loaded=aligned)
    cams = camera_file(scene, catalog) if qcfg.cameras else None
    capture = None
    if cams is not None:
        w, h = qcfg.camera_width, qcfg.camera_width * 3 // 4
        c2w, ks = read_cameras(cams, w, h)
        capture = (catalog.dataset("aligned", scene).transform() @ c2w, ks, w, h)
    out = screen_layers(content, camera, valid, cm.origin, cm.resolution, emb, qcfg, capture)
    view = out.pop("view")
    rendered = out.pop("views")
    score = scene_score(out, valid, cm.resolution)
    arrays = dict(out)
    if view is not None:
        arrays |= {"view_poses": view["poses"], "view_blur_share": view["blur"], "view_hole_share": view["hole"]}
    ds = catalog.dataset("quality", scene)
    with ds.writing() as root:
        ds.write(root, arrays, {"origin": list(map(float, cm.origin)), "resolution": cm.resolution,
                                "embodiment": emb.name, **score, "views_rendered": rendered,
                                "capture_cameras": 0 if capture is None else len(capture[0])})
    pic = catalog.dataset("quality_picture", scene)
    pic.save(screen_picture(out, support, valid, view, cm.origin, cm.resolution,
                            f"score {score['score']:.2f}: the share of valid cells not flagged\n"
                            "warn: the scene is kept, its episodes avoid the flagged cells\n"
                            "reject: dropped when screen.reject=true"))
    # the run summary's screening table shows the score at once; the verdict is the episodes stage's
    screening = {k: v for k, v in score.items() if k == "score" or k.endswith("_share")}
    return {"outputs": [str(ds.path), str(pic.path)], "quality": score, "views_rendered": rendered,
            "capture_cameras": 0 if capture is None else len(capture[0]),
            "screening": screening | {"verdict": None, "kept": None}}
