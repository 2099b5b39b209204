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


def _canonical(s):
    return s.gaussians.transformed(np.linalg.inv(s.transform))


def test_the_look_changes_colours_only_and_adds_the_ceiling_and_details_after():
    """synthetic.look (materials, painted details, light) recolours the Gaussians of a seed without
    moving one: positions, shapes, opacities and instances are those of the flat scene. The ceiling's
    and the furniture details' Gaussians come after them: the ceiling at the walls' top facing down
    (structure), details inside the rooms, those on a goal object inside its box; the goal objects and
    their boxes are the flat scene's, and the same seed gives the same scene again."""
    from navcore.gaussians.model import quat_to_rotmat
    from stages.synthesize.materials import LookConfig

    off = LookConfig(enabled=False, ceiling=False, furnish=False)
    flat = generate_scene(3, SyntheticConfig(num_gaussians=30_000, look=off))
    dressed = generate_scene(3, SyntheticConfig(num_gaussians=30_000))
    again = generate_scene(3, SyntheticConfig(num_gaussians=30_000))
    n = len(flat.gaussians)
    a, b = _canonical(flat), _canonical(dressed)
    for key in ("means", "quats", "log_scales", "opacity_logits"):
        assert np.array_equal(getattr(flat.gaussians, key), getattr(dressed.gaussians, key)[:n]), key
    assert np.array_equal(flat.instance_ids, dressed.instance_ids[:n])
    assert not np.allclose(flat.gaussians.sh[:n], dressed.gaussians.sh[:n])
    assert np.array_equal(dressed.gaussians.sh, again.gaussians.sh)
    h = dressed.layout.wall_height
    assert a.means[:, 2].max() < h + 0.01  # the flat scene had nothing above the walls
    extra, ids = b.means[n:], dressed.instance_ids[n:]
    top = extra[:, 2] > h - 0.01
    assert top.sum() > 0.1 * n and (ids[top] == 0).all() and np.abs(extra[top, 2] - h).max() < 0.01
    assert (quat_to_rotmat(b.quats[n:][top])[:, 2, 2] < -0.9).all()  # the ceiling faces the rooms below
    assert (~top).sum() > 0 and extra[~top, 2].max() < h - 0.3  # details: below the ceiling
    objects = {o.instance_id: o for o in dressed.layout.objects}
    assert [o.category for o in flat.layout.objects] == [o.category for o in dressed.layout.objects]
    for k, o in objects.items():  # a detail on a goal object stays inside the object's box
        lo, hi = o.aabb()
        pts = extra[ids == k]
        assert (pts >= lo - 0.02).all() and (pts <= hi + 0.02).all(), o.category


def test_dressed_surfaces_carry_texture_and_windows_are_bright():
    """Every room's floor and walls vary in colour far more than the flat scene's one colour plus
    noise, and a window's Gaussians are brighter than the wall around them."""
    from navcore.gaussians.model import quat_to_rotmat
    from stages.synthesize.materials import LookConfig, dress, plan_rooms

    s = generate_scene(4, SyntheticConfig(num_gaussians=40_000, look=LookConfig(enabled=False, ceiling=False,
                                                                                 furnish=False)))
    g = _canonical(s)
    normals = quat_to_rotmat(g.quats)[:, :, 2]
    surf = s.instance_ids >= 0
    cfg = LookConfig(windows_per_room=(2, 2), colour_noise=0.0)
    rgb = dress(s.layout, g.means[surf], normals[surf], s.instance_ids[surf], np.random.default_rng(9), cfg)
    flat_rgb = np.clip(g.colors[surf], 0, 1)
    floor = (s.instance_ids[surf] == 0) & (g.means[surf][:, 2] < 0.01)
    assert rgb[floor].std(0).mean() > 0.05  # textures, light and rugs: not one colour
    assert rgb[floor].std(0).mean() > 2 * flat_rgb[floor].std(0).mean()
    looks = plan_rooms(s.layout, np.random.default_rng(9), cfg)
    windows = [d for look in looks for _, d in look.decals if d.kind == "window"]
    assert windows and all(d.colour.min() > 0.8 for d in windows)


def test_every_objectnav_category_is_placed_by_the_default_layout():
    """The goal objects' categories keep their labels through the new world's furniture: over 40
    seeds of the default layout every ObjectNav category is placed, in at least a tenth of the scenes
    (the default dataset's ObjectNav episodes then cover every category a scene holds: test_episodes)."""
    from navcore.nav.tasks import OBJECTNAV_CATEGORIES
    from stages.synthesize.layout import make_layout

    cfg = SyntheticConfig()
    seen = {c: 0 for c in OBJECTNAV_CATEGORIES}
    for seed in range(40):
        for cat in {o.category for o in make_layout(np.random.default_rng(seed), cfg.layout).objects}:
            seen[cat] += 1
    assert set(CATEGORIES) == set(OBJECTNAV_CATEGORIES)
    assert min(seen.values()) >= 4, seen
