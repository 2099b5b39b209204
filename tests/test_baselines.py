"""The learned baselines: navarena train (loss falls, one seed -> one checkpoint), checkpoints
(round trip; damaged, unsafe or foreign files refused), the shipped pointnav_bc (sha256-checked,
in-process and behind the agent server, better than depth_reactive), the model cards and docs."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from navcore.baselines.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from navcore.baselines.model import NavNet, NavSpec, depth_input, goal_input
from navcore.io.release import sha256_file

TINY = ["--rounds", "2", "--episodes-per-round", "6", "--grad-steps", "12", "--batch-episodes", "4", "--slots", "6",
        "--width", "32", "--height", "24", "--val-episodes", "0", "--renderer", "cpu", "--max-learner-steps", "40",
        "--quiet"]


@pytest.fixture(scope="module")
def trained(episode_run, tmp_path_factory):
    """Two tiny training runs with one seed on the session's data root (CPU renderer)."""
    from navarena.train import main

    root = episode_run[0]
    outs = [tmp_path_factory.mktemp(f"train{i}") for i in range(2)]
    for out in outs:
        assert main([str(root), "--out", str(out), *TINY]) == 0
    return outs


def test_tiny_training_loss_falls_and_one_seed_gives_one_checkpoint(trained):
    a, b = trained
    card = json.loads((a / "model_card.json").read_text())
    bc, dagger = card["curve"]
    assert (bc["kind"], dagger["kind"], dagger["beta"]) == ("bc", "dagger", 0.5)
    assert bc["loss"] < bc["loss_first"], bc  # behaviour cloning learns
    assert dagger["frames"] == bc["frames"] + dagger["new_frames"] > bc["frames"]  # DAgger aggregates
    assert (a / "model.pt").read_bytes() == (b / "model.pt").read_bytes()
    assert card["sha256"] == sha256_file(a / "model.pt")
    for r in ("round_0.npz", "round_1.npz"):
        assert (a / "rounds" / r).read_bytes() == (b / "rounds" / r).read_bytes()
    ck = load_checkpoint(a / "model.pt", kind="pointnav")
    assert ck["meta"]["seed"] == 0 and ck["meta"]["config"]["rounds"] == 2
    assert "collect_s" not in ck["meta"]["curve"][0]  # timings live in the card only


def test_init_fine_tunes_from_a_checkpoint(trained, episode_run, tmp_path, monkeypatch):
    """--init starts from a checkpoint's weights: a 1-round run from the trained tiny model begins
    at a lower loss than the same run from random weights, and its card records the checkpoint and
    its sha256; a checkpoint of another track, a missing file and an unknown shipped name are refused
    with the name in the message."""
    import navarena.train as train
    from navarena.train import main

    root, model = episode_run[0], trained[0] / "model.pt"
    args = [a for a in TINY if a not in ("--rounds", "2")] + ["--rounds", "1"]
    assert main([str(root), "--out", str(tmp_path / "fresh"), *args]) == 0
    reads = []
    read = train.init_checkpoint
    monkeypatch.setattr(train, "init_checkpoint", lambda *a: reads.append(a) or read(*a))
    assert main([str(root), "--out", str(tmp_path / "tuned"), *args, "--init", str(model)]) == 0
    assert len(reads) == 1  # the checkpoint is read once, for its network and its weights
    fresh, tuned = (json.loads((tmp_path / r / "model_card.json").read_text()) for r in ("fresh", "tuned"))
    assert tuned["curve"][0]["loss_first"] < fresh["curve"][0]["loss_first"]
    assert tuned["config"]["init"] == str(model) and tuned["config"]["init_sha256"] == sha256_file(model)
    assert "init_sha256" not in fresh["config"]
    assert tuned["data"]["groups"] == {"synthetic": len(tuned["data"]["train_scenes"])}  # the generator's scenes
    for bad, why in ((["--task", "objectnav"], "not 'objectnav'"), ([], "does not exist"), ([], "no shipped baseline")):
        init = {"does not exist": str(tmp_path / "none.pt"), "no shipped baseline": "no_such_bc"}.get(why, str(model))
        with pytest.raises(SystemExit, match=why):
            main([str(root), "--out", str(tmp_path / "bad"), *args, *bad, "--init", init])


def test_init_with_aux_goal_adds_the_head_to_the_checkpoints_network(episode_run, tmp_path):
    """--init of a network without the goal-position head plus --aux-goal: every weight of the
    checkpoint is loaded and the head is new; a checkpoint whose network differs otherwise is refused."""
    from navarena.train import main
    from navcore.baselines.train import TrainConfig, Trainer, init_checkpoint

    torch.manual_seed(1)
    plain = NavNet(NavSpec(task="objectnav"))
    f = tmp_path / "plain.pt"
    save_checkpoint(f, "objectnav", plain.spec.to_dict(), plain.state_dict(), {})
    cfg = TrainConfig(task="objectnav", init=str(f), spec=NavSpec(task="objectnav", aux_goal=True), renderer="cpu")
    tr = Trainer(episode_run[0], tmp_path / "run", cfg, quiet=True, init=init_checkpoint(str(f), "objectnav"))
    got = tr.net.state_dict()
    assert all(torch.equal(got[k], v) for k, v in plain.state_dict().items()) and "aux.weight" in got
    args = [str(episode_run[0]), "--out", str(tmp_path / "tuned"), "--task", "objectnav", *TINY, "--rounds", "1",
            "--init", str(f), "--aux-goal"]
    assert main(args) == 0
    card = json.loads((tmp_path / "tuned" / "model_card.json").read_text())
    assert card["config"]["spec"]["aux_goal"] and card["config"]["init_sha256"] == sha256_file(f)
    assert "aux_loss" in card["curve"][0]
    other = NavNet(NavSpec(task="objectnav", hidden=32))
    g = tmp_path / "other.pt"
    save_checkpoint(g, "objectnav", other.spec.to_dict(), other.state_dict(), {})
    bad = TrainConfig(task="objectnav", init=str(g), spec=NavSpec(task="objectnav", aux_goal=True), renderer="cpu")
    with pytest.raises(SystemExit, match="is not this run's"):
        Trainer(episode_run[0], tmp_path / "bad", bad, quiet=True, init=init_checkpoint(str(g), "objectnav"))


def test_a_fine_tune_can_begin_with_a_dagger_round(trained, episode_run, tmp_path):
    """--first-round dagger: round 0 is a DAgger round driven by the --init network (beta^1), so its
    rollouts are not the expert's (the behaviour-cloning round 0 of the same run is); it needs --init."""
    from navarena.train import main

    root, model = episode_run[0], trained[0] / "model.pt"
    args = [a for a in TINY if a not in ("--rounds", "2")] + ["--rounds", "1", "--init", str(model)]
    assert main([str(root), "--out", str(tmp_path / "bc"), *args]) == 0
    assert main([str(root), "--out", str(tmp_path / "dg"), *args, "--first-round", "dagger"]) == 0
    bc, dg = (json.loads((tmp_path / r / "model_card.json").read_text()) for r in ("bc", "dg"))
    assert (bc["curve"][0]["kind"], bc["curve"][0]["beta"]) == ("bc", 1.0)
    assert (dg["curve"][0]["kind"], dg["curve"][0]["beta"]) == ("dagger", 0.5)
    assert dg["config"]["first_round"] == "dagger"
    za, zb = (np.load(tmp_path / r / "rounds" / "round_0.npz") for r in ("bc", "dg"))
    assert not np.array_equal(za["prev"], zb["prev"])  # the learner drove some of round 0's steps
    with pytest.raises(SystemExit, match="needs --init"):
        main([str(root), "--out", str(tmp_path / "bad"), *TINY, "--first-round", "dagger"])


def test_a_card_trained_on_real_captures_says_so():
    """A card whose training scenes include real captures (a catalog group other than the generator's)
    does not claim to be trained on generated scenes alone, and names the groups and the fine-tuning."""
    from navcore.baselines.card import licence_line, real_note

    card = {"licence": "Apache-2.0", "config": {"init": "pointnav_bc"}, "data": {"groups": {"real_indoor": 2}}}
    line = licence_line(card)
    assert "2 of group `real_indoor`" in line and "generated scenes (Apache-2.0)" not in line
    assert "Fine-tuned from `pointnav_bc`" in line and "real captures" in real_note(card)
    plain = {"licence": "Apache-2.0", "config": {}, "data": {"groups": {"synthetic": 3}}}
    assert "no third-party data" in licence_line(plain) and "generated scenes only" in real_note(plain)


