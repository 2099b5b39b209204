"""The release (issue 45): built from a finished data root, verified, loaded with the tools users
have (datasets, pyarrow, mlcroissant), its licences, evaluation set, versions and damage detection."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from navcore.io.release import MANIFEST, RELEASE_JSON, read_card_front_matter, read_manifest, sha256_file, write_manifest
from navcore.nav.eval_set import EvalSetConfig, allocate, feasible_size, select

# synth_0000 (d0ba0a89) is the only generated scene: holding out 10 % as test puts it in the test split
HELD_OUT = ["episodes.scene_splits.val_unseen=0", "episodes.scene_splits.test=0.1"]
SMALL = ["task.pointnav.episodes_per_scene=24", "task.imagenav.episodes_per_scene=12", "task.objectnav.episodes_per_scene=12"]


def _candidates(groups=2, scenes=3, per=(100, 100, 100), categories=("bed", "chair", "sofa")) -> pd.DataFrame:
    rows = []
    for g in range(groups):
        for s in range(scenes):
            for d, n in zip(("easy", "medium", "hard"), per):
                for k in range(n):
                    rows.append({"task": "objectnav", "scene_id": f"g{g}s{s}", "group": f"g{g}",
                                 "episode_id": f"test_{d}_{k:04d}", "difficulty": d,
                                 "goal_object_category": categories[k % len(categories)], "split": "test"})
    return pd.DataFrame(rows)


def test_eval_set_has_the_papers_proportions_and_spreads_over_strata():
    chosen, report = select(_candidates(), EvalSetConfig())
    assert report["objectnav"]["selected"] == 600
    assert chosen["difficulty"].value_counts().to_dict() == {"easy": 180, "medium": 240, "hard": 180}
    # round robin: groups and scenes (and categories within a scene) share each difficulty evenly
    per_scene = chosen.groupby(["difficulty", "scene_id"]).size()
    assert per_scene.groupby("difficulty").agg(lambda x: x.max() - x.min()).max() <= 1
    per_cat = chosen.groupby(["difficulty", "scene_id", "goal_object_category"]).size()
    assert per_cat.groupby(["difficulty", "scene_id"]).agg(lambda x: x.max() - x.min()).max() <= 1
    again, _ = select(_candidates().sample(frac=1.0, random_state=3), EvalSetConfig())
    assert again.equals(chosen)  # independent of the candidates' order
    other, _ = select(_candidates(), EvalSetConfig(seed=1))
    assert not other.equals(chosen)


def test_eval_set_shrinks_keeping_the_proportions():
    # 50 medium episodes: N = 126 splits into 38 / 50.4 -> 50 / 38 (largest remainders), 127 would need 51
    chosen, report = select(_candidates(groups=1, scenes=1, per=(100, 50, 100)), EvalSetConfig())
    assert report["objectnav"]["selected"] == 126 == len(chosen)
    assert report["objectnav"]["per_difficulty"] == {"easy": 38, "medium": 50, "hard": 38}
    assert chosen["difficulty"].value_counts().to_dict() == allocate(126, EvalSetConfig().proportions)
    assert feasible_size({"easy": 0}, 600, EvalSetConfig().proportions) == 0
    assert allocate(600, {"easy": 0.3, "medium": 0.4, "hard": 0.3}) == {"easy": 180, "medium": 240, "hard": 180}
    empty, report = select(_candidates().assign(split="train"), EvalSetConfig())
    assert empty.empty and report == {}


@pytest.fixture(scope="module")
def release_root(tmp_path_factory, make_cfg):
    """A finished data root of two scenes: a generated one (the project's licence) and the same
    Gaussians brought in as an outside capture whose catalog entry names no licence."""
    from pipeline.executor import execute

    root = tmp_path_factory.mktemp("release_root")
    s = execute(make_cfg(root, *SMALL, *HELD_OUT))
    assert not s["failures"], s["failures"]
    catalog = root / "catalog.yaml"
    catalog.write_text(
        "synthetic: {prefix: synth, group: synthetic, count: 1, first_seed: 0, num_gaussians: 60000}\n"
        "scenes:\n"
        f"  - {{name: borrowed, group: outside, path: {root}/00_sources/synthetic/synth_0000/scene.ply,\n"
        "     source_url: 'https://example.org/capture', attribution: 'someone'}\n")
    over = [*SMALL, *HELD_OUT, f"scenes.catalog={catalog}"]
    s = execute(make_cfg(root, *over))
    assert not s["failures"], s["failures"]
    return root, over


@pytest.fixture(scope="module")
def release(release_root, make_cfg, tmp_path_factory):
    from pipeline.release.build import build_release

    root, over = release_root
    out = root / "11_releases" / "r1"
    summary = build_release(make_cfg(root, *over, "release.version=1.0.0"), out)
    return out, summary


def test_release_verifies_and_leaves_out_the_licenceless_scene(release, release_root):
    from navarena.verify_release import verify

    out, summary = release
    info = json.loads((out / RELEASE_JSON).read_text())
    assert [e["name"] for e in info["scenes"]["excluded"]] == ["borrowed"]
    assert "no licence stated" in info["scenes"]["excluded"][0]["reason"]
    borrowed = info["scenes"]["excluded"][0]["scene_id"]
    card = (out / "README.md").read_text()
    assert "Scenes left out of this public release" in card and "borrowed" in card
    # each scene's ObjectNav goal source, as scenes.parquet records it from the semantics stage's marker
    scenes = pq.read_table(out / "scenes.parquet").to_pandas()
    for r in scenes.itertuples():
        goals = f"`{r.goal_segmenter}`, {int(r.goal_instances or 0)} instances" if r.goal_segmenter else "none"
        assert f"| {r.scene_id} | {r.group} |" in card and f"| {goals} | `" in card, goals
    assert "No rendered frames ship" in card
    assert not [f for f in read_manifest(out / MANIFEST) if borrowed in f]  # no episodes, assets, goal images
    assert summary["hard_links"] > 0 and summary["copies"] == 0  # the data root's bytes, not a second copy
    report = verify(out, sample=0, quiet=True)
    assert report.ok, report.problems
    assert report.checked["episodes re-checked"] == summary["episodes"] + sum(
        r["selected"] for r in info["eval_set"]["per_task"].values())


def test_release_loads_with_datasets_pyarrow_and_croissant(release, tmp_path, monkeypatch):
    import datasets
    import mlcroissant as mlc
    import pyarrow.dataset as pds

    out, _ = release
    monkeypatch.setenv("HF_DATASETS_CACHE", str(tmp_path / "hf"))
    fm = read_card_front_matter(out / "README.md")
    card = {(c["config_name"], s["name"]): s["num_examples"] for c in fm["dataset_info"] for s in c["splits"]}
    assert {sp for _, sp in card} == {"test", "eval_zeroshot"}
    keys = ["task", "split", "scene_id", "episode_id"]
    for (task, split), n in card.items():
        # datasets adds no columns from paths: the key columns come from the files themselves, and the
        # card's datasets join finds every step's one episode
        eps_hf = datasets.load_dataset(str(out), task, split=split).to_pandas()
        steps_hf = datasets.load_dataset(str(out), f"{task}_trajectories", split=split).to_pandas()
        assert len(eps_hf) == n and set(eps_hf["task"]) == {task} and set(eps_hf["split"]) == {split}
        assert set(eps_hf["scene_id"]) and not eps_hf.duplicated(["scene_id", "episode_id"]).any()
        joined = steps_hf.merge(eps_hf, on=keys, validate="many_to_one")
        assert len(joined) == len(steps_hf) > 0 and joined[keys].drop_duplicates().shape[0] == n
    table = pds.dataset(out / "episodes", format="parquet").to_table()
    assert table.num_rows == sum(card.values())
    assert table.schema.names[:3] == ["task", "split", "scene_id"]
    for read in (pd.read_parquet, lambda f: pq.read_table(f).to_pandas()):  # a folder read as one table
        frame = read(out / "episodes")
        assert len(frame) == table.num_rows
        assert frame.groupby(["task", "split"], observed=True).size().to_dict() == \
            {(t, sp): n for (t, sp), n in card.items()}
    # every file's key columns are its path's
    for f in (out / "episodes").rglob("*.parquet"):
        t = pq.read_table(f, columns=["task", "split", "scene_id"]).to_pandas().drop_duplicates()
        assert t.values.tolist() == [list(f.relative_to(out / "episodes").with_suffix("").parts)]
    # the card's pandas join of expert steps to episodes: every step finds its one episode
    eps = table.to_pandas()
    steps = pd.read_parquet(out / "trajectories")
    assert not eps.duplicated(keys).any()  # unique across the release
    # and without the split, outside the evaluation set's split (its episodes are copies of test episodes)
    assert not eps[eps["split"] != "eval_zeroshot"].duplicated(["task", "scene_id", "episode_id"]).any()
    joined = steps.merge(eps, on=keys, validate="many_to_one")
    assert len(joined) == len(steps) > len(eps) and (joined.groupby(keys).size().reset_index()[keys].shape[0]
                                                     == len(eps))
    assert "steps.merge(eps" in (out / "README.md").read_text()
    md = mlc.Dataset(jsonld=str(out / "croissant.json"))
    assert not md.metadata.issues.errors
    assert not [w for w in md.metadata.issues.warnings if "citeAs" in str(w)]  # a citation without release.citation
    assert "@misc{" in json.loads((out / "croissant.json").read_text())["citeAs"]
    card_text = (out / "README.md").read_text()
    assert "## Citation" in card_text
    from navcore.io.episode_schema import EPISODE_SCHEMA, FIELD_DOCS, TRAJECTORY_SCHEMA

    for kind, schema in (("episodes", EPISODE_SCHEMA), ("trajectories", TRAJECTORY_SCHEMA)):
        assert set(FIELD_DOCS[kind]) == set(schema.names)  # every column has its meaning, no stale one
        assert all(f"| `{f.name}` | `{f.type}` | {FIELD_DOCS[kind][f.name]} |" in card_text for f in schema
                   if f.name != "split")  # the key columns are described once, before the tables
    n = sum(1 for _ in md.records("pointnav"))
    assert n == card[("pointnav", "test")] + card[("pointnav", "eval_zeroshot")]
    rec = next(iter(md.records("pointnav")))
    assert isinstance(rec["pointnav/geodesic_distance"], float)
    splits = {r["pointnav/split"].decode() if isinstance(r["pointnav/split"], bytes) else r["pointnav/split"]
              for r in md.records("pointnav")}
    assert splits == {"test", "eval_zeroshot"}
    step = next(iter(md.records("pointnav_trajectories")))["pointnav_trajectories/scene_id"]
    assert (step.decode() if isinstance(step, bytes) else step) in set(table["scene_id"].to_pylist())


def test_eval_set_ships_as_a_split_and_runs_in_evaluate(release, release_root, make_cfg):
    import pyarrow.dataset as pds

    from pipeline.executor import execute

    out, _ = release
    root, over = release_root
    info = json.loads((out / RELEASE_JSON).read_text())
    listing = pq.read_table(out / "eval_sets" / "eval_zeroshot.parquet").to_pandas()
    for task, r in info["eval_set"]["per_task"].items():
        mine = listing[listing["task"] == task]
        assert len(mine) == r["selected"] > 0
        assert mine["difficulty"].value_counts().to_dict() == {k: v for k, v in r["per_difficulty"].items() if v}
        assert r["per_difficulty"] == allocate(r["selected"], EvalSetConfig().proportions)
    # the data root has the same listing; evaluate.split=eval_zeroshot runs exactly those episodes, and
    # draws the same listing itself where no release wrote one
    in_root = root / "05_eval_sets" / "eval_zeroshot.parquet"
    assert pq.read_table(in_root).equals(pq.read_table(out / "eval_sets" / "eval_zeroshot.parquet"))
    in_root.unlink()
    s = execute(make_cfg(root, *over, "stages=[evaluate]", "evaluate.split=eval_zeroshot", "evaluate.render=false",
                         "evaluate.agent=oracle", "evaluate.run=zs", "scenes.ids=[synth_0000]"))
    assert not s["failures"], s["failures"]
    res = pd.concat(pd.read_parquet(p) for p in (root / "07_eval" / "zs" / "results").rglob("*.parquet"))
    assert sorted(zip(res["task"], res["episode_id"])) == sorted(zip(listing["task"], listing["episode_id"]))
    assert pq.read_table(in_root).equals(pq.read_table(out / "eval_sets" / "eval_zeroshot.parquet"))
    budgets = {"easy": 500, "medium": 1000, "hard": 1500}
    eps = pds.dataset(out / "episodes", format="parquet").to_table().to_pandas()
    zs = eps[eps["split"] == "eval_zeroshot"]
    assert (zs["max_steps"] == zs["difficulty"].map(budgets)).all()


def test_copied_release_is_independent_of_the_data_root(release, release_root, make_cfg, tmp_path):
    """release.copy_files (navarena release --copy): no file shares its bytes with the data root; a
    byte flipped in the copy leaves the root and the hard-linked release as they were."""
    from navarena.verify_release import verify
    from pipeline.release.build import build_release

    root, over = release_root
    linked, _ = release
    out = tmp_path / "copied"
    summary = build_release(make_cfg(root, *over, "release.version=1.0.0", "release.copy_files=true"), out)
    root_inodes = {f.stat().st_ino for f in root.rglob("*") if f.is_file() and out not in f.parents}
    files = [f for f in out.rglob("*") if f.is_file()]
    assert files and not any(f.stat().st_ino in root_inodes for f in files)
    assert summary["hard_links"] == 0 and summary["copies"] > 0
    victim = next(out.glob("episodes/pointnav/*/*.parquet"))
    twin = linked / victim.relative_to(out)
    before = twin.read_bytes()
    data = bytearray(victim.read_bytes())
    data[len(data) // 2] ^= 0xFF
    victim.write_bytes(bytes(data))
    assert not verify(out, sample=0, quiet=True).ok
    assert twin.read_bytes() == before and verify(linked, sample=0, quiet=True).ok


def test_internal_release_keeps_every_scene(release_root, make_cfg):
    from pipeline.release.build import build_release

    root, over = release_root
    out = root / "11_releases" / "internal"
    build_release(make_cfg(root, *over, "release.public=false"), out)
    info = json.loads((out / RELEASE_JSON).read_text())
    assert info["scenes"]["included"] == 2 and not info["scenes"]["excluded"]
    card = (out / "README.md").read_text()
    assert "Internal release" in card.split("\n## ")[0]
    assert "| borrowed |" in card and "unknown (**not redistributable**)" in card
    assert read_card_front_matter(out / "README.md")["license"] == "other"  # mixed licences


def test_release_refuses_an_unfinished_root_naming_scenes_and_stages(release_root, make_cfg):
    from pipeline.release.build import ReleaseError, build_release

    root, over = release_root
    with pytest.raises(ReleaseError, match=r"synth_0000 \(d0ba0a89\) stage episodes: made with another config"):
        build_release(make_cfg(root, *over, "task.pointnav.episodes_per_scene=25"), root / "11_releases" / "nope")
    assert not (root / "11_releases" / "nope").exists()


def test_versions_reuse_unchanged_files_and_write_notes(release, release_root, make_cfg, monkeypatch):
    from pipeline.release.build import ReleaseError, build_release

    out, _ = release
    root, over = release_root
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    v2 = root / "11_releases" / "r2"
    summary = build_release(make_cfg(root, *over, "release.version=1.1.0", f"release.previous={out}"), v2)
    notes = (v2 / "RELEASE_NOTES.md").read_text()
    assert "0 added, 0 removed, 0 changed, 1 unchanged" in notes
    old, new = read_manifest(out / MANIFEST), read_manifest(v2 / MANIFEST)
    episodes = [f for f in new if f.startswith(("episodes/", "trajectories/"))]
    assert episodes and all(old[f] == new[f] for f in episodes)  # byte-identical episodes across versions
    assert all(os.stat(out / f).st_ino == os.stat(v2 / f).st_ino for f in episodes)  # one copy of the bytes
    assert summary["reused_from_previous"] >= len(episodes)
    # determinism: the same root, config and time stamp give the same bytes
    v2b = root / "11_releases" / "r2b"
    build_release(make_cfg(root, *over, "release.version=1.1.0", f"release.previous={out}"), v2b)
    assert read_manifest(v2b / MANIFEST) == new
    with pytest.raises(ReleaseError, match="not higher"):
        build_release(make_cfg(root, *over, "release.version=1.0.0", f"release.previous={out}"), root / "11_releases" / "x")


def _damaged_copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)  # real copies: damage must not reach the data root through hard links
    return dst


def _rehash(folder: Path, rel: str) -> None:
    m = read_manifest(folder / MANIFEST)
    m[rel] = ((folder / rel).stat().st_size, sha256_file(folder / rel))
    write_manifest(folder / MANIFEST, m)


@pytest.mark.parametrize("damage", ["flip", "truncate", "delete", "extra", "schema", "edit", "misplaced", "task"])
def test_verify_release_names_every_damaged_file(release, tmp_path, damage):
    from navarena.verify_release import verify

    out, _ = release
    rel = next(f for f in read_manifest(out / MANIFEST) if f.startswith("episodes/pointnav/test/"))
    d = _damaged_copy(out, tmp_path / "copy")
    p = d / rel
    if damage == "flip":
        b = bytearray(p.read_bytes())
        b[len(b) // 2] ^= 0x01
        p.write_bytes(bytes(b))
        want = "sha256 differs"
    elif damage == "truncate":
        p.write_bytes(p.read_bytes()[:-100])
        want = "truncated"
    elif damage == "delete":
        p.unlink()
        want = "missing"
    elif damage == "extra":
        (d / "episodes" / "stray.parquet").write_bytes(b"x")
        rel, want = "episodes/stray.parquet", "unexpected"
    elif damage == "schema":
        t = pq.read_table(p)
        t = t.set_column(t.schema.get_field_index("geodesic_distance"), "geodesic_distance", t["geodesic_distance"].cast(pa.float64()))
        pq.write_table(t, p)
        _rehash(d, rel)  # even with a consistent manifest the schema check names it
        want = "schema differs"
    elif damage in ("misplaced", "task"):  # rows that say another split (or task) than their file's path
        t = pq.read_table(p)
        col = "split" if damage == "misplaced" else "task_type"
        t = t.set_column(t.schema.get_field_index(col), t.schema.field(col), pa.array(["train" if col == "split" else "imagenav"]
                                                                                  * t.num_rows, pa.string()))
        pq.write_table(t, p)
        _rehash(d, rel)
        want = "rows of split ['train']" if damage == "misplaced" else "rows of task_type ['imagenav']"
    else:  # an edited episode whose manifest line was updated too: the re-check against the map finds it
        t = pq.read_table(p).to_pandas()
        t.loc[0, "geodesic_distance"] = np.float32(t.loc[0, "geodesic_distance"] * 0.7)
        pq.write_table(pa.Table.from_pandas(t, schema=pq.read_schema(p), preserve_index=False), p)
        _rehash(d, rel)
        want = "stored geodesic"
    report = verify(d, sample=0, quiet=True)
    assert not report.ok
    assert any(pr["file"].startswith(rel) and want in pr["problem"] for pr in report.problems), report.problems


FUZZ_KINDS = {"parquet": lambda f: f.endswith(".parquet"), "json": lambda f: f.endswith(".json"),
              "pgm": lambda f: f.endswith(".pgm"), "png": lambda f: f.endswith(".png"),
              "yaml": lambda f: f.endswith(".yaml"), "card": lambda f: f == "README.md",
              "manifest": lambda f: f == MANIFEST, "manifest digest": lambda f: f == MANIFEST + ".sha256"}


def test_verify_release_fuzz_never_crashes_and_names_the_file(release, tmp_path, capsys):
    """Bytes flipped at random offsets of every kind of file a release holds, truncations and
    deletions: every case exits 1, names the damaged file, and raises nothing."""
    from navarena.verify_release import main

    out, _ = release
    d = _damaged_copy(out, tmp_path / "copy")
    files = sorted(str(p.relative_to(d)) for p in d.rglob("*") if p.is_file())
    rng = np.random.default_rng(0)
    cases = 0
    for kind, match in FUZZ_KINDS.items():
        pool = [f for f in files if match(f)]
        assert pool, f"the release holds no {kind} file"
        for rel in [pool[k] for k in rng.choice(len(pool), min(2, len(pool)), replace=False)]:
            p = d / rel
            original = p.read_bytes()
            damages = [("flip", int(rng.integers(0, len(original)))) for _ in range(3)]
            damages += [("truncate", int(rng.integers(0, len(original)))), ("delete", 0)]
            for how, at in damages:
                if how == "flip":
                    b = bytearray(original)
                    b[at] ^= int(rng.integers(1, 256))
                    p.write_bytes(bytes(b))
                elif how == "truncate":
                    p.write_bytes(original[:at])
                else:
                    p.unlink()
                try:
                    rc = main([str(d), "--sample", "3", "--quiet"])
                finally:
                    p.write_bytes(original)
                err = capsys.readouterr().err
                assert rc == 1, (rel, how, at)
                assert f"] {rel}" in err, (rel, how, at, err)
                assert "Traceback" not in err
                cases += 1
    assert main([str(d), "--sample", "3", "--quiet"]) == 0  # restored: clean again
    print(f"verify-release fuzz: {cases} cases")
    assert cases >= 40


def test_verify_release_cli_exit_codes(release, tmp_path, capsys):
    from navarena.verify_release import main

    out, _ = release
    assert main([str(out), "--sample", "5", "--quiet"]) == 0
    d = _damaged_copy(out, tmp_path / "copy")
    (d / "scenes.parquet").unlink()
    assert main([str(d), "--sample", "5", "--quiet", "--json", str(tmp_path / "r.json")]) == 1
    assert "scenes.parquet: missing" in capsys.readouterr().err
    assert json.loads((tmp_path / "r.json").read_text())["ok"] is False


def test_licence_table_and_catalog_provenance(tmp_path):
    from navcore.io.catalog import Catalog
    from navcore.io.licences import PROJECT_LICENSE, redistributable

    assert redistributable("CC-BY-4.0")[0] and redistributable("MIT")[0]
    for lic in (None, "", "CC-BY-NC-4.0", "CC-BY-ND-4.0", "ScanNet Terms of Use (no redistribution)"):
        assert not redistributable(lic)[0]
    assert redistributable("CC-BY-NC-4.0", ["CC-BY-NC-4.0"]) == (True, "allowed by release.extra_licenses")
    ply = tmp_path / "a.ply"
    ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nend_header\n")
    cat = tmp_path / "c.yaml"
    cat.write_text("synthetic: {count: 1}\nscenes:\n  - {name: a, path: a.ply, format: inria_ply, license: CC-BY-4.0, "
                   "source_url: 'https://x.org', attribution: me}\n")
    c = Catalog(cat, tmp_path / "data")
    a, syn = sorted(c.scenes, key=lambda s: s.format)
    assert (a.license, a.source_url, a.attribution) == ("CC-BY-4.0", "https://x.org", "me")
    assert syn.license == PROJECT_LICENSE and "seed 0" in syn.attribution
    # the project's licence is the one pyproject and LICENSE declare
    root = Path(__file__).resolve().parents[1]
    assert f'license = "{PROJECT_LICENSE}"' in (root / "pyproject.toml").read_text()
    assert "Apache License" in (root / "LICENSE").read_text() and PROJECT_LICENSE == "Apache-2.0"
    cat.write_text("scenes:\n  - {name: a, path: a.ply, format: inria_ply, license: 3}\n")
    with pytest.raises(ValueError, match="license must be a string"):
        Catalog(cat, tmp_path / "data")


def test_verify_release_bounds_a_geodesic_from_both_sides_of_a_binary_map(tmp_path):
    """A released map's wall with a pinch (two free cells meeting only at a corner) and a way round.
    Cell by cell the geodesic goes through the pinch; with the clearance rebuilt with the robot's
    radius (release.json's embodiment) it goes round. An episode planned on the stored clearance may
    have either (the 500-scene simulation's release held one of 2.45 m whose map gives 1.09 m cell by
    cell and 2.49 m with the radius), so both pass; a geodesic shorter than the first or longer than
    the second is named."""
    from navarena.verify_release import SceneMap, map_settings
    from navcore.io.asset_files import write_pgm

    occ = np.zeros((40, 40), bool)
    occ[19:21, :] = True
    occ[19, 10] = occ[20, 11] = False  # the pinch
    occ[19:21, 34:] = False  # the way round, 0.3 m wide
    write_pgm(tmp_path / "nav_map.pgm", occ)
    (tmp_path / "nav_map.yaml").write_text("image: nav_map.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
                                           "occupied_thresh: 0.65\nfree_thresh: 0.25\n")
    start, goal = np.array([0.575, 0.5]), [(0.525, 1.5)]
    sm = SceneMap(tmp_path, *map_settings({"config": {"embodiment": {"radius": 0.18},
                                                      "episodes": {"geodesic_neighbourhood": 6}}}))
    through, round_ = sm.geodesic(start, goal), sm.geodesic(start, goal, "radius")
    assert abs(through - 1.0) < 0.05 and round_ > 2.5 * through  # over to x > 1.7 m and back
    for stored in (through, round_, (through + round_) / 2):
        assert sm.check_geodesic(start, goal, stored) is None, stored
    assert "recomputed on the map 1.0" in sm.check_geodesic(start, goal, 0.5 * through)
    assert "with the robot's radius" in sm.check_geodesic(start, goal, 1.5 * round_)
    # without the radius (a release.json that does not say, or says nonsense) only cell by cell
    assert "recomputed on the map 1.0" in SceneMap(tmp_path).check_geodesic(start, goal, round_)
    from stages.episodes.config import EpisodesConfig

    fallback = EpisodesConfig().geodesic_neighbourhood  # the episodes stage's default, where release.json is silent
    for info in ({}, {"config": None}, {"config": {"embodiment": {"radius": "x"}}}, {"config": {"embodiment": {"radius": True}}}):
        assert map_settings(info) == (None, fallback)


def test_scene_ids_by_split_agree_between_the_release_and_its_data_root(release, release_root):
    """NavDataset.scene_ids(task, split): the scenes holding episodes of that split, the same for a
    release (split in the path) and the data root it came from (split a column); every listed
    scene's episodes of the split exist, and an unknown split lists none."""
    from navcore.eval.dataset import NavDataset

    out, _ = release
    rel, root = NavDataset(out), NavDataset(release_root[0])
    eval_set = json.loads((out / RELEASE_JSON).read_text())["eval_set"]["name"]  # a release's own split
    splits = {s for sid in rel.scene_ids("pointnav") for s in rel.episode_table(sid, "pointnav")["split"]} - {eval_set}
    assert splits
    for split in splits:
        in_release = rel.scene_ids("pointnav", split=split)
        assert in_release and set(in_release) <= set(root.scene_ids("pointnav", split=split))
        for sid in in_release:
            assert rel.episodes(sid, "pointnav", split=split, limit=1)
    assert rel.scene_ids("pointnav", split="nope") == root.scene_ids("pointnav", split="nope") == []
