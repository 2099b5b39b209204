"""The pipeline: outputs, markers, reruns, config changes, failures, determinism, Dask."""
import json
import os
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import zarr

from navcore.io.datasets import CostmapDataset
from pipeline.config import register_configs
from pipeline.executor import execute

register_configs()


def statuses(summary):
    return {r["stage"]: r["status"] for r in summary["results"]}


@pytest.fixture(scope="module")
def costmap_root(tmp_path_factory, make_cfg, copy_data_root):
    """copy(dest) -> scene id: a copy of the small scene through the costmap (stages=[costmap], the
    defaults), made once, for tests that would otherwise run the same stages again."""
    root = tmp_path_factory.mktemp("costmap_root")
    s = execute(make_cfg(root, "stages=[costmap]"))
    assert set(statuses(s).values()) == {"done"} and not s["failures"], s["failures"]
    sid = s["results"][0]["scene_id"]

    def copy(dest: Path) -> str:
        copy_data_root(root, dest)
        return sid
    return copy


def test_full_run_then_cached_then_partial_recompute(tmp_path, make_cfg, capsys):
    cfg = make_cfg(tmp_path, "asset.write_compressed_splat=true")
    s1 = execute(cfg)
    assert set(statuses(s1).values()) == {"done"} and not s1["failures"]
    # without a terminal (here: captured) no bar redraws: a line per (stage, scene) task as it ends
    out = capsys.readouterr().out
    n = len([r for r in s1["results"] if ":" not in r["stage"]])  # (stage, scene) tasks, not dataset-level steps
    assert re.search(rf"\[\d+/{n}\] done costmap \w+ \(\w+\), \d+ s", out), out[-2000:]
    sid = s1["results"][0]["scene_id"]
    asset = next((tmp_path / "09_assets" / "synthetic").iterdir())
    man = json.loads((asset / "manifest.json").read_text())
    assert man["scene_id"] == sid and man["map_info"]["resolution"] == 0.05
    # every file of the asset holds what the stores hold
    from PIL import Image

    from navcore.gaussians.formats import read_gaussians
    from navcore.io.asset_files import read_pgm
    from navcore.io.datasets import AlignedGaussianDataset, GaussianDataset

    store = GaussianDataset(tmp_path / "01_scenes" / sid / "gaussians.zarr")
    aligned, attrs = AlignedGaussianDataset(tmp_path / "01_scenes" / sid / "alignment.json", store).load()
    source, _ = store.load()
    t = np.asarray(attrs["source_to_aligned"])
    assert np.allclose(aligned.means, source.means @ t[:3, :3].T + t[:3, 3], atol=1e-5)  # derived on read
    assert not (tmp_path / "01_scenes" / sid / "aligned.zarr").exists()  # the Gaussians are stored once
    ply = read_gaussians(asset / "aligned.ply")
    assert len(ply) == len(aligned) and np.allclose(ply.means, aligned.means, atol=1e-6)
    # source.ply is the generated original itself: linked, not a second copy
    original = next((tmp_path / "00_sources" / "synthetic").iterdir()) / "scene.ply"
    assert (asset / "source.ply").samefile(original) and man["files"]["source_ply"] == "source.ply"
    assert len(read_gaussians(asset / "source.ply")) == len(source)
    splat = read_gaussians(asset / "compressed.splat")  # .splat is sorted by size x opacity
    assert len(splat) == len(aligned)
    assert np.allclose(np.sort(splat.means, axis=0), np.sort(aligned.means, axis=0), atol=1e-5)
    g = zarr.open_group(str(tmp_path / "03_costmaps" / f"{sid}.zarr"))["locobot"]
    occ, sup = np.asarray(g["occ"][...]), np.asarray(g["support"][...])
    assert np.array_equal(read_pgm(asset / "nav_map.pgm"), occ)  # PGM rows flipped, 0 = occupied
    assert np.array_equal(np.asarray(Image.open(asset / "nav_mask.png"))[::-1] > 0, sup)
    # the costmap picture: the map enlarged k times, a scale bar on it, its legend under it
    from navcore.io.map_picture import topdown_image

    pic = np.asarray(Image.open(asset / "costmap_topdown.png"))
    k = int(np.ceil(480 / max(occ.shape)))
    layers = {n: np.asarray(g[n][...]) for n in ("raw", "components")}
    cells = pic[:occ.shape[0] * k:k, :occ.shape[1] * k:k]
    assert cells.shape[:2] == occ.shape and pic.shape[0] > occ.shape[0] * k + 60  # legend rows below
    assert (cells != topdown_image(layers["raw"], sup, occ, layers["components"])).any(-1).mean() < 0.03
    # drawn by the costmap stage (before semantics and the asset), the asset holding the same bytes
    assert (tmp_path / "03_costmaps" / f"{sid}.png").read_bytes() == (asset / "costmap_topdown.png").read_bytes()
    assert man["map_info"]["size"] == [occ.shape[1], occ.shape[0]]
    ros = (asset / "nav_map.yaml").read_text()
    assert "image: nav_map.pgm" in ros and f"resolution: {man['map_info']['resolution']}" in ros
    labels = json.loads((asset / "labels.json").read_text())["labels"]
    assert labels and all({"instance_id", "category", "position"} <= set(lab) for lab in labels)
    assert man["files"]["labels"] == "labels.json" and man["files"]["compressed_ply"] == "compressed.splat"
    for stage in ("ingest", "voxelize", "align", "costmap", "asset"):  # markers vouch for this config
        m = json.loads((tmp_path / "_markers" / stage / f"{sid}.json").read_text())
        assert m["stage"] == stage and m["config_hash"] == s1["config_hashes"][stage]

    assert set(statuses(execute(cfg)).values()) == {"cached"}
    # a run killed after its last export task but before the dataset-level step: the next run's
    # scene tasks are all cached, yet it must finish the dataset files
    meta = next((tmp_path / "10_exports").rglob("dataset_meta.json"))
    before = json.loads(meta.read_text())
    meta.unlink()
    (tmp_path / "_markers" / "export" / "_finalize.json").unlink()
    s2 = execute(cfg)
    assert statuses(s2)["export:finalize"] == "done" and statuses(s2)["export"] == "cached"
    after = json.loads(meta.read_text())
    stamp = {k for k in before if "date" in k or "time" in k}  # build time stamps differ between runs
    assert {k: v for k, v in after.items() if k not in stamp} == {k: v for k, v in before.items() if k not in stamp}
    # a changed costmap parameter recomputes costmap and what depends on it, nothing upstream
    s3 = execute(make_cfg(tmp_path, "stages=[costmap]", "costmap.resolution=0.1"))
    st = statuses(s3)
    assert st["costmap"] == "done" and st["voxelize"] == "cached" and "asset" not in st
    occ01 = np.asarray(zarr.open_group(str(tmp_path / "03_costmaps" / f"{sid}.zarr"))["locobot"]["occ"][...])
    assert occ01.shape[0] < occ.shape[0]
    # force recomputes only the selected stage
    s4 = execute(make_cfg(tmp_path, "stages=[align]", "force=true"))
    assert statuses(s4)["align"] == "done" and statuses(s4)["voxelize"] == "cached"
    latest = json.loads((tmp_path / "_runs" / "latest.json").read_text())
    assert latest["counts"]["align"] == {"done": 1}


def test_keys_added_to_a_stage_leave_its_hash_at_their_defaults(tmp_path, make_cfg):
    """Stage.added (semantics.view_selection, semantics.coverage, semantics.detector.models, a key
    inside a nested section): a root made before the keys existed stays valid at their defaults;
    another value recomputes the stage and what follows."""
    from omegaconf import OmegaConf

    from pipeline.graph import config_hashes

    cfg = make_cfg(tmp_path)
    old = cfg.copy()  # the config as before the keys existed
    sem = OmegaConf.to_container(old.semantics)
    del sem["view_selection"], sem["coverage"], sem["detector"]["models"]
    OmegaConf.set_struct(old, False)
    old._set_value({**{k: old[k] for k in old}, "semantics": OmegaConf.create(sem)})
    h, h_old = config_hashes(cfg), config_hashes(old)
    assert h == h_old
    h_cov = config_hashes(make_cfg(tmp_path, "semantics.view_selection=coverage"))
    changed = {k for k in h if h[k] != h_cov[k]}
    assert "semantics" in changed and "costmap" not in changed and "objectnav_episodes" in changed
    h_det = config_hashes(make_cfg(tmp_path, "semantics.segmenter=detector"))
    h_mix = config_hashes(make_cfg(tmp_path, "semantics.segmenter=detector", "+semantics.detector.models.chair=/m/nanodet.onnx"))
    assert {k for k in h if h_det[k] != h_mix[k]} == changed  # the nested key counts once it is set
    # while another segmenter runs, the detector's settings decide nothing: the oracle's roots stay valid
    assert config_hashes(make_cfg(tmp_path, "+semantics.detector.models.chair=/m/nanodet.onnx")) == h


