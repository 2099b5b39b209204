"""A trained 3DGS in the frame of a real scan (issue 35, section 2's stand-in for a published
trained-model + mesh pair, which this machine cannot download): views of the real ScanNet scan
(one splat per scanned point, ../shared/data/real_labelled) are rendered from poses inside the
room, and a 3DGS is trained on them with gsplat's default densification from a sparse, noisy
subset of the scan's points (as SfM would give). The result has what training gives (splats of
every size, floaters and blur where few views reach, thin floors) and the scan is its geometry
truth in the same frame: `python -m benchmarks.captures.scan_truth --model` compares them.

CUDA only (gsplat). Writes model.ply (INRIA layout, degree-0 colour), cameras.json (INRIA layout:
the training views) and train.json (steps, final L1, PSNR on held-out views, seconds).

    python -m benchmarks.captures.train_on_scan SCAN_FOLDER OUT_FOLDER [--steps 7000] [--seed 0]
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

SH_C0 = 0.28209479177387814
WIDTH, HEIGHT, HFOV_DEG = 320, 240, 90.0


def room_poses(coord: np.ndarray, floor: np.ndarray, rng, positions: int = 80, yaws: int = 8) -> np.ndarray:
    """[M, 4, 4] camera -> world (OpenCV axes) inside the room: positions over the scan's floor
    with no scanned point within 0.4 m horizontally between 0.1 and 1.8 m above the floor, at
    1.1-1.5 m, looking around (yaws evenly, a random offset) 10 degrees down."""
    from scipy.spatial import cKDTree

    z0 = float(np.median(coord[floor, 2]))
    band = coord[~floor & (coord[:, 2] > z0 + 0.1) & (coord[:, 2] < z0 + 1.8)]
    cand = coord[floor][rng.choice(floor.sum(), min(20000, floor.sum()), replace=False), :2]
    d, _ = cKDTree(band[:, :2]).query(cand)
    cand = cand[d > 0.4]
    pick = [cand[rng.integers(len(cand))]]  # farthest point sampling: spread over the room
    dist = np.hypot(*(cand - pick[0]).T)
    while len(pick) < min(positions, len(cand)):
        pick.append(cand[int(np.argmax(dist))])
        dist = np.minimum(dist, np.hypot(*(cand - pick[-1]).T))
    out = []
    pitch = math.radians(-10.0)
    for xy in pick:
        h = z0 + rng.uniform(1.1, 1.5)
        for k in range(yaws):
            yaw = 2 * math.pi * k / yaws + rng.uniform(0, 2 * math.pi / yaws)
            fwd = np.array([math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)])
            right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
            down = np.cross(fwd, right)
            m = np.eye(4)
            m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, down, fwd, [xy[0], xy[1], h]
            out.append(m)
    return np.stack(out)


def write_ply(path: Path, means, scales_log, quats, opacity_logit, rgb_dc) -> None:
    """INRIA-layout binary PLY, degree-0 colour (f_dc = SH DC coefficients)."""
    n = len(means)
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
             "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    data = np.zeros((n, len(names)), np.float32)
    data[:, 0:3], data[:, 6:9], data[:, 9] = means, rgb_dc, opacity_logit
    data[:, 10:13], data[:, 13:17] = scales_log, quats
    header = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % n + \
        "".join(f"property float {p}\n" for p in names) + "end_header\n"
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(data.astype("<f4").tobytes())


def main(argv=None) -> int:
    import torch
    from gsplat import DefaultStrategy, rasterization

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scan", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--steps", type=int, default=7000)
    ap.add_argument("--init-share", type=float, default=0.2, help="share of the scan's points the model starts from")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--split-mib", type=int, default=0, help="split model.ply into parts of this many MiB")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rng = np.random.default_rng(args.seed)
    torch.manual_seed(args.seed)
    dev = "cuda"
    coord = np.load(args.scan / "coord.npy").astype(np.float64)
    names = [n.strip().lower() for n in (args.scan / "classes.txt").read_text().splitlines()]
    if "floor" not in names:
        raise ValueError(f"{args.scan / 'classes.txt'}: no 'floor' class; the training poses stand on the scan's "
                         "floor-labelled points")
    floor = np.load(args.scan / "segment.npy") == names.index("floor")
    if floor.sum() < 100:
        raise ValueError(f"{args.scan}: only {int(floor.sum())} floor-labelled points; too few to place cameras on")
    teacher = {k: torch.tensor(v, dtype=torch.float32, device=dev) for k, v in {
        "means": coord, "quats": np.load(args.scan / "quat.npy"), "scales": np.load(args.scan / "scale.npy"),
        "opacities": np.load(args.scan / "opacity.npy"), "colors": np.load(args.scan / "color.npy") / 255.0}.items()}
    c2w = room_poses(coord, floor, rng)
    f = (WIDTH / 2) / math.tan(math.radians(HFOV_DEG) / 2)
    K = torch.tensor([[f, 0, WIDTH / 2], [0, f, HEIGHT / 2], [0, 0, 1]], dtype=torch.float32, device=dev)
    vms = torch.tensor(np.linalg.inv(c2w), dtype=torch.float32, device=dev)
    with torch.no_grad():  # the "photos": the real scan rendered from each pose
        images = torch.cat([rasterization(teacher["means"], teacher["quats"], teacher["scales"], teacher["opacities"],
                                          teacher["colors"], vms[i:i + 16], K[None].expand(len(vms[i:i + 16]), 3, 3),
                                          WIDTH, HEIGHT)[0] for i in range(0, len(vms), 16)])
    held = np.arange(len(vms)) % 10 == 0  # every tenth view held out for PSNR
    train_ids = np.flatnonzero(~held)
    # start: a sparse noisy subset of the scan's points (SfM-like), isotropic, faint
    init = rng.choice(len(coord), int(args.init_share * len(coord)), replace=False)
    pts = coord[init] + rng.normal(0, 0.01, (len(init), 3))
    from scipy.spatial import cKDTree

    d, _ = cKDTree(pts).query(pts, k=4)
    s0 = np.log(np.clip(d[:, 1:].mean(1), 1e-3, 0.2))
    col = np.load(args.scan / "color.npy")[init] / 255.0
    params = torch.nn.ParameterDict({
        "means": torch.nn.Parameter(torch.tensor(pts, dtype=torch.float32, device=dev)),
        "scales": torch.nn.Parameter(torch.tensor(np.repeat(s0[:, None], 3, 1), dtype=torch.float32, device=dev)),
        "quats": torch.nn.Parameter(torch.tensor(np.tile([1.0, 0, 0, 0], (len(pts), 1)), dtype=torch.float32, device=dev)),
        "opacities": torch.nn.Parameter(torch.full((len(pts),), math.log(0.1 / 0.9), device=dev)),
        "sh0": torch.nn.Parameter(torch.tensor((col - 0.5) / SH_C0, dtype=torch.float32, device=dev)[:, None, :]),
    })
    extent = float(np.linalg.norm(coord.max(0) - coord.min(0))) / 2
    lrs = {"means": 1.6e-4 * extent, "scales": 5e-3, "quats": 1e-3, "opacities": 5e-2, "sh0": 2.5e-3}
    opts = {k: torch.optim.Adam([params[k]], lr=lr, eps=1e-15) for k, lr in lrs.items()}
    strategy = DefaultStrategy(verbose=False)
    strategy.check_sanity(params, opts)
    state = strategy.initialize_state(scene_scale=extent)
    losses = []
    for step in range(args.steps):
        i = int(train_ids[rng.integers(len(train_ids))])
        img, _, info = rasterization(params["means"], params["quats"], torch.exp(params["scales"]),
                                     torch.sigmoid(params["opacities"]), params["sh0"], vms[i:i + 1], K[None],
                                     WIDTH, HEIGHT, sh_degree=0, packed=False)
        strategy.step_pre_backward(params, opts, state, step, info)
        loss = (img[0] - images[i]).abs().mean()
        loss.backward()
        for o in opts.values():
            o.step()
            o.zero_grad(set_to_none=True)
        strategy.step_post_backward(params, opts, state, step, info, packed=False)
        losses.append(float(loss))
    with torch.no_grad():
        psnr = []
        for i in np.flatnonzero(held):
            img = rasterization(params["means"], params["quats"], torch.exp(params["scales"]),
                                torch.sigmoid(params["opacities"]), params["sh0"], vms[i:i + 1], K[None], WIDTH, HEIGHT,
                                sh_degree=0)[0][0].clamp(0, 1)
            psnr.append(float(-10 * torch.log10(((img - images[i]) ** 2).mean())))
    args.out.mkdir(parents=True, exist_ok=True)
    q = torch.nn.functional.normalize(params["quats"], dim=-1)
    write_ply(args.out / "model.ply", params["means"].detach().cpu().numpy(), params["scales"].detach().cpu().numpy(),
              q.detach().cpu().numpy(), params["opacities"].detach().cpu().numpy(),
              params["sh0"][:, 0].detach().cpu().numpy())
    cams = [{"id": k, "img_name": f"view_{k:04d}", "width": WIDTH, "height": HEIGHT, "position": c[:3, 3].tolist(),
             "rotation": c[:3, :3].tolist(), "fx": f, "fy": f} for k, c in enumerate(c2w[~held])]
    (args.out / "cameras.json").write_text(json.dumps(cams, allow_nan=False))  # strict JSON: NaN / inf raise
    rep = {"views": len(vms), "train_views": int((~held).sum()), "steps": args.steps, "init_gaussians": len(pts),
           "gaussians": len(params["means"]), "l1_last_100": float(np.mean(losses[-100:])),
           "psnr_held_out_median": float(np.median(psnr)), "seconds": time.perf_counter() - t0,
           "device": torch.cuda.get_device_name(0)}
    (args.out / "train.json").write_text(json.dumps(rep, indent=1, allow_nan=False))
    if args.split_mib:  # a transfer that takes files of a bounded size: model.ply.partK, joined by cat
        data = (args.out / "model.ply").read_bytes()
        step = args.split_mib << 20
        for k in range(0, len(data), step):
            (args.out / f"model.ply.part{k // step}").write_bytes(data[k:k + step])
        (args.out / "model.ply").unlink()
    print(json.dumps(rep))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
