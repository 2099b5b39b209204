"""LeRobot export: a split of a stored run, loaded back with the lerobot package's own
LeRobotDataset (CPU renderer, a few tiny episodes)."""
import hashlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from benchmarks.gpu.render_gpu import psnr


def _lerobot():
    """lerobot's LeRobotDataset (its test requests conftest's torchvision_shim)."""
    pytest.importorskip("torchcodec", reason="torchcodec needs FFmpeg 5 shared libraries (scripts/system_packages.sh)")
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset


@pytest.fixture(scope="module")
def exported(episode_run, tmp_path_factory):
    from navarena.lerobot import export_lerobot

    root, _, _ = episode_run
    out = tmp_path_factory.mktemp("lerobot") / "navarena_train"
    res = export_lerobot(root, out, split="train", tasks=["pointnav", "objectnav"], fps=5, width=48, height=36,
                         episodes_per_scene=2, renderer="cpu", episodes_per_file=3)
    return root, out, res


def test_a_user_loads_the_export_in_a_fresh_interpreter(exported):
    """As a user does: a new interpreter of the venv, lerobot's own class, no test fixture (the
    venv's start-up hook from make setup lets torchvision load next to the CPU torch)."""
    import subprocess
    import sys

    _lerobot()
    _, out, res = exported
    code = ("from lerobot.datasets.lerobot_dataset import LeRobotDataset\n"
            f"ds = LeRobotDataset('navarena/test_train', root={str(out)!r})\n"
            "print(ds.num_episodes, len(ds), tuple(ds[0]['observation.images.rgb'].shape))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.split("\n")[-2] == f"{res['episodes']} {res['frames']} (3, 36, 48)"


def test_lerobot_dataset_class_loads_the_export(exported, torchvision_shim):
    from navcore.io.catalog import Catalog
    from navcore.nav.embodiment import Embodiment
    from navcore.render import Renderer
    from navcore.render.camera import embodiment_camera

    root, out, res = exported
    LeRobotDataset = _lerobot()
    ds = LeRobotDataset("navarena/test_train", root=out)
    assert ds.num_episodes == res["episodes"] == 4 and len(ds) == res["frames"]
    assert ds.fps == 5 and set(ds.meta.video_keys) == {"observation.images.rgb"}
    assert len(list((out / "data/chunk-000").glob("*.parquet"))) == 2  # 3 episodes a file
    meta = pd.read_parquet(out / "meta/episodes/chunk-000/file-000.parquet")
    cat = Catalog.for_root(root)
    for ep in range(ds.num_episodes):
        m = meta.iloc[ep]
        lo, hi = int(m["dataset_from_index"]), int(m["dataset_to_index"])
        items = [ds[i] for i in range(lo, hi)]
        assert [int(it["frame_index"]) for it in items] == list(range(hi - lo))
        task = m["navarena/task"]
        assert items[0]["task"] == ("Navigate to the point goal." if task == "pointnav" else items[0]["task"])
        if task == "objectnav":
            assert items[0]["task"].startswith("Navigate to the ") and items[0]["task"] != "Navigate to the point goal."
        # the trajectory at 5 Hz: every 4th stored 20 Hz row and the last
        tr = cat.dataset("trajectories", cat.scene(m["navarena/scene_id"]), task=task).load().to_pandas()
        tr = tr[tr["episode_id"] == m["navarena/episode_id"]].sort_values("step")
        steps = tr["step"].to_numpy()
        keep = tr[(steps % 4 == 0) | (steps == steps[-1])]
        state = torch.stack([it["observation.state"] for it in items]).numpy()
        assert np.allclose(state, keep[["position_x", "position_y", "yaw"]].to_numpy(), atol=1e-5)
        # waypoint actions integrate to the next state; the last frame's is zero
        wp = torch.stack([it["action.waypoint"] for it in items]).numpy().astype(np.float64)
        x, y, yaw = state[:-1, 0], state[:-1, 1], state[:-1, 2]
        nx = x + np.cos(yaw) * wp[:-1, 0] - np.sin(yaw) * wp[:-1, 1]
        ny = y + np.sin(yaw) * wp[:-1, 0] + np.cos(yaw) * wp[:-1, 1]
        assert np.allclose(np.stack([nx, ny], 1), state[1:, :2], atol=1e-4) and not wp[-1].any()
        assert np.allclose(np.angle(np.exp(1j * (yaw + wp[:-1, 2] - state[1:, 2]))), 0, atol=1e-4)
        v = torch.stack([it["action"] for it in items]).numpy()
        assert (np.abs(v[:, 0]) <= Embodiment().max_linear_velocity + 1e-5).all()
    # pixels: H.264 of the CPU render (PSNR), depth exact
    it = ds[3]
    gs, _ = cat.dataset("aligned", cat.scene(meta.iloc[0]["navarena/scene_id"])).load()
    vm, k, w, h = embodiment_camera(Embodiment(), it["observation.state"].numpy()[None].astype(np.float64), 48, 36)
    ref = Renderer(gs, "cpu").render(vm, k, w, h)
    rgb = it["observation.images.rgb"].permute(1, 2, 0).numpy()  # float [0, 1], CHW from the decoder
    assert psnr(rgb, ref.rgb[0].numpy()) > 30
    assert torch.equal(it["observation.depth"][..., 0], ref.depth[0])
    # action chunks through lerobot's own delta_timestamps
    chunked = LeRobotDataset("navarena/test_train", root=out, delta_timestamps={"action": [0.0, 0.2, 0.4]})
    a = chunked[0]
    assert a["action"].shape == (3, 2) and torch.equal(a["action"][1], ds[1]["action"])


def test_lerobot_export_is_deterministic(exported, tmp_path):
    from navarena.lerobot import export_lerobot

    root, out, _ = exported
    again = tmp_path / "again"
    export_lerobot(root, again, split="train", tasks=["pointnav", "objectnav"], fps=5, width=48, height=36,
                   episodes_per_scene=2, renderer="cpu", episodes_per_file=3)
    digest = lambda d: {str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest()  # noqa: E731
                        for p in sorted(d.rglob("*")) if p.is_file()}
    assert any(f.endswith(".mp4") for f in digest(out))
    assert digest(again) == digest(out)
    with pytest.raises(ValueError, match="divide"):
        export_lerobot(root, tmp_path / "x", fps=3)
    with pytest.raises(ValueError, match="no episodes"):
        export_lerobot(root, tmp_path / "y", split="no_such_split", renderer="cpu")
    assert not (tmp_path / "y").exists()


def test_episodes_in_total_round_robin(exported, tmp_path):
    """--episodes N: N in total over the scenes and tasks (a first try of a big split)."""
    from navarena.lerobot import export_lerobot
    from navcore.render.frames import round_robin

    assert round_robin({"a": 5, "b": 1, "c": 0}, 4) == {"a": 3, "b": 1}
    assert round_robin({"a": 2, "b": 1}, 10) == {"a": 2, "b": 1}
    root, _, _ = exported
    res = export_lerobot(root, tmp_path / "three", split="train", tasks=["pointnav", "objectnav"], fps=5, width=48,
                         height=36, renderer="cpu", episodes=3)
    assert res["episodes"] == 3


# A process that compiles the CPU renderer cold (an empty numba cache) and then encodes the frames.
_ENCODE_AFTER_COLD_COMPILE = """
import sys
from pathlib import Path
import numpy as np
from navcore.io.video import H264Writer
from navcore.gaussians.model import GaussianScene
from navcore.render import Renderer
from navcore.render.camera import intrinsics, viewmats
r = np.random.default_rng(0)
n = 500
gs = GaussianScene(np.column_stack([r.uniform(1.5, 6, n), r.uniform(-3, 3, n), r.uniform(-2, 2, n)]),
                   r.normal(size=(n, 4)), np.log(r.uniform(0.02, 0.3, (n, 3))), r.uniform(-2, 4, n),
                   r.normal(0, 0.4, (n, 1, 3)))
Renderer(gs, "cpu").render(viewmats(np.array([[0.0, 0.0, 0.0]]), 0.5), intrinsics(48, 36, 90)[None], 48, 36)
frames = np.load(sys.argv[1])
with H264Writer(Path(sys.argv[2]), 5, crf=18, b_frames=0) as v:
    for f in frames:
        v.add(f)
"""


def test_the_exporter_encodes_with_the_deterministic_x264_settings(tmp_path):
    """The fix the slow test below proves end to end (a cold renderer compilation before encoding):
    one encoder thread and cpu-independent assembly, whatever the caller asks besides."""
    from navcore.io.video import DETERMINISTIC_X264, H264Writer

    with H264Writer(tmp_path / "a.mp4", 5, crf=18, b_frames=0) as w:
        w.add(np.zeros((36, 48, 3), np.uint8))
        assert DETERMINISTIC_X264.items() <= w.options.items()  # what the stream was opened with


@pytest.mark.slow
def test_the_videos_bytes_do_not_depend_on_what_the_process_ran_before(exported, tmp_path):
    """x264's macroblock-tree assembly read a stack value it never wrote, so an episode's MP4
    depended on what ran before it in the process: after a cold compilation of the renderer, the
    same 48x36 frames gave different bytes in each of 3 processes. The encoder (the exporter's
    settings) must give the bytes of a process that ran nothing else."""
    import os
    import subprocess
    import sys

    import av

    from navcore.io.video import H264Writer

    _, out, _ = exported
    first = sorted(out.rglob("*.mp4"))[0]
    with av.open(str(first)) as c:
        frames = np.stack([f.to_ndarray(format="rgb24") for f in c.decode(video=0)])
    assert frames.shape[1:] == (36, 48, 3) and len(frames) > 20
    np.save(tmp_path / "frames.npy", frames)
    with H264Writer(tmp_path / "here.mp4", 5, crf=18, b_frames=0) as here:  # as the exporter's
        for f in frames:
            here.add(f)
    # an empty numba cache: a cold compilation (without the fix, 3 of 3 such processes differed)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    subprocess.run([sys.executable, "-c", _ENCODE_AFTER_COLD_COMPILE, str(tmp_path / "frames.npy"),
                    str(tmp_path / "cold.mp4")], check=True, env=env, cwd=str(Path(__file__).parents[1]))
    assert (tmp_path / "cold.mp4").read_bytes() == (tmp_path / "here.mp4").read_bytes()
