"""Room layouts and furniture as analytic primitives (boxes, cylinders, spheres).

Everything here is in the canonical frame: z up, floor at z = 0, metres. The primitives are
the single description from which both the ground-truth mesh and the Gaussians are made.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import box as shp_box

CATEGORIES = ("chair", "table", "bed", "sofa", "toilet", "tv_monitor", "plant", "cabinet")


@dataclass
class Part:
    """One primitive. kind: 'box' (size = extents), 'cylinder' (size = (2r, 2r, h)) or
    'sphere' (size = diameters, an ellipsoid); centre in metres; yaw about +z in radians."""

    kind: str
    center: np.ndarray  # [3] m
    size: np.ndarray  # [3] m
    yaw: float
    instance: int  # 0 = structure (walls, floor, ceiling), >= 1 objects
    skip_bottom: bool = False  # bottom face rests on the floor: a real capture never sees it
    skip_top: bool = False  # top face of a ceiling slab: outside the rooms, never seen
    skip_sides: bool = False  # side faces of floor / ceiling slabs: buried under walls or
    # against the next room's slab (a capture never sees them; sampled, they poke into doorways)


@dataclass
class SceneObject:
    instance_id: int
    category: str
    center: np.ndarray  # [3] m, centre of the bounding box
    size: np.ndarray  # [3] m, oriented box extents
    yaw: float

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        hx = 0.5 * (abs(c) * self.size[0] + abs(s) * self.size[1])
        hy = 0.5 * (abs(s) * self.size[0] + abs(c) * self.size[1])
        h = np.array([hx, hy, 0.5 * self.size[2]])
        return self.center - h, self.center + h


@dataclass
class Layout:
    parts: list[Part] = field(default_factory=list)
    objects: list[SceneObject] = field(default_factory=list)
    rooms: list[tuple[float, float, float, float]] = field(default_factory=list)  # interior x0, y0, x1, y1
    doors: list[tuple[float, float, float, float]] = field(default_factory=list)  # door opening rectangles
    wall_height: float = 2.6


@dataclass
class LayoutConfig:
    """Parameters of the procedural layout."""

    rooms_min: int = 2
    """Fewest rooms."""
    rooms_max: int = 4
    """Most rooms."""
    room_size_min_m: float = 3.6
    """Smallest room side (wall centre to wall centre), metres."""
    room_size_max_m: float = 6.4
    """Largest room side, metres."""
    wall_height_m: float = 2.6
    """Wall height, metres."""
    wall_thickness_m: float = 0.12
    """Wall thickness, metres."""
    door_width_min_m: float = 1.0
    """Narrowest doorway, metres (the widest robot, radius 0.4 m, must pass)."""
    door_width_max_m: float = 1.4
    """Widest doorway, metres."""
    door_height_m: float = 2.1
    """Doorway height, metres."""
    objects_min: int = 2
    """Fewest furniture items per room."""
    objects_max: int = 5
    """Most furniture items per room."""
    ceiling: bool = False
    """Close the rooms with a ceiling slab."""


def _grid_rooms(rng: np.random.Generator, cfg: LayoutConfig):
    """Pick n connected cells of a 3x3 grid by a random walk; return cells and the grid lines."""
    n = int(rng.integers(cfg.rooms_min, cfg.rooms_max + 1))
    cells = [(1, 1)]
    while len(cells) < n:
        r, c = cells[int(rng.integers(len(cells)))]
        dr, dc = [(0, 1), (1, 0), (0, -1), (-1, 0)][int(rng.integers(4))]
        nb = (r + dr, c + dc)
        if 0 <= nb[0] < 3 and 0 <= nb[1] < 3 and nb not in cells:
            cells.append(nb)
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(cfg.room_size_min_m, cfg.room_size_max_m, 3))])
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(cfg.room_size_min_m, cfg.room_size_max_m, 3))])
    return cells, xs, ys


def _wall(parts, a, b, fixed, axis, cfg: LayoutConfig, door: tuple[float, float] | None):
    """Wall from a to b along `axis` ('x' or 'y') at the other coordinate `fixed`, with an
    optional doorway (start, end) along the wall."""
    t, h = cfg.wall_thickness_m, cfg.wall_height_m
    a, b = a - t / 2, b + t / 2  # close the corners
    spans = [(a, b, 0.0, h)]
    if door is not None:
        d0, d1 = door
        spans = [(a, d0, 0.0, h), (d1, b, 0.0, h), (d0, d1, cfg.door_height_m, h)]
    for s0, s1, z0, z1 in spans:
        if s1 - s0 < 1e-3:
            continue
        mid, length = 0.5 * (s0 + s1), s1 - s0
        if axis == "x":
            c, size = [mid, fixed, 0.5 * (z0 + z1)], [length, t, z1 - z0]
        else:
            c, size = [fixed, mid, 0.5 * (z0 + z1)], [t, length, z1 - z0]
        parts.append(Part("box", np.array(c), np.array(size), 0.0, 0, skip_bottom=z0 == 0.0))


def _furniture(category: str, rng: np.random.Generator) -> tuple[list[tuple[str, list, list]], np.ndarray, bool]:
    """Parts of one item in its local frame (centre of footprint at the origin, front = -y).

    Returns:
        (parts as (kind, centre, size), overall size [3], goes against a wall).
    """
    j = lambda v: v * rng.uniform(0.88, 1.12)
    if category == "chair":
        w, d, sh, bh = j(0.46), j(0.46), j(0.45), j(0.45)
        leg = 0.04
        p = [("box", [0, 0, sh - 0.025], [w, d, 0.05]), ("box", [0, d / 2 - 0.025, sh + bh / 2], [w, 0.05, bh])]
        p += [("box", [sx * (w / 2 - leg / 2), sy * (d / 2 - leg / 2), (sh - 0.05) / 2], [leg, leg, sh - 0.05])
              for sx in (-1, 1) for sy in (-1, 1)]
        return p, np.array([w, d, sh + bh]), False
    if category == "table":
        w, d, h = j(1.3), j(0.8), j(0.74)
        leg = 0.06
        p = [("box", [0, 0, h - 0.02], [w, d, 0.04])]
        p += [("box", [sx * (w / 2 - leg), sy * (d / 2 - leg), (h - 0.04) / 2], [leg, leg, h - 0.04])
              for sx in (-1, 1) for sy in (-1, 1)]
        return p, np.array([w, d, h]), False
    if category == "bed":
        w, d, h = j(1.5), j(2.0), j(0.5)
        return [("box", [0, 0, h / 2], [w, d, h]), ("box", [0, d / 2 - 0.04, 0.55], [w, 0.08, 1.1])], \
            np.array([w, d, 1.1]), True
    if category == "sofa":
        w, d = j(2.0), j(0.9)
        p = [("box", [0, 0, 0.21], [w, d, 0.42]), ("box", [0, d / 2 - 0.1, 0.42], [w, 0.2, 0.84])]
        p += [("box", [sx * (w / 2 - 0.1), 0, 0.3], [0.2, d, 0.6]) for sx in (-1, 1)]
        return p, np.array([w, d, 0.84]), True
    if category == "toilet":
        r = j(0.2)
        return [("cylinder", [0, -0.1, 0.2], [2 * r, 2 * r, 0.4]), ("box", [0, 0.2, 0.4], [0.42, 0.2, 0.8])], \
            np.array([0.42, 0.3 + 2 * r, 0.8]), True
    if category == "tv_monitor":
        w = j(1.0)
        return [("box", [0, 0, 0.95], [w, 0.06, 0.6]), ("box", [0, 0, 0.33], [0.08, 0.06, 0.66]),
                ("box", [0, 0, 0.01], [0.4, 0.25, 0.02])], np.array([w, 0.25, 1.25]), True
    if category == "plant":
        r = j(0.17)
        fr = j(0.33)
        return [("cylinder", [0, 0, 0.18], [2 * r, 2 * r, 0.36]), ("sphere", [0, 0, 0.36 + fr], [2 * fr] * 3)], \
            np.array([2 * fr, 2 * fr, 0.36 + 2 * fr]), False
    if category == "cabinet":
        tall = rng.random() < 0.5
        w, d, h = (j(0.9), j(0.45), j(1.8)) if tall else (j(1.2), j(0.5), j(0.85))
        return [("box", [0, 0, h / 2], [w, d, h])], np.array([w, d, h]), True
    raise ValueError(f"unknown category {category!r}")


def make_layout(rng: np.random.Generator, cfg: LayoutConfig) -> Layout:
    """Rooms on a grid joined by doorways (a spanning tree plus some extra doors), then furniture."""
    lay = Layout(wall_height=cfg.wall_height_m)
    cells, xs, ys = _grid_rooms(rng, cfg)
    t = cfg.wall_thickness_m
    cellset = set(cells)
    # doors: spanning tree over adjacent cells (every room reachable), plus extra doors at random
    adj = [(a, b) for a in cells for b in cells if a < b and abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1]
    order = rng.permutation(len(adj))
    parent = {c: c for c in cells}

    def find(c):
        while parent[c] != c:
            c = parent[c]
        return c
    doors = set()
    for k in order:
        a, b = adj[k]
        if find(a) != find(b):
            parent[find(a)] = find(b)
            doors.add((a, b))
        elif rng.random() < 0.3:
            doors.add((a, b))

    def door_span(lo, hi):
        w = rng.uniform(cfg.door_width_min_m, cfg.door_width_max_m)
        c = rng.uniform(lo + t / 2 + 0.15 + w / 2, hi - t / 2 - 0.15 - w / 2)
        return c - w / 2, c + w / 2

    # walls along x on the grid lines ys[a] (between rows a-1 and a), then walls along y on xs[a]
    for axis, lines, spans in (("x", ys, xs), ("y", xs, ys)):
        for a in range(4):
            for b in range(3):
                side0, side1 = ((a - 1, b), (a, b)) if axis == "x" else ((b, a - 1), (b, a))
                if side0 not in cellset and side1 not in cellset:
                    continue
                door = None
                if tuple(sorted((side0, side1))) in doors:
                    door = door_span(spans[b], spans[b + 1])
                    lo, hi = lines[a] - t / 2, lines[a] + t / 2
                    lay.doors.append((door[0], lo, door[1], hi) if axis == "x" else (lo, door[0], hi, door[1]))
                _wall(lay.parts, spans[b], spans[b + 1], lines[a], axis, cfg, door)
    for r, c in cells:
        x0, x1, y0, y1 = xs[c], xs[c + 1], ys[r], ys[r + 1]
        lay.rooms.append((x0 + t / 2, y0 + t / 2, x1 - t / 2, y1 - t / 2))
        lay.parts.append(Part("box", np.array([(x0 + x1) / 2, (y0 + y1) / 2, -0.025]),
                              np.array([x1 - x0 + t, y1 - y0 + t, 0.05]), 0.0, 0, skip_bottom=True,
                              skip_sides=True))
        if cfg.ceiling:
            lay.parts.append(Part("box", np.array([(x0 + x1) / 2, (y0 + y1) / 2, cfg.wall_height_m + 0.025]),
                                  np.array([x1 - x0 + t, y1 - y0 + t, 0.05]), 0.0, 0, skip_top=True,
                                  skip_sides=True))
    _place_furniture(lay, rng, cfg)
    return lay


def _place_furniture(lay: Layout, rng: np.random.Generator, cfg: LayoutConfig) -> None:
    """Rejection-sample furniture footprints in each room, clear of doorways and each other."""
    keep_clear = [shp_box(d[0], d[1], d[2], d[3]).buffer(1.0) for d in lay.doors]
    next_id = 1
    for (x0, y0, x1, y1) in lay.rooms:
        placed = []
        n = int(rng.integers(cfg.objects_min, cfg.objects_max + 1))
        for _ in range(n):
            cat = CATEGORIES[int(rng.integers(len(CATEGORIES)))]
            for _attempt in range(40):
                parts, size, against_wall = _furniture(cat, rng)
                if against_wall:
                    side = int(rng.integers(4))  # back against wall `side`; front faces the room
                    yaw = [0.0, np.pi / 2, np.pi, -np.pi / 2][side]
                    half_d = size[1] / 2 + 0.02
                    if side == 0:
                        cx, cy = rng.uniform(x0 + size[0] / 2, x1 - size[0] / 2), y1 - half_d
                    elif side == 1:
                        cx, cy = x0 + half_d, rng.uniform(y0 + size[0] / 2, y1 - size[0] / 2)
                    elif side == 2:
                        cx, cy = rng.uniform(x0 + size[0] / 2, x1 - size[0] / 2), y0 + half_d
                    else:
                        cx, cy = x1 - half_d, rng.uniform(y0 + size[0] / 2, y1 - size[0] / 2)
                else:
                    yaw = float(rng.uniform(-np.pi, np.pi))
                    m = 0.5 * np.hypot(size[0], size[1]) + 0.35
                    if x1 - x0 < 2 * m or y1 - y0 < 2 * m:
                        continue
                    cx, cy = rng.uniform(x0 + m, x1 - m), rng.uniform(y0 + m, y1 - m)
                fp = shapely.affinity.rotate(shp_box(-size[0] / 2, -size[1] / 2, size[0] / 2, size[1] / 2),
                                             yaw, use_radians=True)
                fp = shapely.affinity.translate(fp, cx, cy)
                if not shp_box(x0, y0, x1, y1).contains(fp):
                    continue
                # 0.9 m between items leaves a passage for the widest robot
                if any(fp.distance(o) < 0.9 for o in placed) or any(fp.intersects(k) for k in keep_clear):
                    continue
                placed.append(fp)
                c, s = np.cos(yaw), np.sin(yaw)
                for kind, pc, psize in parts:
                    pc = np.asarray(pc, dtype=float)
                    world = np.array([cx + c * pc[0] - s * pc[1], cy + s * pc[0] + c * pc[1], pc[2]])
                    psize = np.asarray(psize, dtype=float)
                    lay.parts.append(Part(kind, world, psize, yaw, next_id,
                                          skip_bottom=bool(abs(world[2] - psize[2] / 2) < 1e-6)))
                lay.objects.append(SceneObject(next_id, cat, np.array([cx, cy, size[2] / 2]), size, yaw))
                next_id += 1
                break
