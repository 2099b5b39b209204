"""bench-spatial: the costmap against the ground-truth mesh queried with python-fcl.

For each synthetic scene: generate -> voxelize (source frame) -> align -> costmap at 0.02, 0.05
and 0.10 m, then the same random queries for both sides, drawn in the scene's floor area:
5,000 states and 1,000 straight motions (<= 0.5 m). FCL checks a cylinder of radius r spanning
the body interval [h_min, h_max] (a motion: the exact swept volume, two end cylinders plus the
box between them) against the mesh. "Positive" = in collision; FN = the costmap accepts a pose
FCL finds in collision (unsafe); FP = the costmap rejects a pose FCL finds free. Rates are
FN / FCL-positives and FP / FCL-negatives.

Writes data/08_reports/bench_spatial.json and bench_spatial.md.
  python -m benchmarks.map.spatial [--scenes 10] [--gaussians 300000] [--out data/08_reports]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.pages import write_page
from navcore.gaussians.content import CONTENT_KEY, content_mask, content_of
from navcore.gaussians.floor import AlignConfig, fit_floor, floor_transform
from navcore.io import jsonio
from navcore.nav.costmap import Costmap
from navcore.nav.embodiment import Embodiment
from navcore.voxels.field import VoxelizeConfig
from stages.costmap.build import CostmapConfig, build_costmap
from stages.costmap.render_check import RenderCheckConfig, check_costmap, estimate_rates
from stages.synthesize.generate import SyntheticConfig, generate_scene
from stages.synthesize.realism import RealismConfig

RESOLUTIONS = (0.02, 0.05, 0.10)


def sample_queries(rooms: np.ndarray, rng, n_states: int, n_motions: int, max_len: float = 0.5):
    """Uniform points in the union of room interiors (canonical frame), and segments from such
    points in a uniform direction with a uniform length in [0, max_len]."""
    area = (rooms[:, 2] - rooms[:, 0]) * (rooms[:, 3] - rooms[:, 1])

    def pts(n):
        r = rooms[rng.choice(len(rooms), n, p=area / area.sum())]
        return np.stack([rng.uniform(r[:, 0], r[:, 2]), rng.uniform(r[:, 1], r[:, 3])], 1)
    states = pts(n_states)
    a = pts(n_motions)
    th = rng.uniform(-np.pi, np.pi, n_motions)
    ln = rng.uniform(0, max_len, n_motions)
    b = a + np.stack([np.cos(th), np.sin(th)], 1) * ln[:, None]
    return states, np.concatenate([a, b], 1)


class FclReference:
    """Cylinder / swept-cylinder collision against the ground-truth mesh (canonical frame)."""

    def __init__(self, mesh, emb: Embodiment, aligned_to_canonical: np.ndarray):
        import fcl

        self.fcl = fcl
        bvh = fcl.BVHModel()
        bvh.beginModel(len(mesh.vertices), len(mesh.faces))
        bvh.addSubModel(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int32))
        bvh.endModel()
        self.mesh = fcl.CollisionObject(bvh, fcl.Transform())
        self.h = emb.h_max - emb.h_min
        self.zc = 0.5 * (emb.h_min + emb.h_max)
        self.r = emb.radius
        self.cyl = fcl.CollisionObject(fcl.Cylinder(self.r, self.h), fcl.Transform())
        self.box_geom = None
        self.a2c = aligned_to_canonical
        self.req = fcl.CollisionRequest()

    def _hit(self, obj, rot_al: np.ndarray, pos_al: np.ndarray) -> bool:
        r = self.a2c[:3, :3] @ rot_al
        t = self.a2c[:3, :3] @ pos_al + self.a2c[:3, 3]
        obj.setTransform(self.fcl.Transform(r, t))
        return self.fcl.collide(obj, self.mesh, self.req, self.fcl.CollisionResult()) > 0

    def state(self, x: float, y: float) -> bool:
        return self._hit(self.cyl, np.eye(3), np.array([x, y, self.zc]))

    def motion(self, x0, y0, x1, y1) -> bool:
        if self.state(x0, y0) or self.state(x1, y1):
            return True
        ln = float(np.hypot(x1 - x0, y1 - y0))
        if ln < 1e-9:
            return False
        c, s = (x1 - x0) / ln, (y1 - y0) / ln
        box = self.fcl.CollisionObject(self.fcl.Box(ln, 2 * self.r, self.h), self.fcl.Transform())
        rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        return self._hit(box, rot, np.array([(x0 + x1) / 2, (y0 + y1) / 2, self.zc]))


def time_per_call(fn, args_list, repeats: int = 5) -> float:
    """Median over repeats of the mean seconds per call of fn(*args) over args_list."""
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for a in args_list:
            fn(*a)
        out.append((time.perf_counter() - t0) / len(args_list))
    return float(np.median(out))


def time_batch(fn, arg, n: int, repeats: int = 7) -> float:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(arg)
        out.append((time.perf_counter() - t0) / n)
    return float(np.median(out))


def align_synthetic(sc, cameras: bool = False) -> tuple[np.ndarray, np.ndarray, "object", "object"]:
    """A generated scene through content and floor alignment as the pipeline does them: (floor
    normal in the source frame, source -> aligned transform, all Gaussians aligned, the aligned
    content). cameras: with the capture path as evidence (the pipeline's case for scenes that
    have cameras; real SOG / SPZ captures have none, hence the default)."""
    from navcore.gaussians.cameras import cameras_from_json

    g = sc.gaussians
    g.extras[CONTENT_KEY] = content_mask(g.means)[0]
    c2w = cameras_from_json({"hfov_deg": 90.0, "poses": sc.cameras}, 64, 48)[0] if cameras else None
    n, d, _ = fit_floor(content_of(g), AlignConfig(), c2w)
    t_align = floor_transform(n, d)
    renderable = g.transformed(t_align)
    return n, t_align, renderable, content_of(renderable)


def run_scene(seed: int, n_gauss: int, emb: Embodiment, vcfg: VoxelizeConfig, n_states: int,
              n_motions: int, realism: "str | RealismConfig" = "none", resolutions=RESOLUTIONS, timing: bool = True,
              render_check: RenderCheckConfig | None = None, ablations: dict | None = None,
              cameras: bool = False, costmap: dict | None = None) -> dict:
    """One synthetic scene through content -> align -> costmap, against FCL on the mesh; with
    render_check, the render-based estimate of the 0.05 m map's FP / FN rates at the first
    render_check.poses of the same states, beside the true rates there; ablations: name -> CostmapConfig
    overrides whose 0.05 m state FP / FN are reported beside the default's; cameras: align with the
    capture path as evidence; costmap: CostmapConfig fields other than the defaults (--costmap)."""
    real = realism if isinstance(realism, RealismConfig) else RealismConfig(level=realism)
    sc = generate_scene(seed, SyntheticConfig(num_gaussians=n_gauss, realism=real))
    n, t_align, renderable, aligned = align_synthetic(sc, cameras)
    # alignment error against the ground truth: normal angle, and height of the true floor
    up_src = sc.transform[:3, :3] @ [0, 0, 1.0]
    tilt = float(np.degrees(np.arccos(np.clip(n @ up_src, -1, 1))))
    rooms = np.asarray(sc.layout.rooms)
    corners = np.array([[r[i], r[j], 0.0] for r in rooms for i in (0, 2) for j in (1, 3)])
    can_to_al = t_align @ sc.transform
    height = float(np.abs((corners @ can_to_al[:3, :3].T + can_to_al[:3, 3])[:, 2]).max())

    from stages.synthesize.surface import layout_mesh

    mesh, _ = layout_mesh(sc.layout.parts)
    rng = np.random.default_rng(seed + 7)
    states_c, segs_c = sample_queries(rooms, rng, n_states, n_motions)
    # canonical (z = 0 floor) -> aligned for our queries
    to_al = lambda p: (np.c_[p, np.zeros(len(p))] @ can_to_al[:3, :3].T + can_to_al[:3, 3])[:, :2]
    states = to_al(states_c)
    segs = np.concatenate([to_al(segs_c[:, :2]), to_al(segs_c[:, 2:])], 1)
    ref = FclReference(mesh, emb, np.linalg.inv(can_to_al))
    ref_state = np.array([ref.state(x, y) for x, y in states])
    ref_motion = np.array([ref.motion(*s) for s in segs])
    out = {"seed": seed, "n_gaussians": len(renderable), "align_tilt_deg": tilt, "align_height_m": height,
           "fcl_state_positive": int(ref_state.sum()), "fcl_motion_positive": int(ref_motion.sum()), "res": {}}
    for res in resolutions:
        t0 = time.perf_counter()
        layers, info = build_costmap(aligned, emb, CostmapConfig(resolution=res, **(costmap or {})), vcfg)
        build_s = time.perf_counter() - t0
        cm = Costmap.from_layers(layers)
        ours_state = ~cm.are_states_valid(states)
        ours_motion = ~cm.are_motions_valid(segs)
        r = {"build_s": build_s,
             "fp_state": int((ours_state & ~ref_state).sum()), "fn_state": int((~ours_state & ref_state).sum()),
             "fp_motion": int((ours_motion & ~ref_motion).sum()), "fn_motion": int((~ours_motion & ref_motion).sum()),
             "neg_state": int((~ref_state).sum()), "pos_state": int(ref_state.sum()),
             "neg_motion": int((~ref_motion).sum()), "pos_motion": int(ref_motion.sum()),
             "clearance_kib": layers.clearance.nbytes / 1024, "occ_bitmap_kib": np.packbits(layers.occ).nbytes / 1024,
             "cells": int(layers.occ.size), "supported_area_m2": info["supported_area_m2"],
             "free_area_m2": info["free_area_m2"]}
        if res == 0.05 and timing:  # query speed on the paper's resolution
            sl = [(float(x), float(y)) for x, y in states]
            ml = [tuple(map(float, s)) for s in segs]
            big_s = np.tile(states, (10, 1))
            big_m = np.tile(segs, (10, 1))
            cm.are_states_valid(big_s[:10]), cm.are_motions_valid(big_m[:10])
            out["timing"] = {
                "state_us_single": 1e6 * time_per_call(cm.is_state_valid, sl),
                "state_us_batch": 1e6 * time_batch(cm.are_states_valid, big_s, len(big_s)),
                "motion_us_single": 1e6 * time_per_call(cm.is_motion_valid, ml),
                "motion_us_batch": 1e6 * time_batch(cm.are_motions_valid, big_m, len(big_m)),
                "fcl_state_us": 1e6 * time_per_call(ref.state, sl[:1000], repeats=3),
                "fcl_motion_us": 1e6 * time_per_call(ref.motion, ml[:500], repeats=3),
            }
        out["res"][f"{res:.2f}"] = r
        for name, kw in (ablations or {}).items() if res == 0.05 else ():
            abl = Costmap.from_layers(build_costmap(aligned, emb, CostmapConfig(resolution=res, **kw), vcfg)[0])
            blocked = ~abl.are_states_valid(states)
            r.setdefault("ablations", {})[name] = {"overrides": kw, "fp_state": int((blocked & ~ref_state).sum()),
                                                   "fn_state": int((~blocked & ref_state).sum())}
        if res == 0.05 and render_check is not None:
            k = render_check.poses
            t0 = time.perf_counter()
            est = check_costmap(aligned, cm, emb, render_check, xy=states[:k])
            true = estimate_rates(ours_state[:k], ref_state[:k])
            out["render_check"] = {
                "fp_est": est["fp_est"], "fn_est": est["fn_est"], "fp_true": true["fp_est"],
                "fn_true": true["fn_est"], "poses": k, "seconds": time.perf_counter() - t0,
                "render_vs_mesh_agreement": float((est["render_blocked_mask"] == ref_state[:k]).mean()),
                "abs_err_fp": abs(est["fp_est"] - true["fp_est"]), "abs_err_fn": abs(est["fn_est"] - true["fn_est"])}
    return out


def voxelize_1m_cpu(repeats: int = 3) -> dict:
    """Time and peak memory of voxelizing a 1M-Gaussian scene at 0.05 m, in a fresh process."""
    code = r"""
