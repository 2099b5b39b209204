"""Sources that change under a finished run (pipeline.sources): a real scene's source file replaced,
truncated, touched or deleted, and its label files edited, are noticed on the next run, which
recomputes exactly that scene's affected stages (or fails naming the file) and never keeps
outputs made from bytes that no longer exist."""
import os
import shutil
from pathlib import Path

import pytest

from navcore.io.release import sha256_file
from pipeline import sources
from pipeline.executor import execute


def _write(path: Path, data: bytes, mtime_ns: int | None = None) -> None:
    path.write_bytes(data)
    if mtime_ns is not None:
        os.utime(path, ns=(mtime_ns, mtime_ns))


def test_record_and_problem_known_answers(tmp_path):
    f = tmp_path / "scene.ply"
    _write(f, b"a" * 100)
    rec = sources.record([str(f)])
    assert rec == {str(f): [100, f.stat().st_mtime_ns, sha256_file(f)]}
    assert sources.problem(rec, [str(f)]) is None and sources.problem(None, [str(f)]) is None
    st = f.stat()
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))  # touched: same bytes, another mtime
    assert sources.problem(rec, [str(f)]) is None
    _write(f, b"b" * 100)  # other bytes, same size
    p = sources.problem(rec, [str(f)])
    assert p["file"] == str(f) and p["old_sha256"] == rec[str(f)][2] and p["new_sha256"] == sha256_file(f)
    assert rec[str(f)][2][:16] in p["message"] and p["new_sha256"][:16] in p["message"]
    _write(f, b"a" * 40)  # truncated
    assert "100 -> 40 bytes" in sources.problem(rec, [str(f)])["message"]
    f.unlink()
    p = sources.problem(rec, [str(f)])
    assert "was deleted" in p["message"] and p["new_sha256"] is None
    # other bytes behind the recorded size and mtime: only verify=checksum can tell
    _write(f, b"c" * 100, rec[str(f)][1])
    assert sources.problem(rec, [str(f)], "size") is None
    assert sources.problem(rec, [str(f)], "checksum")["new_sha256"] == sha256_file(f)
    assert sources.problem(rec, [str(f)], "none") is None
    # a folder layout that gained or lost a file
    g = tmp_path / "g"
    _write(g, b"x")
    assert "was added" in sources.problem(rec, [str(f), str(g)])["message"]
    rec2 = sources.record([str(g)])
    assert "no longer one of the scene's files" in sources.problem(rec2, [])["message"]
    assert sources.record([str(tmp_path / "nope.ply"), str(g)]) == rec2  # the stage reading it names it


def test_label_files_of_a_catalog_entry(tmp_path):
    from navcore.labels.shipped import LabelSpec

    (tmp_path / "m").mkdir()
    for name in ("scene0001_00_vh_clean_2.labels.ply", "scene0001_00_vh_clean_2.0.010000.segs.json",
                 "scene0001_00.aggregation.json", "names.txt"):
        (tmp_path / "m" / name).write_text("x")
    spec = LabelSpec(classes="m/names.txt", mesh="m/scene0001_00_vh_clean_2.labels.ply", mesh_classes="nyu40",
                     base=str(tmp_path))
    assert [Path(p).name for p in sources.label_files(spec)] == ["names.txt", "scene0001_00.aggregation.json",
                                                     "scene0001_00_vh_clean_2.0.010000.segs.json",
                                                     "scene0001_00_vh_clean_2.labels.ply"]
    assert sources.label_files(LabelSpec(classes="scannet20")) == []


@pytest.fixture(scope="module")
def two_sources(tmp_path_factory):
    """Two small rooms written as INRIA PLY files (different seeds), outside any data root."""
    from navcore.gaussians.formats.ply import write_inria_ply
    from stages.synthesize.generate import SyntheticConfig, generate_scene
    from stages.synthesize.layout import LayoutConfig

    d = tmp_path_factory.mktemp("sources")
    out = []
    for seed in (1, 2):
        small = SyntheticConfig(num_gaussians=30_000, layout=LayoutConfig(rooms_max=2, room_size_max_m=4.4))
        scene = generate_scene(seed, small).gaussians
        write_inria_ply(d / f"room{seed}.ply", scene)
        out.append(d / f"room{seed}.ply")
    return out


def _statuses(summary) -> dict:
    return {(r["scene"], r["stage"]): r["status"] for r in summary["results"] if r["stage"] != "synthesize"}


