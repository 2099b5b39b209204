"""Closed-loop evaluation: environment rules, protocols, metrics on hand-made rollouts, agents."""
import math

import numpy as np
import pytest

from navcore.eval.agents import make_agent
from navcore.eval.env import EnvConfig, NavEnv
from navcore.eval.loop import run_episode, run_episodes
from navcore.eval.metrics import aggregate, dtw, episode_metrics
from navcore.nav.actions import MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT


def test_moves_collisions_and_action_forms(ctx, make_episode):
    env = NavEnv(ctx, EnvConfig(render=False))
    env.reset(make_episode(start=(1.0, 0.5, -math.pi / 2)))  # facing the wall at y = 0
    env.step(MOVE_FORWARD)
    assert env.state.y == pytest.approx(0.25) and env.state.collisions == 0
    env.step(MOVE_FORWARD)  # would end at y = 0, inside the wall: blocked, truncated at the contact
    assert env.state.y == pytest.approx(0.125, abs=0.006) and env.state.y >= 0.125 - 1e-9
    assert env.state.collisions == 1 and env.state.moves == 2
    env.step(TURN_LEFT)  # turning in place never collides
    assert env.state.yaw == pytest.approx(-math.pi / 2 + math.radians(15))
    env.reset(make_episode())
    env.step({"waypoints": [{"x": 0.2, "y": 0.1, "yaw": 0.3}]})
    assert (env.state.x, env.state.y, env.state.yaw) == pytest.approx((1.2, 0.6, 0.3))
    env.step({"v": 0.5, "w": 1.0, "dt": 0.2})  # 0.1 m along the heading, then +0.2 rad
    assert (env.state.x, env.state.y) == pytest.approx((1.2 + 0.1 * math.cos(0.3), 0.6 + 0.1 * math.sin(0.3)))
    assert env.state.yaw == pytest.approx(0.5)
    s = env.state
    m = episode_metrics(s, 2.0, 2.0, "distance")
    assert m["collision_rate"] == 0 and m["steps"] == 2
    assert s.path_length == pytest.approx(math.hypot(0.2, 0.1) + 0.1)
    env.step({"jump": 1})  # refused: a step spent, recorded
    assert env.state.invalid_actions == 1 and "unknown action" in env.state.action_error


def test_explicit_stop_outside_the_region_fails(ctx, make_episode):
    env = NavEnv(ctx, EnvConfig(render=False, protocol="explicit_stop"))
    env.reset(make_episode())
    env.step(MOVE_FORWARD)
    _, info = env.step(STOP)
    assert info["done"] and not info["success"] and info["end_reason"] == "stop"
    m = episode_metrics(env.state, 2.0, 1.75, "explicit_stop")
    assert m["stop_sr"] == 0 and m["sr"] == 0 and m["spl"] == 0 and m["osr"] == 0
    assert math.isnan(m["distance_sr"])  # not defined by an explicit-stop run
    assert m["ne"] == pytest.approx(1.75)
    assert m["soft_spl"] == pytest.approx((1 - 1.75 / 2.0) * 2.0 / 2.0)
    with pytest.raises(RuntimeError):
        env.step(MOVE_FORWARD)


def test_distance_protocol_ends_on_entry_and_stop_only_consumes_a_step(ctx, make_episode):
    env = NavEnv(ctx, EnvConfig(render=False, protocol="distance"))
    env.reset(make_episode(start=(2.2, 0.5, 0.0), goal=(3.0, 0.5), geodesic=0.8))
    _, info = env.step(STOP)
    assert not info["done"] and info["steps"] == 1
    env.step(MOVE_FORWARD)  # 2.45: 0.55 from the goal, outside
    _, info = env.step(MOVE_FORWARD)  # 2.70: inside
    assert info["done"] and info["success"] and info["end_reason"] == "entered"
    m = episode_metrics(env.state, 0.8, 0.3, "distance")
    assert m["sr"] == 1 and m["distance_sr"] == 1
    assert math.isnan(m["stop_sr"]) and math.isnan(m["osr"])  # 0 / equal to Distance SR by construction
    assert m["spl"] == pytest.approx(0.8 / max(0.5, 0.8))  # walked 0.5 < geodesic 0.8: SPL 1
    # the budget ends an episode
    env.reset(make_episode(max_steps=3))
    for a in (TURN_LEFT, TURN_RIGHT, TURN_LEFT):
        _, info = env.step(a)
    assert info["done"] and info["end_reason"] == "budget" and not info["success"]


def test_pose_criterion_and_spl_by_hand(ctx, make_episode):
    env = NavEnv(ctx, EnvConfig(render=False, protocol="explicit_stop"))
    for heading_deg, pose_ok in ((20.0, 1.0), (45.0, 0.0)):
        ep = make_episode(start=(2.9, 0.5, math.radians(heading_deg)), task="imagenav", goal_yaw=0.0,
                     heading_tolerance=math.radians(30), geodesic=0.1)
        env.reset(ep)
        env.step(STOP)
        m = episode_metrics(env.state, 0.1, 0.1, "explicit_stop")
        assert m["sr"] == 1 and m["pose_sr"] == pose_ok
    env.reset(make_episode(start=(1.0, 0.5, 0.0), goal=(1.5, 0.5), radius=0.3, geodesic=0.5))
    for _ in range(3):
        env.step(MOVE_FORWARD)  # overshoots to 1.75, still inside (0.25 from the goal)
    env.step(STOP)
    m = episode_metrics(env.state, 0.5, 0.25, "explicit_stop")
    assert env.state.path_length == pytest.approx(0.75) and m["spl"] == pytest.approx(0.5 / 0.75)
    rows = [{"difficulty": "easy", "sr": 1.0, "distance_sr": 1.0, "pose_sr": 0.5},
            {"difficulty": "hard", "sr": 0.5, "distance_sr": 0.5, "pose_sr": 0.0}]
    agg = aggregate(rows)
    assert agg["overall"]["distance_sr"] == 0.75 and agg["overall"]["pose_retention"] == pytest.approx(0.25 / 0.75)
    assert agg["easy"]["episodes"] == 1


