"""Hostile input: every reader under hypothesis-drawn corruption (truncation, bit flips, lying and
huge counts, NaN / inf / 1e30 / denormals, empty files, folders in place of files, decompression
bombs) ends in the scene's SceneFormatError or a validated scene: no other exception, no hang,
no allocation beyond a bound on the input's size. `make test-faults` runs 10,000 cases a kind
(faults.fuzz_readers); here a few dozen each, plus the cases that found real defects."""
import gzip
import struct
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from faults.fuzz_readers import KINDS, READER_OF, apply_case, case_strategy, make_seed, run_case, small_scene
from navcore.gaussians import SceneFormatError
from navcore.gaussians.formats import write_sog, write_spz
from navcore.gaussians.validate import read_validated


@pytest.mark.parametrize("kind", KINDS)
def test_reader_survives_random_corruption(kind, tmp_path_factory):
    work = tmp_path_factory.mktemp(kind)
    seed = make_seed(kind, work / "seed")
    assert run_case(seed, READER_OF[kind])[0] == "accepted"  # the seed itself is valid

    @settings(max_examples=12, database=None, deadline=None, suppress_health_check=list(HealthCheck))
    @given(case_strategy())
    def one(case):
        path = apply_case(seed, work / "case", *case)
        outcome, detail = run_case(path, READER_OF[kind])
        assert outcome in ("accepted", "rejected"), (case, outcome, detail)

    one()


def _expect_rejected(path, fmt, match):
    with pytest.raises(SceneFormatError, match=match) as e:
        read_validated(path, fmt, scene_id="hostile")
    assert "hostile" in str(e.value)  # the error names the scene


def test_folder_in_place_of_a_file_is_a_format_error(tmp_path):
    for name, fmt in (("a.ply", "ply"), ("a.splat", "splat"), ("a.spz", "spz")):
        (tmp_path / name).mkdir()
        _expect_rejected(tmp_path / name, fmt, "is a folder")


def test_decompression_bombs_are_refused_before_they_inflate(tmp_path):
    s = small_scene(40, 0, 1)
    write_spz(tmp_path / "ok.spz", s, version=2)
    payload = gzip.decompress((tmp_path / "ok.spz").read_bytes())
    # the payload followed by 256 MB of zeros: a 250 KB file
    (tmp_path / "bomb.spz").write_bytes(gzip.compress(payload + bytes(1 << 28), mtime=0))
    _expect_rejected(tmp_path / "bomb.spz", "spz", "inflates past")
    # a header that claims 2^31 Gaussians for a few hundred bytes
    lying = bytearray(payload)
    lying[8:12] = struct.pack("<I", 2**31 - 1)
    (tmp_path / "lying.spz").write_bytes(gzip.compress(bytes(lying), mtime=0))
    _expect_rejected(tmp_path / "lying.spz", "spz", "decompression bomb or a lying header")
    # a .sog whose meta.json inflates to 256 MB inside the zip
    write_sog(tmp_path / "ok.sog", s)
    with zipfile.ZipFile(tmp_path / "ok.sog") as zf:
        files = {n: zf.read(n) for n in zf.namelist()}
    with zipfile.ZipFile(tmp_path / "bomb.sog", "w", zipfile.ZIP_DEFLATED) as zf:
        for n, d in files.items():
            zf.writestr(n, d + bytes(1 << 28) if n == "meta.json" else d)
    _expect_rejected(tmp_path / "bomb.sog", "sog", "decompression bomb")


def test_npy_headers_that_lie_allocate_nothing(tmp_path):
    from navcore.gaussians.formats import write_npy_folder

    s = small_scene(40, 0, 2)
    write_npy_folder(tmp_path / "f", s)
    coord = (tmp_path / "f" / "coord.npy").read_bytes()
    (tmp_path / "f" / "coord.npy").write_bytes(coord.replace(b"(40, 3)", b"(400000000000, 3)"))
    _expect_rejected(tmp_path / "f", "npy_folder", "lying header")
    # a version-2 header whose length field claims 4 GB: numpy would allocate it before checking
    bad = bytearray(coord)
    bad[6:8] = b"\x02\x00"
    bad[8:12] = struct.pack("<I", 2**32 - 1)
    (tmp_path / "f" / "coord.npy").write_bytes(bytes(bad))
    _expect_rejected(tmp_path / "f", "npy_folder", "header claims")
    np.save(tmp_path / "f" / "coord.npy", np.array([object()] * 40))  # pickled objects are never loaded
    _expect_rejected(tmp_path / "f", "npy_folder", "object")


