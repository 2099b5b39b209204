"""Find the up direction and the floor plane of a scene, and the rigid motion that puts the floor
at z = 0 with +z up. Works in any source frame (up along +-x, +-y or +-z, tilts up to 30 degrees)
and on trained reconstructions: floaters (the content mask keeps them out), reflection Gaussians
mirrored below a shiny floor, ceilings, thick noisy floors, sparse halls.

Evidence comes from the Gaussians themselves: a flat Gaussian (smallest axis well below the other
two) is a piece of surface whose normal is its smallest axis.
1. Up-axis candidates: the three coordinate axes, the dominant normals of the flat Gaussians
   (greedy mode search on the sphere, opacity-weighted), ``up_hint`` and the mean up vector of the
   capture cameras when the scene has them.
2. Indoors a scene is thinnest along gravity (a storey is ~2.5-10 m high, rooms and halls are
   wider): the candidates whose robust extent (2nd-98th percentile of the centres along them) is
   within ``thin_tolerance`` of the thinnest are kept; among them the one with the most flat mass
   facing along it within a third of ``normal_tolerance_deg`` (floor and ceiling; the tight
   tolerance prefers the exact normal to a nearby coordinate axis) is the up axis, refined to the
   mean normal of the flat Gaussians facing along it. ``up_hint`` / cameras restrict the
   candidates to those within ``max_tilt_deg`` of them.
3. Sign and height: for both signs, peaks of the height histograms of the flat Gaussians facing up
   and of all opaque Gaussians (a thick, noisy trained floor may have lost its flat splats but is
   still the room's densest layer) are floor candidates. Each is scored by
   strength (the area the opaque Gaussians of its slab cover / the largest such area: a floor
   spans the room, while table tops, and their mirror images under a shiny floor, are dense but
   small) x room above it (the share of the content's opacity
   that lies above rather than below it: reflections below a shiny floor are a shallow layer, the
   room above reaches the ceiling) x furniture (opacity 0.05-1.2 m above it,
   relative to the best candidate): floors carry furniture, ceilings have lamps at most, and a
   reflected room below a shiny floor is fainter than the floor itself. With cameras, only
   peaks below (nearly) all cameras count, and the sign follows their up vectors.
   Under a glossy floor the mirror symmetry decides (stages/align/design.md): the share of the
   flat surfaces below a candidate whose reflection across it lands on a flat surface above
   (``mirrored_below``) is reflection and leaves the candidate's "below"; a faded floor's flat
   upward splats count towards its area at any opacity >= ``faint_floor_alpha``.
4. Refinement (``refine_floor_plane``): a weighted least-squares plane through the floor slab's
   opaque Gaussians (and the faint flat upward ones of a glossy floor), iterated until the normal
   stops moving in a wide band, then in narrowing bands; floor cells weighted by their evidence,
   capped at the median cell's.
``alignment.json`` gets every candidate with its numbers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from navcore.gaussians.model import GaussianScene
from navcore.gaussians.surfaces import surface_normals


@dataclass
class AlignConfig:
    """Parameters of the floor alignment."""

    max_gaussians: int = 400_000
    """The floor is found on a seeded random subset of at most this many content Gaussians."""
    flat_ratio: float = 0.5
    """A Gaussian is flat (a piece of surface) when its smallest scale is below this share of the middle one."""
    normal_tolerance_deg: float = 15.0
    """A flat Gaussian faces along a direction when its normal is within this angle of it."""
    dominant_normals: int = 4
    """Dominant normal directions searched among the flat Gaussians (besides the coordinate axes)."""
    thin_tolerance: float = 0.15
    """Up-axis candidates with an extent within this share of the thinnest one's compete on flat mass."""
    bin_m: float = 0.02
    """Height histogram bin, metres."""
    min_peak_strength: float = 0.05
    """Floor candidates are histogram peaks at least this share of the strongest."""
    coverage_cell_m: float = 0.25
    """A floor candidate's strength is the area its flat Gaussians cover, counted in cells of this size, metres."""
    coverage_halfwidth_m: float = 0.08
    """... taking the opaque Gaussians (alpha >= refine_min_alpha) within this distance of the candidate's height, metres."""
    furniture_band: tuple[float, float] = (0.05, 1.2)
    """Heights above a floor candidate where furniture stands, metres."""
    up_hint: list[float] | None = None
    """Approximate up direction in the source frame (e.g. [0, 0, 1]); null = any."""
    max_tilt_deg: float = 45.0
    """With up_hint or cameras: largest angle between the up axis and them."""
    refine_band: float = 0.15
    """The plane refinement starts with the floor slab's Gaussians within this distance of the floor
    candidate's plane (wide: a start a degree off across a 15 m hall is 13 cm high at its walls),
    metres."""
    glossy_mirror_share: float = 0.5
    """A chosen floor with at least this mirrored_below is glossy: its refinement takes the flat
    upward splats only (reflections below it are opaque too). Measured: generated glossy floors
    0.999-1.0, trained-like scenes 0.017-0.026, the real room 0.015, the real hall 0.001."""
    refine_band_glossy: float = 0.05
    """The refinement's first band on a glossy floor (glossy_mirror_share), metres: its flat upward
    splats, found by the mirror test, start near the candidate's plane; the wide band would take in
    reflected low surfaces below it."""
    refine_band_halved_to: float = 0.04
    """The band is halved from refine_band down to this, then narrowed to 3 robust sigmas of the
    residuals, metres."""
    refine_band_min: float = 0.01
    """The narrowest band of the refinement, metres."""
    refine_converged_deg: float = 0.002
    """A band has settled when a pass moves the normal less than this, degrees."""
    refine_max_passes: int = 200
    """Bound on the refinement's passes over all bands."""
    refine_min_alpha: float = 0.5
    """Gaussians at least this opaque are 'opaque': a floor candidate's second histogram and its area."""
    faint_floor_alpha: float = 0.05
    """Flat Gaussians facing up count towards a floor candidate's area from this opacity on (a glossy
    floor's own splats fade; opaque ones of any shape count too)."""
    mirror_depth_m: float = 2.5
    """Depth below a floor candidate searched for a mirror image of the room above it, metres."""
    mirror_tolerance_m: float = 0.03
    """A Gaussian below a candidate is a mirror image when its reflection lands this close to one above."""
    mirror_samples: int = 20_000
    """Gaussians below a candidate tested for a mirror image (a seeded subset)."""
    area_balanced_refinement: bool = True
    """The floor plane's least squares weight each floor cell (coverage_cell_m) by its opacity capped
    at the median cell's, so that the densest patch does not tilt the plane of the whole room and a
    cell of a few stray splats does not weigh as much as a full one."""
    seed: int = 0
    """Seed of the subsampling and of the dominant-normal search."""


