"""results.json in the layout of the authors' navarena-bench (evaluation protocol 2.x): one file per
run with `meta`, `run_summary`, `metric_results`, `episode_results` and `artifacts`, written beside
our Parquet results so their hub and replay tools read our runs.

Their documented fields are kept under their names (episode results: episode_id, scene_path,
success, path_length, geodesic_distance, final_distance, num_steps, status; overall: num_episodes,
success_rate, spl, navigation_error, avg_path_length, avg_geodesic_distance, avg_num_steps; metric
names sr, spl, soft_spl, ne, osr, cr, dtw, ndtw, avg_steps). Our further metrics (Distance / Stop SR,
NE geodesic, Pose SR, CR per move) are added beside them under our names. A metric the run's
protocol does not define is null, never NaN (strict JSON). The structure is pinned by
RESULTS_SCHEMA (JSON Schema), which the tests validate every written file against.
"""
from __future__ import annotations

import math
import os
import time

import pandas as pd

PROTOCOL_VERSION = "2.0"
OURS_TO_THEIRS = {"sr": "sr", "spl": "spl", "soft_spl": "soft_spl", "ne": "ne", "osr": "osr",
                  "collision_rate": "cr", "dtw": "dtw", "ndtw": "ndtw", "steps": "avg_steps",
                  "distance_sr": "distance_sr", "stop_sr": "stop_sr", "ne_geodesic": "ne_geodesic",
                  "pose_sr": "pose_sr", "collision_rate_moves": "cr_moves"}
SUCCESS_POLICY = {"distance": "geometric_distance", "explicit_stop": "explicit_stop"}
TERMINATION_POLICY = {"distance": "success_or_timeout", "explicit_stop": "stop_or_timeout"}
STATUS = {"entered": "success", "stop": "stopped", "budget": "timeout", "agent_error": "error"}

_NUM = {"type": ["number", "null"]}
_METRIC = {"type": "object", "required": ["value", "count"],
           "properties": {"value": _NUM, "count": {"type": "integer", "minimum": 0}}}
RESULTS_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "navarena-bench results.json (evaluation protocol 2.x)",
    "type": "object",
    "required": ["meta", "run_summary", "metric_results", "episode_results", "artifacts"],
    "properties": {
        "meta": {"type": "object",
                 "required": ["evaluation_protocol_version", "run", "agent", "tasks", "success_policy",
                              "termination_policy", "created_at"],
                 "properties": {"evaluation_protocol_version": {"type": "string", "pattern": r"^2\.\d+"},
                                "tasks": {"type": "array", "items": {"enum": ["pointnav", "imagenav", "objectnav"]}},
                                "success_policy": {"enum": list(SUCCESS_POLICY.values()) + ["mixed"]}}},
        "run_summary": {"type": "object",
                        "required": ["num_episodes", "num_completed", "num_errors", "success_rate", "spl",
                                     "navigation_error", "avg_path_length", "avg_geodesic_distance", "avg_num_steps"],
                        "properties": {"num_episodes": {"type": "integer", "minimum": 0},
                                       "success_rate": _NUM, "spl": _NUM, "navigation_error": _NUM}},
        "metric_results": {"type": "object", "required": ["overall", "by_task"],
                           "properties": {"overall": {"type": "object", "additionalProperties": _METRIC,
                                                      "required": ["sr", "spl", "ne", "cr", "avg_steps"]},
                                          "by_task": {"type": "object",
                                                      "additionalProperties": {"type": "object",
                                                                               "additionalProperties": _METRIC}},
                                          "by_difficulty": {"type": "object"}}},
        "episode_results": {"type": "array", "items": {
            "type": "object",
            "required": ["episode_id", "scene_path", "task_type", "success", "path_length", "geodesic_distance",
                         "final_distance", "num_steps", "status"],
            "properties": {"success": {"type": "boolean"}, "num_steps": {"type": "integer", "minimum": 0},
                           "path_length": {"type": "number", "minimum": 0}, "geodesic_distance": _NUM,
                           "final_distance": _NUM,
                           "status": {"enum": sorted(set(STATUS.values()))},
                           "metrics": {"type": "object", "additionalProperties": _NUM}}}},
        "artifacts": {"type": "object"},
    },
}


def _num(v):
    v = float(v)
    return None if math.isnan(v) or math.isinf(v) else v


def _metrics(df: pd.DataFrame) -> dict:
    out = {}
    for ours, theirs in OURS_TO_THEIRS.items():
        if ours in df:
            vals = df[ours].astype(float)
            vals = vals[vals.notna()]
            out[theirs] = {"value": _num(vals.mean()) if len(vals) else None, "count": int(len(vals))}
    return out


def build(df: pd.DataFrame, run: str, agent: str = "", artifacts: dict | None = None) -> dict:
    """results.json of one run from its per-episode results (load_results' DataFrame)."""
    protocols = sorted(set(df["protocol"])) if len(df) else []
    one = protocols[0] if len(protocols) == 1 else None
    episodes = []
    for r in df.sort_values(["scene_id", "task", "episode_id"]).to_dict("records"):
        episodes.append({
            "episode_id": r["episode_id"], "scene_path": r["scene_id"], "task_type": r["task"],
            "difficulty": r["difficulty"], "success": bool(r["sr"] == 1), "path_length": float(r["path_length"]),
            "geodesic_distance": _num(r["geodesic"]), "final_distance": _num(r["ne"]), "num_steps": int(r["steps"]),
            "status": "error" if r["error"] else STATUS.get(r["end_reason"], "failure")
            if r["sr"] != 1 else "success",
            "end_reason": r["end_reason"], "error": r["error"] or None,
            "metrics": {theirs: _num(r[ours]) for ours, theirs in OURS_TO_THEIRS.items() if ours in r}})
    n = len(df)
    mean = lambda c: _num(df[c].astype(float).mean()) if n else None  # noqa: E731
    stamp = int(os.environ.get("SOURCE_DATE_EPOCH", time.time()))
    return {
        "meta": {"evaluation_protocol_version": PROTOCOL_VERSION, "producer": "navarena", "run": run,
                 "agent": agent, "protocol": one or ",".join(protocols),
                 "success_policy": SUCCESS_POLICY[one] if one else "mixed",
                 "termination_policy": TERMINATION_POLICY[one] if one else "mixed",
                 "tasks": sorted(set(df["task"])) if n else [], "scenes": sorted(set(df["scene_id"])) if n else [],
                 "created_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(stamp))},
        "run_summary": {"num_episodes": n, "num_completed": int((df["error"] == "").sum()) if n else 0,
                        "num_errors": int((df["error"] != "").sum()) if n else 0,
                        "success_rate": mean("sr"), "spl": mean("spl"), "navigation_error": mean("ne"),
                        "avg_path_length": mean("path_length"), "avg_geodesic_distance": mean("geodesic"),
                        "avg_num_steps": mean("steps")},
        "metric_results": {"overall": _metrics(df),
                           "by_task": {t: _metrics(g) for t, g in df.groupby("task")} if n else {},
                           "by_difficulty": {f"{t}/{d}": _metrics(g) for (t, d), g in df.groupby(["task", "difficulty"])}
                           if n else {}},
        "episode_results": episodes,
        "artifacts": artifacts or {},
    }


def validate(doc: dict) -> None:
    """Raise jsonschema.ValidationError unless `doc` fits RESULTS_SCHEMA (and is strict JSON)."""
    import json

    import jsonschema

    json.dumps(doc, allow_nan=False)
    jsonschema.validate(doc, RESULTS_SCHEMA)
