"""The canonical tables of the episodes stage (read by export and evaluate): one pyarrow schema each, defined here only.

Stored hive-partitioned by task and scene (`task=` and `scene_id=` come from the folder names, so
they are not columns of the files):
    data/05_episodes/task={task}/scene_id={scene_id}/part-0.parquet      one row per episode
    data/06_trajectories/task={task}/scene_id={scene_id}/part-0.parquet  one row per expert step
Frame: the scene's aligned frame (z up, metres, floor z = 0); rotations are quaternions
[qx, qy, qz, qw] of the heading (yaw about +z, counter-clockwise from +x).

Trajectories are the bulk of a release (about 500 rows an episode at 20 Hz), so they are encoded
for size (``TRAJECTORY_WRITE``): float32 throughout (positions to about 4 um at 50 m from the
origin; the validity re-check allows exactly that rounding), BYTE_STREAM_SPLIT for the floats,
delta encoding for ``step``, dictionaries for the strings; the columns derived from others
(quaternion, world-frame velocity, relative waypoint, accelerations, curvature) are rounded to the
binary grids of ``TRAJECTORY_QUANTA`` so that their low bytes compress away. The stored poses
(x, y, yaw) and controls (v, omega) are float32 exactly as computed.
"""
from __future__ import annotations

import pyarrow as pa

F64, F32, I32, I8, STR = pa.float64(), pa.float32(), pa.int32(), pa.int8(), pa.string()


def _fields(*specs) -> list[pa.Field]:
    return [pa.field(n, t) for n, t in specs]


def _pose(prefix: str) -> list[tuple[str, pa.DataType]]:
    return [(f"{prefix}position_x", F64), (f"{prefix}position_y", F64), (f"{prefix}position_z", F64),
            (f"{prefix}rotation_qx", F64), (f"{prefix}rotation_qy", F64), (f"{prefix}rotation_qz", F64),
            (f"{prefix}rotation_qw", F64)]


EPISODE_SCHEMA = pa.schema(_fields(
    ("episode_id", STR),            # "{split}_{index:06d}", unique within (task, scene)
    ("split", STR),                 # train | val_seen | val_unseen | test
    ("scene_path", STR),            # "{group}/{scene_id}"
    ("task_type", STR),             # pointnav | imagenav | objectnav
    ("embodiment", STR),
    ("difficulty", STR),            # easy | medium | hard (by geodesic distance)
    ("max_steps", I32),             # closed-loop step budget of the difficulty
    *_pose("start_"), ("start_yaw", F64),
    ("goal_type", STR),             # position | image | object
    *_pose("goal_"), ("goal_yaw", F64),  # ObjectNav: the nearest view point of the goal set
    ("success_radius", F32),        # metres
    ("heading_tolerance", F32),     # radians (ImageNav Pose SR), NaN otherwise
    ("geodesic_distance", F32),     # metres: the shortest valid path known (what SPL divides by)
    ("euclidean_distance", F32),    # metres, start to goal position
    ("num_steps", I32),             # rows of the expert trajectory (dt steps)
    ("total_time", F32),            # seconds
    ("path_length", F32),           # metres travelled by the expert
    ("avg_speed", F32), ("max_speed", F32),  # m/s
    ("oracle_actions", pa.list_(I8)),  # discrete expert: 0 stop, 1 forward, 2 left, 3 right
    ("goal_image_path", STR),       # ImageNav: relative path of the goal image once rendered
    ("goal_camera_json", STR),      # ImageNav: camera pose and intrinsics to render the goal view
    ("goal_object_category", STR), ("goal_object_id", I32),
    ("instruction_text", STR), ("instruction_language", STR),
    ("goals_json", STR),            # JSON array of all goals (ObjectNav: instances + view points)
    ("seed", pa.int64()),           # the (scene, task) stream seed
))

def _pose32(prefix: str) -> list[tuple[str, pa.DataType]]:
    return [(name, F32) for name, _ in _pose(prefix)]


TRAJECTORY_SCHEMA = pa.schema(_fields(
    ("episode_id", STR),
    ("step", I32),                  # row k is the state at t = k dt
    ("timestamp", F32),             # seconds
    *_pose32(""), ("yaw", F32),
    ("action", STR),                # move_forward | turn_left | turn_right | stop (the control's kind)
    ("action_id", I8),              # 0 stop, 1 move_forward, 2 turn_left, 3 turn_right (Habitat's ids)
    ("linear_velocity", F32),       # v held from this row to the next, m/s (robot frame, forward)
    ("angular_velocity", F32),      # omega held from this row to the next, rad/s (counter-clockwise)
    ("linear_velocity_x", F32), ("linear_velocity_y", F32),  # v in the world frame, m/s
    ("linear_acceleration", F32),   # (v_k - v_k-1) / dt, m/s^2
    ("angular_acceleration", F32),  # (omega_k - omega_k-1) / dt, rad/s^2
    ("curvature", F32),             # omega / v where v > 0, else 0, 1/m
    ("dx", F32), ("dy", F32), ("dyaw", F32),  # pose change to the next row in this row's robot frame
    ("phase", STR),                 # rotate | translate | stop
))

def _pose_docs(prefix: str, what: str) -> dict[str, str]:
    return {**{f"{prefix}position_{a}": f"{what} position {a}, metres (aligned frame; z = 0 is the floor)" for a in "xyz"},
            **{f"{prefix}rotation_q{a}": f"{what} heading as a quaternion, component {a} (yaw about +z)" for a in "xyzw"}}


