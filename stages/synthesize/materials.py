"""What a generated room looks like: procedural materials on every surface, painted details
(baseboards, door frames, closed doors, windows, pictures, rugs) and baked light, as the colours of
the Gaussians the geometry already placed. Geometry is never touched here, so the costmap, the
ground-truth mesh and the episodes of a seed stay what they were; only the colours change.

Materials are procedural (no texture images ship): each is a function of a point's coordinates on
its surface (metres), from integer-hashed value noise, so that a pattern is continuous across a
wall and the same for a seed on every machine. Per surface and per scene: the material, its
colours, scale and orientation are drawn (ProcTHOR-style randomisation).

Light is baked, not simulated: an ambient level and tint per scene, a falloff from each room's light
(a window or a ceiling lamp), ambient occlusion where the floor meets a wall, under furniture, and
where a wall meets the floor or the ceiling.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MATERIALS = ("wood", "tile", "carpet", "plaster", "wallpaper", "fabric", "stone", "painted", "metal")
"""Every material a surface may get."""
FLOOR_MATERIALS = ("wood", "tile", "carpet", "stone")
WALL_MATERIALS = ("plaster", "wallpaper", "painted", "tile")
FURNITURE_MATERIALS = {"chair": ("wood", "fabric", "metal"), "table": ("wood", "stone", "metal"), "bed": ("fabric",),
                       "sofa": ("fabric",), "toilet": ("painted",), "tv_monitor": ("metal",), "plant": ("fabric",),
                       "cabinet": ("wood", "painted")}
"""The materials each ObjectNav category is drawn from (a plant's foliage: fabric-like noise in greens)."""


@dataclass
class LookConfig:
    """How generated scenes look (synthetic.look)."""

    enabled: bool = True
    """Textured surfaces, painted details and baked light (false: the flat colours of NavArena before
    issue 82: walls white, floor brown, one colour an object)."""
    ceiling: bool = True
    """Close every room with a ceiling (its Gaussians are added above the walls; no obstacle)."""
    furnish: bool = True
    """Furniture details and clutter (stages/synthesize/furnish.py): pillows, blankets and cushions on the
    goal objects (inside their boxes), things on tables and floors and bookshelves (structure: obstacles
    without a goal category)."""
    ambient: tuple[float, float] = (0.55, 0.8)
    """Range of the scene's ambient light level (the rest comes from each room's light)."""
    occlusion: float = 0.45
    """Darkening in corners, where floor meets wall and under furniture (0: none)."""
    pictures_per_room: tuple[int, int] = (1, 4)
    """Fewest and most framed pictures on a room's walls."""
    windows_per_room: tuple[int, int] = (0, 2)
    """Fewest and most (bright) windows on a room's outer walls."""
    rug_share: float = 0.5
    """Probability that a room has a rug."""
    colour_noise: float = 0.1
    """Per-Gaussian colour noise, standard deviation (a trained 3DGS is never flat: its view-dependent
    colour noise), mostly shared by the three channels (chroma_share). With speckle, what brings the
    renders' gradient energy to the captures' (docs/benchmarks/bench_realism.md): 0.04 and speckle
    0.1 gave 0.30x of it."""
    chroma_share: float = 0.25
    """Share of colour_noise drawn per channel (the rest is one draw for all three: brightness). Drawn
    per channel alone, 0.1 of noise turned plain walls into multi-coloured confetti (looked at)."""
    speckle: float = 0.3
    """Per-Gaussian brightness noise (log-normal sigma): the blotchy texture a trained 3DGS shows."""


@dataclass
class Material:
    kind: str
    base: np.ndarray  # [3] RGB 0..1
    accent: np.ndarray  # [3] RGB 0..1 (grain, grout, stripes, seams)
    scale: float  # m, the pattern's size (plank width, tile side, stripe period)
    angle: float  # rad, the pattern's orientation on its surface
    seed: int = 0


@dataclass
class Decal:
    """A painted rectangle on a surface: (u0, v0, u1, v1) in the surface's coordinates (m)."""

    kind: str  # picture | window | door | rug
    rect: tuple[float, float, float, float]
    colour: np.ndarray
    frame: float = 0.0  # m, frame width
    frame_colour: np.ndarray = field(default_factory=lambda: np.zeros(3))
    seed: int = 0


def _hash01(ix: np.ndarray, iy: np.ndarray, seed: int) -> np.ndarray:
    """Uniform 0..1 per integer lattice point (a 32-bit integer hash: the same on every machine)."""
    h = (ix.astype(np.int64) * 73856093) ^ (iy.astype(np.int64) * 19349663) ^ (int(seed) * 83492791)
    h = (h ^ (h >> 13)) * 1274126177
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF).astype(np.float64) / float(0xFFFFFF)


