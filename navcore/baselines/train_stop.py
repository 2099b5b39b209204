"""navarena train-stop: ObjectNav's stop verifier (navcore.baselines.verifier) from a data root or
a release.

    navarena train-stop data --out runs/objectnav_stop               # poses of the training scenes
    navarena eval data --agent objectnav_bc --agent-arg verifier=runs/objectnav_stop/stop.pt \\
        --protocol explicit_stop --tasks objectnav

Data: for each training scene (the objectnav episodes' train split), `poses_per_scene` robot poses
on the cells the episodes were drawn on (the navigation graph's), rendered with the embodiment's
camera: `near_share` of them within `near_range` metres of an object instance (of any category:
the goals of the scene's ObjectNav episodes, their success regions), facing it up to `yaw_noise`
degrees off for the `facing_share` of those and any way for the rest, the others anywhere. Each
pose is labelled for every category: inside the success radius of one of its regions (the
evaluator's rule). The same is drawn on the held-out scenes (val_unseen, else test) for the check.
Training: binary cross-entropy per category, AdamW, mirrored frames (a pose's label does not depend
on left and right). The run folder gets stop.pt (the checkpoint, with its config, data and curve
in meta) and stop_card.json (the same, readable).

Deterministic for a seed on one device (the CPU renderer; gsplat's sums are not bitwise
reproducible).
"""
from __future__ import annotations

import math
import platform
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from navcore.baselines.agent import default_device
from navcore.baselines.checkpoint import save_checkpoint
from navcore.baselines.model import parameter_count
from navcore.baselines.verifier import KIND, StopNet, StopSpec, stop_input
from navcore.eval.dataset import NavDataset
from navcore.io import jsonio
from navcore.io.atomic import write_text_atomic
from navcore.io.tool_progress import ToolProgress
from navcore.nav.poses import region_distance
from navcore.seeds import stream_seed


@dataclass
class StopConfig:
    """Every setting of a verifier run (recorded in its card)."""

    poses_per_scene: int = 2500
    """Rendered poses per training scene (the defaults are the shipped verifier's recipe)."""
    val_poses_per_scene: int = 500
    """Rendered poses per held-out scene (the check)."""
    near_share: float = 0.7
    """Share of poses near an object instance (the rest anywhere on the graph's cells)."""
    near_range: float = 2.0
    """Metres from an instance's success region (its footprint) that count as near."""
    facing_share: float = 0.75
    """Share of the near poses that face the instance (the rest: any yaw)."""
    yaw_noise: float = 30.0
    """Degrees: how far off the instance's centre a facing pose may look (uniform)."""
    grad_steps: int = 4000
    batch: int = 256
    lr: float = 1e-3
    weight_decay: float = 1e-4
    width: int = 640
    height: int = 480
    """Render size (the network pools to its own input size; the evaluation's 640 x 480: the CPU
    renderer is slow at it, 160 x 120 trains faster and matches it less well)."""
    train_split: str = "train"
    val_split: str | None = None
    """The check's split (None: val_unseen if present, else test)."""
    scenes: int | None = None
    """The first N training scenes (None: all)."""
    renderer: str = "auto"
    device: str = "auto"
    seed: int = 0
    spec: StopSpec = StopSpec()


def scene_regions(ds: NavDataset, sid: str) -> dict[str, tuple[np.ndarray, float]]:
    """category -> (success regions [k, 4] of its instances, success radius), from the scene's
    ObjectNav episodes (every split: the same instances)."""
    out: dict[str, tuple[list, float]] = {}
    for ep in ds.episodes(sid, "objectnav"):
        regions, radius = out.get(ep.category, ([], ep.success_radius))
        regions.extend(map(tuple, np.asarray(ep.regions, np.float64).reshape(-1, 4)))
        out[ep.category] = (regions, radius)
    return {c: (np.asarray(sorted(set(r)), np.float64).reshape(-1, 4), rad) for c, (r, rad) in sorted(out.items())}


def pose_labels(xy: np.ndarray, regions: dict[str, tuple[np.ndarray, float]], categories) -> np.ndarray:
    """uint8 [n, len(categories)]: 1 where a STOP at the point would succeed for the category."""
    out = np.zeros((len(xy), len(categories)), np.uint8)
    for j, c in enumerate(categories):
        if c in regions:
            r, radius = regions[c]
            out[:, j] = region_distance(xy, r) <= radius + 1e-9
    return out


