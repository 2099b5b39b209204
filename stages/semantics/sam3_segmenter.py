"""The `sam3` segmenter: SAM3 promptable concept segmentation (Meta's `sam3` package), batched.

Optional extra (`pip install -e '.[sam3]'`: sam3 and torchvision; a CUDA build of torch, since
torchvision's CPU operators are not on PyPI for torch's CPU build). Weights are read from a local
checkpoint (semantics.sam3.checkpoint), never downloaded at run time; README says how to get them.

One call segments a batch of frames for all prompts: the image encoder runs once per frame, the
text encoder once per prompt list, and the grounding head once for every (frame, prompt) pair in
one batch (FindStage img_ids x text_ids), as SAM3's own batched evaluation does. A detection is
kept when its score (box probability x presence probability, as Sam3Processor) is at least
`confidence`; its mask is the sigmoid of the mask logits upsampled to the frame, > 0.5.
"""
from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path

import numpy as np
import torch

from stages.semantics.segmenters import Segmenter

BPE_FILE = "bpe_simple_vocab_16e6.txt.gz"
_MODELS: dict = {}  # (checkpoint, bpe, device) -> model, shared by the scenes of one worker


def write_byte_vocabulary(path: Path) -> Path:
    """A BPE vocabulary without merges (single bytes only): enough to run SAM3 with random weights
    (tests, timing), never to use trained ones."""
    import gzip

    with gzip.open(path, "wt") as f:
        f.write("#version: 0.2\n")
    return Path(path)


def build_model(checkpoint: str | None, bpe_path: str | None, device: str):
    """SAM3's image model with the weights of a local checkpoint (None: random weights, for tests)."""
    try:
        from sam3.model_builder import build_sam3_image_model
    except ImportError as e:
        raise ImportError("the sam3 segmenter needs the optional extra: pip install -e '.[sam3]' (the sam3 package "
                          f"and torchvision for a CUDA build of torch); import failed: {e}") from None
    if checkpoint is not None and not Path(checkpoint).is_file():
        raise FileNotFoundError(f"SAM3 checkpoint {checkpoint} not found (semantics.sam3.checkpoint); README: "
                                "'SAM3 weights'")
    bpe = Path(bpe_path) if bpe_path else (Path(checkpoint).parent / BPE_FILE if checkpoint else None)
    if bpe is None or not bpe.is_file():
        raise FileNotFoundError(f"SAM3 BPE vocabulary {bpe} not found (semantics.sam3.bpe_path, or {BPE_FILE} "
                                "next to the checkpoint)")
    return build_sam3_image_model(bpe_path=str(bpe), device=device, eval_mode=True, checkpoint_path=checkpoint,
                                  load_from_HF=False)


class Sam3Segmenter(Segmenter):
    """Args: model (a built SAM3 image model) or checkpoint (+ bpe_path) to build one; device;
    confidence: detection threshold; resolution: model input size; batch: frames per forward."""

    def __init__(self, checkpoint: str | None = None, bpe_path: str | None = None, device: str = "cuda",
                 confidence: float = 0.5, resolution: int = 1008, batch: int = 8, model=None):
        if device.startswith("cuda") and not torch.cuda.is_available():
            raise RuntimeError("the sam3 segmenter is set to run on CUDA (semantics.sam3.device) and there is none")
        key = (checkpoint, bpe_path, device)
        if model is None:
            if key not in _MODELS:
                _MODELS[key] = build_model(checkpoint, bpe_path, device)
            model = _MODELS[key]
        self.model, self.device = model, torch.device(device)
        self.confidence, self.resolution, self.batch = confidence, resolution, batch

    @classmethod
    def from_scene(cls, scene, catalog, renderer, cfg, seed: int) -> "Sam3Segmenter":
        c = cfg.sam3
        if not c.checkpoint:
            raise ValueError("semantics.segmenter=sam3 needs semantics.sam3.checkpoint (a local sam3.pt; README: "
                             "'SAM3 weights')")
        return cls(c.checkpoint, c.bpe_path, c.device, c.confidence, c.resolution, c.batch)

    def segment(self, rgb, prompts, context):
        return self.segment_batch(rgb[None], prompts, [context])[0]

    def segment_batch(self, rgbs, prompts: list[str], contexts: list[dict]) -> list[dict]:
        out = []
        for s in range(0, len(rgbs), self.batch):
            out += self._segment(np.asarray(rgbs[s:s + self.batch]), prompts)
        return out

    @torch.inference_mode()
    def _segment(self, rgbs: np.ndarray, prompts: list[str]) -> list[dict]:
        from sam3.model.data_misc import FindStage

        n, p = len(rgbs), len(prompts)
        h, w = rgbs.shape[1:3]
        x = torch.from_numpy(rgbs).to(self.device).permute(0, 3, 1, 2).float()
        x = torch.nn.functional.interpolate(x, size=(self.resolution, self.resolution), mode="bilinear",
                                            antialias=True, align_corners=False)
        x = (x / 255.0 - 0.5) / 0.5  # Sam3Processor's normalisation
        autocast = torch.autocast("cuda", dtype=torch.bfloat16) if self.device.type == "cuda" else nullcontext()
        with autocast:
            backbone = self.model.backbone.forward_image(x)
            backbone.update(self.model.backbone.forward_text(prompts, device=self.device))
            img_ids = torch.arange(n, device=self.device).repeat_interleave(p)
            txt_ids = torch.arange(p, device=self.device).repeat(n)
            find = FindStage(img_ids=img_ids, text_ids=txt_ids, input_boxes=None, input_boxes_mask=None,
                             input_boxes_label=None, input_points=None, input_points_mask=None)
            res = self.model.forward_grounding(backbone_out=backbone, find_input=find, find_target=None,
                                               geometric_prompt=self.model._get_dummy_prompt(n * p))
        probs = res["pred_logits"].float().sigmoid().squeeze(-1) * res["presence_logit_dec"].float().sigmoid()
        keep = probs >= self.confidence  # [n * p, queries]
        frames: list[dict] = [{q: [] for q in prompts} for _ in range(n)]
        qi, di = torch.nonzero(keep, as_tuple=True)
        if len(qi):
            logits = res["pred_masks"][qi, di].float()[:, None]
            masks = torch.nn.functional.interpolate(logits, size=(h, w), mode="bilinear", align_corners=False)
            masks = (masks[:, 0].sigmoid() > 0.5).cpu().numpy()
            scores = probs[qi, di].cpu().numpy()
            for k, q in enumerate(qi.cpu().numpy()):
                if masks[k].any():
                    frames[q // p][prompts[q % p]].append((masks[k], float(scores[k])))
        return frames

