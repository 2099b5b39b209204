"""The `open_vocab` segmenter: open weights, no licence gate, offline.

A text-prompted detector (OWLv2 or OWL-ViT through `transformers`) finds boxes for every
(frame, prompt) of a batch in one forward pass; a promptable mask model (SAM through
`transformers`) turns each frame's boxes into masks in one decoder pass (its image encoder runs on
the whole batch of frames at once). Both load from local folders written by
`save_pretrained` / `huggingface-cli download` and never download at run time
(`local_files_only`, HF_HUB_OFFLINE during loading); README "Open-vocabulary weights" gives the
download commands.

    semantics.segmenter=open_vocab semantics.open_vocab.detector=/models/owlv2-base-patch16-ensemble \
        semantics.open_vocab.masker=/models/sam-vit-base

Per frame and prompt, detections above `box_threshold` are kept, overlapping ones of a prompt
suppressed (NMS at `nms_iou`), at most `max_detections` per frame; each kept box becomes one mask
(`{prompt: [(mask, score)]}`, the Segmenter interface), its score the detector's.
"""
from __future__ import annotations

import os
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from stages.semantics.segmenters import Segmenter, SegmenterUnavailable

DETECTORS = ("owlv2", "owlvit")
MASKERS = ("sam",)
WEIGHT_FILES = ("model.safetensors", "pytorch_model.bin", "model.safetensors.index.json", "pytorch_model.bin.index.json")


@dataclass
class OpenVocabConfig:
    """The `open_vocab` segmenter (pip install -e '.[open_vocab]'; weights: docs/tasks.md)."""

    detector: Optional[str] = None
    """Local folder of a text-prompted detector (OWLv2 / OWL-ViT: config.json, weights,
    preprocessor_config.json and the tokenizer files)."""
    masker: Optional[str] = None
    """Local folder of a promptable mask model (SAM: config.json, weights, preprocessor_config.json)."""
    device: str = "auto"
    """auto (cuda when available) | cuda | cpu."""
    box_threshold: float = 0.2
    """Detections whose score is below this are dropped."""
    nms_iou: float = 0.5
    """Boxes of one prompt overlapping a better one by more than this IoU are dropped."""
    max_detections: int = 20
    """At most this many boxes per frame (best scores first)."""
    mask_threshold: float = 0.0
    """Mask logits above this are inside the mask."""
    batch: int = 8
    """Frames per detector / image-encoder pass."""
    fast_processor: bool = True
    """Resize and pad frames with transformers' fast (torch) image processors where they load (they
    need torchvision), else the slow numpy ones: on an H100 the slow OWLv2 preprocessing at 960 px
    is most of the detector's time."""


def _check_folder(path: Optional[str], key: str, kinds: tuple[str, ...], example: str) -> Path:
    """The folder a config key names, with the files a local model needs; a clear error otherwise."""
    if not path:
        raise SegmenterUnavailable(f"{key} is not set: point it to a local {' / '.join(kinds)} folder ({example}); "
                                   "see README 'Open-vocabulary weights' (nothing is downloaded at run time)")
    p = Path(path)
    if not p.is_dir():
        raise SegmenterUnavailable(f"{key}={path!r}: no such folder (expected a local {' / '.join(kinds)} model folder)")
    missing = [f for f in ("config.json", "preprocessor_config.json") if not (p / f).is_file()]
    if not any((p / f).is_file() for f in WEIGHT_FILES):
        missing.append(" or ".join(WEIGHT_FILES[:2]))
    if missing:
        hint = ""
        if "preprocessor_config.json" in missing and (p / "processor_config.json").is_file():
            import transformers

            hint = (f"; it holds a processor_config.json, as transformers >= 5 saves a processor: the open_vocab extra "
                    f"takes transformers < 5 (installed here: {transformers.__version__}), whose folders hold "
                    "preprocessor_config.json (pip install -e '.[open_vocab]')")
        raise SegmenterUnavailable(f"{key}={path!r}: missing {', '.join(missing)} (a model folder written by save_pretrained "
                                   f"or huggingface-cli download; see README 'Open-vocabulary weights'){hint}")
    return p