def sample_poses(cells_xy: np.ndarray, regions: dict[str, tuple[np.ndarray, float]], n: int, cfg: StopConfig,
                 rng: np.random.Generator) -> np.ndarray:
    """[n, 3] poses (x, y, yaw) on the cells (see the module docstring)."""
    boxes = np.concatenate([r for r, _ in regions.values()]) if regions else np.zeros((0, 4))
    near = [np.flatnonzero(region_distance(cells_xy, b[None]) <= cfg.near_range) for b in boxes]
    near_ok = [i for i, c in enumerate(near) if len(c)]
    poses = np.empty((n, 3))
    for k in range(n):
        if near_ok and rng.random() < cfg.near_share:
            b = near_ok[int(rng.integers(len(near_ok)))]
            xy = cells_xy[near[b][int(rng.integers(len(near[b])))]]
            if rng.random() < cfg.facing_share:
                cx, cy = (boxes[b, 0] + boxes[b, 2]) / 2, (boxes[b, 1] + boxes[b, 3]) / 2
                yaw = math.atan2(cy - xy[1], cx - xy[0]) + math.radians(rng.uniform(-cfg.yaw_noise, cfg.yaw_noise))
            else:
                yaw = rng.uniform(-math.pi, math.pi)
        else:
            xy = cells_xy[int(rng.integers(len(cells_xy)))]
            yaw = rng.uniform(-math.pi, math.pi)
        poses[k] = (xy[0], xy[1], math.atan2(math.sin(yaw), math.cos(yaw)))
    return poses


class StopData:
    """Rendered verifier inputs (uint8 [n, 4, h, w]: depth then RGB, scaled to 0..255) and labels."""

    def __init__(self, frames: np.ndarray, labels: np.ndarray, scenes: list[str]):
        self.frames, self.labels, self.scenes = frames, labels, scenes

    def __len__(self) -> int:
        return len(self.labels)


def render_poses(ds: NavDataset, scene_ids: list[str], per_scene: int, cfg: StopConfig, what: str,
                 quiet: bool = False) -> StopData:
    """`per_scene` labelled, rendered poses of each scene (each scene's draw depends on the seed and
    the scene only)."""
    dev = default_device(cfg.device)
    frames, labels = [], []
    with ToolProgress(f"train-stop {what}", len(scene_ids), quiet, unit="scenes") as bar:
        for sid in scene_ids:
            regions = scene_regions(ds, sid)
            ctx = ds.scene_context(sid, renderer=cfg.renderer)
            cells_xy = ctx.costmap.cell_centers(ctx.graph.cells)
            rng = np.random.default_rng(stream_seed(cfg.seed, sid, f"train-stop-{what}") % 2**32)
            poses = sample_poses(cells_xy, regions, per_scene, cfg, rng)
            labels.append(pose_labels(poses[:, :2], regions, cfg.spec.categories))
            for a in range(0, len(poses), 256):
                rgb, depth = ctx.render(poses[a:a + 256], cfg.width, cfg.height, on_device=True)
                x = stop_input(depth.to(dev), rgb.to(dev), cfg.spec)
                frames.append((x * 255 + 0.5).to(torch.uint8).cpu().numpy())
            bar.advance(frames=len(poses))
    return StopData(np.concatenate(frames), np.concatenate(labels), list(scene_ids))


def check(net: StopNet, data: StopData, device: str) -> dict:
    """Held-out figures at P >= 0.5: loss, precision and recall of the positives, the positive share."""
    net.eval()
    logits = []
    with torch.no_grad():
        for a in range(0, len(data), 512):
            logits.append(net(torch.from_numpy(data.frames[a:a + 512]).to(device).float().div_(255)).cpu())
    z = torch.cat(logits)
    y = torch.from_numpy(data.labels).float()
    loss = float(nn.functional.binary_cross_entropy_with_logits(z, y))
    pred, pos = (z >= 0), (y > 0.5)
    tp = float((pred & pos).sum())
    return {"loss": round(loss, 4), "precision": round(tp / max(1.0, float(pred.sum())), 4),
            "recall": round(tp / max(1.0, float(pos.sum())), 4), "positive_share": round(float(pos.float().mean()), 4),
            "frames": len(data)}


