"""Renderer-backed observation datasets over a stored run: frames equal the environment's own
rendering at the same poses, the expert's actions ride along, filters and shuffling hold."""
import numpy as np
import pandas as pd
import pytest
import torch

from navarena.observations import ExpertObservations, ExpertObservationStream


@pytest.fixture(scope="module")
def stream_args(episode_run):
    root, _, _ = episode_run
    return root, dict(tasks=["pointnav"], stride=7, width=32, height=24, renderer="cpu", episodes_per_scene=3)


def test_stream_frames_match_the_environment_render_and_carry_expert_actions(stream_args):
    from navcore.gaussians.content import without_splats
    from navcore.io.catalog import Catalog
    from navcore.nav.embodiment import Embodiment
    from navcore.render import Renderer
    from navcore.render.camera import embodiment_camera

    root, kw = stream_args
    batches = list(ExpertObservationStream(root, batch_size=10, **kw))
    n = sum(len(b["rgb"]) for b in batches)
    tr = pd.read_parquet(root / "06_trajectories" / "task=pointnav")
    eps = sorted(set(tr["episode_id"]))[:3]
    sel = tr[tr["episode_id"].isin(eps)]
    last = sel.groupby("episode_id")["step"].transform("max")
    assert n == int(((sel["step"] % 7 == 0) | (sel["step"] == last)).sum())  # stride, last step kept
    b = batches[0]
    assert b["rgb"].dtype == torch.uint8 and b["rgb"].shape[1:] == (24, 32, 3) and b["depth"].shape[1:] == (24, 32)
    # an independent path: the scene's renderer at the stored poses
    cat = Catalog.for_root(root)
    sid = b["scene_id"][0]
    gs, _ = cat.dataset("aligned", cat.scene(sid)).load()
    gs = without_splats(gs, cat.dataset("costmaps", cat.scene(sid)).hidden("locobot"))  # less the hidden noise
    vm, k, w, h = embodiment_camera(Embodiment(), b["pose"].numpy().astype(np.float64), 32, 24)
    ref = Renderer(gs, "cpu").render(vm, k, w, h)
    assert torch.equal(b["rgb"], (ref.rgb * 255 + 0.5).clamp(0, 255).to(torch.uint8))
    assert torch.allclose(b["depth"], ref.depth)
    row = sel[(sel["episode_id"] == b["episode_id"][1]) & (sel["step"] == int(b["step"][1]))].iloc[0]
    assert b["velocity"][1].tolist() == pytest.approx([row["linear_velocity"], row["angular_velocity"]], abs=1e-6)
    assert b["waypoint"][1].tolist() == pytest.approx([row["dx"], row["dy"], row["dyaw"]], abs=1e-6)
    assert b["pose"][1].tolist() == pytest.approx([row["position_x"], row["position_y"], row["yaw"]], abs=1e-5)


def test_shuffle_is_seeded_and_the_map_style_dataset_agrees(stream_args):
    root, kw = stream_args
    a = [b["step"].tolist() for b in ExpertObservationStream(root, batch_size=8, shuffle=True, seed=3, **kw)]
    b = [b["step"].tolist() for b in ExpertObservationStream(root, batch_size=8, shuffle=True, seed=3, **kw)]
    plain = [b["step"].tolist() for b in ExpertObservationStream(root, batch_size=8, **kw)]
    assert a == b and a != plain and sorted(sum(a, [])) == sorted(sum(plain, []))
    ds = ExpertObservations(root, **kw)
    idx = [5, 0, 3]
    many = ds.__getitems__(idx)
    for i, m in zip(idx, many):
        one = ds[i]
        assert torch.equal(one["rgb"], m["rgb"]) and one["episode_id"] == m["episode_id"]
    dl = torch.utils.data.DataLoader(ds, batch_size=4, shuffle=True, generator=torch.Generator().manual_seed(0))
    batch = next(iter(dl))
    assert batch["rgb"].shape == (4, 24, 32, 3) and len(batch["episode_id"]) == 4
    assert len(ExpertObservations(root, split="no_such_split", **kw)) == 0
