"""bench-scale's release cost takes SAM3's segmenting rate from the GPU it costs the other GPU stages on."""
import json

from benchmarks.scale.bench_scale import SAM3_FPS_H100, sam3_rate


def test_sam3_rate_comes_from_the_same_gpu_or_the_h100_default(tmp_path):
    assert sam3_rate(tmp_path, "NVIDIA H200") == (SAM3_FPS_H100, "the H100's sam3 timing of 2026-11-22 (SAM3_FPS_H100)")
    (tmp_path / "semantics_gpu.json").write_text(json.dumps({"device": "NVIDIA H200", "sam3_timing": {"frames_per_s": 17.5}}))
    assert sam3_rate(tmp_path, "NVIDIA H200") == (17.5, "semantics_gpu.json's sam3 timing on NVIDIA H200")
    # a timing of another GPU, or a report without one, is not used
    assert sam3_rate(tmp_path, "NVIDIA H100 80GB HBM3")[0] == SAM3_FPS_H100
    (tmp_path / "semantics_gpu.json").write_text(json.dumps({"device": "NVIDIA H200", "sam3_timing": None}))
    assert sam3_rate(tmp_path, "NVIDIA H200")[0] == SAM3_FPS_H100
