"""Compile the CPU kernels ahead of a first run: numba compiles each kernel on its first call and
caches it beside its module (`__pycache__/*.nbi, *.nbc`), so every later process loads it in
milliseconds. On a fresh checkout the first pipeline run spends about 45 s of one core compiling;
processes that start at the same time (Dask workers, pytest-xdist workers) each compile the same
kernels. This does it once, on two cores: the renderer's kernels in a child process while this one
runs a tiny scene through the stages up to the costmap, then the rest of the default stages (whose
views then load the renderer's kernels from the cache) beside a second child compiling the kernels
of the checks (the rasteriser's visit counts, the render check's per-ray hits).

    python -m pipeline.kernels            # about 40 s on two cores when nothing is cached
    python -m pipeline.kernels --if-stale # nothing when the caches are newer than their sources
"""
from __future__ import annotations

import argparse
import io
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PROJECT = Path(__file__).resolve().parents[1]
TINY = ("scenes.count=1", "scenes.num_gaussians=5000", "synthetic.layout.rooms_min=1", "synthetic.layout.rooms_max=1",
        "synthetic.layout.room_size_min_m=3.6", "synthetic.layout.room_size_max_m=4.0", "task.pointnav.episodes_per_scene=2",
        "task.imagenav.episodes_per_scene=1", "task.objectnav.episodes_per_scene=1", "executor=sync",
        "episodes.scene_splits.val_unseen=0", "episodes.scene_splits.test=0")
"""One small generated room, every default stage in a few seconds once compiled."""


def kernel_modules(project: Path = PROJECT) -> list[Path]:
    """The project's source files that define cached numba kernels."""
    out = []
    for pkg in ("navcore", "stages"):
        for f in sorted((project / pkg).rglob("*.py")):
            text = f.read_text(encoding="utf-8", errors="replace")
            if "cache=True" in text and "numba" in text:
                out.append(f)
    return out


def stale(project: Path = PROJECT) -> list[Path]:
    """The kernel modules whose cache is older than their source, or missing for the renderer's
    compositing kernel (the sign of a fresh checkout); modules that a run never calls (and so
    never cached) do not count."""
    bad = []
    for f in kernel_modules(project):
        idx = list((f.parent / "__pycache__").glob(f"{f.stem}.*.nbi"))
        if (idx and max(i.stat().st_mtime for i in idx) < f.stat().st_mtime) or (not idx and f.name == "composite.py"):
            bad.append(f)
    return bad


def _tiny_view():
    """A small generated scene and one 64 x 48 camera 3 m in front of it: (gaussians, viewmat, K)."""
    import numpy as np

    from stages.synthesize.generate import SyntheticConfig, generate_scene

    gs = generate_scene(0, SyntheticConfig(num_gaussians=3000)).gaussians
    vm = np.eye(4, dtype=np.float32)
    vm[2, 3] = 3.0
    return gs, vm, np.array([[40, 0, 32], [0, 40, 24], [0, 0, 1]], np.float32)


def render_kernels() -> None:
    """The CPU renderer's kernels: colour and depth, with extra channels, and with features."""
    import numpy as np

    from navcore.render import Renderer

    gs, vm, K = _tiny_view()
    r = Renderer(gs, "cpu")
    r.render(vm[None], K[None], 64, 48)
    r.render(vm[None], K[None], 64, 48, extra=np.ones((len(gs.means), 2), np.float32))
    r.render(vm[None], K[None], 64, 48, features=np.ones((len(gs.means), 3), np.float32))


def analysis_kernels() -> None:
    """The kernels of the checks and benchmarks: the rasteriser counting the Gaussians it reads
    (visits) and the render check's per-ray hits."""
    import numpy as np

    from navcore.render import cpu_fast
    from navcore.render.ray_hits import panorama_hit_depth_cpu, ray_gaussians

    gs, vm, K = _tiny_view()
    n = len(gs.means)
    cpu_fast.render_one(cpu_fast.prepare(gs), vm, K, 64, 48, 0, visits=np.zeros((n, 2), np.uint8))
    panorama_hit_depth_cpu(ray_gaussians(gs), np.zeros((1, 1, 3)), np.array([0, n]), np.arange(n), 8, 4, -0.5, 0.5,
                           0.0, 2.0)


def pipeline_kernels(root: Path, *overrides: str) -> None:
    from hydra import compose, initialize_config_dir
    from rich.console import Console

    from pipeline.config import CONF_DIR, register_configs
    from pipeline.executor import execute

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=[f"data_root={root}", *TINY, *overrides])
    summary = execute(cfg, Console(file=io.StringIO()))  # the run's summary is of no interest here
    if summary["failures"]:
        raise RuntimeError(f"the kernels' tiny run failed: {summary['failures'][:2]}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pipeline.kernels", description=__doc__.split("\n")[0])
    ap.add_argument("--if-stale", action="store_true", help="do nothing when the caches are newer than their sources")
    ap.add_argument("--only", choices=("render", "analysis"), help=argparse.SUPPRESS)  # the child processes
    args = ap.parse_args(argv)
    if args.only:
        render_kernels() if args.only == "render" else analysis_kernels()
        return 0
    if args.if_stale and not stale():
        return 0
    t = time.perf_counter()
    def child(what: str) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, "-m", "pipeline.kernels", "--only", what], cwd=PROJECT)

    render = child("render")
    with tempfile.TemporaryDirectory(prefix="navarena_kernels_") as tmp:
        pipeline_kernels(Path(tmp), "stages=[costmap]")
        if render.wait() != 0:
            raise RuntimeError("compiling the renderer's kernels failed (see above)")
        analysis = child("analysis")  # on the other core while the rest of the stages run here
        pipeline_kernels(Path(tmp))
        if analysis.wait() != 0:
            raise RuntimeError("compiling the analysis kernels failed (see above)")
    print(f"CPU kernels compiled and cached in {time.perf_counter() - t:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
