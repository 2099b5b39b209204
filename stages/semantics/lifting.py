"""Lifting per-frame category masks to 3D instance candidates (the paper's procedure).

Per frame: erode each mask, back-project its pixels that have a valid depth, voxel-downsample the
frame's labelled cloud (delta_down). Pooled over frames: vote on a coarser grid (delta_vote),
drop cells with too little support, give each cell its majority label and drop ties; transfer
the cell labels to the Gaussian centres inside; DBSCAN per category; drop small clusters; each
cluster's centroid is an instance candidate. Pure functions of arrays (no IO).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage


@dataclass
class LiftingConfig:
    """Parameters of the lifting (metres unless said)."""

    erosion_px: int = 2
    """Erode each mask by this many pixels (0 = off): boundary pixels are the least reliable."""
    max_depth: float = 8.0
    """Ignore pixels farther than this."""
    delta_down: float = 0.02
    """Per-frame voxel downsampling of the labelled points."""
    delta_vote: float = 0.1
    """Voting grid cell size."""
    min_support: int = 3
    """Cells with less support (over all frames) are dropped."""
    support: str = "views"
    """What a vote is: "views" (each frame casts one vote per cell and label: a cell seen in one
    frame cannot outvote a cell seen in many, however many of its pixels fall in it) or "points"
    (every downsampled point votes)."""
    exclude_ties: bool = True
    """Drop cells whose two most voted categories tie."""
    voting: bool = True
    """Majority voting per cell (off = every point keeps its own label: the naive baseline)."""
    dbscan_eps: float = 0.2
    """DBSCAN radius on labelled Gaussian centres (the least one used, see dbscan_eps_spacing)."""
    dbscan_eps_spacing: float = 2.5
    """The radius is at least this many times the median nearest-neighbour spacing of the labelled
    centres of a category (sparser scenes get a proportionally larger radius; 0 = fixed radius)."""
    dbscan_min_samples: int = 5
    """DBSCAN core-point threshold."""
    min_cluster: int = 30
    """Clusters with fewer Gaussians are dropped."""
    dbscan_max_points: int = 50_000
    """Above this many labelled points of a category, DBSCAN runs on one point per delta_down voxel
    weighted by how many it stands for (sklearn's sample_weight), the labels then mapped back:
    DBSCAN holds every point's eps-neighbourhood, and the dense clouds of a large real capture
    (hundreds of thousands of Gaussians per category) outgrew 20 GB. Smaller clouds are clustered
    point by point as before."""
    min_top_m: float = 0.0
    """Instances whose highest point lies below this height (aligned frame, floor z = 0) are
    dropped: floor texture taken for an object (0 = off; the detector sets detector.min_top_m)."""
    min_views: int = 1
    """An instance needs votes from at least this many distinct views (its `views`): multi-view
    consistency against detections that do not recur in 3D (the detector segmenter asks for
    detector.min_views; with support=points every frame counts)."""
    confusable: list[list[int]] | None = None
    """Groups of labels a segmenter confuses with each other (the detector's bed and sofa): instances
    of one group whose boxes overlap by `confusable_overlap` of the smaller are one object seen under
    two names, merged into one instance of the label with the most view votes over its cells (a class
    vote across views per instance; `class_vote` below). None: no merging."""
    confusable_overlap: float = 0.3
    """Share of the smaller box's volume the two boxes must share to be merged."""


def back_project(depth: np.ndarray, K: np.ndarray, cam_to_world: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """World points [M, 3] of pixels [M, 2] (row, col) with their depth (camera z, OpenCV axes)."""
    z = depth[pixels[:, 0], pixels[:, 1]]
    u, v = pixels[:, 1] + 0.5, pixels[:, 0] + 0.5
    x = (u - K[0, 2]) / K[0, 0] * z
    y = (v - K[1, 2]) / K[1, 1] * z
    pc = np.stack([x, y, z], 1)
    return pc @ cam_to_world[:3, :3].T + cam_to_world[:3, 3]


def voxel_keys(points: np.ndarray, size: float) -> np.ndarray:
    """[M, 3] int64 voxel indices."""
    return np.floor(points / size).astype(np.int64)


def frame_points(depth: np.ndarray, K: np.ndarray, cam_to_world: np.ndarray, masks: dict,
                 cfg: LiftingConfig) -> tuple[np.ndarray, np.ndarray]:
    """One frame's labelled, downsampled points: (points [M, 3], labels [M] int).

    masks: {label: bool [H, W] or a list of them (one per detection; each is eroded on its own, so
    that two touching detections of one category do not shield each other's boundary)}."""
    pts, labs = [], []
    valid = (depth > 0) & (depth <= cfg.max_depth)
    for label, mask in masks.items():
        dets = [mask] if isinstance(mask, np.ndarray) else list(mask)
        if cfg.erosion_px > 0:
            dets = [ndimage.binary_erosion(d, iterations=cfg.erosion_px, border_value=0) for d in dets]
        m = np.logical_or.reduce(dets) if len(dets) > 1 else dets[0]
        pix = np.argwhere(m & valid)
        if not len(pix):
            continue
        p = back_project(depth, K, cam_to_world, pix)
        _, first = np.unique(voxel_keys(p, cfg.delta_down), axis=0, return_index=True)  # one point per voxel
        p = p[np.sort(first)]
        pts.append(p)
        labs.append(np.full(len(p), label, np.int64))
    if not pts:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    return np.concatenate(pts), np.concatenate(labs)


def vote(points: np.ndarray, labels: np.ndarray, cfg: LiftingConfig, frames: np.ndarray | None = None,
         voters: dict | None = None) -> dict[tuple, tuple[int, int, float]]:
    """Pooled points -> {cell: (label, support, confidence)} on the delta_vote grid (majority label,
    cells under min_support dropped, ties dropped when exclude_ties). `frames` [M]: the frame of
    each point (cfg.support == "views": one vote per frame, cell and label). `voters`, when given,
    receives {cell: frames that voted for its label} (the views behind each kept cell)."""
    if not len(points):
        return {}
    keys = voxel_keys(points, cfg.delta_vote)
    if frames is not None:
        frames = np.asarray(frames)
    if cfg.support == "views":
        if frames is None:
            raise ValueError("support='views' needs the frame of each point")
        _, first = np.unique(np.column_stack([keys, labels, frames]), axis=0, return_index=True)
        keys, labels, frames = keys[first], labels[first], frames[first]
    elif cfg.support != "points":
        raise ValueError(f"lifting.support={cfg.support!r}; choose views | points")
    cells, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    cats = np.unique(labels)
    counts = np.zeros((len(cells), len(cats)), np.int64)
    np.add.at(counts, (inv, np.searchsorted(cats, labels)), 1)
    total = counts.sum(1)
    order = np.sort(counts, 1)
    best = counts.argmax(1)
    keep = total >= cfg.min_support
    if cfg.exclude_ties and counts.shape[1] > 1:
        keep &= order[:, -1] > order[:, -2]
    if voters is not None and frames is not None:
        won = keep[inv] & (labels == cats[best[inv]])
        for i, f in zip(inv[won], frames[won]):
            voters.setdefault(tuple(cells[i]), set()).add(int(f))
    return {tuple(c): (int(cats[b]), int(t), float(counts[i, b] / t))
            for i, (c, b, t) in enumerate(zip(cells, best, total)) if keep[i]}


def dbscan_radius(xyz: np.ndarray, cfg: LiftingConfig) -> float:
    """cfg.dbscan_eps, or dbscan_eps_spacing x the median nearest-neighbour spacing if larger."""
    if cfg.dbscan_eps_spacing <= 0 or len(xyz) < 2:
        return cfg.dbscan_eps
    from scipy.spatial import cKDTree

    d, _ = cKDTree(xyz).query(xyz, k=2)
    return max(cfg.dbscan_eps, cfg.dbscan_eps_spacing * float(np.median(d[:, 1])))


def lift(frames, gaussian_means: np.ndarray, cfg: LiftingConfig) -> list[dict]:
    """Instance candidates from frames.

    Args:
        frames: iterable of (depth [H, W] m, K [3, 3], cam_to_world [4, 4], masks {label: bool [H, W] or
            a list of them}).
        gaussian_means: [N, 3] scene Gaussian centres (the labels are transferred to them).
    Returns:
        list of {label, center [3], min [3], max [3], support (Gaussians), confidence, views (distinct
        frames that voted for it), agreement (view_support)}; instances under cfg.min_views views dropped.
    """
    pts, labs, fids = [], [], []
    per_cell = cfg.voting and cfg.support == "views"
    for f, (depth, K, c2w, masks) in enumerate(frames):
        p, lab = frame_points(depth, K, c2w, masks, cfg)
        if per_cell and len(p):  # a frame casts one vote per (cell, label): keep one point per pair, at
            # the cell's centre (the same votes; memory scales with the cells a frame labels, not its
            # pixels: thousands of views of a large capture pooled ~25x fewer points)
            u = np.unique(np.column_stack([voxel_keys(p, cfg.delta_vote), lab]), axis=0)
            p, lab = (u[:, :3] + 0.5) * cfg.delta_vote, u[:, 3]
        pts.append(p)
        labs.append(lab)
        fids.append(np.full(len(p), f, np.int64))
    points = np.concatenate(pts) if pts else np.zeros((0, 3))
    labels = np.concatenate(labs) if labs else np.zeros(0, np.int64)
    gkeys = voxel_keys(gaussian_means, cfg.delta_vote)
    frames_of = np.concatenate(fids) if fids else np.zeros(0, np.int64)
    voters: dict[tuple, set[int]] = {}
    if cfg.voting:
        cells = vote(points, labels, cfg, frames_of, voters)
        g_label = np.full(len(gaussian_means), -1, np.int64)
        g_conf = np.zeros(len(gaussian_means))
        for i, k in enumerate(map(tuple, gkeys)):
            if k in cells:
                g_label[i], _, g_conf[i] = cells[k]
        members = [(lab, np.flatnonzero(g_label == lab)) for lab in np.unique(g_label[g_label >= 0])]
        cloud = lambda idx: gaussian_means[idx]  # noqa: E731
    else:  # the naive baseline: cluster the back-projected points themselves (pooled frames
        # overlap: one point per delta_down voxel and label)
        _, first = np.unique(np.column_stack([voxel_keys(points, cfg.delta_down), labels]), axis=0,
                             return_index=True)
        keep = np.sort(first)
        points, labels, frames_of = points[keep], labels[keep], frames_of[keep]
        g_conf = None
        members = [(lab, np.flatnonzero(labels == lab)) for lab in np.unique(labels)]
        cloud = lambda idx: points[idx]  # noqa: E731
    out = []
    for lab, idx in members:
        xyz = cloud(idx)
        if len(xyz) < cfg.min_cluster:
            continue
        cl = cluster(xyz, cfg)
        for c in np.unique(cl[cl >= 0]):
            sel = cl == c
            if sel.sum() < cfg.min_cluster:
                continue
            p = xyz[sel]
            conf = float(g_conf[idx[sel]].mean()) if g_conf is not None else 1.0
            views, agreement = view_support(voxel_keys(p, cfg.delta_vote), voters) if cfg.voting else \
                (len(np.unique(frames_of[idx[sel]])), 1.0)
            votes = sum(len(voters.get(tuple(k), ())) for k in np.unique(voxel_keys(p, cfg.delta_vote), axis=0))
            out.append({"label": int(lab), "center": p.mean(0), "min": p.min(0), "max": p.max(0),
                        "support": int(sel.sum()), "confidence": conf, "views": views, "agreement": agreement,
                        "votes": int(votes), "points": p})
    if cfg.confusable and cfg.voting:
        out = class_vote(out, cfg.confusable, cfg.confusable_overlap, voters, cfg.delta_vote)
    kept = []
    for o in out:
        p = o.pop("points")
        if o["views"] >= cfg.min_views and not (cfg.min_top_m > 0 and float(p[:, 2].max()) < cfg.min_top_m):
            kept.append(o)
    return kept


def box_overlap(a: dict, b: dict) -> float:
    """Volume shared by two instances' axis-aligned boxes, as a share of the smaller box's volume."""
    lo, hi = np.maximum(a["min"], b["min"]), np.minimum(a["max"], b["max"])
    inter = float(np.prod(np.clip(hi - lo, 0, None)))
    vol = min(float(np.prod(np.maximum(x["max"] - x["min"], 1e-6))) for x in (a, b))
    return inter / vol


def class_vote(instances: list[dict], groups: list[list[int]], overlap: float, voters: dict[tuple, set[int]],
               delta_vote: float) -> list[dict]:
    """Instances of confusable labels (one group) whose boxes overlap by `overlap` of the smaller are
    merged, transitively, into one instance labelled by the view votes summed per label over the merged
    instances (the label most views gave its cells), its views counted over all its cells; the others
    pass unchanged. Each merged instance records the votes per label it was chosen from (`label_votes`).
    Runs before the min_views filter: two halves of one object, each seen from too few views under
    its own name, can make one instance."""
    group_of = {lab: g for g, labs in enumerate(groups) for lab in labs}
    parent = list(range(len(instances)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, a in enumerate(instances):
        for j in range(i + 1, len(instances)):
            b = instances[j]
            if a["label"] != b["label"] and group_of.get(a["label"], -1) == group_of.get(b["label"], -2) \
                    and box_overlap(a, b) >= overlap:
                parent[root(j)] = root(i)
    merged: dict[int, list[dict]] = {}
    for i, inst in enumerate(instances):
        merged.setdefault(root(i), []).append(inst)
    out = []
    for members in merged.values():
        if len(members) == 1:
            out.append(members[0])
            continue
        votes: dict[int, int] = {}
        for m in members:
            votes[m["label"]] = votes.get(m["label"], 0) + m["votes"]
        label = max(sorted(votes), key=lambda lab: votes[lab])
        p = np.concatenate([m["points"] for m in members])
        n = sum(m["support"] for m in members)
        views, agreement = view_support(voxel_keys(p, delta_vote), voters)
        out.append({"label": int(label), "center": p.mean(0), "min": p.min(0), "max": p.max(0), "support": int(n),
                    "confidence": float(sum(m["confidence"] * m["support"] for m in members) / n),
                    "views": views, "agreement": agreement,
                    "votes": int(sum(votes.values())), "points": p, "label_votes": votes})
    return out


def cluster(xyz: np.ndarray, cfg: LiftingConfig) -> np.ndarray:
    """DBSCAN labels of a category's points (-1 = noise), on voxel representatives above
    cfg.dbscan_max_points points (LiftingConfig.dbscan_max_points)."""
    from sklearn.cluster import DBSCAN

    eps = dbscan_radius(xyz, cfg)
    if len(xyz) <= cfg.dbscan_max_points:
        return DBSCAN(eps=eps, min_samples=cfg.dbscan_min_samples).fit_predict(xyz)
    _, rep, inv, count = np.unique(voxel_keys(xyz, cfg.delta_down), axis=0, return_index=True, return_inverse=True,
                                   return_counts=True)
    labels = DBSCAN(eps=eps, min_samples=cfg.dbscan_min_samples).fit_predict(xyz[rep], sample_weight=count)
    return labels[inv.reshape(-1)]


def view_support(cell_keys: np.ndarray, voters: dict[tuple, set[int]]) -> tuple[int, float]:
    """(distinct views that voted for an instance's cells, their agreement: the mean share of the
    instance's cells each of those views voted for; 1.0 = every view saw and labelled the whole
    instance, low = views that each back the instance in a different small place)."""
    cells = {tuple(k) for k in cell_keys}
    per_frame: dict[int, int] = {}
    for c in cells:
        for f in voters.get(c, ()):
            per_frame[f] = per_frame.get(f, 0) + 1
    if not per_frame:
        return 0, 0.0
    return len(per_frame), float(np.mean([n / len(cells) for n in per_frame.values()]))
