"""The open_vocab segmenter (OWLv2 + SAM through transformers) with small random-initialised models
saved to local folders: loading (offline, clear errors), batching, prompts, thresholds, mask shapes,
and the semantics stage end to end."""
from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("transformers", reason="the open_vocab extra: pip install -e '.[open_vocab]'")


@pytest.fixture(scope="module")
def models(tmp_path_factory, torchvision_shim):
    """(detector folder, masker folder): tiny OWLv2 (64 px, 16 px patches, a letters-only CLIP BPE
    vocabulary) and SAM (64 px) with random weights, written by save_pretrained."""
    from benchmarks.goals.open_vocab_timing import build_models

    return build_models(tmp_path_factory.mktemp("open_vocab"), tiny=True)


def _frames(n, h=48, w=64, seed=0):
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, (h, w, 3), dtype=np.uint8) for _ in range(n)]


def test_missing_or_wrong_weights_name_the_key_and_the_files(tmp_path, models):
    from stages.semantics.open_vocab import OpenVocabConfig, OpenVocabSegmenter
    from stages.semantics.segmenters import SegmenterUnavailable

    det, sam = models
    with pytest.raises(SegmenterUnavailable, match="semantics.open_vocab.detector is not set"):
        OpenVocabSegmenter(OpenVocabConfig(masker=str(sam)))
    with pytest.raises(SegmenterUnavailable, match="semantics.open_vocab.masker=.*no such folder"):
        OpenVocabSegmenter(OpenVocabConfig(detector=str(det), masker=str(tmp_path / "nope")))
    (tmp_path / "half").mkdir()
    (tmp_path / "half" / "config.json").write_text('{"model_type": "sam"}')
    with pytest.raises(SegmenterUnavailable, match="missing preprocessor_config.json, model.safetensors or pytorch_model.bin"):
        OpenVocabSegmenter(OpenVocabConfig(detector=str(det), masker=str(tmp_path / "half")))
    # a folder saved by transformers >= 5 (one processor_config.json): the error says which transformers the extra takes
    (tmp_path / "half" / "processor_config.json").write_text("{}")
    with pytest.raises(SegmenterUnavailable, match=r"processor_config.json, as transformers >= 5 .* takes transformers < 5"):
        OpenVocabSegmenter(OpenVocabConfig(detector=str(det), masker=str(tmp_path / "half")))
    with pytest.raises(SegmenterUnavailable, match="holds a 'sam' model; this segmenter takes owlv2, owlvit"):
        OpenVocabSegmenter(OpenVocabConfig(detector=str(sam), masker=str(sam)))


def test_nms_known_answer():
    from stages.semantics.open_vocab import nms

    boxes = np.array([[0, 0, 10, 10], [1, 1, 10, 10], [20, 20, 30, 30], [0, 0, 10, 4.0]])
    scores = np.array([0.5, 0.9, 0.3, 0.4])
    assert nms(boxes, scores, 0.5).tolist() == [1, 3, 2]  # box 0 overlaps 1 by 0.81; box 3 by 0.4 / 0.81 < 0.5


