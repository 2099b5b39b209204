"""The `detector` segmenter (issue 47): the shipped real weights, the class table, box -> mask by
depth, and the lifting's multi-view support."""
from __future__ import annotations

import numpy as np
import pytest

from navcore.io.models import MODEL_FILES, load_net
from stages.semantics.detector import COCO_TO_GOAL, DetectorConfig, box_mask, boxes_of, detect
from stages.semantics.lifting import LiftingConfig, lift, view_support


@pytest.fixture(scope="module")
def net():
    return load_net(None)


def test_shipped_weights_load_and_are_the_published_ones(net, tmp_path):
    n, names = net
    assert len(names) == 80 and names[56] == "chair" and names[57] == "sofa"  # Darknet's spelling of couch
    mapped = {COCO_TO_GOAL[n] for n in names if n in COCO_TO_GOAL}
    assert mapped == set(COCO_TO_GOAL.values())  # every goal of the table is reachable with the shipped names
    out = detect(n, np.zeros((240, 320, 3), np.uint8), 320)
    assert out.shape[1] == 85 and len(out) == 300 + 1200  # two heads: 10 x 10 and 20 x 20 cells, 3 anchors
    assert (out[:, 4] * out[:, 5:].max(1) < 0.2).all()  # nothing in a black frame
    bad = tmp_path / "m"
    bad.mkdir()
    with pytest.raises(FileNotFoundError, match="Darknet"):
        load_net(str(bad))
    assert len(MODEL_FILES) == 3


def test_class_table_agrees_with_the_goal_vocabulary():
    from navcore.labels import GOAL_ALIASES, GOAL_CATEGORIES

    for coco, goal in COCO_TO_GOAL.items():
        assert goal in GOAL_CATEGORIES
        assert GOAL_ALIASES.get(coco, goal) == goal  # the shared alias table says the same where it knows the name
    assert "cabinet" not in COCO_TO_GOAL.values()  # COCO cannot name it
    assert set(DetectorConfig().categories) <= set(COCO_TO_GOAL.values())
    assert not {"toilet", "chair"} & set(DetectorConfig().categories)  # off by default: measured precision


def _raw(rows):
    """Detections as the network gives them: cx, cy, w, h, objectness, 80 class scores."""
    out = np.zeros((len(rows), 85), np.float32)
    for i, (cx, cy, w, h, obj, cls, p) in enumerate(rows):
        out[i, :5] = cx, cy, w, h, obj
        out[i, 5 + cls] = p
    return out


def test_boxes_threshold_map_and_nms(net):
    _, names = net
    cfg = DetectorConfig()
    raw = _raw([(0.5, 0.5, 0.2, 0.4, 0.9, 57, 0.9),      # sofa (COCO's couch) 0.81
                (0.51, 0.5, 0.2, 0.4, 0.9, 57, 0.8),     # the same couch, suppressed by NMS
                (0.2, 0.2, 0.1, 0.1, 0.9, 59, 0.4),      # bed 0.36 < the threshold 0.4
                (0.6, 0.2, 0.1, 0.1, 0.9, 56, 0.9),      # chair: off by default
                (0.8, 0.8, 0.1, 0.1, 0.9, 61, 0.9),      # toilet: not allowed by default
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
    assert set(table["category"].to_pylist()) <= set(DetectorConfig().categories)
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
    from stages.semantics.detector import nanodet_raw

    outs = _nanodet_outputs()
    cell = 5 * 26 + 7  # stride 16 (26 x 26): row 5, column 7 -> centre (120, 88) pixels
    peaks = (2, 3, 4, 1)  # left, top, right, bottom in strides
    reg = np.full((4, 11), -50.0, np.float32)
    reg[np.arange(4), peaks] = 50.0
    outs["reg1"][0, cell] = reg.ravel()
    outs["score1"][0, cell, 59] = 0.8  # bed
    raw = nanodet_raw(outs, 416)
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
        nanodet_raw(outs, 416)


def test_model_spec_reads_the_json_beside_an_onnx(tmp_path):
    import json

    from navcore.io.models import model_spec

    assert model_spec(None) == {"family": "yolo", "input_size": None}
    m = tmp_path / "det.onnx"
    assert model_spec(str(m))["family"] == "yolo"  # an ONNX with no JSON: a YOLO export
    m.with_suffix(".json").write_text(json.dumps({"family": "nanodet", "input_size": 416}))
    assert model_spec(str(m)) == {"family": "nanodet", "input_size": 416}
    m.with_suffix(".json").write_text(json.dumps({"family": "ssd"}))
    with pytest.raises(ValueError, match="ssd"):
        model_spec(str(m))


def test_an_opencv_without_the_darknet_reader_gets_a_clear_error(monkeypatch):
    """OpenCV 5 removed readNetFromDarknet; a GPU image that brings it (the device's did, shadowing
    the pinned 4.x) must get the fix named, not an AttributeError from inside the semantics stage."""
    import cv2

    class Dnn:  # cv2.dnn as OpenCV 5 has it: an ONNX reader, no Darknet one
        readNetFromONNX = staticmethod(cv2.dnn.readNetFromONNX)

    monkeypatch.setattr(cv2, "dnn", Dnn)
    with pytest.raises(RuntimeError, match=r"no Darknet reader.*opencv-python-headless>=4.8,<5"):
        load_net(None)


def test_categories_given_to_another_model_are_boxed_by_it_alone(monkeypatch, tmp_path):
    """semantics.detector.models: each model runs once a view and keeps only its own categories;
    the view's boxes are the union (a chair from the second model, a bed from the default)."""
    import stages.semantics.detector as det
    from navcore.io.models import MODEL_DIR

    second = tmp_path / "second"  # another Darknet folder (the shipped files, copied)
    second.mkdir()
    for f in MODEL_DIR.iterdir():
        (second / f.name).write_bytes(f.read_bytes())
    names = [n.strip() for n in (MODEL_DIR / "coco.names").read_text().splitlines() if n.strip()]

    def row(cls: str) -> np.ndarray:  # one confident detection of a class in the middle of the frame
        r = np.zeros(85, np.float32)
        r[:5] = [0.5, 0.5, 0.2, 0.2, 1.0]
        r[5 + names.index(cls)] = 0.9
        return r

    seen = []

    def fake_detect(net, rgb, size, family="yolo"):  # both models "see" a bed and a chair
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
