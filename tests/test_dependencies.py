"""The design's twelve packages are installed by `make setup` and used by the code; each package the
code imports is declared where its product gets it: the library's (navcore, navarena) in the navarena
distribution's dependencies or an extra, the pipeline project's (pipeline, stages) there or in its
dependency group."""
from __future__ import annotations

import ast
import importlib
import importlib.metadata
import re
import sys

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib


def dist_name(requirement: str) -> str:
    return re.split(r"[<>=!~;\[ (]", requirement, maxsplit=1)[0].strip().lower().replace("_", "-")


def declared(project_root) -> dict[str, set[str]]:
    """{"library": the installed navarena's runtime dependencies, "extras": its extras', "pipeline":
    the pipeline dependency group's (pyproject.toml)}, as normalised distribution names."""
    reqs = importlib.metadata.requires("navarena") or []
    groups = tomllib.loads((project_root / "pyproject.toml").read_text())["dependency-groups"]
    return {"library": {dist_name(r) for r in reqs if "extra ==" not in r},
            "extras": {dist_name(r) for r in reqs if "extra ==" in r},
            "pipeline": {dist_name(r) for r in groups["pipeline"] if isinstance(r, str)}}

DESIGN = {  # distribution -> import name
    "dask": "dask", "distributed": "distributed", "pyarrow": "pyarrow", "zarr": "zarr", "numpy": "numpy",
    "torch": "torch", "gsplat": "gsplat", "open3d": "open3d", "scikit-learn": "sklearn", "shapely": "shapely",
    "hydra-core": "hydra", "ompl": "ompl",
}


@pytest.mark.parametrize("dist,module", sorted(DESIGN.items()))
def test_design_package_is_installed_declared_and_used(dist, module, project_root):
    importlib.import_module(module)  # installed by make setup (gsplat imports without CUDA)
    d = declared(project_root)
    names = d["library"] | d["pipeline"] | d["extras"]
    declared_ = dist in names or (dist == "distributed" and "dask" in names) or \
        (dist == "open3d" and "open3d-cpu" in names)  # dask[distributed]; the CPU build of open3d
    assert declared_, f"{dist} is declared neither by the navarena distribution nor by the pipeline group ({sorted(names)})"
    pattern = re.compile(rf"^\s*(import|from)\s+{module}(\.|\s|$)|require\(\"{module}[.\"]", re.M)
    users = [p for pkg in ("navcore", "stages", "pipeline") for p in (project_root / pkg).rglob("*.py")
             if pattern.search(p.read_text())]
    assert users, f"no module of navcore / stages / pipeline imports {module}"


OPTIONAL = {  # imported only by the code of an extra (or of the GPU), behind a clear error
    "transformers": "open_vocab", "sam3": "sam3", "datasets": "lerobot", "lerobot": "lerobot",
    "torchvision": "sam3", "torchcodec": "lerobot",
}


def top_level_imports(path) -> tuple[set[str], set[str]]:
    """(modules imported at a module's top level, modules imported anywhere) by their first name."""
    tree = ast.parse(path.read_text())

    def names(nodes):
        out = {a.name.split(".")[0] for n in nodes if isinstance(n, ast.Import) for a in n.names}
        return out | {n.module.split(".")[0] for n in nodes if isinstance(n, ast.ImportFrom) and n.module and not n.level}
    return names(tree.body), names(ast.walk(tree))


def test_every_imported_package_is_a_runtime_dependency(project_root):
    """Each third-party package that the code imports is declared for its product: navcore and
    navarena by the distribution (at module level: its dependencies; inside a function: an extra,
    or the pipeline group behind navcore.optional's clear error), stages and pipeline by the
    distribution or the pipeline group. The evaluation's finalize step once imported jsonschema,
    declared only by the test extra, and failed on a machine set up without it."""
    d = declared(project_root)
    dists = importlib.metadata.packages_distributions()
    ours = {"navcore", "stages", "pipeline", "navarena", "benchmarks", "tests"}

    def dists_of(mod):
        names = {x.lower().replace("_", "-") for x in dists.get(mod, [mod])}
        return names | {n.removesuffix("-cpu") for n in names} | {n.replace("-core", "") for n in names}

    missing = {}
    for pkg in ("navcore", "navarena", "stages", "pipeline"):
        library = pkg in ("navcore", "navarena")
        for path in (project_root / pkg).rglob("*.py"):
            top, anywhere = top_level_imports(path)
            for mod in anywhere:
                if mod in ours or mod in sys.stdlib_module_names or mod in OPTIONAL or mod == "__future__":
                    continue
                ok = d["library"] | ({"dask"} if mod == "distributed" else set())
                if not library:
                    ok |= d["pipeline"] | {"open3d"}
                elif mod not in top:  # imported where a feature needs it
                    ok |= d["extras"] | d["pipeline"] | {"open3d"}
                if not dists_of(mod) & ok:
                    missing.setdefault(mod, []).append(str(path.relative_to(project_root)))
    assert not missing, f"imported but not declared for the product that imports them: {missing}"