def test_start_inside_the_region_then_walking_out_is_no_success(ctx, make_episode):
    """The start pose never counts: Distance SR / OSR need the region entered after an action."""
    for protocol in ("distance", "explicit_stop"):
        env = NavEnv(ctx, EnvConfig(render=False, protocol=protocol))
        env.reset(make_episode(start=(2.6, 0.5, math.pi), goal=(3.0, 0.5), radius=0.5, geodesic=0.2, max_steps=3))
        for _ in range(3):
            env.step(MOVE_FORWARD)  # 2.35, 2.10, 1.85: out of the region after the first action
        s = env.state
        assert s.done and s.end_reason == "budget" and not s.success
        m = episode_metrics(s, 0.2, 1.15, protocol)
        assert m["sr"] == 0 and m["spl"] == 0
        assert (m["distance_sr"] == 0) if protocol == "distance" else (m["osr"] == 0 and m["stop_sr"] == 0)


def test_each_metric_only_from_the_protocol_that_defines_it(ctx, make_episode):
    env = NavEnv(ctx, EnvConfig(render=False, protocol="explicit_stop"))
    env.reset(make_episode(start=(2.2, 0.5, 0.0), goal=(3.0, 0.5), geodesic=0.8))
    for a in (MOVE_FORWARD, MOVE_FORWARD, MOVE_FORWARD, MOVE_FORWARD):  # through the region to 3.2
        env.step(a)
    env.step(TURN_LEFT)
    env.step(TURN_LEFT)
    m = episode_metrics(env.state, 0.8, 0.2, "explicit_stop")
    assert m["osr"] == 1 and m["stop_sr"] == 0 and m["sr"] == 0 and math.isnan(m["distance_sr"])
    rows = [{"difficulty": "easy", **m}]
    agg = aggregate(rows)["overall"]
    assert math.isnan(agg["distance_sr"]) and agg["osr"] == 1
    from stages.evaluate.report import tables

    md = tables({"oracle_explicit_stop": {"protocol": "explicit_stop", "tasks": {"pointnav": aggregate(rows)}}})
    line = next(x for x in md.splitlines() if x.startswith("| oracle_explicit_stop |"))
    assert "explicit_stop" in md and line.split("|")[5].strip() == "-"  # Dist. SR column empty


@pytest.mark.parametrize("mode,actions_collided,moves_collided", [("stay", 1, 2), ("truncate", 2, 4), ("slide", 2, 4)])
def test_collision_rate_per_action_and_per_move(ctx, make_episode, mode, actions_collided, moves_collided):
    """The definitions (per policy action, per attempted translation) hold in every dynamics mode;
    what changes is where a blocked move ends: under stay the robot stays at y = 0.5, so the third
    waypoint (to 0.4 m) and the last forward step (at -60 degrees) are free; under truncate / slide it
    already stands at the wall (y = 0.125), and both are blocked too."""
    env = _env_with(ctx, mode)
    env.reset(make_episode(start=(1.0, 0.5, -math.pi / 2), max_steps=10))  # facing the wall at y = 0
    env.step({"waypoints": [{"x": 0.6}, {"x": 0.6}, {"x": 0.1}]})
    env.step(TURN_LEFT)
    env.step(TURN_LEFT)
    env.step(MOVE_FORWARD)
    m = episode_metrics(env.state, 2.0, 2.0, "distance")
    assert m["collision_rate"] == pytest.approx(actions_collided / 4)  # of 4 policy actions
    assert m["collision_rate_moves"] == pytest.approx(moves_collided / 4)  # of 4 attempted translations


def test_spl_of_an_immediate_success_with_zero_optimum(ctx, make_episode):
    env = NavEnv(ctx, EnvConfig(render=False, protocol="explicit_stop"))
    env.reset(make_episode(start=(3.0, 0.5, 0.0), goal=(3.0, 0.5), geodesic=0.0))
    env.step(STOP)
    m = episode_metrics(env.state, 0.0, 0.0, "explicit_stop")
    assert m["sr"] == 1 and m["spl"] == 1 and m["soft_spl"] == 1  # 0/0: no motion needed, none made


def test_ne_euclidean_and_geodesic(ctx, make_episode):
    env = NavEnv(ctx, EnvConfig(render=False))
    env.reset(make_episode(start=(1.0, 0.5, 0.0), goal=(3.0, 0.5), geodesic=2.0))
    m = episode_metrics(env.state, 2.0, env.geodesic_to_goal(), "distance")
    assert m["ne"] == pytest.approx(2.0)
    assert m["ne_geodesic"] == pytest.approx(env.geodesic_to_goal()) and m["ne_geodesic"] >= m["ne"] - 1e-6


def test_non_finite_and_malformed_actions_spend_a_step_and_are_recorded(ctx, make_episode):
    """An invalid action counts as one step with a recorded error (pose unchanged); the episode goes on."""
    env = NavEnv(ctx, EnvConfig(render=False))
    env.reset(make_episode())
    bad = ({"waypoints": [{"x": float("nan")}]}, {"x": float("inf")}, {"v": 0.5, "dt": -1.0},
           {"waypoints": [{"x": 0.1}] * 1000}, {"waypoints": "far"}, 1.5, "1", True, {"v": 0.2, "w": None}, {})
    for k, a in enumerate(bad, 1):
        _, info = env.step(a)
        assert env.state.steps == k and env.state.invalid_actions == k and not info["done"]
        assert env.state.pose.tolist() == pytest.approx([1.0, 0.5, 0.0])
    assert env.state.action_error.startswith("step 1: ") and "finite" in env.state.action_error
    env.step({"x": 0.2, "y": 0.0, "yaw": 0.1})  # navarena-server's flat waypoint
    assert (env.state.x, env.state.yaw) == pytest.approx((1.2, 0.1)) and env.state.invalid_actions == len(bad)
    assert all(math.isfinite(v) for v in env.state.pose)


