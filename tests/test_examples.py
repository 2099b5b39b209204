"""The scripts of examples/ run as users run them (a fresh interpreter of the venv, from the
project root) on a small generated data root, and do what their docstrings say."""
import subprocess
import sys

import pytest


def run_example(project_root, name, *args, timeout=600):
    p = subprocess.run([sys.executable, f"examples/{name}", *map(str, args)], cwd=project_root, capture_output=True,
                       text=True, timeout=timeout)
    assert p.returncode == 0, p.stderr[-3000:]
    return p.stdout


def test_query_episodes(episode_run, project_root, tmp_path):
    import pyarrow.dataset as ds

    root, _, _ = episode_run
    out = run_example(project_root, "query_episodes.py", root, "--plot", tmp_path / "geo.png")
    n = ds.dataset(root / "05_episodes", partitioning="hive").count_rows()
    assert out.startswith(f"{n} episodes in 1 scenes")
    assert "expert steps" in out and (tmp_path / "geo.png").stat().st_size > 5_000


def test_custom_policy_is_evaluated_in_closed_loop(episode_run, project_root):
    root, _, _ = episode_run
    out = run_example(project_root, "custom_policy.py", root, "--episodes", 2)
    assert "GoalSeeker on 2 PointNav episodes: SR" in out  # the library alone: 2 episodes of the one scene


@pytest.mark.filterwarnings("ignore")
def test_tiny_policy_trains_and_its_loss_goes_down(episode_run, project_root):
    root, _, _ = episode_run
    out = run_example(project_root, "train_tiny_policy.py", root, "--steps", 25, "--batch", 16)
    last = out.strip().splitlines()[-1]
    first, mean_last = (float(x) for x in last.split("loss ")[1].split(" (")[0].split(" -> "))
    assert mean_last < first, out
