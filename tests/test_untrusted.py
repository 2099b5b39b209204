"""Untrusted input, audited: nothing from outside (catalogs, sources, label files, meshes, agent-server
frames, results files, release folders) is unpickled, eval'd, loaded with an unsafe YAML loader,
read with allow_pickle=True or torch.load without weights_only=True, and names read from files
cannot lead out of the folder they must stay in."""
import ast
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CODE = ("navcore", "pipeline", "stages", "navarena", "benchmarks", "examples", "scripts")

UNSAFE_MODULES = {"pickle", "cPickle", "_pickle", "dill", "cloudpickle", "joblib", "marshal", "shelve", "jsonpickle"}
"""Modules whose loads run code from their input: any use of their readers is flagged."""

ALLOWED = {
    ("navcore/registry.py", "importlib.import_module"):
        "a 'package.module:attr' the user's own config names (an agent, segmenter, planner, metric); catalogs, "
        "sources and results never reach it (formats are looked up in a fixed table, navcore.gaussians.formats)",
    ("navarena/cli.py", "importlib.import_module"): "the CLI's fixed command tables (CONSUMER, PRODUCER), never input",
    ("navcore/optional.py", "importlib.import_module"): "a fixed package name of the library's own call sites",
    ("navarena/__init__.py", "importlib.import_module"): "the fixed table of the public API's names (_API), never input",
    ("pipeline/config_reference.py", "importlib.import_module"): "the CLI's fixed tool table, for the generated reference",
    ("navarena/doctor.py", "importlib.import_module"): "a fixed list of packages whose presence doctor reports",
    ("benchmarks/scale/render_cpu.py", "importlib.import_module"):
        "the project's own renderer at an older commit of this repository (git show), for an A/B timing",
}
"""(file, call) -> why the call is safe there. A flagged call elsewhere fails the audit; an entry
that no longer matches anything fails too (the list stays true)."""


def _name(node) -> str:
    """Dotted name of a call's function ("np.load", "eval"), or ""."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):  # a method of a computed object: "?.eval" (no builtin)
        return f"{_name(node.value) or '?'}.{node.attr}"
    return ""


def _kw(call: ast.Call, name: str):
    for k in call.keywords:
        if k.arg == name:
            return k.value
    return None


def _is_const(node, value) -> bool:
    return isinstance(node, ast.Constant) and node.value is value


def flagged(tree: ast.AST) -> list[tuple[int, str, str]]:
    """(line, call, why) of every call that could run code from, or unpickle, its input."""
    out = []
    aliases = {}  # import pickle as pk / from pickle import loads
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in UNSAFE_MODULES:
                    aliases[a.asname or a.name] = a.name
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in UNSAFE_MODULES:
            for a in node.names:
                out.append((node.lineno, f"from {node.module} import {a.name}", "an unpickling module's reader"))
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        n = _name(node.func)
        head = n.split(".")[0]
        if head in aliases or head in UNSAFE_MODULES and "." in n:
            out.append((node.lineno, n, "unpickles (runs code from) its input"))
        elif n in ("eval", "exec", "compile", "__import__"):
            out.append((node.lineno, n, "evaluates code"))
        elif n.endswith("importlib.import_module") or n == "import_module":
            out.append((node.lineno, "importlib.import_module", "imports a module by name"))
        elif n in ("yaml.unsafe_load", "yaml.full_load", "yaml.unsafe_load_all", "yaml.full_load_all"):
            out.append((node.lineno, n, "an unsafe YAML loader"))
        elif n in ("yaml.load", "yaml.load_all"):
            loader = _kw(node, "Loader") or (node.args[1] if len(node.args) > 1 else None)
            if not (loader is not None and _name(loader).split(".")[-1] in ("SafeLoader", "CSafeLoader")):
                out.append((node.lineno, n, "yaml.load without SafeLoader"))
        elif n.endswith(".load") and head in ("np", "numpy") or n in ("np.load", "numpy.load"):
            ap = _kw(node, "allow_pickle")
            if ap is not None and not _is_const(ap, False):
                out.append((node.lineno, n, "allow_pickle not False"))
        elif n == "torch.load":
            if not _is_const(_kw(node, "weights_only"), True):
                out.append((node.lineno, n, "torch.load without weights_only=True"))
        elif n.endswith("read_pickle") or n.endswith("from_pickle"):
            out.append((node.lineno, n, "unpickles its input"))
        elif n.endswith("from_pretrained") and _is_const(_kw(node, "trust_remote_code"), True):
            out.append((node.lineno, n, "trust_remote_code=True runs the model folder's code"))
    return out


def audit() -> tuple[list[str], set]:
    bad, used = [], set()
    for top in CODE:
        for f in sorted((ROOT / top).rglob("*.py")):
            rel = str(f.relative_to(ROOT))
            for line, call, why in flagged(ast.parse(f.read_text(), rel)):
                if (rel, call) in ALLOWED:
                    used.add((rel, call))
                else:
                    bad.append(f"{rel}:{line}: {call} ({why})")
    return bad, used


def test_no_code_runs_from_input_outside_the_allow_list():
    bad, used = audit()
    assert not bad, "calls that could run code from their input:\n" + "\n".join(bad)
    assert used == set(ALLOWED), f"allow-list entries that match nothing any more: {set(ALLOWED) - used}"


def test_the_audit_catches_what_it_must():
    src = """