def test_a_card_without_held_out_checks_says_its_file_is_the_last_round():
    """A run with --val-episodes 0 ran no check: its card names no check split and does not call the
    kept round the best checked one."""
    from navcore.baselines.card import kept

    curve = [{"round": 0}, {"round": 1}]
    assert kept({"config": {"keep": "best"}, "curve": curve, "selected_round": 1}) == \
        " The file holds round 1's weights (the last round: no held-out check ran)."
    checked = [{"round": 0, "val_sr": 0.5, "val_spl": 0.4}, {"round": 1, "val_sr": 0.2, "val_spl": 0.1}]
    assert "(the best held-out check)" in kept({"config": {"keep": "best"}, "curve": checked, "selected_round": 0})


@pytest.mark.parametrize("keep", ["best", "last"])
def test_model_keeps_the_best_checked_round(keep, episode_run, tmp_path, monkeypatch):
    """A DAgger round can be worse than the one before: with keep=best the final model.pt holds the
    round with the best held-out check (here round 0, scripted: SR 0.5 then 0.25), with keep=last
    the last round's; the network state a resumed run goes on from is the last round's either way."""
    from navarena.train import main
    from navcore.baselines.train import TrainConfig, Trainer

    checks = iter([{"episodes": 4, "sr": 0.5, "spl": 0.4}, {"episodes": 4, "sr": 0.25, "spl": 0.2}])
    monkeypatch.setattr(Trainer, "evaluate", lambda self, *a, **k: next(checks))
    args = [a for a in TINY if a not in ("--val-episodes", "0")]
    assert main([str(episode_run[0]), "--out", str(tmp_path), *args, "--val-episodes", "4", "--val-split", "train",
                 "--keep", keep]) == 0
    card = json.loads((tmp_path / "model_card.json").read_text())
    assert [e["val_sr"] for e in card["curve"]] == [0.5, 0.25]
    assert card["selected_round"] == (0 if keep == "best" else 1)
    final = load_checkpoint(tmp_path / "model.pt", kind="pointnav")["state_dict"]
    best = torch.load(tmp_path / "rounds" / "best.pt", weights_only=True)
    last = torch.load(tmp_path / "checkpoint.pt", weights_only=True)["net"]
    same = lambda a, b: all(torch.equal(a[k], b[k]) for k in a)  # noqa: E731
    assert same(final, best if keep == "best" else last) and not same(best, last)
    assert TrainConfig(keep=keep).keep == keep
    with pytest.raises(ValueError, match="keep"):
        TrainConfig(keep="first")


def test_objectnav_check_also_measures_stop_sr(episode_run, tmp_path, monkeypatch):
    """ObjectNav's held-out check after a round runs under distance and explicit_stop (scripted here:
    SR 0.5 and Stop SR 0.25); the card's curve and its table carry both. The check passes its
    protocol on: a policy that always stops ends each explicit_stop episode at its first step."""
    from navarena.train import main
    from navcore.baselines.card import curve_table
    from navcore.baselines.checkpoint import save_checkpoint
    from navcore.baselines.train import Collector, TrainConfig, Trainer
    from navcore.eval.dataset import NavDataset

    calls = []

    def check(self, model, sha, split, n, width=None, height=None, protocol="distance"):
        calls.append(protocol)
        return {"episodes": n, "sr": 0.5 if protocol == "distance" else 0.25, "spl": 0.4}

    monkeypatch.setattr(Trainer, "evaluate", check)
    args = [a for a in TINY if a not in ("--val-episodes", "0", "--rounds", "2")]
    assert main([str(episode_run[0]), "--out", str(tmp_path / "run"), *args, "--rounds", "1", "--task", "objectnav",
                 "--val-episodes", "2", "--val-split", "train", "--episodes-per-round", "2", "--max-learner-steps", "10",
                 "--grad-steps", "2"]) == 0
    card = json.loads((tmp_path / "run" / "model_card.json").read_text())
    assert calls == ["distance", "explicit_stop"]
    assert (card["curve"][0]["val_sr"], card["curve"][0]["val_stop_sr"]) == (0.5, 0.25)
    assert "| val Stop SR |" in curve_table(card) and "| 0.250 |" in curve_table(card)

    cfg = TrainConfig(task="pointnav", slots=2, width=32, height=24, renderer="cpu")
    col = Collector(episode_run[0], cfg, "cpu")
    state = {k: v.clone() for k, v in col.net.state_dict().items()}
    state["head.weight"].zero_()
    state["head.bias"].copy_(torch.tensor([10.0, 0.0, 0.0, 0.0]))  # STOP, whatever it sees
    sha = save_checkpoint(tmp_path / "stop.pt", "pointnav", cfg.spec.to_dict(), state, {})
    sid = NavDataset(episode_run[0]).scene_ids("pointnav")[0]
    rows = col.check((sid, "train", 2, str(tmp_path / "stop.pt"), sha, 32, 24, "explicit_stop"))
    assert len(rows) == 2 and all(r["steps"] == 1 and r["end_reason"] == "stop" for r in rows)


def test_objectnav_keeps_the_round_that_also_stops(episode_run, tmp_path, monkeypatch):
    """ObjectNav's --keep best ranks a round by the mean of its check's SR and Stop SR (check_score),
    not SR alone: scripted, round 0 reads SR 0.5 and Stop SR 0.1 (mean 0.3), round 1 0.4 and 0.3
    (mean 0.35), and round 1 is kept, where SR alone would keep round 0. Other tracks rank by SR."""
    from navarena.train import main
    from navcore.baselines.train import Trainer, check_score

    checks = iter([{"episodes": 2, "sr": 0.5, "spl": 0.4}, {"episodes": 2, "sr": 0.1, "spl": 0.1},
                   {"episodes": 2, "sr": 0.4, "spl": 0.3}, {"episodes": 2, "sr": 0.3, "spl": 0.3}])
    monkeypatch.setattr(Trainer, "evaluate", lambda self, *a, **k: next(checks))
    args = [a for a in TINY if a not in ("--val-episodes", "0", "--rounds", "2")]
    assert main([str(episode_run[0]), "--out", str(tmp_path / "run"), *args, "--rounds", "2", "--task", "objectnav",
                 "--val-episodes", "2", "--val-split", "train", "--episodes-per-round", "2", "--max-learner-steps", "10",
                 "--grad-steps", "2"]) == 0
    card = json.loads((tmp_path / "run" / "model_card.json").read_text())
    assert [(e["val_sr"], e["val_stop_sr"]) for e in card["curve"]] == [(0.5, 0.1), (0.4, 0.3)]
    assert card["selected_round"] == 1
    assert check_score({"val_sr": 0.5, "val_spl": 0.4}) == (0.5, 0.4)
    assert check_score({"val_sr": 0.5, "val_stop_sr": 0.1, "val_spl": 0.4}) == (0.3, 0.4)


def test_collection_workers_give_the_same_run_and_check(episode_run, tmp_path):
    """Collection and the held-out check spread over worker processes (one scene each) give the
    same checkpoint and the same check as this process alone."""
    from navarena.train import main

    one = ["--rounds", "1", *TINY[2:]]
    one[one.index("--val-episodes") + 1] = "4"
    one += ["--val-split", "train"]  # the session root holds no held-out scene
    runs = []
    for workers in (0, 2):
        out = tmp_path / f"w{workers}"
        assert main([str(episode_run[0]), "--out", str(out), "--workers", str(workers), *one]) == 0
        runs.append((out / "model.pt").read_bytes())
        curve = json.loads((out / "model_card.json").read_text())["curve"][0]
        runs.append({k: curve[k] for k in ("val_split", "val_episodes", "val_sr", "val_spl")})
    assert runs[1]["val_episodes"] >= 1
    assert runs[0] == runs[2] and runs[1] == runs[3], runs[1::2]