@contextmanager
def _offline():
    old = {k: os.environ.get(k) for k in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE")}
    os.environ.update({"HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1"})
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _model_type(folder: Path, key: str, allowed: tuple[str, ...]) -> str:
    from transformers import AutoConfig

    try:
        with _offline():
            mt = AutoConfig.from_pretrained(folder, local_files_only=True).model_type
    except (OSError, ValueError) as e:
        raise SegmenterUnavailable(f"{key}: {folder / 'config.json'} is not a model config transformers reads ({e})") from None
    if mt not in allowed:
        raise SegmenterUnavailable(f"{key}: {folder} holds a {mt or 'unknown'!r} model; this segmenter takes {', '.join(allowed)}")
    return mt


def _processor(cls, folder: Path, fast: bool):
    """A processor from a local folder: the fast image processor when asked for and loadable."""
    if fast:
        try:
            return cls.from_pretrained(folder, local_files_only=True, use_fast=True)
        except (ImportError, ValueError, TypeError, OSError, RuntimeError):
            pass
    return cls.from_pretrained(folder, local_files_only=True)


def nms(boxes: np.ndarray, scores: np.ndarray, iou: float) -> np.ndarray:
    """Indices of the boxes [K, 4] (x0, y0, x1, y1) kept by greedy non-maximum suppression, best first."""
    order = np.argsort(-scores, kind="stable")
    keep = []
    area = np.clip(boxes[:, 2] - boxes[:, 0], 0, None) * np.clip(boxes[:, 3] - boxes[:, 1], 0, None)
    while len(order):
        i = order[0]
        keep.append(i)
        rest = order[1:]
        w = np.clip(np.minimum(boxes[i, 2], boxes[rest, 2]) - np.maximum(boxes[i, 0], boxes[rest, 0]), 0, None)
        h = np.clip(np.minimum(boxes[i, 3], boxes[rest, 3]) - np.maximum(boxes[i, 1], boxes[rest, 1]), 0, None)
        inter = w * h
        order = rest[inter / np.maximum(area[i] + area[rest] - inter, 1e-12) <= iou]
    return np.asarray(keep, np.int64)


class OpenVocabSegmenter(Segmenter):
    """Detector boxes per (frame, prompt), then one mask per box (module doc)."""

    def __init__(self, cfg: OpenVocabConfig):
        import torch
        from transformers import AutoModelForZeroShotObjectDetection, AutoProcessor

        self.cfg = cfg
        det = _check_folder(cfg.detector, "semantics.open_vocab.detector", DETECTORS,
                            "e.g. /models/owlv2-base-patch16-ensemble")
        msk = _check_folder(cfg.masker, "semantics.open_vocab.masker", MASKERS, "e.g. /models/sam-vit-base")
        self.square = _model_type(det, "semantics.open_vocab.detector", DETECTORS) == "owlv2"
        _model_type(msk, "semantics.open_vocab.masker", MASKERS)
        dev = cfg.device if cfg.device != "auto" else ("cuda" if torch.cuda.is_available() else "cpu")
        if dev.startswith("cuda") and not torch.cuda.is_available():
            raise SegmenterUnavailable("semantics.open_vocab.device=cuda but torch sees no CUDA device (use cpu or auto)")
        self.device = torch.device(dev)
        with _offline():
            self.det_proc = _processor(AutoProcessor, det, cfg.fast_processor)
            self.det = AutoModelForZeroShotObjectDetection.from_pretrained(det, local_files_only=True).to(self.device).eval()
            from transformers import SamModel, SamProcessor

            self.mask_proc = _processor(SamProcessor, msk, cfg.fast_processor)
            self.masker = SamModel.from_pretrained(msk, local_files_only=True).to(self.device).eval()

    @classmethod
    def from_scene(cls, scene, catalog, renderer, cfg, seed: int) -> "OpenVocabSegmenter":
        return cls(cfg.open_vocab)

    def segment(self, rgb, prompts, context):
        return self.segment_batch([rgb], prompts, [context])[0]

    def detect(self, rgbs: list[np.ndarray], prompts: list[str]) -> list[list[tuple[int, np.ndarray, float]]]:
        """Per frame: [(prompt index, box [4] x0 y0 x1 y1 in pixels, score)] after threshold, NMS and the cap."""
        import torch

        out = []
        for s in range(0, len(rgbs), max(1, self.cfg.batch)):
            chunk = [np.asarray(r) for r in rgbs[s:s + self.cfg.batch]]
            inp = self.det_proc(text=[list(prompts)] * len(chunk), images=chunk, return_tensors="pt", padding=True)
            with torch.no_grad():
                res = self.det(**{k: v.to(self.device) for k, v in inp.items()})
            # OWLv2 pads each image to a square at its bottom and right: its boxes are relative to that square
            sizes = torch.tensor([[max(r.shape[:2])] * 2 if self.square else list(r.shape[:2]) for r in chunk])
            post = self.det_proc.image_processor.post_process_object_detection(
                res, threshold=self.cfg.box_threshold, target_sizes=sizes) if hasattr(self.det_proc, "image_processor") \
                else self.det_proc.post_process_object_detection(res, threshold=self.cfg.box_threshold, target_sizes=sizes)
            for r, img in zip(post, chunk):
                boxes, scores, labels = (r["boxes"].cpu().numpy().astype(np.float64), r["scores"].cpu().numpy().astype(np.float64),
                                         r["labels"].cpu().numpy().astype(np.int64))
                h, w = img.shape[:2]
                boxes = np.column_stack([np.clip(boxes[:, 0], 0, w), np.clip(boxes[:, 1], 0, h),
                                         np.clip(boxes[:, 2], 0, w), np.clip(boxes[:, 3], 0, h)]) if len(boxes) else boxes
                dets = []
                for p in range(len(prompts)):
                    sel = np.flatnonzero((labels == p) & (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])) \
                        if len(boxes) else np.zeros(0, np.int64)
                    for i in sel[nms(boxes[sel], scores[sel], self.cfg.nms_iou)] if len(sel) else []:
                        dets.append((p, boxes[i], float(scores[i])))
                dets.sort(key=lambda d: -d[2])
                out.append(dets[:self.cfg.max_detections])
        return out

    def masks(self, rgbs: list[np.ndarray], dets: list[list]) -> list[list[np.ndarray]]:
        """Per frame, one bool mask [H, W] per detection (its box as the prompt)."""
        import torch

        out: list[list[np.ndarray]] = [[] for _ in rgbs]
        for s in range(0, len(rgbs), max(1, self.cfg.batch)):
            idx = [i for i in range(s, min(s + self.cfg.batch, len(rgbs))) if dets[i]]
            if not idx:
                continue
            # the image encoder once for the whole batch of frames, the prompt decoder once per frame
            inp = self.mask_proc(images=[rgbs[i] for i in idx], return_tensors="pt")
            with torch.no_grad():
                emb = self.masker.get_image_embeddings(inp["pixel_values"].to(self.device))
            for k, i in enumerate(idx):
                (h, w), (rh, rw) = inp["original_sizes"][k].tolist(), inp["reshaped_input_sizes"][k].tolist()
                # boxes in the resized frame's pixels, as SamProcessor normalises them
                boxes = np.array([d[1] for d in dets[i]], np.float64) * [rw / w, rh / h, rw / w, rh / h]
                with torch.no_grad():
                    res = self.masker(image_embeddings=emb[k:k + 1], multimask_output=False,
                                      input_boxes=torch.as_tensor(boxes[None], dtype=torch.float32, device=self.device))
                m = self.mask_proc.post_process_masks(res.pred_masks.cpu(), inp["original_sizes"][k:k + 1],
                                                      inp["reshaped_input_sizes"][k:k + 1],
                                                      mask_threshold=self.cfg.mask_threshold, binarize=True)[0]
                out[i] = [np.asarray(m[j, 0], bool) for j in range(len(boxes))]
        return out

    def segment_batch(self, rgbs, prompts, contexts):
        rgbs = [np.asarray(r) for r in rgbs]
        dets = self.detect(rgbs, prompts)
        masks = self.masks(rgbs, dets)
        out = []
        for d, m in zip(dets, masks):
            seg: dict = {p: [] for p in prompts}
            for (p, _box, score), mask in zip(d, m):
                if mask.any():
                    seg[prompts[p]].append((mask, score))
            out.append(seg)
        return out