import pickle as pk
import numpy as np, yaml, torch
from dill import loads
pk.load(open("x", "rb"))
eval("1")
yaml.load(s)
yaml.load(s, Loader=yaml.SafeLoader)
yaml.full_load(s)
np.load("a.npy", allow_pickle=True)
np.load("a.npy")
torch.load("w.pt")
torch.load("w.pt", weights_only=True)
import pandas as pd; pd.read_pickle("x")
"""
    calls = [c for _, c, _ in flagged(ast.parse(src))]
    assert set(calls) == {
        "from dill import loads", "pk.load", "eval", "yaml.load", "yaml.full_load", "np.load", "torch.load",
        "pd.read_pickle"}
    assert calls.count("yaml.load") == 1 and calls.count("torch.load") == 1 and calls.count("np.load") == 1


def test_names_read_from_files_stay_in_their_folder(tmp_path):
    from navcore.paths import PathEscapeError, contained

    (tmp_path / "f").mkdir()
    (tmp_path / "secret").write_text("x")
    assert contained(tmp_path / "f", "a/b.webp", "w") == tmp_path / "f" / "a" / "b.webp"
    for name in ("../secret", str(tmp_path / "secret"), "a/../../secret", "", 3):
        with pytest.raises(PathEscapeError, match="w: "):
            contained(tmp_path / "f", name, "w")
    (tmp_path / "f" / "link").symlink_to(tmp_path)
    with pytest.raises(PathEscapeError, match="points outside"):
        contained(tmp_path / "f", "link/secret", "w")


def test_a_sog_meta_cannot_read_outside_its_folder(tmp_path):
    from navcore.gaussians.errors import SceneFormatError
    from navcore.gaussians.formats import read_gaussians

    (tmp_path / "scene").mkdir()
    lod = {"lodLevels": 1, "filenames": ["../outside/meta.json"], "tree": {"lods": {"0": {"file": 0}}}}
    (tmp_path / "scene" / "lod-meta.json").write_text(json.dumps(lod))
    with pytest.raises(SceneFormatError, match="points outside"):
        read_gaussians(tmp_path / "scene" / "lod-meta.json")
    meta = {"version": 2, "count": 1, "means": {"files": ["../../etc/passwd"]}}
    (tmp_path / "scene" / "meta.json").write_text(json.dumps(meta))
    (tmp_path / "scene" / "lod-meta.json").unlink()
    with pytest.raises(SceneFormatError, match="points outside"):
        read_gaussians(tmp_path / "scene" / "meta.json")


def test_asset_files_cannot_name_files_outside_the_asset(tmp_path):
    from navcore.io.asset_files import aligned_model, read_nav_map
    from navcore.paths import PathEscapeError

    (tmp_path / "a").mkdir()
    (tmp_path / "x.ply").write_text("x")
    (tmp_path / "a" / "manifest.json").write_text(json.dumps({"files": {"aligned": "../x.ply"}}))
    with pytest.raises(PathEscapeError, match="files.aligned"):
        aligned_model(tmp_path / "a")
    (tmp_path / "a" / "nav_map.yaml").write_text("image: /etc/hostname\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(PathEscapeError, match="image"):
        read_nav_map(tmp_path / "a")


def test_catalog_paths_leading_out_are_resolved_and_listed(tmp_path):
    from navcore.io.catalog import Catalog

    (tmp_path / "cats").mkdir()
    (tmp_path / "cats" / "in.ply").write_text("")
    cat = tmp_path / "cats" / "c.yaml"
    cat.write_text("scenes:\n"
                   "  - {name: inside, path: in.ply}\n"
                   "  - {name: up, path: ../elsewhere/s.ply, labels: {classes: nyu40, mesh: /abs/m.ply}}\n")
    c = Catalog(cat, tmp_path / "d")
    assert [(o["scene"], o["key"], o["resolved"]) for o in c.outside] == [
        ("up", "path", str(tmp_path / "elsewhere" / "s.ply")), ("up", "labels.mesh", "/abs/m.ply")]