def test_voxel_opacity_field_is_a_storage_key(tmp_path, make_cfg, costmap_root):
    # 02_voxels/A is kept only with voxelize.store_opacity=true; V (all any later stage reads) is
    # the same, so voxelize alone re-runs and no later stage's hash changes; the default leaves
    # every hash as it was before the key existed
    from omegaconf import OmegaConf

    from pipeline.graph import config_hashes

    cfg = make_cfg(tmp_path, "stages=[costmap]")
    old = cfg.copy()  # the config as before the key existed
    vox = OmegaConf.to_container(old.voxelize)
    del vox["store_opacity"]
    OmegaConf.set_struct(old, False)
    old._set_value({**{k: old[k] for k in old}, "voxelize": OmegaConf.create(vox)})
    assert "store_opacity" not in old.voxelize
    h, h_old = config_hashes(cfg), config_hashes(old)
    h_on = config_hashes(make_cfg(tmp_path, "voxelize.store_opacity=true"))
    assert h == h_old
    assert {k for k in h if h[k] != h_on[k]} == {"voxelize"}
    sid = costmap_root(tmp_path)  # execute(cfg)
    assert set(statuses(execute(cfg)).values()) == {"cached"}  # the copy is the same finished root
    vox = tmp_path / "02_voxels" / f"{sid}.zarr"
    g = zarr.open_group(str(vox), mode="r")
    v_before = np.asarray(g["V"][...])
    assert "A" not in g and "A_scale" not in g.attrs and v_before.any()
    s2 = execute(make_cfg(tmp_path, "stages=[costmap]", "voxelize.store_opacity=true"))
    assert statuses(s2) == {"synthesize": "cached", "ingest": "cached", "voxelize": "done", "align": "cached",
                            "costmap": "cached"}
    g = zarr.open_group(str(vox), mode="r")
    a, tau = np.asarray(g["A"][...]) * g.attrs["A_scale"], g.attrs["tau_occ"]  # V thresholds the exact A
    assert np.array_equal(np.asarray(g["V"][...]), v_before)
    assert not (v_before & (a < tau - 0.5 / 255)).any() and v_before[a > tau + 0.5 / 255].all()


@pytest.mark.parametrize("cross_device", [False, True])
def test_asset_refers_to_a_compressed_original_without_copying_it(tmp_path, real_indoor_dir, monkeypatch,
                                                                  cross_device):
    # a streamed SOG scene is a folder of files: the asset links every one of them under source/
    # (their bytes are the original's, no PLY conversion of ~10x the size); where a hard link cannot
    # be made (another filesystem) a symbolic link refers to it, never a copy
    from navcore.io.datasets import FolderWriter
    from stages.asset.stage import asset_source

    lod = real_indoor_dir / "fungi_room_sog_lod"
    if not (lod / "lod-meta.json").exists():
        pytest.skip(f"real indoor scenes not present at {real_indoor_dir}")
    if cross_device:
        def no_hard_links(src, dst):
            raise OSError(18, "Invalid cross-device link")
        monkeypatch.setattr(os, "link", no_hard_links)
    out = FolderWriter(tmp_path)
    ply, files = asset_source(out, "reference", {"source": str(lod / "lod-meta.json"), "format": "sog"}, None, None)
    originals = sorted(p for p in lod.rglob("*") if p.is_file())
    assert ply is None and files == [f"source/{p.relative_to(lod)}" for p in originals]
    for f, p in zip(files, originals):
        assert (tmp_path / f).samefile(p) and (tmp_path / f).is_symlink() == cross_device
    # a single-file source keeps its name; an INRIA PLY is the V1 source.ply itself
    spz = real_indoor_dir / "wangsha_hall_lod3.spz"
    assert asset_source(out, "reference", {"source": str(spz)}, None, None) == (None, ["source/wangsha_hall_lod3.spz"])
    assert (tmp_path / "source" / "wangsha_hall_lod3.spz").samefile(spz)
    assert asset_source(out, "none", {"source": str(spz)}, None, None) == (None, [])
    with pytest.raises(ValueError, match="asset.source='copy'"):
        asset_source(out, "copy", {"source": str(spz)}, None, None)


def test_compressed_sources_keep_the_aligned_model_as_spz_by_default():
    """asset.aligned_format=auto: SPZ for compressed originals (SPZ, SOG, .splat, SuperSplat's
    PLY: the PLY flavour read from the header), an INRIA PLY otherwise."""
    from navcore.io.asset_files import aligned_file
    from stages.asset.stage import compressed_source

    real = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
    for fmt, src, want in (("spz", "x.spz", True), ("sog", "x/lod-meta.json", True), ("splat", "x.splat", True),
                           ("inria_ply", "x.ply", False), ("npy_folder", "x", False)):
        assert compressed_source({"format": fmt, "source": src}) == want
        assert aligned_file("auto", want) == ("aligned.spz" if want else "aligned.ply")
    if real.is_dir():
        assert compressed_source({"format": "ply", "source": str(real / "supersplat_guitar.compressed.ply")})
        assert not compressed_source({"format": "ply", "source": str(real / "inria_sh0_donut.ply")})
    assert aligned_file("ply", True) == "aligned.ply" and aligned_file("spz", False) == "aligned.spz"


def test_asset_aligned_model_as_spz(tmp_path, make_cfg):
    # asset.aligned_format=spz: the aligned model as a Niantic SPZ v4 (8-bit attributes, 24-bit fixed
    # point positions at 1/4096 m) in place of the V1 PLY, named by the manifest
    from navcore.gaussians.formats import read_gaussians
    from navcore.io.asset_files import aligned_model
    from navcore.io.datasets import AlignedGaussianDataset, GaussianDataset

    s = execute(make_cfg(tmp_path, "stages=[asset]", "asset.aligned_format=spz"))
    sid = next(r["scene_id"] for r in s["results"] if r["stage"] == "asset" and r["status"] == "done")
    asset = next((tmp_path / "09_assets").glob(f"*/{sid}"))
    man = json.loads((asset / "manifest.json").read_text())
    assert man["files"]["aligned"] == "aligned.spz" and man["files"]["aligned_ply"] is None
    assert not (asset / "aligned.ply").exists() and aligned_model(asset) == asset / "aligned.spz"
    aligned, _ = AlignedGaussianDataset(tmp_path / "01_scenes" / sid / "alignment.json",
                                        GaussianDataset(tmp_path / "01_scenes" / sid / "gaussians.zarr")).load()
    spz = read_gaussians(asset / "aligned.spz")
    assert len(spz) == len(aligned) and np.abs(spz.means - aligned.means).max() <= 0.5 / 4096 + 1e-6
    assert np.abs(spz.alphas - aligned.alphas).max() <= 0.5 / 255 + 1e-6
    ply_bytes = len(aligned) * 4 * (11 + 3 * aligned.sh.shape[1])  # INRIA: xyz, normals, SH, opacity, scale, rot
    assert (asset / "aligned.spz").stat().st_size < 0.4 * ply_bytes
    with pytest.raises(ValueError, match="asset.aligned_format='las'"):
        from navcore.io.asset_files import aligned_file
        aligned_file("las")


def render_psnr(a, b, width: int = 160, height: int = 120) -> float:
    """The lowest PSNR (dB) between CPU renders of two scenes from 4 views inside scene a."""
    from benchmarks.gpu.render_gpu import psnr
    from navcore.gaussians.model import render_sh_degree
    from navcore.nav.embodiment import Embodiment
    from navcore.render import cpu_fast
    from navcore.render.camera import embodiment_camera

    c = np.median(a.means, 0)
    poses = np.array([[c[0], c[1], k * np.pi / 2] for k in range(4)])
    vm, K, _, _ = embodiment_camera(Embodiment(), poses, width, height)
    ga, gb = cpu_fast.prepare(a), cpu_fast.prepare(b)
    deg = render_sh_degree(None, ga["sh"].shape[1])
    worst = np.inf
    for i in range(len(vm)):
        x = np.clip(cpu_fast.render_one(ga, vm[i], K[i], width, height, deg)[0], 0, 1)
        y = np.clip(cpu_fast.render_one(gb, vm[i], K[i], width, height, deg)[0], 0, 1)
        worst = min(worst, psnr(x, y))
    return worst


def test_asset_aligned_model_from_the_source_and_its_transform(tmp_path, make_cfg):
    """asset.aligned_format=source: no aligned file; the asset's link to the original, how ingest
    read it and the extrinsic matrix give the pipeline's aligned scene to the bit; a changed
    original is refused by its checksum; habitat export, which names an aligned file, says why not."""
    import shutil

    from navcore.gaussians.errors import SceneFormatError
    from navcore.io.asset_files import aligned_model, load_aligned
    from navcore.io.datasets import AlignedGaussianDataset, GaussianDataset

    s = execute(make_cfg(tmp_path, "stages=[asset]", "asset.aligned_format=source"))
    sid = next(r["scene_id"] for r in s["results"] if r["stage"] == "asset" and r["status"] == "done")
    asset = next((tmp_path / "09_assets").glob(f"*/{sid}"))
    man = json.loads((asset / "manifest.json").read_text())
    assert man["files"]["aligned"] is None and man["aligned_from_source"]["path"] == "source.ply"
    assert not list(asset.glob("aligned.*")) and man["source"]["files"] == ["source.ply"]
    aligned, _ = AlignedGaussianDataset(tmp_path / "01_scenes" / sid / "alignment.json",
                                        GaussianDataset(tmp_path / "01_scenes" / sid / "gaussians.zarr")).load()
    got = load_aligned(asset)
    for k in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        assert np.array_equal(getattr(got, k), getattr(aligned, k)), k
    with pytest.raises(FileNotFoundError, match="aligned_format=source"):
        aligned_model(asset)
    copy = tmp_path / "copy"
    shutil.copytree(asset, copy)
    (copy / "source.ply").unlink()
    data = bytearray((asset / "source.ply").read_bytes())
    data[-8] ^= 0x40  # one float of the last Gaussian
    (copy / "source.ply").write_bytes(bytes(data))
    with pytest.raises(SceneFormatError, match="not the original the asset"):
        load_aligned(copy)
    bad = execute(make_cfg(tmp_path / "b", "stages=[asset]", "asset.aligned_format=source", "asset.source=none"))
    assert "aligned_format=source needs asset.source=reference" in str(bad["failures"])
    habitat = execute(make_cfg(tmp_path, "stages=[export]", "asset.aligned_format=source"))
    assert "habitat" in str(habitat["failures"]) and "keeps none" in str(habitat["failures"])


