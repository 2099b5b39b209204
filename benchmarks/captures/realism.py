"""make bench-realism: how far the generated world's frames are from the real captures' (issue 82).

Frames are rendered the way every evaluation renders them: the embodiment's camera (its height,
pitch and field of view, so heights and pitches match between the sets) at poses drawn on each
scene's costmap where the robot may stand (clearance at least its radius), any heading, the scene
as the camera sees it (navcore.gaussians.content.camera_scene), on the CPU renderer. Per frame:

- near_black_top: share of the upper third's pixels darker than 16 of 255 in every channel (the
  black void above a room without a ceiling);
- colour_entropy: Shannon entropy (bits) of the frame's RGB histogram, 8 bins a channel;
- gradient_energy: mean squared Sobel gradient of the luminance (0..1 scale);
- spectrum_slope: slope of log radially averaged power against log spatial frequency of the
  luminance, fitted over the middle of the band (natural images: about -2; flat colour steeper);
- depth histogram: the share of pixels per depth bin (nothing hit counts as the last bin).

Then a small CNN learns to tell generated frames from real ones at 64 x 48 (equal numbers of each,
frames of one scene never on both sides of the split: generated scenes split by scene, each real
capture's frames by pose blocks), and its held-out accuracy is reported: 0.5 is indistinguishable.
Medians over 3 seeds.

    python -m benchmarks.captures.realism --generated data --real data/realism/captures \
        [--before data/realism/before] [--frames 120] [--docs]

Writes data/08_reports/realism.json, and with --docs docs/benchmarks/bench_realism.md with a picture of
generated frames (docs/benchmarks/bench_realism_generated.png). Real captures' renders are never
written anywhere (their sources state no licence: ../shared/data/real_indoor/README.md).
"""
from __future__ import annotations

import argparse
import time
import zlib
from pathlib import Path

import numpy as np

from benchmarks import machine, write_report
from benchmarks.pages import PAGES_DIR, ROOT, write_page

DEPTH_BINS = (0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, np.inf)
"""Depth histogram bin edges (m); nothing hit counts as beyond the last finite edge."""
STATS = ("near_black_top", "colour_entropy", "gradient_energy", "spectrum_slope")
TARGETS = {"near_black_top": "<= 0.01 (absolute)", "colour_entropy": ">= 0.85x the captures'",
           "gradient_energy": ">= 0.7x the captures'", "classifier_accuracy": "<= 0.8"}
"""Issue 82's targets for the generated world, against the shared captures."""


def luminance(rgb: np.ndarray) -> np.ndarray:
    """[H, W] float64 in 0..1 of uint8 RGB [H, W, 3] (Rec. 601 weights)."""
    return rgb.astype(np.float64) @ np.array([0.299, 0.587, 0.114]) / 255.0