@pytest.mark.parametrize("task", ["imagenav", "objectnav"])
def test_tiny_training_of_the_other_tracks(task, episode_run, tmp_path):
    """ImageNav (RGB-D + the goal image; here FiLM-conditioned ResNet-9) and ObjectNav (RGB-D + the goal
    category, FiLM-conditioned, on the frozen pretrained EfficientNet-Lite0): the loss falls, the checkpoint
    is of the track and its agent acts on the track's observations; both
    are labelled by the searching expert, and the card names it (auto resolved)."""
    from navarena.train import main
    from navcore.eval.dataset import NavDataset
    from navcore.eval.loop import InProcessBatch, run_episodes_batched

    root = episode_run[0]
    extra = ["--aux-goal", "--film"]  # the goal-position head and the goal's FiLM, options of both tracks
    if task == "imagenav":  # and the ResNet-9 at a small input
        extra += ["--encoder", "resnet", "--input", "32", "24"]
    else:  # and the frozen pretrained encoder
        extra += ["--encoder", "effnet_lite0", "--input", "64", "48"]
    assert main([str(root), "--out", str(tmp_path), "--task", task, *TINY, *extra]) == 0
    card = json.loads((tmp_path / "model_card.json").read_text())
    assert card["task"] == task and card["curve"][0]["loss"] < card["curve"][0]["loss_first"]
    ck = load_checkpoint(tmp_path / "model.pt", kind=task)
    assert NavSpec(**ck["spec"]).task == task
    z = np.load(tmp_path / "rounds" / "round_0.npz")
    assert z["obs"].shape[1] == 4 and z["seq_goal"].shape[1] == (3 if task == "imagenav" else 0)
    assert card["config"]["expert"] == "search" and ck["spec"].get("rgbd", False) == (task == "imagenav")
    assert card["config"]["view_overlap"] == 0.5  # ImageNav's found criterion, recorded
    aux = z["aux"]
    assert aux.shape == (len(z["label"]), 3)
    # the goal-position head's targets: goal_input's encoding, on every step
    assert np.isfinite(aux).all() and np.allclose(aux[:, 1] ** 2 + aux[:, 2] ** 2, 1, atol=1e-5)
    assert ck["spec"]["aux_goal"] and {"aux_loss_first", "aux_loss"} <= set(card["curve"][0])
    assert ck["spec"]["film"] and ck["spec"]["encoder"] == ("resnet" if task == "imagenav" else "effnet_lite0")
    if task == "objectnav":  # the nearest success region: the expert stops within the success radius of one
        from navcore.eval.dataset import NavDataset

        radius = max(e.success_radius for sid in NavDataset(root).scene_ids(task)
                     for e in NavDataset(root).episodes(sid, task, "train"))
        ends = np.cumsum(z["lengths"]) - 1
        stops = ends[z["label"][ends] == 0]
        assert len(stops) and (aux[stops, 0] <= np.log1p(radius) + 1e-6).all() and (aux[:, 0] > np.log1p(radius)).any()
    ds = NavDataset(root)
    sid = next(s for s in ds.scene_ids(task) if len(ds.episodes(s, task, None)))
    eps = ds.episodes(sid, task, None)[:2]
    cfg = ds.env_config(protocol="explicit_stop", width=32, height=24)
    ctx = ds.scene_context(sid, renderer="cpu")
    from navcore.eval.agents import agent_for

    rows = run_episodes_batched(ctx, eps, InProcessBatch(lambda: agent_for("learned", checkpoint=str(tmp_path / "model.pt"),
                                                                           device="cpu")), 2, cfg)
    assert len(rows) == 2 and not any(r["error"] for r in rows), rows
    if task == "objectnav":  # the searching expert: longer episodes than the oracle's
        assert main([str(root), "--out", str(tmp_path / "geo"), "--task", task, *TINY, "--rounds", "1",
                     "--expert", "geodesic"]) == 0
        geo = np.load(tmp_path / "geo" / "rounds" / "round_0.npz")
        assert z["lengths"].sum() > geo["lengths"].sum(), \
            (z["lengths"], geo["lengths"])
        from navcore.baselines.card import card_markdown  # the card names the expert that labelled it

        geo_card = json.loads((tmp_path / "geo" / "model_card.json").read_text())
        assert "labelled by the searching expert" in card_markdown(card, shipped=False)
        assert "labelled by the geodesic oracle)" in card_markdown(geo_card, shipped=False)


@pytest.mark.parametrize("veto", [True, False])
def test_a_learners_false_stop_is_labelled_and_the_expert_goes_on(veto, episode_run):
    """DAgger with a learner that always stops (beta 0): without the veto each episode ends at its
    first step, labelled with the expert's move; with it the expert's moves are executed instead,
    so the episodes go on and every one of the learner's false stops is labelled."""
    from navcore.baselines.train import Collector, TrainConfig
    from navcore.eval.dataset import NavDataset
    from navcore.nav.actions import STOP

    root = episode_run[0]
    cfg = TrainConfig(task="pointnav", slots=3, width=32, height=24, renderer="cpu", max_learner_steps=12,
                      stop_veto=veto)
    col = Collector(root, cfg, "cpu")
    with torch.no_grad():
        col.net.head.weight.zero_()
        col.net.head.bias.copy_(torch.tensor([10.0, 0.0, 0.0, 0.0]))  # STOP, whatever it sees
    ds = NavDataset(root)
    sid = ds.scene_ids("pointnav")[0]
    eps = [e for e in ds.episodes(sid, "pointnav", "train") if e.geodesic > 1.0][:3]
    steps = col.rollouts(sid, eps, 0.0, np.random.default_rng(0))
    assert len(steps.lengths) == len(eps) and STOP not in set(steps.label[steps.starts].tolist())
    if veto:
        assert (steps.lengths > 4).all()
        executed = np.concatenate([steps.prev[a + 1:a + n] for a, n in zip(steps.starts, steps.lengths)])
        assert STOP not in set(executed.tolist())  # the learner's stops were never executed
    else:
        assert (steps.lengths == 1).all()


def test_resume_after_the_last_round_changes_nothing(trained, episode_run, tmp_path):
    import shutil

    from navarena.train import main

    out = tmp_path / "resumed"
    shutil.copytree(trained[0], out)
    before = (out / "model.pt").read_bytes()
    assert main([str(episode_run[0]), "--out", str(out), "--resume", *TINY]) == 0
    assert (out / "model.pt").read_bytes() == before


def test_a_sampling_agent_draws_moves_by_the_policy_and_stops_only_when_stop_leads(tmp_path):
    """sample=true: moves drawn in the network's proportions (known logits), STOP only when it is the
    argmax, the same seed and episode give the same actions; the greedy agent takes the argmax every
    time; stop_threshold moves the STOP decision to a probability."""
    from navcore.baselines.agent import LearnedNavAgent

    net = NavNet(NavSpec(hidden=16, embed=16))
    f = tmp_path / "p.pt"
    save_checkpoint(f, "pointnav", net.spec.to_dict(), net.state_dict(), {})
    logits = torch.log(torch.tensor([[0.1, 0.5, 0.3, 0.1]]))  # STOP, FORWARD, LEFT, RIGHT

    def agents(sample, seed=7, **kw):
        a = LearnedNavAgent(checkpoint=str(f), device="cpu", sample=sample, seed=seed, **kw)
        a.net.step = lambda frames, goal, prev, h: (logits.expand(len(prev), 4), h)
        a.reset({"episode_id": 3})
        return a

    obs = {"depth": np.full((24, 32), 2.0, np.float32), "pointgoal": np.array([2.0, 0.1], np.float32)}
    a = agents(True)
    drawn = np.array([a.act(obs) for _ in range(6000)])
    freq = np.bincount(drawn, minlength=4) / len(drawn)
    assert freq[0] == 0 and np.allclose(freq[1:], [0.5 / 0.9, 0.3 / 0.9, 0.1 / 0.9], atol=0.02), freq
    b = agents(True)
    assert [b.act(obs) for _ in range(50)] == drawn[:50].tolist()  # seeded by (seed, episode)
    c = agents(True, seed=8)
    assert [c.act(obs) for _ in range(50)] != drawn[:50].tolist()
    greedy = agents(False)
    assert {greedy.act(obs) for _ in range(50)} == {1}
    logits = torch.log(torch.tensor([[0.4, 0.3, 0.2, 0.1]]))  # STOP leads: a sampling agent stops too
    assert agents(True).act(obs) == 0
    # stop_threshold: STOP at p(STOP) >= it, else the most likely move (0.4 < 0.5: FORWARD; 0.4 >= 0.3: STOP)
    assert agents(False, stop_threshold=0.5).act(obs) == 1 and agents(False, stop_threshold=0.3).act(obs) == 0
    logits = torch.log(torch.tensor([[0.35, 0.4, 0.2, 0.05]]))
    assert agents(False).act(obs) == 1 and agents(False, stop_threshold=0.35).act(obs) == 0
    with pytest.raises(ValueError, match="stop_threshold=1.5"):
        agents(False, stop_threshold=1.5)
    with pytest.raises(ValueError, match="sample='yes'"):
        LearnedNavAgent(checkpoint=str(f), device="cpu", sample="yes")