def _plane_svd(points: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    w = np.ones(len(points)) if weights is None else weights
    c = (points * w[:, None]).sum(0) / w.sum()
    q = (points - c) * np.sqrt(w)[:, None]
    _, _, vt = np.linalg.svd(q, full_matrices=False)
    n = vt[-1]
    return n, -float(n @ c)


def _canonical(d: np.ndarray) -> np.ndarray:
    """Unsigned direction: the sign that makes the largest component positive."""
    d = d / np.linalg.norm(d)
    return d if d[np.argmax(np.abs(d))] > 0 else -d


def dominant_normals(normals: np.ndarray, weights: np.ndarray, k: int, rng: np.random.Generator,
                     tol_deg: float = 8.0, n_probe: int = 1000, n_eval: int = 40_000) -> list[np.ndarray]:
    """Up to k dominant unsigned directions among surface normals (greedy mode search: the probe
    with the most weight within tol_deg, refined by the weighted mean of its inliers, removed)."""
    if len(normals) == 0:
        return []
    pick = rng.choice(len(normals), min(n_eval, len(normals)), replace=False)
    nrm, w = normals[pick], weights[pick]
    cos_t, out = np.cos(np.radians(tol_deg)), []
    alive = np.ones(len(nrm), bool)
    for _ in range(k):
        if w[alive].sum() <= 0.02 * w.sum():
            break
        idx = np.nonzero(alive)[0]
        probes = nrm[rng.choice(idx, min(n_probe, len(idx)), replace=False, p=w[idx] / w[idx].sum())]
        score = np.zeros(len(probes))
        for c0 in range(0, len(probes), 100):
            score[c0:c0 + 100] = ((np.abs(probes[c0:c0 + 100] @ nrm[alive].T) > cos_t) * w[alive]).sum(1)
        d = probes[np.argmax(score)]
        for _ in range(3):  # refine: weighted mean of sign-aligned inliers
            dots = nrm @ d
            inl = alive & (np.abs(dots) > cos_t)
            if not inl.any():
                break
            d = ((nrm[inl] * np.sign(dots[inl])[:, None]) * w[inl, None]).sum(0)
            d /= np.linalg.norm(d)
        out.append(_canonical(d))
        alive &= np.abs(nrm @ d) <= np.cos(np.radians(2 * tol_deg))
    return out


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(abs(a @ b), 0, 1))))


