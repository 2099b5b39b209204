"""Furniture that looks like furniture, and the clutter of a lived-in room: detail parts added to a
layout after its furniture is placed, from their own random stream (the layout, its objects and
their boxes stay those of the seed).

- on the goal objects, inside their boxes (their instance id: goals keep their labels and boxes):
  pillows and a blanket on a bed, seat and back cushions on a sofa, a seat cushion on a chair;
- structure (instance 0, no goal category): things on tables (books, cups, vases, a bowl), things
  on the floor (boxes, baskets) and bookshelves with books against the walls, placed clear of
  doorways, furniture and each other so that every room stays passable.

Each detail carries the material its Gaussians are dressed with (stages/synthesize/materials.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import box as shp_box

from stages.synthesize.layout import Layout, Part


@dataclass
class Detail:
    part: Part
    look: str  # the material kind its Gaussians get (materials.MATERIALS)
    hue: float | None = None  # a colour hint (0..1 hue), or None for the material's own draw


def _local(obj, pc, size, yaw_extra: float = 0.0) -> tuple[np.ndarray, np.ndarray, float]:
    """An object's local (centre, size) into the canonical frame."""
    c, s = np.cos(obj.yaw), np.sin(obj.yaw)
    base = obj.center - np.array([0, 0, obj.size[2] / 2])  # the footprint's centre on the floor
    w = np.array([base[0] + c * pc[0] - s * pc[1], base[1] + s * pc[0] + c * pc[1], pc[2]])
    return w, np.asarray(size, float), float(obj.yaw + yaw_extra)


def _on_objects(lay: Layout, rng: np.random.Generator) -> list[Detail]:
    out = []
    for o in lay.objects:
        w, d, h = o.size
        if o.category == "bed":  # mattress top about 0.5 m; the headboard at +y
            top = min(0.5, h)
            for sx in ((-0.25, 0.25) if w > 1.2 else (0.0,)):
                pw = min(0.55, w / 2 - 0.05)
                c, s, y = _local(o, [sx * w, d / 2 - 0.3, top + 0.07], [pw, 0.35, 0.14])
                out.append(Detail(Part("box", c, s, y, o.instance_id, skip_bottom=True), "fabric", rng.uniform(0, 1)))
            c, s, y = _local(o, [0, -d * 0.15, top + 0.025], [w - 0.02, d * 0.6, 0.05])
            out.append(Detail(Part("box", c, s, y, o.instance_id, skip_bottom=True), "fabric", rng.uniform(0, 1)))
        elif o.category == "sofa":  # seat 0.42 m between 0.2 m arms, back at +y
            n = 3 if w > 1.8 else 2
            cw = (w - 0.4) / n
            hue = rng.uniform(0, 1)
            for i in range(n):
                x = -w / 2 + 0.2 + cw * (i + 0.5)
                c, s, y = _local(o, [x, -0.05, 0.49], [cw - 0.02, d - 0.3, 0.14])
                out.append(Detail(Part("box", c, s, y, o.instance_id, skip_bottom=True), "fabric", hue))
                c, s, y = _local(o, [x, d / 2 - 0.28, 0.68], [cw - 0.04, 0.16, 0.3])
                out.append(Detail(Part("box", c, s, y, o.instance_id), "fabric", hue))
        elif o.category == "chair" and rng.random() < 0.5:
            c, s, y = _local(o, [0, -0.02, min(0.45, h) + 0.03], [w - 0.06, d - 0.1, 0.05])
            out.append(Detail(Part("box", c, s, y, o.instance_id, skip_bottom=True), "fabric", rng.uniform(0, 1)))
        elif o.category == "table":  # things on the table top (structure: they are no goal)
            for _ in range(int(rng.integers(0, 5))):
                px, py = rng.uniform(-w / 2 + 0.12, w / 2 - 0.12), rng.uniform(-d / 2 + 0.12, d / 2 - 0.12)
                kind = rng.choice(["book", "cup", "vase", "bowl"])
                if kind == "book":
                    t = rng.uniform(0.03, 0.08)
                    c, s, y = _local(o, [px, py, h + t / 2], [rng.uniform(0.15, 0.25), rng.uniform(0.2, 0.3), t],
                                     rng.uniform(-0.5, 0.5))
                    out.append(Detail(Part("box", c, s, y, 0, skip_bottom=True), "painted", rng.uniform(0, 1)))
                else:
                    r, ht = {"cup": (0.04, 0.1), "vase": (0.06, rng.uniform(0.2, 0.35)), "bowl": (0.11, 0.07)}[kind]
                    c, s, y = _local(o, [px, py, h + ht / 2], [2 * r, 2 * r, ht])
                    out.append(Detail(Part("cylinder", c, s, y, 0, skip_bottom=True), "painted", rng.uniform(0, 1)))
    return out


