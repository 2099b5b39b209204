"""The leave-one-capture-out run's table (benchmarks.baselines.captures_loo): runs read from their
evaluation labels, paired with the reference on the same episodes."""
import pandas as pd
import pytest

from benchmarks.baselines import captures_loo


def _results(path, successes, error_at=None):
    path.mkdir(parents=True)
    pd.DataFrame({"episode_id": [f"test_{i}" for i in range(len(successes))],
                  "sr": [float(s) for s in successes],
                  "error": ["boom" if i == error_at else None for i in range(len(successes))]}
                 ).to_parquet(path / "results.parquet")


def test_capture_table_pairs_each_run_with_the_reference(tmp_path, monkeypatch):
    monkeypatch.setattr(captures_loo, "EVAL", tmp_path)
    _results(tmp_path / "zs_room_world", [1, 1, 0, 0, 1, 0])
    _results(tmp_path / "zs_room_depth_reactive", [1, 0, 0, 1, 0, 0])
    _results(tmp_path / "loo_room", [1, 1, 1, 1, 1, 1], error_at=5)  # the errored episode is left out of the pair
    _results(tmp_path / "zs_room_b_world", [0, 0])  # another capture whose name starts like this one
    assert captures_loo.run_of("zs_room_b_world", ["room", "room_b"]) == ("room_b", "world")
    assert captures_loo.run_of("loo_room", ["room", "room_b"]) == ("room", "loo")
    rows, lines = captures_loo.capture_table(["room", "room_b"])
    by = {(r["capture"], r["run"]): r for r in rows}
    world, loo = by[("room", "world")], by[("room", "loo")]
    assert (world["episodes"], world["sr"], world["sr_ref"], world["only"], world["only_ref"]) == (6, 0.5, 1 / 3, 2, 1)
    assert world["p"] == pytest.approx(1.0)  # 2 against 1: no evidence either way
    assert (loo["episodes"], loo["only"], loo["only_ref"], loo["sr"]) == (5, 3, 0, 1.0)
    assert loo["p"] == pytest.approx(0.25)
    assert by[("room", "depth_reactive")] == {"capture": "room", "run": "depth_reactive", "episodes": 6, "sr": 1 / 3}
    assert lines[0] == "| capture | world | loo | depth_reactive |"
    assert lines[3] == "| room_b | 0.00 (2) | - | - |"


def test_loo_evaluates_only_finished_fine_tunes_one_after_the_other(tmp_path, monkeypatch):
    """A fine-tune that failed part-way (out of GPU memory: a model.pt of its --init weights, no card)
    is not evaluated as the leave-one-out run; by default the fine-tunes run one at a time, each with
    every worker."""
    caps, runs = tmp_path / "caps", tmp_path / "runs"
    for c in ("a", "b", "c"):
        (caps / c / "05_episodes" / "task=pointnav" / "x").mkdir(parents=True)
    monkeypatch.setattr(captures_loo, "CAPS", caps)
    monkeypatch.setattr(captures_loo, "RUNS", runs)
    monkeypatch.setattr(captures_loo, "WORKERS", 12)
    started, live, most = [], [0], [0]

    def fake_run(cmd, out=None, env=None):
        label = out.stem
        live[0] += 1
        most[0] = max(most[0], live[0])
        started.append((label, cmd[cmd.index("--workers") + 1]))
        folder = runs / label
        folder.mkdir(parents=True)
        (folder / "model.pt").write_bytes(b"init")
        if label != "loo_b":  # loo_b dies after writing its driver weights
            (folder / "model_card.json").write_text("{}")
        live[0] -= 1
        return 0 if label != "loo_b" else 1

    evaluated = []
    monkeypatch.setattr(captures_loo, "run", fake_run)
    monkeypatch.setattr(captures_loo, "evaluate", lambda jobs, *a: evaluated.extend(j[0] for j in jobs) or 0)
    rc = captures_loo.loo(1, 8, 10, 0.5, 5, 1, "cpu", (64, 48), control=False, captures_only=True)
    assert rc == 1
    assert sorted(evaluated) == ["loo_a", "loo_a_sample", "loo_c", "loo_c_sample"]  # greedy and sampled
    assert most[0] == 1 and all(w == 12 for _, w in started)


def test_sampled_decoding_is_its_own_run_of_the_same_policy(tmp_path, monkeypatch):
    """`world+sample` evaluates the world's checkpoint with its moves sampled, under its own label and
    column; a registry name takes the suffix too; a bad --loo-decoding is refused."""
    monkeypatch.setattr(captures_loo, "RUNS", tmp_path)
    greedy, sampled = captures_loo.agent_args("world"), captures_loo.agent_args("world+sample")
    assert sampled == greedy + ["--agent-arg", "sample=true"] and "sample=true" not in greedy
    assert captures_loo.agent_args("loo_room+sample")[3] == f"checkpoint={tmp_path / 'loo_room' / 'model.pt'}"
    assert captures_loo.agent_args("pointnav_bc+sample") == ["--agent", "pointnav_bc", "--agent-arg", "sample=true"]
    assert captures_loo.label_of("world+sample") == "world_sample" and captures_loo.label_of("world") == "world"
    assert captures_loo.run_of("loo_room_sample", ["room"]) == ("room", "loo_sample")
    assert captures_loo.run_of("zs_room_world_sample", ["room"]) == ("room", "world_sample")
    assert captures_loo.decodings("sample") == ("+sample",) and captures_loo.decodings("greedy,sample,greedy") == ("", "+sample")
    with pytest.raises(SystemExit, match="greedy, sample or both"):
        captures_loo.decodings("beam")
    monkeypatch.setattr(captures_loo, "EVAL", tmp_path / "eval")
    _results(tmp_path / "eval" / "zs_room_world", [1, 0, 0, 0])
    _results(tmp_path / "eval" / "zs_room_world_sample", [1, 1, 1, 0])
    _results(tmp_path / "eval" / "zs_room_depth_reactive", [0, 0, 1, 0])
    rows, lines = captures_loo.capture_table(["room"])
    assert lines[0] == "| capture | world | world_sample | depth_reactive |"
    assert {r["run"]: r["sr"] for r in rows} == {"world": 0.25, "world_sample": 0.75, "depth_reactive": 0.25}
