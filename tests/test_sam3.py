"""The sam3 segmenter's loading and inference path, with a randomly initialised SAM3 model.

Runs wherever the optional extra imports (pip install -e '.[sam3]'; SAM3 needs torchvision's
compiled operators, which PyPI has for CUDA builds of torch only); skipped elsewhere. The model is
SAM3's full architecture: the test saves its random weights as a checkpoint in SAM3's layout,
loads them through the segmenter's checkpoint path, and segments a batch of tiny frames.
"""
import numpy as np
import pytest
import torch

try:
    import sam3  # noqa: F401

    SAM3_ERROR = None
except Exception as e:  # ImportError, or torchvision's operators missing for a CPU build of torch
    SAM3_ERROR = f"{type(e).__name__}: {e}"

pytestmark = pytest.mark.skipif(SAM3_ERROR is not None, reason=f"sam3 not importable here ({SAM3_ERROR})")


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    from stages.semantics.sam3_segmenter import BPE_FILE, build_model, write_byte_vocabulary

    d = tmp_path_factory.mktemp("sam3")
    write_byte_vocabulary(d / BPE_FILE)
    torch.manual_seed(0)
    device = "cuda" if torch.cuda.is_available() else "cpu"
    model = build_model(None, str(d / BPE_FILE), device)  # random weights
    state = {f"detector.{k}": v.detach().cpu() for k, v in model.state_dict().items()}
    torch.save({"model": state}, d / "sam3.pt")
    del model
    return d / "sam3.pt", state, device


def test_sam3_loads_a_local_checkpoint_and_segments_batches(checkpoint):
    from stages.semantics.sam3_segmenter import Sam3Segmenter

    path, state, device = checkpoint
    seg = Sam3Segmenter(str(path), device=device, confidence=0.0, batch=2)  # BPE found next to the checkpoint
    loaded = seg.model.state_dict()
    for k in list(state)[:: max(1, len(state) // 50)]:  # the weights are the checkpoint's
        assert torch.equal(loaded[k.removeprefix("detector.")].cpu(), state[k]), k
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, (3, 48, 64, 3), dtype=np.uint8)
    prompts = ["chair", "tv monitor"]
    out = seg.segment_batch(frames, prompts, [{}] * 3)
    assert len(out) == 3 and all(set(o) == set(prompts) for o in out)
    dets = [d for o in out for p in prompts for d in o[p]]
    assert dets, "confidence 0 keeps every query with a non-empty mask"
    for mask, score in dets:
        assert mask.dtype == bool and mask.shape == (48, 64) and mask.any() and 0.0 <= score <= 1.0
    # a frame gives the same detections alone as in a batch (batch 2 split the 3 frames 2 + 1)
    alone = seg.segment(frames[0], prompts, {})
    for p in prompts:
        a = sorted(s for _, s in alone[p])[-10:]
        b = sorted(s for _, s in out[0][p])[-10:]
        assert len(a) == len(b) and np.allclose(a, b, atol=0.02)
    with pytest.raises(FileNotFoundError, match="checkpoint"):
        Sam3Segmenter(str(path.parent / "missing.pt"), device=device)
