"""navarena render-episodes: MP4 panes (RGB | depth | map), the per-scene HTML report, and the
report opened in headless Chromium."""
import shutil
import subprocess

import numpy as np
import pytest

from navarena.render_episodes import MapInset, costmap_image, headings


@pytest.fixture(scope="module")
def rendered(episode_run, tmp_path_factory):
    from navarena.render_episodes import render_episodes

    root, _, _ = episode_run
    out = tmp_path_factory.mktemp("render")
    res = render_episodes(root, out, tasks=("pointnav",), per_scene_task=1, width=64, height=48, fps=10, stride=8,
                          renderer="cpu")
    return root, out, res


def test_count_is_the_total_round_robin_and_one_index_links_every_video(rendered):
    from navarena.render_episodes import choose_episodes
    from navcore.render.frames import SceneFrames

    root, out, res = rendered
    src = SceneFrames(root, tasks=("pointnav", "imagenav"), width=8, height=8, renderer="cpu")
    sids, tasks = src.scene_ids, ("pointnav", "imagenav")
    plan = choose_episodes(src.catalog, sids, tasks, None, 3, None, None)
    assert sum(len(v) for v in plan.values()) == 3  # in total, not per scene and task
    order = [(s, t) for s in sids for t in tasks]
    assert list(plan) == order[:len(plan)] and all(len(v) == 1 for v in plan.values()) or len(order) < 3
    per = choose_episodes(src.catalog, sids, ("pointnav",), None, 3, 2, None)
    assert len(per) == len(sids) and all(len(v) == 2 for v in per.values())
    index = (out / "index.html").read_text()
    videos = list(out.glob("*/videos/*.mp4"))
    assert videos and all(f"{v.parent.parent.name}/videos/{v.name}" in index for v in videos)
    assert res["index"] == str(out / "index.html")


def test_progress_prints_plain_lines_without_a_terminal(capsys):
    from navcore.io.tool_progress import ToolProgress

    with ToolProgress("render-episodes", 3, unit="videos", log_every=0) as p:
        p.advance(1, 100)
        p.advance(1, 100)
    err = capsys.readouterr().err
    assert "render-episodes: 1/3 videos, 100 frames" in err and "left" in err
    assert "render-episodes: 2/2 videos, 200 frames" in err and "(done)" in err


def test_videos_show_rgb_depth_and_the_map_with_the_path(rendered):
    import av
    import pandas as pd

    root, out, res = rendered
    assert res["videos"] == res["scenes"] >= 1
    video = next(out.glob("*/videos/pointnav_*.mp4"))
    with av.open(str(video)) as c:
        frames = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
    eid = video.stem.split("_", 1)[1]
    tr = pd.read_parquet(root / "06_trajectories" / "task=pointnav")
    steps = tr[tr["episode_id"] == eid]["step"]
    assert len(frames) == int(((steps % 8 == 0) | (steps == steps.max())).sum())
    assert frames[0].shape == (48, 64 * 2 + 48, 3)  # RGB | depth | square map inset
    red = lambda f: ((f[:, 128:, 0] > 150) & (f[:, 128:, 1] < 90) & (f[:, 128:, 2] < 90)).sum()  # noqa: E731
    assert red(frames[-1]) > red(frames[0])  # the walked path is drawn as it grows


def test_map_inset_and_headings():
    class CM:  # a 4 m x 2 m room, walls on the border
        resolution, origin = 0.05, (0.0, 0.0)
        clearance = np.ones((40, 80), np.float32)
        clearance[[0, -1], :] = 0
        clearance[:, [0, -1]] = 0
        occupancy = clearance < 0.5

    img = costmap_image(CM)
    assert img.shape == (40, 80, 3) and (img[0] == 20).all() and (img[20, 40] == 255).all()
    inset = MapInset(CM, np.array([[1.0, 1.0], [3.0, 1.0]]), np.array([[3.0, 1.0]]), 0.3, 100)
    x0, y0 = inset.px(1.0, 1.0)
    x1, y1 = inset.px(3.0, 1.0)
    assert y0 == pytest.approx(y1) and x1 - x0 == pytest.approx(2.0 * inset.scale)
    assert headings(np.array([[0, 0], [1, 0], [1, 0], [1, 1]], float), 0.7) == pytest.approx([0.7, 0, 0, np.pi / 2])


@pytest.mark.skipif(not shutil.which("chromium"), reason="Chromium is not installed (scripts/system_packages.sh)")
def test_report_in_headless_chromium(rendered, tmp_path):
    from PIL import Image

    _, out, _ = rendered
    page = next(out.glob("*/index.html"))
    html = page.read_text()
    assert all((page.parent / name).exists() for name in ("costmap.png", "density.png", "difficulty.png"))
    assert html.count("<video") == 1
    args = ["chromium", "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
            "--virtual-time-budget=8000"]
    dom = subprocess.run([*args, "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120).stdout
    assert "videos ready: 1 of 1" in dom  # the browser decoded the H.264 video
    shot = tmp_path / "report.png"
    subprocess.run([*args, "--window-size=1300,2000", f"--screenshot={shot}", page.as_uri()], capture_output=True,
                   timeout=120, check=True)
    img = np.asarray(Image.open(shot).convert("RGB"))
    assert img.shape[:2] == (2000, 1300)
    assert len(np.unique(img[::4, ::4].reshape(-1, 3), axis=0)) > 50  # images drawn, not a blank page
