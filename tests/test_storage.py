"""The grids' codecs (navcore.io.codecs): chosen per dtype, readable by any Zarr v3 reader, exact
round trips, and stores written before them (zarr's default codecs) read as they were."""
import json
from types import SimpleNamespace

import numpy as np
import zarr

from navcore.io.codecs import array_codecs, slab_shards
from navcore.io.datasets import COSTMAP_LAYERS, CostmapDataset
from navcore.nav.embodiment import Embodiment


def _layers(rng):
    ny, nx = 40, 50
    clearance = rng.uniform(0, 2, (ny, nx)).astype(np.float32)
    clearance[:5] = -1.0
    occ = clearance < 0.3
    return SimpleNamespace(origin=(1.0, -2.0), resolution=0.05, margin=0.003, raw=rng.random((ny, nx)) < 0.1,
                           support=clearance >= 0, occ=occ, clearance=clearance,
                           components=np.where(occ, 0, 1 + (np.arange(nx) > 25)).astype(np.int32))


def _codec_names(array_dir):
    meta = json.loads((array_dir / "zarr.json").read_text())
    return [(c["name"], c.get("configuration", {}).get("shuffle")) for c in meta["codecs"]]


def test_costmap_store_codecs_and_exact_round_trip(tmp_path, rng):
    layers, emb = _layers(rng), Embodiment()
    ds = CostmapDataset(tmp_path / "c.zarr")
    with ds.writing() as root:
        CostmapDataset.write_layers(root, emb, layers, {}, hidden=np.array([3, 9, 27]))
    got, attrs, _ = ds.load_layers(emb.name)
    for name in COSTMAP_LAYERS:
        assert got[name].dtype == getattr(layers, name).dtype and np.array_equal(got[name], getattr(layers, name))
    assert np.array_equal(ds.hidden(emb.name), [3, 9, 27])
    group = tmp_path / "c.zarr" / emb.name
    assert ("blosc", "bitshuffle") in _codec_names(group / "occ")  # bool: bit-packed by the shuffle
    assert ("zstd", None) in _codec_names(group / "clearance")  # float32: zstd 19
    assert ("blosc", "shuffle") in _codec_names(group / "components")
    cm = ds.load(emb.name)
    assert np.array_equal(cm.clearance, layers.clearance)


def test_stores_written_with_zarrs_default_codecs_still_read(tmp_path, rng):
    """A costmap store as the stage wrote it before the codecs were chosen (no codec arguments)."""
    layers, emb = _layers(rng), Embodiment()
    root = zarr.open_group(str(tmp_path / "old.zarr"), mode="w")
    g = root.create_group(emb.name)
    for name in COSTMAP_LAYERS:
        arr = getattr(layers, name)
        g.create_array(name, data=arr, chunks=arr.shape)
    g.attrs.update({"origin": list(layers.origin), "resolution": 0.05, "radius": emb.radius, "margin": 0.003})
    assert ("zstd", None) in _codec_names(tmp_path / "old.zarr" / emb.name / "occ")
    got, _, _ = CostmapDataset(tmp_path / "old.zarr").load_layers(emb.name)
    assert all(np.array_equal(got[n], getattr(layers, n)) for n in COSTMAP_LAYERS)


def test_sharded_bool_grid_is_smaller_than_the_default_and_exact(tmp_path, rng):
    """A sparse occupancy grid (3 % set, in slabs as a voxel grid is) written in slab shards with
    the bool codec: exact, fewer bytes than zarr's default, one file per x-slab."""
    shape, chunks = (96, 70, 130), (32, 64, 64)
    v = np.zeros(shape, bool)
    v[:, 10:12, :] = True  # a floor
    v[rng.random(shape) < 0.01] = True  # clutter
    sizes = {}
    for name, kw in (("new", dict(shards=slab_shards(shape, chunks), **array_codecs(bool))), ("old", {})):
        g = zarr.open_group(str(tmp_path / f"{name}.zarr"), mode="w")
        a = g.create_array("V", shape=shape, dtype="bool", chunks=chunks, fill_value=False, **kw)
        for x0 in range(0, shape[0], 40):  # x-blocks that straddle the shards, as the stage writes
            a[x0:x0 + 40] = v[x0:x0 + 40]
        assert np.array_equal(zarr.open_group(str(tmp_path / f"{name}.zarr"), mode="r")["V"][...], v)
        files = [f for f in (tmp_path / f"{name}.zarr" / "V").rglob("*") if f.is_file() and f.name != "zarr.json"]
        sizes[name] = (sum(f.stat().st_size for f in files), len(files))
    assert sizes["new"][0] < 0.8 * sizes["old"][0], sizes
    assert sizes["new"][1] == 3 and sizes["old"][1] == 3 * 2 * 3, sizes  # one file per slab of 32, not per chunk
