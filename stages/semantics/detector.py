"""The `detector` segmenter: a box detector on the rendered views, boxes turned into masks by depth.

Real, shippable COCO detectors (80 classes, a few MB each, sha256-checked on load:
navcore/io/models.py, provenance and licence beside each in navcore/models/), run on the CPU through
OpenCV's DNN module: PP-PicoDet-S 320 and YOLOX-Nano 416 (ONNX, Apache-2.0) and Yolo-Fastest-1.1-XL
(Darknet, public domain), or a user's Darknet folder or ONNX file (YOLO, GFL or YOLOX heads). The
default detector is a per-category mix of the shipped models chosen by measurement
(navcore/models/detector.json): each model runs once a view and boxes its own categories. COCO classes
map onto the goal vocabulary by a written table (COCO_TO_GOAL); the goal categories COCO cannot name
(cabinet) are never produced.

A box frames an object and whatever lies behind it (wall, floor). The mask the lifting needs is
taken from the view's rendered depth inside the box (`box_mask`): pixels on the floor (below
`floor_margin` in the aligned frame) are dropped, the depths left are histogrammed, and the nearest
depth mode holding at least `mode_share` of them is the object; the mask is the box's pixels within
`depth_band` metres behind that mode (and a little in front), its largest 4-connected component. So
the wall behind a chair and the floor under it get no vote.

Per-view precision of a small COCO detector on renders is low; what makes a goal is multi-view
consistency (lifting: a cell needs votes from `lifting.min_support` views, a detector instance
needs `min_views` distinct views whose masks agree in 3D, and overlapping instances of categories the
detector confuses, bed and sofa, are one object named by a class vote across the views). The
per-category models, thresholds and allow-list were chosen on the real labelled ScanNet scan and the
3DGS trained on it (benchmarks/goals/semantics_detector.py, which writes them): see
docs/benchmarks/bench_semantics_detector.md.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from navcore.io.models import ModelSpec, default_detector, load_net, model_thresholds
from stages.semantics.segmenters import Segmenter

COCO_TO_GOAL = {
    "bed": "bed",
    "chair": "chair",
    "couch": "sofa", "sofa": "sofa",
    "dining table": "table", "diningtable": "table",
    "toilet": "toilet",
    "tv": "tv_monitor", "tvmonitor": "tv_monitor",
    "potted plant": "plant", "pottedplant": "plant",
}
"""COCO class -> ObjectNav goal category, under both spellings of the class names: COCO's own
(couch, dining table, tv, potted plant) and Darknet's coco.names, which the shipped model uses
(sofa, diningtable, tvmonitor, pottedplant). COCO has no cabinet; its sink, refrigerator, oven and
bench name no default goal category (add them to semantics.categories and detector.class_map)."""


@dataclass
class DetectorConfig:
    """The `detector` segmenter (semantics.segmenter=detector)."""

    model: str | None = None
    """Folder of a Darknet model (*.cfg, *.weights, *.names) or an ONNX file (*.onnx with a
    *.names or classes.txt beside it), or a shipped model's name (yolo_fastest_1.1_coco, picodet_s_320_coco,
    yolox_nano_416_coco); null (with models empty) = the default detector, the per-category mix of shipped
    models that navcore/models/detector.json names."""
    models: dict[str, str] = field(default_factory=dict)
    """Goal category -> the model that boxes it (a path, as `model`), for categories another
    detector sees better; the others are `model`'s. Each model runs once a view. E.g.
    {chair: .../nanodet.onnx}: NanoDet-g boxed the ScanNet room's chairs, which Yolo-Fastest never
    did (docs/own-capture.md, "Other COCO detectors")."""
    class_map: dict[str, str] = field(default_factory=lambda: dict(COCO_TO_GOAL))
    """Detector class name -> goal category (COCO_TO_GOAL); classes not in it are ignored."""
    categories: list[str] | None = None
    """Goal categories the detector may produce (an allow-list); null: the model's own, chosen by
    measurement and written beside it (navcore/models/<model>/thresholds.json, by
    `python -m benchmarks.goals.semantics_detector --choose`: the categories whose boxes were right at
    least half the time on the labelled ScanNet room's renders), or FALLBACK_CATEGORIES for a model
    with no such file. Add a category with semantics.detector.categories=[...] where a capture suits it."""
    confidence: dict[str, float] = field(default_factory=dict)
    """Per-category score thresholds (objectness x class score), over the model's own
    (thresholds.json) where model_thresholds; a category in neither uses default_confidence."""
    default_confidence: float = 0.4
    """Threshold of an allowed category with no threshold of its own."""
    model_thresholds: bool = True
    """Read the model's thresholds.json (its allow-list and thresholds) under what is given here
    (false: categories and confidence alone, as a benchmark that sweeps thresholds needs)."""
    spacing: float = 0.75
    """Free-space pose spacing for this segmenter, metres (semantics.spacing is for the others): a
    COCO detector needs objects large and near in a view; at the stage's 1.5 m / 60 deg it boxed the
    ScanNet room's bed in 2 of 198 views and lifted nothing, at 0.75 m / 30 deg in 20 of 996."""
    yaw_step_deg: float = 30.0
    """Yaw step of the free-space poses for this segmenter, degrees."""
    camera_height: float | None = 1.3
    """Height of the free-space views' camera for this segmenter, metres (null: the embodiment's).
    A COCO detector learnt from photos taken at eye height looking a little down: on the ScanNet
    room at 1.3 m / -15 deg it boxed the sofa in 7 views (5 right) and lifted it, at the robot's
    1.0 m / 0 deg in 2 (none right) and never lifted it (docs/benchmarks/bench_semantics_detector.md,
    "view geometry"); 1.5 m / -20 to -30 deg mistook the sofa seen from above for a bed."""
    camera_pitch_deg: float | None = -15.0
    """Pitch of the free-space views' camera, degrees, negative looks down (null: the embodiment's)."""
    input_size: int = 320
    """Network input side, pixels (a multiple of 32; the model's cfg says 320). A fixed-size ONNX
    model's own size (its JSON beside it) takes precedence."""
    nms: float = 0.45
    """Non-maximum suppression IoU, per category."""
    threads: int = 0
    """OpenCV threads (0 = OpenCV's default: every core)."""
    mask: str = "depth"
    """depth: the box's nearest depth mode (module doc) | box: the whole box (for comparison)."""
    depth_band: float = 0.6
    """Metres behind the nearest depth mode a mask reaches (an object's depth extent)."""
    front_band: float = 0.15
    """Metres in front of the mode a mask reaches."""
    mode_share: float = 0.15
    """The object's mode is the nearest one holding at least this share of the box's depths."""
    floor_margin: float = 0.05
    """Pixels whose point lies below this height (aligned frame, floor z = 0) are floor."""
    min_mask_px: int = 30
    """Masks with fewer pixels are dropped."""
    min_top_m: float = 0.25
    """Instances whose top lies below this height (metres above the floor) are dropped: on the real
    captures without labels every one of the 9 lifted "beds" that were wrong (8 in the wangsha hall,
    1 in the fungi room: blurred floor and display-case bases seen from above) topped out at
    0.06-0.20 m, while every goal category rises above 0.3 m."""
    confusable: list[list[str]] = field(default_factory=lambda: [["bed", "sofa"]])
    """Groups of categories the detector takes for one another: overlapping instances of one group are
    one object, named by a class vote across the views (lifting.class_vote). COCO detectors call a
    sofa seen from above a bed (PicoDet-S on the ScanNet room: docs/benchmarks/bench_semantics_detector.md)."""
    min_views: int = 4
    """An instance needs detections from at least this many distinct views (lifting): on the ScanNet
    scan's renders 3 views kept a false bed beside the real one, 4 only the real one."""


FALLBACK_CATEGORIES = ["bed", "sofa", "table", "tv_monitor", "plant"]
"""The allow-list of a detector model that ships no thresholds.json."""


def resolved(cfg: DetectorConfig) -> DetectorConfig:
    """`cfg` with its models, allow-list and thresholds filled in (module doc): with no model named
    (model null, models empty) the default detector's (navcore/models/detector.json), else the named
    model's thresholds.json; what `cfg` gives itself wins."""
    doc = None
    if cfg.model_thresholds and cfg.model is None and not cfg.models:
        doc = default_detector()
        if doc:
            cfg = replace(cfg, model=doc["model"], models={k: v for k, v in doc["models"].items() if v != doc["model"]})
    if doc is None and cfg.model_thresholds:
        doc = model_thresholds(cfg.model)
    categories = cfg.categories if cfg.categories is not None else list(doc["categories"] if doc else FALLBACK_CATEGORIES)
    confidence = {**(doc["confidence"] if doc else {}), **cfg.confidence}
    return replace(cfg, categories=list(categories), confidence=confidence, model_thresholds=False)


def preprocess(rgb: np.ndarray, spec: ModelSpec, size: int) -> tuple[np.ndarray, float, float]:
    """The network's input blob [1, 3, size, size] of an RGB frame, and the factors (fx, fy) that take
    the input's normalised coordinates to the frame's (1, 1 for a stretch; the letterbox's share)."""
    import cv2

    h, w = rgb.shape[:2]
    img = rgb if spec.channels == "rgb" else rgb[..., ::-1]
    interp = cv2.INTER_CUBIC if spec.interpolation == "cubic" else cv2.INTER_LINEAR
    if spec.resize == "letterbox":
        r = min(size / h, size / w)
        nh, nw = int(h * r), int(w * r)
        canvas = np.full((size, size, 3), spec.pad, np.float32)
        canvas[:nh, :nw] = cv2.resize(np.ascontiguousarray(img), (nw, nh), interpolation=interp)
        fx, fy = size / (w * r), size / (h * r)
    else:
        canvas = cv2.resize(np.ascontiguousarray(img), (size, size), interpolation=interp).astype(np.float32)
        fx = fy = 1.0
    x = (canvas * np.float32(spec.scale) - np.asarray(spec.mean, np.float32)) / np.asarray(spec.std, np.float32)
    return np.ascontiguousarray(x.transpose(2, 0, 1)[None], dtype=np.float32), fx, fy


def detect(net, rgb: np.ndarray, size: int, spec: ModelSpec | None = None) -> np.ndarray:
    """Raw detections of one frame: [M, 4 + 1 + C] (cx, cy, w, h normalised to the frame, objectness,
    class scores), whichever the model's family (navcore.io.models.ModelSpec)."""
    spec = spec or ModelSpec()
    blob, fx, fy = preprocess(rgb, spec, size)
    net.setInput(blob)
    names = net.getUnconnectedOutLayersNames()
    outs = net.forward(names)
    if spec.family == "gfl":
        raw = gfl_raw(dict(zip(names, outs)), size, spec.strides)
    elif spec.family == "yolox":
        raw = yolox_raw(outs[0], size, spec.strides or (8, 16, 32))
    else:
        raw = np.concatenate([o.reshape(-1, o.shape[-1]) for o in outs])
    if fx != 1.0 or fy != 1.0:
        raw = raw.copy()
        raw[:, [0, 2]] *= fx
        raw[:, [1, 3]] *= fy
    return raw


def level_stride(size: int, cells: int) -> int:
    """The stride of an output level of `cells` cells on a square input of side `size`: the power of
    two whose ceil(size / stride) squared is the count (416 / 64 leaves a 7 x 7 level)."""
    side = int(round(np.sqrt(cells)))
    stride = int(2 ** round(np.log2(size / side)))
    if side * side != cells or -(-size // stride) != side:
        raise ValueError(f"an output level of {cells} cells is no square grid of a {size}-pixel input")
    return stride


def gfl_raw(outs: dict[str, np.ndarray], size: int, strides: tuple[int, ...] | None = None) -> np.ndarray:
    """Generalized-focal-loss heads (NanoDet, PP-PicoDet: per stride, class scores [1, n, C] after the
    sigmoid and box distributions [1, n, 4 (reg_max + 1)]) as [n, 4 + 1 + C] rows like a YOLO's: each
    side's distance from its cell's centre is the expectation of its softmaxed distribution, in
    strides; objectness 1."""
    widths = sorted({o.shape[-1] for o in outs.values()})  # the box outputs' 4 (reg_max + 1) < COCO's 80 classes
    flat = [o.reshape(o.shape[-2], o.shape[-1]) for o in outs.values()]
    scores = sorted((o for o in flat if o.shape[-1] == widths[-1]), key=len, reverse=True)
    regs = sorted((o for o in flat if o.shape[-1] == widths[0]), key=len, reverse=True)
    if len(widths) != 2 or widths[0] % 4 or len(scores) != len(regs) or any(len(a) != len(b) for a, b in zip(scores, regs)):
        raise ValueError(f"GFL detector outputs do not pair up by stride: {[o.shape for o in outs.values()]}")
    rows = []
    for k, (sc, rg) in enumerate(zip(scores, regs)):
        stride = strides[k] if strides else level_stride(size, len(sc))
        side = -(-size // stride)
        d = rg.reshape(len(rg), 4, -1)
        d = np.exp(d - d.max(-1, keepdims=True))
        dist = (d / d.sum(-1, keepdims=True)) @ np.arange(d.shape[-1], dtype=np.float32) * stride  # l, t, r, b pixels
        iy, ix = np.divmod(np.arange(len(sc)), side)
        cx, cy = (ix + 0.5) * stride, (iy + 0.5) * stride
        x0, y0, x1, y1 = cx - dist[:, 0], cy - dist[:, 1], cx + dist[:, 2], cy + dist[:, 3]
        rows.append(np.column_stack([(x0 + x1) / 2 / size, (y0 + y1) / 2 / size, (x1 - x0) / size, (y1 - y0) / size,
                                     np.ones(len(sc), np.float32), sc]))
    return np.concatenate(rows).astype(np.float32)


def yolox_raw(out: np.ndarray, size: int, strides: tuple[int, ...]) -> np.ndarray:
    """YOLOX's undecoded output [1, n, 5 + C] (per cell of each stride's grid, row-major: dx, dy,
    log w, log h in strides, then objectness and class scores after the sigmoid) as YOLO rows: centre
    (dx + gx, dy + gy) * stride, size exp(log) * stride, normalised by the input side."""
    o = out.reshape(-1, out.shape[-1])
    grid, stride = [], []
    for s in strides:
        ys, xs = np.mgrid[:size // s, :size // s]
        grid.append(np.stack([xs.ravel(), ys.ravel()], 1))
        stride.append(np.full((xs.size, 1), s, np.float32))
    grid, st = np.concatenate(grid), np.concatenate(stride)
    if len(grid) != len(o):
        raise ValueError(f"YOLOX output of {len(o)} rows; a {size}-pixel input at strides {strides} has {len(grid)}")
    xy = (o[:, :2] + grid) * st / size
    wh = np.exp(np.minimum(o[:, 2:4], 20.0)) * st / size
    return np.concatenate([xy, wh, o[:, 4:]], 1).astype(np.float32)


def boxes_of(raw: np.ndarray, names: list[str], cfg: DetectorConfig, width: int, height: int
             ) -> list[tuple[str, np.ndarray, float]]:
    """(goal category, box [x0, y0, x1, y1] pixels, score) of the allowed categories after
    per-category thresholds and NMS."""
    import cv2

    if not len(raw):
        return []
    if cfg.categories is None:
        cfg = resolved(cfg)
    cls = raw[:, 5:].argmax(1)
    score = raw[:, 4] * raw[np.arange(len(raw)), 5 + cls]
    out = []
    by_cat: dict[str, list[int]] = {}
    for i in np.flatnonzero(score > min([cfg.default_confidence, *cfg.confidence.values()])):
        cat = cfg.class_map.get(names[cls[i]] if cls[i] < len(names) else "")
        if cat in cfg.categories and score[i] >= cfg.confidence.get(cat, cfg.default_confidence):
            by_cat.setdefault(cat, []).append(int(i))
    for cat, idx in sorted(by_cat.items()):
        cx, cy, w, h = (raw[idx, k] for k in range(4))
        xywh = np.stack([(cx - w / 2) * width, (cy - h / 2) * height, w * width, h * height], 1)
        keep = cv2.dnn.NMSBoxes(xywh.tolist(), score[idx].tolist(), 0.0, cfg.nms)
        for k in np.asarray(keep).reshape(-1):
            x, y, bw, bh = xywh[k]
            box = np.array([max(0.0, x), max(0.0, y), min(float(width), x + bw), min(float(height), y + bh)])
            if box[2] > box[0] and box[3] > box[1]:
                out.append((cat, box, float(score[idx[k]])))
    return out


def box_mask(box: np.ndarray, depth: np.ndarray, K: np.ndarray, cam_to_world: np.ndarray, cfg: DetectorConfig
             ) -> np.ndarray | None:
    """The object's pixels of a box: the nearest substantial depth mode off the floor, grown over
    `depth_band`, its largest connected component ([H, W] bool), or None."""
    from scipy import ndimage

    h, w = depth.shape
    x0, y0, x1, y1 = int(box[0]), int(box[1]), int(np.ceil(box[2])), int(np.ceil(box[3]))
    mask = np.zeros((h, w), bool)
    if cfg.mask == "box":
        mask[y0:y1, x0:x1] = depth[y0:y1, x0:x1] > 0
        return mask if mask.sum() >= cfg.min_mask_px else None
    if cfg.mask != "depth":
        raise ValueError(f"semantics.detector.mask={cfg.mask!r}; choose depth | box")
    d = depth[y0:y1, x0:x1]
    rows, cols = np.mgrid[y0:y1, x0:x1]
    z = d
    x = (cols + 0.5 - K[0, 2]) / K[0, 0] * z
    y = (rows + 0.5 - K[1, 2]) / K[1, 1] * z
    height = cam_to_world[2, 0] * x + cam_to_world[2, 1] * y + cam_to_world[2, 2] * z + cam_to_world[2, 3]
    ok = (d > 0) & (height > cfg.floor_margin)
    if ok.sum() < cfg.min_mask_px:
        return None
    vals = d[ok]
    bins = np.arange(vals.min(), vals.max() + 0.1, 0.05)
    hist = np.histogram(vals, bins)[0] if len(bins) > 1 else np.array([len(vals)])
    smooth = np.convolve(hist, np.ones(3) / 3, mode="same")
    # the nearest local maximum whose +-band window holds enough of the box's depths
    mode = None
    for i in range(len(smooth)):
        if (i == 0 or smooth[i] >= smooth[i - 1]) and (i == len(smooth) - 1 or smooth[i] >= smooth[i + 1]):
            centre = bins[i] + 0.025 if len(bins) > 1 else float(vals[0])
            share = np.mean((vals >= centre - cfg.front_band) & (vals <= centre + cfg.depth_band))
            if share >= cfg.mode_share:
                mode = centre
                break
    if mode is None:
        return None
    sel = ok & (d >= mode - cfg.front_band) & (d <= mode + cfg.depth_band)
    lab, n = ndimage.label(sel)
    if n == 0:
        return None
    sizes = np.bincount(lab.ravel())[1:]
    sel = lab == (1 + int(sizes.argmax()))
    if sel.sum() < cfg.min_mask_px:
        return None
    mask[y0:y1, x0:x1] = sel
    return mask


class DetectorSegmenter(Segmenter):
    """Boxes of a COCO detector on the rendered RGB, masks from the rendered depth (module doc).

    Needs context["depth"] and context["cam_to_world"] (the semantics stage passes them)."""

    def __init__(self, cfg: DetectorConfig, prompts_of: dict[str, str]):
        import cv2

        cfg = resolved(cfg)
        self.cfg = cfg
        if cfg.threads:
            cv2.setNumThreads(int(cfg.threads))
        # one entry per distinct model: (net, class names, spec, input side, the categories it boxes)
        own = {m: [c for c in cfg.categories if cfg.models.get(c) == m] for m in set(cfg.models.values())}
        rest = [c for c in cfg.categories if c not in cfg.models]
        self.runs = []
        for model, cats in [(cfg.model, rest), *sorted(own.items())]:
            if not cats:
                continue
            net, names, spec = load_net(model)
            self.runs.append((net, names, spec, spec.input_size or cfg.input_size, replace(cfg, categories=cats)))
        self.input_size = self.runs[0][3] if self.runs else cfg.input_size
        self.prompts_of = prompts_of  # goal category -> the stage's prompt string
        self.last_boxes: list = []  # the boxes of the last frame (category, box, score): benchmarks read them

    @classmethod
    def from_scene(cls, scene, catalog, renderer, cfg, seed: int) -> "DetectorSegmenter":
        return cls(cfg.detector, {c: cfg.prompt(c) for c in cfg.categories})

    def segment(self, rgb: np.ndarray, prompts: list[str], context: dict) -> dict[str, list[tuple[np.ndarray, float]]]:
        if context.get("depth") is None or context.get("cam_to_world") is None:
            raise ValueError("the detector segmenter needs the view's rendered depth and camera pose in its context")
        h, w = rgb.shape[:2]
        out: dict[str, list] = {p: [] for p in prompts}
        frame = np.ascontiguousarray(rgb)
        self.last_boxes = [b for net, names, spec, size, cfg in self.runs
                           for b in boxes_of(detect(net, frame, size, spec), names, cfg, w, h)]
        for cat, box, score in self.last_boxes:
            p = self.prompts_of.get(cat)
            if p not in out:
                continue
            m = box_mask(box, context["depth"], context["K"], context["cam_to_world"], self.cfg)
            if m is not None:
                out[p].append((m, score))
        return out
