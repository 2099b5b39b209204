"""bench-real: the pipeline on real trained indoor scenes (catalogs/real_indoor.yaml), with the
same parameters as the synthetic ones, and the checks that need no ground truth.

Per scene: read time, floaters, up axis, floor error (height of the flat-surface density peak near
the chosen floor), voxel grid against the content box, seconds per stage, free area and components,
episodes per task, oracle SR under both protocols, the render-based FP / FN estimates of the
costmap, the top-down costmap, the floor side view and three egocentric views at episode starts
(CPU renderer, 320x240). Then, on realistic synthetic scenes (realism level moderate) against the
mesh: the costmap's true state FP / FN rates and the render estimator's error at the same poses.

Writes data/08_reports/bench_real.{json,md} and docs/benchmarks/bench_real.md. Pictures of the real scenes
go to data/08_reports/bench_real/ only: their sources state no licence, so no render of them is
committed or published (the markdown links the local files).
  python -m benchmarks.captures.real [--data data] [--synthetic-scenes 3] [--poses 200]
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks import machine
from benchmarks.map.floor_level import floor_level
from benchmarks.pages import write_page
from navcore.io import jsonio

TASKS = ("pointnav", "imagenav", "objectnav")
PROTOCOLS = ("distance", "explicit_stop")
STAGES = ("ingest", "voxelize", "align", "costmap", "screen", "episodes", "semantics", "asset", "objectnav_episodes",
          "export")


def compose(data: str, *over: str):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return hydra_compose("config", overrides=[f"data_root={data}", "scenes=real_indoor", *over])


def run_pipeline(data: str, executor: str) -> dict:
    """The default stages, then the oracle under both protocols; returns the run summaries."""
    from pipeline.executor import execute

    out = {"dataset": execute(compose(data, f"executor={executor}"))}
    for p in PROTOCOLS:
        out[p] = execute(compose(data, f"executor={executor}", "stages=[evaluate]", "evaluate.agent=oracle",
                                 f"evaluate.protocol={p}", "evaluate.render=false"))
    return out


def floor_error(aligned) -> float:
    """|height| of the density peak of the flat, upward-facing content Gaussians within 0.3 m of
    the chosen floor (1 cm bins): how far the plane sits from the floor the Gaussians show."""
    from navcore.gaussians.surfaces import horizontal_surfaces

    z = aligned.means[:, 2]
    sel = horizontal_surfaces(aligned, 0.5, 15.0) & (np.abs(z) < 0.3)
    hist, edges = np.histogram(z[sel], np.arange(-0.3, 0.3001, 0.01), weights=aligned.alphas[sel])
    return float(abs(0.5 * (edges[np.argmax(hist)] + edges[np.argmax(hist) + 1])))


def marker(catalog, scene, stage: str) -> dict:
    p = catalog.path("markers", scene, stage=stage)
    return json.loads(p.read_text()) if p.exists() else {}


def episode_counts(catalog, scene) -> dict:
    import pyarrow.parquet as pq

    out = {}
    for t in TASKS:
        p = catalog.path("episodes", scene, task=t)
        out[t] = pq.read_metadata(p).num_rows if p.exists() else 0
    return out


def oracle_sr(data: Path, scene_id: str) -> dict:
    import pandas as pd

    out = {}
    for p in PROTOCOLS:
        f = data / "07_eval" / f"oracle_{p}" / "results" / f"scene_id={scene_id}" / "part-0.parquet"
        df = pd.read_parquet(f, columns=["task", "sr"]) if f.exists() else pd.DataFrame(columns=["task", "sr"])
        out[p] = {"all": round(float(df["sr"].mean()), 4) if len(df) else None,
                  **{t: round(float(g["sr"].mean()), 4) for t, g in df.groupby("task")}}
    return out


def egocentric_views(gs, catalog, scene, emb, folder: Path, k: int = 3) -> list[str]:
    """RGB at the starts of the first k PointNav episodes (CPU renderer, 320x240)."""
    import pyarrow.parquet as pq
    from PIL import Image

    from navcore.render import Renderer
    from navcore.render.camera import embodiment_camera

    p = catalog.path("episodes", scene, task="pointnav")
    if not p.exists():
        return []
    ep = pq.read_table(p, columns=["start_position_x", "start_position_y", "start_yaw"]).to_pandas().head(k)
    if not len(ep):
        return []
    vm, ks, w, h = embodiment_camera(emb, ep.to_numpy(), 320, 240)
    rgb = Renderer(gs, "cpu").render(vm, ks, w, h).rgb.numpy()
    names = []
    for i, im in enumerate(rgb):
        name = f"{scene.name}_view{i}.png"
        Image.fromarray((im * 255).round().astype(np.uint8)).save(folder / name)
        names.append(name)
    return names


def scene_report(data: Path, catalog, scene, cfg, poses: int, pictures: Path) -> dict:
    from omegaconf import OmegaConf

    from navcore.gaussians.content import content_of
    from navcore.gaussians.formats import read_gaussians
    from stages.costmap.build import obstacle_classes
    from stages.costmap.render_check import RenderCheckConfig, check_costmap

    t0 = time.perf_counter()
    read_gaussians(scene.path, None)
    read_s = time.perf_counter() - t0
    ingest = json.loads(catalog.path("ingest_report", scene).read_text())
    align = json.loads(catalog.path("alignment", scene).read_text())
    vox = marker(catalog, scene, "voxelize").get("info", {})
    cm_info = marker(catalog, scene, "costmap").get("info", {})
    emb = OmegaConf.to_object(cfg.embodiment)
    gs, _ = catalog.dataset("aligned", scene).load()
    cm = catalog.dataset("costmaps", scene).load(emb.name)
    t0 = time.perf_counter()
    content = content_of(gs)
    _, noise, _ = obstacle_classes(content, OmegaConf.to_object(cfg.costmap))
    rc = check_costmap(content, cm, emb, RenderCheckConfig(poses=poses), backend="cpu", noise=noise)
    rc_s = time.perf_counter() - t0
    asset = catalog.path("asset", scene)
    pics = {}
    for name in ("costmap_topdown.png", "floor_side_view.png"):
        if (asset / name).exists():
            shutil.copyfile(asset / name, pictures / f"{scene.name}_{name}")
            pics[name[:-4]] = f"{scene.name}_{name}"
    pics["views"] = egocentric_views(gs, catalog, scene, emb, pictures)
    main = cm_info.get("embodiments", {}).get(emb.name, {})
    return {
        "scene": scene.name, "scene_id": scene.scene_id, "source": scene.path, "format": scene.format,
        "gaussians": ingest["validation"]["n_input"], "read_s": round(read_s, 2),
        "floaters": ingest["content"]["floaters"], "content_box_m": ingest["content"]["content_box_m"],
        "all_box_m": ingest["content"]["all_box_m"],
        "up_axis": align["up_axis"], "tilt_deg": round(align["tilt_from_nearest_axis_deg"], 3),
        "floor_error_m": round(floor_error(content_of(gs)), 4),
        "floor_level": floor_level(content_of(gs).means, content_of(gs).alphas),
        "floor_to_ceiling_m": align["floor_to_ceiling_m"], "ceiling_from": align["ceiling_from"],
        "narrowest_gaps_m": cm_info.get("scale", {}).get("narrowest_gaps_m"),
        "warnings": cm_info.get("warnings", []),
        "grid_shape": vox.get("grid_shape"), "grid_voxels": vox.get("grid_voxels"),
        "content_voxels": vox.get("content_voxels"),
        "seconds": {s: marker(catalog, scene, s).get("duration_s") for s in STAGES},
        "free_area_m2": main.get("free_area_m2"), "main_component_area_m2": main.get("main_component_area_m2"),
        "free_components": main.get("free_components"),
        "episodes": episode_counts(catalog, scene), "oracle_sr": oracle_sr(data, scene.scene_id),
        "semantics": {k: v for k, v in marker(catalog, scene, "semantics").get("info", {}).items()
                      if k in ("labels_from", "shortfall", "instances", "segmenter")},
        "objectnav_rejections": marker(catalog, scene, "objectnav_episodes").get("info", {}).get("tasks", {})
        .get("objectnav", {}).get("rejections", {}),
        "screening": marker(catalog, scene, "episodes").get("info", {}).get("screening", {}),
        "screen_rejections": {t: {k: v for k, v in r.get("rejections", {}).items() if "screened" in k or "blurred" in k}
                              for st in ("episodes", "objectnav_episodes")
                              for t, r in marker(catalog, scene, st).get("info", {}).get("tasks", {}).items()},
        "render_fp_est": round(rc["fp_est"], 4), "render_fn_est": round(rc["fn_est"], 4),
        "render_check": {k: rc[k] for k in ("render_free", "render_blocked", "costmap_blocked", "poses", "fp_ci95",
                                            "fn_ci95", "fn_noise_only")} | {"seconds": round(rc_s, 1)},
        "direct_evidence": {k: rc["direct"][k] for k in ("fp_est", "fn_est", "fp_ci95", "fn_ci95", "render_blocked")},
        "render_vs_direct_agreement": round(float((rc["render_blocked_mask"] == rc["direct_blocked_mask"]).mean()), 4),
        "pictures": pics,
    }


def objectnav_labelled(data: Path, executor: str, pictures: Path) -> list[dict]:
    """ObjectNav on the real labelled scans (scenes=real_labelled): episodes per category, the
    goal mapping, the oracle's SR under both protocols, and one rendered goal view per category
    (CPU renderer, 320x240, from the first view point of the episode's goal instance; pictures
    kept out of git)."""
    import pandas as pd
    from omegaconf import OmegaConf
    from PIL import Image

    from benchmarks.captures.scan_truth import measure
    from navcore.io.catalog import Catalog
    from navcore.render import Renderer
    from navcore.render.camera import embodiment_camera
    from pipeline.config import CONF_DIR
    from pipeline.executor import execute

    over = ["scenes=real_labelled", f"executor={executor}", "task=[objectnav]"]
    s = execute(compose(str(data), *over, "stages=[episodes]"))
    for p in PROTOCOLS:
        execute(compose(str(data), *over, "stages=[evaluate]", "evaluate.agent=oracle", f"evaluate.protocol={p}",
                        "evaluate.render=false", "evaluate.tasks=[objectnav]"))
    cfg = compose(str(data), *over)
    emb = OmegaConf.to_object(cfg.embodiment)
    catalog = Catalog(CONF_DIR.parent / cfg.scenes.catalog, data)
    out = []
    for scene in catalog.select():
        sem = marker(catalog, scene, "semantics").get("info", {})
        ep_info = marker(catalog, scene, "objectnav_episodes").get("info", {}).get("tasks", {}).get("objectnav", {})
        row = {"scene": scene.name, "labels_from": sem.get("labels_from"), "goal_mapping": sem.get("goal_mapping", {}),
               "failures": [f["error"] for f in s["failures"] if f["scene_id"] == scene.scene_id],
               "episodes": 0, "by_category": {}, "rejections": ep_info.get("rejections", {}),
               "oracle_sr": oracle_sr(data, scene.scene_id), "goal_views": {}}
        try:  # the costmap against the scan's own points, each embodiment's (benchmarks.captures.scan_truth)
            row["scan_truth"] = measure(Path(scene.path), 4000)
        except (ValueError, FileNotFoundError) as e:  # no per-point labels (a labels.json scan)
            row["scan_truth"] = {"absent": f"{type(e).__name__}: {e}"}
        p = catalog.path("episodes", scene, task="objectnav")
        if p.exists():
            e = pd.read_parquet(p)
            row["episodes"] = len(e)
            row["by_category"] = {str(k): int(v) for k, v in e["goal_object_category"].value_counts().sort_index().items()}
            gs, _ = catalog.dataset("aligned", scene).load()
            poses = []
            for cat, g in e.groupby("goal_object_category"):
                goal = next(x for x in json.loads(g.iloc[0]["goals_json"]) if x["object_id"] == g.iloc[0]["goal_object_id"])
                v = goal["view_points"][0]
                poses.append((str(cat), [v["position"][0], v["position"][1], v["yaw"]]))
            if poses:
                vm, ks, w, h = embodiment_camera(emb, np.array([q for _, q in poses]), 320, 240)
                rgb = Renderer(gs, "cpu").render(vm, ks, w, h).rgb.numpy()
                for (cat, _), im in zip(poses, rgb):
                    name = f"{scene.name}_goal_{cat}.png"
                    Image.fromarray((im * 255).round().astype(np.uint8)).save(pictures / name)
                    row["goal_views"][cat] = name
        out.append(row)
    return out


def synthetic_validation(n_scenes: int, poses: int, gaussians: int, levels=("moderate", "heavy")) -> dict:
    """Realistic synthetic scenes (n_scenes seeds per level): costmap vs mesh, and the render
    estimator vs the truth at the same poses. The costmap's rates and the alignment are the first
    level's; the estimator's errors are over every level."""
    from benchmarks.map.spatial import run_scene
    from navcore.nav.embodiment import Embodiment
    from navcore.voxels.field import VoxelizeConfig
    from stages.costmap.render_check import RenderCheckConfig

    rows = []
    for level, k in ((lv, k) for lv in levels for k in range(n_scenes)):
        t0 = time.perf_counter()
        r = run_scene(200 + k, gaussians, Embodiment(), VoxelizeConfig(), 3000, 600, realism=level,
                      resolutions=(0.05,), timing=False, render_check=RenderCheckConfig(poses=poses))
        r5 = r["res"]["0.05"]
        rows.append({"level": level, "seed": r["seed"], "align_tilt_deg": r["align_tilt_deg"],
                     "align_height_m": r["align_height_m"],
                     **{k2: r5[k2] for k2 in ("fp_state", "fn_state", "neg_state", "pos_state", "fp_motion",
                                              "fn_motion", "neg_motion", "pos_motion")},
                     "render_check": r["render_check"], "seconds": time.perf_counter() - t0})
        print(f"synthetic {level} {200 + k}: FP {r5['fp_state']}/{r5['neg_state']} FN {r5['fn_state']}/"
              f"{r5['pos_state']} estimate {r['render_check']}", flush=True)
    first = [r for r in rows if r["level"] == levels[0]]
    tot = lambda key: sum(r[key] for r in first)  # noqa: E731
    errs = {lv: [e for r in rows if r["level"] == lv for e in (r["render_check"]["abs_err_fp"],
                                                               r["render_check"]["abs_err_fn"])] for lv in levels}
    every = [e for v in errs.values() for e in v]
    return {"scenes": rows, "levels": list(levels), "realism_fp_state": tot("fp_state") / max(tot("neg_state"), 1),
            "realism_fn_state": tot("fn_state") / max(tot("pos_state"), 1),
            "realism_fp_motion": tot("fp_motion") / max(tot("neg_motion"), 1),
            "realism_fn_motion": tot("fn_motion") / max(tot("pos_motion"), 1),
            "estimator_abs_err": float(np.mean(every)), "estimator_abs_err_max": float(np.max(every)),
            "estimator_abs_err_by_level": {lv: {"mean": float(np.mean(v)), "max": float(np.max(v))}
                                           for lv, v in errs.items()},
            "realism_align_max_tilt_deg": max(r["align_tilt_deg"] for r in first),
            "realism_align_max_height_m": max(r["align_height_m"] for r in first)}


def scan_truth_row(scan: str, embodiment: str, floor: str, r: dict) -> str:
    """One row of the scan-truth table: poses free / blocked, FP and FN with their intervals, and the
    area rates (benchmarks.captures.scan_truth's figures `r`)."""
    c = r.get("cells")
    area = f"{c['fp_rate']:.1%} / {c['fn_rate']:.2%}" if c else "-"
    return (f"| {scan} | {embodiment} | {floor} | {r['scan_free']} / {r['scan_blocked']} | "
            f"{r['fp_rate']:.1%} ({r['fp_ci95'][0]:.1%}-{r['fp_ci95'][1]:.1%}) | {r['fn_rate']:.2%} "
            f"({r['fn_ci95'][0]:.2%}-{r['fn_ci95'][1]:.2%}) | {area} |")


def markdown(rep: dict, pictures_rel: str) -> str:
    pct = lambda v: "n/a" if v is None else f"{100 * v:.1f} %"
    ci = lambda c: f"{100 * c[0]:.1f}-{100 * c[1]:.1f} %"  # noqa: E731
    lines = [f"# bench-real ({rep['machine']})", "",
             "Real trained indoor scenes (`catalogs/real_indoor.yaml`), default parameters. Reproduce: `make bench-real`.",
             "", "| | " + " | ".join(s["scene"] for s in rep["scenes"]) + " |",
             "|---|" + "---|" * len(rep["scenes"])]
    rows = [
        ("Gaussians (read s)", lambda s: f"{s['gaussians']:,} ({s['read_s']:.1f} s, {s['format']})"),
        ("floaters removed", lambda s: f"{s['floaters']:,}"),
        ("extent: all / content (m)", lambda s: " x ".join(f"{v:.0f}" for v in s["all_box_m"]) + " / "
         + " x ".join(f"{v:.1f}" for v in s["content_box_m"])),
        ("up axis (tilt)", lambda s: f"{s['up_axis']} ({s['tilt_deg']:.2f} deg)"),
        ("floor error vs density peak", lambda s: f"{100 * s['floor_error_m']:.1f} cm"),
        ("aligned floor tilt: cell-median plane (95 % CI) / open3d RANSAC", lambda s: "{:.3f} deg ({:.3f}-{:.3f}) / "
         "{:.3f} deg".format(s["floor_level"]["tilt_deg"], *s["floor_level"]["tilt_ci95_deg"],
                             s["floor_level"]["ransac_tilt_deg"])),
        ("aligned floor: 3 x 3 cell-median spread", lambda s: f"{100 * s['floor_level']['spread_3x3_m']:.1f} cm"),
        ("floor to ceiling", lambda s: f"{s['floor_to_ceiling_m']:.2f} m ({s['ceiling_from']})"),
        ("narrowest doorway-like gaps", lambda s: ", ".join(f"{g:.2f}" for g in s["narrowest_gaps_m"] or []) or "none"),
        ("voxel grid / content voxels", lambda s: f"{s['grid_voxels']:,} / {s['content_voxels']:,} "
         f"({s['grid_voxels'] / max(s['content_voxels'], 1):.2f}x)"),
        ("free area (main component), components", lambda s: f"{s['free_area_m2']:.1f} m2 "
         f"({s['main_component_area_m2']:.1f}), {s['free_components']}"),
        ("episodes pointnav / imagenav / objectnav", lambda s: " / ".join(str(s["episodes"][t]) for t in TASKS)),
        ("oracle SR distance / explicit stop", lambda s: f"{s['oracle_sr']['distance']['all']} / "
         f"{s['oracle_sr']['explicit_stop']['all']}"),
        ("render check: FP est (95 % CI)", lambda s: f"{pct(s['render_fp_est'])} ({ci(s['render_check']['fp_ci95'])})"),
        ("render check: FN est (95 % CI)", lambda s: f"{pct(s['render_fn_est'])} ({ci(s['render_check']['fn_ci95'])})"),
        ("render check: FN poses, of them blocked only by splats the costmap calls noise", lambda s:
         f"{round(s['render_fn_est'] * s['render_check']['render_blocked'])}, {s['render_check']['fn_noise_only']}"),
        ("render check: poses, blocked in the render, seconds", lambda s: f"{s['render_check']['poses']}, "
         f"{s['render_check']['render_blocked']}, {s['render_check']['seconds']:.1f}"),
        ("direct evidence: FN (95 % CI), blocked poses", lambda s: f"{pct(s['direct_evidence']['fn_est'])} "
         f"({ci(s['direct_evidence']['fn_ci95'])}), {s['direct_evidence']['render_blocked']}"),
        ("render = direct verdict", lambda s: pct(s["render_vs_direct_agreement"])),
        ("warnings", lambda s: "; ".join(s["warnings"]) or "none"),
        ("screening: score, verdict", lambda s: f"{s['screening'].get('score', float('nan')):.2f}, "
         f"{s['screening'].get('verdict', '-')}"),
        ("screening: blobs / floor holes / views blur / views holes (share of valid cells)", lambda s: " / ".join(
            pct(s["screening"].get(k, 0.0)) for k in ("blur_share", "hole_share", "view_blur_share", "view_hole_share"))),
        ("screening: graph cells kept out (with the margin)", lambda s: pct(s["screening"].get("screened_share_of_graph", 0.0))),
        ("screening: rejections pointnav; imagenav", lambda s: "; ".join(
            ", ".join(f"{k} {v}" for k, v in s["screen_rejections"].get(t, {}).items()) or "none" for t in ("pointnav", "imagenav"))),
    ]
    rows += [(f"seconds: {st}", (lambda st: lambda s: f"{s['seconds'][st]:.1f}" if s["seconds"][st] else "-")(st))
             for st in STAGES]
    for name, f in rows:
        lines.append(f"| {name} | " + " | ".join(f(s) for s in rep["scenes"]) + " |")
    lines += objectnav_markdown(rep)
    v = rep["synthetic"]
    lines += ["", f"## Realistic synthetic scenes ({len(v['scenes'])} scenes: realism "
              f"{' and '.join(v['levels'])}, against the mesh)", "",
              "| figure | value | target |", "|---|---|---|",
              f"| state FP / FN at 0.05 m ({v['levels'][0]}) | {pct(v['realism_fp_state'])} / "
              f"{pct(v['realism_fn_state'])} | <= 5 % / 0 |",
              f"| motion FP / FN ({v['levels'][0]}) | {pct(v['realism_fp_motion'])} / {pct(v['realism_fn_motion'])} | |",
              *(f"| render estimator, {lv}: mean / max abs. error of FP and FN rates | {pct(e['mean'])} / "
                f"{pct(e['max'])} | <= 2 points |" for lv, e in v["estimator_abs_err_by_level"].items()),
              f"| floor normal / height error, worst scene | {v['realism_align_max_tilt_deg']:.3f} deg / "
              f"{100 * v['realism_align_max_height_m']:.1f} cm | |", "",
              "| level | seed | FP true | FP est | FN true | FN est | render = mesh verdict |",
              "|---|---|---|---|---|---|---|"]
    for r in v["scenes"]:
        c = r["render_check"]
        lines.append(f"| {r['level']} | {r['seed']} | {pct(c['fp_true'])} | {pct(c['fp_est'])} | {pct(c['fn_true'])} | "
                     f"{pct(c['fn_est'])} | {pct(c['render_vs_mesh_agreement'])} |")
    lines += ["", "## Pictures", "",
              f"Written to `{pictures_rel}/` by the run, not committed: the real scenes' sources state no licence, "
              "so their renders (and maps) stay on the machine that made them.", ""]
    for s in rep["scenes"]:
        p = s["pictures"]
        lines.append(f"- {s['scene']}: " + ", ".join(f"`{pictures_rel}/{x}`" for x in
                                                     [p.get("costmap_topdown"), p.get("floor_side_view"), *p["views"]] if x))
    return "\n".join(lines) + "\n"


def objectnav_markdown(rep: dict) -> list[str]:
    """ObjectNav on the real scenes: the trained captures (why none without labels) and the
    labelled scans (per category, the goal mapping, the oracle's SR, the goal views)."""
    lines = ["", "## ObjectNav on real scenes", "", "| scene | labels | episodes by category | oracle SR distance / "
             "explicit stop | no episodes because |", "|---|---|---|---|---|"]
    for s in rep["scenes"]:
        sem = s.get("semantics", {})
        why = "; ".join(x.get("reason", "") for x in sem.get("shortfall", [])) or \
            ", ".join(f"{k} {v}" for k, v in s.get("objectnav_rejections", {}).items())
        sr = lambda p: s["oracle_sr"][p].get("objectnav", "-")  # noqa: E731
        lines.append(f"| {s['scene']} | {sem.get('labels_from') or 'none'} | {s['episodes']['objectnav']} | "
                     f"{sr('distance')} / {sr('explicit_stop')} | {why if not s['episodes']['objectnav'] else ''} |")
    for s in rep.get("objectnav_labelled", []):
        cats = ", ".join(f"{k} {v}" for k, v in s["by_category"].items())
        why = "" if s["episodes"] else ("; ".join(s["failures"]) or ", ".join(f"{k} {v}" for k, v in s["rejections"].items()))
        sr = lambda p: s["oracle_sr"][p].get("objectnav", "-")  # noqa: E731
        lines.append(f"| {s['scene']} (labelled scan) | {s['labels_from']} | {s['episodes']}{f' ({cats})' if cats else ''} | "
                     f"{sr('distance')} / {sr('explicit_stop')} | {why} |")
    lines += ["", "### The costmap against scanned geometry (labelled scans; `python -m benchmarks.captures.scan_truth`)", "",
              "Poses over the scan's floor; blocked when a scanned non-floor point lies in the body cylinder. "
              "FP: scan free, costmap blocked (target <= 10 %); FN: scan blocked, costmap free (target <= 0.5 %).", "",
              "Area: the same on every point of a 2 cm grid over the scan's floor, as shares of the scan's "
              "blocked / free area (no sampling). A scan without per-point labels takes its floor by height.", "",
              "| scan | embodiment (radius, body band) | floor | poses free / blocked | FP (95 % CI) | FN (95 % CI) | area FP / FN |",
              "|---|---|---|---|---|---|---|"]
    for s in rep.get("objectnav_labelled", []):
        r = s.get("scan_truth", {})
        if "fp_rate" not in r:
            lines.append(f"| {s['scene']} | | | n/a: {r.get('absent', 'not measured')} | | | |")
            continue
        for e in (r.get("embodiments") or {r["embodiment"]: r}).values():
            lines.append(scan_truth_row(s["scene"], f"{e['embodiment']} (r {e['radius_m']:g} m, {e['band_m'][0]:g}-"
                                                    f"{e['band_m'][1]:g} m)", e.get("floor", "labelled"), e))
    t = rep.get("trained_scan")
    if t and "fp_rate" in t:
        lines.append(scan_truth_row(f"{t['scene']} ({t['gaussians']:,} Gaussians)", t["embodiment"], "labelled", t))
        a = t["in_aligned_heights"]
        lines += ["", f"The trained 3DGS (`python -m benchmarks.captures.train_on_scan` on a GPU: views of the real scan rendered "
                  f"from poses inside the room, a 3DGS trained on them from a fifth of the scan's points; "
                  f"data/trained_scan/) is compared with the scan in its own frame after its own alignment: the "
                  f"scanned floor lies {100 * t['scan_floor_height_m']:.1f} cm above the model's z = 0, tilted "
                  f"{t['scan_floor_tilt_deg']:.2f} deg; the body band is measured from the scanned floor (from the "
                  f"model's z = 0 instead: FP {a['fp_rate']:.1%}, FN {a['fn_rate']:.2%}). Its screen score "
                  f"{t['screen']['score']:.2f} (blobs {t['screen']['blur_share']:.1%}, unseen by its "
                  f"{t['screen']['capture_cameras']} cameras {t['screen']['unseen_share']:.1%})."]
    elif t:
        lines += ["", f"Trained 3DGS of the scan: {t.get('absent')}"]
    for s in rep.get("objectnav_labelled", []):
        if s["goal_mapping"]:
            lines += ["", f"{s['scene']}: goal categories from dataset classes: " + "; ".join(
                f"{g} <- " + ", ".join(f"{c} ({n})" for c, n in sorted(m.items())) for g, m in sorted(s["goal_mapping"].items()))]
    return lines


def trained_scan(model: Path, poses: int = 4000) -> dict:
    """The costmap of a 3DGS trained in the real ScanNet scan's frame against the scan
    (benchmarks.captures.scan_truth.measure_model), or why not."""
    from benchmarks.captures.scan_truth import measure_model
    from navcore.io.catalog import Catalog
    from pipeline.config import CONF_DIR

    entry = next(e for e in Catalog(CONF_DIR.parent / "catalogs" / "real_labelled.yaml", "data").select()
                 if e.name == "scannet_scene0000_02")
    scan = Path(entry.path)
    if not model.is_file() or not (scan / "coord.npy").is_file():
        return {"absent": f"no trained model at {model} (make bench-trained-scan on a GPU) or no scan at {scan}"}
    return measure_model(model.resolve(), scan, poses)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="data")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", default="docs/bench_real.md")
    ap.add_argument("--executor", default="sync", help="pipeline executor for the real scenes")
    ap.add_argument("--poses", type=int, default=200, help="poses of the render check per scene")
    ap.add_argument("--synthetic-scenes", type=int, default=3)
    ap.add_argument("--no-labelled", dest="labelled", action="store_false",
                    help="skip ObjectNav on the real labelled scans (scenes=real_labelled)")
    ap.add_argument("--synthetic-gaussians", type=int, default=300_000)
    ap.add_argument("--trained-model", default="data/trained_scan/model.ply",
                    help="a 3DGS trained in the ScanNet scan's frame (benchmarks.captures.train_on_scan, on a GPU)")
    args = ap.parse_args(argv)
    from navcore.io.catalog import Catalog
    from pipeline.config import CONF_DIR

    data, out = Path(args.data), Path(args.out)
    pictures = out / "bench_real"
    pictures.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    runs = run_pipeline(str(data), args.executor)
    cfg = compose(str(data))
    catalog = Catalog(CONF_DIR.parent / cfg.scenes.catalog, data)
    failures = [f for r in runs.values() for f in r["failures"]]
    scenes = []
    for scene in catalog.select():
        if any(f["scene_id"] == scene.scene_id for f in failures):
            print(f"{scene.name}: failed ({[f['error'] for f in failures if f['scene_id'] == scene.scene_id]})")
            continue
        scenes.append(scene_report(data, catalog, scene, cfg, args.poses, pictures))
        print(json.dumps({k: v for k, v in scenes[-1].items() if k != "pictures"}), flush=True)
    labelled = objectnav_labelled(data / "real_labelled", args.executor, pictures) if args.labelled else []
    trained = trained_scan(Path(args.trained_model)) if args.labelled else None
    rep = {"machine": machine(), "scenes": scenes, "failures": failures, "objectnav_labelled": labelled,
           "trained_scan": trained,
           "pipeline_wall_s": round(time.perf_counter() - t0, 1),
           "synthetic": synthetic_validation(args.synthetic_scenes, args.poses, args.synthetic_gaussians)}
    rep.update({k: rep["synthetic"][k] for k in ("realism_fp_state", "realism_fn_state", "estimator_abs_err")})
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_real.json").write_text(jsonio.dumps(rep, indent=1))
    md = markdown(rep, str(pictures))
    (out / "bench_real.md").write_text(md)
    write_page(Path(args.docs).name, md)
    print(md)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
