"""Time of one gradient step of navarena train's fit, its episodes padded to the longest (every frame
encoded, as before 2026-12-06) against packed (only the episodes' own frames encoded: NavNet.forward's
`valid`), on this machine's CPU or GPU.

A step is the trainer's: `--batch` whole episodes of the track's network (its default spec, or
`--encoder` / `--size`), forward (with the aux head but for PointNav), a masked loss, backward, an AdamW step. Episode
lengths are drawn from a geometric law of mean `--mean-length` clipped to [2, `--max-length`]
(ObjectNav's DAgger round on the H100: 62,521 frames in 768 episodes, a mean of 81, learner-driven up
to 500 steps), the same draws for both ways; the median of `--steps` steps after one warm-up each.

    python -m benchmarks.baselines.fit_step [--task objectnav] [--batch 8] [--steps 6] [--device cpu]
        -> data/08_reports/fit_step.json
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def measure(task: str, batch: int, steps: int, mean_length: float, max_length: int, device: str, encoder: str | None,
            size: tuple[int, int] | None, chunk: int, seed: int = 0) -> dict:
    import torch

    from navcore.baselines.model import NavNet, NavSpec

    torch.manual_seed(seed)
    kw = {"encoder": encoder} if encoder else {}
    if size:
        kw.update(depth_w=size[0], depth_h=size[1])
    aux = task != "pointnav"  # PointNav's goal is an input, no aux head
    spec = NavSpec(task=task, aux_goal=aux, film=task == "objectnav", **kw)
    net = NavNet(spec).to(device).train()
    opt = torch.optim.AdamW(net.parameters(), 1e-4)
    rng = np.random.default_rng(seed)
    draws = [np.clip(rng.geometric(1.0 / mean_length, batch), 2, max_length) for _ in range(steps + 1)]
    goal_size = spec.goal_size
    out = {}
    for packed in (False, True):
        times, frames_done = [], []
        for k, lens in enumerate(draws):
            t_max = int(lens.max())
            valid = torch.arange(t_max)[:, None] < torch.from_numpy(lens)[None]
            n = int(valid.sum())
            channels = spec.obs_channels + (3 if spec.goal == "image" else 0)
            shape = (n,) if packed else (t_max, batch)
            frames = torch.rand(*shape, channels, spec.depth_h, spec.depth_w, device=device)
            goal = torch.zeros(t_max, batch, goal_size, device=device)
            prev = torch.zeros(t_max, batch, dtype=torch.long, device=device)
            v = valid.to(device)
            if device.startswith("cuda"):
                torch.cuda.synchronize()
            t0 = time.perf_counter()
            res = net(frames, goal, prev, aux=aux, chunk=chunk, valid=v if packed else None)
            (res[0][v].square().mean() + (res[2][v].square().mean() if aux else 0.0)).backward()
            opt.step()
            opt.zero_grad()
            if device.startswith("cuda"):
                torch.cuda.synchronize()
            if k:  # the first step warms up
                times.append(time.perf_counter() - t0)
                frames_done.append(n)
        out["packed" if packed else "padded"] = {"median_s": float(np.median(times)), "steps": len(times),
                                                 "frames_per_s": float(np.sum(frames_done) / np.sum(times))}
    padded_frames = [int(d.max()) * batch for d in draws[1:]]
    own = [int(d.sum()) for d in draws[1:]]
    return {"task": task, "spec": {"encoder": spec.encoder, "width": spec.depth_w, "height": spec.depth_h,
                                   "channels": spec.obs_channels}, "batch": batch, "device": device, "chunk": chunk,
            "mean_length": mean_length, "max_length": max_length,
            "padding_share": float(1 - np.sum(own) / np.sum(padded_frames)), **out,
            "speedup": out["padded"]["median_s"] / out["packed"]["median_s"]}


def markdown(r: dict, machine: str) -> str:
    return "\n".join([
        f"fit step ({r['task']}, {r['spec']['encoder']} {r['spec']['width']} x {r['spec']['height']}, batch {r['batch']}, "
        f"{r['device']}; {machine}): padding {r['padding_share']:.0%} of the padded batch's frames",
        "", "| way | median s a step | own frames / s |", "|---|---:|---:|",
        *(f"| {k} | {r[k]['median_s']:.3f} | {r[k]['frames_per_s']:.0f} |" for k in ("padded", "packed")),
        "", f"packed is {r['speedup']:.1f}x faster a step", ""])


def main(argv=None) -> dict:
    from benchmarks import machine, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="objectnav", choices=("pointnav", "imagenav", "objectnav"))
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--steps", type=int, default=6)
    ap.add_argument("--mean-length", type=float, default=81.0)
    ap.add_argument("--max-length", type=int, default=500)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--encoder", default=None, help="cnn | resnet (the spec's default otherwise)")
    ap.add_argument("--size", type=int, nargs=2, default=None, metavar=("W", "H"))
    ap.add_argument("--chunk", type=int, default=1024, help="navarena train's --encode-chunk")
    ap.add_argument("--out", default="data/08_reports")
    a = ap.parse_args(argv)
    if a.device == "cpu":
        import torch

        torch.set_num_threads(max(1, torch.get_num_threads()))
    r = measure(a.task, a.batch, a.steps, a.mean_length, a.max_length, a.device, a.encoder,
                tuple(a.size) if a.size else None, a.chunk)
    r["machine"] = machine()
    write_report(a.out, "fit_step.json", r)
    print(markdown(r, r["machine"]))
    return r


if __name__ == "__main__":
    main()