import json, time, numpy as np, resource
from navcore.gaussians.content import CONTENT_KEY, content_mask, content_of
from stages.synthesize.generate import SyntheticConfig, generate_scene
from stages.synthesize.realism import RealismConfig
from navcore.voxels.field import VoxelizeConfig, opacity_field
from navcore.voxels.grid import grid_for_points
def status(key):
    for line in open('/proc/self/status'):
        if line.startswith(key): return int(line.split()[1]) * 1024
def reset_peak():
    try:
        open('/proc/self/clear_refs', 'w').write('5')  # resets VmHWM (Linux >= 4.0)
        return True
    except OSError:
        return False
g = generate_scene(4242, SyntheticConfig(num_gaussians=1_000_000)).gaussians
grid = grid_for_points(g.means, 0.05, margin=0.1, lo_q=0.1, hi_q=99.9)
cfg = VoxelizeConfig(device='cpu')
opacity_field(g.subset(slice(0, 1000)), grid, cfg)  # JIT warm-up (cached on disk after the first run)
base = status('VmRSS')
reset = reset_peak()
times = []
for _ in range(REPEATS):
    t = time.perf_counter(); a = opacity_field(g, grid, cfg); times.append(time.perf_counter() - t)
peak = status('VmHWM') if reset else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print(json.dumps({"n_gaussians": len(g), "grid": list(grid.shape), "voxels": grid.n_voxels, "times_s": times,
                  "median_s": float(np.median(times)), "peak_rss_mb": peak / 2**20, "rss_before_mb": base / 2**20,
                  "occupied": int((a >= 0.5).sum()), "peak_is_voxelize_only": reset}))
