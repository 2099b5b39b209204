"""Property-based fuzzing (hypothesis) of the inputs besides 3DGS files that a shared dataset brings:
catalogs (YAML), SceneSplat label folders (instance.npy / segment.npy / classes.txt beside the
Gaussians) and labelled meshes (a ScanNet mesh with its segs / aggregation json, a Replica
mesh_semantic.ply with info_semantic.json, a point cloud with per-vertex ids).

Each case mutates a small valid seed: the byte mutations of the reader fuzzer (truncated,
bit-flipped, lying counts, bombs, a file replaced by a folder), and structural ones: a value of the
YAML / JSON tree replaced by another type, a huge number, a path leading out ('..', absolute), a
long string, a YAML tag that would construct Python objects, an alias bomb; a label array replaced
by an object (pickled) array, another shape, another length, NaN or huge ids. A case must end in
an accepted input (a catalog whose every output path stays inside the data root; an instance table
/ transferred labels) or in a clear error: ValueError (SceneFormatError, FileNotFoundError
included) naming the file. Anything else is a crash, a case over TIME_LIMIT_S a hang, one over the
memory budget a blow-up.

    PYTHONPATH=tests python -m faults.fuzz_inputs --cases 10000   # -> data/08_reports/fuzz_inputs.json
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import signal
import time
import tracemalloc
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import yaml

from faults.fuzz_readers import (
    ALLOC_BASE,
    ALLOC_PER_BYTE,
    OPS,
    TIME_LIMIT_S,
    Hang,
    Tally,
    cap_address_space,
    mutate,
    small_scene,
)

KINDS = ("catalog", "label_folder", "mesh_scannet", "mesh_replica", "mesh_points")
GROUP = {"catalog": "catalogs", "label_folder": "label folders", "mesh_scannet": "labelled meshes",
         "mesh_replica": "labelled meshes", "mesh_points": "labelled meshes"}

VALUES = (None, -1, 0, 2**70, 1e308, math.nan, "", "../../../../etc/passwd", "/etc/passwd", "a/../../b", [1, [2]],
          {"x": {"y": 1}}, "x" * 20000, True, "é/ü\u202e", "a\0b", "nyu40", -2**63, 1.5, "  ", ".hidden", "..")
"""Values a structural mutation puts into a YAML / JSON tree."""
YAML_TRICKS = ("!!python/object/apply:os.system ['echo fuzz']", "!!python/name:os.system",
               "&a [*a]", "!!binary AAAA", "!!set {a, b}", "!!timestamp 2001-12-14", "*undefined_alias")
NPY_TRICKS = ("object", "shape_2d", "longer", "shorter", "nan", "huge", "negative", "bool", "scalar", "structured",
              "fortran", "uint64")


# ---- seeds ------------------------------------------------------------------------------------

def write_labelled_ply(path: Path, verts, faces=None, vprops=None, fprops=None) -> None:
    """A small ASCII PLY with int vertex / face properties (what ScanNet / Replica ship, in ASCII)."""
    vprops, fprops = vprops or {}, fprops or {}
    lines = ["ply", "format ascii 1.0", f"element vertex {len(verts)}", "property float x", "property float y",
             "property float z"] + [f"property int {k}" for k in vprops]
    if faces is not None:
        lines += [f"element face {len(faces)}", "property list uchar int vertex_indices"] + \
            [f"property int {k}" for k in fprops]
    lines.append("end_header")
    for i, v in enumerate(verts):
        lines.append(" ".join([f"{x:.6f}" for x in v] + [str(int(vprops[k][i])) for k in vprops]))
    for i, f in enumerate(faces if faces is not None else []):
        lines.append(" ".join([str(len(f))] + [str(int(j)) for j in f] + [str(int(fprops[k][i])) for k in fprops]))
    path.write_text("\n".join(lines) + "\n")


def _boxes():
    """Two boxes (a sofa and a chair): vertices [16, 3], triangles [24, 3]."""
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return np.concatenate([cube * [1, 1, 0.5], cube * 0.5 + [2, 0, 0]]), np.concatenate([faces, faces + 8])


def make_seed(kind: str, folder: Path) -> Path:
    """The valid seed of one kind; returns what the case reads (catalog file, label folder, mesh)."""
    folder.mkdir(parents=True, exist_ok=True)
    verts, faces = _boxes()
    if kind == "catalog":
        (folder / "room.ply").write_text("")
        (folder / "names.txt").write_text("wall\nsofa\nchair\n")
        spec = {"scenes": [
            {"name": "room", "group": "shared", "path": "room.ply", "license": "CC-BY-4.0", "source_url": "https://x",
             "labels": {"classes": "names.txt", "id_offset": 0, "ignore": [-1], "goal_map": {"couch": "sofa"},
                        "max_distance": 0.05}},
            {"name": "hall", "id": "hall0001", "path": "hall.spz", "format": "spz"}],
            "synthetic": {"prefix": "s", "group": "synthetic", "count": 2, "first_seed": 0, "num_gaussians": 1000},
            "layout": {"instances": {"path": "{root}/04_semantics/{scene_id}/instances.parquet", "type": "parquet"}}}
        (folder / "catalog.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
        return folder / "catalog.yaml"
    if kind == "label_folder":
        from navcore.gaussians.formats import write_npy_folder

        s = small_scene(60, 0, 7)
        s.means[:30] = np.random.default_rng(1).uniform(0, 0.4, (30, 3))  # two tight instances
        s.means[30:] = np.random.default_rng(2).uniform(2, 2.4, (30, 3))
        write_npy_folder(folder / "npy", s)
        np.save(folder / "npy" / "instance.npy", np.repeat([1, 2], 30).astype(np.int32))
        np.save(folder / "npy" / "segment.npy", np.repeat([1, 2], 30).astype(np.int32))
        (folder / "npy" / "classes.txt").write_text("wall\nsofa\nchair\n")
        return folder / "npy"
    if kind == "mesh_scannet":
        write_labelled_ply(folder / "scene0001_00_vh_clean_2.labels.ply", verts, faces, {"label": [6] * 8 + [5] * 8})
        (folder / "scene0001_00_vh_clean_2.0.010000.segs.json").write_text(json.dumps({"segIndices": [10] * 8 + [20] * 8}))
        (folder / "scene0001_00.aggregation.json").write_text(json.dumps({"segGroups": [
            {"objectId": 0, "label": "couch", "segments": [10]}, {"objectId": 4, "label": "chair", "segments": [20]}]}))
        return folder / "scene0001_00_vh_clean_2.labels.ply"
    if kind == "mesh_replica":
        write_labelled_ply(folder / "mesh_semantic.ply", verts, faces, fprops={"object_id": [7] * 12 + [9] * 12})
        (folder / "info_semantic.json").write_text(json.dumps({
            "classes": [{"id": 1, "name": "sofa"}, {"id": 2, "name": "chair"}],
            "objects": [{"id": 7, "class_id": 1}, {"id": 9, "class_name": "chair"}]}))
        return folder / "mesh_semantic.ply"
    if kind == "mesh_points":
        write_labelled_ply(folder / "points.ply", verts, None, {"label": [6] * 8 + [5] * 8, "instance": [1] * 8 + [2] * 8})
        return folder / "points.ply"
    raise ValueError(kind)


# ---- mutations --------------------------------------------------------------------------------

def _paths(tree, prefix=()):
    """Every (path, value) of a YAML / JSON tree, containers included."""
    yield prefix, tree
    if isinstance(tree, dict):
        for k, v in tree.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            yield from _paths(v, prefix + (i,))


def _set(tree, path, value):
    if not path:
        return value
    node = tree
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return tree


def mutate_tree(text: str, a: int, b: int, as_yaml: bool) -> str:
    """One structural mutation of a YAML / JSON document: a value replaced (b picks it from VALUES),
    a key dropped, or (YAML) a tag / alias trick put in a value's place."""
    tree = yaml.safe_load(text) if as_yaml else json.loads(text)
    paths = list(_paths(tree))
    path, _ = paths[a % len(paths)]
    mode = b % 4
    if mode == 3 and path:  # drop the key / item
        parent = tree
        for k in path[:-1]:
            parent = parent[k]
        del parent[path[-1]]
        return yaml.safe_dump(tree) if as_yaml else json.dumps(tree)
    if mode == 2 and as_yaml:  # a tag or alias the safe loader must refuse (or a plain value)
        marker = "FUZZ_TRICK_VALUE"
        out = yaml.safe_dump(_set(tree, path, marker))
        return out.replace(marker, YAML_TRICKS[b // 4 % len(YAML_TRICKS)])
    value = VALUES[b // 4 % len(VALUES)]
    tree = _set(tree, path, value)
    return yaml.safe_dump(tree) if as_yaml else json.dumps(tree, allow_nan=True)


def npy_trick(path: Path, trick: str) -> None:
    """Replace a label array by a hostile one."""
    arr = np.load(path)
    n = len(arr)
    if trick == "object":
        np.save(path, np.array([{"x": 1}] * n, dtype=object), allow_pickle=True)
        return
    new = {"shape_2d": lambda: np.stack([arr, arr], 1), "longer": lambda: np.concatenate([arr, arr[:7]]),
           "shorter": lambda: arr[: n // 2], "nan": lambda: np.where(np.arange(n) % 3, arr, np.nan),
           "huge": lambda: arr.astype(np.int64) + 2**62, "negative": lambda: -arr.astype(np.int64) - 5,
           "bool": lambda: arr > 1, "scalar": lambda: np.array(3), "uint64": lambda: arr.astype(np.uint64) + 2**63,
           "structured": lambda: np.zeros(n, dtype=[("a", "<i4"), ("b", "<f4")]),
           "fortran": lambda: np.asfortranarray(np.stack([arr] * 3, 1))}[trick]()
    np.save(path, new)


def apply_case(kind: str, seed: Path, work: Path, member: int, op: str, a: int, b: int, poison: float,
               structural: int) -> Path:
    """Copy the seed's folder to `work` and apply one mutation; returns the path to read.
    structural: 0 a byte mutation (op) of one file, 1 a tree / array mutation."""
    if work.exists():
        shutil.rmtree(work)
    shutil.copytree(seed.parent if seed.is_file() else seed, work / "in")
    target = work / "in" / (seed.name if seed.is_file() else "")
    files = sorted(p for p in (work / "in").rglob("*") if p.is_file() and p.stat().st_size)
    if kind == "label_folder":  # the label files, not the Gaussians (the reader fuzzer covers those)
        files = [p for p in files if p.name in ("instance.npy", "segment.npy", "classes.txt")]
    elif kind == "catalog":
        files = [target]
    p = files[member % len(files)]
    if structural and p.suffix in (".yaml", ".json"):
        try:
            p.write_text(mutate_tree(p.read_text(), a, b, p.suffix == ".yaml"))
            return target
        except (ValueError, yaml.YAMLError):  # the seed file is already broken: fall back to bytes
            pass
    if structural and p.suffix == ".npy":
        npy_trick(p, NPY_TRICKS[b % len(NPY_TRICKS)])
        return target
    new = mutate(p.read_bytes(), op, a, b, poison, min(p.stat().st_size, 64))
    if new is None:
        p.unlink()
        p.mkdir()
    else:
        p.write_bytes(new)
    return target


# ---- one case ---------------------------------------------------------------------------------

def read_input(kind: str, path: Path, work: Path) -> None:
    """What the pipeline does with the input: raises on a bad one."""
    if kind == "catalog":
        from navcore.io.catalog import Catalog
        from pipeline import sources

        cat = Catalog(path, work / "root")
        for scene in cat.select(0, 1, None, None):
            sources.files("episodes", scene) if scene.path and Path(scene.path).parent.exists() else None
            for ds in ("scene", "markers", "instances", "costmaps"):
                p = cat.path(ds, scene, stage="ingest") if ds == "markers" else cat.dataset(ds, scene).path
                if not Path(p).resolve().is_relative_to(cat.root):
                    raise AssertionError(f"a catalog steered {ds} to {p}, outside the data root")
            if scene.labels is not None:
                sources.label_files(scene.labels)
        return
    if kind == "label_folder":
        from navcore.gaussians.validate import read_validated
        from navcore.instances import gaussian_labels
        from navcore.labels import GoalVocabulary
        from navcore.labels.shipped import CleaningConfig, LabelReport, instances_from_gaussians

        scene, _ = read_validated(path, "npy_folder", scene_id="fuzz")
        entry = SimpleNamespace(path=str(path), labels=None, scene_id="fuzz", name="fuzz", synthetic=False)
        per = gaussian_labels(entry, scene, np.eye(4))
        if per is not None:
            inst, seg, names = per
            instances_from_gaussians(scene.means, scene.alphas, inst, seg, names, GoalVocabulary(), CleaningConfig(),
                                     None, LabelReport())
        return
    from navcore.labels import builtin
    from navcore.labels.mesh import read_labelled_geometry, transfer

    geom = read_labelled_geometry(path, builtin("nyu40") if kind == "mesh_points" else None)
    transfer(geom, np.array([[0.5, 0.5, 0.52], [2.25, 0.25, 0.6], [9.0, 9.0, 9.0]]), 0.05)


def _alarm(signum, frame):
    raise Hang()


def run_case(kind: str, path: Path, work: Path) -> tuple[str, str]:
    """(outcome, detail): outcome accepted | rejected | crash | hang | memory."""
    folder = path if path.is_dir() else path.parent
    size = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())
    budget = ALLOC_BASE + ALLOC_PER_BYTE * size
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, TIME_LIMIT_S)
    tracemalloc.start()
    try:
        read_input(kind, path, work)
        outcome, detail = "accepted", ""
    except ValueError as e:  # SceneFormatError, PathEscapeError, FileNotFoundError-free clear errors
        outcome, detail = "rejected", str(e)
        if str(folder) not in detail and "fuzz" not in detail:
            outcome, detail = "crash", f"{type(e).__name__} naming no file: {detail[:200]}"
    except FileNotFoundError as e:
        outcome, detail = "rejected", str(e)
    except Hang:
        outcome, detail = "hang", f"over {TIME_LIMIT_S} s"
    except MemoryError as e:
        outcome, detail = "memory", f"MemoryError {e}"
    except Exception as e:  # noqa: BLE001 - what fuzzing is for
        outcome, detail = "crash", f"{type(e).__name__}: {e}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    if outcome in ("accepted", "rejected") and peak > budget:
        outcome, detail = "memory", f"peak {peak:,} bytes for {size:,} bytes of input"
    return outcome, detail


def fuzz_kind(kind: str, cases: int, seed: int, work: Path, log=None) -> dict:
    """Run `cases` hypothesis-drawn mutations of one seed kind; returns counts and the failing cases."""
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hseed
    from hypothesis import strategies as st

    from faults.fuzz_readers import POISON

    src = make_seed(kind, work / "seed")
    read_input(kind, src, work / "seed")  # the seed is valid, and the imports are not part of a case's memory
    tally = Tally(kind, log)

    @hseed(seed)
    @settings(max_examples=cases, database=None, deadline=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(st.tuples(st.integers(0, 63), st.sampled_from(OPS), st.integers(0, 2**32 - 1), st.integers(0, 2**16),
                     st.sampled_from(POISON), st.integers(0, 1)))
    def one(case):
        member, op, a, b, poison, structural = case
        path = apply_case(kind, src, work / "case", member, op, a, b, poison, structural)
        t0 = time.perf_counter()
        tally.add(list(case), *run_case(kind, path, work / "case"), t0)

    one()
    return tally.report()


def main(argv=None) -> dict:
    from benchmarks import machine, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=10_000, help="cases per input (labelled meshes: over their three seeds)")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--work", default="/tmp/navarena_fuzz_inputs")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--address-space-gb", type=float, default=16.0)
    args = ap.parse_args(argv)
    cap_address_space(args.address_space_gb)
    kinds = args.kinds.split(",")
    per_group = {g: sum(1 for k in kinds if GROUP[k] == g) for g in set(GROUP[k] for k in kinds)}
    rep = {"machine": machine(), "cases_per_input": args.cases, "kinds": {}}
    t0 = time.perf_counter()
    for kind in kinds:
        t = time.perf_counter()
        n = -(-args.cases // per_group[GROUP[kind]])
        r = fuzz_kind(kind, n, args.seed, Path(args.work) / kind,
                      log=lambda k, f: print(json.dumps({"kind": k, **f}), flush=True))
        r["seconds"], r["input"] = round(time.perf_counter() - t, 1), GROUP[kind]
        rep["kinds"][kind] = r
        print(kind, {k: v for k, v in r.items() if k != "failures"}, flush=True)
    groups: dict[str, int] = {}
    for r in rep["kinds"].values():
        groups[r["input"]] = groups.get(r["input"], 0) + r["cases"]
    rep["cases_per_group"] = groups
    rep["fuzz_cases"] = sum(r["cases"] for r in rep["kinds"].values())
    rep["fuzz_crashes"] = sum(r["crash"] + r["memory"] for r in rep["kinds"].values())
    rep["fuzz_hangs"] = sum(r["hang"] for r in rep["kinds"].values())
    rep["seconds"] = round(time.perf_counter() - t0, 1)
    write_report(args.out, "fuzz_inputs.json", rep)
    return rep


if __name__ == "__main__":
    main()
