"""The design's twelve packages are installed by `make setup` and used by the code."""
from __future__ import annotations

import importlib
import importlib.metadata
import re

import pytest

DESIGN = {  # distribution -> import name
    "dask": "dask", "distributed": "distributed", "pyarrow": "pyarrow", "zarr": "zarr", "numpy": "numpy",
    "torch": "torch", "gsplat": "gsplat", "open3d": "open3d", "scikit-learn": "sklearn", "shapely": "shapely",
    "hydra-core": "hydra", "ompl": "ompl",
}


@pytest.mark.parametrize("dist,module", sorted(DESIGN.items()))
def test_design_package_is_installed_declared_and_used(dist, module, project_root):
    importlib.import_module(module)  # installed by make setup (gsplat imports without CUDA)
    reqs = [r for r in importlib.metadata.requires("navarena") or [] if "extra ==" not in r]  # the installed metadata
    names = {re.split(r"[<>=!~;\[ (]", r, maxsplit=1)[0].strip().lower() for r in reqs}
    declared = dist in names or (dist == "distributed" and "dask" in names) or \
        (dist == "open3d" and "open3d-cpu" in names)  # dask[distributed]; the CPU build of open3d
    assert declared, f"{dist} is not a runtime dependency of the installed navarena ({sorted(names)})"
    pattern = re.compile(rf"^\s*(import|from)\s+{module}(\.|\s|$)", re.M)
    users = [p for pkg in ("navcore", "stages", "pipeline") for p in (project_root / pkg).rglob("*.py")
             if pattern.search(p.read_text())]
    assert users, f"no module of navcore / stages / pipeline imports {module}"