""".replace("REPEATS", str(repeats))
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", type=int, default=10)
    ap.add_argument("--gaussians", type=int, default=1_000_000,
                    help="Gaussians per scene (real indoor captures hold 1-3 M)")
    ap.add_argument("--states", type=int, default=5000)
    ap.add_argument("--motions", type=int, default=1000)
    ap.add_argument("--sample", default="max", help="voxel sampling: max (ours) or center (DESIGN eq. 1)")
    ap.add_argument("--out", default="data/08_reports")
    ap.add_argument("--skip-voxelize-1m", action="store_true")
    ap.add_argument("--realism-scenes", type=int, default=3,
                    help="scenes of the agreement table at realism level moderate (0 = skip)")
    ap.add_argument("--ablate-faint", action="store_true",
                    help="realism table: also build each map with every opacity as a potential obstacle")
    ap.add_argument("--docs", action="store_true", help="also write docs/bench_spatial.md (make bench-spatial)")
    ap.add_argument("--costmap", action="append", default=[], metavar="K=V",
                    help="a CostmapConfig field other than its default (repeatable; e.g. evidence=surface): the "
                         "figures a changed default would give; refused with --docs, whose page is the defaults'")
    ap.add_argument("--merge-gpu", action="store_true",
                    help="only fold OUT/voxelize_gpu.json into an existing OUT/bench_spatial.json")
    args = ap.parse_args(argv)
    out = Path(args.out)
    costmap = costmap_overrides(args.costmap)
    if costmap and args.docs:
        raise SystemExit("bench-spatial: --costmap measures a setting that is not the default; its page is the defaults' "
                         "(leave out --docs, write to another --out)")
    if args.merge_gpu:
        rep = json.loads((out / "bench_spatial.json").read_text())
        write_report(rep, out, args.docs)
        return 0
    t_run = time.perf_counter()
    emb = Embodiment()
    vcfg = VoxelizeConfig(sample=args.sample)
    scenes = []
    for k in range(args.scenes):
        t0 = time.perf_counter()
        r = run_scene(100 + k, args.gaussians, emb, vcfg, args.states, args.motions, costmap=costmap)
        scenes.append(r)
        r5 = r["res"]["0.05"]
        print(f"scene {k}: FN state {r5['fn_state']} motion {r5['fn_motion']}  FP state {r5['fp_state']}/{r5['neg_state']} "
              f"motion {r5['fp_motion']}/{r5['neg_motion']}  tilt {r['align_tilt_deg']:.4f} deg  "
              f"h {r['align_height_m'] * 1000:.2f} mm  ({time.perf_counter() - t0:.0f} s)", flush=True)
    rep: dict = {"machine": f"{os.cpu_count()} CPU cores ({os.uname().machine})", "embodiment": vars(emb),
                 "voxel_sample": args.sample, "scenes": len(scenes), "gaussians_per_scene": args.gaussians,
                 "states_per_scene": args.states, "motions_per_scene": args.motions,
                 "fp_state": {}, "fn_state": {}, "fp_motion": {}, "fn_motion": {}, "storage_kib": {},
                 "occ_bitmap_kib": {}, "fn_state_count": {}, "fn_motion_count": {}}
    for res in RESOLUTIONS:
        key = f"{res:.2f}"
        tot = lambda k: sum(s["res"][key][k] for s in scenes)
        rep["fp_state"][key] = tot("fp_state") / max(tot("neg_state"), 1)
        rep["fn_state"][key] = tot("fn_state") / max(tot("pos_state"), 1)
        rep["fp_motion"][key] = tot("fp_motion") / max(tot("neg_motion"), 1)
        rep["fn_motion"][key] = tot("fn_motion") / max(tot("pos_motion"), 1)
        rep["fn_state_count"][key] = tot("fn_state")
        rep["fn_motion_count"][key] = tot("fn_motion")
        rep["storage_kib"][key] = float(np.mean([s["res"][key]["clearance_kib"] for s in scenes]))
        rep["occ_bitmap_kib"][key] = float(np.mean([s["res"][key]["occ_bitmap_kib"] for s in scenes]))
    timings = [s["timing"] for s in scenes if "timing" in s]
    for k in timings[0]:
        rep[k] = float(np.median([t[k] for t in timings]))
    rep["speedup_state"] = rep["fcl_state_us"] / rep["state_us_single"]
    rep["speedup_motion"] = rep["fcl_motion_us"] / rep["motion_us_single"]
    rep["speedup_state_batch"] = rep["fcl_state_us"] / rep["state_us_batch"]
    rep["speedup_motion_batch"] = rep["fcl_motion_us"] / rep["motion_us_batch"]
    rep["align_max_tilt_deg"] = max(s["align_tilt_deg"] for s in scenes)
    rep["align_max_height_m"] = max(s["align_height_m"] for s in scenes)
    if not args.skip_voxelize_1m:
        v = voxelize_1m_cpu()
        rep["voxelize_1m_cpu_s"] = v["median_s"]
        rep["voxelize_1m_cpu"] = v
    if args.realism_scenes:
        rows = []
        for k in range(args.realism_scenes):
            r = run_scene(300 + k, args.gaussians, emb, vcfg, args.states, args.motions, realism="moderate",
                          resolutions=(0.05,), timing=False, costmap=costmap,
                          ablations={"all_opacities": {"min_obstacle_alpha": 0.0}} if args.ablate_faint else None)
            rows.append(r)
            r5 = r["res"]["0.05"]
            print(f"realistic scene {k}: FN state {r5['fn_state']} motion {r5['fn_motion']}  FP state "
                  f"{r5['fp_state']}/{r5['neg_state']}  tilt {r['align_tilt_deg']:.3f} deg", flush=True)
        tot = lambda key: sum(r["res"]["0.05"][key] for r in rows)
        rep["realism_moderate"] = {
            "scenes": len(rows), "fp_state": tot("fp_state") / max(tot("neg_state"), 1),
            "fn_state": tot("fn_state") / max(tot("pos_state"), 1), "fn_state_count": tot("fn_state"),
            "fp_motion": tot("fp_motion") / max(tot("neg_motion"), 1),
            "fn_motion": tot("fn_motion") / max(tot("pos_motion"), 1), "fn_motion_count": tot("fn_motion"),
            "align_max_tilt_deg": max(r["align_tilt_deg"] for r in rows),
            "align_max_height_m": max(r["align_height_m"] for r in rows), "per_scene": rows}
        if args.ablate_faint:
            abl = [r["res"]["0.05"]["ablations"]["all_opacities"] for r in rows]
            rep["realism_moderate"]["fp_state_all_opacities"] = sum(a["fp_state"] for a in abl) / max(tot("neg_state"), 1)
            rep["realism_moderate"]["fn_state_all_opacities"] = sum(a["fn_state"] for a in abl) / max(tot("pos_state"), 1)
    rep["per_scene"] = scenes
    rep["costmap_overrides"] = costmap
    rep["wall_s"] = time.perf_counter() - t_run
    rep["argv"] = " ".join(argv if argv is not None else sys.argv[1:])
    write_report(rep, out, args.docs)
    return 0


def costmap_overrides(items: list[str]) -> dict:
    """--costmap K=V items -> CostmapConfig keyword arguments, typed and checked by the config's own
    schema (OmegaConf, as the pipeline's overrides are)."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    keys = [item.partition("=")[0] for item in items]
    try:
        if not all("=" in item for item in items):
            raise ValueError("no '='")
        typed = OmegaConf.merge(OmegaConf.structured(CostmapConfig), OmegaConf.from_dotlist(items))
    except (OmegaConfBaseException, ValueError) as e:
        raise SystemExit(f"bench-spatial: --costmap {' '.join(items)}: K=V with K a CostmapConfig field and V of its "
                         f"type ({str(e).splitlines()[0]})") from None
    return {k: typed[k] for k in keys}


def write_report(rep: dict, out: Path, docs: bool = False) -> None:
    """Merge the GPU voxelization figure (from benchmarks.map.voxelize_gpu on a CUDA machine) when
    present, then write the JSON and the markdown table (and docs/benchmarks/bench_spatial.md with docs)."""
    gpu_file = out / "voxelize_gpu.json"
    if gpu_file.exists():
        gv = json.loads(gpu_file.read_text())
        rep["voxelize_1m_gpu_s"] = gv["median_s"]
        rep["voxelize_1m_gpu"] = gv
    else:
        rep.setdefault("voxelize_1m_gpu_s", None)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_spatial.json").write_text(jsonio.dumps(rep, indent=1))
    (out / "bench_spatial.md").write_text(markdown(rep))
    if docs:
        write_page("bench_spatial.md", markdown(rep))
    print(markdown(rep))


def markdown(rep: dict) -> str:
    pct = lambda v: f"{100 * v:.2f} %"
    lines = [f"# bench-spatial ({rep['scenes']} synthetic scenes, {rep['gaussians_per_scene']:,} Gaussians each, "
             f"{rep['machine']}, voxel sampling '{rep['voxel_sample']}')", "",
             "## Agreement with python-fcl on the ground-truth mesh (paper Table 3)", "",
             "| resolution | state FP | state FN | motion FP | motion FN | clearance field KiB | M_occ bitmap KiB |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for key in rep["fp_state"]:
        lines.append(f"| {key} m | {pct(rep['fp_state'][key])} | {pct(rep['fn_state'][key])} "
                     f"({rep['fn_state_count'][key]}) | {pct(rep['fp_motion'][key])} | {pct(rep['fn_motion'][key])} "
                     f"({rep['fn_motion_count'][key]}) | {rep['storage_kib'][key]:.1f} | {rep['occ_bitmap_kib'][key]:.1f} |")
    lines += ["", "Paper at 0.05 m: FN 0, FP 6.03 % (state) and 4.71 % (motion), 61.6 KiB per map.", ""]
    rm = rep.get("realism_moderate")
    if rm:
        lines += [f"### Realistic scenes (synthetic.realism.level=moderate: reflections, far floaters, noisy "
                  f"floors, haze, sparse coverage, random up axis; {rm['scenes']} scenes, 0.05 m)", "",
                  "| state FP | state FN | motion FP | motion FN | floor normal / height error, worst |",
                  "| --- | --- | --- | --- | --- |",
                  f"| {pct(rm['fp_state'])} | {pct(rm['fn_state'])} ({rm['fn_state_count']}) | {pct(rm['fp_motion'])} "
                  f"| {pct(rm['fn_motion'])} ({rm['fn_motion_count']}) | {rm['align_max_tilt_deg']:.3f} deg / "
                  f"{rm['align_max_height_m'] * 1000:.1f} mm |", "", "Targets: FN 0, state FP <= 5 %.", ""]
        if "fp_state_all_opacities" in rm:
            lines += [f"Ablation (`--ablate-faint`): with every opacity a potential obstacle (costmap.min_obstacle_alpha=0) "
                      f"state FP {pct(rm['fp_state_all_opacities'])}, FN {pct(rm['fn_state_all_opacities'])}: "
                      "the haze of trained scenes fills the air in front of surfaces.", ""]
    lines += ["## Query speed per query (paper Table 2)", "",
              "| query | ours single | ours batched | FCL | speed-up single | speed-up batched |",
              "| --- | --- | --- | --- | --- | --- |",
              f"| state | {rep['state_us_single']:.3f} us | {rep['state_us_batch']:.4f} us | {rep['fcl_state_us']:.2f} us "
              f"| {rep['speedup_state']:.0f}x | {rep['speedup_state_batch']:.0f}x |",
              f"| motion | {rep['motion_us_single']:.3f} us | {rep['motion_us_batch']:.4f} us | {rep['fcl_motion_us']:.2f} us "
              f"| {rep['speedup_motion']:.0f}x | {rep['speedup_motion_batch']:.0f}x |", "",
              "Paper: 0.986 us / 39.65 us (ours), 7.9x / 10.7x over FCL.", "",
              "## Alignment and voxelization", "",
              f"- floor normal error, worst scene: {rep['align_max_tilt_deg']:.4f} deg; floor height error, worst "
              f"scene: {rep['align_max_height_m'] * 1000:.2f} mm"]
    if rep.get("voxelize_1m_cpu"):
        v = rep["voxelize_1m_cpu"]
        lines.append(f"- voxelize {v['n_gaussians']:,} Gaussians at 0.05 m ({v['voxels']:,} voxels), CPU: "
                     f"{v['median_s']:.2f} s median of {len(v['times_s'])}, peak RSS {v['peak_rss_mb']:.0f} MB "
                     f"({v['peak_rss_mb'] - v['rss_before_mb']:.0f} MB above the loaded scene)")
    if rep.get("voxelize_1m_gpu"):
        v = rep["voxelize_1m_gpu"]
        lines.append(f"- voxelize 1M at 0.05 m on {v.get('device', 'GPU')}: {v['median_s']:.3f} s median, "
                     f"peak GPU memory {v.get('peak_gpu_mb', float('nan')):.0f} MB")
    if rep.get("wall_s"):
        lines += ["", f"This run: `python -m benchmarks.map.spatial {rep.get('argv', '')}`, {rep['wall_s'] / 60:.0f} min wall on "
                  f"{rep['machine']} (query times are absolute figures of a shared machine; the FCL reference was "
                  "timed in the same run)."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
