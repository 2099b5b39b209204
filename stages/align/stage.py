"""Stage `align`: up axis and floor plane of the scene's content -> rigid transform. Only the
transform is stored (alignment.json): the `aligned` dataset applies it to the canonical store on
read (positions and rotations; floaters too: the renderable model stays whole), so the Gaussians
are stored once. alignment.json also explains the choice (every candidate with its numbers) and reports the metric
scale evidence (floor-to-ceiling height); floor_side_view.png shows the Gaussian density seen from
two sides with the chosen floor. The voxel field in the aligned frame is re-evaluated from the
transformed Gaussians by the costmap stage (exact, unlike resampling the source grid)."""
from __future__ import annotations

import numpy as np
from omegaconf import OmegaConf

from navcore.gaussians.cameras import camera_file, read_cameras
from navcore.gaussians.content import content_of
from navcore.gaussians.floor import AlignConfig, axis_name, fit_floor, floor_transform, nearest_axis
from navcore.gaussians.model import GaussianScene
from navcore.gaussians.surfaces import horizontal_surfaces


def ceiling_height(aligned: GaussianScene, cfg: AlignConfig) -> tuple[float, str]:
    """Height of the ceiling above the floor (metres) in an aligned scene's content: the height
    band above 1.5 m where flat, horizontal Gaussians cover the most area; the 99.5th percentile of
    the content's heights when no ceiling was reconstructed (open halls, sparse captures)."""
    z = aligned.means[:, 2].astype(np.float64)
    facing = horizontal_surfaces(aligned, cfg.flat_ratio, cfg.normal_tolerance_deg) & (z > 1.5)
    top = float(np.percentile(z, 99.5))
    floor_cells = len(np.unique(np.floor(aligned.means[np.abs(z) < 0.1, :2] / cfg.coverage_cell_m).astype(np.int64),
                                axis=0))
    if facing.sum() < 50:
        return top, "content_top"
    bands = np.floor(z[facing] / 0.1).astype(np.int64)
    cells = np.floor(aligned.means[facing, :2] / cfg.coverage_cell_m).astype(np.int64)
    keys = np.unique(np.column_stack([bands, cells]), axis=0)
    b, area = np.unique(keys[:, 0], return_counts=True)
    if area.max() < 0.1 * max(floor_cells, 1):
        return top, "content_top"
    return float((b[np.argmax(area)] + 0.5) * 0.1), "flat_peak"


def side_view(aligned: GaussianScene, title: str):
    """Picture of the Gaussian density seen along y and along x (log scale), floor at z = 0 marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = aligned.means
    lo, hi = np.percentile(p, 0.5, axis=0), np.percentile(p, 99.5, axis=0)
    zlo, zhi = min(lo[2], -1.0), max(hi[2], 2.0)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), dpi=110)
    for ax, k, name in ((axes[0], 0, "x"), (axes[1], 1, "y")):
        bins = [np.arange(lo[k] - 0.5, hi[k] + 0.5, 0.05), np.arange(zlo - 0.2, zhi + 0.2, 0.02)]
        h, xe, ze = np.histogram2d(p[:, k], p[:, 2], bins, weights=aligned.alphas)
        ax.imshow(np.log1p(h.T), origin="lower", extent=(xe[0], xe[-1], ze[0], ze[-1]), aspect="auto", cmap="magma")
        ax.axhline(0.0, color="cyan", lw=1, label="floor (z = 0)")
        ax.set_xlabel(f"{name} (m)")
        ax.set_ylabel("z (m)")
        ax.legend(loc="upper right", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def plt_close(fig) -> None:
    import matplotlib.pyplot as plt

    plt.close(fig)


def run(scene, cfg, catalog) -> dict:
    acfg: AlignConfig = OmegaConf.to_object(cfg.align)
    gs, _ = catalog.dataset("scene", scene).load()
    content = content_of(gs)
    cams = camera_file(scene, catalog)
    c2w = read_cameras(cams, 64, 48)[0] if cams is not None else None
    n, d, info = fit_floor(content, acfg, c2w)
    t = floor_transform(n, d)
    aligned = gs.transformed(t)  # not stored: the `aligned` dataset derives it on read from these 16 numbers
    out = catalog.dataset("alignment", scene)
    aligned_content = content_of(aligned)
    ceiling, how = ceiling_height(aligned_content, acfg)
    tilt = nearest_axis(n)[1]
    up = axis_name(n)
    summary = {"up_axis": up, "floor_normal_source": list(map(float, n)), "floor_offset": d,
               "tilt_from_nearest_axis_deg": tilt, "floor_to_ceiling_m": round(ceiling, 3), "ceiling_from": how,
               "cameras": str(cams) if cams is not None else None}
    out.save({"source_to_aligned": t.tolist(), **summary, "candidates": info})
    fig = side_view(aligned_content, f"{scene.name}: up axis {up}, floor-to-ceiling {ceiling:.2f} m ({how})")
    catalog.dataset("floor_side_view", scene).save(fig)
    plt_close(fig)
    return {"outputs": [str(out.path)], **{k: summary[k] for k in ("up_axis", "tilt_from_nearest_axis_deg",
                                                                "floor_to_ceiling_m")}}