def test_dtw_known_answers():
    a = np.array([[0, 0], [1, 0], [2, 0]], float)
    b = np.array([[0, 0], [2, 0]], float)
    assert dtw(a, b) == pytest.approx(1.0)
    assert dtw(a, a) == 0.0
    assert dtw(b, a) == pytest.approx(1.0)
    # a shifted copy: every point one metre off
    assert dtw(a, a + [0, 1]) == pytest.approx(3.0)


def test_oracle_succeeds_random_rarely_and_a_crashing_agent_fails_its_episode(ctx, make_episode):
    ep = make_episode(start=(1.0, 0.5, 0.0), goal=(3.0, 0.5), geodesic=2.3, max_steps=500)
    ep.reference_path = np.array([[1.0, 0.5], [2.0, 2.2], [3.0, 0.5]])
    for protocol in ("distance", "explicit_stop"):
        row = run_episode(NavEnv(ctx, EnvConfig(render=False, protocol=protocol)), make_agent("oracle"), ep)
        assert row["sr"] == 1 and row["collision_rate"] == 0 and 0 < row["ndtw"] <= 1

    class Boom:
        def reset(self, task):
            self.n = 0

        def act(self, obs):
            self.n += 1
            if self.n > 3:
                raise RuntimeError("agent crashed")
            return MOVE_FORWARD

    rows = run_episodes(ctx, [ep, ep], Boom(), EnvConfig(render=False))
    assert [r["end_reason"] for r in rows] == ["agent_error"] * 2 and "crashed" in rows[0]["error"]
    assert rows[0]["sr"] == 0 and rows[0]["steps"] == 3
    with pytest.raises(ValueError, match="unknown agent"):
        make_agent("nope")
    assert type(make_agent("navcore.eval.agents:RandomAgent")).__name__ == "RandomAgent"


def test_batched_env_matches_single_envs_and_gym_wrapper(ctx, make_episode):
    from navarena.gym_env import NavGymEnv
    from navcore.eval.batch import BatchNavEnv

    eps = [make_episode(start=(1.0, 0.5, a), max_steps=60) for a in (0.0, 1.5, -1.0)]
    for i, e in enumerate(eps):
        e.episode_id = f"b{i}"
    rng = np.random.default_rng(1)
    acts = rng.integers(1, 4, size=(40, 3))
    batch = BatchNavEnv(ctx, 3, EnvConfig(render=False))
    batch.reset(eps)
    singles = [NavEnv(ctx, EnvConfig(render=False)) for _ in eps]
    for s, e in zip(singles, eps):
        s.reset(e)
    for row in acts:
        live = [None if s.state.done else int(a) for s, a in zip(singles, row)]
        _, infos = batch.step(live)
        for s, a in zip(singles, live):
            if a is not None:
                s.step(a)
        assert [tuple(i["pose"]) for i in infos] == [tuple(s.info()["pose"]) for s in singles]
    env = NavGymEnv(ctx, eps, EnvConfig(render=False, protocol="explicit_stop"))
    from gymnasium.utils.env_checker import check_env

    check_env(env, skip_render_check=True)
    obs, _ = env.reset(options={"episode": make_episode(start=(2.0, 0.5, 0.0), goal=(2.4, 0.5), geodesic=0.4)})
    _, reward, terminated, truncated, info = env.step(STOP)
    assert terminated and not truncated and info["success"] and reward == pytest.approx(2.5 - 0.01)


