"""Views that something the costmap does not know blocks: the robot's camera rendered at episode
starts, ImageNav goal views and trajectory frames, against the costmap's own free distance in the
same directions.

    python -m benchmarks.dataset.blind_views --root data/real_indoor [--per-kind 100] [--out data/08_reports]
        -> blind_views.json, and docs/benchmarks/bench_blind_views.md (--docs)

A view counts as blocked when its rendered depth (median over a 40x30 frame, SH degree 0) is under
`--near` metres while the costmap sees at least twice as far (median of 9 rays over the field of
view, `Costmap.view_depths`): the camera is in or against Gaussians the costmap left out (floaters
dropped as isolated clusters, haze under the opacity threshold), not facing a wall it knows.
Measured twice: on the scene as the robot's camera sees it (less the noise splats the costmap hides
from it, `navcore.gaussians.content.camera_scene`) and on all Gaussians (as before the hiding).
Sampled views: up to --per-kind of each kind per scene and task, evenly over the table (seeded by
nothing: the same rows every run).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.pages import write_page


def rendered_depth(renderer, emb, poses: np.ndarray, batch: int = 64) -> np.ndarray:
    from navcore.render.camera import embodiment_camera

    out = []
    for a in range(0, len(poses), batch):
        vm, k, w, h = embodiment_camera(emb, poses[a:a + batch], 40, 30)
        out.append(np.median(renderer.render(vm, k, w, h).depth.numpy().reshape(len(vm), -1), 1))
    return np.concatenate(out) if out else np.zeros(0)


def costmap_depth(cm, emb, poses: np.ndarray, max_range: float) -> np.ndarray:
    return np.array([cm.fov_depth(p[:2], p[2], emb.hfov_deg, max_range) for p in poses])


def _rows(df: pd.DataFrame, n: int) -> pd.DataFrame:
    return df.iloc[np.unique(np.linspace(0, len(df) - 1, min(n, len(df))).astype(int))] if len(df) else df


def scene_views(root: Path, sid: str, per_kind: int, near: float) -> dict:
    from navcore.gaussians.content import without_splats
    from navcore.io.datasets import AlignedGaussianDataset, CostmapDataset, GaussianDataset
    from navcore.nav.embodiment import Embodiment
    from navcore.render import Renderer

    emb = Embodiment()
    gs, _ = AlignedGaussianDataset(root / "01_scenes" / sid / "alignment.json",
                                   GaussianDataset(root / "01_scenes" / sid / "gaussians.zarr")).load()
    store = CostmapDataset(root / "03_costmaps" / f"{sid}.zarr")
    cm, hidden = store.load(emb.name), store.hidden(emb.name)
    renderers = {"camera": Renderer(without_splats(gs, hidden), "cpu", sh_degree=0), "all": Renderer(gs, "cpu", sh_degree=0)}
    res = {"gaussians": int(len(gs.means)), "hidden": int(len(hidden)), "kinds": {}}
    for task in ("pointnav", "imagenav", "objectnav"):
        eps = sorted((root / "05_episodes" / f"task={task}" / f"scene_id={sid}").glob("*.parquet"))
        trs = sorted((root / "06_trajectories" / f"task={task}" / f"scene_id={sid}").glob("*.parquet"))
        df = pd.concat([pd.read_parquet(f) for f in eps]) if eps else pd.DataFrame()
        if not len(df):
            continue
        kinds = {"start": _rows(df, per_kind)[["start_position_x", "start_position_y", "start_yaw"]]}
        if task == "imagenav":
            kinds["goal_view"] = _rows(df, per_kind)[["goal_position_x", "goal_position_y", "goal_yaw"]]
        if trs:
            tr = pd.concat([pd.read_parquet(f, columns=["position_x", "position_y", "yaw"]) for f in trs])
            kinds["trajectory"] = _rows(tr, per_kind)
        for kind, t in kinds.items():
            poses = t.to_numpy(np.float64)
            cd = costmap_depth(cm, emb, poses, max_range=4 * near)
            row = {"views": len(poses)}
            for name, renderer in renderers.items():
                rd = rendered_depth(renderer, emb, poses)
                blocked = (rd < near) & (cd >= 2 * near)
                sfx = "" if name == "camera" else "_all_gaussians"
                row.update({f"blocked{sfx}": int(blocked.sum()),
                            f"blocked_share{sfx}": float(blocked.mean()) if len(poses) else 0.0,
                            f"rendered_under_near{sfx}": int((rd < near).sum())})
            res["kinds"][f"{task}/{kind}"] = row
    return res


def main(argv=None) -> dict:
    from benchmarks import machine, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", default="data/real_indoor")
    ap.add_argument("--per-kind", type=int, default=100)
    ap.add_argument("--near", type=float, default=0.5)
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", default=None, help="also write this markdown table (docs/bench_blind_views.md)")
    a = ap.parse_args(argv)
    root = Path(a.root)
    scenes = sorted(p.stem for p in (root / "03_costmaps").glob("*.zarr"))
    if not scenes:
        raise SystemExit(f"no costmaps under {root / '03_costmaps'}: run the pipeline on that data root first")
    rep = {"machine": machine(), "root": str(root), "near_m": a.near, "per_kind": a.per_kind,
           "scenes": {sid: scene_views(root, sid, a.per_kind, a.near) for sid in scenes}}
    write_report(a.out, "blind_views.json", rep)
    if a.docs:
        write_page(Path(a.docs).name, markdown(rep))
    return rep


def markdown(rep: dict) -> str:
    L = ["# Views blocked by what the costmap does not know", "",
         f"Machine: {rep['machine']}. Data root `{rep['root']}`. Reproduce: `python -m benchmarks.dataset.blind_views "
         f"--root {rep['root']} --per-kind {rep['per_kind']} --docs docs/bench_blind_views.md`.", "",
         f"Blocked: rendered depth (median of a 40x30 frame) under {rep['near_m']} m while the costmap's free "
         f"distance in the field of view (median of 9 rays) is at least {2 * rep['near_m']} m. Under near: every "
         "view with the rendered median under it (walls the costmap knows included). Camera: the scene as the "
         "pipeline renders it, less the noise splats the costmap hides; all: every Gaussian.", "",
         "| scene | Gaussians (hidden) | kind | views | blocked: camera | all | under near: camera | all |",
         "|---|---|---|---|---|---|---|---|"]
    for sid, sc in rep["scenes"].items():
        for kind, k in sc["kinds"].items():
            L.append(f"| {sid} | {sc['gaussians']:,} ({sc['hidden']:,}) | {kind} | {k['views']} | "
                     f"{k['blocked']} ({k['blocked_share']:.0%}) | {k['blocked_all_gaussians']} "
                     f"({k['blocked_share_all_gaussians']:.0%}) | {k['rendered_under_near']} | "
                     f"{k['rendered_under_near_all_gaussians']} |")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    main()