def test_changed_source_recomputes_that_scene_downstream_only(tmp_path, make_cfg, two_sources):
    a, b = tmp_path / "a.ply", tmp_path / "b.ply"
    shutil.copy(two_sources[0], a)
    shutil.copy(two_sources[0], b)
    cat = tmp_path / "cat.yaml"
    cat.write_text(f"scenes:\n  - {{name: a, group: t, path: {a}}}\n  - {{name: b, group: t, path: {b}}}\n")
    cfg = make_cfg(tmp_path / "d", f"scenes.catalog={cat}", "scenes.count=null", "stages=[align]")
    stages = ("ingest", "voxelize", "align")
    first = execute(cfg)
    assert {v for v in _statuses(first).values()} == {"done"}
    marker = tmp_path / "d" / "_markers" / "align"
    recorded = [m for m in marker.glob("*.json")]
    assert all(str(a) in p.read_text() or str(b) in p.read_text() for p in recorded)

    # touched (copied over with the same bytes): nothing to redo
    shutil.copy(two_sources[0], a)
    assert set(_statuses(execute(cfg)).values()) == {"cached"}
    import json  # ... and the markers now record the new mtime (the next run stats, it does not hash)
    recs = [json.loads(p.read_text())["sources"] for p in (tmp_path / "d" / "_markers" / "align").glob("*.json")]
    assert len(recs) == 2 and all(rec[1] == os.stat(f).st_mtime_ns for r in recs for f, rec in r.items())

    # replaced with another room's bytes: scene a's stages recomputed, b untouched
    old = sha256_file(a)
    shutil.copy(two_sources[1], a)
    s = execute(cfg)
    st = _statuses(s)
    assert [st[("a", x)] for x in stages] == ["done"] * 3 and [st[("b", x)] for x in stages] == ["cached"] * 3
    (row,) = s["sources_changed"]
    assert row["scene"] == "a" and row["file"] == str(a) and row["stages"] == list(stages)
    assert row["old_sha256"] == old and row["new_sha256"] == sha256_file(a)
    # ... and the outputs are those of a fresh run on the new bytes
    from benchmarks.dataset.compare_data import compare

    fresh = tmp_path / "fresh"
    (fresh / "s").mkdir(parents=True)
    shutil.copy(two_sources[1], fresh / "s" / "a.ply")
    shutil.copy(two_sources[0], fresh / "s" / "b.ply")
    cat2 = fresh / "cat.yaml"
    cat2.write_text(f"scenes:\n  - {{name: a, group: t, path: {fresh / 's' / 'a.ply'}}}\n"
                    f"  - {{name: b, group: t, path: {fresh / 's' / 'b.ply'}}}\n")
    execute(make_cfg(fresh / "d", f"scenes.catalog={cat2}", "scenes.count=null", "stages=[align]"))
    c = compare(tmp_path / "d", fresh / "d")
    assert c["files"][0] > 10 and not c["only_first"] and not c["only_second"], c
    for rel in c["differing"]:  # only where the stores and reports name their source's path
        mine = (tmp_path / "d" / rel).read_text().replace(str(tmp_path), "<T>")
        theirs = (fresh / "d" / rel).read_text().replace(str(fresh / "s"), "<T>").replace(str(fresh), "<T>")
        assert mine.replace("<T>/d", "<ROOT>") == theirs.replace("<T>/d", "<ROOT>"), rel

    # truncated: ingest fails naming the file and why it ran; nothing downstream is trusted
    data = a.read_bytes()
    a.write_bytes(data[: len(data) // 2])
    s = execute(cfg)
    st = _statuses(s)
    assert st[("a", "ingest")] == "failed" and [st[("a", x)] for x in stages[1:]] == ["skipped"] * 2
    err = next(r["error"] for r in s["results"] if r["scene"] == "a" and r["stage"] == "ingest")
    assert str(a) in err and "recomputed because" in err and "sha256" in err
    sid = next(r["scene_id"] for r in s["results"] if r["scene"] == "a")
    assert not (tmp_path / "d" / "_markers" / "ingest" / f"{sid}.json").exists()

    # deleted: a failure naming the file, not a silent reuse of what it made
    a.unlink()
    s = execute(cfg)
    err = next(r["error"] for r in s["results"] if r["scene"] == "a" and r["stage"] == "ingest")
    assert "a.ply" in err and ("not found" in err or "does not exist" in err)
    assert _statuses(s)[("b", "align")] == "cached"

    # restored: ingest redone; the later stages' outputs were made from these very bytes and stand
    shutil.copy(two_sources[1], a)
    st = _statuses(execute(cfg))
    assert st[("a", "ingest")] == "done" and [st[("a", x)] for x in stages[1:]] == ["cached"] * 2
    assert set(_statuses(execute(cfg)).values()) == {"cached"}

    # other bytes behind the same size and mtime: only verify=checksum notices
    st0 = a.stat()
    arr = bytearray(a.read_bytes())
    arr[-5] ^= 0xFF  # one byte of the last Gaussian's data
    _write(a, bytes(arr), st0.st_mtime_ns)
    assert set(_statuses(execute(cfg)).values()) == {"cached"}
    cfg.verify = "checksum"
    s = execute(cfg)
    assert _statuses(s)[("a", "ingest")] == "done" and _statuses(s)[("b", "ingest")] == "cached"
    assert s["sources_changed"][0]["new_sha256"] == sha256_file(a)


def test_a_folder_source_is_listed_once_a_run(tmp_path):
    from types import SimpleNamespace

    (tmp_path / "npy").mkdir()
    (tmp_path / "npy" / "coord.npy").write_bytes(b"x")
    scene = SimpleNamespace(synthetic=False, path=str(tmp_path / "npy"), labels=None)
    with sources.one_listing_a_run():
        first = sources.files("costmap", scene)
        (tmp_path / "npy" / "segment.npy").write_bytes(b"y")
        assert sources.files("episodes", scene) == first  # the run's client lists once
    assert len(sources.files("costmap", scene)) == 2  # the next run (or a worker) sees the new file
    assert sources.files("ingest", scene) == sources.files("costmap", scene)
    assert sources.files("synthesize", scene) == []  # upstream of the reader: none
