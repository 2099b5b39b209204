"""Readers, writers and validation on the real sample files and on generated corrupt files."""
import dataclasses
import gzip
import struct

import numpy as np
import pytest

from navcore.gaussians import GaussianScene, SceneFormatError
from navcore.gaussians.formats import (
    detect_format,
    read_gaussians,
    read_npy_folder,
    read_sog,
    read_spz,
    write_inria_ply,
    write_npy_folder,
    write_sog,
    write_sog_lod,
    write_splat,
    write_spz,
)
from navcore.gaussians.validate import sanitize

REAL = {"inria_sh0_donut.ply": (45_624, 0), "inria_sh3_small.ply": (9_080, 3),
        "supersplat_guitar.compressed.ply": (90_854, 0), "antimatter_plant.splat": (113_648, 0)}


def random_scene(n=500, deg=0, seed=0) -> GaussianScene:
    r = np.random.default_rng(seed)
    q = r.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return GaussianScene(r.uniform(-3, 3, (n, 3)), q, r.uniform(-5, -1, (n, 3)), r.uniform(-3, 3, n),
                         r.normal(0, 0.5, (n, (deg + 1) ** 2, 3)))


def same_rotation(q1, q2, tol):
    return np.all(np.abs(np.abs((q1 * q2).sum(1)) - 1) < tol)


@pytest.mark.parametrize("name", list(REAL))
def test_real_files_read_with_expected_counts(name, real_dir):
    if not (real_dir / name).exists():
        pytest.skip(f"real sample {name} not present at {real_dir}")
    s = read_gaussians(real_dir / name)
    n, deg = REAL[name]
    assert len(s) == n and s.sh_degree == deg
    clean, rep = sanitize(s, name)
    assert rep.n_input == n and rep.n_kept == n  # these files are valid, nothing to drop
    assert np.allclose(np.linalg.norm(clean.quats, axis=1), 1, atol=1e-5)
    assert np.isfinite(clean.means).all()


def test_real_inria_sh3_rest_layout(real_dir):
    """f_rest is channel-major in INRIA files: sh[:, 1:, c] == f_rest[c*15:(c+1)*15]."""
    from navcore.gaussians.formats.ply import read_elements

    p = real_dir / "inria_sh3_small.ply"
    if not p.exists():
        pytest.skip("real sample missing")
    v = read_elements(p)["vertex"]
    s = read_gaussians(p)
    assert np.array_equal(s.sh[:, 1:, 1], np.stack([v[f"f_rest_{15 + j}"] for j in range(15)], 1))


def test_supersplat_decodes_to_plausible_values(real_dir):
    p = real_dir / "supersplat_guitar.compressed.ply"
    if not p.exists():
        pytest.skip("real sample missing")
    s = read_gaussians(p)
    # decoded positions lie inside the chunk boxes: the guitar is ~1 m, not arbitrary
    ext = s.means.max(0) - s.means.min(0)
    assert (ext < 10).all() and (ext > 0.1).all()
    assert np.allclose(np.linalg.norm(s.quats, axis=1), 1, atol=2e-3)


@pytest.mark.parametrize("deg", [0, 1, 2, 3])
def test_inria_ply_round_trip_is_exact(tmp_path, deg):
    s = random_scene(deg=deg)
    write_inria_ply(tmp_path / "a.ply", s)
    t = read_gaussians(tmp_path / "a.ply")
    for f in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        assert np.array_equal(getattr(s, f), getattr(t, f)), f


def test_splat_round_trip_within_quantization(tmp_path):
    s = random_scene()
    write_splat(tmp_path / "a.splat", s)
    t = read_gaussians(tmp_path / "a.splat")
    order = np.argsort(-(s.scales.prod(1) * s.alphas), kind="stable")
    assert np.allclose(t.means, s.means[order], atol=1e-6)
    assert np.allclose(t.log_scales, s.log_scales[order], atol=1e-5)
    assert np.allclose(t.alphas, s.alphas[order], atol=1 / 255)
    assert same_rotation(t.quats / np.linalg.norm(t.quats, axis=1, keepdims=True), s.quats[order], 0.02)