class StopTrainer:
    """One verifier run: `StopTrainer(root, out, StopConfig()).run()` renders the poses, fits and
    writes out/stop.pt and out/stop_card.json; returns the card."""

    def __init__(self, root, out, cfg: StopConfig, quiet: bool = False):
        self.ds, self.out, self.cfg, self.quiet = NavDataset(root), Path(out), cfg, quiet
        self.root = str(root)
        self.device = default_device(cfg.device)
        tables = {sid: self.ds.episode_table(sid, "objectnav") for sid in self.ds.scene_ids("objectnav")}
        splits = {sid: set(t["split"]) for sid, t in tables.items()}
        self.train_scenes = [s for s, sp in splits.items() if cfg.train_split in sp][:cfg.scenes or None]
        if not self.train_scenes:
            raise SystemExit(f"navarena train-stop: {root} has no objectnav episodes in split {cfg.train_split!r}")
        self.val_split = cfg.val_split or next((s for s in ("val_unseen", "test")
                                                if any(s in sp for sp in splits.values())), None)
        self.val_scenes = [s for s, sp in splits.items() if self.val_split in sp] if self.val_split else []

    def log(self, msg: str) -> None:
        if not self.quiet:
            print(msg, flush=True)

    def run(self) -> dict:
        cfg, dev = self.cfg, self.device
        self.out.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        train = render_poses(self.ds, self.train_scenes, cfg.poses_per_scene, cfg, "train", self.quiet)
        val = render_poses(self.ds, self.val_scenes, cfg.val_poses_per_scene, cfg, "val", self.quiet) \
            if self.val_scenes else None
        render_s = time.perf_counter() - t0
        self.log(f"train-stop: {len(train):,} training poses of {len(self.train_scenes)} scenes "
                 f"({train.labels.any(1).mean():.1%} positive for some category), {render_s:.0f} s")
        torch.manual_seed(cfg.seed)
        net = StopNet(cfg.spec).to(dev)
        opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
        sched = torch.optim.lr_scheduler.OneCycleLR(opt, cfg.lr, total_steps=cfg.grad_steps, pct_start=0.1)
        rng = np.random.default_rng(stream_seed(cfg.seed, "train-stop", "fit") % 2**32)
        curve, losses, t1 = [], [], time.perf_counter()
        checks = max(1, cfg.grad_steps // 5)
        for step in range(cfg.grad_steps):
            net.train()
            pick = rng.integers(0, len(train), cfg.batch)
            x = torch.from_numpy(train.frames[pick]).to(dev).float().div_(255)
            flip = torch.from_numpy(rng.random(cfg.batch) < 0.5).to(dev)
            x = torch.where(flip[:, None, None, None], x.flip(-1), x)
            y = torch.from_numpy(train.labels[pick]).to(dev).float()
            loss = nn.functional.binary_cross_entropy_with_logits(net(x), y)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            losses.append(loss.item())
            if (step + 1) % checks == 0:
                entry = {"step": step + 1, "loss": round(float(np.mean(losses[-checks:])), 4)}
                if val is not None:
                    entry["val"] = check(net, val, dev)
                curve.append(entry)
                dt = time.perf_counter() - t1
                self.log(f"  step {step + 1}/{cfg.grad_steps}: loss {entry['loss']:.3f}"
                         + (f", val loss {entry['val']['loss']:.3f} precision {entry['val']['precision']:.2f} "
                            f"recall {entry['val']['recall']:.2f}" if val is not None else "")
                         + f", {(cfg.grad_steps - step - 1) * dt / (step + 1):.0f} s left")
        fit_s = time.perf_counter() - t1
        meta = {"config": {**{k: v for k, v in asdict(cfg).items() if k != "spec"}, "spec": cfg.spec.to_dict()},
                "data": {"root": self.root, "train_scenes": self.train_scenes, "train_poses": len(train),
                         "val_split": self.val_split, "val_scenes": self.val_scenes,
                         "val_poses": len(val) if val is not None else 0,
                         "positive_share": [round(float(v), 4) for v in train.labels.mean(0)]},
                "curve": curve, "parameters": parameter_count(net)}
        # timings live in the card only: the checkpoint's bytes depend on the config and seed alone
        timing = {"render_s": round(render_s, 1), "fit_s": round(fit_s, 1),
                  "machine": torch.cuda.get_device_name(0) if dev.startswith("cuda") else f"{platform.machine()} CPU"}
        sha = save_checkpoint(self.out / "stop.pt", KIND, cfg.spec.to_dict(), net.state_dict(), meta)
        card = {"file": "stop.pt", "sha256": sha, **meta, "timing": timing}
        write_text_atomic(self.out / "stop_card.json", jsonio.dumps(card, indent=1, sort_keys=True) + "\n")
        return {"model": str(self.out / "stop.pt"), **card}
