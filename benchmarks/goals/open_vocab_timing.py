"""Time of the open_vocab segmenter at the published models' sizes (random weights: the download
is the user's; the speed is the architecture's).

Builds OWLv2 base / patch 16 (768 px; google/owlv2-base-patch16-ensemble's configuration) and SAM
ViT-B (1024 px; facebook/sam-vit-base's) with random weights, saves them to local folders as a
user's download would be, and runs OpenVocabSegmenter.segment_batch on frames at the semantics
stage's render size (320x240) with the default eight prompts. Reports frames/s, the split between
detector and masker, detections per frame (random weights: the cap, `max_detections`, bounds the
masker's work) and seconds per scene at the stage's views per scene.

    python -m benchmarks.goals.open_vocab_timing [--frames 8] [--device auto] [--out data/08_reports]
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from navcore.io import jsonio


def build_models(root: Path, tiny: bool = False) -> tuple[Path, Path]:
    """(detector folder, masker folder) with random weights, written by save_pretrained as a user's
    download would be: the published architectures (OWLv2 base / patch 16 at 960 px, SAM ViT-B at
    1024 px), or with `tiny` the same architectures at 64 px with one small layer each (tests). The
    tokenizer is a letters-only CLIP BPE vocabulary (its special tokens last: OWL masks a query
    whose first id is 0)."""
    import torch
    from transformers import (
        CLIPTokenizer,
        Owlv2Config,
        Owlv2ForObjectDetection,
        Owlv2ImageProcessor,
        Owlv2Processor,
        SamConfig,
        SamModel,
        SamProcessor,
    )
    from transformers.models.sam.image_processing_sam import SamImageProcessor

    vocab = {"!": 0}
    for suffix in ("", "</w>"):
        for c in "abcdefghijklmnopqrstuvwxyz":
            vocab[c + suffix] = len(vocab)
    vocab["<|startoftext|>"], vocab["<|endoftext|>"] = len(vocab), len(vocab) + 1
    (root / "vocab.json").write_text(jsonio.dumps(vocab))
    (root / "merges.txt").write_text("#version: 0.2\n")
    tok = CLIPTokenizer(str(root / "vocab.json"), str(root / "merges.txt"), pad_token="!")
    torch.manual_seed(0)
    if tiny:
        det_cfg = Owlv2Config(text_config=dict(vocab_size=len(vocab), hidden_size=32, intermediate_size=64,
                                               num_hidden_layers=1, num_attention_heads=2, max_position_embeddings=16),
                              vision_config=dict(hidden_size=32, intermediate_size=64, num_hidden_layers=1,
                                                 num_attention_heads=2, image_size=64, patch_size=16), projection_dim=32)
        sam_cfg = SamConfig(
            vision_config=dict(hidden_size=32, output_channels=16, num_hidden_layers=1, num_attention_heads=2,
                               image_size=64, patch_size=16, mlp_dim=64, global_attn_indexes=[0], window_size=2,
                               num_pos_feats=8),
            prompt_encoder_config=dict(hidden_size=16, image_size=64, patch_size=16, mask_input_channels=4),
            mask_decoder_config=dict(hidden_size=16, mlp_dim=32, num_hidden_layers=1, num_attention_heads=2,
                                     iou_head_hidden_dim=16))
        det_px, sam_proc = 64, SamImageProcessor(size={"longest_edge": 64}, pad_size={"height": 64, "width": 64},
                                                 mask_size={"longest_edge": 16}, mask_pad_size={"height": 16, "width": 16})
    else:
        det_cfg, sam_cfg, det_px, sam_proc = Owlv2Config(), SamConfig(), 960, SamImageProcessor()
        det_cfg.vision_config.image_size = 960  # the ensemble checkpoint's input size
    Owlv2ForObjectDetection(det_cfg).eval().save_pretrained(root / "det")
    Owlv2Processor(image_processor=Owlv2ImageProcessor(size={"height": det_px, "width": det_px}),
                   tokenizer=tok).save_pretrained(root / "det")
    SamModel(sam_cfg).eval().save_pretrained(root / "sam")
    SamProcessor(sam_proc).save_pretrained(root / "sam")
    return root / "det", root / "sam"


def run(frames: int, device: str, batch: int, views_per_scene: int, fast: bool = True) -> dict:
    import torch

    from stages.semantics.open_vocab import OpenVocabConfig, OpenVocabSegmenter
    from stages.semantics.segmenters import SegmenterUnavailable

    prompts = ["chair", "bed", "sofa", "toilet", "tv monitor", "plant", "table", "cabinet"]
    with tempfile.TemporaryDirectory() as tmp:
        det, sam = build_models(Path(tmp))
        try:
            seg = OpenVocabSegmenter(OpenVocabConfig(detector=str(det), masker=str(sam), device=device, batch=batch,
                                                     fast_processor=fast))
        except SegmenterUnavailable as e:
            return {"error": str(e)}
        rng = np.random.default_rng(0)
        rgbs = [rng.integers(0, 256, (240, 320, 3), dtype=np.uint8) for _ in range(frames)]
        seg.segment_batch(rgbs[:1], prompts, [{}])  # warm-up (CUDA context, kernels)
        sync = torch.cuda.synchronize if seg.device.type == "cuda" else (lambda: None)
        sync()
        t0 = time.perf_counter()
        dets = seg.detect(rgbs, prompts)
        sync()
        t1 = time.perf_counter()
        seg.masks(rgbs, dets)
        sync()
        t2 = time.perf_counter()
        total = t2 - t0
        return {"device": torch.cuda.get_device_name(0) if seg.device.type == "cuda" else "cpu",
                "torch": torch.__version__, "frames": frames, "batch": batch, "prompts": len(prompts),
                "resolution": [320, 240], "detector": "OWLv2 base/16 at 960 px (random weights)",
                "masker": "SAM ViT-B at 1024 px (random weights)",
                "detections_per_frame": float(np.mean([len(d) for d in dets])),
                "image_processors": f"{type(seg.det_proc.image_processor).__name__}, {type(seg.mask_proc.image_processor).__name__}",
                "frames_per_s": frames / total, "detector_s_per_frame": (t1 - t0) / frames,
                "masker_s_per_frame": (t2 - t1) / frames,
                "views_per_scene": views_per_scene, "seconds_per_scene": total / frames * views_per_scene}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--device", default="auto")
    ap.add_argument("--slow-processors", dest="fast", action="store_false", help="the numpy image processors")
    ap.add_argument("--views-per-scene", type=int, default=55, help="the synthetic scenes' capture views (bench-semantics)")
    ap.add_argument("--out", default="data/08_reports")
    args = ap.parse_args(argv)
    from benchmarks import machine

    rep = {"machine": machine(), **run(args.frames, args.device, args.batch, args.views_per_scene, args.fast)}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "open_vocab_timing_gpu.json" if rep.get("device", "cpu") != "cpu" else "open_vocab_timing_cpu.json"
    (out / name).write_text(jsonio.dumps(rep, indent=1))
    print(json.dumps(rep, indent=1))
    return rep


if __name__ == "__main__":
    main()