def test_evaluate_stage_writes_results_reports_plots_and_video(episode_run, make_cfg):
    import json

    import av
    import pandas as pd

    from pipeline.executor import execute

    root, over, _ = episode_run
    common = [*over[:-1], "export.chunk_size=8", "stages=[evaluate]", "evaluate.tasks=[pointnav,objectnav]",
              "evaluate.episodes_per_scene=3"]
    from rich.console import Console

    console = Console(record=True, width=80, force_terminal=False)
    s = execute(make_cfg(root, *common, "evaluate.agent=oracle", "evaluate.width=32", "evaluate.height=24",
                         "evaluate.renderer=cpu", "evaluate.videos=1", "evaluate.trajectory_plots=1",
                         "evaluate.protocol=explicit_stop"), console)
    assert not s["failures"], s["failures"]
    # the console counts episodes (not only stage tasks) and logs each one as it finishes
    shown = console.export_text()
    assert "episodes" in shown and "steps/s" in shown and shown.count(": success, ") == 6, shown[-3000:]
    assert not execute(make_cfg(root, *common, "evaluate.agent=random", "evaluate.render=false",
                                "evaluate.difficulty=easy", "evaluate.batch_slots=2"))["failures"]
    run = root / "07_eval" / "oracle_explicit_stop"
    res = pd.read_parquet(run / "results")
    assert len(res) == 6 and set(res["task"]) == {"pointnav", "objectnav"}
    assert all(len(x) == len(y) >= 1 for x, y in zip(res["trajectory_x"], res["trajectory_y"]))
    summary = json.loads((run / "summary.json").read_text())
    assert summary["episodes"] == 6 and summary["tasks"]["pointnav"]["overall"]["sr"] == 1.0
    assert summary["tasks"]["objectnav"]["overall"]["spl"] > 0.9
    rnd = pd.read_parquet(root / "07_eval" / "random_distance" / "results")
    assert (rnd["difficulty"] == "easy").all() and len(rnd) <= 6
    from navcore.io.progress_log import read_log

    for name, n in (("oracle_explicit_stop", 6), ("random_distance", len(rnd))):  # sequential and batched loops
        logs = [read_log(p) for p in (root / "_progress" / "eval" / name).glob("*.jsonl")]
        assert sum(h["total"] for h, _ in logs) == sum(len(items) for _, items in logs) == n
    tables = (root / "07_eval" / "tables.md").read_text()
    assert "random_distance" in tables and "oracle_explicit_stop" in tables and "Table 7" in tables
    from PIL import Image

    plot = np.asarray(Image.open(root / "07_eval" / "sr_by_difficulty.png"))
    assert plot.ndim == 3 and plot.shape[0] >= 200 and len(np.unique(plot.reshape(-1, plot.shape[2]), axis=0)) > 4
    assert len(list((run / "plots").glob("*.png"))) == 1
    videos = list((run / "videos").glob("*.mp4"))
    assert len(videos) == 1
    with av.open(str(videos[0])) as c:
        frames = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
    first = res[res["task"] == "pointnav"].sort_values("episode_id").iloc[0]
    assert frames[0].shape == (24, 32, 3) and len(frames) == first["steps"] + 1  # reset + every step
    # results.json in navarena-bench's protocol 2.x layout, validated against the schema
    import jsonschema

    from stages.evaluate.bench_results import RESULTS_SCHEMA, validate

    for name, n in (("oracle_explicit_stop", 6), ("random_distance", len(rnd))):
        doc = json.loads((root / "07_eval" / name / "results.json").read_text())
        validate(doc)
        assert doc["meta"]["evaluation_protocol_version"].startswith("2.")
        assert doc["run_summary"]["num_episodes"] == len(doc["episode_results"]) == n
        assert all((root / "07_eval" / name / p).exists() for p in doc["artifacts"]["results_parquet"])
    assert doc["meta"]["success_policy"] == "geometric_distance" and doc["metric_results"]["overall"]["stop_sr"]["value"] is None
    oracle = json.loads((run / "results.json").read_text())
    assert oracle["run_summary"]["success_rate"] == pytest.approx(res["sr"].mean())
    assert {e["status"] for e in oracle["episode_results"]} == {"success"} and oracle["artifacts"]["videos"]
    broken = json.loads((run / "results.json").read_text())
    broken["episode_results"][0]["num_steps"] = -1
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(broken, RESULTS_SCHEMA)


def test_batched_loop_equals_the_single_loop_for_in_process_agents(ctx, make_episode):
    from navcore.eval.loop import InProcessBatch, run_episodes_batched

    eps = [make_episode(start=(1.0, 0.5, a), goal=g, geodesic=2.3, max_steps=300)
           for a, g in ((0.0, (3.0, 0.5)), (1.0, (3.5, 2.5)), (-2.0, (1.5, 2.5)), (2.5, (3.0, 1.5)))]
    for i, e in enumerate(eps):
        e.episode_id = f"q{i}"
    single = run_episodes(ctx, eps, make_agent("oracle"), EnvConfig(render=False))
    batched = run_episodes_batched(ctx, eps, InProcessBatch(lambda: make_agent("oracle")), 3, EnvConfig(render=False))
    assert [r["episode_id"] for r in batched] == [e.episode_id for e in eps]
    for a, b in zip(single, batched):
        assert (a["sr"], a["steps"], a["spl"]) == (b["sr"], b["steps"], b["spl"]) and a["sr"] == 1
    # random: each episode's moves depend on its id, not on its slot, the slot count or the order
    key = lambda rows: {r["episode_id"]: (r["steps"], r["sr"], tuple(np.round(r["trajectory"].ravel(), 6))) for r in rows}  # noqa: E731
    single = key(run_episodes(ctx, eps, make_agent("random"), EnvConfig(render=False)))
    for slots, order in ((3, eps), (2, eps[::-1])):
        assert key(run_episodes_batched(ctx, order, InProcessBatch(lambda: make_agent("random")), slots,
                                        EnvConfig(render=False))) == single
    assert len({v[2] for v in single.values()}) == len(eps)  # and the episodes' streams differ


def test_several_scenes_in_flight_give_each_episode_the_result_it_has_alone(ctx, make_episode):
    """evaluate_scenes: scenes whose episodes run beside each other's in one batch (fewer slots than
    episodes, two scenes in flight) give every episode the steps, success and trajectory it has when its
    scene runs alone, one episode at a time, with the scene's seed (random: seeded per scene and
    episode; oracle: bound to its own slot's environment); the rows come in the scenes' order, and a
    scene's context is made only when it joins: the third after the first scene's last episode ended."""
    from navcore.eval.loop import SceneEpisodes, evaluate_episodes, evaluate_scenes

    cfg = EnvConfig(render=False)
    goals = ((3.0, 0.5), (3.5, 2.5), (1.5, 2.5), (3.0, 1.5))
    scenes = []
    for k in range(3):
        eps = [make_episode(start=(1.0, 0.5, 0.4 * j), goal=goals[(j + k) % 4], geodesic=2.3, max_steps=40 + 30 * j)
               for j in range(k + 2)]
        for e in eps:
            e.scene_id = f"s{k}"
        scenes.append(eps)
    key = lambda rows: [(r["scene_id"], r["episode_id"], r["steps"], r["sr"], tuple(np.round(r["trajectory"].ravel(), 6)))  # noqa: E731
                        for r in rows]
    for agent in ("random", "oracle"):
        alone = [r for k, eps in enumerate(scenes) for r in evaluate_episodes(ctx, eps, agent, cfg, seed=100 + k)]
        events = []

        def made(k):
            events.append(("context", k))
            return ctx

        together = evaluate_scenes([SceneEpisodes(eps, lambda k=k: made(k), 100 + k) for k, eps in enumerate(scenes)],
                                   agent, cfg, batch_slots=3, scenes_at_once=2,
                                   on_result=lambda row, frames: events.append(("row", row["scene_id"])))
        assert key(together) == key(alone) and len(together) == 9
        if agent == "random":  # the scenes' seeds matter: another seed gives other moves
            assert key(evaluate_episodes(ctx, scenes[0], agent, cfg, seed=7)) != key(alone[:2])
        rows_of_first = [i for i, e in enumerate(events) if e == ("row", "s0")]
        assert events[:2] == [("context", 0), ("context", 1)] and len(rows_of_first) == 2
        assert events.index(("context", 2)) > rows_of_first[-1]