def test_asset_aligned_spz_renders_as_the_aligned_scene(tmp_path, make_cfg):
    """The stored SPZ's round trip: its CPU renders against the aligned scene's, >= 40 dB."""
    from navcore.io.asset_files import load_aligned
    from navcore.io.datasets import AlignedGaussianDataset, GaussianDataset

    s = execute(make_cfg(tmp_path, "stages=[asset]", "asset.aligned_format=spz"))
    sid = next(r["scene_id"] for r in s["results"] if r["stage"] == "asset" and r["status"] == "done")
    asset = next((tmp_path / "09_assets").glob(f"*/{sid}"))
    aligned, _ = AlignedGaussianDataset(tmp_path / "01_scenes" / sid / "alignment.json",
                                        GaussianDataset(tmp_path / "01_scenes" / sid / "gaussians.zarr")).load()
    assert render_psnr(aligned, load_aligned(asset)) >= 40.0


def test_damaged_outputs_behind_a_marker_are_recomputed(tmp_path, make_cfg, costmap_root):
    """Markers record their outputs' sizes and sha256: a deleted or truncated output recomputes its
    stage (verify=size, a stat per file); a same-size change needs verify=checksum."""
    over = ("stages=[costmap,episodes]", "task=[pointnav]", "task.pointnav.episodes_per_scene=5")
    sid = costmap_root(tmp_path)
    s1 = execute(make_cfg(tmp_path, *over))
    st = statuses(s1)
    assert st["costmap"] == "cached" and st["episodes"] == "done" and not s1["failures"]
    m = json.loads((tmp_path / "_markers" / "costmap" / f"{sid}.json").read_text())
    chunk = next(k for k in m["manifest"] if k.startswith("03_costmaps/") and "/clearance/c/" in k)
    assert m["manifest"][chunk][0] == (tmp_path / chunk).stat().st_size
    before = {k: (tmp_path / k).read_bytes() for k in m["manifest"]}
    (tmp_path / chunk).write_bytes((tmp_path / chunk).read_bytes()[:-7])  # truncated
    ep = next((tmp_path / "05_episodes").rglob("part-0.parquet"))
    raw = bytearray(ep.read_bytes())
    raw[len(raw) // 2] ^= 0xFF  # same size, different bytes
    ep.write_bytes(bytes(raw))
    s2 = execute(make_cfg(tmp_path, *over))
    st = statuses(s2)
    assert st["costmap"] == "done" and st["align"] == "cached" and st["episodes"] == "cached"
    redo = next(r for r in s2["results"] if r["stage"] == "costmap")
    assert chunk in redo["recomputed"] and "bytes" in redo["recomputed"]
    assert {k: (tmp_path / k).read_bytes() for k in m["manifest"]} == before  # recomputed the same bytes
    s3 = execute(make_cfg(tmp_path, *over, "verify=checksum"))
    st = statuses(s3)
    assert st["episodes"] == "done" and st["costmap"] == "cached"
    assert "sha256" in next(r for r in s3["results"] if r["stage"] == "episodes")["recomputed"]
    ep.unlink()  # a deleted output
    s4 = execute(make_cfg(tmp_path, *over))
    assert statuses(s4)["episodes"] == "done" and ep.exists()
    assert "missing" in next(r for r in s4["results"] if r["stage"] == "episodes")["recomputed"]
    assert set(statuses(execute(make_cfg(tmp_path, *over, "verify=checksum"))).values()) == {"cached"}


def test_task_locks_make_a_second_writer_wait_and_die_with_their_holder(tmp_path):
    import signal
    import subprocess
    import sys
    import time

    from pipeline.locks import locked

    lock = tmp_path / "_locks" / "costmap" / "abc.lock"
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time; sys.path.insert(0, %r)\n"
        "from pipeline.locks import locked\n"
        "from pathlib import Path\n"
        "with locked(Path(%r)):\n"
        "    print('held', flush=True); time.sleep(60)") % (str(Path(__file__).parent.parent), str(lock))],
        stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "held"
    assert lock.read_text().split()[1] == str(holder.pid)  # the holder names itself
    t0 = time.perf_counter()
    killer = __import__("threading").Timer(1.0, lambda: holder.send_signal(signal.SIGKILL))
    killer.start()
    with locked(lock) as waited:  # blocks until the kernel releases the killed holder's lock
        assert waited >= 0.9 and time.perf_counter() - t0 < 30
        assert lock.read_text().split()[1] == str(os.getpid())
    holder.wait()


def test_failing_scene_is_recorded_and_others_complete(tmp_path, make_cfg):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nend_header\n")
    cat = tmp_path / "cat.yaml"
    cat.write_text(f"scenes:\n  - {{name: broken, group: test, path: {bad}, format: inria_ply}}\n"
                   f"  - {{name: gone, group: test, path: {tmp_path / 'gone.ply'}}}\n"
                   "synthetic: {prefix: s, group: synthetic, count: 1, first_seed: 3, num_gaussians: 60000}\n")
    cfg = make_cfg(tmp_path / "d", f"scenes.catalog={cat}", "scenes.count=null", "stages=[align]")
    s = execute(cfg)
    by_scene = {}
    for r in s["results"]:
        by_scene.setdefault(r["scene"], {})[r["stage"]] = r
    gone = by_scene["gone"]["ingest"]
    assert gone["status"] == "failed" and "file not found" in gone["error"] and "gone.ply" in gone["error"]
    assert gone["error"].startswith("SceneFileNotFoundError: scene ")
    # a run with a failed task exits non-zero unless failures are allowed
    from pipeline.executor import main_cfg

    assert main_cfg(cfg) == 1
    cfg.allow_failures = True
    assert main_cfg(cfg) == 0
    assert by_scene["broken"]["ingest"]["status"] == "failed"
    assert "bad.ply" in by_scene["broken"]["ingest"]["error"] and "declares 1,000" in by_scene["broken"]["ingest"]["error"]
    assert by_scene["broken"]["align"]["status"] == "skipped"
    assert by_scene["s_0003"]["align"]["status"] == "done"
    assert not (tmp_path / "d" / "_markers" / "ingest" / f"{by_scene['broken']['ingest']['scene_id']}.json").exists()


def test_changed_settings_of_a_stage_the_run_does_not_name_are_refused(tmp_path, make_cfg, costmap_root):
    """stages=[screen] with another costmap resolution would overwrite the costmaps made before:
    refused (nothing touched) with the keys that differ and how to keep or recompute; naming the
    stage recomputes, and the run summary says what changed."""
    from pipeline.executor import UnknownKeysError, main_cfg

    sid = costmap_root(tmp_path)  # execute(make_cfg(tmp_path, "stages=[costmap]"))
    marker = tmp_path / "_markers" / "costmap" / f"{sid}.json"
    before = marker.read_bytes()
    assert json.loads(before)["config"]["costmap"]["resolution"] == 0.05  # markers record their settings
    refused = execute(make_cfg(tmp_path, "stages=[screen]", "costmap.resolution=0.1"))
    assert refused["failures"] and not refused["results"] and marker.read_bytes() == before
    assert "costmap (1 scene(s)): costmap.resolution: 0.05 -> 0.1" in refused["refused"]
    assert "costmap.resolution=0.05" in refused["refused"] and "force=true" in refused["refused"]
    assert main_cfg(make_cfg(tmp_path, "stages=[screen]", "costmap.resolution=0.1")) == 1
    s2 = execute(make_cfg(tmp_path, "stages=[costmap,screen]", "costmap.resolution=0.1"))
    assert statuses(s2)["costmap"] == "done" and not s2["failures"]
    assert s2["config_changes"]["costmap"]["keys"] == [["costmap.resolution", "0.05", "0.1"]]
    assert "costmap" not in s2["config_changes"] or s2["config_changes"]["costmap"]["scenes"] == [sid]
    # a misspelt key added with `+` is refused with the closest key
    with pytest.raises(UnknownKeysError, match=r"evaluate.agnet \(did you mean evaluate.agent\?\)"):
        execute(make_cfg(tmp_path, "+evaluate.agnet=oracle"))
    assert main_cfg(make_cfg(tmp_path, "+evaluate.agnet=oracle")) == 2


