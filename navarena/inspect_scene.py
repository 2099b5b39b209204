"""``navarena inspect FILE``: a 3DGS file looked at before any pipeline run, in seconds.

Reads the file with the pipeline's own readers (format detected from the name and header, values
validated as ingest does), then prints the format, the Gaussian count (and what validation
dropped), the content (the floaters ingest's content rule would leave out), the robust extent
(1st-99th percentile of the content's centres) per axis, the likely up axis and floor found by the
align stage's own method on a sample of the content, the floor-to-top height, and a plausibility
hint on the units; writes a top-down picture (the content's density seen along the up axis, with
a scale bar) beside the output path given, or into the working directory.

    navarena inspect SCENE_FILE [--format FMT] [--picture PNG] [--json]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from navcore.io import jsonio

SAMPLE = 400_000
"""Content Gaussians the up-axis search looks at (a deterministic sample): seconds on big scenes."""


def inspect(path: str, fmt: str | None = None) -> tuple[dict, np.ndarray]:
    """The facts of the module doc as a dict (no picture), and the content's centres [N, 3]."""
    from navcore.gaussians.content import content_mask
    from navcore.gaussians.floor import AlignConfig, axis_name, fit_floor
    from navcore.gaussians.formats import detect_format
    from navcore.gaussians.model import sh_degree_for_coeffs
    from navcore.gaussians.validate import read_validated

    t0 = time.perf_counter()
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{path}: file not found")
    fmt = fmt or detect_format(p)
    scene, report = read_validated(p, fmt)
    keep, _ = content_mask(scene.means)
    content = scene.subset(keep)
    lo, hi = np.percentile(content.means, [1, 99], axis=0)
    sample = content
    if len(content) > SAMPLE:
        sample = content.subset(np.sort(np.random.default_rng(0).choice(len(content), SAMPLE, replace=False)))
    out = {"file": str(p), "format": fmt, "gaussians": int(report.n_input), "dropped_by_validation": int(report.n_input - report.n_kept),
           "content_gaussians": int(keep.sum()), "floaters": int((~keep).sum()),
           "extent_m": {a: round(float(h - lo_), 3) for a, lo_, h in zip("xyz", lo, hi)},
           "sh_degree": sh_degree_for_coeffs(scene.sh.shape[1])}
    try:
        n, d, _ = fit_floor(sample, AlignConfig())
        heights = content.means @ n + d
        top = float(np.percentile(heights, 99))
        out |= {"up_axis": axis_name(n), "up_vector": [round(float(v), 4) for v in n],
                "floor_to_top_m": round(top, 2), "units_hint": _units_hint(top, out["extent_m"])}
    except ValueError as e:  # no floor found: the thinnest extent stands in for the height
        out |= {"up_axis": None, "up_error": str(e), "units_hint": _units_hint(min(out["extent_m"].values()), out["extent_m"])}
    out["seconds"] = round(time.perf_counter() - t0, 1)
    return out, content.means


def _units_hint(top: float, extent: dict) -> str:
    """Whether a floor-to-top height (or the thinnest extent) reads as a room in metres."""
    if top < 1.0:
        return f"floor to top {top:.2f} m: too low for a room in metres (centimetres would read 100x larger: ingest.scale)"
    if top > 30 or max(extent.values()) > 500:
        return f"floor to top {top:.1f} m: large for a building in metres; centimetres? (ingest.scale=0.01)"
    return "plausible for metres"