# ---- blocked moves (navcore.nav.dynamics) ----------------------------------------------------------

def _env_with(ctx, mode):
    from navcore.eval.env import DynamicsConfig

    return NavEnv(ctx, EnvConfig(render=False, dynamics=DynamicsConfig(blocked=mode)))


def test_blocked_move_known_poses_per_mode(ctx, make_episode):
    """room_with_door: the wall's cells start at x = 2.0 m, clearance 2.025 - x, robot radius 0.1:
    valid up to x = 1.925. A 1 m forward move from x = 1.5 and a 0.8 m move at 45 degrees."""
    ends = {}
    for mode in ("stay", "truncate", "slide"):
        env = _env_with(ctx, mode)
        env.reset(make_episode(start=(1.5, 1.0, 0.0)))
        env.step({"x": 1.0, "yaw": 0.3})
        straight = (env.state.x, env.state.y, env.state.yaw)
        env.reset(make_episode(start=(1.5, 1.0, math.pi / 4)))
        env.step({"x": 0.8})
        ends[mode] = (straight, (env.state.x, env.state.y), env.state.collisions)
    (s1, s2, c) = ends["stay"]
    assert s1 == pytest.approx((1.5, 1.0, 0.3)) and s2 == pytest.approx((1.5, 1.0)) and c == 1  # the turn applies
    (s1, s2, c) = ends["truncate"]
    assert s1[0] == pytest.approx(1.925, abs=0.006) and s1[0] <= 1.925 + 1e-9 and s1[1:] == pytest.approx((1.0, 0.3))
    assert s2 == pytest.approx((1.925, 1.425), abs=0.006) and c == 1
    (s1, s2, c) = ends["slide"]
    assert s1[0] == pytest.approx(1.925, abs=0.006) and s1[1] == pytest.approx(1.0)  # head-on: nothing to slide along
    assert s2[0] == pytest.approx(1.925, abs=0.006) and s2[1] == pytest.approx(1.0 + 0.8 * math.sqrt(0.5), abs=0.006)
    assert c == 1


@pytest.mark.parametrize("angle_deg", [30, 60, 85])
def test_slide_follows_habitats_sliding_rule_on_a_wall(ctx, make_episode, angle_deg):
    """habitat-sim's allow_sliding: a step into a wall ends at the wall, moved along it by the step's
    component along the wall (d cos theta for a wall met at theta). The wall of room_with_door at
    x = 2 (contact at x = 1.925), a 1 m step from (1.8, 0.5) meeting it at 30, 60 and 85 degrees."""
    env = _env_with(ctx, "slide")
    theta = math.radians(angle_deg)
    env.reset(make_episode(start=(1.8, 0.5, math.pi / 2 - theta)))  # heading theta away from the wall's +y direction
    env.step({"x": 1.0})
    assert env.state.collisions == 1
    assert env.state.x == pytest.approx(1.925, abs=0.006) and env.state.x <= 1.925 + 1e-9
    assert env.state.y - 0.5 == pytest.approx(math.cos(theta), abs=0.006)


def test_swept_paths_never_enter_an_obstacle(ctx, room_with_door):
    """Random blocked and free moves in every mode: each leg is a valid motion of the costmap, and
    points every quarter cell along it keep the robot's disk clear of every obstacle cell."""
    from navcore.nav.dynamics import blocked_motion

    cm = room_with_door
    rng = np.random.default_rng(5)
    valid = np.argwhere(~cm.occupancy)
    starts = cm.cell_centers(valid[rng.integers(len(valid), size=150)])
    blocked = 0
    for mode in ("stay", "truncate", "slide"):
        for x0, y0 in starts:
            a, d = rng.uniform(-math.pi, math.pi), rng.uniform(0.1, 1.5)
            x1, y1 = x0 + d * math.cos(a), y0 + d * math.sin(a)
            if cm.is_motion_valid(x0, y0, x1, y1):
                continue
            blocked += 1
            p = (x0, y0)
            for q in blocked_motion(cm, x0, y0, x1, y1, mode):
                assert cm.is_motion_valid(p[0], p[1], q[0], q[1])
                n = max(2, int(math.hypot(q[0] - p[0], q[1] - p[1]) / (cm.resolution / 4)) + 2)
                pts = np.linspace(p, q, n)
                assert (cm.clearance_at(pts) >= cm.radius - 1e-6).all()
                p = q
    assert blocked > 100


