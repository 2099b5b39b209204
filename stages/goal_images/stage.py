"""Stage `goal_images`: the ImageNav goal views, rendered at each episode's stored goal camera.

Canonical store: data/05_goal_images/task=imagenav/scene_id={id}/part-0.parquet, one row per
episode (episode_id, width, height, jpeg bytes), joinable with the episodes table on episode_id;
the NavArena export writes them out as goal_images/{episode_id}_goal.jpg.
"""
from __future__ import annotations

import io
import json
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
from omegaconf import OmegaConf

from navcore.gaussians.content import camera_scene

GOAL_IMAGE_SCHEMA = pa.schema([pa.field("episode_id", pa.string()), pa.field("width", pa.int32()),
                               pa.field("height", pa.int32()), pa.field("jpeg", pa.binary())])


@dataclass
class GoalImagesConfig:
    """ImageNav goal images."""

    enabled: bool = False
    """Render them (off by default: milliseconds an image with gsplat, ~1.5 s at 640x480 with the
    CPU renderer; the environment renders the goal view at reset either way)."""
    renderer: str = "auto"
    """auto (gsplat on CUDA, else the CPU renderer) | cpu | gsplat."""
    quality: int = 95
    """JPEG quality."""
    batch: int = 16
    """Views per render call."""


def render_goal_images(gs, cameras: list[dict], backend: str = "auto", batch: int = 16):
    """Goal cameras (episodes' goal_camera_json) -> list of HxWx3 uint8 images, `batch` views per
    render call (consecutive cameras of one image size and field of view share a call)."""
    from navcore.render import Renderer
    from navcore.render.camera import intrinsics, viewmats

    r = Renderer(gs, backend)
    out = []
    k = 0
    while k < len(cameras):
        size = lambda c: (c["width"], c["height"], c["hfov_deg"])  # noqa: E731
        group = [cameras[k]]
        while len(group) < batch and k + len(group) < len(cameras) and size(cameras[k + len(group)]) == size(group[0]):
            group.append(cameras[k + len(group)])
        vm = np.concatenate([viewmats(np.array([[c["position"][0], c["position"][1], c["yaw"]]]), c["position"][2],
                                      c["pitch_deg"]) for c in group])
        w, h, hfov = size(group[0])
        kk = np.repeat(intrinsics(w, h, hfov)[None], len(group), 0)
        rgb = r.render(vm, kk, w, h).rgb
        out += list((rgb.clamp(0, 1) * 255 + 0.5).to("cpu").numpy().astype(np.uint8))
        k += len(group)
    return out


def run(scene, cfg, catalog) -> dict:
    from PIL import Image

    gcfg: GoalImagesConfig = OmegaConf.to_object(cfg.goal_images)
    out = catalog.dataset("goal_images", scene, task="imagenav")
    src = catalog.dataset("episodes", scene, task="imagenav")
    if not gcfg.enabled or not src.exists():
        out.delete()
        return {"outputs": [], "images": 0, "enabled": gcfg.enabled}
    eps = src.load(["episode_id", "goal_camera_json"]).to_pylist()
    gs, _ = camera_scene(catalog, scene, cfg.embodiment.name)  # less the floaters the robot drives through
    cams = [json.loads(e["goal_camera_json"]) for e in eps]
    imgs = render_goal_images(gs, cams, gcfg.renderer, gcfg.batch)
    jpegs = []
    for img in imgs:
        buf = io.BytesIO()
        Image.fromarray(img).save(buf, format="JPEG", quality=gcfg.quality)
        jpegs.append(buf.getvalue())
    table = pa.table({"episode_id": [e["episode_id"] for e in eps], "width": [c["width"] for c in cams],
                      "height": [c["height"] for c in cams], "jpeg": jpegs}, schema=GOAL_IMAGE_SCHEMA)
    out.save(table, compression="none")  # JPEG does not compress further
    return {"outputs": [str(out.path)], "images": len(jpegs)}