def test_a_plain_misspelt_key_gets_the_friendly_refusal(capsys):
    """`navarena run costmap.resolutoin=0.02` (no `+`): the closest key and exit 2, before Hydra."""
    from pipeline.__main__ import main
    from pipeline.config import unknown_override_keys

    assert unknown_override_keys(["costmap.resolutoin=0.02", "scenes=real_indoor", "hydra.run.dir=x",
                                  "task.pointnav.episodes_per_scene=3", "+x.y=1", "--cfg", "job"]) == \
        ["costmap.resolutoin (did you mean costmap.resolution?)"]
    assert unknown_override_keys(["costmap.resolution=0.02", "stages=[costmap]", "data_root=d"]) == []
    with pytest.raises(SystemExit) as e:
        main(["costmap.resolutoin=0.02", "stages=[costmap]"])
    assert e.value.code == 2
    err = capsys.readouterr().err.replace("\n", " ")
    assert "did you mean" in err and "costmap.resolution?" in err and "Traceback" not in err


def test_same_config_same_bytes_whatever_the_workers(tmp_path, make_cfg, costmap_root):
    """Sync and a 2-process Dask LocalCluster produce byte-identical stores."""
    costmap_root(tmp_path / "a")  # execute(make_cfg(tmp_path / "a", "stages=[costmap]")), sync
    execute(make_cfg(tmp_path / "b", "stages=[costmap]", "executor=local", "executor.n_workers=2",
                     "executor.dashboard=false"))
    files_a = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a" / "03_costmaps").rglob("*") if p.is_file())
    assert files_a
    for rel in files_a + sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a" / "02_voxels").rglob("*")
                                if p.is_file()):
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes(), rel


def test_shards_are_disjoint_and_cover(tmp_path, project_root):
    from navcore.io.catalog import Catalog

    cat = Catalog(project_root / "catalogs" / "synthetic_large.yaml", tmp_path)
    shards = [cat.select(k, 3) for k in range(3)]
    ids = [s.scene_id for sh in shards for s in sh]
    assert len(ids) == len(set(ids)) == len(cat.scenes)


def test_several_embodiments_and_existing_scheduler(tmp_path, make_cfg):
    """costmap.embodiments adds maps per scene; executor.address runs on a given scheduler."""
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=1, processes=False, dashboard_address=None) as cluster:
        s = execute(make_cfg(tmp_path, "stages=[costmap]", "costmap.embodiments=[stretch,navarena_default]",
                             "costmap.resolution=0.1", f"executor.address={cluster.scheduler_address}"))
    assert not s["failures"]
    sid = s["results"][0]["scene_id"]
    g = zarr.open_group(str(tmp_path / "03_costmaps" / f"{sid}.zarr"))
    assert sorted(g.group_keys()) == ["locobot", "navarena_default", "stretch"]
    free = {k: (~np.asarray(g[k]["occ"][...])).sum() for k in g.group_keys()}
    # a bigger body has less free space; all maps share one grid
    assert free["locobot"] > free["stretch"] > free["navarena_default"] > 0
    assert len({g[k]["occ"].shape for k in g.group_keys()}) == 1


def test_batch_submission_scripts(project_root, make_cfg):
    """The sharded array job and the dask-jobqueue worker jobs carry what the config says."""
    from pipeline.submit import array_script

    s = array_script("slurm", 16, ["scenes=synthetic_large", "costmap.resolution=0.02"], 8, "32G", "02:00:00",
                     "cpu", None, "/venv/bin/python", project_root)
    assert "#SBATCH --array=0-15" in s and "#SBATCH --partition=cpu" in s
    assert "scenes.shard=$SLURM_ARRAY_TASK_ID scenes.num_shards=16" in s and s.rstrip().endswith(
        "scenes=synthetic_large costmap.resolution=0.02")
    r = array_script("slurm", 2, [], 1, "4G", "00:01:00", None, None, "python", project_root, requeue_before=30,
                     max_requeues=3)  # a task near its time limit requeues itself
    assert "#SBATCH --signal=B:USR1@30" in r and "#SBATCH --requeue" in r and "trap requeue USR1" in r
    assert 'scontrol requeue "$task"' in r and "-lt 3 ]" in r and "#SBATCH --array=0-1\n" in r
    assert "#SBATCH --array=0-1%1" in array_script("slurm", 2, [], 1, "4G", "1:00:00", None, None, "python", project_root,
                                                   max_running=1)
    import subprocess

    assert subprocess.run(["bash", "-n"], input=r, text=True).returncode == 0  # valid bash
    p = array_script("pbs", 4, [], 4, "16gb", "01:00:00", None, "acct", "python", project_root)
    assert "#PBS -J 0-3" in p and "$PBS_ARRAY_INDEX" in p and "#PBS -A acct" in p
    pytest.importorskip("dask_jobqueue")
    from pipeline.backends import jobqueue_cluster

    def job_script(*overrides):
        cluster, placement = jobqueue_cluster(make_cfg("/tmp/unused", "executor=slurm", *overrides).executor)
        try:
            return cluster.job_script(), placement
        finally:
            cluster.close()

    js, placement = job_script("executor.jobqueue.cores=16", "executor.jobqueue.queue=gpu",
                               "executor.jobqueue.job_extra_directives=['--constraint=skylake']")
    assert "#SBATCH -p gpu" in js and "--constraint=skylake" in js and "#SBATCH --cpus-per-task=16" in js
    assert placement.gpu_workers == 0 and "--resources MEMORY=16.000" in js  # 32 GB over 2 processes
    # GPU jobs: the GPUs requested, one worker process per GPU, each advertising one
    js, placement = job_script("executor.jobqueue.gpus_per_job=4")
    assert "#SBATCH --gres=gpu:4" in js and "--nworkers 4" in js and "GPU=1,CPU=1,MEMORY=8.000" in js
    assert placement.gpu_workers and placement.worker_memory_gb == 8.0


def test_gpu_stages_go_to_gpu_workers_only(tmp_path, make_cfg):
    """Two (pretend) GPUs on a CPU machine: each GPU worker sees only its own GPU, the stages that
    declare a GPU run on those workers only, one at a time per GPU, and the others on the CPU
    workers, which see no GPU."""
    from pipeline.executor import execute
    from pipeline.graph import BY_NAME

    cfg = make_cfg(tmp_path / "data", "executor.kind=local", "executor.gpus=2", "executor.n_workers=1",
                   "executor.dashboard=false", "stages=[voxelize,align,costmap]", "scenes.count=2")
    summary = execute(cfg)
    done = [r for r in summary["results"] if r["status"] in ("done", "n/a")]
    assert not summary["failures"] and {r["stage"] for r in done} >= {"voxelize", "costmap"}
    for r in done:
        if BY_NAME[r["stage"]].gpu:
            assert r["worker"] == f"gpu-{r['gpu']}" and r["gpu"] in ("0", "1")
        else:
            assert r["worker"] == "cpu-0" and "gpu" not in r
    placed = summary["placement"]
    gpu_done = [r for r in done if r["status"] == "done" and BY_NAME[r["stage"]].gpu]
    assert placed["gpu_tasks"] == len(gpu_done) and not placed["misplaced"]
    assert {w: v["tasks"] for w, v in placed["workers"].items() if v["gpu"]} == {
        f"gpu-{g}": {"voxelize": sum(r["gpu"] == g for r in gpu_done)} for g in {r["gpu"] for r in gpu_done}}


def test_placement_report_known_answer():
    """The summary's placement section: CUDA work on a GPU other than the pinned one is reported,
    and the seconds GPU and CPU stages ran side by side are the intervals' intersection."""
    from pipeline.summary import placement

    def r(stage, worker, t0, t1, **gpu):
        return {"stage": stage, "scene_id": "s", "status": "done", "worker": worker, "started": t0, "finished": t1, **gpu}

    ok = {"gpu": "0", "gpu_pinned_uuid": "aa", "cuda_device": 0, "gpu_uuid": "aa"}
    results = [r("voxelize", "gpu-0", 0.0, 4.0, **ok), r("semantics", "gpu-0", 6.0, 10.0, **ok),
               r("semantics", "gpu-1", 1.0, 2.0, gpu="1", gpu_pinned_uuid="bb", cuda_device=0, gpu_uuid="aa"),
               r("costmap", "cpu-0", 3.0, 7.0), r("costmap", "cpu-1", 9.0, 12.0),
               {"stage": "align", "scene_id": "s", "status": "cached"}]
    p = placement(results)
    assert [m["worker"] for m in p["misplaced"]] == ["gpu-1"]
    # GPU busy [0, 4] + [6, 10]; CPU [3, 7] + [9, 12]: both at [3, 4], [6, 7], [9, 10]
    assert p["gpu_busy_s"] == 8.0 and p["cpu_busy_s"] == 7.0 and p["cpu_gpu_overlap_s"] == 3.0
    assert p["workers"]["gpu-0"] == {"gpu": "0", "pinned_uuid": "aa", "cuda_uuids": ["aa"],
                                     "tasks": {"voxelize": 1, "semantics": 1}, "busy_s": 8.0}
    assert p["gpu_tasks"] == 3 and p["gpu_tasks_with_cuda"] == 3
    assert placement([results[-1]]) is None


