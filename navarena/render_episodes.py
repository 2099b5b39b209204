"""`navarena render-episodes`: videos of chosen episodes and a per-scene HTML report.

    navarena render-episodes --root data --scene 35bf402a --task pointnav --count 3 --out reports/episodes
    navarena render-episodes --root data --run oracle_distance --count 6 --out reports/episodes
    navarena render-episodes --root data --per-scene-task 2 --out reports/episodes   # 2 of every scene and task

--count is the number of videos in total (round robin over scenes and tasks).

Each video (H.264 MP4, which browsers play) shows, side by side, the egocentric RGB, the depth
(turbo colour map, near = red... far = blue, black = nothing hit) and a top-down map inset: the
costmap (black: obstacles; grey: too close for the robot's footprint; white: free), the path walked
so far, the robot's pose and the goal's success region. Along the expert trajectory by default,
along an evaluation run's executed trajectory with --run.

The report (unless --no-report) is {out}/index.html, linking every scene and video, and per scene
{out}/{scene_id}/index.html: the costmap, start and goal density over it, the difficulty histogram
per task, geodesic distances, and the videos with their episode table. It references its files
relatively, so the folder can be copied or served as it is.
"""
from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import pandas as pd

from navarena import quick
from navarena.quick import shorten
from navcore.io.catalog import Catalog
from navcore.io.tool_progress import ToolProgress
from navcore.nav.embodiment import Embodiment
from navcore.nav.tasks import TASK_TYPES

FREE, INFLATED, OBSTACLE = (255, 255, 255), (170, 170, 170), (20, 20, 20)


def costmap_image(cm) -> np.ndarray:
    """RGB uint8 [ny, nx, 3] of a costmap, row 0 at the top (north up)."""
    img = np.empty((*cm.clearance.shape, 3), np.uint8)
    img[:] = FREE
    img[cm.occupancy] = INFLATED
    img[cm.clearance <= 0] = OBSTACLE
    return img[::-1].copy()


def _turbo(depth: np.ndarray, far: float) -> np.ndarray:
    from navcore.optional import require

    colormaps = require("matplotlib", "the depth colours of navarena render-episodes").colormaps
    d = np.clip(depth / far, 0, 1)
    rgb = (colormaps["turbo_r"](d)[..., :3] * 255).astype(np.uint8)
    rgb[depth <= 0] = 0
    return rgb


class MapInset:
    """The costmap cropped around an episode, scaled to `size`; draws the path, pose and goal."""

    def __init__(self, cm, xy: np.ndarray, goals: np.ndarray, radius: float, size: int, margin: float = 1.0):
        from PIL import Image

        self.cm, self.radius = cm, radius
        pts = np.concatenate([xy, goals])
        lo, hi = pts.min(0) - margin - radius, pts.max(0) + margin + radius
        side = float(max(hi - lo))
        centre = (lo + hi) / 2
        self.lo = centre - side / 2
        self.scale = size / side  # pixels a metre
        self.size = size
        full = costmap_image(cm)
        ny, nx = cm.clearance.shape
        # world box -> costmap pixels (row 0 = north), padded with free space outside the map
        res = cm.resolution
        x0 = int(np.floor((self.lo[0] - cm.origin[0]) / res))
        y1 = int(np.floor((self.lo[1] + side - cm.origin[1]) / res))
        n = int(np.ceil(side / res))
        canvas = np.full((n, n, 3), FREE, np.uint8)
        r0 = ny - 1 - y1  # top row of the box in the flipped image
        rs, cs = slice(max(r0, 0), min(r0 + n, ny)), slice(max(x0, 0), min(x0 + n, nx))
        canvas[rs.start - r0:rs.stop - r0, cs.start - x0:cs.stop - x0] = full[rs, cs]
        self.base = Image.fromarray(canvas).resize((size, size), Image.NEAREST)
        self.goals = goals

    def px(self, x, y):
        return (x - self.lo[0]) * self.scale, self.size - (y - self.lo[1]) * self.scale

    def draw(self, path: np.ndarray, pose) -> np.ndarray:
        from PIL import ImageDraw

        im = self.base.copy()
        d = ImageDraw.Draw(im)
        r = self.radius * self.scale
        for g in self.goals:
            gx, gy = self.px(*g)
            d.ellipse([gx - r, gy - r, gx + r, gy + r], outline=(230, 120, 0), width=2)
        if len(path) > 1:
            d.line([self.px(*p) for p in path], fill=(200, 30, 30), width=2)
        x, y = self.px(pose[0], pose[1])
        d.ellipse([x - 4, y - 4, x + 4, y + 4], fill=(30, 90, 220))
        d.line([(x, y), (x + 10 * np.cos(pose[2]), y - 10 * np.sin(pose[2]))], fill=(30, 90, 220), width=2)
        return np.asarray(im)