def fit_floor(scene: GaussianScene, cfg: AlignConfig, cameras_c2w: np.ndarray | None = None
              ) -> tuple[np.ndarray, float, dict]:
    """Floor plane n . p + d = 0 (unit n pointing up into the room) of a scene's content.

    Args:
        scene: content Gaussians, source frame, metres.
        cameras_c2w: [M, 4, 4] capture cameras (camera -> source frame, OpenCV axes) or None.
    Returns:
        (n [3], d, info with every up-axis and floor candidate and the choice).
    """
    rng = np.random.default_rng(cfg.seed)
    if len(scene) < 10:
        raise ValueError(f"only {len(scene)} content Gaussians: nothing to find a floor in")
    if len(scene) > cfg.max_gaussians:
        scene = scene.subset(np.sort(rng.choice(len(scene), cfg.max_gaussians, replace=False)))
    p = scene.means.astype(np.float64)
    alpha = scene.alphas
    normals, flat = surface_normals(scene, cfg.flat_ratio)
    cos_t = np.cos(np.radians(cfg.normal_tolerance_deg))
    cos_tight = np.cos(np.radians(cfg.normal_tolerance_deg / 3))  # ranks nearby candidates by exactness

    # 1. up-axis candidates
    # dominant normals first: a floor tilted by a degree keeps its exact normal, not the nearby axis
    cands = [(d, "dominant_normal") for d in dominant_normals(normals[flat], alpha[flat], cfg.dominant_normals, rng)]
    cands += [(e, "axis") for e in np.eye(3)]
    hint = None if cfg.up_hint is None else np.asarray(cfg.up_hint, float) / np.linalg.norm(cfg.up_hint)
    cam_up = cam_pos = None
    if cameras_c2w is not None and len(cameras_c2w):
        cam_up = -np.asarray(cameras_c2w)[:, :3, 1].mean(0)  # OpenCV: y points down
        cam_up /= max(np.linalg.norm(cam_up), 1e-12)
        cam_pos = np.asarray(cameras_c2w)[:, :3, 3]
        cands.append((_canonical(cam_up), "cameras"))
    if hint is not None:
        cands.append((_canonical(hint), "up_hint"))
    axes = []
    for d, src in cands:
        if any(_angle(d, a["dir"]) < 3.0 for a in axes):
            continue
        t = p @ d
        lo, hi = np.percentile(t, [2, 98])
        facing = flat & (np.abs(normals @ d) > cos_tight)
        allowed = all(_angle(d, ref) <= cfg.max_tilt_deg for ref in (hint, cam_up) if ref is not None)
        axes.append({"dir": d, "source": src, "extent_m": float(hi - lo), "allowed": allowed,
                     "flat_facing_fraction": float(alpha[facing].sum() / max(alpha[flat].sum(), 1e-12))})
    ok = [a for a in axes if a["allowed"]]
    if not ok:
        raise ValueError(f"no up-axis candidate within {cfg.max_tilt_deg} deg of the up hint / camera up vectors")
    thin = min(a["extent_m"] for a in ok)
    contenders = [a for a in ok if a["extent_m"] <= (1 + cfg.thin_tolerance) * thin]
    up = max(contenders, key=lambda a: a["flat_facing_fraction"])
    u = up["dir"]
    for _ in range(3):  # refine to the mean normal of the surfaces facing along it (floor, ceiling)
        dots = normals @ u
        inl = flat & (np.abs(dots) > cos_t)
        if inl.sum() < 100:
            break
        v = ((normals[inl] * np.sign(dots[inl])[:, None]) * alpha[inl, None]).sum(0)
        u = v / np.linalg.norm(v)

    # 2. sign and floor height
    t = p @ u
    facing = flat & (np.abs(normals @ u) > cos_t)
    opaque = alpha >= cfg.refine_min_alpha
    e1 = np.cross(u, [1.0, 0, 0] if abs(u[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    plane_xy = np.stack([p @ e1, p @ np.cross(u, e1)], 1)

    # each Gaussian's cfg.coverage_cell_m cell of the plane, numbered once (candidate areas, refinement)
    cell = np.unique(np.floor(plane_xy / cfg.coverage_cell_m).astype(np.int64), axis=0, return_inverse=True)[1].reshape(-1)

    def coverage(sel: np.ndarray) -> int:
        """Area covered by the selected Gaussians, in cfg.coverage_cell_m cells of the plane."""
        return len(np.unique(cell[sel]))
    from scipy.spatial import cKDTree

    # horizontal surfaces only: a wall's reflection lands on the wall about any nearby plane, a table
    # top's only about the true mirror (a plane off by dz puts it 2 dz off)
    flat_idx = np.nonzero(facing)[0]
    pts3 = np.column_stack([plane_xy, t])
    tree = cKDTree(pts3[flat_idx]) if len(flat_idx) else None

    def mirror_share(h: np.ndarray, sign: float, z: float) -> float:
        """Share of the opacity within cfg.mirror_depth_m below the plane at signed height z whose
        mirror image across it lands on a Gaussian above (within cfg.mirror_tolerance_m): the
        mirrored room a glossy floor grows is symmetric about the floor, and about no other plane.
        h: the signed heights (sign * t)."""
        sel = flat_idx[(h[flat_idx] < z - 0.05) & (h[flat_idx] > z - cfg.mirror_depth_m)]
        if len(sel) < 50 or tree is None:
            return 0.0
        if len(sel) > cfg.mirror_samples:
            sel = np.sort(rng.choice(sel, cfg.mirror_samples, replace=False))
        q = pts3[sel].copy()
        q[:, 2] = 2 * sign * z - q[:, 2]  # reflect the height across the plane (t = sign * h)
        dist, _ = tree.query(q, distance_upper_bound=cfg.mirror_tolerance_m)
        w = alpha[sel]
        return float(w[np.isfinite(dist)].sum() / max(w.sum(), 1e-12))

    floors = []
    for sign in (1.0, -1.0):
        if cam_up is not None and sign * (u @ cam_up) < 0:
            continue  # cameras say which way is up
        h = sign * t
        lo, hi = np.percentile(h, [0.5, 99.5])
        bins = np.arange(lo - 0.5, hi + 0.5 + cfg.bin_m, cfg.bin_m)
        peak_ok = np.zeros(len(bins) - 1, bool)
        # peaks of the flat, facing surfaces, and of all the opacity: a thick noisy floor is no
        # longer made of flat Gaussians but is still the densest layer of the room
        for sel in (facing, opaque):
            hist = gaussian_filter1d(np.histogram(h[sel], bins, weights=alpha[sel])[0], 1.0)
            new = (hist >= np.roll(hist, 1)) & (hist >= np.roll(hist, -1)) & (hist >= cfg.min_peak_strength * hist.max())
            for i in np.nonzero(new)[0]:
                if not peak_ok[max(i - 2, 0):i + 3].any():
                    peak_ok[i] = True
        cam_h = None if cam_pos is None else np.percentile(sign * (cam_pos @ u), 5)
        order = np.sort(h)
        csum = np.concatenate([[0.0], np.cumsum(alpha[np.argsort(h)])])
        mass = lambda a, b: csum[np.searchsorted(order, b)] - csum[np.searchsorted(order, a)]
        for i in np.nonzero(peak_ok)[0]:
            z = 0.5 * (bins[i] + bins[i + 1])
            if cam_h is not None and z > cam_h - 0.1:
                continue  # a floor lies below the cameras
            above, below = mass(z + 0.05, np.inf), mass(-np.inf, z - 0.05)
            # a glossy floor's own splats can be faint (the fit explains its shine by the room below):
            # its flat, upward-facing Gaussians count at any opacity
            slab = (opaque | (facing & (alpha >= cfg.faint_floor_alpha))) & (np.abs(h - z) <= cfg.coverage_halfwidth_m)
            mirrored = mirror_share(h, sign, z)
            reflection = mirrored * mass(z - cfg.mirror_depth_m, z - 0.05)
            floors.append({"sign": sign, "height": float(z), "strength": float(coverage(slab)),
                           "mirrored_below": mirrored,
                           "open_above": float(above / max(above + below - reflection, 1e-12)),
                           "furniture": float(mass(z + cfg.furniture_band[0], z + cfg.furniture_band[1]))})
    if not floors:
        raise ValueError("no floor candidate: no horizontal surface found along the up axis"
                         + (" below the capture cameras" if cam_pos is not None else ""))
    top_s = max(f["strength"] for f in floors)
    if top_s <= 0:
        raise ValueError("no floor candidate: no floor layer covers any area (is this a room, in metres?)")
    top_f = max(f["furniture"] for f in floors)
    for f in floors:
        f["strength"] /= top_s
        f["furniture"] /= max(top_f, 1e-12)
        f["score"] = f["strength"] * f["open_above"] * f["furniture"]
    best = max(floors, key=lambda f: f["score"])
    n = best["sign"] * u
    d = -best["height"]

    # 3. refinement: a plane through the floor slab's opaque Gaussians (and the faint flat upward ones
    # of a faded floor), iterated in a wide band until the normal stops moving, then in a band
    # narrowed to 3 robust sigmas of the residuals, again until it settles; each floor cell's
    # weight is its evidence, capped at the median cell's (stages/align/design.md, issue 46)
    # under a glossy floor (a mirror image of the room below it) opaque reflections share the
    # floor's slab: there only the flat upward splats, which the mirror test found, feed the fit
    glossy = best["mirrored_below"] >= cfg.glossy_mirror_share
    cand = (facing & (alpha >= cfg.faint_floor_alpha)) | (opaque & ~glossy)
    n, d, info_refine = refine_floor_plane(p, alpha, cand, cell, n, d, cfg, glossy)
    info_refine["glossy"] = bool(glossy)
    floors.sort(key=lambda f: -f["score"])
    info = {"up_axis_candidates": [{**a, "dir": np.round(a["dir"], 5).tolist()} for a in axes],
            "up_axis": np.round(u, 5).tolist(), "up_axis_source": up["source"],
            "floor_candidates": floors[:12], "chosen": floors.index(best), "normal": n.tolist(), "d": float(d),
            "used_cameras": cam_pos is not None, "gaussians_used": int(len(p)), "refinement": info_refine}
    return n, float(d), info


def refine_floor_plane(p: np.ndarray, alpha: np.ndarray, cand: np.ndarray, cell: np.ndarray, n: np.ndarray,
                       d: float, cfg: AlignConfig, glossy_start: bool = False) -> tuple[np.ndarray, float, dict]:
    """The floor plane n . p + d = 0 refined from a start (the histogram's plane) by weighted least
    squares through the candidate Gaussians ``cand`` within a band of the plane.

    The band starts at ``refine_band`` (wide enough to hold the whole floor under a start that is a
    degree off) and each band is iterated until the normal moves less than ``refine_converged_deg``;
    only then is it narrowed: halved down to ``refine_band_halved_to`` (the feet of walls and
    furniture leave the fit), then to 3 robust sigmas of the residuals (at least
    ``refine_band_min``), until a settled band no longer narrows (at most ``refine_max_passes``).
    Weights: opacity, and with ``area_balanced_refinement`` each ``cell`` (coverage_cell_m of the
    plane) weighted by its summed opacity capped at the median cell's, so that neither the densest
    patch nor a cell of two stray splats tilts the room's plane. A pass whose plane turns more than
    10 degrees from the start keeps the start (a sloppy patch)."""
    n0 = n.copy()
    band = cfg.refine_band_glossy if glossy_start else cfg.refine_band
    passes, bands, moved = 0, [], float("nan")
    while passes < cfg.refine_max_passes:
        sel = np.nonzero(cand & (np.abs(p @ n + d) < band))[0]
        if len(sel) < 100:
            break
        passes += 1
        w = alpha[sel].astype(np.float64)
        if cfg.area_balanced_refinement:
            inv = np.unique(cell[sel], return_inverse=True)[1].reshape(-1)
            tot = np.bincount(inv, weights=w)
            w = w * (np.minimum(tot, np.median(tot)) / tot)[inv]
        n2, d2 = _plane_svd(p[sel], w)
        if n2 @ n < 0:
            n2, d2 = -n2, -d2
        if _angle(n2, n0) > 10:
            break
        moved = _angle(n2, n)
        n, d = n2, float(d2)
        if moved < cfg.refine_converged_deg:  # this band has settled: narrow it
            if band > cfg.refine_band_halved_to:  # halving: furniture bases and wall feet leave first
                narrower = max(0.5 * band, cfg.refine_band_halved_to)
            else:  # then to the floor's own thickness
                res = np.abs(p[sel] @ n + d)
                narrower = max(3.0 * 1.4826 * float(np.median(res)), cfg.refine_band_min)
                if narrower >= 0.999 * band:
                    break  # converged
            bands.append(round(band, 4))
            band = narrower
    return n, d, {"passes": passes, "bands_m": bands + [round(band, 4)], "last_move_deg": moved,
                  "converged": bool(moved < cfg.refine_converged_deg)}


def nearest_axis(n: np.ndarray) -> tuple[str, float]:
    """The signed coordinate axis nearest a unit direction ('-y') and the angle to it, degrees."""
    k = int(np.argmax(np.abs(n)))
    return ("-" if n[k] < 0 else "+") + "xyz"[k], float(np.degrees(np.arccos(min(1.0, abs(n[k])))))


def axis_name(n: np.ndarray) -> str:
    """The signed coordinate axis nearest a direction, e.g. '-y' (with the angle when tilted > 1 deg)."""
    name, tilt = nearest_axis(n)
    return name if tilt <= 1.0 else f"{name} (tilted {tilt:.1f} deg)"


def floor_transform(n: np.ndarray, d: float) -> np.ndarray:
    """Rigid 4x4 (source -> aligned) rotating n onto +z by the smallest rotation and moving the
    plane n . p + d = 0 to z = 0."""
    n = np.asarray(n, float) / np.linalg.norm(n)
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(n, z)
    s, c = np.linalg.norm(v), float(n @ z)
    if s < 1e-12:
        r = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        k = v / s
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        r = np.eye(3) + s * kx + (1 - c) * kx @ kx
    t = np.eye(4)
    t[:3, :3] = r
    t[2, 3] = d  # a plane point p0 = -d n maps to R p0 = -d z; shift by +d
    return t