def picture(m: np.ndarray, path: str, out_png: str, info: dict | None = None) -> str:
    """Top-down density of the content's centres `m` (of the file `path`) seen along the found up
    axis (or +z), in the frame the align stage will give (up turned onto +z: x right, y up, as the
    costmap picture draws it), with a 1 m scale bar."""
    from navcore.optional import require

    require("matplotlib", "the scene picture of navarena inspect").use("Agg")
    import matplotlib.pyplot as plt

    from navcore.gaussians.floor import floor_transform
    from navcore.io.map_picture import FRAME_NOTE

    up = np.asarray((info or {}).get("up_vector") or [0, 0, 1], float)
    # the frame the align stage gives (up turned onto +z by the smallest rotation): the costmap
    # picture's axes, so the two pictures of one scene are drawn the same way round
    p = m @ floor_transform(up, 0.0)[:3, :3].T
    u, v = p[:, 0], p[:, 1]
    (u0, u1), (v0, v1) = np.percentile(u, [0.5, 99.5]), np.percentile(v, [0.5, 99.5])
    res = max(u1 - u0, v1 - v0) / 400
    h, _, _ = np.histogram2d(v, u, bins=[max(int((v1 - v0) / res), 1), max(int((u1 - u0) / res), 1)],
                             range=[[v0, v1], [u0, u1]])
    fig, ax = plt.subplots(figsize=(6, 6 * (v1 - v0) / max(u1 - u0, 1e-9) + 0.6))
    ax.imshow(np.log1p(h), origin="lower", cmap="magma", extent=[u0, u1, v0, v1])
    ax.plot([u0 + 0.05 * (u1 - u0), u0 + 0.05 * (u1 - u0) + 1.0], [v0 + 0.05 * (v1 - v0)] * 2, color="cyan", lw=3)
    ax.text(u0 + 0.05 * (u1 - u0), v0 + 0.08 * (v1 - v0), "1 m", color="cyan")
    ax.set_title(f"{Path(path).name}: content seen along up {(info or {}).get('up_axis') or '+z (assumed)'}\n"
                 f"{FRAME_NOTE}; before the floor is fitted, as the costmap picture after", fontsize=8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    fig.tight_layout()
    fig.savefig(out_png, dpi=100)
    plt.close(fig)
    return out_png


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="navarena inspect", description=__doc__.split("\n")[0].split(": ", 1)[1])
    ap.add_argument("file", help="a 3DGS file or folder (.ply, .spz, .splat, .sog, lod-meta.json, .npy folder)")
    ap.add_argument("--format", default=None, help="force a reader (inria_ply, supersplat_ply, splat, spz, sog, npy_folder)")
    ap.add_argument("--picture", default=None, help="top-down PNG to write (default: <file name>_topdown.png here)")
    ap.add_argument("--json", action="store_true", help="print the facts as JSON")
    a = ap.parse_args(argv)
    try:
        info, means = inspect(a.file, a.format)
    except (FileNotFoundError, ValueError) as e:  # SceneFormatError is a ValueError naming the file
        print(f"navarena inspect: {e}", file=sys.stderr)
        return 2
    from navcore.optional import MissingPackage

    try:  # the facts do not need the picture's package (the media extra): without it they still print
        info["picture"] = picture(means, a.file, a.picture or f"{Path(a.file).name.replace('.', '_')}_topdown.png", info)
    except MissingPackage as e:
        info["picture"] = f"none ({e})"
    if a.json:
        print(jsonio.dumps(info, indent=1))
        return 0
    ext = info["extent_m"]
    print(f"{info['file']}\n  format          {info['format']} (SH degree {info['sh_degree']})\n"
          f"  Gaussians       {info['gaussians']:,} ({info['dropped_by_validation']:,} dropped by validation)\n"
          f"  content         {info['content_gaussians']:,} ({info['floaters']:,} floaters left out)\n"
          f"  extent (1-99 %) x {ext['x']} m, y {ext['y']} m, z {ext['z']} m")
    if info.get("up_axis"):
        print(f"  up axis         {info['up_axis']}  {info['up_vector']}\n"
              f"  floor to top    {info['floor_to_top_m']} m: {info['units_hint']}")
    else:
        print(f"  up axis         not found: {info.get('up_error')}\n  units           {info['units_hint']}")
    print(f"  picture         {info['picture']}\n  ({info['seconds']} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