def write_mp4(path: Path, frames, fps: int) -> None:
    """RGB uint8 frames -> H.264 MP4 (yuv420p, browsers play it; odd sizes cut to even), atomically."""
    from navcore.io.atomic import atomic_path
    from navcore.io.video import H264Writer

    with atomic_path(path) as tmp, H264Writer(tmp, fps, crf=20) as video:
        for f in frames:
            video.add(f)


def episode_video(src, cm, sid: str, poses: np.ndarray, goals: np.ndarray, radius: float, path: Path,
                  fps: int, far: float = 6.0, batch: int = 32) -> dict:
    """Render one trajectory (poses [n, 3]) to `path`; returns the video's facts."""
    h = src.height
    inset = MapInset(cm, poses[:, :2], goals, radius, h - h % 2)

    def frames():
        for a in range(0, len(poses), batch):
            rgb, depth = src.frames(sid, poses[a:a + batch])
            rgb, depth = rgb.numpy(), depth.numpy()
            for k in range(len(rgb)):
                i = a + k
                pane = np.concatenate([rgb[k], _turbo(depth[k], far), inset.draw(poses[:i + 1, :2], poses[i])], 1)
                yield pane[: pane.shape[0] - pane.shape[0] % 2, : pane.shape[1] - pane.shape[1] % 2]

    write_mp4(path, frames(), fps)
    return {"frames": len(poses), "seconds": len(poses) / fps}


def headings(xy: np.ndarray, start_yaw: float) -> np.ndarray:
    """Headings along executed positions: the direction of each move (the last one where none)."""
    yaw = np.full(len(xy), start_yaw)
    for i in range(1, len(xy)):
        dx, dy = xy[i] - xy[i - 1]
        yaw[i] = np.arctan2(dy, dx) if dx or dy else yaw[i - 1]
    return yaw


def _episodes(cat: Catalog, sid: str, task: str) -> pd.DataFrame:
    ds = cat.dataset("episodes", cat.scene(sid), task=task)
    return ds.load().to_pandas() if ds.exists() else pd.DataFrame()


def _goals(e: dict) -> np.ndarray:
    goals = json.loads(e["goals_json"]) if e.get("goals_json") else []
    if e["task_type"] == "objectnav" and goals:
        return np.array([g["position"][:2] for g in goals], float)
    return np.array([[e["goal_position_x"], e["goal_position_y"]]], float)