@pytest.mark.parametrize("version", [2, 3, 4])
def test_spz_round_trip_within_quantization(tmp_path, version):
    s = random_scene(deg=1)
    write_spz(tmp_path / "a.spz", s, version=version)
    t = read_spz(tmp_path / "a.spz")
    assert np.allclose(t.means, s.means, atol=2 ** -12)
    assert np.allclose(t.log_scales, s.log_scales, atol=1 / 32 + 1e-6)
    assert np.allclose(t.alphas, s.alphas, atol=1 / 255)
    assert same_rotation(t.quats, s.quats, 2e-3 if version >= 3 else 0.03)
    assert np.allclose(t.sh[:, 1:], np.clip(s.sh[:, 1:], -1, 127 / 128), atol=1 / 128)


def test_npy_folder_round_trip(tmp_path):
    s = random_scene()
    write_npy_folder(tmp_path / "scene", s)
    t = read_npy_folder(tmp_path / "scene")
    assert np.allclose(t.means, s.means) and np.allclose(t.alphas, s.alphas, atol=1e-6)
    assert np.allclose(t.colors, s.colors, atol=1 / 255)


# ---- corrupted inputs: clear errors, never a crash ---------------------------------------

def test_lying_header_is_reported_with_counts(tmp_path):
    s = random_scene(n=100)
    write_inria_ply(tmp_path / "a.ply", s)
    data = (tmp_path / "a.ply").read_bytes().replace(b"element vertex 100", b"element vertex 4000000000")
    (tmp_path / "b.ply").write_bytes(data)
    with pytest.raises(SceneFormatError, match=r"declares 4,000,000,000 vertex rows.*room for 100"):
        read_gaussians(tmp_path / "b.ply")


def test_truncated_ply_is_reported(tmp_path):
    write_inria_ply(tmp_path / "a.ply", random_scene(n=100))
    data = (tmp_path / "a.ply").read_bytes()
    (tmp_path / "t.ply").write_bytes(data[:-1000])
    with pytest.raises(SceneFormatError, match="t.ply.*truncated"):
        read_gaussians(tmp_path / "t.ply")


def test_missing_property_is_named(tmp_path):
    write_inria_ply(tmp_path / "a.ply", random_scene(n=10))
    data = (tmp_path / "a.ply").read_bytes().replace(b"property float opacity\n", b"property float opacitx\n")
    (tmp_path / "m.ply").write_bytes(data)
    with pytest.raises(SceneFormatError, match="lacks required properties: opacity"):
        read_gaussians(tmp_path / "m.ply")


def test_nan_zero_quaternion_and_absurd_scale_are_dropped_and_counted():
    s = random_scene(n=200)
    s.means[3, 1] = np.nan
    s.opacity_logits[4] = np.inf
    s.quats[10] = 0
    s.log_scales[20, 2] = 15.0  # sigma 3.3 km in a 6 m scene
    clean, rep = sanitize(s, "x.ply")
    assert rep.dropped == {"non_finite": 2, "zero_quaternion": 1, "absurd_scale": 1}
    assert len(clean) == 196 and np.isfinite(clean.means).all()


def test_empty_and_all_bad_scenes_are_refused(tmp_path):
    with pytest.raises(SceneFormatError, match="no Gaussians"):
        sanitize(random_scene(n=0), "e.ply", "abcd1234")
    s = random_scene(n=5)
    s.means[:] = np.nan
    with pytest.raises(SceneFormatError, match="scene 'abcd1234'.*no usable Gaussians"):
        sanitize(s, "e.ply", "abcd1234")


def test_bad_splat_and_spz_files(tmp_path):
    (tmp_path / "a.splat").write_bytes(b"\0" * 70)
    with pytest.raises(SceneFormatError, match="not a multiple of 32"):
        read_gaussians(tmp_path / "a.splat")
    (tmp_path / "a.spz").write_bytes(b"not gzip")
    with pytest.raises(SceneFormatError, match="gzip"):
        read_gaussians(tmp_path / "a.spz")
    (tmp_path / "b.spz").write_bytes(gzip.compress(struct.pack("<IIIBBBB", 0x12345678, 2, 1, 0, 12, 0, 0)))
    with pytest.raises(SceneFormatError, match="magic"):
        read_gaussians(tmp_path / "b.spz")
    (tmp_path / "c.spz").write_bytes(gzip.compress(struct.pack("<IIIBBBB", 0x5053474E, 2, 1000, 0, 12, 0, 0)))
    with pytest.raises(SceneFormatError, match="declares 1,000 Gaussians"):
        read_gaussians(tmp_path / "c.spz")


