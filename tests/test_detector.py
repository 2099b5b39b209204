"""The `detector` segmenter (issue 47): the shipped real weights, the class table, box -> mask by
depth, and the lifting's multi-view support."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from navcore.io.models import DEFAULT_MODEL, MODELS_ROOT, SHIPPED, load_net
from navcore.io.release import sha256_file
from stages.semantics.detector import COCO_TO_GOAL, DetectorConfig, box_mask, boxes_of, detect, resolved
from stages.semantics.lifting import LiftingConfig, lift, view_support

SHARED_MODELS = Path(__file__).resolve().parents[2] / "shared" / "models"
PHOTO = Path(__file__).resolve().parents[2] / "shared/data/real_labelled/sunrgbd_000017_bedroom/source/000017.jpg"


def _darknet() -> bool:
    import cv2

    return hasattr(cv2.dnn, "readNetFromDarknet")


needs_darknet = pytest.mark.skipif(not _darknet(), reason="OpenCV 5 has no Darknet reader (Yolo-Fastest needs OpenCV 4)")
COCO_NAMES = [n.strip() for n in (MODELS_ROOT / "yolox_nano_416_coco" / "classes.txt").read_text().splitlines() if n.strip()]

@pytest.mark.parametrize("name", [pytest.param(n, marks=needs_darknet) if SHIPPED[n].network.endswith(".cfg") else n
                                  for n in sorted(SHIPPED)])
def test_shipped_weights_load_and_are_the_published_ones(name, tmp_path):
    entry = SHIPPED[name]
    for f, digest in entry.files.items():  # the published files, byte for byte
        assert sha256_file(MODELS_ROOT / entry.folder / f) == digest
    assert (MODELS_ROOT / entry.folder / "README.md").is_file() and (MODELS_ROOT / entry.folder / "LICENSE").is_file()
    n, names, spec = load_net(name)
    assert spec == entry.spec
    assert len(names) == 80 and names[56] == "chair" and names[57] == "sofa"  # Darknet's spelling of couch
    mapped = {COCO_TO_GOAL[n] for n in names if n in COCO_TO_GOAL}
    assert mapped == set(COCO_TO_GOAL.values())  # every goal of the table is reachable with the shipped names
    out = detect(n, np.full((240, 320, 3), 128, np.uint8), spec.input_size or 320, spec)
    cells = {"yolo_fastest_1.1_coco": 300 + 1200,  # two heads: 10 x 10 and 20 x 20 cells, 3 anchors
             "picodet_s_320_coco": 40 * 40 + 20 * 20 + 10 * 10 + 5 * 5,  # strides 8-64
             "yolox_nano_416_coco": 52 * 52 + 26 * 26 + 13 * 13}[name]  # strides 8-32
    assert out.shape == (cells, 85)
    goal = [i for i, n in enumerate(names) if n in COCO_TO_GOAL]
    assert (out[:, 4:5] * out[:, 5:][:, goal] < 0.2).all()  # no goal object in a plain grey frame
    bad = tmp_path / "m"
    bad.mkdir()
    with pytest.raises(FileNotFoundError, match="Darknet"):
        load_net(str(bad))


def test_a_damaged_shipped_file_is_named(tmp_path, monkeypatch):
    import navcore.io.models as M

    folder = tmp_path / DEFAULT_MODEL
    folder.mkdir()
    for f in SHIPPED[DEFAULT_MODEL].files:
        (folder / f).write_bytes((MODELS_ROOT / DEFAULT_MODEL / f).read_bytes())
    net_file = folder / SHIPPED[DEFAULT_MODEL].network
    net_file.write_bytes(net_file.read_bytes()[:-1] + b"x")
    monkeypatch.setattr(M, "MODELS_ROOT", tmp_path)
    with pytest.raises(ValueError, match=f"{SHIPPED[DEFAULT_MODEL].network}: sha256 differs"):
        load_net(None)


@pytest.mark.skipif(not PHOTO.is_file(), reason="needs ../shared/data/real_labelled (the SUN RGB-D photo)")
@pytest.mark.parametrize("name, score, box", [("picodet_s_320_coco", 0.85, [178, 150, 643, 518]),
                                              ("yolox_nano_416_coco", 0.41, [179, 151, 661, 514])])
def test_the_shipped_onnx_detectors_box_the_bed_of_a_real_photo_as_upstream_does(name, score, box):
    """The SUN RGB-D bedroom photo: the bed at the score and box the models' own decodes give
    (../shared/models/*/README.md: PicoDet's GFL decode, YOLOX's grid decode with its letterbox)."""
    import cv2

    rgb = np.ascontiguousarray(cv2.imread(str(PHOTO))[..., ::-1])
    n, names, spec = load_net(name)
    raw = detect(n, rgb, spec.input_size, spec)
    cls = raw[:, 5:].argmax(1)
    scores = raw[:, 4] * raw[np.arange(len(raw)), 5 + cls]
    best = int(scores.argmax())
    h, w = rgb.shape[:2]
    cx, cy, bw, bh = raw[best, :4] * [w, h, w, h]
    assert names[cls[best]] == "bed" and scores[best] == pytest.approx(score, abs=0.01)
    np.testing.assert_allclose([cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2], box, atol=2)


def test_the_default_detector_and_the_thresholds_come_from_files_the_benchmark_writes():
    """Provenance: navcore/models/detector.json and each shipped model's thresholds.json say which
    benchmark wrote them, with what rule; the detector's defaults are theirs; every model the default
    names ships; a threshold is the lowest score whose pooled boxes met the stated precision."""
    import json

    from navcore.io.models import DEFAULT_DETECTOR, default_detector
    from stages.semantics.detector import model_thresholds

    doc = default_detector()
    assert "benchmarks.goals.semantics_detector --choose" in doc["about"]
    assert doc["model"] == DEFAULT_MODEL and set(doc["models"].values()) <= set(SHIPPED)
    cfg = resolved(DetectorConfig())
    assert cfg.model == doc["model"] and cfg.categories == doc["categories"] and cfg.confidence == doc["confidence"]
    assert {c: m for c, m in doc["models"].items() if m != doc["model"]} == cfg.models
    assert json.loads(DEFAULT_DETECTOR.read_text()) == doc
    for name in SHIPPED:
        t = model_thresholds(name)
        assert t["model"] == name and t["sha256"] == SHIPPED[name].files[SHIPPED[name].network]
        for cat, th in t["confidence"].items():
            right, boxes = map(int, t["counts_right_of_boxes"][cat][str(th)].split(" / "))
            assert right >= t["min_right"] and right >= t["precision"] * boxes
    # a user's own thresholds and categories win over the file's
    mine = resolved(DetectorConfig(categories=["bed"], confidence={"bed": 0.9}))
    assert mine.categories == ["bed"] and mine.confidence["bed"] == 0.9


def test_class_table_agrees_with_the_goal_vocabulary():
    from navcore.labels import GOAL_ALIASES, GOAL_CATEGORIES

    for coco, goal in COCO_TO_GOAL.items():
        assert goal in GOAL_CATEGORIES
        assert GOAL_ALIASES.get(coco, goal) == goal  # the shared alias table says the same where it knows the name
    assert "cabinet" not in COCO_TO_GOAL.values()  # COCO cannot name it
    for name in SHIPPED:
        assert set(resolved(DetectorConfig(model=name)).categories) <= set(COCO_TO_GOAL.values())


def _raw(rows):
    """Detections as the network gives them: cx, cy, w, h, objectness, 80 class scores."""
    out = np.zeros((len(rows), 85), np.float32)
    for i, (cx, cy, w, h, obj, cls, p) in enumerate(rows):
        out[i, :5] = cx, cy, w, h, obj
        out[i, 5 + cls] = p
    return out


def test_boxes_threshold_map_and_nms():
    names = COCO_NAMES
    cfg = DetectorConfig(categories=["bed", "sofa", "table"], confidence={}, model_thresholds=False)
    raw = _raw([(0.5, 0.5, 0.2, 0.4, 0.9, 57, 0.9),      # sofa (COCO's couch) 0.81
                (0.51, 0.5, 0.2, 0.4, 0.9, 57, 0.8),     # the same couch, suppressed by NMS
                (0.2, 0.2, 0.1, 0.1, 0.9, 59, 0.4),      # bed 0.36 < the threshold 0.4
                (0.6, 0.2, 0.1, 0.1, 0.9, 56, 0.9),      # chair: not allowed
                (0.8, 0.8, 0.1, 0.1, 0.9, 61, 0.9),      # toilet: not allowed
                (0.3, 0.7, 0.1, 0.2, 0.9, 0, 0.9)])      # person: not a goal
    got = boxes_of(raw, names, cfg, 320, 240)
    assert [c for c, _, _ in got] == ["sofa"]
    cat, box, score = got[0]
    assert np.allclose(box, [0.4 * 320, 0.3 * 240, 0.6 * 320, 0.7 * 240]) and score == pytest.approx(0.81, abs=1e-6)


def test_box_mask_keeps_the_nearest_depth_mode_off_the_floor():
    # camera at 1 m height looking along +x (OpenCV axes: x right, y down, z forward)
    h, w = 120, 160
    K = np.array([[100.0, 0, w / 2], [0, 100.0, h / 2], [0, 0, 1]])
    c2w = np.eye(4)
    c2w[:3, :3] = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]])  # camera z -> world x, camera y -> world -z
    c2w[2, 3] = 1.0
    depth = np.full((h, w), 4.0)  # a wall 4 m ahead
    rows = np.arange(h)[:, None] + 0.5
    floor_d = 1.0 / np.maximum((rows - K[1, 2]) / K[1, 1], 1e-6)  # rays below the horizon hit the floor
    depth = np.where((rows > K[1, 2]) & (floor_d < 4.0), floor_d, depth) * np.ones((1, w))
    obj = np.zeros((h, w), bool)
    obj[50:100, 60:100] = True  # an object 2 m ahead (its lower rows would be at the floor's depth)
    depth[obj] = 2.0
    box = np.array([50.0, 40.0, 110.0, 110.0])  # the detector's box: object, wall and floor
    m = box_mask(box, depth, K, c2w, DetectorConfig())
    assert m is not None
    assert m[obj].mean() > 0.95  # the object
    assert not m[~obj].any()  # neither the wall behind nor the floor
    whole = box_mask(box, depth, K, c2w, DetectorConfig(mask="box"))
    assert whole[40:110, 50:110].all()


def test_lifting_counts_views_and_drops_what_one_view_saw():
    from stages.semantics.lifting import vote

    # a 0.3 m cube of Gaussians, seen by 3 views; a 0.3 m false blob seen by one view only
    g = np.random.default_rng(0)
    cube = g.uniform(0, 0.3, (2000, 3)) + [1.0, 1.0, 0.2]
    blob = g.uniform(0, 0.3, (2000, 3)) + [3.0, 1.0, 0.2]
    means = np.concatenate([cube, blob])
    pts = np.concatenate([cube, cube, cube, blob])
    labels = np.zeros(len(pts), np.int64)
    frames = np.repeat([0, 1, 2, 3], 2000)
    voters: dict = {}
    cfg = LiftingConfig(min_support=1, erosion_px=0)
    cells = vote(pts, labels, cfg, frames, voters)
    assert cells and all(v for v in voters.values())
    views, agree = view_support(np.floor(cube / cfg.delta_vote).astype(np.int64), voters)
    assert views == 3 and agree == pytest.approx(1.0)

    class Frames:  # lift() takes back-projected frames; feed it points through a trivial camera
        def __iter__(self):
            for f in range(4):
                p = pts[frames == f]
                depth = np.ones((1, len(p)))
                yield depth, None, None, {0: p}

    import stages.semantics.lifting as L

    orig = L.frame_points
    L.frame_points = lambda depth, K, c2w, masks, cfg: (masks[0], np.zeros(len(masks[0]), np.int64))
    try:
        keep1 = lift(Frames(), means, LiftingConfig(min_support=1, min_cluster=10))
        keep2 = lift(Frames(), means, LiftingConfig(min_support=1, min_cluster=10, min_views=2))
    finally:
        L.frame_points = orig
    assert sorted(c["views"] for c in keep1) == [1, 3]
    assert [c["views"] for c in keep2] == [3] and np.allclose(keep2[0]["center"], cube.mean(0), atol=0.05)


def test_the_stage_runs_the_detector_end_to_end(tmp_path, make_cfg):
    """semantics.segmenter=detector on a generated scene: renders, the real network, depth masks and the
    lifting run through the stage; the instance table carries views and agreement."""
    import pyarrow.parquet as pq

    from pipeline.executor import execute

    s = execute(make_cfg(tmp_path, "stages=[semantics]", "semantics.segmenter=detector", "semantics.shipped_labels=false",
                         "semantics.detector.spacing=1.5", "semantics.detector.yaw_step_deg=90"))
    assert not s["failures"], s["failures"]
    info = next(r for r in s["results"] if r["stage"] == "semantics")
    table = pq.read_table(next(tmp_path.glob("04_semantics/*/instances.parquet")))
    assert {"views", "agreement"} <= set(table.column_names)
    assert all(v >= 4 for v in table["views"].to_pylist())  # detector.min_views
    assert set(table["category"].to_pylist()) <= set(resolved(DetectorConfig()).categories)
    assert info["status"] == "done"


def _nanodet_outputs(size: int = 416, classes: int = 80, bins: int = 11) -> dict[str, np.ndarray]:
    """NanoDet-shaped outputs (3 strides), all cells empty."""
    out = {}
    for k, stride in enumerate((8, 16, 32)):
        n = (size // stride) ** 2
        out[f"score{k}"] = np.zeros((1, n, classes), np.float32)
        out[f"reg{k}"] = np.zeros((1, n, 4 * bins), np.float32)
    return out


def test_nanodet_decoding_known_box():
    """A cell whose distributions peak at known bins decodes to the box they put around its centre,
    in a YOLO-like row the rest of the detector reads unchanged."""
    from stages.semantics.detector import gfl_raw

    outs = _nanodet_outputs()
    cell = 5 * 26 + 7  # stride 16 (26 x 26): row 5, column 7 -> centre (120, 88) pixels
    peaks = (2, 3, 4, 1)  # left, top, right, bottom in strides
    reg = np.full((4, 11), -50.0, np.float32)
    reg[np.arange(4), peaks] = 50.0
    outs["reg1"][0, cell] = reg.ravel()
    outs["score1"][0, cell, 59] = 0.8  # bed
    raw = gfl_raw(outs, 416)
    assert raw.shape == (52 * 52 + 26 * 26 + 13 * 13, 85)
    row = raw[52 * 52 + cell]
    x0, y0, x1, y1 = 120 - 2 * 16, 88 - 3 * 16, 120 + 4 * 16, 88 + 1 * 16
    np.testing.assert_allclose(row[:4] * 416, [(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0], atol=1e-3)
    assert row[4] == 1.0 and row[5 + 59] == pytest.approx(0.8)
    names = [f"c{i}" for i in range(80)]
    names[59] = "bed"
    (cat, box, score), = boxes_of(raw, names, DetectorConfig(), 416, 416)
    assert cat == "bed" and score == pytest.approx(0.8)
    np.testing.assert_allclose(box, [x0, y0, x1, y1], atol=1e-3)
    outs.pop("reg2")
    with pytest.raises(ValueError, match="pair up"):
        gfl_raw(outs, 416)


def test_model_spec_reads_the_json_beside_an_onnx_or_knows_the_release(tmp_path):
    import json

    from navcore.io.models import PICODET, YOLOX, ModelSpec, resolve

    def model_spec(model):
        return resolve(model)[2]

    assert model_spec(None) == SHIPPED[DEFAULT_MODEL].spec
    assert model_spec("yolo_fastest_1.1_coco") == ModelSpec()
    m = tmp_path / "det.onnx"
    with pytest.raises(FileNotFoundError, match="does not exist"):
        model_spec(str(m))
    m.write_bytes(b"an unknown model")
    assert model_spec(str(m)).family == "yolo"  # an ONNX with no JSON, not a known release: a YOLO export
    m.with_suffix(".json").write_text(json.dumps({"family": "nanodet", "input_size": 416}))
    assert model_spec(str(m)) == ModelSpec(family="gfl", input_size=416)
    m.with_suffix(".json").write_text(json.dumps({"family": "picodet", "input_size": 320}))
    assert model_spec(str(m)) == ModelSpec(**{**PICODET.__dict__, "input_size": 320})
    m.with_suffix(".json").write_text(json.dumps({"family": "yolox", "input_size": 416, "pad": 0}))
    assert model_spec(str(m)).pad == 0 and model_spec(str(m)).resize == YOLOX.resize
    m.with_suffix(".json").write_text(json.dumps({"family": "ssd"}))
    with pytest.raises(ValueError, match="ssd"):
        model_spec(str(m))
    m.with_suffix(".json").write_text(json.dumps({"family": "yolo", "channel": "bgr"}))
    with pytest.raises(ValueError, match="unknown keys.*channel"):
        model_spec(str(m))
    m.with_suffix(".json").unlink()
    # a copy of a published release is known by its sha256, no JSON needed
    m.write_bytes((MODELS_ROOT / DEFAULT_MODEL / SHIPPED[DEFAULT_MODEL].network).read_bytes())
    os.utime(m, ns=(1, 1))  # a rewritten file is hashed again (its size or modification time changed)
    assert model_spec(str(m)) == SHIPPED[DEFAULT_MODEL].spec
    assert model_spec(str(tmp_path)) == SHIPPED[DEFAULT_MODEL].spec  # a folder holding one ONNX file


def test_picodet_levels_include_the_7_by_7_of_stride_64():
    """PicoDet at 416 has a 4th level of ceil(416 / 64) = 7 cells a side: its cell centres are
    (x + 0.5) 64 pixels, not 416 / 7 (the stride inferred from the cell count alone)."""
    from stages.semantics.detector import gfl_raw, level_stride

    assert [level_stride(416, n) for n in (2704, 676, 169, 49)] == [8, 16, 32, 64]
    outs = {}
    for k, n in enumerate((2704, 676, 169, 49)):
        outs[f"s{k}"] = np.zeros((1, n, 80), np.float32)
        outs[f"r{k}"] = np.full((1, n, 32), -50.0, np.float32)
    cell = 3 * 7 + 5  # row 3, column 5 -> centre (352, 224)
    reg = np.full((4, 8), -50.0, np.float32)
    reg[np.arange(4), (1, 2, 3, 0)] = 50.0  # left 1, top 2, right 3, bottom 0 strides
    outs["r3"][0, cell] = reg.ravel()
    outs["s3"][0, cell, 59] = 0.9
    raw = gfl_raw(outs, 416)
    row = raw[2704 + 676 + 169 + cell]
    x0, y0, x1, y1 = 352 - 64, 224 - 128, 352 + 192, 224
    np.testing.assert_allclose(row[:4] * 416, [(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0], atol=1e-3)
    assert row[5 + 59] == pytest.approx(0.9)
    with pytest.raises(ValueError, match="no square grid"):
        level_stride(416, 50)


def test_yolox_decoding_known_box_through_the_letterbox():
    """YOLOX's raw row (dx, dy, log w, log h per stride) decodes to its box; the letterbox (top-left,
    aspect kept) maps the box back onto the frame."""
    from navcore.io.models import YOLOX
    from stages.semantics.detector import preprocess, yolox_raw

    size = 416
    out = np.zeros((1, 52 * 52 + 26 * 26 + 13 * 13, 85), np.float32)
    k = 52 * 52 + 10 * 26 + 4  # stride 16: row 10, column 4
    out[0, k, :4] = [0.5, 0.25, np.log(3.0), np.log(2.0)]  # centre (4.5, 10.25) strides, 3 x 2 strides
    out[0, k, 4], out[0, k, 5 + 59] = 0.8, 0.9
    raw = yolox_raw(out, size, (8, 16, 32))
    np.testing.assert_allclose(raw[k, :4] * size, [72, 164, 48, 32], atol=1e-3)
    assert raw[k, 4] == pytest.approx(0.8) and raw[k, 5 + 59] == pytest.approx(0.9)
    # a 640 x 480 frame: r = 0.65, the image fills 416 x 312 of the canvas, the rest is 114
    frame = np.zeros((480, 640, 3), np.uint8)
    frame[:, :, 0] = 200  # red: the network reads BGR, so channel 2
    blob, fx, fy = preprocess(frame, YOLOX, size)
    assert blob.shape == (1, 3, 416, 416) and blob[0, 2, 0, 0] == 200 and blob[0, 0, 0, 0] == 0
    assert (blob[0, :, 312:, :] == 114).all() and blob[0, 2, 311, 415] == 200
    assert fx == pytest.approx(1.0) and fy == pytest.approx(416 / 312)
    with pytest.raises(ValueError, match="3549"):
        yolox_raw(out[:, :-1], size, (8, 16, 32))


def test_picodet_preprocessing_is_rgb_with_imagenet_statistics():
    from navcore.io.models import PICODET
    from stages.semantics.detector import preprocess

    frame = np.full((48, 64, 3), (255, 0, 128), np.uint8)
    blob, fx, fy = preprocess(frame, PICODET, 32)
    expect = (np.array([1.0, 0.0, 128 / 255]) - PICODET.mean) / PICODET.std
    np.testing.assert_allclose(blob[0, :, 5, 5], expect, atol=1e-3)
    assert (fx, fy) == (1.0, 1.0)


def test_an_opencv_without_the_darknet_reader_gets_a_clear_error(monkeypatch):
    """OpenCV 5 removed readNetFromDarknet; a GPU image that brings it (the device's did, shadowing
    the pinned 4.x) must get the fix named, not an AttributeError from inside the semantics stage."""
    import cv2

    class Dnn:  # cv2.dnn as OpenCV 5 has it: an ONNX reader, no Darknet one
        readNetFromONNX = staticmethod(cv2.dnn.readNetFromONNX)

    monkeypatch.setattr(cv2, "dnn", Dnn)
    with pytest.raises(RuntimeError, match=r"no Darknet reader.*opencv-python-headless>=4.8,<5"):
        load_net("yolo_fastest_1.1_coco")
    load_net(None)  # the default is an ONNX model: OpenCV 5 reads it


def test_categories_given_to_another_model_are_boxed_by_it_alone(monkeypatch, tmp_path):
    """semantics.detector.models: each model runs once a view and keeps only its own categories;
    the view's boxes are the union (a chair from the second model, a bed from the default)."""
    import stages.semantics.detector as det
    pico = MODELS_ROOT / "picodet_s_320_coco"
    second = tmp_path / "second"  # another model's folder (a shipped ONNX model, copied)
    second.mkdir()
    for f in pico.iterdir():
        (second / f.name).write_bytes(f.read_bytes())
    names = COCO_NAMES

    def row(cls: str) -> np.ndarray:  # one confident detection of a class in the middle of the frame
        r = np.zeros(85, np.float32)
        r[:5] = [0.5, 0.5, 0.2, 0.2, 1.0]
        r[5 + names.index(cls)] = 0.9
        return r

    seen = []

    def fake_detect(net, rgb, size, spec=None):  # both models "see" a bed and a chair
        seen.append(id(net))
        return np.stack([row("bed"), row("chair")])

    monkeypatch.setattr(det, "detect", fake_detect)
    cfg = det.DetectorConfig(categories=["bed", "chair"], models={"chair": str(second)})
    seg = det.DetectorSegmenter(cfg, {"bed": "bed", "chair": "chair"})
    assert [sorted(r[4].categories) for r in seg.runs] == [["bed"], ["chair"]]
    depth = np.full((240, 320), 2.0, np.float32)
    K = np.array([[160.0, 0, 160], [0, 160.0, 120], [0, 0, 1]])
    c2w = np.eye(4)
    c2w[2, 3] = 1.0
    seg.segment(np.zeros((240, 320, 3), np.uint8), ["bed", "chair"], {"depth": depth, "K": K, "cam_to_world": c2w})
    assert sorted(b[0] for b in seg.last_boxes) == ["bed", "chair"]  # one of each, not two of each
    assert len(set(seen)) == 2  # each model ran once


def test_class_vote_merges_one_object_seen_under_two_names():
    """A sofa that some views call a bed: two overlapping instances of a confusable pair become one,
    named by the views' votes over its cells; a chair beside it and a bed elsewhere stay."""
    from stages.semantics.lifting import class_vote, voxel_keys

    g = np.random.default_rng(1)
    sofa = g.uniform(0, 1, (400, 3)) * [2.0, 0.9, 0.8] + [1.0, 1.0, 0.0]
    half_a, half_b = sofa[sofa[:, 0] < 2.2], sofa[sofa[:, 0] >= 1.8]  # overlapping halves
    far_bed = g.uniform(0, 1, (400, 3)) * [2.0, 1.6, 0.6] + [5.0, 5.0, 0.0]
    chair = g.uniform(0, 1, (200, 3)) * [0.5, 0.5, 0.9] + [1.5, 0.2, 0.0]  # touches the sofa, another pair
    voters: dict = {}
    for pts, frames in ((half_a, range(0, 3)), (half_b, range(3, 8)), (far_bed, range(8, 14)), (chair, range(14, 19))):
        for k in map(tuple, voxel_keys(pts, 0.1)):
            voters.setdefault(k, set()).update(frames)

    def inst(label, p, votes):
        return {"label": label, "center": p.mean(0), "min": p.min(0), "max": p.max(0), "support": len(p),
                "confidence": 1.0, "views": 0, "agreement": 1.0, "votes": votes, "points": p}

    BED, SOFA, CHAIR = 0, 1, 2
    out = class_vote([inst(BED, half_a, 30), inst(SOFA, half_b, 50), inst(BED, far_bed, 99), inst(CHAIR, chair, 40)],
                     [[BED, SOFA]], 0.3, voters, 0.1)
    assert sorted(o["label"] for o in out) == [BED, SOFA, CHAIR]
    merged = next(o for o in out if o["label"] == SOFA)
    assert merged["label_votes"] == {BED: 30, SOFA: 50} and merged["support"] == len(half_a) + len(half_b)
    assert merged["views"] == 8  # the views of both halves: each alone had too few for min_views 4
    np.testing.assert_allclose(merged["min"], np.minimum(half_a.min(0), half_b.min(0)))
    # no groups: nothing merges
    assert len(class_vote([inst(BED, half_a, 30), inst(SOFA, half_b, 50)], [], 0.3, voters, 0.1)) == 2


def test_a_rechosen_default_detector_changes_the_semantics_hash(tmp_path, monkeypatch, make_cfg):
    """The default detector lives in files (detector.json, thresholds.json) the benchmark rewrites: the
    semantics stage hashes what they resolve to, so a re-chosen default recomputes the detector's scenes
    (it was cached before) and leaves the oracle's alone."""
    import json

    import navcore.io.models as M
    from pipeline.graph import config_hashes

    det = make_cfg(tmp_path, "semantics.segmenter=detector")
    oracle = make_cfg(tmp_path, "semantics.segmenter=oracle")
    before, before_oracle = config_hashes(det)["semantics"], config_hashes(oracle)["semantics"]
    doc = json.loads(M.DEFAULT_DETECTOR.read_text())
    doc["confidence"]["bed"] = 0.95
    moved = tmp_path / "detector.json"
    moved.write_text(json.dumps(doc))
    monkeypatch.setattr(M, "DEFAULT_DETECTOR", moved)
    assert config_hashes(det)["semantics"] != before
    assert config_hashes(oracle)["semantics"] == before_oracle