def test_forward_and_turn_policy_facing_a_wall_escapes(ctx, make_episode):
    """NavArena-Server's ImageNav example drives forward and steers; blocked in front of a wall it
    must still turn away (the old rule threw the step's turn away with the blocked translation)."""
    for mode in ("stay", "truncate", "slide"):
        env = _env_with(ctx, mode)
        env.reset(make_episode(start=(1.8, 1.0, 0.0), goal=(3.5, 0.5), radius=0.2, max_steps=40))
        for _ in range(30):
            env.step({"x": 0.25, "yaw": 0.3})
            assert not env.state.done
        s = env.state
        assert s.path_length > 2.0 and s.collisions < 12, (mode, s.path_length, s.collisions)
        assert math.hypot(s.x - 1.8, s.y - 1.0) > 0.3


def test_unknown_dynamics_mode_is_refused(ctx):
    with pytest.raises(ValueError, match="dynamics.blocked"):
        _env_with(ctx, "bounce")


def test_every_json_a_full_run_writes_is_strict(episode_run, tmp_path, make_cfg):
    """The default graph through export plus an evaluation under both protocols: every .json and
    .json.gz under the data root parses with a strict parser (no NaN / Infinity), and the summary
    says what its nulls mean."""
    import gzip
    import json as _json
    import shutil

    from pipeline.executor import execute

    root, over, _ = episode_run
    data = tmp_path / "d"
    shutil.copytree(root, data)
    keep = [o for o in over if not o.startswith("stages=")]
    for protocol in ("distance", "explicit_stop"):
        s = execute(make_cfg(data, *keep, "stages=[evaluate]", "evaluate.render=false", "evaluate.episodes_per_scene=3",
                             f"evaluate.protocol={protocol}"))
        assert not s["failures"], s["failures"]

    def refuse(name):
        raise ValueError(f"non-standard JSON constant {name}")

    files = sorted(p for p in data.rglob("*") if p.name.endswith((".json", ".json.gz")))
    for p in files:
        raw = gzip.decompress(p.read_bytes()) if p.name.endswith(".gz") else p.read_bytes()
        _json.loads(raw, parse_constant=refuse)
    names = {p.name for p in files}
    assert {"summary.json", "results.json", "latest.json", "dataset_meta.json"} <= names and len(files) > 20
    summary = _json.loads((data / "07_eval" / "oracle_distance" / "summary.json").read_text())
    assert summary["tasks"]["pointnav"]["overall"]["stop_sr"] is None and "distance run" in summary["null_means"]["stop_sr"]


def test_presets_paper_and_habitat(make_cfg, tmp_path):
    paper = make_cfg(tmp_path, "+preset=paper")
    habitat = make_cfg(tmp_path, "+preset=habitat")
    default = make_cfg(tmp_path)
    assert (paper.task.objectnav.success_rule, paper.evaluate.dynamics.blocked) == ("centre", "stay")
    assert (habitat.task.objectnav.success_rule, habitat.evaluate.dynamics.blocked) == ("footprint", "slide")
    assert (default.task.objectnav.success_rule, default.evaluate.dynamics.blocked) == ("footprint", "truncate")


def test_depth_reactive_explores_where_there_is_no_point_goal(ctx, make_episode):
    """Without a goal vector (ImageNav, ObjectNav) depth_reactive drives forward while the centre
    of its depth band is clear and, once blocked, keeps turning the way it began until clear (known
    answers on hand-made depth); in closed loop on an ObjectNav episode it runs without an agent
    error, never stops and moves."""
    agent = make_agent("depth_reactive")
    agent.reset({})
    open_room = np.full((24, 32), 3.0, np.float32)
    wall_left_freer = np.full((24, 32), 0.2, np.float32)
    wall_left_freer[:, :10] = 2.0
    wall_right_freer = np.full((24, 32), 0.2, np.float32)
    wall_right_freer[:, 22:] = 2.0
    seq = [agent.act({"depth": d}) for d in (open_room, wall_left_freer, wall_right_freer, wall_right_freer,
                                             open_room, wall_right_freer)]
    assert seq == [MOVE_FORWARD, TURN_LEFT, TURN_LEFT, TURN_LEFT, MOVE_FORWARD, TURN_RIGHT]
    assert agent.act({"depth": np.zeros((24, 32), np.float32)}) == MOVE_FORWARD  # nothing hit: open
    ep = make_episode(start=(1.0, 0.5, 0.0), goal=(3.0, 0.5), radius=0.3, max_steps=60, task="objectnav")
    row = run_episode(NavEnv(ctx, EnvConfig(protocol="distance", width=32, height=24)), make_agent("depth_reactive"), ep)
    assert row["end_reason"] in ("entered", "budget") and not row["error"] and row["path_length"] > 0.5


def test_a_users_agent_is_imported_from_the_current_folder_or_refused_in_one_line(tmp_path):
    """navarena eval --agent pkg.module:Class finds the package in the folder it runs from (as
    python -m does) before anything runs; an agent that cannot be imported is one line naming the
    module and the folder, exit 2, no traceback."""
    import subprocess
    import sys

    pkg = tmp_path / "my_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "policy.py").write_text("class MyAgent:\n    def reset(self, task):\n        pass\n\n"
                                   "    def act(self, obs):\n        return 0\n")
    from pathlib import Path

    script = Path(sys.executable).parent / "navarena"  # the console script: its folder, not the current one, is on sys.path
    run = lambda agent: subprocess.run([str(script), "eval", str(tmp_path / "no_root"), "--agent", agent],  # noqa: E731
                                       cwd=tmp_path, capture_output=True, text=True)
    bad = run("my_pkgx.policy:MyAgent")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1 and "'my_pkgx'" in bad.stderr and str(tmp_path) in bad.stderr
    missing = run("my_pkg.policy:Nope")
    assert missing.returncode == 2 and "has no attribute 'Nope'" in missing.stderr
    good = run("my_pkg.policy:MyAgent")  # the agent imports; the run stops at the missing data root instead
    assert good.returncode == 2 and "my_pkg" not in good.stderr and "no_root" in good.stderr, good.stderr


