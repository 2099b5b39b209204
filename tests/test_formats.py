"""Readers, writers and validation on the real sample files and on generated corrupt files."""
import gzip
import struct

import numpy as np
import pytest

from stages.gaussians import GaussianScene, SceneFormatError
from stages.gaussians.formats import (read_gaussians, read_npy_folder, read_spz, write_inria_ply, write_npy_folder,
                                      write_splat, write_spz)
from stages.gaussians.validate import sanitize
from tests.conftest import REAL_DIR

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
def test_real_files_read_with_expected_counts(name):
    if not (REAL_DIR / name).exists():
        pytest.skip(f"real sample {name} not present at {REAL_DIR}")
    s = read_gaussians(REAL_DIR / name)
    n, deg = REAL[name]
    assert len(s) == n and s.sh_degree == deg
    clean, rep = sanitize(s, name)
    assert rep.n_input == n and rep.n_kept == n  # these files are valid, nothing to drop
    assert np.allclose(np.linalg.norm(clean.quats, axis=1), 1, atol=1e-5)
    assert np.isfinite(clean.means).all()


def test_real_inria_sh3_rest_layout():
    """f_rest is channel-major in INRIA files: sh[:, 1:, c] == f_rest[c*15:(c+1)*15]."""
    from stages.gaussians.formats.ply import _read_elements

    p = REAL_DIR / "inria_sh3_small.ply"
    if not p.exists():
        pytest.skip("real sample missing")
    v = _read_elements(p)["vertex"]
    s = read_gaussians(p)
    assert np.array_equal(s.sh[:, 1:, 1], np.stack([v[f"f_rest_{15 + j}"] for j in range(15)], 1))


def test_supersplat_decodes_to_plausible_values():
    p = REAL_DIR / "supersplat_guitar.compressed.ply"
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


@pytest.mark.parametrize("version", [2, 3])
def test_spz_round_trip_within_quantization(tmp_path, version):
    s = random_scene(deg=1)
    write_spz(tmp_path / "a.spz", s, version=version)
    t = read_spz(tmp_path / "a.spz")
    assert np.allclose(t.means, s.means, atol=2 ** -12)
    assert np.allclose(t.log_scales, s.log_scales, atol=1 / 32 + 1e-6)
    assert np.allclose(t.alphas, s.alphas, atol=1 / 255)
    assert same_rotation(t.quats, s.quats, 2e-3 if version == 3 else 0.03)
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
    from stages.gaussians.model import quat_to_rotmat
    from stages.gaussians.sh import sh_basis

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