def value_noise(u: np.ndarray, v: np.ndarray, seed: int) -> np.ndarray:
    """Smooth value noise in 0..1 at (u, v) in lattice units (bilinear with a smoothstep)."""
    iu, iv = np.floor(u), np.floor(v)
    fu, fv = u - iu, v - iv
    su, sv = fu * fu * (3 - 2 * fu), fv * fv * (3 - 2 * fv)
    a, b = _hash01(iu, iv, seed), _hash01(iu + 1, iv, seed)
    c, d = _hash01(iu, iv + 1, seed), _hash01(iu + 1, iv + 1, seed)
    return (a * (1 - su) + b * su) * (1 - sv) + (c * (1 - su) + d * su) * sv


def fbm(u: np.ndarray, v: np.ndarray, seed: int, octaves: int = 4) -> np.ndarray:
    """Fractal noise (octaves of value noise, each twice the frequency and half the amplitude), 0..1."""
    out, amp, total = np.zeros_like(u, dtype=np.float64), 1.0, 0.0
    for k in range(octaves):
        out += amp * value_noise(u * 2 ** k, v * 2 ** k, seed + 101 * k)
        total += amp
        amp *= 0.5
    return out / total


def _mix(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    return a[None] * (1 - t[:, None]) + b[None] * t[:, None]


def pattern(m: Material, uv: np.ndarray) -> np.ndarray:
    """RGB [M, 3] of material m at surface coordinates uv [M, 2] (m)."""
    c, s = np.cos(m.angle), np.sin(m.angle)
    u = (uv[:, 0] * c - uv[:, 1] * s) / m.scale
    v = (uv[:, 0] * s + uv[:, 1] * c) / m.scale
    k = m.kind
    if k == "wood":  # planks along u: per-plank tint, grain stripes, dark seams
        plank = np.floor(v)
        along = u * 0.25 + _hash01(plank, plank * 0 + 7, m.seed) * 10  # planks end at staggered places
        tint = 0.7 + 0.6 * _hash01(plank, np.floor(along), m.seed + 1)
        grain = 0.5 + 0.5 * np.sin(40 * (v - plank) + 6 * fbm(u * 2, v * 2, m.seed + 2))
        seam = (np.minimum(v - plank, 1 - (v - plank)) < 0.06) | (np.minimum(along % 1, 1 - along % 1) < 0.01)
        rgb = _mix(m.base, m.accent, 0.35 * grain) * tint[:, None]
        return np.where(seam[:, None], rgb * 0.45, rgb)
    if k == "tile":  # a grid of tiles with grout and per-tile variation
        fu, fv = u - np.floor(u), v - np.floor(v)
        grout = (np.minimum(fu, 1 - fu) < 0.05) | (np.minimum(fv, 1 - fv) < 0.05)
        tint = 0.75 + 0.5 * _hash01(np.floor(u), np.floor(v), m.seed)
        rgb = m.base[None] * tint[:, None] * (0.92 + 0.16 * fbm(u * 3, v * 3, m.seed + 3))[:, None]
        return np.where(grout[:, None], m.accent[None], rgb)
    if k == "carpet":  # fine fibre noise over a mottled base
        fine = value_noise(u * 40, v * 40, m.seed)
        mottle = fbm(u * 0.7, v * 0.7, m.seed + 4)
        return _mix(m.base, m.accent, 0.5 * mottle) * (0.8 + 0.35 * fine)[:, None]
    if k == "plaster":  # nearly uniform, soft low-frequency variation
        return m.base[None] * (0.9 + 0.14 * fbm(u * 1.5, v * 1.5, m.seed))[:, None]
    if k == "wallpaper":  # stripes, or a dot lattice, in the accent colour
        if m.seed % 2:
            t = (np.sin(2 * np.pi * u) > 0.3).astype(np.float64)
        else:
            fu, fv = u * 2 - np.floor(u * 2) - 0.5, v * 2 - np.floor(v * 2) - 0.5
            t = (fu * fu + fv * fv < 0.06).astype(np.float64)
        return _mix(m.base, m.accent, 0.7 * t) * (0.95 + 0.08 * fbm(u, v, m.seed + 5))[:, None]
    if k == "fabric":  # a weave and folds
        weave = 0.5 + 0.5 * np.sin(60 * u) * np.sin(60 * v)
        folds = fbm(u * 0.8, v * 0.8, m.seed + 6)
        return _mix(m.base, m.accent, 0.25 * weave) * (0.75 + 0.45 * folds)[:, None]
    if k == "stone":  # irregular slabs: the nearest of jittered lattice points, a tint each
        iu, iv = np.floor(u), np.floor(v)
        best, tint = np.full(len(u), np.inf), np.zeros(len(u))
        for du in (-1, 0, 1):
            for dv in (-1, 0, 1):
                cu, cv = iu + du, iv + dv
                px, py = cu + _hash01(cu, cv, m.seed), cv + _hash01(cu, cv, m.seed + 9)
                d = (u - px) ** 2 + (v - py) ** 2
                closer = d < best
                best, tint = np.where(closer, d, best), np.where(closer, _hash01(cu, cv, m.seed + 11), tint)
        rgb = _mix(m.base, m.accent, 0.6 * tint) * (0.85 + 0.25 * fbm(u * 4, v * 4, m.seed + 12))[:, None]
        return rgb
    if k == "metal":  # brushed: streaks along u
        return m.base[None] * (0.8 + 0.3 * value_noise(u * 2, v * 80, m.seed))[:, None]
    return m.base[None] * (0.94 + 0.08 * fbm(u * 2, v * 2, m.seed))[:, None]  # painted


def _hsv(h: float, s: float, v: float) -> np.ndarray:
    import colorsys

    return np.array(colorsys.hsv_to_rgb(h % 1.0, min(max(s, 0.0), 1.0), min(max(v, 0.0), 1.0)))


def draw_material(kind: str, rng: np.random.Generator) -> Material:
    """A material of `kind` with colours, scale and orientation drawn from plausible ranges."""
    seed = int(rng.integers(1 << 30))
    angle = float(rng.choice([0.0, np.pi / 2])) + float(rng.normal(0, 0.02))
    if kind == "wood":
        h, v = rng.uniform(0.05, 0.11), rng.uniform(0.35, 0.8)
        base, accent, scale = _hsv(h, rng.uniform(0.35, 0.7), v), _hsv(h, 0.7, v * 0.45), rng.uniform(0.14, 0.26)
    elif kind == "tile":
        h, v = rng.uniform(0, 1), rng.uniform(0.55, 0.95)
        base = _hsv(h, rng.uniform(0.0, 0.25), v)
        accent = _hsv(h, 0.05, rng.choice([0.35, 0.9]))
        scale = rng.uniform(0.3, 0.7)
    elif kind == "carpet":
        h = rng.uniform(0, 1)
        base, accent, scale = _hsv(h, rng.uniform(0.1, 0.5), rng.uniform(0.25, 0.65)), _hsv(h + 0.05, 0.4, 0.4), 1.0
    elif kind == "plaster":
        base, accent, scale = _hsv(rng.uniform(0.05, 0.15), rng.uniform(0.0, 0.15), rng.uniform(0.75, 0.95)), np.ones(3), 1.0
    elif kind == "wallpaper":
        h = rng.uniform(0, 1)
        base = _hsv(h, rng.uniform(0.05, 0.35), rng.uniform(0.65, 0.92))
        accent, scale = _hsv(h + rng.uniform(-0.1, 0.1), 0.4, rng.uniform(0.4, 0.75)), rng.uniform(0.08, 0.25)
    elif kind == "fabric":
        h = rng.uniform(0, 1)
        base = _hsv(h, rng.uniform(0.15, 0.6), rng.uniform(0.25, 0.8))
        accent, scale = base * 0.7, rng.uniform(0.3, 0.8)
    elif kind == "stone":
        h = rng.uniform(0.05, 0.15)
        base, accent, scale = _hsv(h, rng.uniform(0.05, 0.2), rng.uniform(0.45, 0.8)), _hsv(h, 0.1, 0.35), rng.uniform(0.3, 0.8)
    elif kind == "metal":
        v = rng.uniform(0.15, 0.75)
        base, accent, scale = _hsv(0.6, rng.uniform(0.0, 0.1), v), np.full(3, v), 1.0
    else:  # painted
        base, accent, scale = _hsv(rng.uniform(0, 1), rng.uniform(0.05, 0.45), rng.uniform(0.45, 0.95)), np.ones(3), 1.0
    return Material(kind, np.asarray(base, float), np.asarray(accent, float), float(scale), angle, seed)


def surface_coords(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """[M, 2] coordinates of points on their surfaces (m): horizontal surfaces (x, y); vertical ones
    (distance along the surface's horizontal direction, height), continuous along a wall."""
    horiz = np.abs(normals[:, 2]) > 0.7
    h = np.stack([-normals[:, 1], normals[:, 0]], 1)
    h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-9)
    along = points[:, 0] * h[:, 0] + points[:, 1] * h[:, 1]
    return np.where(horiz[:, None], points[:, :2], np.stack([along, points[:, 2]], 1))


@dataclass
class RoomLook:
    floor: Material
    wall: Material
    ceiling: Material
    light: np.ndarray  # [3] m, the room's light (a window's centre, or a ceiling lamp)
    light_range: float  # m, distance at which the light's share has halved
    decals: list[tuple[int, Decal]]  # (wall side 0..3: y1, x0, y0, x1; -1: the floor)


def _room_side(points: np.ndarray, room) -> np.ndarray:
    """Which of a room's walls (0: y = y1, 1: x = x0, 2: y = y0, 3: x = x1) each point is nearest."""
    x0, y0, x1, y1 = room
    d = np.stack([np.abs(points[:, 1] - y1), np.abs(points[:, 0] - x0), np.abs(points[:, 1] - y0),
                  np.abs(points[:, 0] - x1)], 1)
    return np.argmin(d, axis=1)


def _along(points: np.ndarray, side: np.ndarray) -> np.ndarray:
    """Coordinate along a wall: x on the walls y = const (sides 0, 2), y on x = const (1, 3)."""
    return np.where(side % 2 == 0, points[:, 0], points[:, 1])


def _shares_side(rooms, k: int, side: int, gap: float = 0.5) -> bool:
    """Whether room k's wall `side` is shared with another room (an inner wall)."""
    x0, y0, x1, y1 = rooms[k]
    for j, (a0, b0, a1, b1) in enumerate(rooms):
        if j == k:
            continue
        overlap_x, overlap_y = min(x1, a1) - max(x0, a0) > 0.3, min(y1, b1) - max(y0, b0) > 0.3
        if (side == 0 and overlap_x and abs(b0 - y1) < gap) or (side == 2 and overlap_x and abs(b1 - y0) < gap) \
                or (side == 1 and overlap_y and abs(a1 - x0) < gap) or (side == 3 and overlap_y and abs(a0 - x1) < gap):
            return True
    return False


def _side_span(room, side: int) -> tuple[float, float]:
    x0, y0, x1, y1 = room
    return (x0, x1) if side % 2 == 0 else (y0, y1)


def _picture(rng: np.random.Generator) -> Decal:
    return Decal("picture", (0, 0, 0, 0), _hsv(rng.uniform(0, 1), rng.uniform(0.3, 0.8), rng.uniform(0.3, 0.9)),
                 frame=float(rng.uniform(0.02, 0.05)), frame_colour=_hsv(rng.uniform(0.05, 0.1), 0.5, rng.uniform(0.1, 0.6)),
                 seed=int(rng.integers(1 << 30)))


def plan_rooms(lay, rng: np.random.Generator, cfg: LookConfig) -> list[RoomLook]:
    """Each room's materials, light and painted details (windows, pictures, a closed door, a rug)."""
    out = []
    h = lay.wall_height
    door_sides = {}
    for k, room in enumerate(lay.rooms):  # the walls with a doorway keep it clear of paintings
        for d in lay.doors:
            c = np.array([[(d[0] + d[2]) / 2, (d[1] + d[3]) / 2, 1.0]])
            x0, y0, x1, y1 = room
            if x0 - 0.2 <= c[0, 0] <= x1 + 0.2 and y0 - 0.2 <= c[0, 1] <= y1 + 0.2:
                door_sides.setdefault(k, []).append((int(_room_side(c, room)[0]),
                                                     float(_along(c, _room_side(c, room))[0])))
    for k, room in enumerate(lay.rooms):
        x0, y0, x1, y1 = room
        floor = draw_material(str(rng.choice(FLOOR_MATERIALS)), rng)
        wall = draw_material(str(rng.choice(WALL_MATERIALS, p=[0.45, 0.2, 0.3, 0.05])), rng)
        ceiling = draw_material("plaster", rng)
        decals: list[tuple[int, Decal]] = []
        used: list[tuple[int, float, float]] = [(s, a - 0.9, a + 0.9) for s, a in door_sides.get(k, [])]

        def free_span(side: int, width: float) -> tuple[float, float] | None:
            lo, hi = _side_span(room, side)
            for _ in range(12):
                if hi - lo < width + 0.6:
                    return None
                a = float(rng.uniform(lo + 0.3, hi - 0.3 - width))
                if all(s != side or a + width < u0 or a > u1 for s, u0, u1 in used):
                    used.append((side, a - 0.1, a + width + 0.1))
                    return a, a + width
            return None

        light = np.array([(x0 + x1) / 2, (y0 + y1) / 2, h - 0.3])
        outer = [s for s in range(4) if not _shares_side(lay.rooms, k, s)]
        for _ in range(int(rng.integers(cfg.windows_per_room[0], cfg.windows_per_room[1] + 1))):
            side, width = int(rng.integers(4)), float(rng.uniform(0.8, 1.6))
            if side not in outer:  # a window looks outside: never into the next room
                continue
            span = free_span(side, width)
            if span is None:
                continue
            z0, z1 = float(rng.uniform(0.8, 1.0)), float(rng.uniform(1.9, min(2.3, h - 0.15)))
            sky = _hsv(rng.uniform(0.55, 0.62), rng.uniform(0.0, 0.15), 1.0)
            decals.append((side, Decal("window", (span[0], z0, span[1], z1), sky, frame=0.06,
                                       frame_colour=_hsv(0.1, 0.05, rng.uniform(0.8, 0.95)))))
            centre = (span[0] + span[1]) / 2
            inward = {0: (centre, y1 - 0.6), 1: (x0 + 0.6, centre), 2: (centre, y0 + 0.6), 3: (x1 - 0.6, centre)}[side]
            light = np.array([*inward, (z0 + z1) / 2])
        if rng.random() < 0.4:  # a closed door painted on a wall: what the room leads to, elsewhere
            side = int(rng.integers(4))
            span = free_span(side, 0.85)
            if span is not None:
                decals.append((side, Decal("door", (span[0], 0.0, span[1], 2.05),
                                           _hsv(rng.uniform(0.05, 0.12), rng.uniform(0.2, 0.6), rng.uniform(0.3, 0.9)),
                                           frame=0.07, frame_colour=_hsv(0.1, 0.05, rng.uniform(0.7, 0.95)))))
        for _ in range(int(rng.integers(cfg.pictures_per_room[0], cfg.pictures_per_room[1] + 1))):
            side, width = int(rng.integers(4)), float(rng.uniform(0.35, 1.1))
            span = free_span(side, width)
            if span is None:
                continue
            z0 = float(rng.uniform(1.1, 1.5))
            pic = _picture(rng)
            pic.rect = (span[0], z0, span[1], min(z0 + width * rng.uniform(0.6, 1.2), h - 0.25))
            decals.append((side, pic))
        if rng.random() < cfg.rug_share:
            w, d = rng.uniform(1.2, 2.4), rng.uniform(0.9, 1.8)
            cx, cy = rng.uniform(x0 + w / 2 + 0.2, max(x1 - w / 2 - 0.2, x0 + w / 2 + 0.21)), \
                rng.uniform(y0 + d / 2 + 0.2, max(y1 - d / 2 - 0.2, y0 + d / 2 + 0.21))
            rug = draw_material(str(rng.choice(("carpet", "fabric"))), rng)
            decals.append((-1, Decal("rug", (cx - w / 2, cy - d / 2, cx + w / 2, cy + d / 2), rug.base, frame=0.08,
                                     frame_colour=rug.accent, seed=rug.seed)))
        out.append(RoomLook(floor, wall, ceiling, light, float(rng.uniform(2.0, 4.0)), decals))
    return out


def _in_rect(u: np.ndarray, v: np.ndarray, rect) -> np.ndarray:
    return (u >= rect[0]) & (u <= rect[2]) & (v >= rect[1]) & (v <= rect[3])


def _decal_colour(dec: Decal, u: np.ndarray, v: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Colours of points (u, v) inside a decal's rectangle: frame band, then its content."""
    x0, y0, x1, y1 = dec.rect
    edge = np.minimum.reduce([u - x0, x1 - u, v - y0, y1 - v])
    if dec.kind == "window":  # bright sky, brighter towards the top, with a cross bar
        inner = dec.colour[None] * (0.9 + 0.1 * ((v - y0) / max(y1 - y0, 1e-6)))[:, None]
        bar = (np.abs(u - (x0 + x1) / 2) < 0.025) | (np.abs(v - (y0 + y1) / 2) < 0.025)
        inner = np.where(bar[:, None], dec.frame_colour[None], inner)
    elif dec.kind == "picture":  # an abstract image: fractal noise between three hues
        t = fbm(u * 3, v * 3, dec.seed)
        a, b = dec.colour, np.roll(dec.colour, 1) * 0.9
        inner = _mix(a, b, t) * (0.7 + 0.5 * fbm(u * 9, v * 9, dec.seed + 1))[:, None]
    elif dec.kind == "door":  # a panelled door with a handle
        inner = dec.colour[None] * (0.9 + 0.15 * fbm(u * 4, v * 4, dec.seed))[:, None]
        panel = (np.minimum.reduce([u - x0, x1 - u]) > 0.15) & (np.abs(v - 1.0) > 0.12) & (v > 0.25) & (v < y1 - 0.2)
        inner = np.where(panel[:, None], inner * 0.9, inner)
        handle = (np.abs(u - (x1 - 0.12)) < 0.04) & (np.abs(v - 1.0) < 0.03)
        inner = np.where(handle[:, None], np.array([[0.75, 0.72, 0.6]]), inner)
    else:  # rug
        inner = pattern(Material("carpet", dec.colour, dec.frame_colour, 1.0, 0.0, dec.seed), np.stack([u, v], 1))
    return np.where((edge < dec.frame)[:, None], dec.frame_colour[None] * np.ones_like(base), inner)


def _object_colours(obj, mat: Material, pts: np.ndarray, normals: np.ndarray, rng_seed: int) -> np.ndarray:
    """An object's Gaussians coloured by its material, with its category's own details."""
    rgb = pattern(mat, surface_coords(pts - obj.center, normals))
    z = pts[:, 2]
    if obj.category == "plant":  # a terracotta pot below the foliage
        pot = z < 0.37
        leaves = pattern(Material("fabric", _hsv(0.28 + 0.06 * _hash01(np.array([rng_seed]), np.array([1]), 3)[0], 0.6, 0.45),
                                  _hsv(0.25, 0.7, 0.25), 0.15, 0.0, rng_seed), pts[:, :2] * 3 + pts[:, 1:] * 2)
        rgb = np.where(pot[:, None], np.array([[0.62, 0.33, 0.2]]) * (0.9 + 0.1 * rgb.mean(1, keepdims=True)), leaves)
    elif obj.category == "tv_monitor":  # a dark screen above the stand
        screen = z > 0.65
        rgb = np.where(screen[:, None], np.array([[0.05, 0.06, 0.08]]) + 0.04 * rgb, rgb)
    elif obj.category == "bed":  # bedding on the mattress, a headboard behind
        sheet = (z > 0.3) & (z < 0.52) | (normals[:, 2] > 0.7) & (z < 0.55)
        rgb = np.where(sheet[:, None], np.array([[0.9, 0.89, 0.86]]) * (0.85 + 0.2 * rgb.mean(1, keepdims=True)), rgb)
    elif obj.category == "toilet":
        rgb = np.full_like(rgb, 0.93) * (0.95 + 0.05 * rgb.mean(1, keepdims=True))
    return rgb


def dress(lay, points: np.ndarray, normals: np.ndarray, inst: np.ndarray, rng: np.random.Generator,
          cfg: LookConfig, door_height: float = 2.1, details: list | None = None,
          detail_of: np.ndarray | None = None) -> np.ndarray:
    """Colours [M, 3] (0..1) of a layout's surface Gaussians: materials, painted details and light.

    Args:
        lay: the scene's Layout (rooms, doors, objects, wall height).
        points: [M, 3] canonical-frame centres (z up, floor z = 0), m.
        normals: [M, 3] their surfaces' outward normals.
        inst: [M] instance ids (0: structure, >= 1: the layout's objects).
        rng: the look's own stream (the geometry's draws are not touched).
        door_height: the doorways' height (their frames go round them), m.
        details: stages.synthesize.furnish.Detail list; detail_of: [M] the detail each Gaussian
            belongs to (-1: none). A detail's Gaussians get its own material.
    """
    h = lay.wall_height
    rooms = np.asarray(lay.rooms, float)
    looks = plan_rooms(lay, rng, cfg)
    ambient = float(rng.uniform(*cfg.ambient))
    tint = np.array([1.0, 1.0, 1.0]) + np.array([0.06, 0.0, -0.1]) * float(rng.uniform(-0.6, 1.0))
    base_h = float(rng.uniform(0.06, 0.12))
    base_c = _hsv(rng.uniform(0.05, 0.12), rng.uniform(0.0, 0.3), rng.uniform(0.35, 0.95))
    frame_c = _hsv(rng.uniform(0.05, 0.12), rng.uniform(0.0, 0.3), rng.uniform(0.6, 0.95))
    obj_mats = {o.instance_id: draw_material(str(rng.choice(FURNITURE_MATERIALS[o.category])), rng) for o in lay.objects}
    rgb = np.zeros((len(points), 3))
    shade = np.ones(len(points))
    # the room each Gaussian faces: its centre pushed along its normal, into the nearest room
    probe = points[:, :2] + 0.15 * normals[:, :2]
    inside = ((probe[:, None, 0] >= rooms[None, :, 0]) & (probe[:, None, 0] <= rooms[None, :, 2])
              & (probe[:, None, 1] >= rooms[None, :, 1]) & (probe[:, None, 1] <= rooms[None, :, 3]))
    dx = np.maximum(np.maximum(rooms[None, :, 0] - probe[:, None, 0], probe[:, None, 0] - rooms[None, :, 2]), 0)
    dy = np.maximum(np.maximum(rooms[None, :, 1] - probe[:, None, 1], probe[:, None, 1] - rooms[None, :, 3]), 0)
    room_of = np.where(inside.any(1), np.argmax(inside, 1), np.argmin(dx * dx + dy * dy, 1))
    structure = inst == 0
    floor = structure & (normals[:, 2] > 0.7) & (points[:, 2] < 0.2)
    ceiling = structure & (normals[:, 2] < -0.7) & (points[:, 2] > h - 0.2)
    wall = structure & ~floor & ~ceiling
    emissive = np.zeros(len(points), bool)  # windows are light, not lit
    for k, (room, look) in enumerate(zip(rooms, looks)):
        mine = room_of == k
        for sel, mat in ((floor & mine, look.floor), (wall & mine, look.wall), (ceiling & mine, look.ceiling)):
            idx = np.flatnonzero(sel)
            if len(idx):
                rgb[idx] = pattern(mat, surface_coords(points[idx], normals[idx]))
        idx = np.flatnonzero(wall & mine)
        side = _room_side(points[idx], room)
        u, v = _along(points[idx], side), points[idx, 2]
        rgb[idx] = np.where((v < base_h)[:, None], base_c[None], rgb[idx])  # the baseboard
        for s, dec in look.decals:
            if s >= 0:
                hit = (side == s) & _in_rect(u, v, dec.rect)
                if hit.any():
                    rgb[idx[hit]] = _decal_colour(dec, u[hit], v[hit], rgb[idx[hit]])
                if dec.kind == "window":  # its glass inside the frame is light, not lit
                    x0, y0, x1, y1 = dec.rect
                    emissive[idx[(side == s) & _in_rect(u, v, (x0 + dec.frame, y0 + dec.frame, x1 - dec.frame,
                                                                y1 - dec.frame))]] = True
        fidx = np.flatnonzero(floor & mine)
        for s, dec in look.decals:
            if s < 0:
                hit = _in_rect(points[fidx, 0], points[fidx, 1], dec.rect)
                if hit.any():
                    rgb[fidx[hit]] = _decal_colour(dec, points[fidx[hit], 0], points[fidx[hit], 1], rgb[fidx[hit]])
        # light: ambient plus the room's own light, falling off with distance
        sel = np.flatnonzero(mine)
        d = np.linalg.norm(points[sel] - look.light[None], axis=1)
        shade[sel] = ambient + (1 - ambient) * 1.35 / (1 + (d / look.light_range) ** 2)
        # occlusion: where the floor meets the walls, walls near the floor and the ceiling, corners
        x0, y0, x1, y1 = room
        edge = np.minimum.reduce([points[sel, 0] - x0, x1 - points[sel, 0], points[sel, 1] - y0, y1 - points[sel, 1]])
        fl, wl, cl = floor[sel], wall[sel], ceiling[sel]
        occ = np.ones(len(sel))
        occ[fl] *= 1 - cfg.occlusion * np.exp(-np.maximum(edge[fl], 0) / 0.25)
        zs = points[sel, 2]
        occ[wl] *= (1 - cfg.occlusion * 0.8 * np.exp(-zs[wl] / 0.2)) * (1 - cfg.occlusion * 0.5 * np.exp(-(h - zs[wl]) / 0.3))
        corner = np.sort(np.stack([points[sel, 0] - x0, x1 - points[sel, 0], points[sel, 1] - y0, y1 - points[sel, 1]], 1),
                         axis=1)[:, 1]  # the second nearest wall: small in a corner
        occ[wl] *= 1 - cfg.occlusion * 0.5 * np.exp(-np.maximum(corner[wl], 0) / 0.2)
        occ[cl] *= (1 - cfg.occlusion * 0.6 * np.exp(-np.maximum(edge[cl], 0) / 0.3)) * 0.85
        shade[sel] *= occ
    # a frame round every doorway, on both faces of its wall and on its reveals
    fw = 0.08
    for d in lay.doors:
        along_x = (d[2] - d[0]) > (d[3] - d[1])
        a0, a1, c = (d[0], d[2], (d[1] + d[3]) / 2) if along_x else (d[1], d[3], (d[0] + d[2]) / 2)
        idx = np.flatnonzero(wall & (np.abs(points[:, 1 if along_x else 0] - c) < 0.25))
        u, z = points[idx, 0 if along_x else 1], points[idx, 2]
        near = (u > a0 - fw) & (u < a1 + fw) & (z < door_height + fw)
        rgb[idx[near]] = frame_c * (0.92 + 0.08 * fbm(u[near] * 5, z[near] * 5, 7))[:, None]
    # furniture: its material and details; the floor under and around it darker
    for o in lay.objects:
        sel = np.flatnonzero(inst == o.instance_id)
        if len(sel):
            rgb[sel] = _object_colours(o, obj_mats[o.instance_id], points[sel], normals[sel], obj_mats[o.instance_id].seed)
            shade[sel] *= 1 - cfg.occlusion * 0.6 * np.exp(-points[sel, 2] / 0.1)
        lo, hi = o.aabb()
        fidx = np.flatnonzero(floor)
        gap = np.hypot(np.maximum(np.maximum(lo[0] - points[fidx, 0], points[fidx, 0] - hi[0]), 0),
                       np.maximum(np.maximum(lo[1] - points[fidx, 1], points[fidx, 1] - hi[1]), 0))
        under = 0.9 if o.category in ("bed", "sofa", "cabinet", "toilet") else 0.55  # closed bases shadow more
        shade[fidx] *= 1 - cfg.occlusion * under * np.exp(-gap / 0.15)
    if details and detail_of is not None:
        for k, det in enumerate(details):
            sel = np.flatnonzero(detail_of == k)
            if not len(sel):
                continue
            mat = draw_material(det.look, rng)
            if det.hue is not None:  # the detail's own colour: its hue, the material's saturation and value
                import colorsys

                _, sat, val = colorsys.rgb_to_hsv(*mat.base)
                mat.base = _hsv(det.hue, max(sat, 0.35), val)
                mat.accent = mat.base * 0.7
            rgb[sel] = pattern(mat, surface_coords(points[sel] - det.part.center, normals[sel]))
            shade[sel] *= 1 - cfg.occlusion * 0.5 * np.exp(-points[sel, 2] / 0.1)
    lit = rgb * (shade[:, None] * tint[None])
    lit = np.where(emissive[:, None], np.minimum(rgb * 1.05, 1.0), lit)
    lit = lit * np.exp(rng.normal(0, cfg.speckle, (len(lit), 1))) if cfg.speckle else lit
    # mostly brightness (a capture's grain is grey, not confetti), a little per channel
    grain = rng.normal(0, cfg.colour_noise, (len(lit), 1)) + rng.normal(0, cfg.colour_noise * cfg.chroma_share, lit.shape)
    return np.clip(lit + grain, 0.0, 1.0)
