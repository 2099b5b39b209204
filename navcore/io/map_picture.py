"""Top-down map pictures for people: the map enlarged to a readable size, a scale bar on it and a
legend under it (the costmap picture of the costmap stage, copied into the asset; the screening
picture of the screen stage)."""
from __future__ import annotations

import numpy as np

SCALE_STEPS = (0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)
FRAME_NOTE = "aligned frame (the file's up turned onto +z): x to the right, y up the page"
"""What every top-down picture of a scene says about its axes: the costmap and screening pictures and
`navarena inspect`'s picture draw the same frame, with an x / y axis glyph in the lower-right corner."""
"""Scale-bar lengths, metres: the longest that spans at most a quarter of the map's width."""


def annotated(img: np.ndarray, resolution: float, legend: list[tuple[tuple[int, int, int], str]],
              min_side: int = 480, note: str | None = None) -> np.ndarray:
    """`img` ([ny, nx, 3] uint8, one pixel a map cell of `resolution` metres, north up) enlarged by
    the integer factor that brings its longer side to at least `min_side` pixels, a scale bar in
    its lower-left corner, and under it one legend row per (colour, label) and the note's lines."""
    from PIL import Image, ImageDraw

    k = max(1, int(np.ceil(min_side / max(img.shape[:2]))))
    big = np.repeat(np.repeat(img, k, 0), k, 1)
    h, w = big.shape[:2]
    metres = max([s for s in SCALE_STEPS if s / resolution * k <= w / 4] or [SCALE_STEPS[0]])
    bar = max(int(round(metres / resolution * k)), 1)
    row, pad = 16, 8
    notes = note.split("\n") if note else []
    lines = len(legend) + len(notes)
    width = max(w, 420)
    canvas = Image.new("RGB", (width, h + pad * 2 + row * lines), (255, 255, 255))
    canvas.paste(Image.fromarray(big), (0, 0))
    d = ImageDraw.Draw(canvas)
    x0, y0 = 10, h - 14
    d.rectangle([x0 - 4, y0 - 14, x0 + bar + 4, y0 + 8], fill=(255, 255, 255))
    d.rectangle([x0, y0, x0 + bar, y0 + 4], fill=(0, 0, 0))
    d.text((x0, y0 - 13), f"{metres:g} m", fill=(0, 0, 0))
    ax, ay, arm = w - 40, h - 12, 24  # the axes: x to the right, y up the page
    d.rectangle([ax - 6, ay - arm - 14, ax + arm + 12, ay + 6], fill=(255, 255, 255))
    d.line([ax, ay, ax + arm, ay], fill=(200, 0, 0), width=2)
    d.line([ax, ay, ax, ay - arm], fill=(0, 150, 0), width=2)
    d.text((ax + arm + 2, ay - 6), "x", fill=(200, 0, 0))
    d.text((ax + 3, ay - arm - 12), "y", fill=(0, 150, 0))
    y = h + pad
    for colour, label in legend:
        d.rectangle([10, y + 2, 22, y + 12], fill=tuple(colour), outline=(0, 0, 0))
        d.text((30, y + 1), label, fill=(0, 0, 0))
        y += row
    for text in notes:
        d.text((10, y + 1), text, fill=(80, 80, 80))
        y += row
    return np.asarray(canvas)


TOPDOWN_LEGEND = [((255, 255, 255), "free: the robot's centre may be here"),
                  ((170, 205, 240), "free island cut off from the main free space (no episodes)"),
                  ((160, 160, 160), "within the robot's radius (+ margin) of an obstacle"),
                  ((0, 0, 0), "obstacle in the robot's body band"),
                  ((235, 190, 190), "unsupported: no floor seen (outside the scene, holes)")]


def topdown_image(raw, support, occ, components=None) -> np.ndarray:
    """RGB picture of a costmap (north up), one pixel a cell: free white (islands not connected to
    the largest free component light blue), obstacles black, inflation grey, unsupported pink."""
    img = np.full(occ.shape + (3,), 255, np.uint8)
    if components is not None:
        img[components > 1] = TOPDOWN_LEGEND[1][0]
    img[occ & support] = TOPDOWN_LEGEND[2][0]
    img[raw] = TOPDOWN_LEGEND[3][0]
    img[~support] = TOPDOWN_LEGEND[4][0]
    return img[::-1]


def topdown_picture(raw, support, occ, components, resolution: float, embodiment: str) -> np.ndarray:
    """The costmap picture (03_costmaps/{scene_id}.png, the asset's costmap_topdown.png): topdown_image
    enlarged, with a scale bar and its legend."""
    return annotated(topdown_image(raw, support, occ, components), resolution, TOPDOWN_LEGEND,
                     note=f"costmap of {embodiment} at {resolution:g} m a cell; {FRAME_NOTE}")