def render_episodes(root, out, scenes=None, tasks=TASK_TYPES, episodes=None,
                    count: int = 6, run: str | None = None, width: int = 320, height: int = 240, fps: int = 10,
                    stride: int = 2, renderer: str = "auto", embodiment: Embodiment | None = None,
                    report: bool = True, quiet: bool = False, per_scene_task: int | None = None) -> dict:
    """Videos of chosen episodes and, with `report`, each scene's index.html plus {out}/index.html
    linking every scene and video. The episodes: `episodes` (ids), else `count` in total taken
    round robin over the scenes and tasks (each pair's first episodes by id), else with
    `per_scene_task` that many of every scene and task. Expert trajectories at 20 Hz / `stride`, or
    an evaluation run's executed positions (`run`, headings from their motion)."""
    from navcore.render.frames import SceneFrames

    emb = embodiment or Embodiment()
    src = SceneFrames(root, tasks=tasks, scenes=scenes, width=width, height=height, embodiment=emb, renderer=renderer)
    cat = src.catalog
    out = Path(out)
    plan = choose_episodes(cat, src.scene_ids, tasks, episodes, count, per_scene_task, run)
    made: dict[str, list[dict]] = {}
    with ToolProgress("render-episodes", sum(len(c) for c in plan.values()), quiet, unit="videos") as bar:
        for sid in src.scene_ids:
            cm = cat.dataset("costmaps", cat.scene(sid)).load(emb.name)
            results = None
            if run:
                ds = cat.dataset("eval_results", cat.scene(sid), run=run)
                results = ds.load().to_pandas() if ds.exists() else pd.DataFrame()
            vids = []
            for task in tasks:
                chosen = plan.get((sid, task))
                if chosen is None or not len(chosen):
                    continue
                tr = cat.dataset("trajectories", cat.scene(sid), task=task).load(
                    ["episode_id", "step", "position_x", "position_y", "yaw"]).to_pandas()
                for e in chosen.to_dict("records"):
                    e["task_type"] = task
                    if results is not None:
                        r = results[(results["task"] == task) & (results["episode_id"] == e["episode_id"])].iloc[0]
                        xy = np.stack([r["trajectory_x"], r["trajectory_y"]], 1).astype(np.float64)
                        poses = np.concatenate([xy, headings(xy, float(e["start_yaw"]))[:, None]], 1)
                        kind, outcome = "agent", ("success" if r["sr"] == 1 else r["end_reason"])
                    else:
                        t = tr[tr["episode_id"] == e["episode_id"]].sort_values("step")
                        t = t[(t["step"] % stride == 0) | (t["step"] == t["step"].max())]
                        poses = t[["position_x", "position_y", "yaw"]].to_numpy(np.float64)
                        kind, outcome = "expert", "expert"
                    name = f"{task}_{e['episode_id']}.mp4"
                    facts = episode_video(src, cm, sid, poses, _goals(e), float(e["success_radius"]),
                                          out / sid / "videos" / name, fps)
                    bar.advance(1, len(poses))
                    vids.append({"file": f"videos/{name}", "task": task, "episode_id": e["episode_id"],
                                 "difficulty": e["difficulty"], "geodesic": float(e["geodesic_distance"]),
                                 "trajectory": kind, "outcome": outcome, **facts})
            if vids or report:
                made[sid] = vids
            if report:
                write_report(cat, sid, out / sid, vids, emb)
    if report:
        write_index(out, made)
    return {"scenes": len(made), "videos": sum(len(v) for v in made.values()), "out": str(out),
            "index": str(out / "index.html") if report else None}


def choose_episodes(cat: Catalog, scene_ids: list[str], tasks, episodes, count: int, per_scene_task: int | None,
                    run: str | None) -> dict[tuple[str, str], pd.DataFrame]:
    """(scene, task) -> the episodes to render (see render_episodes); with `run`, only episodes the
    run evaluated."""
    pools: dict[tuple[str, str], pd.DataFrame] = {}
    for sid in scene_ids:
        evaluated = None
        if run:
            ds = cat.dataset("eval_results", cat.scene(sid), run=run)
            evaluated = ds.load(["task", "episode_id"]).to_pandas() if ds.exists() else pd.DataFrame(
                {"task": [], "episode_id": []})
        for task in tasks:
            eps = _episodes(cat, sid, task)
            if not len(eps):
                continue
            eps = eps.sort_values("episode_id")
            if episodes:
                eps = eps[eps["episode_id"].isin(episodes)]
            if evaluated is not None:
                eps = eps[eps["episode_id"].isin(set(evaluated[evaluated["task"] == task]["episode_id"]))]
            if len(eps):
                pools[(sid, task)] = eps
    if episodes:
        return pools
    if per_scene_task is not None:
        return {k: v.head(per_scene_task) for k, v in pools.items()}
    from navcore.render.frames import round_robin

    return {k: pools[k].head(n) for k, n in round_robin({k: len(v) for k, v in pools.items()}, count).items()}


