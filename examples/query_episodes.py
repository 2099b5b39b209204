"""Query a data root's episodes and trajectories with pandas, and plot their geodesic distances.

    .venv/bin/python examples/query_episodes.py [DATA_ROOT] [--plot geodesic.png]

Episodes are Parquet partitioned by task and scene (data/05_episodes/task=*/scene_id=*/), expert
trajectories the same under data/06_trajectories (one row per 20 Hz step). Column meanings:
docs/tasks.md and navcore/io/episode_schema.py.
"""
import argparse
from pathlib import Path

import pandas as pd


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("root", nargs="?", default="data", help="the data root (default: data)")
    ap.add_argument("--plot", default="geodesic.png", help="where to write the histogram")
    a = ap.parse_args(argv)
    root = Path(a.root)
    pd.options.display.width = 120

    eps = pd.read_parquet(root / "05_episodes")  # every task; `task` and `scene_id` come from the folders
    print(f"{len(eps)} episodes in {eps.scene_id.nunique()} scenes")
    print(eps.groupby(["task", "difficulty"], observed=True)["geodesic_distance"].describe()[["count", "mean", "max"]])

    # one task, filtered while reading (only its files are opened)
    point = pd.read_parquet(root / "05_episodes", filters=[("task", "==", "pointnav")])
    if len(point):
        first = point.sort_values("episode_id").iloc[0]
        traj = pd.read_parquet(root / "06_trajectories", filters=[("task", "==", "pointnav"),
                                                                  ("scene_id", "==", first.scene_id)])
        steps = traj[traj.episode_id == first.episode_id].sort_values("step")
        print(f"\n{first.episode_id} in scene {first.scene_id}: {first.geodesic_distance:.2f} m geodesic, "
              f"{len(steps)} expert steps ({steps.timestamp.iloc[-1]:.1f} s)")
        print(steps[["timestamp", "position_x", "position_y", "yaw", "linear_velocity", "angular_velocity"]].head())

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5))
    for task, g in eps.groupby("task", observed=True):
        ax.hist(g.geodesic_distance, bins=30, histtype="step", label=f"{task} ({len(g)})")
    ax.set_xlabel("geodesic distance (m)")
    ax.set_ylabel("episodes")
    ax.legend()
    fig.tight_layout()
    fig.savefig(a.plot, dpi=100)
    print(f"\nwrote {a.plot}")
    return eps


if __name__ == "__main__":
    main()
