"""Segmenters: an RGB frame and category prompts -> per-category masks with scores.

    seg.segment(rgb, prompts, context) -> {prompt: [(mask bool [H, W], score), ...]}
    seg.segment_batch(rgbs, prompts, contexts) -> one such dict per frame (batched models override it)

`rgb` is [H, W, 3] uint8. `context` carries what a privileged segmenter may use: the frame's
camera (viewmat, K, cam_to_world), its rendered depth ([H, W] metres, 0 where nothing) and, when
the segmenter declares per-Gaussian `gaussian_features`, their
composite rendered in the same pass as the frame (`extra`, [H, W, C]).

Implementations by registry key (or "module:Class"), each built by `from_scene(scene, ...)`:
`oracle` renders the ground-truth per-Gaussian instance labels of synthetic scenes with the scene
renderer and passes them through a corruption model that imitates a real segmenter (documented in
`Corruption`); `sam3` is SAM3 concept segmentation (stages/semantics/sam3_segmenter.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from navcore.registry import Registry

SEGMENTERS = Registry("segmenter", {
    "oracle": "stages.semantics.segmenters:OracleSegmenter",
    "sam3": "stages.semantics.sam3_segmenter:Sam3Segmenter",  # imports torch and sam3 when used
    "open_vocab": "stages.semantics.open_vocab:OpenVocabSegmenter",  # OWLv2 + SAM through transformers
    "detector": "stages.semantics.detector:DetectorSegmenter",  # a COCO box detector (OpenCV DNN), depth masks
})


@dataclass
class Corruption:
    """How the oracle's masks are spoiled, per (object, frame), seeded.

    bleed_px: boundary bleeding: each mask is dilated or eroded (sign at random) by up to this many
        pixels. miss_rate: probability that an object is not detected in a frame. confusion_rate:
        probability that a detected object is reported under another category. fp_blobs: mean number
        (Poisson) of false-positive blobs per frame, discs of fp_radius_px pixels (at random in
        [fp_radius_px / 2, fp_radius_px]) under a random category.
    """

    bleed_px: int = 0
    miss_rate: float = 0.0
    confusion_rate: float = 0.0
    fp_blobs: float = 0.0
    fp_radius_px: int = 12


CORRUPTION_LEVELS = {
    "none": Corruption(),
    "moderate": Corruption(bleed_px=3, miss_rate=0.15, confusion_rate=0.05, fp_blobs=0.3),
    "heavy": Corruption(bleed_px=6, miss_rate=0.3, confusion_rate=0.15, fp_blobs=1.0),
}


def corrupt(instance_map: np.ndarray, categories: dict[int, str], prompts: list[str], c: Corruption,
            rng: np.random.Generator) -> dict[str, list[tuple[np.ndarray, float]]]:
    """Per-category masks from an instance-id image [H, W] (0 = none), spoiled by `c`."""
    out: dict[str, list] = {p: [] for p in prompts}
    h, w = instance_map.shape
    for iid in np.unique(instance_map[instance_map > 0]):
        cat = categories.get(int(iid))
        if cat not in out or rng.random() < c.miss_rate:
            continue
        mask = instance_map == iid
        if c.bleed_px > 0:
            k = int(rng.integers(1, c.bleed_px + 1))
            mask = (ndimage.binary_dilation(mask, iterations=k) if rng.random() < 0.5
                    else ndimage.binary_erosion(mask, iterations=k))
        if rng.random() < c.confusion_rate and len(prompts) > 1:
            cat = str(rng.choice([p for p in prompts if p != cat]))
        if mask.any():
            out[cat].append((mask, float(rng.uniform(0.6, 1.0))))
    for _ in range(rng.poisson(c.fp_blobs) if c.fp_blobs > 0 else 0):
        r = rng.uniform(c.fp_radius_px / 2, c.fp_radius_px)
        cy, cx = rng.uniform(0, h), rng.uniform(0, w)
        yy, xx = np.mgrid[:h, :w]
        blob = (yy + 0.5 - cy) ** 2 + (xx + 0.5 - cx) ** 2 <= r * r
        out[str(rng.choice(prompts))].append((blob, float(rng.uniform(0.3, 0.8))))
    return out


class SegmenterUnavailable(ValueError):
    """The segmenter cannot serve this scene (e.g. the oracle on a scene without ground truth)."""


class Segmenter:
    """Interface of a segmenter (see the module doc)."""

    gaussian_features: np.ndarray | None = None
    """[N, C] per-Gaussian features to composite with each frame (context["extra"]); None: none."""

    @classmethod
    def from_scene(cls, scene, catalog, renderer, cfg, seed: int) -> "Segmenter":
        """The segmenter of one scene from the semantics config (`cfg`, SemanticsConfig)."""
        raise NotImplementedError

    def segment(self, rgb: np.ndarray, prompts: list[str], context: dict) -> dict[str, list[tuple[np.ndarray, float]]]:
        raise NotImplementedError

    def segment_batch(self, rgbs, prompts: list[str], contexts: list[dict]) -> list[dict]:
        return [self.segment(r, prompts, c) for r, c in zip(rgbs, contexts)]


class OracleSegmenter(Segmenter):
    """Ground-truth masks rendered from per-Gaussian instance ids, then corrupted.

    Args:
        renderer: navcore.render.Renderer of the scene. instance_ids: [N] int per Gaussian (0 = none).
        categories: {instance id: category}. corruption: a Corruption or a level name. seed: rng seed.
    """

    def __init__(self, renderer, instance_ids: np.ndarray, categories: dict[int, str],
                 corruption: Corruption | str = "none", seed: int = 0, min_weight: float = 0.5):
        self.renderer, self.categories = renderer, categories
        self.c = CORRUPTION_LEVELS[corruption] if isinstance(corruption, str) else corruption
        self.rng = np.random.default_rng(seed)
        ids = np.asarray(instance_ids)
        self.ids = np.unique(ids[ids > 0])
        onehot = np.zeros((len(ids), len(self.ids)), np.float32)
        rows = np.flatnonzero(ids > 0)
        onehot[rows, np.searchsorted(self.ids, ids[rows])] = 1.0
        self.gaussian_features, self.min_weight = onehot, min_weight

    @classmethod
    def from_scene(cls, scene, catalog, renderer, cfg, seed: int) -> "OracleSegmenter":
        """Ground truth of a synthetic scene (its per-Gaussian instance ids and labels.json), or of
        a real scene that ships per-Gaussian labels (SceneSplat arrays or a labelled mesh, see
        navcore.instances.gaussian_labels: its cleaned instances, by the goal vocabulary); the
        corruption of `cfg.oracle`."""
        if not scene.synthetic:
            ids, categories = real_truth(scene, catalog, cfg)
        else:
            src = catalog.dataset("source_synthetic", scene)
            ids = src.read_ground_truth("instance_ids.npy")
            if ids is None:
                raise SegmenterUnavailable(f"scene {scene.scene_id!r} ({scene.name}): the oracle segmenter needs the "
                                           "per-Gaussian ground truth of a synthetic scene")
            labels = src.read_ground_truth("labels.json")["labels"]
            categories = {int(lab["instance_id"]): cfg.prompt(lab["category"]) for lab in labels}
        if len(ids) != renderer.num_gaussians:
            raise SegmenterUnavailable(f"scene {scene.scene_id!r}: the ground truth labels {len(ids)} Gaussians, the "
                                       f"scene has {renderer.num_gaussians} (ingest dropped some); the oracle cannot align them")
        return cls(renderer, ids, categories, cfg.oracle.corruption(), seed, cfg.oracle.min_weight)

    def instance_map(self, viewmat: np.ndarray, K: np.ndarray, width: int, height: int,
                     weights: np.ndarray | None = None) -> np.ndarray:
        """[H, W] instance id of each pixel: the label whose composited weight dominates, if >= min_weight
        (`weights` [H, W, C]: the composite when the frame's render pass made it; else rendered here)."""
        if weights is None:
            weights = self.renderer.render(viewmat[None], K[None], width, height,
                                           features=self.gaussian_features).rgb[0].to("cpu").numpy()
        best = weights.argmax(-1)
        return np.where(weights.max(-1) >= self.min_weight, self.ids[best], 0)

    def segment(self, rgb, prompts: list[str], context: dict) -> dict[str, list[tuple[np.ndarray, float]]]:
        h, w = rgb.shape[:2]
        imap = self.instance_map(context["viewmat"], context["K"], w, h, context.get("extra"))
        return corrupt(imap, self.categories, prompts, self.c, self.rng)



def real_truth(scene, catalog, cfg) -> tuple[np.ndarray, dict[int, str]]:
    """Per-Gaussian instance ids (1..K, 0 = none) and {id: prompt} of a real scene's shipped labels:
    the instances the ground-truth path keeps (the same cleaning and vocabulary as
    navcore.instances.shipped_instances), so that the oracle sees what the shipped table holds;
    raises SegmenterUnavailable without labels."""
    from navcore.instances import gaussian_labels
    from navcore.labels.shipped import LabelReport, instances_from_gaussians

    gs, attrs = catalog.dataset("aligned", scene).load()
    t = np.asarray(attrs["source_to_aligned"])
    per = gaussian_labels(scene, gs, t)
    if per is None:
        raise SegmenterUnavailable(f"scene {scene.scene_id!r} ({scene.name}): the oracle segmenter needs per-Gaussian ground "
                                   "truth (a synthetic scene, SceneSplat instance.npy / segment.npy, or labels.mesh in the "
                                   "catalog entry); use semantics.segmenter=sam3 or open_vocab for this scene")
    inst, seg, names = per
    inst = np.asarray(inst)
    ceiling = catalog.dataset("alignment", scene).load().get("floor_to_ceiling_m")
    labels, _ = instances_from_gaussians(gs.means, gs.alphas, inst, seg, names, cfg.vocabulary(scene), cfg.labels,
                                         ceiling, LabelReport())  # the labels as read once (a mesh transfers once)
    kept = {lab["instance_id"]: lab["category"] for lab in labels}
    order = np.array(sorted(kept), np.int64)
    if not len(order):
        return np.zeros(len(inst), np.int64), {}
    pos = np.minimum(np.searchsorted(order, inst), len(order) - 1)
    ids = np.where(order[pos] == inst, pos + 1, 0).astype(np.int64)
    return ids, {k: cfg.prompt(kept[int(iid)]) for k, iid in enumerate(order, 1)}
