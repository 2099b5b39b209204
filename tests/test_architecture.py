"""The code's own structure: layers, cycles, private names, stage folders, IO through the catalog.

Layers: navcore (domain: Gaussians and formats, rendering, the navigation vocabulary, IO datasets)
<- stages (one package per graph stage, independent of each other) <- pipeline. Every import
counts, also the ones inside functions.
"""
import ast
import re
from pathlib import Path

import pytest

LAYERS = ("navcore", "stages", "pipeline")  # lowest first
PACKAGES = (*LAYERS, "navarena")  # navarena: the library's commands, over navcore only


def modules(project_root: Path) -> dict[str, Path]:
    out = {}
    for top in PACKAGES:
        for f in sorted((project_root / top).rglob("*.py")):
            parts = list(f.relative_to(project_root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = f
    return out


def imports_of(name: str, path: Path, known: set[str]) -> list[tuple[str, str, int]]:
    """(imported module, imported name or '', line) of every import of our packages in a module."""
    tree = ast.parse(path.read_text())
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, "", node.lineno) for a in node.names if a.name.split(".")[0] in PACKAGES]
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                mod = ".".join(base + ([mod] if mod else []))
            if mod.split(".")[0] not in PACKAGES:
                continue
            for a in node.names:
                sub = f"{mod}.{a.name}"
                out.append((sub, "", node.lineno) if sub in known else (mod, a.name, node.lineno))
    return out


@pytest.fixture(scope="module")
def graph(project_root):
    mods = modules(project_root)
    return mods, {m: imports_of(m, p, set(mods)) for m, p in mods.items()}


def test_imports_never_go_up_a_layer_and_stages_do_not_import_each_other(graph):
    _, edges = graph
    bad = []
    for m, imps in edges.items():
        for target, _, line in imps:
            top, ttop = m.split(".")[0], target.split(".")[0]
            if "navarena" in (top, ttop):  # the library: navarena -> navcore, never the pipeline project
                if top == "navarena" and ttop not in ("navcore", "navarena") or top != "navarena" and top == "navcore":
                    bad.append(f"{m}:{line} imports {target} (the library reaches only navcore)")
                continue
            lm, lt = LAYERS.index(m.split(".")[0]), LAYERS.index(target.split(".")[0])
            if lt > lm:
                bad.append(f"{m}:{line} imports {target} (a higher layer)")
            if m.startswith("stages.") and target.startswith("stages.") and m.split(".")[1] != target.split(".")[1]:
                bad.append(f"{m}:{line} imports {target} (another stage: shared code belongs in navcore)")
    assert not bad, "\n".join(bad)


def test_no_import_cycles(graph):
    _, edges = graph
    adj = {m: sorted({t for t, _, _ in imps if t in edges and t != m}) for m, imps in edges.items()}
    # a package's __init__ importing its own submodules is no cycle of the design; everything else is
    adj = {m: [t for t in ts if not t.startswith(m + ".")] for m, ts in adj.items()}
    index, low, stack, on, cycles, counter = {}, {}, [], set(), [], [0]

    def strongconnect(v):  # Tarjan
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in adj[v]:
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in adj:
        if v not in index:
            strongconnect(v)
    assert not cycles, cycles


def test_no_private_name_is_used_across_packages(graph, project_root):
    mods, edges = graph
    # a module's package: its parent, or itself for a package's __init__ (which belongs to it)
    pkg = lambda m: m if m in mods and mods[m].name == "__init__.py" else m.rpartition(".")[0]  # noqa: E731
    bad = [f"{m}:{line} imports {name} from {target}" for m, imps in edges.items()
           for target, name, line in imps
           if name.startswith("_") and target.rpartition(".")[0] != pkg(m)]
    # module attributes: `mod._x` on an imported module of another package
    for m, path in mods.items():
        tree = ast.parse(path.read_text())
        aliases = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in LAYERS:
                for a in node.names:
                    if f"{node.module}.{a.name}" in mods:
                        aliases[a.asname or a.name] = f"{node.module}.{a.name}"
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases \
                    and node.attr.startswith("_") and not node.attr.startswith("__"):
                target = aliases[node.value.id]
                if target.rpartition(".")[0] != pkg(m):
                    bad.append(f"{m}:{node.lineno} uses {target}.{node.attr}")
    assert not bad, "\n".join(bad)


def test_stage_packages_are_the_graph_stages(project_root):
    from pipeline.graph import STAGES

    folders = {p.name for p in (project_root / "stages").iterdir() if (p / "__init__.py").exists()}
    assert folders == {s.package or s.name for s in STAGES}
    for s in STAGES:  # the graph holds the functions of stages/<package>/stage.py (package: its name unless shared)
        pkg = s.package or s.name
        assert s.package != s.name, f"{s.name}: package equals its name (leave it None)"
        assert s.run.__module__ == f"stages.{pkg}.stage", s.name
        for fn in (s.inputs, s.finalize):
            assert fn is None or fn.__module__ == f"stages.{pkg}.stage"


IO_BY_HAND = re.compile(r"catalog\.path\(|atomic_path|write_text_atomic|zarr\.open|pq\.(?:read|write)_table|"
                        r"\.read_text\(|\.write_text\(|read_scene_zarr|write_scene_zarr")