def test_the_stop_gate_vetoes_a_stop_where_the_goal_head_puts_the_goal_far(tmp_path):
    """stop_gate (metres): an aux_goal network's STOP is taken only where its goal-position head puts the
    goal within the gate, else its most likely move; a network without the head is refused."""
    from navcore.baselines.agent import LearnedNavAgent

    net = NavNet(NavSpec(task="objectnav", hidden=16, embed=16, aux_goal=True))
    with torch.no_grad():
        net.head.weight.zero_()
        net.head.bias.copy_(torch.tensor([3.0, 1.0, 0.5, 0.0]))  # STOP leads, then FORWARD
        net.aux.weight.zero_()

    def agent(distance_m, **kw):
        with torch.no_grad():
            net.aux.bias.copy_(torch.tensor([math.log1p(distance_m), 1.0, 0.0]))  # goal_input's encoding
        f = tmp_path / f"o{distance_m}.pt"
        save_checkpoint(f, "objectnav", net.spec.to_dict(), net.state_dict(), {})
        a = LearnedNavAgent(checkpoint=str(f), device="cpu", **kw)
        a.reset({"episode_id": 1})
        return a

    obs = {"depth": np.full((48, 64), 2.0, np.float32), "rgb": np.zeros((48, 64, 3), np.uint8), "goal_category": "chair"}
    assert agent(4.0).act(obs) == 0  # no gate: the argmax, STOP
    assert agent(4.0, stop_gate=1.0).act(obs) == 1  # the head says 4 m: FORWARD instead
    assert agent(0.5, stop_gate=1.0).act(obs) == 0  # within the gate: STOP
    assert agent(4.0, stop_gate=1.0, sample=True).act(obs) != 0  # a sampled move, never STOP
    plain = NavNet(NavSpec(task="objectnav", hidden=16, embed=16))
    f = tmp_path / "plain.pt"
    save_checkpoint(f, "objectnav", plain.spec.to_dict(), plain.state_dict(), {})
    with pytest.raises(ValueError, match="goal-position head"):
        LearnedNavAgent(checkpoint=str(f), device="cpu", stop_gate=1.0)
    with pytest.raises(ValueError, match="stop_gate=-1"):
        agent(1.0, stop_gate=-1)