def _free_spot(room, taken, keep_clear, size, rng, against_wall: bool):
    """(centre x, y, yaw, footprint) of a free place for a size [w, d] footprint in a room, or None."""
    x0, y0, x1, y1 = room
    w, d = size
    for _ in range(40):
        if against_wall:
            side = int(rng.integers(4))
            yaw = [0.0, np.pi / 2, np.pi, -np.pi / 2][side]
            half = d / 2 + 0.02
            if x1 - x0 < w + 0.2 or y1 - y0 < w + 0.2:
                return None
            cx, cy = [(rng.uniform(x0 + w / 2, x1 - w / 2), y1 - half), (x0 + half, rng.uniform(y0 + w / 2, y1 - w / 2)),
                      (rng.uniform(x0 + w / 2, x1 - w / 2), y0 + half), (x1 - half, rng.uniform(y0 + w / 2, y1 - w / 2))][side]
        else:
            yaw = float(rng.uniform(-np.pi, np.pi))
            m = 0.5 * np.hypot(w, d) + 0.2
            if x1 - x0 < 2 * m or y1 - y0 < 2 * m:
                return None
            cx, cy = rng.uniform(x0 + m, x1 - m), rng.uniform(y0 + m, y1 - m)
        fp = shapely.affinity.translate(shapely.affinity.rotate(shp_box(-w / 2, -d / 2, w / 2, d / 2), yaw, use_radians=True),
                                        cx, cy)
        # 0.9 m from furniture and other details: a passage for the widest robot stays
        if any(fp.distance(t) < 0.9 for t in taken) or any(fp.intersects(k) for k in keep_clear):
            continue
        return cx, cy, yaw, fp
    return None


def _in_rooms(lay: Layout, rng: np.random.Generator) -> list[Detail]:
    out = []
    keep_clear = [shp_box(*d).buffer(1.0) for d in lay.doors]
    for room in lay.rooms:
        taken = [shapely.affinity.translate(shapely.affinity.rotate(
            shp_box(-o.size[0] / 2, -o.size[1] / 2, o.size[0] / 2, o.size[1] / 2), o.yaw, use_radians=True),
            o.center[0], o.center[1]) for o in lay.objects
            if room[0] <= o.center[0] <= room[2] and room[1] <= o.center[1] <= room[3]]
        if rng.random() < 0.45:  # a bookshelf: sides, top, shelves and rows of books
            w, d, h = rng.uniform(0.7, 1.2), rng.uniform(0.28, 0.36), rng.uniform(1.4, 2.0)
            spot = _free_spot(room, taken, keep_clear, (w, d), rng, against_wall=True)
            if spot is not None:
                cx, cy, yaw, fp = spot
                taken.append(fp)
                c, s = np.cos(yaw), np.sin(yaw)

                def put(kind, pc, size, look, hue=None):
                    world = np.array([cx + c * pc[0] - s * pc[1], cy + s * pc[0] + c * pc[1], pc[2]])
                    out.append(Detail(Part(kind, world, np.asarray(size, float), yaw, 0,
                                           skip_bottom=bool(abs(pc[2] - size[2] / 2) < 1e-6)), look, hue))
                hue = rng.uniform(0.05, 0.12)
                for sx in (-1, 1):
                    put("box", [sx * (w / 2 - 0.01), 0, h / 2], [0.02, d, h], "wood", hue)
                put("box", [0, d / 2 - 0.005, h / 2], [w, 0.01, h], "wood", hue)  # the back board
                put("box", [0, -d / 2 + 0.01, 0.05], [w - 0.04, 0.02, 0.1], "wood", hue)  # the plinth
                levels = int(rng.integers(3, 6))
                for k in range(levels + 1):  # boards from 0.11 m (a board at the floor would read as floor)
                    z = 0.11 + k * (h - 0.13) / levels
                    put("box", [0, 0, z], [w - 0.04, d, 0.02], "wood", hue)
                    if k < levels:  # a row of books, each its own colour, some gaps
                        x = -w / 2 + 0.03
                        while x < w / 2 - 0.06:
                            bw = rng.uniform(0.02, 0.05)
                            bh = rng.uniform(0.15, min(0.3, (h - 0.13) / levels - 0.03))
                            if rng.random() < 0.85:
                                put("box", [x + bw / 2, 0.02, z + 0.01 + bh / 2], [bw, d - 0.08, bh], "painted",
                                    rng.uniform(0, 1))
                            x += bw + 0.002
        for _ in range(int(rng.integers(0, 3))):  # things on the floor
            kind = rng.choice(["box", "basket"])
            size = (rng.uniform(0.25, 0.5), rng.uniform(0.25, 0.45)) if kind == "box" else (rng.uniform(0.3, 0.45),) * 2
            spot = _free_spot(room, taken, keep_clear, size, rng, against_wall=rng.random() < 0.6)
            if spot is None:
                continue
            cx, cy, yaw, fp = spot
            taken.append(fp)
            ht = rng.uniform(0.2, 0.5)
            shape = "box" if kind == "box" else "cylinder"
            out.append(Detail(Part(shape, np.array([cx, cy, ht / 2]), np.array([size[0], size[1], ht]), yaw, 0,
                                   skip_bottom=True), "painted" if kind == "box" else "fabric", rng.uniform(0.05, 0.15)))
    return out


def furnish(lay: Layout, rng: np.random.Generator) -> list[Detail]:
    """Every detail of a layout: on its objects, then in its rooms (see the module docstring)."""
    return _on_objects(lay, rng) + _in_rooms(lay, rng)