def test_ply_headers_with_broken_lines_are_format_errors(tmp_path):
    from navcore.gaussians.formats import write_inria_ply

    write_inria_ply(tmp_path / "ok.ply", small_scene(40, 3, 4))
    raw = (tmp_path / "ok.ply").read_bytes()
    cases = {
        "joined.ply": raw.replace(b"f_rest_2\n", b"f_rest_2*", 1),        # a newline bit-flipped away
        "twice.ply": raw.replace(b"f_rest_34\n", b"f_rest_33\n", 1),      # a property declared twice
        "short.ply": raw.replace(b"property float z\n", b"property float\n", 1),
        "count.ply": raw.replace(b"element vertex 40", b"element vertex 4\x120", 1),
    }
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        _expect_rejected(tmp_path / name, "ply", "PLY")


def test_spz_v4_frame_that_declares_more_than_its_stream_is_refused_before_allocating(tmp_path):
    import struct as _struct

    import zstandard

    write_spz(tmp_path / "ok.spz", small_scene(40, 0, 5), version=4)
    data = bytearray((tmp_path / "ok.spz").read_bytes())
    fields = _struct.Struct("<IIIBBBBI12s").unpack_from(data)  # the v4 header (NGSP, 32 bytes)
    toc, n_streams = fields[7], fields[6]
    entries = np.frombuffer(bytes(data), dtype="<u8", count=2 * n_streams, offset=toc).reshape(n_streams, 2).copy()
    # the first stream replaced by a frame that states 256 MB of content (a few hundred bytes)
    bomb = zstandard.ZstdCompressor(write_content_size=True).compress(bytes(1 << 28))
    start = toc + 16 * n_streams
    body = bytes(data[start + int(entries[0, 0]):])
    entries[0, 0] = len(bomb)
    out = bytes(data[:toc]) + entries.astype("<u8").tobytes() + bomb + body
    (tmp_path / "bomb.spz").write_bytes(out)
    _expect_rejected(tmp_path / "bomb.spz", "spz", "frame declares")


# ---- agent-server frames: a hostile server against the evaluator, a hostile client against ours ----
from faults.fuzz_frames import CLIENT_KINDS, SERVER_KINDS  # noqa: E402


@pytest.mark.parametrize("spec", [f"client:{k}" for k in CLIENT_KINDS] + [f"server:{k}" for k in SERVER_KINDS])
def test_hostile_frames_end_in_recorded_failures(spec):
    """A few dozen drawn frames a type (`make test-faults` runs 10,000): the evaluator accepts,
    skips or rejects each with ProtocolError / ValueError; serve_agent answers each with a
    well-formed frame or nothing; no hang, no MemoryError."""
    from faults.fuzz_frames import run

    rep = run([spec], cases=25, seed=0, time_limit=5.0)[spec]
    assert rep["cases"] == 25 and rep["crashes"] == rep["hangs"] == rep["memory"] == 0, rep["examples"]


def test_frames_that_found_defects():
    import msgpack

    from navcore.eval.agents import make_agent
    from navcore.eval.protocol.codec import ProtocolError, decode_value, unpack
    from navcore.eval.protocol.server import Session
    from navcore.nav.actions import ActionSpace

    # a list as the frame type: was a TypeError (unhashable) instead of a protocol error
    with pytest.raises(ProtocolError):
        unpack(msgpack.packb({"type": [1], "payload": {}, "seq": 1, "timestamp": 0}))
    with pytest.raises(ProtocolError):  # seq True is not an int seq
        unpack(msgpack.packb({"type": "action", "payload": {}, "seq": True, "timestamp": 0}))
    # an image whose PNG header disagrees with its declared shape, and one too large to decode
    from faults.fuzz_frames import png_image

    with pytest.raises(ProtocolError):
        decode_value({"rgb": png_image(8, 8, declared=[2**20, 2**20, 3])})
    with pytest.raises(ProtocolError):
        decode_value({"rgb": png_image(2000, 1000)}, max_pixels=1 << 20)
    # serve_agent never raises, whatever arrives
    s = Session(lambda: make_agent("random"), "native", ActionSpace())
    for data in (b"", b"\xc1", msgpack.packb([1, 2]), msgpack.packb({"type": "observation", "payload": {}, "seq": 3,
                                                                     "timestamp": 0})):
        assert unpack(s.respond(data))["type"] == "error"


