"""The procedural generator and its ground truth."""
import numpy as np

from navcore.gaussians.formats import read_gaussians
from navcore.io.datasets import SyntheticSourceDataset
from stages.synthesize.generate import SyntheticConfig, generate_scene, load_ground_truth, write_synthetic
from stages.synthesize.layout import CATEGORIES


def test_same_seed_same_scene_other_seed_other_scene():
    a = generate_scene(5, SyntheticConfig(num_gaussians=20_000))
    b = generate_scene(5, SyntheticConfig(num_gaussians=20_000))
    c = generate_scene(6, SyntheticConfig(num_gaussians=20_000))
    assert np.array_equal(a.gaussians.means, b.gaussians.means) and np.array_equal(a.transform, b.transform)
    assert not np.array_equal(a.transform, c.transform)


def test_ground_truth_is_consistent_with_the_gaussians(tmp_path, small_scene):
    s = small_scene
    write_synthetic(tmp_path, s, "t")
    gt = load_ground_truth(tmp_path)
    src = read_gaussians(SyntheticSourceDataset(tmp_path).source_file)
    assert len(src) == len(gt["instance_ids"]) == len(s.gaussians)
    t = gt["canonical_to_source"]
    assert np.allclose(t[:3, :3] @ t[:3, :3].T, np.eye(3)) and np.linalg.det(t[:3, :3]) > 0
    tilt = np.degrees(np.arccos(t[2, 2]))
    assert tilt <= 20.0 + 1e-9
    # back in the canonical frame every object's Gaussians lie in its box (+ 3 sigma of spread)
    canon = (src.means.astype(float) - t[:3, 3]) @ t[:3, :3]
    assert len(gt["objects"]) >= 2 * len(gt["floor"]["rooms"])
    for o in gt["objects"]:
        assert o["category"] in CATEGORIES
        pts = canon[gt["instance_ids"] == o["instance_id"]]
        assert len(pts) > 50
        assert (pts >= np.array(o["aabb_min"]) - 0.02).all() and (pts <= np.array(o["aabb_max"]) + 0.02).all()
    # structure: the floor Gaussians sit at z = 0 in the canonical frame
    floor = canon[(gt["instance_ids"] == 0) & (np.abs(canon[:, 2]) < 0.01)]
    assert len(floor) > 1000 and np.abs(floor[:, 2]).max() < 0.01
    # the mesh holds one face label per face and covers every object
    assert len(gt["face_instance"]) == len(gt["mesh"].faces)
    assert set(np.unique(gt["face_instance"])) == {0} | {o["instance_id"] for o in gt["objects"]}
    labels = SyntheticSourceDataset(tmp_path).read_ground_truth("labels.json")["labels"]
    assert {lab["source"] for lab in labels} == {"ground_truth"} and len(labels) == len(gt["objects"])
    assert len(gt["cameras"]["poses"]) > 8