def write_index(out: Path, made: dict[str, list[dict]]) -> Path:
    """{out}/index.html: every scene's report and every video, one page."""
    from navcore.io.atomic import write_text_atomic

    rows = "".join(f"<tr><td><a href='{html.escape(sid)}/index.html'>{html.escape(sid)}</a></td><td>{len(v)}</td><td>"
                   + " ".join(f"<a href='{html.escape(sid)}/{html.escape(x['file'])}'>{html.escape(x['task'])} "
                              f"{html.escape(str(x['episode_id']))}</a>" for x in v) + "</td></tr>"
                   for sid, v in made.items())
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>NavArena episodes</title>
<style>body{{font-family:sans-serif;margin:2em}} td,th{{padding:4px 8px;border-bottom:1px solid #ddd}}</style></head>
<body><h1>NavArena episodes</h1><p>{sum(len(v) for v in made.values())} videos in {len(made)} scene(s); each scene's
page has its costmap, start and goal density, difficulty histogram and the videos with their episode table.</p>
<table><tr><th>scene</th><th>videos</th><th>episodes</th></tr>{rows}</table></body></html>
"""
    page = out / "index.html"
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(page, doc)
    return page


def _density(cm, xy: np.ndarray, cell: float = 0.5) -> np.ndarray:
    ny, nx = cm.clearance.shape
    k = max(1, int(round(cell / cm.resolution)))
    h = np.zeros((ny // k + 1, nx // k + 1))
    if len(xy):
        i = ((xy[:, 1] - cm.origin[1]) / cm.resolution).astype(int) // k
        j = ((xy[:, 0] - cm.origin[0]) / cm.resolution).astype(int) // k
        ok = (i >= 0) & (j >= 0) & (i < h.shape[0]) & (j < h.shape[1])
        np.add.at(h, (i[ok], j[ok]), 1)
    return h


def write_report(cat: Catalog, sid: str, folder: Path, vids: list[dict], emb: Embodiment) -> Path:
    """folder/index.html (+ its PNGs) for one scene."""
    from navcore.optional import require

    require("matplotlib", "the report figures of navarena render-episodes").use("Agg")
    import matplotlib.pyplot as plt

    from navcore.io.atomic import write_text_atomic

    folder.mkdir(parents=True, exist_ok=True)
    cm = cat.dataset("costmaps", cat.scene(sid)).load(emb.name)
    eps = {t: _episodes(cat, sid, t) for t in TASK_TYPES}
    eps = {t: e for t, e in eps.items() if len(e)}
    ny, nx = cm.clearance.shape
    ext = [cm.origin[0], cm.origin[0] + nx * cm.resolution, cm.origin[1], cm.origin[1] + ny * cm.resolution]
    figs = {}
    fig, ax = plt.subplots(figsize=(6, 6 * ny / nx))
    ax.imshow(costmap_image(cm), extent=ext)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"costmap ({emb.name}, {cm.resolution:.2f} m cells; free {100 * (~cm.occupancy).mean():.0f} %)")
    figs["costmap.png"] = fig
    all_eps = pd.concat(eps.values(), ignore_index=True) if eps else pd.DataFrame()
    fig, axes = plt.subplots(1, 2, figsize=(12, 6 * ny / nx))
    for ax, (label, cols) in zip(axes, (("starts", ("start_position_x", "start_position_y")),
                                         ("goals", ("goal_position_x", "goal_position_y")))):
        ax.imshow(costmap_image(cm), extent=ext)
        if len(all_eps):
            d = _density(cm, all_eps[list(cols)].to_numpy(float))
            im = ax.imshow(np.ma.masked_equal(d, 0), origin="lower", extent=ext, cmap="YlOrRd", alpha=0.85,
                           vmin=0, vmax=max(1.0, float(d.max())))
            fig.colorbar(im, ax=ax, shrink=0.7, label="episodes a cell")
        ax.set_title(f"episode {label} ({len(all_eps)} episodes, 0.5 m cells)")
    figs["density.png"] = fig
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.5))
    diffs = ["easy", "medium", "hard"]
    width = 0.8 / max(1, len(eps))
    for k, (t, e) in enumerate(eps.items()):
        counts = [int((e["difficulty"] == d).sum()) for d in diffs]
        axes[0].bar(np.arange(3) + k * width, counts, width, label=t)
        axes[1].hist(e["geodesic_distance"], bins=20, alpha=0.6, label=t)
    axes[0].set_xticks(np.arange(3) + 0.4 - width / 2, diffs)
    axes[0].set_title("episodes per difficulty")
    axes[1].set_title("geodesic distance (m)")
    for ax in axes:
        ax.legend(fontsize=8)
    figs["difficulty.png"] = fig
    for name, fig in figs.items():
        fig.tight_layout()
        fig.savefig(folder / name, dpi=90)
        plt.close(fig)
    rows = "".join(
        f"<tr><td>{html.escape(v['task'])}</td><td>{html.escape(v['episode_id'])}</td><td>{v['difficulty']}</td>"
        f"<td>{v['geodesic']:.2f}</td><td>{v['trajectory']}</td><td>{html.escape(str(v['outcome']))}</td>"
        f"<td>{v['frames']}</td></tr>" for v in vids)
    videos = "".join(
        f'<figure><video src="{html.escape(v["file"])}" controls muted loop preload="auto"></video>'
        f"<figcaption>{html.escape(v['task'])} {html.escape(v['episode_id'])} ({v['difficulty']}, "
        f"{v['geodesic']:.1f} m, {v['trajectory']})</figcaption></figure>" for v in vids)
    counts = ", ".join(f"{t}: {len(e)}" for t, e in eps.items()) or "none"
    doc = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>NavArena scene {html.escape(sid)}</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 24px; color: #222; max-width: 1300px; }}
h1 {{ font-size: 22px; }} h2 {{ font-size: 17px; margin-top: 28px; }}
img {{ max-width: 100%; border: 1px solid #ddd; }}
table {{ border-collapse: collapse; font-size: 13px; }} td, th {{ border: 1px solid #ccc; padding: 3px 8px; }}
.videos {{ display: flex; flex-wrap: wrap; gap: 12px; }} figure {{ margin: 0; }}
video {{ width: 480px; border: 1px solid #ddd; background: #000; }} figcaption {{ font-size: 12px; }}
</style></head>
<body>
<h1>NavArena scene <code>{html.escape(sid)}</code></h1>
<p>Episodes: {counts}. Embodiment {html.escape(emb.name)} (radius {emb.radius:.2f} m).</p>
<h2>Costmap</h2><img src="costmap.png" alt="costmap">
<h2>Where episodes start and end</h2><img src="density.png" alt="start and goal density">
<h2>Difficulty</h2><img src="difficulty.png" alt="difficulty histogram">
<h2>Videos</h2>
<p>RGB | depth (near red, far blue, black: nothing hit) | map (red: path, blue: robot, orange: success region).</p>
<div class="videos">{videos}</div>
<table><tr><th>task</th><th>episode</th><th>difficulty</th><th>geodesic (m)</th><th>trajectory</th><th>outcome</th>
<th>frames</th></tr>{rows}</table>
<p id="media-status">videos loading</p>
<script>
Promise.all([...document.querySelectorAll("video")].map(v => new Promise(ok => {{
  if (v.readyState >= 2) return ok(true);
  v.addEventListener("loadeddata", () => ok(true)); v.addEventListener("error", () => ok(false));
}}))).then(r => {{ document.getElementById("media-status").textContent =
  "videos ready: " + r.filter(Boolean).length + " of " + r.length; }});
</script>
</body></html>
"""
    page = folder / "index.html"
    write_text_atomic(page, doc)
    return page


def main(argv=None) -> dict:
    """navarena render-episodes: MP4 videos (RGB | depth | map) of chosen episodes and a per-scene
    HTML report."""
    import argparse

    ap = argparse.ArgumentParser(prog="navarena render-episodes", description=main.__doc__)
    ap.add_argument("--root", default="data", help="data root")
    ap.add_argument("--out", required=True)
    ap.add_argument("--scene", action="append", help="scene id (repeat; default: every scene)")
    ap.add_argument("--task", action="append", help="task (repeat; default: all three)")
    ap.add_argument("--episodes", default=None, help="comma-separated episode ids")
    ap.add_argument("--count", type=int, default=6, help="videos in total, taken round robin over the scenes and tasks "
                    "(when no --episodes are given); each takes seconds to minutes on a CPU (see the progress line)")
    ap.add_argument("--per-scene-task", type=int, default=None, metavar="N",
                    help="instead of --count: N videos of every scene and task")
    ap.add_argument("--run", default=None, help="an evaluation run: its executed trajectories")
    ap.add_argument("--size", default="320x240", help="WIDTHxHEIGHT of each pane")
    ap.add_argument("--fps", type=int, default=10)
    ap.add_argument("--renderer", default="auto", choices=["auto", "cpu", "gsplat"])
    ap.add_argument("--no-report", action="store_true")
    ap.add_argument("--quiet", action="store_true", help="no progress display")
    args = ap.parse_args(argv)
    from navcore.optional import require

    require("av", "navarena render-episodes (its videos)")  # before any scene loads or frame renders
    if not args.no_report:
        require("matplotlib", "navarena render-episodes (its report's figures; --no-report skips them)")
    shorten(args, quick.VIDEOS, "navarena render-episodes")
    w, h = (int(v) for v in args.size.lower().split("x"))
    res = render_episodes(args.root, args.out, args.scene, args.task or TASK_TYPES,
                          args.episodes.split(",") if args.episodes else None, args.count, args.run, w, h, args.fps,
                          renderer=args.renderer, report=not args.no_report, quiet=args.quiet,
                          per_scene_task=args.per_scene_task)
    print(json.dumps(res))
    return res