def test_ascii_ply_and_not_a_ply(tmp_path):
    txt = ("ply\nformat ascii 1.0\nelement vertex 2\n" + "".join(
        f"property float {p}\n" for p in ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1",
                                          "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])
        + "end_header\n" + "0 0 0 0 0 0 1 -3 -3 -3 1 0 0 0\n1 1 1 0 0 0 1 -3 -3 -3 1 0 0 0\n")
    (tmp_path / "a.ply").write_text(txt)
    assert len(read_gaussians(tmp_path / "a.ply")) == 2
    (tmp_path / "b.ply").write_bytes(b"hello")
    with pytest.raises(SceneFormatError, match="not a PLY"):
        read_gaussians(tmp_path / "b.ply")
    with pytest.raises(SceneFormatError, match="missing.*|does not exist"):
        read_gaussians(tmp_path / "missing.ply")


def test_transform_rotates_view_dependent_colour():
    """Colour seen from direction d before == colour seen from R d after (SH degree 3)."""
    from navcore.gaussians.model import quat_to_rotmat
    from navcore.gaussians.sh import sh_basis

    s = random_scene(n=50, deg=3)
    q = np.array([0.8, 0.2, -0.5, 0.3])
    q /= np.linalg.norm(q)
    t = np.eye(4)
    t[:3, :3] = quat_to_rotmat(q)
    t[:3, 3] = [1.0, -2.0, 0.5]
    r = s.transformed(t)
    d = np.random.default_rng(1).normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    before = np.einsum("nk,nkc->nc", sh_basis(d, 3), s.sh)
    after = np.einsum("nk,nkc->nc", sh_basis(d @ t[:3, :3].T, 3), r.sh)
    assert np.allclose(before, after, atol=1e-4)
    assert np.array_equal(r.sh[:, 0], s.sh[:, 0])
    # orientations turn with the scene: the local axes map by R
    assert np.allclose(quat_to_rotmat(r.quats.astype(float)), t[:3, :3] @ quat_to_rotmat(s.quats.astype(float)), atol=1e-5)


# ---- SPZ v4 and SOG ------------------------------------------------------------------------

@pytest.mark.parametrize("deg", [0, 2])
def test_spz_v4_layout_is_the_reference_one(tmp_path, deg):
    """32-byte plaintext header, TOC at byte 32, one ZSTD stream per non-empty attribute."""
    import zstandard

    s = random_scene(n=300, deg=deg)
    write_spz(tmp_path / "a.spz", s, version=4)
    data = (tmp_path / "a.spz").read_bytes()
    magic, version, n, sh_deg, frac, flags, n_streams, toc = struct.unpack_from("<IIIBBBBI", data)
    assert data[:4] == b"NGSP" and (version, n, sh_deg, frac, toc) == (4, 300, deg, 12, 32)
    assert n_streams == (5 if deg == 0 else 6) and data[20:32] == bytes(12)
    sizes = np.frombuffer(data, "<u8", 2 * n_streams, 32).reshape(-1, 2)
    assert sizes[:, 0].sum() + 32 + 16 * n_streams == len(data)
    assert sizes[0, 1] == 300 * 9  # positions first
    first = data[32 + 16 * n_streams:32 + 16 * n_streams + int(sizes[0, 0])]
    assert len(zstandard.ZstdDecompressor().decompress(first)) == 300 * 9


def test_bad_spz_v4_files(tmp_path):
    write_spz(tmp_path / "a.spz", random_scene(n=200), version=4)
    data = (tmp_path / "a.spz").read_bytes()
    (tmp_path / "t.spz").write_bytes(data[:-50])
    with pytest.raises(SceneFormatError, match="t.spz.*runs past the end.*truncated"):
        read_gaussians(tmp_path / "t.spz")
    lying = bytearray(data)
    struct.pack_into("<I", lying, 8, 4_000_000_000)
    (tmp_path / "l.spz").write_bytes(bytes(lying))
    with pytest.raises(SceneFormatError, match="4,000,000,000 Gaussians need"):
        read_gaussians(tmp_path / "l.spz")
    bad = bytearray(data)
    bad[32 + 16 * 5 + 4:32 + 16 * 5 + 12] = b"\xff" * 8  # inside the first ZSTD frame
    (tmp_path / "z.spz").write_bytes(bytes(bad))
    with pytest.raises(SceneFormatError, match="stream 'positions'"):
        read_gaussians(tmp_path / "z.spz")
    (tmp_path / "x.spz").write_bytes(b"PK\x03\x04 something else")
    with pytest.raises(SceneFormatError, match="neither a gzip stream"):
        read_gaussians(tmp_path / "x.spz")


def assert_sog_close(t: GaussianScene, s: GaussianScene):
    """Within SOG's quantization: 16 bits of the log-transformed position range, 256-entry
    codebooks (quantiles here), 8-bit opacity and smallest-three quaternion components."""
    lt = np.sign(s.means) * np.log1p(np.abs(s.means))
    step = (lt.max(0) - lt.min(0)) / 65535
    assert np.all(np.abs(t.means - s.means) <= np.exp(np.abs(lt)) * step * 0.51 + 1e-6)
    for a, b in ((t.log_scales, s.log_scales), (t.sh[:, 0], s.sh[:, 0]), (t.sh[:, 1:], s.sh[:, 1:])):
        if not a.size:
            continue
        cb = np.unique(a)
        gap = np.diff(cb).max()
        assert np.abs(a - b).max() <= gap / 2 + 1e-5
        assert len(cb) <= 256
    assert np.allclose(t.alphas, s.alphas, atol=0.5 / 255 + 1e-6)
    assert same_rotation(t.quats, s.quats, 2e-4)


@pytest.mark.parametrize("name,deg", [("a.sog", 0), ("a.sog", 3), ("folder", 1)])
def test_sog_round_trip_within_quantization(tmp_path, name, deg):
    s = random_scene(n=700, deg=deg)
    write_sog(tmp_path / name, s)
    assert detect_format(tmp_path / name) == "sog"
    t = read_gaussians(tmp_path / name)
    assert len(t) == 700 and t.sh_degree == deg
    assert_sog_close(t, s)
    if name == "folder":
        assert np.array_equal(read_gaussians(tmp_path / name / "meta.json").means, t.means)


def test_streamed_sog_levels_and_missing_files(tmp_path):
    fine = [random_scene(n=300, seed=1), random_scene(n=200, seed=2)]
    coarse = [random_scene(n=120, seed=3)]
    meta = write_sog_lod(tmp_path / "lod", [fine, coarse])
    assert detect_format(tmp_path / "lod") == "sog" and detect_format(meta) == "sog"
    t = read_gaussians(meta)  # default: the finest complete level, units in file order
    assert len(t) == 500
    assert np.allclose(t.means[:300], fine[0].means, atol=1e-3) and np.allclose(t.means[300:], fine[1].means, atol=1e-3)
    assert len(read_sog(tmp_path / "lod", level=1)) == 120
    (tmp_path / "lod" / "0_1" / "quats.webp").unlink()
    (tmp_path / "lod" / "0_1" / "meta.json").unlink()
    assert len(read_gaussians(meta)) == 120  # level 0 is incomplete: level 1
    with pytest.raises(SceneFormatError, match=r"level 0 lacks 1 of its 2 files \(0_1/meta.json\).*complete levels: \[1\]"):
        read_sog(meta, level=0)
    with pytest.raises(SceneFormatError, match="no level 5"):
        read_sog(meta, level=5)
    (tmp_path / "lod" / "1_0" / "meta.json").unlink()
    with pytest.raises(SceneFormatError, match="no level of this streamed SOG has all its files.*1_0/meta.json"):
        read_sog(meta)


def test_bad_sog_inputs(tmp_path):
    (tmp_path / "a.sog").write_bytes(b"not a zip")
    with pytest.raises(SceneFormatError, match="a.sog.*not a valid zip"):
        read_gaussians(tmp_path / "a.sog")
    write_sog(tmp_path / "f", random_scene(n=50))
    (tmp_path / "f" / "scales.webp").write_bytes(b"RIFF0000WEBPjunk")
    with pytest.raises(SceneFormatError, match="scales.webp.*unreadable WebP"):
        read_gaussians(tmp_path / "f")
    (tmp_path / "f" / "meta.json").write_text('{"version": 1, "count": 3}')
    with pytest.raises(SceneFormatError, match="version 1 is not supported"):
        read_gaussians(tmp_path / "f")


def test_shared_sog_folder_and_spz_agree(real_indoor_dir):
    """The shared streamed SOG (level 3) and the SPZ decoded independently from it: the same
    Gaussians in the same order, within the two formats' quantization."""
    sog, spz = real_indoor_dir / "fungi_room_sog_lod", real_indoor_dir / "fungi_room_lod3.spz"
    if not (sog.exists() and spz.exists()):
        pytest.skip(f"real indoor scenes not present at {real_indoor_dir}")
    with pytest.raises(SceneFormatError, match="level 0 lacks"):
        read_sog(sog, level=0)  # lod-meta.json lists levels 0-2, whose folders are absent
    a, b = read_gaussians(sog), read_gaussians(spz)
    assert len(a) == len(b) == 1_500_000
    assert np.abs(a.means - b.means).max() <= 2 ** -12 / 2 + 1e-6  # SPZ's 12 fractional bits
    assert np.array_equal(np.round(a.alphas * 255), np.round(b.alphas * 255))
    lo, hi = -10.0, 255 / 16 - 10.0  # SPZ's log-scale range, step 1/16
    assert np.abs(np.clip(a.log_scales, lo, hi) - b.log_scales).max() <= 1 / 32 + 1e-5
    lim = 127.5 / (0.15 * 255)  # SPZ's colour range, step 1 / (0.15 * 255)
    assert np.abs(np.clip(a.sh[:, 0], -lim, lim) - b.sh[:, 0]).max() <= 0.5 / (0.15 * 255) + 1e-5
    assert np.percentile(1 - np.abs((a.quats * b.quats).sum(1)), 99) < 2e-3  # SPZ v2: 8-bit x, y, z


def test_reference_store_reads_back_the_copy_and_refuses_a_changed_source(tmp_path, real_dir):
    """A reference store (the source's recipe and a checksum, kilobytes) loads the same Gaussians
    and extras as a full copy; a source edited or removed afterwards is a clear error."""
    import shutil

    from navcore.gaussians.validate import ValidationLimits, read_validated
    from navcore.io.datasets import GaussianDataset

    if not (real_dir / "inria_sh3_small.ply").exists():
        pytest.skip(f"real sample inria_sh3_small.ply not present at {real_dir}")
    src = tmp_path / "scene.ply"
    shutil.copy(real_dir / "inria_sh3_small.ply", src)
    clean, _ = read_validated(src, "inria_ply", "s1", scale=0.5)
    clean.extras["content"] = np.arange(len(clean)) % 3 == 0
    ref, copy = GaussianDataset(tmp_path / "ref.zarr"), GaussianDataset(tmp_path / "copy.zarr")
    ref.save(clean, {"scene_id": "s1"}, {"path": str(src), "format": "inria_ply", "level": None, "scale": 0.5,
                                          "limits": dataclasses.asdict(ValidationLimits())})
    copy.save(clean, {"scene_id": "s1"})
    (a, aa), (b, ba) = ref.load(), copy.load()
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(a.extras["content"], b.extras["content"])
    assert aa["store"] == "reference" and ba["store"] == "copy"
    size = lambda p: sum(f.stat().st_size for f in p.rglob("*") if f.is_file())  # noqa: E731
    assert size(ref.path) < 0.05 * size(copy.path)
    data = bytearray(src.read_bytes())
    data[-5] ^= 0x40  # one bit of the last Gaussian's payload
    src.write_bytes(bytes(data))
    with pytest.raises(SceneFormatError, match="changed since it was ingested"):
        ref.load()
    src.unlink()
    with pytest.raises(SceneFormatError, match="is gone"):
        ref.load()