FIELD_DOCS: dict[str, dict[str, str]] = {
    "episodes": {
        "episode_id": "\"{split}_{index:06d}\"; unique within a task and scene (the pair scene_id, episode_id is "
                      "unique within a task)",
        "split": "train | val_seen | val_unseen | test (the zero-shot set's copies: its own name)",
        "scene_path": "\"{group}/{scene_id}\": the scene's source group and id",
        "task_type": "pointnav | imagenav | objectnav",
        "embodiment": "the robot whose costmap and limits made the episode (navcore/conf/embodiment)",
        "difficulty": "easy | medium | hard, by geodesic distance",
        "max_steps": "closed-loop step budget of the difficulty",
        **_pose_docs("start_", "start"), "start_yaw": "start heading, radians, counter-clockwise from +x",
        "goal_type": "position | image | object",
        **_pose_docs("goal_", "goal"),
        "goal_yaw": "goal heading, radians (ImageNav: the goal view's; ObjectNav: the nearest view point's); NaN for "
                    "PointNav",
        "success_radius": "success threshold around the goal, metres",
        "heading_tolerance": "ImageNav Pose SR: largest heading error at the goal, radians; NaN otherwise",
        "geodesic_distance": "shortest valid path from start to goal known, metres (what SPL divides by)",
        "euclidean_distance": "straight-line start to goal distance, metres",
        "num_steps": "rows of the expert trajectory (20 Hz steps)",
        "total_time": "duration of the expert trajectory, seconds",
        "path_length": "distance the expert travelled, metres",
        "avg_speed": "the expert's mean speed, m/s", "max_speed": "the expert's top speed, m/s",
        "oracle_actions": "the discrete expert's actions: 0 stop, 1 forward, 2 left, 3 right",
        "goal_image_path": "ImageNav: relative path of the goal image once rendered (goal_images)",
        "goal_camera_json": "ImageNav: camera pose and intrinsics that render the goal view (JSON)",
        "goal_object_category": "ObjectNav: the goal category (one of the 8 goal categories)",
        "goal_object_id": "ObjectNav: instance id of the goal chosen for the expert (instances table)",
        "instruction_text": "null: reserved for instructions in words (VLN), which no task writes yet",
        "instruction_language": "null: the instruction's language, reserved with it",
        "goals_json": "JSON array of every goal: ObjectNav instances with their boxes and view points; the goal "
                      "position otherwise",
        "seed": "the (scene, task) random stream's seed",
    },
    "trajectories": {
        "episode_id": "the episode this step belongs to (with the task, split and scene_id folders)",
        "step": "row k is the expert's state at t = k dt (20 Hz)",
        "timestamp": "t, seconds",
        **_pose_docs("", "the robot's"), "yaw": "heading, radians, counter-clockwise from +x",
        "action": "move_forward | turn_left | turn_right | stop: the kind of control of this step",
        "action_id": "0 stop, 1 move_forward, 2 turn_left, 3 turn_right (Habitat's ids)",
        "linear_velocity": "v held from this row to the next, m/s (robot frame, forward)",
        "angular_velocity": "omega held from this row to the next, rad/s (counter-clockwise)",
        "linear_velocity_x": "v in the world frame, x, m/s", "linear_velocity_y": "v in the world frame, y, m/s",
        "linear_acceleration": "(v_k - v_k-1) / dt, m/s^2",
        "angular_acceleration": "(omega_k - omega_k-1) / dt, rad/s^2",
        "curvature": "omega / v where v > 0, else 0, 1/m",
        "dx": "forward change of position to the next row, in this row's robot frame, metres",
        "dy": "leftward change of position to the next row, in this row's robot frame, metres",
        "dyaw": "change of heading to the next row, radians",
        "phase": "rotate | translate | stop",
    },
}
"""What each column of EPISODE_SCHEMA and TRAJECTORY_SCHEMA means (the card's and docs' field
tables are generated from it; tests check that every column has one)."""


def field_table(kind: str, skip: tuple[str, ...] = ()) -> list[str]:
    """Markdown rows (header included) of one table's columns (less `skip`): name, Arrow type, meaning."""
    schema = {"episodes": EPISODE_SCHEMA, "trajectories": TRAJECTORY_SCHEMA}[kind]
    return ["| column | type | meaning |", "|---|---|---|",
            *[f"| `{f.name}` | `{f.type}` | {FIELD_DOCS[kind][f.name]} |" for f in schema if f.name not in skip]]


TRAJECTORY_QUANTA = {
    **dict.fromkeys(("rotation_qz", "rotation_qw", "linear_velocity_x", "linear_velocity_y", "dx", "dy", "dyaw"),
                    2.0**-16),  # 1.5e-5 (m, m/s, rad, unit quaternion)
    **dict.fromkeys(("linear_acceleration", "angular_acceleration", "curvature"), 2.0**-12),  # 2.4e-4
}
"""Binary grid of each derived trajectory column (values are rounded to multiples of it)."""

TRAJECTORY_WRITE = {
    "compression": "zstd",
    "use_dictionary": [f.name for f in TRAJECTORY_SCHEMA if f.type in (STR, I8)],
    "column_encoding": {**{f.name: "BYTE_STREAM_SPLIT" for f in TRAJECTORY_SCHEMA if f.type == F32},
                        "step": "DELTA_BINARY_PACKED"},
    "row_group_size": 1 << 20,
}
"""pyarrow.parquet.write_table options of trajectory tables (canonical store and exports)."""


def quantize_trajectory(cols: dict) -> dict:
    """Round the derived columns of one trajectory (name -> array) to TRAJECTORY_QUANTA."""
    import numpy as np

    return {k: (np.round(np.asarray(v, np.float64) / TRAJECTORY_QUANTA[k]) * TRAJECTORY_QUANTA[k]
                if k in TRAJECTORY_QUANTA else v) for k, v in cols.items()}