@pytest.mark.parametrize("cmd", [["-m", "pipeline"], None])
def test_cli_composes_the_config(cmd, tmp_path):
    """Both entry points compose conf/ (with overrides) from any working directory."""
    import shutil
    import subprocess
    import sys

    if cmd is None:
        exe = shutil.which("navarena", path=str(Path(sys.executable).parent))
        if exe is None:
            pytest.skip("navarena console script not installed (pip install -e .)")
        argv = [exe]
    else:
        argv = [sys.executable, *cmd]
    out = subprocess.run(argv + ["--cfg", "job", "embodiment=stretch", "costmap.resolution=0.02"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "name: stretch" in out.stdout and "resolution: 0.02" in out.stdout


def test_interrupted_write_leaves_nothing_trusted(tmp_path, monkeypatch, make_cfg):
    """A stage dying mid-write leaves neither output nor marker; the rerun recomputes it."""
    from navcore.io.atomic import atomic_path

    final = tmp_path / "out.zarr"
    with pytest.raises(RuntimeError):
        with atomic_path(final) as tmp:
            tmp.mkdir()
            (tmp / "half").write_text("partial")
            raise RuntimeError("killed")
    assert not final.exists() and not any(tmp_path.iterdir())  # no stray temporary either

    # a SIGKILLed writer cannot clean up: its temporary goes at the next write of that output
    # (on this host, once its process is gone); a live writer's temporary is left alone
    import subprocess

    from navcore.io.atomic import HOST

    dead = subprocess.Popen(["true"])
    dead.wait()
    stale = tmp_path / f".tmp-out.zarr-{HOST}-{dead.pid}-x1"
    live = tmp_path / f".tmp-out.zarr-{HOST}-{os.getpid()}-x2"
    for p in (stale, live):
        (p / "out.zarr").mkdir(parents=True)
    with atomic_path(final) as tmp:
        tmp.write_text("whole")
    assert final.read_text() == "whole" and not stale.exists() and live.exists()
    # ... or at the end of the next run that does any work, wherever it lies (a final name with '-')
    from navcore.io.atomic import sweep_stale_temporaries

    deep = tmp_path / "05_episodes" / "task=pointnav"
    stale2 = deep / f".tmp-part-0.parquet-{HOST}-{dead.pid}-ab_c"
    old_dir = deep / f".old-costmaps.zarr-{dead.pid}"
    for p in (stale2 / "part-0.parquet", old_dir / "x"):
        p.parent.mkdir(parents=True)
        p.write_text("partial")
    assert set(sweep_stale_temporaries(tmp_path)) == {stale2, old_dir} and live.exists()

    cfg = make_cfg(tmp_path / "d", "stages=[voxelize]")
    execute(cfg)
    import dataclasses

    from pipeline import graph

    def crashing_run(scene, cfg_, catalog):
        with catalog.dataset("voxels", scene).writing() as g:
            g.create_array("A", shape=(2,), dtype="f4")
            raise MemoryError("worker killed while writing")
    monkeypatch.setitem(graph.BY_NAME, "voxelize", dataclasses.replace(graph.BY_NAME["voxelize"], run=crashing_run))
    s = execute(make_cfg(tmp_path / "d", "stages=[voxelize]", "force=true"))
    r = {x["stage"]: x for x in s["results"]}
    assert r["voxelize"]["status"] == "failed" and "MemoryError" in r["voxelize"]["error"]
    sid = r["voxelize"]["scene_id"]
    assert not (tmp_path / "d" / "_markers" / "voxelize" / f"{sid}.json").exists()
    # the previous complete output is still in place, untouched by the failed attempt
    assert "V" in zarr.open_group(str(tmp_path / "d" / "02_voxels" / f"{sid}.zarr")).array_keys()
    monkeypatch.undo()
    assert {x["stage"]: x["status"] for x in execute(make_cfg(tmp_path / "d", "stages=[voxelize]"))["results"]}[
        "voxelize"] == "done"


def test_stored_costmap_loads_into_the_same_queries(tmp_path, costmap_root):

    sid = costmap_root(tmp_path)
    path = tmp_path / "03_costmaps" / f"{sid}.zarr"
    cm = CostmapDataset(path).load("locobot")
    g = zarr.open_group(str(path))["locobot"]
    occ = np.asarray(g["occ"][...])
    assert np.array_equal(cm.occupancy | ~np.asarray(g["support"][...]), occ)
    free = np.argwhere(~occ)
    xy = cm.cell_centers(free[:: max(1, len(free) // 500)])
    assert cm.are_states_valid(xy).all()  # every free cell centre is a valid pose
    assert (cm.component_at(xy) > 0).all()


def test_catalog_paths_ids_and_layout(tmp_path, project_root):
    from navcore.io.catalog import Catalog, scene_id_for

    (tmp_path / "cats").mkdir()
    cat = tmp_path / "cats" / "mine.yaml"
    cat.write_text("layout:\n  costmaps: '{root}/maps/{group}/{scene_id}.zarr'\n"
                   "scenes:\n  - {name: a, group: g, path: scenes/a.ply, format: inria_ply}\n"
                   "  - {name: b, group: g, path: /abs/b.splat, format: splat}\n")
    c = Catalog(cat, tmp_path / "data")
    a, b = sorted(c.scenes, key=lambda s: s.name)
    assert a.path == str(tmp_path / "cats" / "scenes" / "a.ply") and b.path == "/abs/b.splat"
    import hashlib

    assert a.scene_id == hashlib.sha256(b"g:a").hexdigest()[:8] == scene_id_for("g", "a")
    assert c.path("costmaps", a) == tmp_path / "data" / "maps" / "g" / f"{a.scene_id}.zarr"
    assert c.path("markers", a, stage="align") == tmp_path / "data" / "_markers" / "align" / f"{a.scene_id}.json"
    real = Catalog(project_root / "catalogs" / "real_samples.yaml", tmp_path)
    assert all(Path(s.path).parent == (project_root.parent / "shared" / "data" / "real").resolve() for s in real.scenes)


def test_a_catalog_cannot_steer_writes_outside_the_data_root(tmp_path):
    from navcore.io.catalog import Catalog

    def cat(text):
        f = tmp_path / "c.yaml"
        f.write_text(text)
        return f

    for bad in ("{name: a, group: ../../etc, path: a.ply, format: inria_ply}",
                "{name: a, group: g, id: ../x, path: a.ply, format: inria_ply}",
                "{name: a, group: /abs, path: a.ply, format: inria_ply}"):
        with pytest.raises(ValueError, match="not a plain name"):
            Catalog(cat(f"scenes:\n  - {bad}\n"), tmp_path / "data")
    c = Catalog(cat("layout:\n  costmaps: '/tmp/elsewhere/{scene_id}.zarr'\n  voxels: '{root}/../up/{scene_id}.zarr'\n"
                    "scenes:\n  - {name: a, group: g, path: a.ply, format: inria_ply}\n"), tmp_path / "data")
    for ds in ("costmaps", "voxels"):
        with pytest.raises(ValueError, match="outside the data root"):
            c.path(ds, c.scenes[0])
    with pytest.raises(ValueError, match="not a plain name"):  # a field from the config, e.g. an eval run name
        c.path("eval_summary", run="../../home")
    assert c.path("markers", c.scenes[0], stage="align").is_relative_to(tmp_path / "data")


def test_catalog_datasets_round_trip_atomically_and_find_partitions(tmp_path, project_root):
    import pyarrow as pa

    from navcore.gaussians import GaussianScene
    from navcore.io.catalog import Catalog
    from navcore.io.datasets import GaussianDataset, JSONDataset, ParquetDataset

    cat = Catalog(project_root / "catalogs" / "synthetic.yaml", tmp_path)
    scene = cat.scenes[0]
    rep = cat.dataset("ingest_report", scene)
    assert isinstance(rep, JSONDataset) and rep.path == tmp_path / "01_scenes" / scene.scene_id / "ingest.json"
    rep.save({"a": [1, 2.5, None]})
    assert rep.load() == {"a": [1, 2.5, None]}
    # a failed save leaves the previous content and no temporary behind
    with pytest.raises(TypeError):
        rep.save({"a": object()})
    assert rep.load() == {"a": [1, 2.5, None]}
    assert sorted(p.name for p in rep.path.parent.iterdir()) == ["ingest.json"]
    tables = {}
    for task in ("pointnav", "objectnav"):
        ds = cat.dataset("episodes", scene, task=task)
        assert isinstance(ds, ParquetDataset)
        tables[task] = pa.table({"episode_id": [f"{task}-0", f"{task}-1"], "x": [0.5, 1.5]})
        ds.save(tables[task])
    found = cat.find("episodes", scene)
    assert list(found) == ["objectnav", "pointnav"]
    assert all(found[t].load().equals(tables[t]) for t in found)
    found["objectnav"].delete()
    assert list(cat.find("episodes", scene)) == ["pointnav"]
    # another process's atomic write in progress (a shard exporting while a dataset-level step lists the
    # folder: the concurrent fault scenario, 2026-12-07) and the copy it swaps out are no datasets yet;
    # a template whose free field is a whole path component is where atomic_path's siblings can match
    export = cat.dataset("export_scene", scene, export_name="d").path
    export.mkdir(parents=True)
    for temp in (f".tmp-{scene.scene_id}-host-1-x", f".old-{scene.scene_id}-123"):
        (export.parent / temp).mkdir()
    assert list(cat.find("export_scene", export_name="d")) == [f"{scene.group}/{scene.scene_id}"]
    g = cat.dataset("scene", scene)
    assert isinstance(g, GaussianDataset)
    rng = np.random.default_rng(0)
    q = rng.normal(size=(50, 4))
    gs = GaussianScene.from_colors(rng.normal(size=(50, 3)), q / np.linalg.norm(q, axis=1, keepdims=True),
                                   rng.uniform(0.01, 0.1, (50, 3)), rng.uniform(0.1, 0.9, 50), rng.uniform(size=(50, 3)))
    g.save(gs, {"scene_id": scene.scene_id})
    back, attrs = g.load()
    assert np.array_equal(back.means, gs.means) and np.array_equal(back.sh, gs.sh) and attrs["n_gaussians"] == 50
    with pytest.raises(KeyError, match="needs the field 'task'"):
        cat.dataset("episodes", scene)
    with pytest.raises(KeyError, match="folder of datasets"):
        cat.dataset("episodes_root")


def test_compare_data_normalises_roots_and_reports_every_difference(tmp_path):
    from benchmarks.dataset.compare_data import compare

    for root in ("a", "b"):
        d = tmp_path / root / "01_scenes" / "s"
        d.mkdir(parents=True)
        (d / "ingest.json").write_text(json.dumps({"source": str(tmp_path / root / "00_sources" / "x.ply")}))
        (tmp_path / root / "_markers").mkdir()
        (tmp_path / root / "_markers" / f"{root}.json").write_text(root)  # bookkeeping: ignored
    assert compare(tmp_path / "a", tmp_path / "b") == {"files": [1, 1], "only_first": [], "only_second": [],
                                                        "differing": []}
    (tmp_path / "b" / "01_scenes" / "s" / "ingest.json").write_text("{}")
    (tmp_path / "b" / "extra.bin").write_bytes(b"\0")
    rep = compare(tmp_path / "a", tmp_path / "b")
    assert rep["differing"] == ["01_scenes/s/ingest.json"] and rep["only_second"] == ["extra.bin"]


def test_every_progress_log_and_underscore_folder_of_the_layout_is_bookkeeping_the_byte_comparison_skips():
    """Progress logs hold the writer's pid and a rerun rewrites them: they live in a bookkeeping folder
    ({root}/_progress) beside _markers, never inside a stage's outputs, where they broke the fault suite's
    byte-for-byte comparison of a disturbed run with an undisturbed one."""
    import yaml

    from benchmarks.dataset.compare_data import BOOKKEEPING
    from navcore.io.catalog import LAYOUT_FILE

    layout = yaml.safe_load(LAYOUT_FILE.read_text())
    paths = {k: (v["path"] if isinstance(v, dict) else v) for k, v in layout.items()}
    top = {k: p.split("/")[1] for k, p in paths.items()}
    progress = [k for k in paths if k.endswith("_progress")]
    assert progress and all(top[k] in BOOKKEEPING for k in progress), {k: paths[k] for k in progress}
    assert all(t in BOOKKEEPING for t in top.values() if t.startswith("_")), top
    assert not [p for k, p in paths.items() if top[k] not in BOOKKEEPING and "/_" in p], "a bookkeeping folder inside outputs"


def test_storage_measure_counts_a_hard_link_to_the_source_once_and_names_stale_ones(tmp_path):
    import os

    from benchmarks.dataset.storage import measure

    src = tmp_path / "src.ply"
    src.write_bytes(b"x" * 1000)
    scene = tmp_path / "d" / "01_scenes" / "s1"
    scene.mkdir(parents=True)
    (scene / "ingest.json").write_text(json.dumps({"scene_id": "s1", "group": "g", "source": str(src)}))
    asset = tmp_path / "d" / "09_assets" / "g" / "s1"
    asset.mkdir(parents=True)
    os.link(src, asset / "source.ply")  # the original, linked
    (asset / "aligned.ply").write_bytes(b"y" * 500)
    s = measure(tmp_path / "d")["scenes"][0]
    assert s["source_bytes"] == 1000 and s["unlinked_source_files"] == []
    assert s["store_and_asset_bytes"] == 500 + (scene / "ingest.json").stat().st_size
    # the original replaced by a new file (re-downloaded): the link now holds the old copy
    src.unlink()
    src.write_bytes(b"x" * 1000)
    s = measure(tmp_path / "d")["scenes"][0]
    assert s["unlinked_source_files"] == ["source.ply"]
    assert s["store_and_asset_bytes"] == 1500 + (scene / "ingest.json").stat().st_size


def test_storage_measure_of_a_scene_set_leaves_out_the_other_scenes_of_the_root(tmp_path):
    """A data root holding the default scenes and a scene another catalog put there: measured for the
    default set, neither the other scene's store nor its episode rows count."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from benchmarks.dataset.storage import measure

    root = tmp_path / "d"
    for sid, size, rows in (("s1", 1000, 3), ("other", 9000, 5)):
        src = tmp_path / f"{sid}.ply"
        src.write_bytes(b"x" * size)
        (root / "01_scenes" / sid).mkdir(parents=True)
        (root / "01_scenes" / sid / "ingest.json").write_text(json.dumps({"scene_id": sid, "group": "g", "source": str(src)}))
        (root / "09_assets" / "g" / sid).mkdir(parents=True)
        (root / "09_assets" / "g" / sid / "aligned.ply").write_bytes(b"y" * size)
        for top in ("05_episodes", "06_trajectories"):
            d = root / top / "task=pointnav" / f"scene_id={sid}"
            d.mkdir(parents=True)
            pq.write_table(pa.table({"episode_id": list(range(rows))}), d / "part-0.parquet")
    every, one = measure(root), measure(root, {"s1"})
    assert [s["scene_id"] for s in every["scenes"]] == ["other", "s1"] and every["episodes"] == 8
    assert [s["scene_id"] for s in one["scenes"]] == ["s1"] and one["episodes"] == 3
    own = sum(f.stat().st_size for top in ("05_episodes", "06_trajectories")
              for f in (root / top / "task=pointnav" / "scene_id=s1").iterdir())
    assert one["bytes_per_episode"] == pytest.approx(own / 3)


def test_gpu_job_workers_are_pinned_to_their_own_gpu(monkeypatch):
    """Worker k of a GPU batch job (dask names it <job>-k) keeps only the job's k-th GPU."""
    from types import SimpleNamespace

    from pipeline.backends import PinGPU

    for name, want in [("SLURMCluster-3-0", "4"), ("SLURMCluster-3-1", "6"), ("SLURMCluster-3-2", "4")]:
        monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "4,6")
        PinGPU().setup(SimpleNamespace(name=name))
        assert os.environ["CUDA_VISIBLE_DEVICES"] == want


def test_tasks_refer_to_one_config_that_outlives_workers(tmp_path, make_cfg, monkeypatch):
    """The config and the catalog travel to the cluster once, as a worker plugin (restarted
    workers get it too); each task carries the run's id, not a pickled copy (20,000 tasks by
    value took the client to 13 GB in the scale simulation)."""
    from dask.distributed import Client

    from pipeline.backends import RunContext

    seen, plugins = [], []
    submit, register = Client.submit, Client.register_plugin

    def spy(self, fn, *args, **kw):
        seen.append(args)
        return submit(self, fn, *args, **kw)

    def spy_plugin(self, plugin, *a, **kw):
        plugins.append(plugin)
        return register(self, plugin, *a, **kw)
    monkeypatch.setattr(Client, "submit", spy)
    monkeypatch.setattr(Client, "register_plugin", spy_plugin)
    cfg = make_cfg(tmp_path / "d", "executor.kind=local", "executor.n_workers=1", "executor.dashboard=false",
                   "executor.processes=false", "stages=[ingest]", "scenes.count=2")
    s = execute(cfg)
    assert not s["failures"] and len(seen) == 4  # synthesize + ingest for 2 scenes
    assert len(plugins) == 1 and isinstance(plugins[0], RunContext)
    assert all(a[2] == plugins[0].run_id and isinstance(a[2], str) for a in seen)  # the run's id, not the config


def test_screening_through_the_pipeline_and_screen_reject(tmp_path, make_cfg):
    """A generated scene with injected blurred and hole regions: the screen stage writes its layer
    and picture, the run summary has the scene's score (alone, the verdict once the episodes
    stage has run: one row a scene), the stored episodes keep out
    of the layer grown by the margin; screen.reject with the scene's verdict reject empties its
    shards and recomputes the episodes only (the layer's config is screen.layer)."""
    import pyarrow.parquet as pq

    from navcore.nav.screening import grow

    over = ["stages=[episodes]", "task=[pointnav,imagenav]", "task.pointnav.episodes_per_scene=12",
            "task.imagenav.episodes_per_scene=6", "synthetic.realism.level=moderate",
            "synthetic.realism.blur_regions=2", "synthetic.realism.hole_regions=2"]
    s0 = execute(make_cfg(tmp_path, *over[1:], "stages=[screen]"))  # the layer alone: its score, no verdict yet
    (first,) = s0["screening"]
    assert first["verdict"] is None and first["kept"] is None and 0 < first["score"] < 1
    s1 = execute(make_cfg(tmp_path, *over))
    assert not s1["failures"], s1["failures"]
    sid = s1["results"][0]["scene_id"]
    (entry,) = s1["screening"]  # one row a scene: the episodes stage's
    assert entry["scene_id"] == sid and entry["verdict"] in ("pass", "warn", "reject") and entry["kept"]
    assert entry["score"] == first["score"] and statuses(s1)["screen"] == "cached"
    layer = zarr.open_group(str(tmp_path / "03_costmaps" / "screen" / f"{sid}.zarr"), mode="r")
    flagged = np.asarray(layer["flagged"][...])
    assert 0 < entry["score"] < 1 and abs(entry["score"] - layer.attrs["score"]) < 1e-12 and flagged.any()
    assert (tmp_path / "03_costmaps" / "screen" / f"{sid}.png").is_file()
    res = layer.attrs["resolution"]
    keep_out = grow(flagged, 0.1, res)  # screen.margin_m's default
    origin = np.asarray(layer.attrs["origin"])
    rows = 0
    for task in ("pointnav", "imagenav"):
        t = pq.read_table(tmp_path / "06_trajectories" / f"task={task}" / f"scene_id={sid}" / "part-0.parquet")
        xy = np.c_[t["position_x"].to_numpy(), t["position_y"].to_numpy()]
        ij = np.floor((xy - origin) / res).astype(int)
        assert not keep_out[ij[:, 1], ij[:, 0]].any(), task
        rows += len(xy)
    assert rows > 0
    info = json.loads((tmp_path / "_markers" / "episodes" / f"{sid}.json").read_text())["info"]
    rejections = {k for t in info["tasks"].values() for k in t["rejections"]}
    assert rejections & {"goal_screened", "path_screened"}, rejections
    s2 = execute(make_cfg(tmp_path, *over, "screen.reject=true", "screen.warn_below=1.0", "screen.reject_below=1.0"))
    st = statuses(s2)
    assert st["screen"] == "cached" and st["episodes"] == "done"
    (entry,) = s2["screening"]
    assert entry["verdict"] == "reject" and not entry["kept"]
    for task in ("pointnav", "imagenav"):
        assert pq.read_table(tmp_path / "05_episodes" / f"task={task}" / f"scene_id={sid}" / "part-0.parquet").num_rows == 0


def test_map_pictures_carry_a_scale_bar_of_the_right_length():
    from navcore.io.map_picture import annotated

    img = np.full((100, 200, 3), 255, np.uint8)  # 10 m x 5 m at 0.05 m
    pic = annotated(img, 0.05, [((255, 0, 0), "red")])
    k = 3  # 480 / 200 rounded up
    assert pic.shape[1] == 600 and pic.shape[0] > 300
    bar_row = pic[300 - 14 + 2]  # the bar: 4 px high, 14 px above the map's bottom edge
    black = np.flatnonzero((bar_row == 0).all(-1))
    assert len(black) == 2 / 0.05 * k + 1  # 2 m: the longest step within a quarter of 10 m
    assert ((pic[300:] == (255, 0, 0)).all(-1)).sum() > 50  # the legend's swatch


def test_an_older_runs_task_never_overwrites_a_newer_runs_output(tmp_path, make_cfg):
    """The write fence: a task of a run that started before the one whose marker it finds (an orphan
    of a killed client, still running on an external cluster) is superseded, not run."""
    from navcore.io.catalog import open_catalog
    from pipeline.graph import config_hashes, scene_hash
    from pipeline.tasks import new_run, run_task

    older = new_run()
    cfg = make_cfg(tmp_path, "stages=[align]")
    execute(cfg)  # the newer run
    marker = next((tmp_path / "_markers" / "align").glob("*.json"))
    before = marker.read_bytes()
    cat, (scene,), _ = open_catalog(cfg)
    stale = make_cfg(tmp_path, "stages=[align]", "align.max_gaussians=300000")  # the orphan's other settings
    h = scene_hash(config_hashes(stale)["align"], "align", scene)
    r = run_task("align", scene, stale, cat, h, False, run=older)
    assert r["status"] == "skipped" and "superseded" in r["error"] and marker.read_bytes() == before
    assert json.loads(before)["run"]["started_ns"] > older["started_ns"]
    r = run_task("align", scene, stale, cat, h, False, run=new_run())  # a newer run recomputes
    assert r["status"] == "done" and json.loads(marker.read_text())["config_hash"] == h


def test_ctrl_c_keeps_the_finished_work_and_summarises_it(tmp_path, make_cfg, monkeypatch):
    """Ctrl-C mid-run: the finished (stage, scene) tasks are kept and summarised, exit 130, and the
    same command goes on from there."""
    import json

    import pipeline.executor as ex

    real, calls = ex.run_task, []

    def interrupted_at(n):
        def run(*a, **k):
            calls.append(a[0])
            if len(calls) == n:
                raise KeyboardInterrupt
            return real(*a, **k)
        return run

    monkeypatch.setattr(ex, "run_task", interrupted_at(2))
    s = ex.execute(make_cfg(tmp_path, "stages=[ingest]"))
    assert s["interrupted"] and [r["stage"] for r in s["results"]] == ["synthesize"]
    assert s["results"][0]["status"] == "done"
    assert json.loads((tmp_path / "_runs" / "latest.json").read_text())["interrupted"] is True
    calls.clear()
    monkeypatch.setattr(ex, "run_task", interrupted_at(1))
    assert ex.main_cfg(make_cfg(tmp_path, "stages=[ingest]")) == 130
    monkeypatch.setattr(ex, "run_task", real)
    again = ex.execute(make_cfg(tmp_path, "stages=[ingest]"))
    assert not again["interrupted"] and {r["stage"]: r["status"] for r in again["results"]} == \
        {"synthesize": "cached", "ingest": "done"}


def test_missing_sources_are_named_before_any_worker_starts(tmp_path, make_cfg, monkeypatch, capsys):
    import pipeline.executor as ex

    cat = tmp_path / "cat.yaml"
    cat.write_text("scenes:\n  - {name: gone, path: /nonexistent/scene.ply, format: inria_ply}\n"
                   "  - {name: also_gone, path: missing.splat, format: splat}\n")
    monkeypatch.setattr(ex, "run_on_dask", lambda *a, **k: pytest.fail("workers started for no scene"))
    s = ex.execute(make_cfg(tmp_path, f"scenes.catalog={cat}", "executor=local", "stages=[ingest]"))
    failed = {r["scene"]: r for r in s["results"] if r["status"] == "failed"}
    assert sorted(failed) == ["also_gone", "gone"] and all(r["stage"] == "ingest" for r in failed.values())
    assert "file not found" in failed["gone"]["error"] and "/nonexistent/scene.ply" in failed["gone"]["error"]
    assert sorted(f["scene"] for f in s["failures"]) == ["also_gone", "gone"]
    out = capsys.readouterr().out.replace("\n", " ")
    assert "missing source" in out and "also_gone" in out


def test_a_stage_made_from_an_older_upstream_is_refused_with_the_true_cause(tmp_path, make_cfg, costmap_root):
    """The tour's trap: stages=[costmap] with another resolution leaves the screening made from the
    old costmaps. A later run with that resolution is refused for screen, naming the upstream that
    was recomputed since (not "the code version changed") and the exact command."""
    from pipeline.config_guard import refusal

    costmap_root(tmp_path)
    assert not execute(make_cfg(tmp_path, "stages=[screen]"))["failures"]
    assert not execute(make_cfg(tmp_path, "stages=[costmap]", "costmap.resolution=0.1"))["failures"]
    refused = execute(make_cfg(tmp_path, "stages=[episodes]", "costmap.resolution=0.1", "task=[pointnav]"))
    msg = refused["refused"]
    assert "made from an older costmap" in msg and "code version" not in msg, msg
    assert "navarena run stages=[screen" in msg
    changes = {"screen": {"scenes": ["x"], "keys": [], "cause": "c", "storage_only": False, "stale_after": ["costmap"]}}
    assert "  navarena run stages=[screen] costmap.resolution=0.1" in refusal(changes, ["screen"], ["costmap.resolution=0.1"])


def test_pointnav_and_imagenav_episodes_do_not_wait_for_semantics(tmp_path, make_cfg):
    """The episodes of tasks without object goals need the costmap and its screening only: run before
    semantics in a scene's order, and made even when semantics fails; ObjectNav's follow semantics
    (skipped here, its upstream failed), and the graph says so."""
    from pipeline.executor import execute
    from pipeline.graph import BY_NAME, closure, selection

    def upstream(name):  # what a stage waits for (its needs, transitively)
        out, todo = set(), list(BY_NAME[name].needs)
        while todo:
            n = todo.pop()
            out.add(n)
            todo.extend(BY_NAME[n].needs)
        return out

    assert "semantics" not in upstream("episodes") and "semantics" not in upstream("goal_images")
    assert "semantics" in upstream("objectnav_episodes")
    assert selection(["episodes"]) == ["episodes", "objectnav_episodes"]  # one step for users
    order = [s.name for s in closure(["export"])]
    assert order.index("episodes") < order.index("goal_images") < order.index("semantics")
    assert BY_NAME["objectnav_episodes"].package == "episodes"
    s = execute(make_cfg(tmp_path, "task=[pointnav,imagenav,objectnav]", "semantics.segmenter=detector",
                         f"semantics.detector.model={tmp_path / 'no_such_model.onnx'}",
                         "task.pointnav.episodes_per_scene=6", "task.imagenav.episodes_per_scene=3",
                         "task.objectnav.episodes_per_scene=3"))
    st = statuses(s)
    assert st["semantics"] == "failed" and st["episodes"] == "done" and st["goal_images"] == "done"
    assert st["objectnav_episodes"] == "skipped" and st["asset"] == "skipped"
    sid = s["results"][0]["scene_id"]
    for task, n in (("pointnav", 6), ("imagenav", 3)):
        assert pd.read_parquet(tmp_path / "05_episodes" / f"task={task}" / f"scene_id={sid}").shape[0] == n
    assert not (tmp_path / "05_episodes" / "task=objectnav").exists()
    # the pictures to look at first exist all the same: the costmap's and the screening's
    assert (tmp_path / "03_costmaps" / f"{sid}.png").is_file() and (tmp_path / "03_costmaps" / "screen" / f"{sid}.png").is_file()


def test_an_objectnav_setting_recomputes_objectnav_episodes_only(tmp_path, make_cfg):
    """Each episode stage hashes its own tasks' settings: changing ObjectNav's leaves the PointNav
    episodes (and their bytes) as they are, and changing PointNav's leaves ObjectNav's."""
    from pipeline.executor import execute

    base = ["task=[pointnav,objectnav]", "task.pointnav.episodes_per_scene=6", "task.objectnav.episodes_per_scene=3"]
    s1 = execute(make_cfg(tmp_path, *base))
    assert not s1["failures"], s1["failures"]
    sid = s1["results"][0]["scene_id"]
    pn = tmp_path / "05_episodes" / "task=pointnav" / f"scene_id={sid}" / "part-0.parquet"
    before = pn.read_bytes()
    s2 = execute(make_cfg(tmp_path, *base[:2], "task.objectnav.episodes_per_scene=4", "stages=[episodes]"))
    st = statuses(s2)
    assert st["episodes"] == "cached" and st["objectnav_episodes"] == "done" and pn.read_bytes() == before
    assert pd.read_parquet(tmp_path / "05_episodes" / "task=objectnav").shape[0] == 4
    s3 = execute(make_cfg(tmp_path, base[0], "task.pointnav.episodes_per_scene=5",
                          "task.objectnav.episodes_per_scene=4", "stages=[episodes]"))
    st = statuses(s3)
    assert st["episodes"] == "done" and st["objectnav_episodes"] == "cached"
    assert pd.read_parquet(tmp_path / "05_episodes" / "task=pointnav").shape[0] == 5
    assert pd.read_parquet(tmp_path / "05_episodes" / "task=objectnav").shape[0] == 4


def test_the_screening_hint_names_the_runs_own_data_root(tmp_path):
    """The run summary's screening note points at the run's data root (data_root=...), not at data/."""
    import datetime as dt

    from rich.console import Console

    from pipeline.summary import build_summary, print_summary

    summary = build_summary([], dt.datetime.now(dt.timezone.utc), tmp_path / "c.yaml", [0, 1], [], {})
    summary["screening"] = [{"scene": "hall", "score": 0.64, "blur_share": 0.2, "hole_share": 0.1,
                             "view_blur_share": 0.0, "view_hole_share": 0.0, "unseen_share": 0.0,
                             "verdict": "warn", "kept": True}]
    summary["data_root"] = "data/real_indoor"
    out = tmp_path / "console.txt"
    with open(out, "w") as f:
        print_summary(summary, Console(file=f, width=400))
    text = out.read_text()
    assert "data/real_indoor/03_costmaps/screen/<scene_id>.png" in text and "data/real_indoor/_runs/latest.json" in text


def test_per_scene_tables_print_the_worst_rows_and_count_the_rest(tmp_path):
    """A run of thousands of scenes prints at most TABLE_ROWS rows of each per-scene table (the
    largest shortfalls, the lowest screening scores first) and one line counting the rest by kind
    and naming where the run summary lists them all."""
    import datetime as dt

    from rich.console import Console

    from pipeline.summary import TABLE_ROWS, build_summary, print_summary

    summary = build_summary([], dt.datetime.now(dt.timezone.utc), tmp_path / "c.yaml", [0, 1], [], {})
    n = TABLE_ROWS + 30
    summary["shortfalls"] = [{"scene_id": f"s{i:03d}", "scene": f"room{i}", "stage": "episodes",
                              "shortfall": [{"task": "pointnav", "episodes": 10 if i else 3, "requested": 10,
                                             "reason": "difficulty easy 80% / medium 20% / hard 0%"}]}
                             for i in range(n)]
    summary["screening"] = [{"scene": f"room{i}", "score": 0.99 - i / 1000 if i != 7 else 0.10, "blur_share": 0.0,
                             "hole_share": 0.0, "view_blur_share": 0.0, "view_hole_share": 0.0, "unseen_share": 0.0,
                             "verdict": "reject" if i == 7 else "pass", "kept": i != 7} for i in range(n)]
    summary["data_root"] = "data/big"
    out = tmp_path / "console.txt"
    with open(out, "w") as f:
        print_summary(summary, Console(file=f, width=400))
    text = out.read_text()
    lines = text.splitlines()
    short = [ln for ln in lines if "(room" in ln and "episodes" in ln and "pointnav" in ln]
    assert len(short) == TABLE_ROWS and "s000 (room0)" in short[0]  # the 3-of-10 scene leads
    scr = [ln for ln in lines if ln.strip().startswith("room") and ("pass" in ln or "reject" in ln)]
    assert len(scr) == TABLE_ROWS and scr[0].split()[0] == "room7"  # the lowest score first
    assert "... and 30 more (episodes pointnav 30): every row is under \"shortfalls\" in data/big/_runs/latest.json" in text
    assert "... and 30 more (pass 30): every row is under \"screening\" in data/big/_runs/latest.json" in text


def test_a_generator_setting_recomputes_no_captured_scene(tmp_path, make_cfg):
    """Scenes read from files are keyed by a chain without the generated-only stages: a changed
    synthetic.* setting (or a new generator default) changes every stage's hash of a generated
    scene and none of a captured one, whose finished stages stay cached."""
    from navcore.gaussians import GaussianScene
    from navcore.gaussians.formats import write_inria_ply
    from pipeline.graph import config_hashes

    rng = np.random.default_rng(0)
    n = 2000
    q = rng.normal(size=(n, 4))
    write_inria_ply(tmp_path / "cap.ply", GaussianScene(
        means=rng.uniform(-2, 2, (n, 3)).astype(np.float32), quats=(q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32),
        log_scales=np.full((n, 3), -3, np.float32), opacity_logits=np.zeros(n, np.float32),
        sh=rng.uniform(-1, 1, (n, 1, 3)).astype(np.float32)))
    cat = tmp_path / "cat.yaml"
    cat.write_text(f"scenes:\n  - {{name: cap, group: captures, path: {tmp_path / 'cap.ply'}, format: inria_ply}}\n")
    other = "synthetic.layout.room_size_max_m=4.3"
    a, b = config_hashes(make_cfg(tmp_path)), config_hashes(make_cfg(tmp_path, other))
    assert all(a[k] != b[k] for k in a)  # a generated scene: synthesize heads every chain
    assert a.captured == b.captured and "synthesize" not in a.captured
    assert a.captured["ingest"] != a["ingest"]
    root = tmp_path / "d"
    first = execute(make_cfg(root, f"scenes.catalog={cat}", "scenes.count=null", "stages=[ingest]"))
    assert statuses(first) == {"synthesize": "n/a", "ingest": "done"}
    marker = json.loads(next((root / "_markers" / "ingest").glob("*.json")).read_text())
    assert marker["config_hash"] == a.captured["ingest"] == first["captured_config_hashes"]["ingest"]
    again = execute(make_cfg(root, f"scenes.catalog={cat}", "scenes.count=null", "stages=[ingest]", other))
    assert statuses(again) == {"synthesize": "n/a", "ingest": "cached"}
    assert marker["keyed"] == "captured"
    # a root made before the keying (its marker keyed by the generated scenes' chain): the guard says so
    path = next((root / "_markers" / "ingest").glob("*.json"))
    old = {k: v for k, v in marker.items() if k != "keyed"} | {"config_hash": a["ingest"]}
    path.write_text(json.dumps(old))
    refused = execute(make_cfg(root, f"scenes.catalog={cat}", "scenes.count=null", "stages=[voxelize]"))
    assert "keyed apart from the generator's settings" in refused["refused"]


def test_semantics_off_gives_objectnav_a_said_shortfall_not_a_failure(tmp_path, make_cfg, costmap_root):
    """The own-capture guide's quick first look (semantics.enabled=false) on the default tasks: the
    run succeeds, ObjectNav has no episodes and the summary says why; PointNav and ImageNav stand."""
    costmap_root(tmp_path)
    s = execute(make_cfg(tmp_path, "stages=[episodes]", "semantics.enabled=false"))
    assert not s["failures"], s["failures"]
    on = next(r for r in s["results"] if r["stage"] == "objectnav_episodes")
    (short,) = on["shortfall"]
    assert on["status"] == "done" and short["task"] == "objectnav" and short["episodes"] == 0
    assert "semantics.enabled=false" in short["reason"]
    eps = pd.read_parquet(tmp_path / "05_episodes")
    assert set(eps["task"]) == {"pointnav", "imagenav"} and len(eps) > 0
