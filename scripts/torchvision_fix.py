"""Loads torchvision's Python part next to a torch whose build its C++ operators do not match.

PyPI has no CPU build of torchvision: the wheel is built against CUDA torch, so beside the CPU
torch that `make setup` installs its operator library cannot load, and `import torchvision` then
fails on its unguarded fake registrations (``RuntimeError: operator torchvision::nms does not
exist``). lerobot (loading a LeRobot export) and transformers import torchvision's transforms,
which need no operator. The fix declares those operators' schemas before torchvision's first
import, and does nothing when they exist (a matching torchvision).

An install step of the checkout's venv, not part of the library: `make setup` runs
``python scripts/torchvision_fix.py install``, which copies this file into the venv's site-packages
as the module `navarena_torchvision_fix` with a `.pth` start-up line: an import hook that acts only
when torchvision is imported, so an interpreter that never imports torchvision pays nothing (torch
is not imported early). Calling ``navarena_torchvision_fix.apply()`` before importing lerobot does
the same by hand.
"""
from __future__ import annotations

import sys
import sysconfig
from importlib.abc import MetaPathFinder
from pathlib import Path

PTH = "navarena_torchvision_fix.pth"
MODULE = "navarena_torchvision_fix"
"""The name this file is installed under in site-packages (the .pth imports it at start-up)."""


UNGUARDED = {"nms": "(Tensor dets, Tensor scores, float iou_threshold) -> Tensor",
             "qnms": "(Tensor dets, Tensor scores, float iou_threshold) -> Tensor"}
"""The operators torchvision's _meta_registrations registers fakes for without checking that its
library loaded (0.25: nms; 0.28: nms and qnms), with their schemas."""


def apply() -> list[str]:
    """Declare the UNGUARDED operators torch does not have; the names it had to declare."""
    import torch

    done = []
    for name, schema in UNGUARDED.items():
        try:
            getattr(torch.ops.torchvision, name)
        except (AttributeError, RuntimeError):
            torch.library.define(f"torchvision::{name}", schema)
            done.append(name)
    return done


class _Hook(MetaPathFinder):
    """Runs apply() once, just before the first import of torchvision, then steps aside."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname == "torchvision":
            sys.meta_path.remove(self)
            try:
                apply()
            except Exception:  # noqa: BLE001 - never break an import that would otherwise work
                pass
        return None


def hook() -> None:
    """Install the import hook (idempotent)."""
    if "torchvision" not in sys.modules and not any(isinstance(f, _Hook) for f in sys.meta_path):
        sys.meta_path.insert(0, _Hook())


def install(site: str | None = None) -> Path:
    """Copy this module and write the .pth start-up line into this interpreter's site-packages (or `site`)."""
    folder = Path(site or sysconfig.get_paths()["purelib"])
    (folder / f"{MODULE}.py").write_text(Path(__file__).read_text())
    target = folder / PTH
    target.write_text(f"import {MODULE} as _navarena_tv; _navarena_tv.hook()\n")
    return target


if __name__ == "__main__":
    if sys.argv[1:] == ["install"]:
        print(f"installed {install()}")
    else:
        print("usage: python scripts/torchvision_fix.py install", file=sys.stderr)
        sys.exit(2)
