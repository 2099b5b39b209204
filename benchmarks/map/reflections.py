"""Reflections and mirrored geometry: the floor and the costmap at every reflection level.

Procedural scenes with the realism knobs of reflections only (glossy floor tiles, a floor fading
under them, the room mirrored below, wall mirrors), each against the same scene without them:
the floor's height error at the rooms' corners and its tilt, and the costmap's state FP / FN at
0.05 m against the layout mesh (python-fcl), as in benchmarks.map.spatial.

    python -m benchmarks.map.reflections [--seeds 300,301,302] [--docs]   -> data/08_reports/reflections.json
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from benchmarks.pages import write_page
from navcore.io import jsonio

REFLECTION_LEVELS = {
    "none": {},
    "mirrored_room": dict(reflection_fraction=0.6, reflection_alpha=0.9),
    "glossy_patches": dict(reflection_fraction=0.8, reflection_alpha=0.9, reflection_coverage=0.5,
                           reflection_floor_alpha=0.2),
    "glossy_floor": dict(reflection_fraction=0.8, reflection_alpha=0.9, reflection_floor_alpha=0.2),
    "wall_mirrors": dict(mirror_walls=3, reflection_alpha=0.9),
    "heavy": dict(level="heavy"),
    "heavy_and_mirrors": dict(level="heavy", reflection_fraction=0.8, reflection_alpha=0.8, reflection_coverage=0.7,
                              reflection_floor_alpha=0.3, mirror_walls=2),
    "deep_glossy_floor": dict(reflection_fraction=0.8, reflection_alpha=0.9, reflection_floor_alpha=0.2,
                              reflection_depth=2.5),
}
"""Knobs of each level on top of level none (heavy: every artefact of that preset; heavy_and_mirrors
adds stronger reflections and wall mirrors to it and is compared with heavy); deep_glossy_floor
mirrors 2.5 m of the room under a floor faded to a fifth everywhere: the limit of what is found."""


WITH_CAMERAS = ("deep_glossy_floor",)
"""Levels measured a second time with the capture path as the aligner's evidence (the pipeline's
case for scenes with cameras.json; the real SOG / SPZ captures have none)."""


def levels() -> dict[str, tuple[dict, bool]]:
    """name -> (realism knobs, align with the capture cameras)."""
    out = {name: (knobs, False) for name, knobs in REFLECTION_LEVELS.items()}
    out |= {f"{name}, capture cameras": (REFLECTION_LEVELS[name], True) for name in WITH_CAMERAS}
    return out


def run(seeds: list[int], gaussians: int) -> dict:
    from benchmarks.map.spatial import run_scene
    from navcore.nav.embodiment import Embodiment
    from navcore.voxels.field import VoxelizeConfig
    from stages.synthesize.realism import RealismConfig

    rows = []
    for seed in seeds:
        for name, (knobs, cameras) in levels().items():
            t0 = time.perf_counter()
            r = run_scene(seed, gaussians, Embodiment(), VoxelizeConfig(), 2000, 10,
                          realism=RealismConfig(**{"level": "none", **knobs}), resolutions=(0.05,), timing=False,
                          cameras=cameras)
            r5 = r["res"]["0.05"]
            rows.append({"seed": seed, "level": name, "tilt_deg": r["align_tilt_deg"], "height_m": r["align_height_m"],
                         "fp_state": r5["fp_state"] / max(r5["neg_state"], 1),
                         "fn_state": r5["fn_state"] / max(r5["pos_state"], 1), "seconds": time.perf_counter() - t0})
            print(json.dumps(rows[-1]), flush=True)
    base = {(r["seed"], r["level"]): r for r in rows}
    for r in rows:
        b = base[(r["seed"], "heavy" if r["level"].startswith("heavy") else "none")]
        r["fp_change_points"] = 100 * (r["fp_state"] - b["fp_state"])
        r["fn_change_points"] = 100 * (r["fn_state"] - b["fn_state"])
    return {"seeds": seeds, "gaussians": gaussians, "rows": rows}


def markdown(rep: dict) -> str:
    lines = ["# Reflections and mirrored geometry", "",
             f"`python -m benchmarks.map.reflections --docs` ({len(rep['seeds'])} procedural scenes of {rep['gaussians']:,} "
             "Gaussians per level; the costmap against the layout mesh at 0.05 m, state FP / FN, change against the "
             "same scene without reflections; targets: floor within 5 cm, tilt <= 0.2 deg, FP / FN within 1 point). "
             "Aligned from the Gaussians alone, as for the real SOG / SPZ captures; rows marked capture cameras use the "
             "generated capture path as evidence too, as the align stage does for scenes with a cameras.json.", "",
             "| level | floor height error max (m) | tilt max (deg) | state FP change max (points) | state FN change max (points) |",
             "|---|---|---|---|---|"]
    for name in levels():
        rs = [r for r in rep["rows"] if r["level"] == name]
        lines.append(f"| {name} | {max(r['height_m'] for r in rs):.3f} | {max(r['tilt_deg'] for r in rs):.3f} | "
                     f"{max(abs(r['fp_change_points']) for r in rs):.2f} | {max(abs(r['fn_change_points']) for r in rs):.2f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="300,301,302")
    ap.add_argument("--gaussians", type=int, default=200_000)
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--docs", action="store_true", help="also write docs/bench_reflections.md")
    args = ap.parse_args(argv)
    rep = run([int(s) for s in args.seeds.split(",")], args.gaussians)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "reflections.json").write_text(jsonio.dumps(rep, indent=1))
    md = markdown(rep)
    if args.docs:
        write_page("bench_reflections.md", md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