def test_stages_read_and_write_through_catalog_datasets(project_root):
    bad = [f"{f.relative_to(project_root)}:{i}: {line.strip()}"
           for f in sorted((project_root / "stages").rglob("*.py"))
           for i, line in enumerate(f.read_text().splitlines(), 1) if IO_BY_HAND.search(line)]
    assert not bad, "\n".join(bad)


def test_layout_datasets_have_known_types(project_root):
    import yaml

    from navcore.io.catalog import LAYOUT_FILE
    from navcore.io.datasets import TYPES

    layout = yaml.safe_load(LAYOUT_FILE.read_text())
    for name, entry in layout.items():
        assert isinstance(entry, str) or entry["type"] in TYPES, name


def test_registries_list_without_importing_heavy_modules(project_root):
    """Listing agents, segmenters, planners, metrics and formats imports none of them (lazy
    entries), and every entry resolves."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from navcore.eval.agents import AGENTS\n"
            "from stages.semantics.segmenters import SEGMENTERS\n"
            "from stages.episodes.planner import PLANNERS\n"
            "from navcore.eval.metrics import METRICS\n"
            "from navcore.gaussians.formats import READERS\n"
            "names = [list(r) for r in (AGENTS, SEGMENTERS, PLANNERS, METRICS, READERS)]\n"
            "assert 'sam3' in names[1] and 'stages.semantics.sam3_segmenter' not in sys.modules\n"
            "import pipeline.config\n"
            "assert 'torch' not in sys.modules, 'importing the config pulls in torch'\n"
            "for r in (AGENTS, PLANNERS, METRICS, READERS):\n"
            "    assert all(r[k] is not None for k in r)\n")
    subprocess.run([sys.executable, "-c", code], cwd=project_root, check=True)


def test_moved_modules_leave_no_alias_behind(project_root):
    """What moved out of pipeline/ and stages/ (the catalog to navcore.io, the user tools and the gym
    env to navarena, the evaluator's library to navcore.eval) and out of navarena (the dataset API to
    navcore.eval, the trainers to navcore.baselines, the torchvision install hook to scripts/) has one import path: the old ones are
    gone, and no module is a shim of another."""
    import importlib

    for old in ("pipeline.catalog", "pipeline.observations", "pipeline.lerobot_export", "pipeline.render_episodes",
                "pipeline.inspect_scene", "stages.evaluate.env", "stages.evaluate.gym_env", "stages.evaluate.protocol",
                "stages.align.floor", "navarena.dataset", "navarena.progress", "navarena.torchvision_fix"):
        with pytest.raises(ModuleNotFoundError):
            importlib.import_module(old)
    shims = [str(p.relative_to(project_root)) for top in PACKAGES for p in (project_root / top).rglob("*.py")
             if "Deprecated import path" in p.read_text() or "import *" in p.read_text()]
    assert not shims, shims


def test_pipeline_holds_orchestration_only(project_root):
    orchestration = {"__init__", "__main__", "backends", "config", "executor", "graph", "locks", "markers",
                     "submit", "summary", "tasks", "config_guard", "episode_progress",
                     "sources",  # whether the outside files a marker's outputs came from are still those
                     "config_reference",  # the configuration / CLI reference pages, generated from config and __main__
                     "kernels",  # compiles the CPU kernels ahead of a first run (a tiny run of the stages)
                     "check_costmap"}  # navarena check-costmap: a finished run's costmaps checked with its markers' configs
    found = {p.stem for p in (project_root / "pipeline").glob("*.py")}
    assert found <= orchestration, found - orchestration


def test_the_import_contracts_name_every_stage_and_the_benchmarks(project_root):
    """pyproject's contracts (lint-imports checks them): every stage folder is in the independence
    list, and benchmarks is a root package that nothing of the product may import."""
    import tomllib

    linter = tomllib.loads((project_root / "pyproject.toml").read_text())["tool"]["importlinter"]
    assert "benchmarks" in linter["root_packages"]
    independent = next(c for c in linter["contracts"] if c["type"] == "independence")["modules"]
    folders = {f"stages.{p.name}" for p in (project_root / "stages").iterdir() if (p / "__init__.py").exists()}
    assert set(independent) == folders
    forbidden = [c for c in linter["contracts"] if c["type"] == "forbidden" and c["forbidden_modules"] == ["benchmarks"]]
    assert forbidden and set(forbidden[0]["source_modules"]) == {"navcore", "stages", "pipeline", "navarena"}


def test_navcore_subpackages_have_no_two_way_ties(graph):
    """No two subpackages of navcore import each other (either way round, any module, lazy imports
    included): what both need lives below both (navcore.paths: the path guard that io, gaussians and
    labels share; the pinhole of a field of view in gaussians.cameras, which render re-exports)."""
    _, edges = graph
    sub = lambda m: m.split(".")[1] if m.startswith("navcore.") and m.count(".") >= 2 else None  # noqa: E731
    ties = {(sub(m), sub(t)) for m, imps in edges.items() for t, _, _ in imps
            if sub(m) and sub(t) and sub(m) != sub(t)}
    two_way = {tuple(sorted(p)) for p in ties if p[::-1] in ties}
    assert not two_way, two_way