def test_batched_detection_and_masks_through_the_segmenter_interface(models):
    from stages.semantics.open_vocab import OpenVocabConfig, OpenVocabSegmenter

    det, sam = models
    prompts = ["chair", "tv monitor"]
    frames = _frames(3)
    seg = OpenVocabSegmenter(OpenVocabConfig(detector=str(det), masker=str(sam), device="cpu", box_threshold=0.0,
                                             max_detections=5, batch=3))
    dets = seg.detect(frames, prompts)
    assert sum(map(len, dets)) >= 2 and all(len(f) <= 5 for f in dets), [len(f) for f in dets]  # boxes kept; the cap holds
    masks = seg.masks(frames, dets)
    assert [len(m) for m in masks] == [len(f) for f in dets]  # one mask per box
    assert all(m.dtype == bool and m.shape == (48, 64) for f in masks for m in f)
    out = seg.segment_batch(frames, prompts, [{}] * 3)
    assert len(out) == 3 and all(set(o) == set(prompts) for o in out)
    for o, f, m in zip(out, dets, masks):  # each non-empty mask under its box's prompt, with its score
        for p in range(len(prompts)):
            want = [(mk, d[2]) for d, mk in zip(f, m) if d[0] == p and mk.any()]
            assert [s for _, s in o[prompts[p]]] == [s for _, s in want]
            assert all((a == b).all() for (a, _), (b, _) in zip(o[prompts[p]], want))
    # one frame at a time gives the same masks as the batch (batching changes nothing)
    one = OpenVocabSegmenter(OpenVocabConfig(detector=str(det), masker=str(sam), device="cpu", box_threshold=0.0,
                                             max_detections=5, batch=1))
    for a, b in zip(out, one.segment_batch(frames, prompts, [{}] * 3)):
        for p in prompts:
            assert len(a[p]) == len(b[p])
            assert all(np.mean(x[0] != y[0]) < 0.01 and abs(x[1] - y[1]) < 1e-5 for x, y in zip(a[p], b[p]))
    # a threshold above every score finds nothing; per-frame detections are per prompt
    none = OpenVocabSegmenter(OpenVocabConfig(detector=str(det), masker=str(sam), device="cpu", box_threshold=1.01))
    assert all(not any(o.values()) for o in none.segment_batch(frames, prompts, [{}] * 3))
    mid = OpenVocabSegmenter(OpenVocabConfig(detector=str(det), masker=str(sam), device="cpu", box_threshold=0.3,
                                             max_detections=5))
    kept = mid.detect(frames, prompts)
    assert all(d[2] >= 0.3 for f in kept for d in f) and sum(map(len, kept)) <= sum(map(len, dets))
    assert all(d[0] in (0, 1) and (d[1][2] > d[1][0]) and (d[1][3] > d[1][1]) for f in dets for d in f)
    assert all([x[2] for x in f] == sorted((x[2] for x in f), reverse=True) for f in dets)


def test_semantics_stage_runs_open_vocab_end_to_end(tmp_path, models, make_cfg):
    import pyarrow.parquet as pq

    from pipeline.executor import execute

    det, sam = models
    s = execute(make_cfg(tmp_path, "stages=[semantics]", "semantics.segmenter=open_vocab",
                         f"semantics.open_vocab.detector={det}", f"semantics.open_vocab.masker={sam}",
                         "semantics.open_vocab.box_threshold=0.0", "semantics.max_views=6", "semantics.width=64",
                         "semantics.height=48", "semantics.renderer=cpu", "semantics.categories=[chair,tv_monitor]"))
    assert not s["failures"], s["failures"]
    res = next(r for r in s["results"] if r["stage"] == "semantics")
    marker = json.loads((tmp_path / "_markers" / "semantics" / f"{res['scene_id']}.json").read_text())["info"]
    assert marker["segmenter"] == "open_vocab" and marker["views"] == 6 and marker["seconds"]["segment"] > 0
    table = pq.read_table(tmp_path / "04_semantics" / res["scene_id"] / "instances.parquet")
    assert set(table.column("source").to_pylist()) <= {"model_predicted"}
    assert set(table.column("category").to_pylist()) <= {"chair", "tv_monitor"}


def test_box_prompts_match_sam_processors_own_normalisation(models):
    """The segmenter scales boxes to SAM's resized frame itself (one preprocessing pass per batch);
    the masks equal those of SamProcessor(images, input_boxes) on the same frame (independent reference)."""
    import torch

    from stages.semantics.open_vocab import OpenVocabConfig, OpenVocabSegmenter

    det, sam = models
    seg = OpenVocabSegmenter(OpenVocabConfig(detector=str(det), masker=str(sam), device="cpu", box_threshold=0.0, batch=2))
    frames = _frames(2, seed=3)
    dets = [[(0, np.array([4.0, 6.0, 40.0, 30.0]), 0.9), (1, np.array([30.0, 10.0, 63.0, 47.0]), 0.5)], []]
    ours = seg.masks(frames, dets)
    assert ours[1] == []
    inp = seg.mask_proc(images=frames[0], input_boxes=[[list(map(float, d[1])) for d in dets[0]]], return_tensors="pt")
    with torch.no_grad():
        res = seg.masker(**{k: v for k, v in inp.items() if k in ("pixel_values", "input_boxes")}, multimask_output=False)
    ref = seg.mask_proc.post_process_masks(res.pred_masks, inp["original_sizes"], inp["reshaped_input_sizes"])[0]
    for j, m in enumerate(ours[0]):
        assert (m == ref[j, 0].numpy()).mean() > 0.999
