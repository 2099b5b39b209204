"""benchmarks.baselines.goal_ablation: one episode per goal, the decoys it runs (navcore.eval.decoy),
and the report's paired counts are the episodes' own."""
from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.baselines.goal_ablation import one_per_goal, report
from navcore.eval.decoy import decoy_for


def test_the_report_pairs_episodes():
    rows = {"goal": [{"scene_id": "s", "episode_id": str(i), "sr": float(i < 6), "spl": 0.5 * (i < 6), "steps": 10,
                      "path_length": 2.0} for i in range(10)],
            "decoy": [{"scene_id": "s", "episode_id": str(i), "sr": float(i in (0, 9)), "spl": 0.0, "steps": 20,
                       "path_length": 4.0} for i in range(10)]}
    rep = report(rows, {"goal": 1.0, "decoy": 2.0}, {})
    assert rep["episodes"] == 10
    assert rep["variants"]["goal"]["sr"] == 0.6 and rep["variants"]["decoy"]["sr"] == 0.2
    pair = rep["pairs"]["goal/decoy"]
    assert pair["only_goal"] == 5 and pair["only_decoy"] == 1
    assert pair["sign_test_p"] == pytest.approx(0.21875)  # two-sided binomial, 5 of 6


def test_decoys_come_from_another_goal():
    """Episodes sharing a goal: one per goal is kept, and each decoy is the farthest other goal."""
    def ep(i, x, y):
        return SimpleNamespace(episode_id=f"e{i}", task="imagenav", goal_xy=np.array([x, y]), goal_pose=np.array([x, y, 0.5]))

    pool = [ep(0, 0, 0), ep(1, 0, 0), ep(2, 3, 0), ep(3, 3, 0), ep(4, 0, 5), ep(5, 1, 1)]
    kept = one_per_goal(pool, 3)
    assert [e.episode_id for e in kept] == ["e0", "e2", "e4"]
    decoys = {e.episode_id: decoy_for(e, pool) for e in kept}
    assert [decoys[k].episode_id for k in ("e0", "e2", "e4")] == ["e4", "e4", "e2"]
    for e in kept:
        assert not np.allclose(decoys[e.episode_id].goal_xy, e.goal_xy)
    assert decoy_for(ep(9, 0, 0), [ep(0, 0, 0), ep(1, 0, 0)]) is None  # one goal in the scene: no decoy


def test_an_objectnav_decoy_is_another_category():
    """ObjectNav: one episode per category, each decoy the farthest episode of another category."""
    def ep(i, cat, x):
        return SimpleNamespace(episode_id=f"e{i}", task="objectnav", category=cat, goal_xy=np.array([x, 0.0]),
                               goal_pose=np.array([x, 0.0, 0.0]))

    pool = [ep(0, "chair", 0), ep(1, "chair", 9), ep(2, "bed", 1), ep(3, "sofa", 6), ep(4, "bed", 4)]
    kept = one_per_goal(pool, 5)
    assert [e.category for e in kept] == ["chair", "bed", "sofa"]
    assert {e.episode_id: decoy_for(e, pool).category for e in kept} == {"e0": "sofa", "e2": "chair", "e3": "chair"}


def test_stop_sites_tell_a_stop_beside_another_category_from_a_success():
    """benchmarks.baselines.stop_sites on hand-made ends: distances to boxes (0 inside), the false
    stops' median distance to a goal and the shares beside another category's object."""
    from benchmarks.baselines.stop_sites import stop_sites
    from navcore.nav.poses import region_distance  # the distance stop_sites measures

    boxes = [[1, -1, 2, 1], [-1, -1, 1, 1], [3, 4, 5, 5]]
    assert np.allclose([region_distance((0.0, 0.0), [b])[0] for b in boxes], [1.0, 0.0, 5.0])
    goal, sofa = np.array([[0.0, 0.0, 1.0, 1.0]]), np.array([[6.0, 0.0, 7.0, 1.0]])
    ends = [{"sr": 1.0, "end_reason": "stop", "xy": (1.5, 0.5), "goal_boxes": goal, "other_boxes": sofa},
            {"sr": 0.0, "end_reason": "stop", "xy": (5.5, 0.5), "goal_boxes": goal, "other_boxes": sofa},  # beside the sofa
            {"sr": 0.0, "end_reason": "stop", "xy": (4.0, 3.0), "goal_boxes": goal, "other_boxes": sofa},
            {"sr": 0.0, "end_reason": "budget", "xy": (6.5, 0.5), "goal_boxes": goal, "other_boxes": sofa}]
    rep = stop_sites(ends, beside=1.0)
    assert (rep["successes"], rep["false_stops"]) == (1, 2)
    assert rep["false_stop_goal_distance_median_m"] == round(float(np.median([4.5, np.hypot(3.0, 2.0)])), 2)
    assert rep["false_stops_beside_another_category_1m"] == 0.5 and rep["successes_beside_another_category_1m"] == 0.0
