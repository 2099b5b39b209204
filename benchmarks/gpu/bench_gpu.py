"""make bench-gpu: every GPU figure in one report (CUDA machine).

Runs, each in this process and each recorded even when it fails (its error in the report):
- the ready check (navcore.render.ready: versions, gsplat's kernels, one frame against the CPU renderer);
- benchmarks.gpu.render_gpu: CPU renderer vs gsplat PSNR and depth error; gsplat RGB-D frames/s at
  640x480 and 160x120 on 1 M and 1.5 M Gaussians, one frame and batched;
- benchmarks.closed_loop.eval --gpu: closed-loop environment steps/s with gsplat, one env and vectorised;
- benchmarks.map.voxelize_gpu: voxelization of 1 M Gaussians on the GPU vs the CPU path, same run;
- benchmarks.goals.semantics --gpu: bench-semantics' GPU half (semantics_gpu.json: 10 scenes' precision and
  seconds per scene: render, oracle, lift);
- benchmarks.goals.open_vocab_timing: the open_vocab segmenter's frames/s.
Writes data/08_reports/bench_gpu.{json,md} (and docs/benchmarks/bench_gpu.md with --docs), headed by the
commit, GPU, driver, torch and gsplat versions. Targets (H100): >= 3,000 frames/s 640x480 RGB-D
batched on 1 M Gaussians, closed loop >= 1,000 steps/s vectorised, voxelization of 1 M < 2 s.

    python -m benchmarks.gpu.bench_gpu [--out data/08_reports] [--docs] [--only render,voxelize] [--notes F]
    python -m benchmarks.gpu.bench_gpu --from-report --docs [--notes F]   # the page from bench_gpu.json

The several-GPU figures are their own page (docs/benchmarks/bench_multi_gpu.md, make bench-multi-gpu).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
import traceback
from pathlib import Path

from benchmarks.pages import write_page
from navcore.io import jsonio

PARTS = ("ready", "render", "eval", "voxelize", "semantics", "open_vocab")


def _commit() -> str:
    if os.environ.get("NAVARENA_COMMIT"):  # a copy of the tree without its history (a device's)
        return os.environ["NAVARENA_COMMIT"]
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=Path(__file__).resolve().parents[2], timeout=10).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        return ""


def _part(name: str, out: Path) -> dict:
    """Run one part; its JSON (or its error)."""
    t0 = time.perf_counter()
    try:
        if name == "ready":
            from navcore.render.ready import check

            res = check()
        elif name == "render":
            from benchmarks.gpu import render_gpu

            res = render_gpu.main(["--out", str(out)])
            res = {k: v for k, v in res.items() if k != "per_view"}
        elif name == "eval":
            from benchmarks.closed_loop import eval as bench_eval

            bench_eval.main(["--gpu", "--out", str(out)])
            res = json.loads((out / "eval_gpu.json").read_text())
        elif name == "voxelize":
            from benchmarks.map import voxelize_gpu

            voxelize_gpu.main(["--out", str(out)])
            res = json.loads((out / "voxelize_gpu.json").read_text())
        elif name == "semantics":
            from benchmarks.goals import semantics

            # bench-semantics' GPU half in full (its 10 scenes, the untimed ones over half the cores): one run
            # gives this page's seconds per scene and the semantics_gpu.json that make bench-semantics merges
            jobs = max(1, min(8, (os.cpu_count() or 2) // 2))
            res = semantics.main(["--gpu", "--timed", "2", "--jobs", str(jobs), "--out", str(out)])
            res = {k: v for k, v in res.items() if k not in ("per_scene", "variants")}
        else:
            from benchmarks.goals import open_vocab_timing

            res = open_vocab_timing.main(["--frames", "64", "--batch", "16", "--out", str(out)])
    except BaseException as e:  # noqa: BLE001 - recorded: a missing package or a failed kernel build
        if isinstance(e, KeyboardInterrupt):
            raise
        return {"error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc(limit=4),
                "seconds": round(time.perf_counter() - t0, 1)}
    return {**res, "seconds": round(time.perf_counter() - t0, 1)}


def markdown(rep: dict) -> str:
    v = rep["versions"]
    lines = ["# bench-gpu", "", f"Commit {v.get('commit')}; {v.get('device')}; driver {v.get('driver')} (CUDA "
             f"{v.get('driver_cuda')}); torch {v.get('torch')} (CUDA {v.get('torch_cuda')}); gsplat {v.get('gsplat')}. "
             "Reproduce: `make bench-gpu`.", "", "| figure | value | target |", "|---|---|---|"]
    p = rep["parts"]
    r = p.get("render", {})
    for g in r.get("gsplat_fps_grid", []):
        target = ">= 3,000" if (g["width"], g["batch"]) == (640, max(x["batch"] for x in r["gsplat_fps_grid"])) \
            and g["gaussians"] < 1_200_000 else ""
        lines.append(f"| gsplat RGB-D frames/s, {g['gaussians'] / 1e6:.2f} M Gaussians, {g['width']}x{g['height']}, "
                     f"{g['batch']} a call | {g['fps']:,.0f} | {target} |")
    if "psnr_cpu_vs_gsplat_min" in r:
        lines.append(f"| CPU renderer vs gsplat: PSNR min / median | {r['psnr_cpu_vs_gsplat_min']:.1f} / "
                     f"{r['psnr_cpu_vs_gsplat_median']:.1f} dB | |")
        lines.append(f"| CPU renderer vs gsplat: depth median abs error, worst view | {r['depth_median_abs_m_max'] * 1000:.3f} mm | |")
    for name in PARTS:
        if "error" in p.get(name, {}):
            lines.append(f"| {name}: not measured | {p[name]['error'][:200]} | |")
    for key, label in (("eval", "closed loop (eval_gpu.json)"), ("voxelize", "voxelization (voxelize_gpu.json)"),
                       ("semantics", "semantics (semantics_gpu.json)"), ("open_vocab", "open_vocab segmenter")):
        d = p.get(key, {})
        if d and "error" not in d:
            flat = {k: x for k, x in d.items() if isinstance(x, (int, float)) and not isinstance(x, bool)}
            lines.append(f"| {label} | " + ", ".join(f"{k} {x:.4g}" for k, x in list(flat.items())[:8]) + " | |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", action="store_true", help="also write docs/benchmarks/bench_gpu.md")
    ap.add_argument("--only", default=",".join(PARTS))
    ap.add_argument("--from-report", action="store_true",
                    help="measure nothing: write the pages from OUT/bench_gpu.json (e.g. after a part was re-run and folded in)")
    ap.add_argument("--notes", help="a markdown file appended to the page (how the run was made)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.from_report:
        rep = json.loads((out / "bench_gpu.json").read_text())
        write(rep, out, args.docs, args.notes)
        return rep
    parts = {name: _part(name, out) for name in args.only.split(",") if name}
    ready = parts.get("ready", {})
    rep = {"versions": {"commit": _commit(), **{k: ready.get(k) for k in ("device", "driver", "driver_cuda", "torch",
                                                                         "torch_cuda", "gsplat", "python")}},
           "parts": parts}
    (out / "bench_gpu.json").write_text(jsonio.dumps(rep, indent=1))
    write(rep, out, args.docs, args.notes)
    return rep


def write(rep: dict, out: Path, docs: bool, notes: str | None = None) -> str:
    """bench_gpu.md in `out` (and docs/benchmarks/bench_gpu.md with `docs`) from a report; `notes`: a markdown
    file appended (how the run was made). The several-GPU figures are their own page,
    docs/benchmarks/bench_multi_gpu.md (make bench-multi-gpu)."""
    md = markdown(rep)
    if notes:
        md += "\n" + Path(notes).read_text().strip() + "\n"
    (out / "bench_gpu.md").write_text(md)
    if docs:
        write_page("bench_gpu.md", md)
    print(md)
    return md


if __name__ == "__main__":
    main()
