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


def test_a_benchmark_root_starts_empty_and_only_its_own_is_cleared(tmp_path):
    """A finished simulation or cost-sample root left in place made the next run a resume of cached
    tasks: a benchmark clears a root it made (its mark file), refuses one it did not make, and marks
    the root it starts."""
    import pytest

    from benchmarks.scale.bench_scale import BENCH_MARK, fresh_bench_root

    root = fresh_bench_root(tmp_path / "sim")
    assert sorted(p.name for p in root.iterdir()) == [BENCH_MARK]
    (root / "_runs").mkdir()
    (root / "_runs" / "latest.json").write_text("{}")
    assert sorted(p.name for p in fresh_bench_root(root).iterdir()) == [BENCH_MARK]  # its own: cleared
    other = tmp_path / "data"
    other.mkdir()
    (other / "keep.txt").write_text("x")
    with pytest.raises(SystemExit, match=r"bench_scale sim: .*data holds files no benchmark made"):
        fresh_bench_root(other)
    assert (other / "keep.txt").read_text() == "x"
