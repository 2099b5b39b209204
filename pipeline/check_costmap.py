"""``navarena check-costmap [ROOT]``: the render check (stages/costmap/render_check.py) of every
costmap of a data root, each with the costmap config and embodiment its costmap stage recorded in its
marker, so that a user checks the map their run made, on a capture that has no ground truth.

    navarena check-costmap [ROOT] [--scenes NAME ...] [--poses 200] [--backend auto|cpu|cuda] [--json]
"""
from __future__ import annotations

import sys
from pathlib import Path


def check_root(root: str | Path = "data", scenes: list[str] | None = None, poses: int = 200, seed: int = 0,
               backend: str = "auto") -> dict:
    """The render check of every costmap of a data root (`navarena check-costmap`), each with the
    costmap config and embodiment its costmap stage ran with (the stage's marker): {scene name:
    rates, or {"error": why}}. The catalog is the root's last run's."""
    import json

    from omegaconf import OmegaConf

    from navcore.gaussians.content import content_of
    from navcore.io.catalog import Catalog
    from navcore.nav.embodiment import Embodiment
    from pipeline.markers import read_marker
    from stages.costmap.build import CostmapConfig, obstacle_classes
    from stages.costmap.render_check import RenderCheckConfig, check_costmap

    root = Path(root)
    latest = root / "_runs" / "latest.json"
    if not latest.is_file():
        raise FileNotFoundError(f"{root}: no pipeline run here ({latest} is missing): run the pipeline first")
    catalog = Catalog(Path(json.loads(latest.read_text())["catalog"]), root)
    chosen = [s for s in catalog.select() if not scenes or s.name in scenes or s.scene_id in scenes]
    if scenes and not chosen:
        raise ValueError(f"{root}: no scene named {', '.join(scenes)} in {catalog.file}")
    markers = {s.name: catalog.path("markers", s, stage="costmap") for s in chosen}
    done_by = {name: read_marker(m) for name, m in markers.items()}  # each marker read once
    if not scenes:  # every scene the costmap stage finished (a run may have taken part of the catalog)
        chosen = [s for s in chosen if done_by[s.name] is not None]
        if not chosen:
            raise FileNotFoundError(f"{root}: no costmap here: run the costmap stage first")
    out = {}
    for scene in chosen:
        done = done_by[scene.name]
        if done is None:
            out[scene.name] = {"error": f"no costmap ({markers[scene.name]} is missing or unreadable): run the costmap "
                                        "stage first"}
            continue
        used = done["config"]
        ccfg = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(CostmapConfig), used["costmap"]))
        emb = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(Embodiment), used["embodiment"]))
        gs, _ = catalog.dataset("aligned", scene).load(view_dependent=False)
        content = content_of(gs)
        cm = catalog.dataset("costmaps", scene).load(emb.name)
        _, noise, _ = obstacle_classes(content, ccfg)
        rc = check_costmap(content, cm, emb, RenderCheckConfig(poses=poses, seed=seed), backend=backend, noise=noise)
        out[scene.name] = {"scene_id": scene.scene_id, "embodiment": emb.name, "poses": rc["poses"],
                           "render_blocked": rc["render_blocked"], "fp_est": rc["fp_est"], "fp_ci95": rc["fp_ci95"],
                           "fn_est": rc["fn_est"], "fn_ci95": rc["fn_ci95"], "fn_noise_only": rc["fn_noise_only"],
                           "direct": {k: rc["direct"][k] for k in ("fp_est", "fn_est", "render_blocked")}}
    return out


def main(argv=None) -> int:
    """``navarena check-costmap [ROOT] [--scenes NAME ...] [--poses N]``: the render check of a data
    root's costmaps (module doc), one line a scene (--json: the figures)."""
    import argparse

    from navcore.io import jsonio

    ap = argparse.ArgumentParser(prog="navarena check-costmap", description=(
        "The render check of a data root's costmaps, each with the costmap config and embodiment it was built "
        "with: at sampled poses, what the scene shows within the robot's radius against what the costmap "
        "says; estimated FP / FN rates with 95 % intervals, no ground truth needed (stages/costmap/render_check.py)."))
    ap.add_argument("root", nargs="?", default="data", help="a data root the pipeline ran on (default: data)")
    ap.add_argument("--scenes", nargs="*", default=None, metavar="NAME", help="scene names or ids (default: all)")
    ap.add_argument("--poses", type=int, default=200, help="poses sampled a scene")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--backend", default="auto", choices=("auto", "cpu", "cuda"))
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    a = ap.parse_args(argv)
    try:
        res = check_root(a.root, a.scenes, a.poses, a.seed, a.backend)
    except (FileNotFoundError, ValueError) as e:
        print(f"navarena check-costmap: {e}", file=sys.stderr)
        return 2
    if a.json:
        print(jsonio.dumps(res, indent=1))  # strict JSON: a non-finite rate (no pose of a kind) is null
        return 0
    pct = lambda ci: f"{100 * ci[0]:.1f}-{100 * ci[1]:.1f} %"  # noqa: E731
    for name, r in res.items():
        if "error" in r:
            print(f"{name}: {r['error']}")
            continue
        print(f"{name} ({r['embodiment']}): {r['poses']} poses, {r['render_blocked']} blocked in the render; "
              f"FP est {100 * r['fp_est']:.1f} % ({pct(r['fp_ci95'])}), FN est {100 * r['fn_est']:.1f} % "
              f"({pct(r['fn_ci95'])}); FN poses only splats called noise block: {r['fn_noise_only']}; "
              f"direct evidence FP {100 * r['direct']['fp_est']:.1f} %, FN {100 * r['direct']['fn_est']:.1f} %")
    return 0