def test_checkpoint_round_trip_and_refusals(tmp_path):
    torch.manual_seed(0)
    net = NavNet(NavSpec(hidden=16, embed=16))
    f = tmp_path / "p.pt"
    digest = save_checkpoint(f, "pointnav", net.spec.to_dict(), net.state_dict(), {"seed": 3})
    assert digest == sha256_file(f)
    ck = load_checkpoint(f, kind="pointnav", sha256=digest)
    again = NavNet(NavSpec(**ck["spec"]))
    again.load_state_dict(ck["state_dict"])
    for (k, v), w in zip(net.state_dict().items(), again.state_dict().values()):
        assert torch.equal(v, w), k
    with pytest.raises(CheckpointError, match="a 'pointnav' policy, not 'imagenav'"):
        load_checkpoint(f, kind="imagenav")
    with pytest.raises(CheckpointError, match="sha256 .* differs"):
        load_checkpoint(f, sha256="0" * 64)
    damaged = tmp_path / "damaged.pt"
    data = bytearray(f.read_bytes())
    damaged.write_bytes(bytes(data[: len(data) // 2]))
    with pytest.raises(CheckpointError, match=r"damaged\.pt: is damaged or not a torch file"):
        load_checkpoint(damaged)

    class Payload:  # pickled code: weights_only refuses it
        def __reduce__(self):
            return (print, ("this must never run",))

    unsafe = tmp_path / "unsafe.pt"
    torch.save({"format": "navarena-policy/1", "kind": "pointnav", "spec": {}, "state_dict": {}, "x": Payload()}, unsafe)
    with pytest.raises(CheckpointError, match="holds objects other than plain data"):
        load_checkpoint(unsafe)
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(2)}, foreign)
    with pytest.raises(CheckpointError, match="not a NavArena policy checkpoint"):
        load_checkpoint(foreign)
    with pytest.raises(FileNotFoundError):
        load_checkpoint(tmp_path / "missing.pt")


def test_inputs_are_resolution_independent():
    spec = NavSpec()
    rng = np.random.default_rng(0)
    coarse = rng.uniform(0.3, 8.0, (48, 64)).astype(np.float32)
    coarse[0, :5] = 0.0  # nothing hit reads as the far limit
    fine = np.kron(coarse, np.ones((10, 10), np.float32))  # the same scene at 640 x 480
    a, b = depth_input(coarse, spec), depth_input(fine, spec)
    assert a.shape == b.shape == (1, 1, 48, 64)
    assert torch.allclose(a, b, atol=1e-6)
    assert float(a.max()) == 1.0 and float(a[0, 0, 0, 0]) == 1.0
    g = goal_input([[2.0, np.pi / 2]])
    assert torch.allclose(g, torch.tensor([[np.log1p(2.0), 0.0, 1.0]], dtype=torch.float32), atol=1e-6)


def test_imagenav_specs_from_before_depth_keep_their_network():
    """A spec written before `rgbd` (the first ImageNav network: RGB + goal image, 6 channels) loads
    as that network, and writes the same dict back; the RGB-D one reads depth first."""
    from navcore.baselines.model import NavNet, observation_input

    old = NavSpec(task="imagenav")
    assert "rgbd" not in old.to_dict() and NavSpec(**old.to_dict()) == old
    assert NavNet(old).cnn[0].in_channels == 6
    new = NavSpec(task="imagenav", rgbd=True)
    assert NavSpec(**new.to_dict()) == new and NavNet(new).cnn[0].in_channels == 7
    assert not hasattr(NavNet(new), "aux") and "aux_goal" not in new.to_dict()
    aux = NavSpec(task="imagenav", rgbd=True, aux_goal=True)
    assert NavSpec(**aux.to_dict()) == aux and NavNet(aux).aux.out_features == 3
    t = torch.zeros(2, 1, 7, 48, 64)
    logits, _, pred = NavNet(aux)(t, torch.zeros(2, 1, 0), torch.zeros(2, 1, dtype=torch.long), aux=True)
    assert logits.shape == (2, 1, 4) and pred.shape == (2, 1, 3)
    obs = {"depth": np.full((24, 32), 2.5, np.float32), "rgb": np.full((24, 32, 3), 51, np.uint8),
           "goal_image": np.full((24, 32, 3), 255, np.uint8)}
    frames, goal = observation_input([obs], new, "cpu")
    assert frames.shape == (1, 7, 48, 64) and goal.shape == (1, 0)
    assert torch.allclose(frames[0, :, 0, 0], torch.tensor([0.5, 0.2, 0.2, 0.2, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="rgbd applies to the imagenav network"):
        NavSpec(task="pointnav", rgbd=True)
    with pytest.raises(ValueError, match="aux_goal applies to the imagenav and objectnav networks"):
        NavSpec(task="pointnav", aux_goal=True)
    assert NavNet(NavSpec(task="objectnav", aux_goal=True)).aux.out_features == 3


def test_the_goal_in_the_robot_frame_and_rounds_saved_before_the_aux_target(tmp_path):
    """goal_in_robot_frame on known poses; a round file without `aux` (saved before it) loads with
    NaN targets, which the aux loss skips."""
    from navcore.baselines.model import goal_input
    from navcore.baselines.train import Steps, goal_polar
    from navcore.nav.poses import goal_in_robot_frame

    assert np.allclose(goal_in_robot_frame(1.0, 1.0, np.pi / 2, (1.0, 3.0)), (2.0, 0.0))   # straight ahead
    assert np.allclose(goal_in_robot_frame(1.0, 1.0, np.pi / 2, (0.0, 1.0)), (0.0, 1.0))   # to the left
    assert np.allclose(goal_in_robot_frame(0.0, 0.0, 0.0, (-2.0, 0.0)), (-2.0, 0.0))       # behind

    class Ep:
        goal_xy = (0.0, 3.0)
    assert np.allclose(goal_input(goal_polar(0.0, 0.0, 0.0, Ep)), [[np.log1p(3.0), 0.0, 1.0]], atol=1e-6)  # 3 m on the left

    class Obj:  # ObjectNav: the nearest point of the nearest success region, not goal_xy
        goal_xy, category = (9.0, 9.0), "chair"
        regions = np.array([[2.0, -1.0, 3.0, 1.0], [-1.0, -6.0, 1.0, -4.0]])  # boxes 2 m ahead, 4 m to the right
    assert np.allclose(goal_polar(0.0, 0.0, 0.0, Obj), (2.0, 0.0))
    assert np.allclose(goal_polar(0.0, -3.0, 0.0, Obj), (1.0, -np.pi / 2))  # now the other box is nearer
    assert np.allclose(goal_polar(2.5, 0.5, 1.0, Obj)[0], 0.0)  # inside a footprint
    assert np.isnan(goal_input([np.nan, np.nan]).numpy()).all()  # a step without a target stays NaN
    f = tmp_path / "round_0.npz"
    old = {"obs": np.zeros((5, 4, 2, 2), np.uint8), "goal": np.zeros((5, 0), np.float32), "prev": np.zeros(5, np.int8),
           "label": np.ones(5, np.int8), "lengths": np.array([2, 3]), "seq_goal": np.zeros((2, 3, 2, 2), np.uint8)}
    np.savez(f, **old)
    steps = Steps.load(f)
    assert steps.aux.shape == (5, 3) and np.isnan(steps.aux).all()
    steps.save(tmp_path / "again.npz")
    assert np.isnan(Steps.load(tmp_path / "again.npz").aux).all()


SHIPPED_OBS = {  # an observation of each shipped track at 160 x 120
    "pointnav_bc": {"depth": np.full((120, 160), 3.0, np.float32), "pointgoal": np.array([2.0, 0.0], np.float32)},
    "objectnav_bc": {"depth": np.full((120, 160), 3.0, np.float32), "rgb": np.full((120, 160, 3), 128, np.uint8),
                     "goal_category": "chair"},
    "imagenav_bc": {"depth": np.full((120, 160), 3.0, np.float32), "rgb": np.full((120, 160, 3), 128, np.uint8),
                    "goal_image": np.full((120, 160, 3), 90, np.uint8)},
}


@pytest.mark.parametrize("name", sorted(SHIPPED_OBS))
def test_shipped_baseline_is_checked_and_registered(name):
    from navcore.baselines.agent import shipped
    from navcore.eval.agents import AGENTS, agent_for

    path, digest = shipped(name)
    assert sha256_file(path) == digest
    assert name in AGENTS
    agent = agent_for(name, device="cpu")
    assert agent.task == name.removesuffix("_bc")  # the registry name loads its own track's network
    agent.reset({"task_type": agent.task})
    obs = SHIPPED_OBS[name]
    assert agent.act(obs) in (0, 1, 2, 3)
    with pytest.raises(ValueError, match="needs the observations"):
        agent.act({k: v for k, v in obs.items() if k != "depth"})


def test_a_shipped_baseline_decodes_as_its_card_says(tmp_path):
    """The registry name uses the decoding the card's figures were measured with (imagenav_bc samples,
    pointnav_bc and objectnav_bc act greedily); `sample` given overrides it; a checkpoint file is greedy
    unless told; the card says which."""
    from navcore.baselines.agent import LearnedNavAgent, shipped
    from navcore.baselines.card import card_markdown, cards
    from navcore.eval.agents import agent_for

    decoding = {name: bool(c.get("decoding", {}).get("sample")) for name, c in cards().items()}
    assert decoding == {"pointnav_bc": False, "objectnav_bc": False, "imagenav_bc": True}
    for name, sample in decoding.items():
        assert agent_for(name, device="cpu").sample is sample
        assert agent_for(name, device="cpu", sample=not sample).sample is (not sample)
        text = card_markdown(cards()[name])
        assert ("**Decoding:** sampled" in text) is sample and ("**Decoding:** greedy" in text) is (not sample)
    assert LearnedNavAgent(checkpoint=str(shipped("imagenav_bc")[0]), device="cpu").sample is False


def test_every_shipped_baseline_has_a_registry_name():
    from navcore.baselines.card import cards
    from navcore.eval.agents import AGENTS

    shipped = set(cards())
    assert shipped == set(SHIPPED_OBS), "a shipped baseline without a test observation here, or one gone"
    assert shipped == {k for k in AGENTS if k.endswith("_bc")}


def test_shipped_pointnav_baseline_beats_depth_reactive(episode_run):
    """Fixed PointNav episodes of the session's generated scene, CPU renderer: the learned policy
    reaches more goals than the hand-written depth_reactive (the same budget for both)."""
    from navcore.eval.agents import agent_for
    from navcore.eval.dataset import NavDataset
    from navcore.eval.loop import InProcessBatch, run_episodes_batched

    ds = NavDataset(episode_run[0])
    sid = ds.scene_ids("pointnav")[0]
    eps = ds.episodes(sid, "pointnav")[:8]
    for e in eps:
        e.max_steps = min(e.max_steps, 100)
    ctx = ds.scene_context(sid, renderer="cpu")
    cfg = ds.env_config(width=96, height=72)
    wins = {}
    for name in ("pointnav_bc", "depth_reactive"):
        rows = run_episodes_batched(ctx, eps, InProcessBatch(lambda name=name: agent_for(name, device="cpu")),
                                    len(eps), cfg)
        wins[name] = sum(r["sr"] for r in rows)
    assert wins["pointnav_bc"] > wins["depth_reactive"], wins


@pytest.mark.parametrize("name,task", [("pointnav_bc", "pointnav"), ("imagenav_bc", "imagenav")])
def test_learned_agents_read_the_renderers_frames_in_place_with_the_same_actions(episode_run, name, task):
    """The batched evaluator hands a learned policy its frames (and ImageNav's goal images) as the
    renderer's tensors, not host copies (the round trip that held a learned policy at a few hundred
    steps/s at 640 x 480); the episodes' results are those of the host-copy path, action for action."""
    import torch

    from navcore.baselines.agent import LearnedNavAgent
    from navcore.eval.agents import agent_for
    from navcore.eval.dataset import NavDataset
    from navcore.eval.loop import InProcessBatch, run_episodes_batched

    ds = NavDataset(episode_run[0])
    sid = ds.scene_ids(task)[0]
    eps = ds.episodes(sid, task)[:4]
    for e in eps:
        e.max_steps = min(e.max_steps, 25)
    ctx = ds.scene_context(sid, renderer="cpu")
    cfg = ds.env_config(width=64, height=48)
    seen, act_batch = [], LearnedNavAgent.act_batch.__func__

    def spy(cls, agents, observations):
        seen.extend(type(o[k]) for o in observations for k in ("rgb", "depth", "goal_image") if k in o)
        return act_batch(cls, agents, observations)

    rows = {}
    for on_device in (True, False):
        seen.clear()
        client = InProcessBatch(lambda: agent_for(name, device="cpu"))
        assert client.device_frames
        client.device_frames = on_device
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(LearnedNavAgent, "act_batch", classmethod(spy))
            rows[on_device] = run_episodes_batched(ctx, eps, client, 3, cfg)
        assert seen and set(seen) == ({torch.Tensor} if on_device else {np.ndarray})
    assert not InProcessBatch(lambda: agent_for("depth_reactive")).device_frames  # numpy for every other agent
    for a, b in zip(rows[True], rows[False], strict=True):
        assert np.array_equal(a.pop("trajectory"), b.pop("trajectory"))
        a.pop("seconds"), b.pop("seconds")
        assert a == b


def test_model_cards_and_docs_are_generated_from_the_cards():
    from benchmarks.baselines.evaluation_page import write_docs
    from navcore.baselines.card import cards

    assert "pointnav_bc" in cards()
    assert write_docs(check=True) == [], "run python -m benchmarks.baselines.evaluation_page docs"


def test_a_trial_is_recorded_without_weights_and_not_registered(trained, tmp_path):
    """A run that is measured but not shipped: its card (no model.pt) goes to the trials folder, its
    .md says so, the docs section lists it as not shipped, and no agent name resolves to it."""
    from benchmarks.baselines.evaluation_page import docs_section
    from navcore.baselines.card import card_markdown, cards, ship
    from navcore.eval.agents import AGENTS

    dst = ship(trained[0], "tiny_trial", tmp_path, weights=False)
    assert not (dst / "model.pt").exists() and (dst / "model_card.json").is_file()
    assert cards(tmp_path) == {} and list(cards(tmp_path, weights=False)) == ["tiny_trial"]
    card = cards(tmp_path, weights=False)["tiny_trial"]
    assert "not shipped" in card_markdown(card, shipped=False) and "checked on load" not in card_markdown(card, False)
    assert "tiny_trial` (pointnav; measured, not shipped)" in docs_section({}, None, {"tiny_trial": card})
    assert "tiny_trial" not in AGENTS
    assert "the gap to real captures is not measured yet" in card_markdown(card, False)


def test_a_card_holds_further_tables_and_says_when_real_captures_were_measured(trained, tmp_path):
    """cards evaluation --title adds a table in another setting (replacing one of the same title,
    the main table untouched); --real makes the card say it was measured on real captures."""
    from benchmarks.baselines.evaluation_page import docs_section
    from navcore.baselines.card import add_evaluation, card_markdown, cards, ship

    ship(trained[0], "tiny", tmp_path, weights=False)
    summ = tmp_path / "real_run" / "summary.json"
    summ.parent.mkdir()
    metrics = {"episodes": 30, "sr": 0.5, "spl": 0.4, "ne": 1.0, "collision_rate": 0.1, "steps": 200}
    summ.write_text(json.dumps({"root": "/x/data", "agent": "learned", "label": "tiny", "protocol": "distance",
                                "render": {"width": 160, "height": 120, "renderer": "cpu"},
                                "tasks": {"pointnav": {"overall": metrics}}}))
    for sr in (0.25, 0.5):  # the second replaces the first
        metrics["sr"] = sr
        summ.write_text(json.dumps({**json.loads(summ.read_text()), "tasks": {"pointnav": {"overall": metrics}}}))
        add_evaluation("tiny", [summ], "30 episodes of two captures", "navarena eval ...", tmp_path,
                       title="On real captures", real=True)
    card = cards(tmp_path, weights=False)["tiny"]
    assert len(card["more_evaluations"]) == 1 and card["more_evaluations"][0]["runs"]["real_run"]["root"] == "data"
    md = card_markdown(card, False)
    assert "### On real captures" in md and "| tiny | distance | 160x120 cpu | overall | 30 | 0.500 |" in md
    assert "also measured on real captures" in md and "gap to real captures is not measured" not in md
    assert "#### On real captures" in docs_section({}, None, {"tiny": card})
    # --replace: a re-measured run in place of its namesake, the table's other runs and text kept
    other = tmp_path / "random_run" / "summary.json"
    other.parent.mkdir()
    other.write_text(json.dumps({**json.loads(summ.read_text()), "agent": "random", "label": "random"}))
    add_evaluation("tiny", [summ, other], "30 episodes of two captures", "navarena eval ...", tmp_path,
                   title="On real captures", real=True)
    metrics["sr"] = 0.125
    other.write_text(json.dumps({**json.loads(other.read_text()), "tasks": {"pointnav": {"overall": metrics}}}))
    add_evaluation("tiny", [other], "random re-run.", "navarena eval --agent random", tmp_path, title="On real captures",
                   replace=True)
    table = cards(tmp_path, weights=False)["tiny"]["more_evaluations"][0]
    assert table["real"] and table["conditions"].endswith(" random re-run.") and table["command"].endswith("; navarena eval --agent random")
    assert [r["tasks"]["pointnav"]["overall"]["sr"] for r in table["runs"].values()] == [0.5, 0.125]
    with pytest.raises(SystemExit, match="has no run missing_run"):
        bad = tmp_path / "missing_run" / "summary.json"
        bad.parent.mkdir()
        bad.write_text(other.read_text())
        add_evaluation("tiny", [bad], "", "", tmp_path, title="On real captures", replace=True)


def test_a_card_pairs_each_decoy_run_with_its_own_goal_run_and_states_the_goal_gain():
    """The decoy check in a card: a run shown decoy goals is labelled so in the results table, and
    beside the run of the same agent, arguments, protocol, rendering and episodes shown its own goals it
    gives the goal gain (own SR minus decoy SR; ImageNav's Pose SR beside); a decoy run without such a
    partner (another protocol) has no gain row, and an evaluation without decoy runs no gain table."""
    from navcore.baselines.card import goal_gain_table, results_table

    def run(sr, decoy, protocol="distance", pose=0.1):
        m = {"episodes": 40, "sr": sr, "spl": sr / 2, "ne": 1.0, "collision_rate": 0.1, "steps": 300, "pose_sr": pose}
        return {"root": "r", "agent": "learned", "label": "net", "agent_args": {"checkpoint": "m.pt"}, "protocol": protocol,
                "split": "val_unseen", "episodes_per_scene": 20, "decoy_goal": decoy,
                "render": {"width": 640, "height": 480, "renderer": "gsplat"}, "tasks": {"imagenav": {"overall": m}}}

    card = {"task": "imagenav"}
    ev = {"runs": {"own": run(0.45, False), "decoy": run(0.20, True, pose=0.05),
                   "lonely": run(0.30, True, "explicit_stop")}}
    table = results_table(card, ev)
    assert "| net (decoy goal) | distance | 640x480 gsplat | overall | 40 | 0.200 |" in table
    gain = goal_gain_table(card, ev)
    assert gain in table and "| net | distance | 640x480 gsplat | 40 | 0.450 | 0.200 | +0.250 | 0.100 | 0.050 |" in gain
    assert "explicit_stop" not in gain
    other = run(0.45, False)
    other["agent_args"] = {"checkpoint": "other.pt"}  # another network's run is no partner
    assert goal_gain_table(card, {"runs": {"own": other, "decoy": run(0.2, True)}}) == ""
    assert goal_gain_table(card, {"runs": {"own": run(0.45, False)}}) == ""


@pytest.mark.parametrize("name,task", [("pointnav_bc", "pointnav"), ("objectnav_bc", "objectnav")])
def test_shipped_baseline_behind_the_agent_server_acts_as_in_process(name, task, episode_run, tmp_path):
    """navarena serve-agent --agent NAME, evaluated over ws:// by navarena eval: the same episodes
    end the same way as with the agent in process (the policy is deterministic; objectnav_bc with its
    stop verifier, under explicit_stop). RGB travels as PNG here: the protocol's default JPEG changes
    the pixels an RGB policy sees (objectnav_bc then ends one of these episodes differently)."""
    import subprocess
    import sys
    import time

    import pandas as pd

    from navarena.evaluate import main as evaluate

    root = episode_run[0]
    common = ["--tasks", task, "--difficulty", "easy", "--episodes-per-scene", "2", "--renderer", "cpu",
              "--width", "64", "--height", "48", "--quiet", "--protocol", "explicit_stop" if task == "objectnav" else "distance"]
    assert evaluate([str(root), "--agent", name, *common, "--out", str(tmp_path / "local")]) == 0
    port_file = tmp_path / "port"
    server = subprocess.Popen([sys.executable, "-m", "navarena", "serve-agent", "--agent", name, "--port", "0",
                               "--port-file", str(port_file)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.time() + 120
        while not port_file.exists() or not port_file.read_text().strip():
            assert server.poll() is None and time.time() < deadline, server.stdout.read()[-2000:]
            time.sleep(0.2)
        url = f"ws://127.0.0.1:{int(port_file.read_text())}"
        assert evaluate([str(root), "--agent", url, "--agent-arg", "image_format=png", *common,
                         "--out", str(tmp_path / "remote")]) == 0
    finally:
        server.terminate()
        server.wait(timeout=30)
    cols = ["episode_id", "sr", "steps", "end_reason", "error"]
    local = pd.read_parquet(tmp_path / "local" / "results.parquet")[cols].sort_values("episode_id", ignore_index=True)
    remote = pd.read_parquet(tmp_path / "remote" / "results.parquet")[cols].sort_values("episode_id", ignore_index=True)
    assert len(local) == 2 and (local["error"] == "").all()
    pd.testing.assert_frame_equal(local, remote)


def test_a_one_gpu_run_keeps_the_whole_sets_held_out_scenes():
    """TRAIN_SCENES=N of the reference run: every scene the episodes stage holds out of the SCENES (so the
    zero-shot set is the full run's) and the first N of the others, as the stage splits them."""
    from pathlib import Path

    from benchmarks.baselines.reference import TEST_SHARE, held_out_and_first_train
    from navcore.io.catalog import Catalog
    from stages.episodes.config import EpisodesConfig
    from stages.episodes.generate import scene_split

    splits = {**EpisodesConfig().scene_splits, "test": TEST_SHARE}
    catalog = Path(__file__).resolve().parents[1] / "catalogs/synthetic.yaml"
    every = [s.scene_id for s in Catalog(catalog, "/nonexistent", synthetic_count=64).scenes]
    kept = held_out_and_first_train(64, 5)
    held = [s for s in every if scene_split(s, splits) is not None]
    train = [s for s in every if scene_split(s, splits) is None]
    assert held and set(held) <= set(kept) and len(kept) == len(held) + 5 == len(set(kept))
    assert [s for s in kept if s not in held] == train[:5]
    assert held_out_and_first_train(64, 10_000) == held + train  # more than there are: all of them


def test_navarena_card_ships_a_run_and_keeps_its_markdown(trained, tmp_path, capsys):
    """navarena card ship: the run's model.pt copied beside its card with the copy's sha256 (no
    machine path left in it), loadable by the registry's checkpoint check; markdown writes the .md
    that --check then finds current; evaluation adds a table the .md shows; a folder that is not a
    run is refused with its name and exit 2."""
    from navarena.card import main
    from navcore.baselines.checkpoint import load_checkpoint
    from navcore.io.release import sha256_file

    models = tmp_path / "models"
    assert main(["--models", str(models), "ship", str(trained[0]), "tiny_bc"]) == 0
    card = json.loads((models / "tiny_bc" / "model_card.json").read_text())
    assert card["sha256"] == sha256_file(models / "tiny_bc" / "model.pt") == sha256_file(trained[0] / "model.pt")
    assert "/" not in card["data"]["root"] and card["name"] == "tiny_bc"
    load_checkpoint(models / "tiny_bc" / "model.pt", kind="pointnav", sha256=card["sha256"])
    assert main(["--models", str(models), "markdown", "--check"]) == 1  # no .md yet
    assert main(["--models", str(models), "markdown"]) == 0
    assert main(["--models", str(models), "markdown", "--check"]) == 0
    summ = tmp_path / "tiny_distance" / "summary.json"
    summ.parent.mkdir()
    summ.write_text(json.dumps({"root": "/x/data", "agent": "learned", "label": "tiny_bc", "protocol": "distance",
                                "render": None, "tasks": {"pointnav": {"overall": {"episodes": 4, "sr": 0.75}}}}))
    assert main(["--models", str(models), "evaluation", "tiny_bc", str(summ), "--conditions", "four episodes",
                 "--command", "navarena eval ..."]) == 0
    assert main(["--models", str(models), "markdown", "--check"]) == 1  # the card changed: its .md is stale
    main(["--models", str(models), "markdown"])
    assert "| tiny_bc | distance | no | overall | 4 | 0.750 |" in (models / "tiny_bc" / "model_card.md").read_text()
    capsys.readouterr()
    assert main(["--models", str(models), "ship", str(tmp_path), "x"]) == 2
    assert str(tmp_path) in capsys.readouterr().err


def test_training_noise_is_seeded_and_shaped_as_documented():
    import torch

    from navcore.baselines.model import NavSpec
    from navcore.baselines.train import TrainConfig, augment

    x = torch.rand(3, 2, 4, 48, 64)  # ObjectNav's frames: depth, then RGB
    clean = TrainConfig(task="objectnav", spec=NavSpec(task="objectnav"))
    assert torch.equal(augment(x, clean, torch.Generator().manual_seed(0)), x)
    noisy = TrainConfig(task="objectnav", spec=NavSpec(task="objectnav"), depth_noise=0.1, rgb_noise=0.2)
    a = augment(x, noisy, torch.Generator().manual_seed(1))
    b = augment(x, noisy, torch.Generator().manual_seed(1))
    assert torch.equal(a, b) and a.shape == x.shape
    assert 0.0 <= float(a.min()) and float(a.max()) <= 1.0
    holes = (a[:, :, 0] == 1.0) & (x[:, :, 0] < 1.0)
    assert 0.07 < float(holes.float().mean()) < 0.13  # the holes' share is depth_noise
    kept = ~holes
    rel = (a[:, :, 0][kept] / x[:, :, 0][kept] - 1)
    assert 0.05 < float(rel.std()) < 0.15  # and the rest scaled by 1 + 0.1 N(0, 1) (clamped)
    assert not torch.equal(a[:, :, 1:], x[:, :, 1:])


def test_combined_datasets_read_as_one_and_refuse_a_scene_twice(episode_run, tmp_path, copy_data_root):
    import pytest

    from navcore.eval.dataset import CombinedDataset, NavDataset, open_dataset

    root = episode_run[0]
    other = tmp_path / "other"
    copy_data_root(root, other)
    (sid,) = NavDataset(root).scene_ids("pointnav")
    for folder in ("05_episodes", "06_trajectories"):  # the same episodes under another scene id
        for d in (other / folder).glob(f"task=*/scene_id={sid}"):
            d.rename(d.parent / f"scene_id={sid}x")
    both = open_dataset([root, other])
    assert isinstance(both, CombinedDataset) and both.scene_ids("pointnav") == [sid, sid + "x"]
    a, b = both.episodes(sid, "pointnav", "train"), both.episodes(sid + "x", "pointnav", "train")
    assert [e.episode_id for e in a] == [e.episode_id for e in b] and len(a) > 0
    assert both.info()["kind"] == "combined" and len(both.info()["parts"]) == 2
    with pytest.raises(ValueError, match=f"scene '{sid}' is in both"):
        CombinedDataset([root, root])
    assert isinstance(open_dataset([root]), NavDataset) and isinstance(open_dataset(root), NavDataset)


def test_capture_share_splits_a_rounds_episodes_between_captures_and_generated_scenes():
    import numpy as np

    from navcore.baselines.train import episodes_per_scene

    groups = ["synthetic"] * 8 + ["real_indoor", "real_indoor"]
    scenes = [f"s{i}" for i in range(10)]
    n = episodes_per_scene(scenes, groups, 1000, 0.5, np.random.default_rng(0))
    assert n.sum() == 1000 and n[8:].sum() == 500 and n[:8].sum() == 500 and (n > 0).all()
    uniform = episodes_per_scene(scenes, groups, 1000, None, np.random.default_rng(0))
    assert uniform.sum() == 1000 and 120 < uniform[8:].sum() < 290  # about 2 in 10
    only_real = episodes_per_scene(scenes[8:], groups[8:], 100, 0.5, np.random.default_rng(0))
    assert only_real.sum() == 100


def test_film_and_resnet_specs_round_trip_and_old_specs_keep_their_network():
    from navcore.baselines.model import NavNet, NavSpec

    new = [NavSpec(task="objectnav", film=True), NavSpec(task="imagenav", rgbd=True, encoder="resnet", depth_w=128, depth_h=96),
           NavSpec(task="imagenav", rgbd=True, encoder="resnet", film=True, depth_w=128, depth_h=96)]
    for spec in new:
        assert NavSpec(**spec.to_dict()) == spec
    for old in (NavSpec(), NavSpec(task="objectnav"), NavSpec(task="imagenav", rgbd=True)):
        d = old.to_dict()
        assert "encoder" not in d and "film" not in d  # a checkpoint written before the options reads as before
        assert [k for k in NavNet(old).state_dict() if k.startswith("cnn.")] == \
            ["cnn.0.weight", "cnn.0.bias", "cnn.2.weight", "cnn.2.bias", "cnn.4.weight", "cnn.4.bias", "cnn.6.weight", "cnn.6.bias"]
    with pytest.raises(ValueError, match="film applies"):
        NavSpec(film=True)
    with pytest.raises(ValueError, match="encoder="):
        NavSpec(encoder="vit")


@pytest.mark.parametrize("task", ["objectnav", "imagenav"])
def test_a_film_network_conditions_its_visual_features_on_the_goal_and_learns_a_goal_dependent_action(task):
    """The same frames, two goals (two categories; two goal images): the FiLM network's encoder output
    differs by goal once trained, and it learns an action that depends on the goal alone (a known
    answer a network that ignored its goal could fit no better than chance)."""
    import torch

    from navcore.baselines.model import NavNet, NavSpec

    torch.manual_seed(0)
    spec = NavSpec(task=task, film=True, hidden=16, embed=16, depth_w=32, depth_h=24, rgbd=task == "imagenav",
                   encoder="resnet" if task == "imagenav" else "cnn")
    net = NavNet(spec)
    c = spec.obs_channels
    frames = torch.rand(1, c, 24, 32).expand(8, c, 24, 32)  # one view for every sample
    if task == "objectnav":
        goal = torch.tensor([[1.0], [2.0]] * 4)  # bed, sofa
        inputs = frames
    else:
        images = torch.rand(2, 3, 24, 32)
        goal = torch.zeros(8, 0)
        inputs = torch.cat([frames, images.repeat(4, 1, 1, 1)], 1)
    label = torch.tensor([1, 2] * 4)  # forward for the first goal, left for the second
    prev = torch.full((8,), 4, dtype=torch.long)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    for _ in range(150):  # until it has learned the goal-dependent action
        logits, _ = net.step(inputs, goal, prev, None)
        loss = torch.nn.functional.cross_entropy(logits, label)
        if loss.item() < 0.05 and (logits.argmax(1) == label).all():
            break
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert loss.item() < 0.05 and (net.step(inputs, goal, prev, None)[0].argmax(1) == label).all()
    with torch.no_grad():
        if task == "objectnav":
            cond = net.goal(goal[:2, 0].long())
        else:
            cond = torch.relu(net.goal_proj(net.goal_cnn(images)))
        feats = net.cnn(frames[:2], cond)
    assert not torch.allclose(feats[0], feats[1])  # the goal reached the encoder, not only the recurrent core


@pytest.mark.parametrize("chunk", [0, 4])
def test_packed_encoding_of_uneven_episodes_matches_the_padded_batch(chunk):
    """The trainer encodes only its episodes' own steps (valid), not the padding after the shorter
    ones: every valid step's outputs and every gradient equal the padded batch's, whatever the
    padding frames hold."""
    torch.manual_seed(0)
    spec = NavSpec(task="objectnav", hidden=16, embed=16, depth_w=32, depth_h=24, film=True, aux_goal=True)
    net = NavNet(spec).train()
    t, b = 6, 3
    lens = torch.tensor([6, 2, 4])
    valid = torch.arange(t)[:, None] < lens[None]
    frames = torch.rand(t, b, spec.obs_channels, 24, 32)
    goal = torch.randint(0, len(spec.categories), (t, b, 1)).float()
    prev = torch.randint(0, 5, (t, b))
    runs = []
    for packed in (False, True):
        net.zero_grad()
        f = frames[valid] if packed else torch.where(valid[..., None, None, None], frames, torch.rand_like(frames))
        logits, _, pred = net(f, goal, prev, aux=True, chunk=chunk, valid=valid if packed else None)
        logits, pred = logits[valid], pred[valid]
        (logits.square().sum() + pred.sum()).backward()
        runs.append((logits.detach(), pred.detach(), {k: q.grad.clone() for k, q in net.named_parameters() if q.grad is not None}))
    (l0, p0, g0), (l1, p1, g1) = runs
    assert l1.shape == (int(lens.sum()), 4)
    assert torch.allclose(l0, l1, atol=1e-5) and torch.allclose(p0, p1, atol=1e-5)
    assert g0.keys() == g1.keys() and len(g0) > 10
    for k in g0:
        assert torch.allclose(g0[k], g1[k], atol=1e-4, rtol=1e-4), k


@pytest.mark.parametrize("task,encoder", [("imagenav", "resnet"), ("objectnav", "cnn")])
def test_chunked_encoding_gives_the_same_outputs_and_gradients(task, encoder):
    """The trainer's encode_chunk (gradient checkpointing, a chunk of frames at a time) is a memory
    bound, not another model: outputs and every parameter's gradient match the whole batch at once."""
    torch.manual_seed(0)
    spec = NavSpec(task=task, hidden=16, embed=16, depth_w=32, depth_h=24, rgbd=task == "imagenav", encoder=encoder,
                   film=task == "objectnav", aux_goal=True)
    net = NavNet(spec).train()
    t, b = 7, 3
    frames = torch.rand(t, b, spec.obs_channels + (3 if spec.goal == "image" else 0), 24, 32)
    goal = (torch.randint(0, len(spec.categories), (t, b, 1)).float() if spec.goal == "category"
            else torch.zeros(t, b, 0))
    prev = torch.randint(0, 5, (t, b))
    runs = []
    for chunk in (0, 4, 5):  # whole, uneven chunks (21 frames: 4 x 5 + 1), 5 x 4 + 1
        net.zero_grad()
        logits, h, pred = net(frames, goal, prev, aux=True, chunk=chunk)
        (logits.square().sum() + pred.sum() + h.sum()).backward()
        runs.append((logits.detach(), pred.detach(), {k: p.grad.clone() for k, p in net.named_parameters() if p.grad is not None}))
    for logits, pred, grads in runs[1:]:
        assert torch.allclose(logits, runs[0][0], atol=1e-5) and torch.allclose(pred, runs[0][1], atol=1e-5)
        assert grads.keys() == runs[0][2].keys() and len(grads) > 10
        for k, g in grads.items():
            assert torch.allclose(g, runs[0][2][k], atol=1e-4, rtol=1e-4), k
    with torch.no_grad():  # evaluation: no checkpointing, the same chunks
        assert torch.allclose(net(frames, goal, prev, chunk=4)[0], runs[0][0], atol=1e-5)


def test_fit_step_benchmark_times_the_same_episodes_both_ways(tmp_path):
    """benchmarks.baselines.fit_step: both ways see the same episode lengths (the padded batch's share of
    padding is what packing saves), a report is written, and each way's own-frame rate is positive."""
    import json

    from benchmarks.baselines.fit_step import main

    r = main(["--task", "pointnav", "--batch", "3", "--steps", "1", "--mean-length", "6", "--max-length", "12",
              "--size", "32", "24", "--out", str(tmp_path)])
    assert json.loads((tmp_path / "fit_step.json").read_text())["speedup"] == pytest.approx(r["speedup"])
    assert 0.0 < r["padding_share"] < 1.0
    assert r["padded"]["frames_per_s"] > 0 and r["packed"]["frames_per_s"] > 0
