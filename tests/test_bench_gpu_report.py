"""make bench-gpu's report is written from its JSON alone (`--from-report`: after a part was re-run on
another machine and folded in), with the run's notes; the several-GPU figures are their own page."""
import json

from benchmarks.gpu import bench_gpu


def _report() -> dict:
    grid = [{"gaussians": 1_011_000, "width": w, "height": h, "batch": b, "fps": f}
            for (w, h, b, f) in ((640, 480, 1, 515.0), (640, 480, 64, 3282.4), (160, 120, 64, 2570.0))]
    return {"versions": {"commit": "abc1234", "device": "NVIDIA H200", "driver": "580", "driver_cuda": "13.0",
                         "torch": "2.11", "torch_cuda": "13.0", "gsplat": "1.5.3"},
            "parts": {"render": {"gsplat_fps_grid": grid, "psnr_cpu_vs_gsplat_min": 86.4,
                                 "psnr_cpu_vs_gsplat_median": 111.6, "depth_median_abs_m_max": 0.0},
                      "voxelize": {"median_s": 0.25, "seconds": 9.5},
                      "open_vocab": {"error": "ImportError: no transformers", "seconds": 1.0}}}


def test_report_is_written_from_its_json_with_notes_and_without_the_multi_gpu_page(tmp_path, capsys):
    (tmp_path / "bench_gpu.json").write_text(json.dumps(_report()))
    (tmp_path / "multi_gpu.json").write_text("{}")  # a several-GPU run's report: its own page, never folded in
    notes = tmp_path / "notes.md"
    notes.write_text("How this was run: a test.\n")
    rep = bench_gpu.main(["--from-report", "--out", str(tmp_path), "--notes", str(notes)])
    assert rep == _report()  # nothing measured, the report left as it was
    md = (tmp_path / "bench_gpu.md").read_text()
    rows = [line for line in md.splitlines() if line.startswith("| gsplat")]
    assert len(rows) == 3
    # the target is marked on the batched 640x480 row of the smaller scene only
    assert [r.endswith(">= 3,000 |") for r in rows] == [False, True, False]
    assert "| 3,282 |" in rows[1]
    assert "| open_vocab: not measured | ImportError: no transformers |" in md
    assert "voxelization (voxelize_gpu.json) | median_s 0.25" in md
    assert md.rstrip().endswith("How this was run: a test.")
    assert "Several GPUs" not in md and "bench-multi-gpu" not in md
