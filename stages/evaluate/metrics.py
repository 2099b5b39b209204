"""Metrics: small registered classes, one job each (habitat-lab's habit), computed per episode from
its final EpisodeState, then aggregated overall and per difficulty.

Per episode: Distance SR (inside the success region at some step: the distance protocol's
success), Stop SR (STOP issued inside the region), SR (success under the run's protocol), SPL
(SR x l / max(p, l), l the stored geodesic optimum, p the path walked), SoftSPL ((1 - d_T / d_0)
x l / max(p, l), geodesic distances to the goal at the end and the start), NE (planar Euclidean
distance from the final position to the goal, ObjectNav: to the nearest instance centre),
Collision Rate (rejected / attempted translations), Steps, Pose SR (ImageNav: success and final
heading within the tolerance of the goal yaw), OSR (ever within the region), DTW and nDTW (exact
dynamic time warping of the walked positions against the expert's, nDTW = exp(-DTW / (|R| d_th))
with d_th the success radius). Aggregates are means; Pose Retention = mean Pose SR / mean Distance SR.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from navcore.nav.poses import wrap_angle
from navcore.registry import Registry

METRICS = Registry("metric", {
    "distance_sr": "stages.evaluate.metrics:DistanceSR",
    "stop_sr": "stages.evaluate.metrics:StopSR",
    "sr": "stages.evaluate.metrics:SR",
    "spl": "stages.evaluate.metrics:SPL",
    "soft_spl": "stages.evaluate.metrics:SoftSPL",
    "ne": "stages.evaluate.metrics:NE",
    "collision_rate": "stages.evaluate.metrics:CollisionRate",
    "steps": "stages.evaluate.metrics:Steps",
    "pose_sr": "stages.evaluate.metrics:PoseSR",
    "osr": "stages.evaluate.metrics:OSR",
    "dtw": "stages.evaluate.metrics:DTW",
    "ndtw": "stages.evaluate.metrics:NDTW",
})
"""Every metric, in the order of the result tables."""


@numba.njit(cache=True)
def dtw(a: np.ndarray, b: np.ndarray) -> float:
    """Exact DTW between two 2D polylines' points [n, 2] and [m, 2] (Euclidean point cost)."""
    n, m = a.shape[0], b.shape[0]
    prev = np.full(m + 1, np.inf)
    prev[0] = 0.0
    for i in range(1, n + 1):
        cur = np.full(m + 1, np.inf)
        for j in range(1, m + 1):
            c = math.hypot(a[i - 1, 0] - b[j - 1, 0], a[i - 1, 1] - b[j - 1, 1])
            cur[j] = c + min(prev[j], cur[j - 1], prev[j - 1])
        prev = cur
    return prev[m]


class Metric:
    name = ""

    def __call__(self, s, d0: float, d_final: float, protocol: str) -> float:  # pragma: no cover
        raise NotImplementedError


class DistanceSR(Metric):
    name = "distance_sr"

    def __call__(self, s, d0, d_final, protocol):
        return float(s.ever_in_region)


class StopSR(Metric):
    name = "stop_sr"

    def __call__(self, s, d0, d_final, protocol):
        return float(s.stopped and s.stop_in_region)


class SR(Metric):
    name = "sr"

    def __call__(self, s, d0, d_final, protocol):
        return float(s.success)


class SPL(Metric):
    name = "spl"

    def __call__(self, s, d0, d_final, protocol):
        l = s.ep.geodesic
        return float(s.success) * l / max(s.path_length, l, 1e-9)


class SoftSPL(Metric):
    name = "soft_spl"

    def __call__(self, s, d0, d_final, protocol):
        l = s.ep.geodesic
        progress = max(0.0, 1.0 - d_final / d0) if d0 > 0 else 1.0
        return progress * l / max(s.path_length, l, 1e-9)


class NE(Metric):
    name = "ne"

    def __call__(self, s, d0, d_final, protocol):
        return s.ep.distance_to_centres(s.x, s.y)


class CollisionRate(Metric):
    name = "collision_rate"

    def __call__(self, s, d0, d_final, protocol):
        return s.collisions / s.moves if s.moves else 0.0


class Steps(Metric):
    name = "steps"

    def __call__(self, s, d0, d_final, protocol):
        return float(s.steps)


class PoseSR(Metric):
    name = "pose_sr"

    def __call__(self, s, d0, d_final, protocol):
        if s.ep.goal_yaw is None:
            return math.nan
        ok = abs(float(wrap_angle(s.ep.goal_yaw - s.yaw))) <= s.ep.heading_tolerance
        return float(s.success and ok)


class OSR(Metric):
    name = "osr"

    def __call__(self, s, d0, d_final, protocol):
        return float(s.ever_in_region)


class DTW(Metric):
    name = "dtw"

    def __call__(self, s, d0, d_final, protocol):
        ref = s.ep.reference_path
        if ref is None or not len(ref):
            return math.nan
        return float(dtw(np.asarray(s.positions, float), np.ascontiguousarray(ref, float)))


class NDTW(Metric):
    name = "ndtw"

    def __call__(self, s, d0, d_final, protocol):
        ref = s.ep.reference_path
        if ref is None or not len(ref):
            return math.nan
        d = dtw(np.asarray(s.positions, float), np.ascontiguousarray(ref, float))
        return float(math.exp(-d / (len(ref) * s.ep.success_radius)))


def episode_metrics(s, d0: float, d_final: float, protocol: str, names=None) -> dict[str, float]:
    """All (or the named) metrics of one finished episode."""
    return {n: METRICS[n]()(s, d0, d_final, protocol) for n in (names or METRICS)}


def aggregate(rows: list[dict], by: str | None = "difficulty") -> dict:
    """Means of the metric columns overall and per value of `by` (NaNs ignored), plus Pose
    Retention = Pose SR / Distance SR."""
    def summary(rs):
        out = {"episodes": len(rs)}
        for n in METRICS:
            vals = np.array([r[n] for r in rs if n in r], float)
            vals = vals[~np.isnan(vals)]
            out[n] = float(vals.mean()) if len(vals) else math.nan
        dsr, psr = out.get("distance_sr", math.nan), out.get("pose_sr", math.nan)
        out["pose_retention"] = psr / dsr if dsr and not math.isnan(psr) else math.nan
        return out
    res = {"overall": summary(rows)}
    if by:
        for key in sorted({r.get(by, "") for r in rows}):
            res[key] = summary([r for r in rows if r.get(by, "") == key])
    return res