def near_black_top(rgb: np.ndarray, level: int = 16) -> float:
    """Share of the upper third's pixels with every channel below `level`."""
    top = rgb[: max(1, rgb.shape[0] // 3)]
    return float((top.max(axis=2) < level).mean())


def colour_entropy(rgb: np.ndarray, bins: int = 8) -> float:
    """Entropy (bits) of the joint RGB histogram, `bins` per channel (at most 3 log2(bins))."""
    q = (rgb.astype(np.int64) * bins) // 256
    counts = np.bincount(((q[..., 0] * bins + q[..., 1]) * bins + q[..., 2]).ravel(), minlength=bins ** 3)
    p = counts[counts > 0] / counts.sum()
    return float(-(p * np.log2(p)).sum())


def gradient_energy(rgb: np.ndarray) -> float:
    """Mean squared Sobel gradient magnitude of the luminance (interior pixels)."""
    from scipy.ndimage import sobel

    y = luminance(rgb)
    gx, gy = sobel(y, axis=1, mode="nearest") / 8.0, sobel(y, axis=0, mode="nearest") / 8.0
    return float((gx ** 2 + gy ** 2)[1:-1, 1:-1].mean())


def spectrum_slope(rgb: np.ndarray) -> float:
    """Slope of log power against log frequency (radial average of the luminance's 2-D spectrum,
    Hann-windowed, mean removed), fitted between 1/32 and 1/4 of the sampling rate."""
    y = luminance(rgb)
    h, w = y.shape
    y = (y - y.mean()) * np.outer(np.hanning(h), np.hanning(w))
    power = np.abs(np.fft.fftshift(np.fft.fft2(y))) ** 2
    fy, fx = np.meshgrid(np.fft.fftshift(np.fft.fftfreq(h)), np.fft.fftshift(np.fft.fftfreq(w)), indexing="ij")
    r = np.hypot(fx, fy)
    edges = np.geomspace(1 / 32, 1 / 4, 13)
    idx = np.digitize(r.ravel(), edges)
    pw = power.ravel()
    f, p = [], []
    for k in range(1, len(edges)):
        sel = idx == k
        if sel.any() and pw[sel].mean() > 0:
            f.append(np.sqrt(edges[k - 1] * edges[k]))
            p.append(pw[sel].mean())
    if len(f) < 3:
        return float("nan")
    return float(np.polyfit(np.log(f), np.log(p), 1)[0])


def depth_histogram(depth: np.ndarray) -> np.ndarray:
    """Share of pixels per DEPTH_BINS bin; nothing hit (0, inf or NaN) in the last bin."""
    d = np.where(np.isfinite(depth) & (depth > 0), depth, np.inf)
    return np.histogram(np.minimum(d, 1e9), bins=np.array(DEPTH_BINS[:-1] + (1e10,)))[0] / d.size


def frame_stats(rgb: np.ndarray, depth: np.ndarray) -> dict:
    """Every statistic of one frame (uint8 RGB [H, W, 3], depth [H, W] m)."""
    return {"near_black_top": near_black_top(rgb), "colour_entropy": colour_entropy(rgb),
            "gradient_energy": gradient_energy(rgb), "spectrum_slope": spectrum_slope(rgb),
            "depth_hist": depth_histogram(depth)}


def standing_poses(costmap, radius: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """[n, 3] (x, y, yaw) on cells whose clearance is at least `radius`, any heading."""
    free = np.argwhere(np.asarray(costmap.clearance) >= radius)
    if not len(free):
        raise ValueError("no cell of the costmap has room for the robot")
    cells = free[rng.choice(len(free), size=n, replace=len(free) < n)]
    xy = costmap.cell_centers(cells)
    return np.column_stack([xy, rng.uniform(-np.pi, np.pi, n)])


def render_root(root: Path, frames: int, width: int, height: int, seed: int,
                poses: dict[str, np.ndarray] | None = None) -> dict[str, dict]:
    """scene id -> {"name", "rgb" [F, H, W, 3] uint8, "depth" [F, H, W], "poses" [F, 3], "seconds", "gaussians"} of every
    scene of a data root with a costmap, rendered by the CPU renderer from standing poses (or from the
    given poses of a scene: the same scene of another data root, before and after)."""
    from navcore.eval.dataset import NavDataset
    from navcore.eval.env import SceneContext
    from navcore.gaussians.content import camera_scene
    from navcore.io.catalog import Catalog

    ds = NavDataset(root)
    emb = ds.embodiment
    cat = Catalog.for_root(Path(root))
    out = {}
    for sid in cat.scene_ids("costmaps"):
        scene = cat.scene(sid)
        cm = cat.dataset("costmaps", scene).load(emb.name)
        gs = camera_scene(cat, scene, emb.name)[0]
        ctx = SceneContext(cm, None, emb, gs, "cpu")
        if poses and sid in poses:
            at = poses[sid]
        else:
            at = standing_poses(cm, emb.radius, frames, np.random.default_rng([seed, zlib.crc32(sid.encode())]))
        t0 = time.perf_counter()
        rgb, depth = [], []
        for k in range(0, len(at), 16):
            r, d = ctx.render(at[k:k + 16], width, height)
            rgb.append(r)
            depth.append(d)
        out[sid] = {"name": scene.name, "rgb": np.concatenate(rgb), "depth": np.concatenate(depth), "poses": at,
                    "seconds": time.perf_counter() - t0, "gaussians": len(gs)}
    return out


def summarise(frames: list[dict]) -> dict:
    """Medians of the per-frame statistics and the mean depth histogram of a set of frames."""
    out = {k: float(np.nanmedian([f[k] for f in frames])) for k in STATS}
    out["depth_hist"] = np.mean([f["depth_hist"] for f in frames], axis=0).round(4).tolist()
    out["frames"] = len(frames)
    return out


def classifier_accuracy(gen: list[np.ndarray], real: list[np.ndarray], seed: int, steps: int = 400) -> float:
    """Held-out accuracy of a small CNN telling generated (0) from real (1) frames.

    Args:
        gen, real: per scene, uint8 frames [F, H, W, 3]. The held-out part: a quarter of the
            generated scenes (at least one) and the last quarter of each real scene's frames (its
            poses are independent draws, so a block is as good as a scene here).
        seed: seeds the split of generated scenes, the weights and the batches.
    Returns:
        Accuracy on a class-balanced held-out set.
    """
    import torch
    from torch import nn

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(gen))
    n_test = max(1, len(gen) // 4)
    g_test = np.concatenate([gen[i] for i in order[:n_test]])
    g_train = np.concatenate([gen[i] for i in order[n_test:]])
    cut = [max(1, len(r) * 3 // 4) for r in real]
    r_train = np.concatenate([r[:c] for r, c in zip(real, cut)])
    r_test = np.concatenate([r[c:] for r, c in zip(real, cut)])

    def prep(x):  # [F, H, W, 3] uint8 -> [F, 3, 48, 64] float, area-pooled
        t = torch.as_tensor(x).permute(0, 3, 1, 2).float() / 255.0
        return nn.functional.adaptive_avg_pool2d(t, (48, 64))

    def balanced(a, b):
        n = min(len(a), len(b))
        ia, ib = rng.choice(len(a), n, replace=False), rng.choice(len(b), n, replace=False)
        x = torch.cat([prep(a[ia]), prep(b[ib])])
        return x, torch.cat([torch.zeros(n), torch.ones(n)])

    xtr, ytr = balanced(g_train, r_train)
    xte, yte = balanced(g_test, r_test)
    net = nn.Sequential(nn.Conv2d(3, 16, 5, 2, 2), nn.ReLU(), nn.Conv2d(16, 32, 3, 2, 1), nn.ReLU(),
                        nn.Conv2d(32, 32, 3, 2, 1), nn.ReLU(), nn.AdaptiveAvgPool2d(1), nn.Flatten(), nn.Linear(32, 1))
    opt = torch.optim.Adam(net.parameters(), 1e-3)
    for _ in range(steps):
        b = torch.as_tensor(rng.choice(len(xtr), min(64, len(xtr)), replace=False))
        loss = nn.functional.binary_cross_entropy_with_logits(net(xtr[b]).squeeze(1), ytr[b])
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        return float(((net(xte).squeeze(1) > 0).float() == yte).float().mean())


def picture(frames: np.ndarray, path: Path, cols: int = 6) -> None:
    """A grid of frames [F, H, W, 3], `cols` a row, into a PNG (generated frames only: never a real capture's)."""
    from PIL import Image

    f = frames[: cols * (len(frames) // cols)]
    rows = [np.concatenate(list(f[i:i + cols]), axis=1) for i in range(0, len(f), cols)]
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.concatenate(rows, axis=0)).save(path, optimize=True)


def measure(generated: Path, real: Path, cap: dict, frames: int, width: int, height: int, seeds=(0, 1, 2),
            poses: dict | None = None) -> tuple[dict, dict]:
    """(the report, the generated scenes' frames and poses) of a generated data root against the real
    one's frames `cap` (render_root of `real`); poses: a scene's poses to render it from (another data root's)."""
    gen = render_root(generated, frames, width, height, 0, poses)
    per = {}
    for kind, scenes in (("generated", gen), ("real", cap)):
        for sid, s in scenes.items():
            per[sid] = {"kind": kind, "name": s["name"], "render_s": round(s["seconds"], 1),
                        "frames_per_s": round(len(s["rgb"]) / s["seconds"], 1),
                        **summarise([frame_stats(r, d) for r, d in zip(s["rgb"], s["depth"])])}
    sets = {kind: summarise([frame_stats(r, d) for s in scenes.values() for r, d in zip(s["rgb"], s["depth"])])
            for kind, scenes in (("generated", gen), ("real", cap))}
    ratios = {k: sets["generated"][k] / sets["real"][k] if sets["real"][k] else None
              for k in ("colour_entropy", "gradient_energy")}
    accs = [classifier_accuracy([s["rgb"] for s in gen.values()], [s["rgb"] for s in cap.values()], seed)
            for seed in seeds]
    rep = {"machine": machine(), "generated_root": str(generated), "real_root": str(real), "frames_per_scene": frames,
           "size": [width, height], "renderer": "cpu", "sets": sets, "ratios": ratios, "scenes": per,
           "generated_gaussians_median": float(np.median([s["gaussians"] for s in gen.values()])),
           "classifier_accuracy": float(np.median(accs)), "classifier_accuracies": accs, "targets": TARGETS}
    return rep, {sid: {"rgb": s["rgb"], "poses": s["poses"]} for sid, s in gen.items()}


def markdown(after: dict, picture_name: str | None, before: dict | None = None) -> str:
    """The page: before (the flat world) and after (the world as generated now) against the captures."""
    w, h = after["size"]
    runs = [("before", before), ("after", after)] if before else [("generated", after)]
    r = after["sets"]["real"]
    lines = [f"# Realism: generated frames against the real captures ({after['machine']})", "",
             f"{after['frames_per_scene']} frames a scene at {w} x {h} on the CPU renderer, the embodiment's camera at "
             "poses where the robot may stand (the same height, pitch and field of view in every set), scenes of each data "
             "root: " + "; ".join(f"{name} `{Path(rep['generated_root']).name}` "
                                  f"({sum(s['kind'] == 'generated' for s in rep['scenes'].values())} scenes, median "
                                  f"{rep['generated_gaussians_median']:,.0f} Gaussians rendered)" for name, rep in runs)
             + f"; real: `{Path(after['real_root']).name}` "
             f"({', '.join(s['name'] for s in after['scenes'].values() if s['kind'] == 'real')}).",
             "", "| figure | " + " | ".join(name for name, _ in runs) + " | real captures | "
             + " | ".join(f"{name} / real" for name, _ in runs) + " | target |",
             "|---|" + "---|" * (2 * len(runs) + 2)]
    for k, label in (("near_black_top", "near-black share of the upper third (median)"),
                     ("colour_entropy", "colour histogram entropy, bits (median)"),
                     ("gradient_energy", "gradient energy (median)"), ("spectrum_slope", "power spectrum slope (median)")):
        vals = " | ".join(f"{rep['sets']['generated'][k]:.4g}" for _, rep in runs)
        ratios = " | ".join("-" if rep["ratios"].get(k) is None else f"{rep['ratios'][k]:.2f}x" for _, rep in runs)
        lines.append(f"| {label} | {vals} | {r[k]:.4g} | {ratios} | {TARGETS.get(k, '')} |")
    accs = " | ".join(f"{rep['classifier_accuracy']:.3f}" for _, rep in runs)
    lines += [f"| generated-vs-real classifier, held-out accuracy (median of 3 seeds) | {accs} | | "
              + " | " * (len(runs) - 1) + f" | {TARGETS['classifier_accuracy']} |",
              "", "Depth histogram (share of pixels; the last bin is nothing hit within 8 m):", "",
              "| set | " + " | ".join(f"{a:g}-{b:g} m" for a, b in zip(DEPTH_BINS[:-2], DEPTH_BINS[1:-1])) + " | beyond |",
              "|---|" + "---|" * (len(DEPTH_BINS) - 1)]
    for name, rep in runs:
        lines.append(f"| {name} | " + " | ".join(f"{v:.3f}" for v in rep["sets"]["generated"]["depth_hist"]) + " |")
    lines.append("| real captures | " + " | ".join(f"{v:.3f}" for v in r["depth_hist"]) + " |")
    lines += ["", "Per scene (medians; frames/s: the CPU renderer on this machine):", "",
              "| set | scene | near-black top | entropy | gradient energy | slope | frames/s |", "|---|---|---|---|---|---|---|"]
    for name, rep in runs:
        for sid, s in rep["scenes"].items():
            if s["kind"] == "generated" or rep is after:
                lines.append(f"| {name if s['kind'] == 'generated' else 'real'} | {s['name']} ({sid}) | "
                             f"{s['near_black_top']:.3f} | {s['colour_entropy']:.2f} | {s['gradient_energy']:.2e} | "
                             f"{s['spectrum_slope']:.2f} | {s['frames_per_s']} |")
    if picture_name:
        lines += ["", "Generated frames at the same poses, before (top rows) and after (bottom rows); the real captures' "
                  "renders are not published (their sources state no licence):", "", f"![generated frames]({picture_name})"]
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--generated", type=Path, default=Path("data"), help="a data root of generated scenes (make dataset)")
    ap.add_argument("--before", type=Path, default=None,
                    help="a data root of the same scenes as they looked before (synthetic.look.enabled=false ...)")
    ap.add_argument("--real", type=Path, default=Path("data/realism/captures"), help="a data root of the real captures")
    ap.add_argument("--frames", type=int, default=120, help="frames a scene")
    ap.add_argument("--size", default="160x120", help="render size WxH")
    ap.add_argument("--out", type=Path, default=Path("data/08_reports"))
    ap.add_argument("--docs", action="store_true", help="also write docs/benchmarks/bench_realism.md and its picture")
    a = ap.parse_args(argv)
    w, h = (int(v) for v in a.size.lower().split("x"))
    cap = render_root(a.real, a.frames, w, h, 0)  # the captures' frames, once for both comparisons
    before, old = measure(a.before, a.real, cap, a.frames, w, h) if a.before else (None, None)
    after, gen = measure(a.generated, a.real, cap, a.frames, w, h, poses={k: v["poses"] for k, v in (old or {}).items()})
    rep = {**after, "before": before}
    write_report(a.out, "realism.json", rep, omit=("scenes", "before"))
    if a.docs:
        png = "bench_realism_generated.png"
        scenes = sorted(set(gen) & set(old or gen))  # the same scenes and poses in every row block
        shown = [np.concatenate([frames[s]["rgb"][:6] for s in scenes])[:12] for frames in ((old, gen) if old else (gen,))]
        picture(np.concatenate(shown), ROOT / PAGES_DIR / png)
        write_page("bench_realism.md", markdown(after, png, before))
    return rep


if __name__ == "__main__":
    main()
