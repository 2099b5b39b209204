"""Semantic lifting core: back-projection, voting rules, instances from multi-view masks."""
import math

import numpy as np
import pytest

from stages.render.camera import camera_to_world, intrinsics
from stages.semantics.lifting import LiftingConfig, back_project, lift, vote

W, H = 160, 120


def test_back_projection_known_answer():
    K = intrinsics(W, H, 90)
    c2w = camera_to_world(1.0, 2.0, 0.0, 0.5)  # at (1, 2, 0.5) looking along +x
    depth = np.full((H, W), 2.0)
    p = back_project(depth, K, c2w, np.array([[H // 2 - 1, W // 2 - 1]]))  # pixel centre 0.5 px off axis
    f = K[0, 0]
    assert p[0] == pytest.approx([1.0 + 2.0, 2.0 + 0.5 / f * 2.0, 0.5 + 0.5 / f * 2.0])


def test_voting_majority_support_and_ties():
    cfg = LiftingConfig(delta_vote=1.0, min_support=3)
    pts = np.array([[0.1, 0.1, 0.1]] * 5 + [[1.5, 0.1, 0.1]] * 4 + [[2.5, 0.1, 0.1]] * 2, float)
    labs = np.array([1, 1, 1, 2, 2] + [1, 1, 2, 2] + [3, 3])
    cells = vote(pts, labs, cfg)
    assert cells[(0, 0, 0)] == (1, 5, pytest.approx(0.6))
    assert (1, 0, 0) not in cells  # a tie
    assert (2, 0, 0) not in cells  # too little support
    assert (1, 0, 0) in vote(pts, labs, LiftingConfig(delta_vote=1.0, min_support=3, exclude_ties=False))


def box_points(centre, size, n, rng):
    """Points on the surface of an axis-aligned box."""
    p = rng.uniform(-0.5, 0.5, (n, 3))
    ax = rng.integers(3, size=n)
    p[np.arange(n), ax] = np.sign(p[np.arange(n), ax]) * 0.5
    return np.asarray(centre) + p * np.asarray(size)


def synthetic_frames(points, labels, poses, K):
    """Depth and per-label masks by z-buffered point splats (a stand-in renderer)."""
    frames = []
    for (x, y, yaw) in poses:
        c2w = camera_to_world(x, y, yaw, 0.6)
        w2c = np.linalg.inv(c2w)
        pc = points @ w2c[:3, :3].T + w2c[:3, 3]
        ok = pc[:, 2] > 0.1
        u = np.floor(K[0, 0] * pc[ok, 0] / pc[ok, 2] + K[0, 2]).astype(int)
        v = np.floor(K[1, 1] * pc[ok, 1] / pc[ok, 2] + K[1, 2]).astype(int)
        z, lab = pc[ok, 2], labels[ok]
        inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        depth = np.full((H, W), np.inf)
        labimg = np.zeros((H, W), int)
        for uu, vv, zz, ll in zip(u[inside], v[inside], z[inside], lab[inside]):
            for du in (0, 1):  # 2x2 splats: no holes at this density
                for dv in (0, 1):
                    a, b = min(vv + dv, H - 1), min(uu + du, W - 1)
                    if zz < depth[a, b]:
                        depth[a, b], labimg[a, b] = zz, ll
        depth[np.isinf(depth)] = 0
        frames.append((depth, K, c2w, {k: labimg == k for k in (1, 2)}))
    return frames


def test_lifting_finds_each_object_once_at_its_centre():
    rng = np.random.default_rng(0)
    chair = box_points((2.0, 0.0, 0.4), (0.5, 0.5, 0.8), 4000, rng)
    table = box_points((2.5, 1.5, 0.35), (1.0, 0.6, 0.7), 6000, rng)
    floor = np.column_stack([rng.uniform(0, 4, 8000), rng.uniform(-1, 3, 8000), np.zeros(8000)])
    means = np.concatenate([chair, table, floor])
    labels = np.concatenate([np.full(4000, 1), np.full(6000, 2), np.zeros(8000, int)])
    K = intrinsics(W, H, 90)
    # around the objects, so that every side face is seen and links the front and back faces
    poses = [(0.0, 0.5, a) for a in np.linspace(-0.6, 0.9, 6)] + [(4.5, 0.5, math.pi + a) for a in (-0.4, 0.0, 0.4)]
    poses += [(2.0, -1.6, math.pi / 2 + a) for a in (-0.4, 0.0, 0.4)] + [(2.5, 3.2, -math.pi / 2)]
    found = lift(synthetic_frames(means, labels, poses, K), means, LiftingConfig())
    by = {}
    for f in found:
        by.setdefault(f["label"], []).append(f)
    assert set(by) == {1, 2} and len(by[1]) == 1 and len(by[2]) == 1
    assert np.hypot(*(by[1][0]["center"][:2] - (2.0, 0.0))) < 0.2
    assert np.hypot(*(by[2][0]["center"][:2] - (2.5, 1.5))) < 0.25
    assert all(0.5 < f["confidence"] <= 1.0 for f in found)