def test_errored_episodes_are_counted_apart_never_as_failures():
    rows = [{"sr": 1.0, "spl": 0.8, "difficulty": "easy", "error": ""},
            {"sr": 0.0, "spl": 0.0, "difficulty": "easy", "error": "ConnectionError: agent server unreachable"},
            {"sr": 0.0, "spl": 0.0, "difficulty": "hard", "error": ""}]
    agg = aggregate(rows)
    assert agg["overall"]["episodes"] == 2 and agg["overall"]["errored"] == 1
    assert agg["overall"]["sr"] == 0.5 and agg["easy"]["sr"] == 1.0 and agg["easy"]["errored"] == 1


def test_the_evaluate_verb_stops_when_the_agent_server_cannot_be_reached(ctx, make_episode):
    """evaluate_episodes: an agent server unreachable for max_connect_failures episodes in a row
    stops the run (AgentUnreachable naming its address) instead of waiting out every episode, one at a
    time or batched; the episodes it tried were reported."""
    import time

    from navcore.eval.loop import AgentUnreachable, evaluate_episodes

    eps = [make_episode(start=(1.0, 0.5, 0.1 * i)) for i in range(8)]
    for i, e in enumerate(eps):
        e.episode_id = f"u{i}"
    for slots in (1, 2):
        seen = []
        t0 = time.perf_counter()
        with pytest.raises(AgentUnreachable, match="ws://127.0.0.1:9"):
            evaluate_episodes(ctx, eps, "ws://127.0.0.1:9", EnvConfig(render=False), timeout=0.3,
                              agent_args={"retries": 1}, batch_slots=slots, max_connect_failures=3,
                              on_result=lambda row, frames: seen.append(row))
        assert time.perf_counter() - t0 < 10
        assert seen and all("unreachable" in r["error"] for r in seen)
        if slots == 1:
            assert len(seen) == 3  # stopped at the third failure in a row, not after all 8