def test_quaternions_near_float32_max_normalize_to_unit(tmp_path):
    """Found by the 10,000-case npy_folder run: components of 3.4e38 have a norm above float32's
    range, and dividing by it in float32 gave zero quaternions in a 'validated' scene."""
    from navcore.gaussians.formats import write_npy_folder

    gs = small_scene(4, 0, 1)
    gs.quats[1] = [3.4e38, 3.4e38, 0.0, 0.0]
    gs.quats[2] = [3.4e38, 0.0, 0.0, 0.0]
    write_npy_folder(tmp_path / "s", gs)
    scene, _ = read_validated(tmp_path / "s", "npy_folder", scene_id="hostile")
    assert np.allclose(np.linalg.norm(scene.quats.astype(np.float64), axis=1), 1, atol=1e-6)
    assert np.allclose(scene.quats[1], [2 ** -0.5, 2 ** -0.5, 0, 0], atol=1e-6)


@pytest.mark.parametrize("kind", ["catalog", "label_folder", "mesh_scannet", "mesh_replica", "mesh_points"])
def test_catalogs_label_folders_and_meshes_survive_random_corruption(kind, tmp_path):
    """A few dozen cases of faults.fuzz_inputs (10,000 an input in make test-faults)."""
    from faults.fuzz_inputs import fuzz_kind

    rep = fuzz_kind(kind, 30, 0, tmp_path)
    assert rep["cases"] == 30 and rep["crash"] == rep["hang"] == rep["memory"] == 0, rep["failures"]


@pytest.mark.parametrize("text, match", [
    (b"\xff\xfe scenes", "not UTF-8"), ("scenes:\n  - {name: a\n", "not valid YAML"),
    ("scenes: !!python/object/apply:os.system ['true']\n", "not valid YAML"), ("- a\n- b\n", "must be a mapping"),
    ("scenes: {name: a}\n", "scenes must be a list"), ("scenes:\n  - just a string\n", "scene entry 1: must be a mapping"),
    ("scenes:\n  - {name: [a], path: a.ply}\n", "'name' must be a non-empty string"),
    ("scenes:\n  - {name: a, path: " + "x" * 300 + ".ply}\n", "not a usable path"),
    ("scenes:\n  - {name: a, path: a.ply, labels: {max_distance: far}}\n", "labels.max_distance"),
    ("scenes:\n  - {name: a, path: a.ply, labels: {ignore: [a]}}\n", "labels.ignore"),
    ("synthetic: {count: 100000000000000}\n", "count must be an integer"),
    ("layout:\n  instances: '{root}/{scefe_id}.parquet'\n", "unknown placeholder"),
    ("layout:\n  episodes_root: {path: x, type: parquet}\n", "must be a folder template"),
    ("layout:\n  instances: {path: '{root}/x', type: zarr}\n", "of type 'parquet'"),
    ("layout:\n  instances: '{root}/}{'\n", "malformed"),
])
def test_catalog_defects_found_by_fuzzing_are_clear_errors(tmp_path, text, match):
    from navcore.io.catalog import Catalog

    f = tmp_path / "c.yaml"
    f.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(ValueError, match=match) as e:
        Catalog(f, tmp_path / "d")
    assert str(f) in str(e.value)


def test_mesh_defects_found_by_fuzzing_are_clear_errors(tmp_path):
    import json

    from faults.fuzz_inputs import make_seed
    from navcore.labels.mesh import read_labelled_geometry

    mesh = make_seed("mesh_replica", tmp_path / "r")
    (tmp_path / "r" / "info_semantic.json").write_text(json.dumps({"classes": None, "objects": [{"id": None}]}))
    with pytest.raises(ValueError, match="malformed labels") as e:
        read_labelled_geometry(mesh)
    assert str(mesh) in str(e.value)
    text = mesh.read_text().replace("element face 24", "element face 0")  # labels per face, no faces
    mesh.write_text(text.split("end_header")[0] + "end_header\n" + "\n".join(text.split("end_header\n")[1].splitlines()[:16]))
    with pytest.raises(ValueError, match="no faces|malformed"):
        read_labelled_geometry(mesh)
