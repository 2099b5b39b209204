"""Metrics: small registered classes, one job each (habitat-lab's habit), computed per episode from
its final EpisodeState, then aggregated overall and per difficulty.

Per episode:
- SR: success under the run's protocol. Distance SR: the distance protocol's success (the agent
  entered the success region after at least one action; the start pose never counts), defined in
  distance-protocol runs only. Stop SR: STOP issued inside the region, and OSR (oracle success: inside
  the region after some action, stopped or not), defined in explicit-stop runs only: in a distance
  run Stop SR is 0 by construction (entering ends the episode) and OSR equals Distance SR, so both
  are NaN there and no table prints a metric from a run whose protocol does not define it.
- SPL: SR x l / max(p, l), l the stored geodesic optimum, p the path walked; 0/0 (an optimum of 0
  and no motion) counts as a ratio of 1, so SPL = SR. SoftSPL: (1 - d_T / d_0) x l / max(p, l),
  geodesic distances to the goal at the end and the start (d_0 = 0: progress 1), same 0/0 rule.
- NE: planar Euclidean distance from the final position to the goal (ObjectNav: to the nearest
  instance centre), as the paper. NE geodesic (`ne_geodesic`): the costmap geodesic from the final
  position to the goal (ObjectNav: to the nearest view point), as Habitat's distance_to_goal.
- Collision Rate (`collision_rate`): actions with a rejected move / attempted policy actions, the
  paper's "fraction of attempted policy actions"; `collision_rate_moves`: rejected / attempted
  translations (one waypoint action may try several).
- Steps; Pose SR (ImageNav: success and final heading within the tolerance of the goal yaw); DTW and
  nDTW (exact dynamic time warping of the walked positions against the expert's, nDTW =
  exp(-DTW / (|R| d_th)) with d_th the success radius).
Aggregates are means over the episodes where a metric is defined; Pose Retention = mean Pose SR /
mean SR.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from navcore.nav.poses import wrap_angle
from navcore.registry import Registry

METRICS = Registry("metric", {
    "distance_sr": "navcore.eval.metrics:DistanceSR",
    "stop_sr": "navcore.eval.metrics:StopSR",
    "sr": "navcore.eval.metrics:SR",
    "spl": "navcore.eval.metrics:SPL",
    "soft_spl": "navcore.eval.metrics:SoftSPL",
    "ne": "navcore.eval.metrics:NE",
    "ne_geodesic": "navcore.eval.metrics:NEGeodesic",
    "collision_rate": "navcore.eval.metrics:CollisionRate",
    "collision_rate_moves": "navcore.eval.metrics:CollisionRateMoves",
    "steps": "navcore.eval.metrics:Steps",
    "pose_sr": "navcore.eval.metrics:PoseSR",
    "osr": "navcore.eval.metrics:OSR",
    "dtw": "navcore.eval.metrics:DTW",
    "ndtw": "navcore.eval.metrics:NDTW",
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
    protocols: tuple[str, ...] = ("distance", "explicit_stop")
    """The protocols whose runs define the metric (elsewhere it is NaN)."""

    def __call__(self, s, d0: float, d_final: float, protocol: str) -> float:  # pragma: no cover
        raise NotImplementedError


class DistanceSR(Metric):
    name = "distance_sr"
    protocols = ("distance",)

    def __call__(self, s, d0, d_final, protocol):
        return float(s.success)


class StopSR(Metric):
    name = "stop_sr"
    protocols = ("explicit_stop",)

    def __call__(self, s, d0, d_final, protocol):
        return float(s.stopped and s.stop_in_region)


class SR(Metric):
    name = "sr"

    def __call__(self, s, d0, d_final, protocol):
        return float(s.success)


def efficiency(optimum: float, walked: float) -> float:
    """l / max(p, l), with 0/0 (optimum 0, no motion) defined as 1."""
    den = max(walked, optimum)
    return optimum / den if den > 0 else 1.0


class SPL(Metric):
    name = "spl"

    def __call__(self, s, d0, d_final, protocol):
        return float(s.success) * efficiency(s.ep.geodesic, s.path_length)


class SoftSPL(Metric):
    name = "soft_spl"

    def __call__(self, s, d0, d_final, protocol):
        progress = max(0.0, 1.0 - d_final / d0) if d0 > 0 else 1.0
        return progress * efficiency(s.ep.geodesic, s.path_length)


class NE(Metric):
    name = "ne"

    def __call__(self, s, d0, d_final, protocol):
        return s.ep.distance_to_goal(s.x, s.y)


class NEGeodesic(Metric):
    name = "ne_geodesic"

    def __call__(self, s, d0, d_final, protocol):
        return float(d_final)


class CollisionRate(Metric):
    name = "collision_rate"

    def __call__(self, s, d0, d_final, protocol):
        return s.collided_actions / s.steps if s.steps else 0.0


class CollisionRateMoves(Metric):
    name = "collision_rate_moves"

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
    protocols = ("explicit_stop",)

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
    """All (or the named) metrics of one finished episode; NaN for a metric the run's protocol does
    not define."""
    out = {}
    for n in names or METRICS:
        m = METRICS[n]()
        out[n] = m(s, d0, d_final, protocol) if protocol in m.protocols else math.nan
    return out


def aggregate(rows: list[dict], by: str | None = "difficulty") -> dict:
    """Means of the metric columns overall and per value of `by` (NaNs ignored), plus Pose
    Retention = Pose SR / SR. Episodes that ended in an error (an agent that raised or could not be
    reached: the row's `error`) measure no navigation: they are counted apart (`errored`) and left
    out of every mean, never counted as failures of the policy."""
    def summary(rs):
        errored = sum(bool(r.get("error")) for r in rs)
        rs = [r for r in rs if not r.get("error")]
        out = {"episodes": len(rs), "errored": errored}
        for n in METRICS:
            vals = np.array([r[n] for r in rs if n in r], float)
            vals = vals[~np.isnan(vals)]
            out[n] = float(vals.mean()) if len(vals) else math.nan
        dsr, psr = out.get("sr", math.nan), out.get("pose_sr", math.nan)
        out["pose_retention"] = psr / dsr if dsr and not math.isnan(psr) else math.nan
        return out
    res = {"overall": summary(rows)}
    if by:
        for key in sorted({r.get(by, "") for r in rows}):
            res[key] = summary([r for r in rows if r.get(by, "") == key])
    return res