def test_navarena_eval_keeps_what_finished_when_the_agent_server_is_gone(episode_run, tmp_path):
    """navarena eval against an agent server that is not there: exit 3 with one line naming its
    address, summary.json written with the episodes apart as errored and the reason it stopped."""
    import json
    import subprocess
    import sys

    out = tmp_path / "gone"
    p = subprocess.run([sys.executable, "-m", "navarena", "eval", str(episode_run[0]), "--agent", "ws://127.0.0.1:9",
                        "--agent-arg", "retries=1", "--timeout", "0.3", "--no-render", "--tasks", "pointnav",
                        "--episodes-per-scene", "5", "--out", str(out), "--quiet"], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 3, p.stderr[-2000:]
    assert "ws://127.0.0.1:9" in p.stderr and "Traceback" not in p.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped"] and summary["tasks"]["pointnav"]["overall"]["errored"] == 3
    assert summary["tasks"]["pointnav"]["overall"]["episodes"] == 0


def test_sigterm_stops_an_evaluation_and_keeps_the_finished_episodes(episode_run, tmp_path):
    """SIGTERM (a batch system's stop) ends navarena eval within seconds, as Ctrl-C does: the episodes
    that finished are written and marked interrupted."""
    import json
    import signal
    import subprocess
    import sys
    import time

    started = tmp_path / "second_episode_started"
    (tmp_path / "slow_agent.py").write_text(  # marks the start of its second episode: one has finished
        "import pathlib, time\n\nclass Slow:\n    episodes = 0\n\n    def __init__(self, **_):\n        pass\n\n"
        "    def reset(self, task):\n        self.t = 0\n        Slow.episodes += 1\n        if Slow.episodes == 2:\n"
        f"            pathlib.Path({str(started)!r}).touch()\n\n"
        "    def act(self, obs):\n        time.sleep(0.02)\n        self.t += 1\n        return 1 if self.t < 15 else 0\n")
    out = tmp_path / "term"
    p = subprocess.Popen([sys.executable, "-m", "navarena", "eval", str(episode_run[0]), "--agent", "slow_agent:Slow",
                          "--protocol", "explicit_stop", "--no-render", "--tasks", "pointnav", "--out", str(out),
                          "--quiet"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not started.exists() and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    assert started.exists() and p.poll() is None, p.communicate()[1][-2000:]
    t0 = time.perf_counter()
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 130, err[-2000:]
    assert time.perf_counter() - t0 < 10
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] and summary["episodes"] >= 1


def test_progress_time_left_counts_the_step_budgets_still_to_run():
    """With a budget, the time left is the unfinished episodes' step budgets at the frame rate so far,
    an upper bound that an episode running its whole budget cannot exceed."""
    import time

    from navcore.io.tool_progress import ToolProgress

    with ToolProgress("eval", 4, quiet=True, budget=4000) as p:
        time.sleep(0.05)
        p.advance(frames=100, budget=1000)  # an episode that stopped after 100 of its 1,000 steps
        rate = p.frames / (time.perf_counter() - p.t0)
        left = p.budget_left_s()
        assert left == pytest.approx(3000 / rate, rel=0.2)
    with ToolProgress("eval", 4, quiet=True) as q:
        assert q.budget_left_s() is None


@pytest.mark.parametrize("task", ["pointnav", "imagenav", "objectnav"])
def test_a_decoy_goal_is_another_goal_of_the_scene_and_the_agent_sees_it(episode_run, task):
    """--decoy-goal: each episode shown another goal of its scene and task (another category, another
    goal pose), the environment's goal observation and the agent's task are the decoy's, and the
    episode is still scored on its own goal."""
    import dataclasses

    from navcore.eval.dataset import NavDataset
    from navcore.eval.decoy import goal_key, with_decoys
    from navcore.eval.loop import task_info

    ds = NavDataset(episode_run[0])
    (sid,) = ds.scene_ids(task)
    pool = ds.episodes(sid, task)
    eps, none = with_decoys(pool[:4], pool)
    assert len(eps) == 4 and none == []
    ctx = ds.scene_context(sid, render=task == "imagenav", renderer="cpu")
    env = NavEnv(ctx, ds.env_config(width=64, height=48, render=task == "imagenav"))
    for ep in eps:
        d = ep.shown
        assert goal_key(d) != goal_key(ep) and d.scene_id == ep.scene_id and d in pool  # a goal this scene offers
        assert ctx.costmap.is_state_valid(*d.goal_xy) if task != "objectnav" else d.category in {e.category for e in pool}
        obs = env.reset(ep)
        true = NavEnv(ctx, env.cfg).reset(dataclasses.replace(ep, shown=None))
        if task == "objectnav":
            assert obs["goal_category"] == task_info(ep)["goal_category"] == d.category != ep.category
        elif task == "imagenav":
            seen = ctx.render(d.goal_pose[None], 64, 48)[0][0]
            assert np.array_equal(obs["goal_image"], seen) and not np.array_equal(obs["goal_image"], true["goal_image"])
        else:
            assert not np.allclose(obs["pointgoal"], true["pointgoal"])
        assert env.state.ep is ep and np.array_equal(env.state.ep.goal_xy, ep.goal_xy)  # scored on its own goal


def test_a_network_that_ignores_its_goal_has_no_goal_gain(episode_run, tmp_path):
    """A constructed ObjectNav network whose goal embedding is zero reads no goal: navarena eval with
    and without --decoy-goal gives it the same episodes, actions and SR (goal gain 0); the decoy run
    records which episode's goal each one was shown."""
    import json

    import pandas as pd
    import torch

    from navarena.evaluate import main
    from navcore.baselines.checkpoint import save_checkpoint
    from navcore.baselines.model import NavNet, NavSpec

    torch.manual_seed(0)
    net = NavNet(NavSpec(hidden=16, embed=16, task="objectnav"))
    with torch.no_grad():
        net.goal.weight.zero_()
    f = tmp_path / "blind.pt"
    save_checkpoint(f, "objectnav", net.spec.to_dict(), net.state_dict(), {})
    common = [str(episode_run[0]), "--agent", "learned", "--agent-arg", f"checkpoint={f}", "--tasks", "objectnav",
              "--episodes-per-scene", "2", "--renderer", "cpu", "--width", "64", "--height", "48", "--quiet"]
    assert main([*common, "--out", str(tmp_path / "true")]) == 0
    assert main([*common, "--decoy-goal", "--out", str(tmp_path / "decoy")]) == 0
    a, b = (pd.read_parquet(tmp_path / k / "results.parquet") for k in ("true", "decoy"))
    assert list(a["episode_id"]) == list(b["episode_id"]) and len(a) == 2
    assert (a["steps"].tolist(), a["sr"].tolist()) == (b["steps"].tolist(), b["sr"].tolist())
    assert (b["shown_goal_of"] != b["episode_id"]).all() and "shown_goal_of" not in a
    sa, sb = (json.loads((tmp_path / k / "summary.json").read_text()) for k in ("true", "decoy"))
    assert sb["decoy_goal"] is True and sa["decoy_goal"] is False
    assert sa["tasks"]["objectnav"]["overall"]["sr"] - sb["tasks"]["objectnav"]["overall"]["sr"] == 0


def test_distance_fields_are_shared_by_goal_set_not_by_episode(ctx, make_episode):
    """A scene's episodes share a few goal sets (an ObjectNav category, the goals PointNav episodes
    are drawn to): one Dijkstra search per goal set, the same field for every episode of it, whatever
    the episode's id or task; another goal set gets its own field, equal to the graph's search."""
    a = make_episode(goal=(3.0, 0.5))
    b = make_episode(goal=(3.0, 0.5), task="imagenav")
    c = make_episode(goal=(1.5, 0.5))
    assert ctx.field(a) is ctx.field(b)
    assert ctx.field(c) is not ctx.field(a)
    cells = ctx.costmap.cells_of(np.array([[1.5, 0.5]]))
    np.testing.assert_array_equal(ctx.field(c).node_dist, ctx.graph.field(cells).node_dist)
    n = len(ctx._fields)
    ctx.field(make_episode(goal=(3.0, 0.5), episode_id=a.episode_id))
    assert len(ctx._fields) == n  # a repeated goal set costs no search


def test_an_episode_looks_its_field_up_once_and_its_distances_are_the_fields(ctx, make_episode, monkeypatch):
    """Every step's info carries the distance to the goal: the episode asks the scene for its goal
    set's field once (the first call), and each distance is that field's value at the pose; the next
    episode asks again."""
    from navcore.nav.oracle import geodesic_potential

    real, asked = type(ctx).field, []
    monkeypatch.setattr(type(ctx), "field", lambda self, ep: asked.append(ep.episode_id) or real(self, ep))
    env = NavEnv(ctx, EnvConfig(render=False))
    a, b = make_episode(goal=(3.0, 0.5)), make_episode(goal=(0.5, 2.5))
    cm = ctx.costmap
    for ep in (a, b):
        env.reset(ep)
        for action in (TURN_LEFT, MOVE_FORWARD, TURN_RIGHT, MOVE_FORWARD):
            _, info = env.step(action)
            s = env.state
            want = geodesic_potential(real(ctx, ep).grid, cm.origin[0], cm.origin[1], cm.resolution, s.x, s.y)
            assert info["distance_to_goal"] == pytest.approx(float(want)) and not info["done"]
    assert asked == [a.episode_id, b.episode_id]
