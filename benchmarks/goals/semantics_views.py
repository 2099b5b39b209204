"""How many free-space views the semantic layer needs: instance recall and valid-centre rate of
the lifted candidates against the ground truth, per covering-pose density (spacing, headings),
on the synthetic scenes of a finished data root (oracle segmenter at a corruption level).

Scenes without capture cameras (most real ones) are segmented from free-space poses; each view
costs a SAM3 forward (~60 ms on an H100), so the pose density sets the release's GPU-hours.

    python -m benchmarks.goals.semantics_views --data /tmp/default_ds
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np

DENSITIES = ((1.0, 45.0), (1.5, 45.0), (1.5, 60.0), (2.0, 60.0), (2.0, 90.0))
COVERAGE = ((1.0, 45.0), (1.5, 60.0))
"""Lattices also thinned by semantics.view_selection=coverage (issue 61: views chosen to see the
surfaces, not by the area)."""
SELECTIONS = tuple((s, y, "grid") for s, y in DENSITIES) + tuple((s, y, "coverage") for s, y in COVERAGE)


def score(labels: list[dict], truth, categories: list[str]) -> dict:
    """Predicted centres inside a ground-truth box of their category (valid) and ground-truth
    objects of the categories that got such a centre (found); aligned frame, boxes grown 5 cm."""
    t = truth.to_pylist()
    t = [r for r in t if r["category"] in categories]
    lo = np.array([[r["min_x"], r["min_y"], r["min_z"]] for r in t]).reshape(-1, 3) - 0.05
    hi = np.array([[r["max_x"], r["max_y"], r["max_z"]] for r in t]).reshape(-1, 3) + 0.05
    cat = np.array([r["category"] for r in t])
    found = np.zeros(len(t), bool)
    valid = 0
    for p in labels:
        c = np.asarray(p["position"])
        inside = (cat == p["category"]) & (c >= lo).all(1) & (c <= hi).all(1)
        valid += bool(inside.any())
        found |= inside
    return {"predicted": len(labels), "valid": valid, "objects": len(t), "found": int(found.sum())}


def run(args) -> dict:
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from navcore.instances import load_instances
    from navcore.io.catalog import open_catalog
    from navcore.render import Renderer
    from navcore.seeds import stream_seed
    from pipeline.config import CONF_DIR, register_configs
    from stages.semantics.config import SemanticsConfig
    from stages.semantics.segmenters import OracleSegmenter
    from stages.semantics.stage import covering_cameras, predict_instances

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=[f"data_root={args.data}", *args.overrides])
    catalog, scenes, _ = open_catalog(cfg)
    scenes = [s for s in scenes if s.synthetic][: args.scenes]
    base: SemanticsConfig = OmegaConf.to_object(cfg.semantics)
    base = dataclasses.replace(base, poses="free_space", oracle=dataclasses.replace(base.oracle, level=args.level))
    emb = OmegaConf.to_object(cfg.embodiment)
    rows = []
    for scene in scenes:
        gs, attrs = catalog.dataset("aligned", scene).load()
        cm = catalog.dataset("costmaps", scene).load(emb.name)
        truth = load_instances(scene, catalog, "ground_truth")
        renderer = Renderer(gs, args.renderer)
        for spacing, yaw, selection in SELECTIONS:
            scfg = dataclasses.replace(base, spacing=spacing, yaw_step_deg=yaw, view_selection=selection)
            cover: dict = {}
            t_sel = time.perf_counter()
            c2w, ks, _ = covering_cameras(scene, catalog, scfg, emb, np.asarray(attrs["source_to_aligned"]), cm, gs, cover)
            select_s = time.perf_counter() - t_sel
            seg = OracleSegmenter.from_scene(scene, catalog, renderer, scfg, stream_seed(scfg.seed, scene.scene_id,
                                                                                          "semantics"))
            t0 = time.perf_counter()
            labels, _, _ = predict_instances(renderer, seg, c2w, ks, gs.means, scfg)
            r = score(labels, truth, scfg.categories)
            rows.append({"scene": scene.scene_id, "spacing_m": spacing, "yaw_step_deg": yaw, "selection": selection,
                         "views": len(c2w), "seconds": round(time.perf_counter() - t0, 2),
                         "selection_seconds": round(select_s, 2), "coverage": cover.get("coverage"), **r})
            print(json.dumps(rows[-1]), flush=True)
    table = []
    for spacing, yaw, selection in SELECTIONS:
        sel = [r for r in rows if (r["spacing_m"], r["yaw_step_deg"], r["selection"]) == (spacing, yaw, selection)]
        p, v = sum(r["predicted"] for r in sel), sum(r["valid"] for r in sel)
        o, f = sum(r["objects"] for r in sel), sum(r["found"] for r in sel)
        table.append({"spacing_m": spacing, "yaw_step_deg": yaw, "selection": selection,
                      "views": sum(r["views"] for r in sel), "seconds": round(sum(r["seconds"] for r in sel), 1),
                      "recall": f / o if o else None, "valid_center_rate": v / p if p else None,
                      "predicted": p, "objects": o})
    return {"data": str(args.data), "level": args.level, "scenes": len(scenes), "renderer": args.renderer,
            "densities": table, "per_scene": rows}


def markdown(rep: dict) -> str:
    base = rep["densities"][0]
    import platform

    lines = [f"# Free-space view density of the semantic layer ({rep['scenes']} synthetic scenes, oracle at "
             f"{rep['level']})", "",
             "Reproduce: `python -m benchmarks.goals.semantics_views --data <a finished data root of the default "
             f"scenes> --docs` ({platform.machine()}, {os.cpu_count()} cores; {rep['renderer']} renderer). Headings = "
             "360 / yaw step. Selection: `grid` is every view of the lattice; `coverage` is "
             "`semantics.view_selection=coverage` on that lattice (the fewest views that see each surface voxel "
             "`semantics.coverage.k` times from distinct directions; k from the data root's config). Seconds: "
             "segmenting and lifting, all scenes.", "",
             "| spacing (m) | headings | selection | views | views vs 1 m / 45 deg | seconds | recall | valid centres | "
             "predicted |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rep["densities"]:
        lines.append(f"| {r['spacing_m']} | {int(round(360 / r['yaw_step_deg']))} | {r['selection']} | {r['views']} | "
                     f"{r['views'] / base['views']:.2f} | {r['seconds']} | {100 * (r['recall'] or 0):.1f} % | "
                     f"{100 * (r['valid_center_rate'] or 0):.1f} % | {r['predicted']} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    from benchmarks import write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="data", help="a data root whose costmaps exist (synthetic scenes)")
    ap.add_argument("--scenes", type=int, default=4)
    ap.add_argument("--level", default="moderate", help="oracle corruption level: none | moderate | heavy")
    ap.add_argument("--renderer", default="auto")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", action="store_true", help="also write docs/benchmarks/bench_semantics_views.md")
    ap.add_argument("overrides", nargs="*", help="Hydra overrides of the data root's config")
    args = ap.parse_args(argv)
    rep = run(args)
    write_report(args.out, "semantics_views.json", rep, omit=("per_scene",))
    (Path(args.out) / "semantics_views.md").write_text(markdown(rep))
    if args.docs:
        from benchmarks.pages import write_page

        write_page("bench_semantics_views.md", markdown(rep))
    return rep


if __name__ == "__main__":
    main()
