"""The GPU ready check of `make setup-gpu`: is this machine set up for the protocol's renderer?

Prints the device, its driver and the CUDA version the driver supports, torch (and the CUDA it was
built for) and gsplat; compiles gsplat's CUDA kernels (its first call builds them into
TORCH_EXTENSIONS_DIR; the set-up runs this once so that no run pays for it); renders one 640x480
RGB-D frame of a small room with gsplat and with the CPU renderer and reports their agreement
(PSNR, median depth difference). Exits non-zero with what to do when anything is missing.

    python -m navcore.render.ready [--json PATH]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time

import numpy as np


def _driver() -> tuple[str, str]:
    """(driver version, CUDA version the driver supports) from nvidia-smi, or ('', '')."""
    try:
        out = subprocess.run(["nvidia-smi"], capture_output=True, text=True, timeout=30).stdout
        drv = subprocess.run(["nvidia-smi", "--query-gpu=driver_version", "--format=csv,noheader"],
                             capture_output=True, text=True, timeout=30).stdout.strip().splitlines()
    except (OSError, subprocess.TimeoutExpired):
        return "", ""
    cuda = out.split("CUDA Version:")[1].split()[0] if "CUDA Version:" in out else ""
    return (drv[0] if drv else ""), cuda


def test_room(n_side: int = 120, seed: int = 0):
    """A 4 x 4 m room: floor, four walls 2.5 m high and a red box, as flat Gaussians (~70 k)."""
    from navcore.gaussians.model import GaussianScene, rotmat_to_quat

    rng = np.random.default_rng(seed)
    parts = []

    def plane(origin, u, v, nu, nv, colour):
        a, b = np.meshgrid(np.linspace(0, 1, nu), np.linspace(0, 1, nv))
        p = origin + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
        n = np.cross(u, v)
        q = rotmat_to_quat(np.stack([u / np.linalg.norm(u), v / np.linalg.norm(v), n / np.linalg.norm(n)], 1))
        step = max(np.linalg.norm(u) / nu, np.linalg.norm(v) / nv)
        col = np.clip(colour + rng.normal(0, 0.03, (len(p), 3)), 0, 1)
        parts.append((p, np.tile(q, (len(p), 1)), np.tile([step, step, step / 10], (len(p), 1)), col))

    plane(np.array([-2.0, -2, 0]), np.array([4.0, 0, 0]), np.array([0, 4.0, 0]), n_side, n_side, np.array([0.6, 0.55, 0.5]))
    for o, u, col in (([-2, -2, 0], [4, 0, 0], [0.8, 0.8, 0.85]), ([2, -2, 0], [0, 4, 0], [0.7, 0.8, 0.7]),
                      ([2, 2, 0], [-4, 0, 0], [0.8, 0.75, 0.6]), ([-2, 2, 0], [0, -4, 0], [0.6, 0.7, 0.8])):
        plane(np.array(o, float), np.array(u, float), np.array([0, 0, 2.5]), n_side, n_side * 5 // 8, np.array(col))
    plane(np.array([0.5, -0.5, 0.6]), np.array([0.6, 0, 0]), np.array([0, 0.6, 0]), 30, 30, np.array([0.9, 0.1, 0.1]))
    p, q, s, c = (np.concatenate(x) for x in zip(*parts))
    return GaussianScene.from_colors(p, q, s, np.full(len(p), 0.95), c)


def check(width: int = 640, height: int = 480) -> dict:
    """The check's findings; raises SystemExit with what to do when the machine is not ready."""
    import torch

    driver, driver_cuda = _driver()
    info = {"python": sys.version.split()[0], "torch": torch.__version__, "torch_cuda": torch.version.cuda,
            "driver": driver, "driver_cuda": driver_cuda}
    if not torch.cuda.is_available():
        why = ("this torch is a CPU build (torch.version.cuda is None): rerun make setup-gpu, which installs the CUDA "
               "build matching the driver" if torch.version.cuda is None else
               f"torch {torch.__version__} was built for CUDA {torch.version.cuda} but sees no GPU (driver "
               f"{driver or 'not found'}, CUDA {driver_cuda or 'unknown'}): is the driver older than that CUDA? "
               "pick an older build: make setup-gpu CUDA=12.x")
        raise SystemExit(f"GPU not ready: {why}")
    info["device"] = torch.cuda.get_device_name(0)
    try:
        import gsplat
    except ImportError as e:
        raise SystemExit(f"GPU not ready: gsplat does not import ({e}); make setup-gpu installs gsplat==1.5.3") from None
    info["gsplat"] = gsplat.__version__
    from navcore.nav.embodiment import Embodiment
    from navcore.render import Renderer
    from navcore.render.camera import embodiment_camera

    gs = test_room()
    vm, K, w, h = embodiment_camera(Embodiment(), np.array([[-1.5, -1.2, 0.6]]), width, height)
    t0 = time.perf_counter()
    try:
        g = Renderer(gs, "gsplat")
        a = g.render(vm, K, w, h)
        torch.cuda.synchronize()
    except Exception as e:  # noqa: BLE001 - the compile's failure, explained
        msg = str(e).splitlines()[-1] if str(e) else type(e).__name__
        raise SystemExit(f"GPU not ready: gsplat could not build or run its CUDA kernels ({type(e).__name__}: {msg}). "
                         "Its first call compiles them with nvcc: install the CUDA toolkit of torch's CUDA "
                         f"({torch.version.cuda}) or point CUDA_HOME at it; out of memory: lower the batch "
                         "(evaluate.batch_slots, semantics.batch)") from None
    info["first_render_s"] = round(time.perf_counter() - t0, 2)  # the kernels' compile on a fresh machine
    t0 = time.perf_counter()
    for _ in range(10):
        g.render(vm, K, w, h)
    torch.cuda.synchronize()
    info["render_ms"] = round((time.perf_counter() - t0) / 10 * 1000, 2)
    b = Renderer(gs, "cpu").render(vm, K, w, h)
    ga, ca = a.rgb[0].float().cpu().numpy(), b.rgb[0].float().numpy()
    mse = float(np.mean((ga - ca) ** 2))
    info["psnr_db_vs_cpu"] = round(10 * np.log10(1.0 / mse), 2) if mse > 0 else float("inf")
    both = (a.alpha[0].cpu().numpy() > 0.5) & (b.alpha[0].numpy() > 0.5)
    dd = np.abs(a.depth[0].cpu().numpy() - b.depth[0].numpy())[both]
    info["depth_median_abs_m_vs_cpu"] = float(np.median(dd)) if dd.size else None
    info["frame"] = [w, h]
    if info["psnr_db_vs_cpu"] < 35:
        raise SystemExit(f"GPU not ready: gsplat's frame differs from the CPU renderer's ({info['psnr_db_vs_cpu']} dB < 35)")
    return info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", help="also write the findings here")
    args = ap.parse_args(argv)
    info = check()
    for k, v in info.items():
        print(f"{k:28s} {v}")
    print("GPU ready")
    if args.json:
        from navcore.io import jsonio

        with open(args.json, "w") as f:
            f.write(jsonio.dumps(info, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
