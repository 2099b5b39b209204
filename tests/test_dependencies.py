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


OPTIONAL = {  # imported only by the code of an extra (or of the GPU), behind a clear error
    "transformers": "open_vocab", "sam3": "sam3", "datasets": "lerobot", "lerobot": "lerobot",
    "torchvision": "sam3", "torchcodec": "lerobot",
}


def test_every_imported_package_is_a_runtime_dependency(project_root):
    """Each third-party package that navcore / stages / pipeline / navarena import is a runtime
    dependency of the installed navarena (or the code of a named extra): the evaluation's
    finalize step once imported jsonschema, declared only by the test extra, and failed on a
    machine set up without it."""
    import ast
    import sys

    reqs = importlib.metadata.requires("navarena") or []
    runtime = {re.split(r"[<>=!~;\[ (]", r, maxsplit=1)[0].strip().lower().replace("_", "-")
               for r in reqs if "extra ==" not in r}
    dists = importlib.metadata.packages_distributions()
    ours = {"navcore", "stages", "pipeline", "navarena", "benchmarks", "tests"}
    missing = {}
    for pkg in ("navcore", "stages", "pipeline", "navarena"):
        for path in (project_root / pkg).rglob("*.py"):
            tree = ast.parse(path.read_text())
            mods = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
            mods |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module and not n.level}
            for mod in mods:
                if mod in ours or mod in sys.stdlib_module_names or mod in OPTIONAL or mod == "__future__":
                    continue
                names = {d.lower().replace("_", "-") for d in dists.get(mod, [mod])}
                names |= {n.removesuffix("-cpu") for n in names} | {n.replace("-core", "") for n in names}
                if not names & (runtime | {"open3d"}) and not (mod == "distributed" and "dask" in runtime):
                    missing.setdefault(mod, []).append(str(path.relative_to(project_root)))
    assert not missing, f"imported but not runtime dependencies of navarena: {missing}"
