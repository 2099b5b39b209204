"""ObjectNav's stop verifier: navarena train-stop (labels by the evaluator's rule, poses near and
facing instances, loss falls, one seed -> one checkpoint), its checkpoint refused when foreign, and
the learned agent's veto and forced stop, alone and batched."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from navcore.baselines.checkpoint import CheckpointError, save_checkpoint
from navcore.baselines.model import NavNet, NavSpec
from navcore.baselines.verifier import KIND, StopNet, StopSpec, category_index, load_verifier, stop_input
from navcore.nav.poses import region_distance

TINY = ["--poses-per-scene", "48", "--grad-steps", "25", "--batch", "16", "--width", "32", "--height", "24",
        "--input", "32", "24", "--renderer", "cpu", "--device", "cpu", "--quiet"]


def test_labels_follow_the_evaluators_rule():
    """A pose is positive for a category within its success radius of one of the category's
    regions (boxes, the evaluator's region_distance), whatever the other categories."""
    from navcore.baselines.train_stop import pose_labels

    regions = {"chair": (np.array([[0.0, 0.0, 1.0, 1.0]]), 0.5), "bed": (np.array([[4.0, 0.0, 6.0, 2.0]]), 1.0)}
    cats = ("chair", "bed", "sofa")
    xy = np.array([[0.5, 0.5], [1.4, 0.5], [1.6, 0.5], [3.2, 1.0], [2.9, 1.0]])
    got = pose_labels(xy, regions, cats)
    want = [[1, 0, 0], [1, 0, 0], [0, 0, 0], [0, 1, 0], [0, 0, 0]]  # 0.4 / 0.6 m from the chair, 0.8 / 1.1 from the bed
    assert got.tolist() == want
    assert got.dtype == np.uint8


def test_poses_near_an_instance_face_it():
    from navcore.baselines.train_stop import StopConfig, sample_poses

    g = np.stack(np.meshgrid(np.arange(0, 8, 0.25), np.arange(0, 8, 0.25)), -1).reshape(-1, 2)
    box = np.array([[3.0, 3.0, 4.0, 4.0]])
    cfg = StopConfig(near_share=1.0, facing_share=1.0, yaw_noise=0.0, near_range=1.0)
    poses = sample_poses(g, {"chair": (box, 0.5)}, 200, cfg, np.random.default_rng(0))
    assert (region_distance(poses[:, :2], box) <= 1.0 + 1e-9).all()
    want = np.arctan2(3.5 - poses[:, 1], 3.5 - poses[:, 0])
    assert np.allclose(np.angle(np.exp(1j * (poses[:, 2] - want))), 0, atol=1e-9)
    spread = sample_poses(g, {"chair": (box, 0.5)}, 400, StopConfig(near_share=0.0), np.random.default_rng(1))
    assert (region_distance(spread[:, :2], box) > 1.0).mean() > 0.8  # the rest anywhere on the cells
    assert (np.abs(spread[:, 2]) <= math.pi).all()


@pytest.fixture(scope="module")
def stop_runs(episode_run, tmp_path_factory):
    from navarena.train_stop import main

    outs = [tmp_path_factory.mktemp(f"stop{i}") for i in range(2)]
    for out in outs:
        assert main([str(episode_run[0]), "--out", str(out), *TINY]) == 0
    return outs


def test_tiny_train_stop_loss_falls_and_one_seed_gives_one_checkpoint(stop_runs):
    a, b = stop_runs
    assert (a / "stop.pt").read_bytes() == (b / "stop.pt").read_bytes()
    card = json.loads((a / "stop_card.json").read_text())
    assert card["curve"][-1]["loss"] < card["curve"][0]["loss"], card["curve"]
    assert card["data"]["train_poses"] == 48 * len(card["data"]["train_scenes"]) > 0
    assert 0 < max(card["data"]["positive_share"]) < 1  # near an instance and away from it
    assert "timing" in card
    net = load_verifier(str(a / "stop.pt"), card["sha256"], "cpu")
    assert (net.spec.depth_w, net.spec.depth_h) == (32, 24) and not net.training


def test_a_foreign_or_damaged_verifier_is_refused(tmp_path):
    policy = NavNet(NavSpec(task="objectnav", hidden=16, embed=16))
    f = tmp_path / "policy.pt"
    save_checkpoint(f, "objectnav", policy.spec.to_dict(), policy.state_dict(), {})
    with pytest.raises(CheckpointError, match=f"a 'objectnav' policy, not '{KIND}'"):
        load_verifier(str(f), None, "cpu")
    bad = tmp_path / "bad.pt"
    save_checkpoint(bad, KIND, StopSpec(width=8).to_dict(), StopNet(StopSpec(width=4)).state_dict(), {})
    with pytest.raises(CheckpointError, match="do not fit the stop verifier"):
        load_verifier(str(bad), None, "cpu")
    with pytest.raises(CheckpointError, match="sha256"):
        load_verifier(str(bad), "0" * 64, "cpu")


def _verifier(tmp_path, chair: float, bed: float) -> str:
    """A verifier whose P does not depend on the frame: `chair` and `bed`, every other category 0."""
    spec = StopSpec(depth_h=24, depth_w=32, width=4)
    net = StopNet(spec)
    with torch.no_grad():
        net.head[-1].weight.zero_()
        logit = torch.full((len(spec.categories),), -30.0)
        logit[spec.categories.index("chair")] = math.log(chair / (1 - chair))
        logit[spec.categories.index("bed")] = math.log(bed / (1 - bed))
        net.head[-1].bias.copy_(logit)
    f = tmp_path / f"v_{chair}_{bed}.pt"
    save_checkpoint(f, KIND, spec.to_dict(), net.state_dict(), {})
    return str(f)


def _policy(tmp_path, lead: str) -> str:
    """An ObjectNav policy whose argmax is `lead` (stop or forward) whatever it sees."""
    net = NavNet(NavSpec(task="objectnav", hidden=16, embed=16))
    with torch.no_grad():
        net.head.weight.zero_()
        net.head.bias.copy_(torch.tensor([3.0, 1.0, 0.5, 0.0] if lead == "stop" else [1.0, 3.0, 0.5, 0.0]))
    f = tmp_path / f"p_{lead}.pt"
    save_checkpoint(f, "objectnav", net.spec.to_dict(), net.state_dict(), {})
    return str(f)


def _obs(category: str) -> dict:
    return {"depth": np.full((48, 64), 2.0, np.float32), "rgb": np.zeros((48, 64, 3), np.uint8),
            "goal_category": category}


def test_the_verifier_vetoes_a_stop_for_the_wrong_category_and_can_force_one(tmp_path):
    from navcore.baselines.agent import LearnedNavAgent

    v = _verifier(tmp_path, chair=0.9, bed=0.2)

    def act(lead, category, **kw):
        a = LearnedNavAgent(checkpoint=_policy(tmp_path, lead), device="cpu", **kw)
        a.reset({"episode_id": 1})
        return a.act(_obs(category))

    assert act("stop", "bed") == 0  # no verifier: the policy's STOP
    assert act("stop", "chair", verifier=v) == 0  # P 0.9 >= 0.5: the STOP stands
    assert act("stop", "bed", verifier=v) == 1  # P 0.2 < 0.5: vetoed, FORWARD (the likeliest move)
    assert act("stop", "bed", verifier=v, stop_check=0.1) == 0
    assert act("forward", "chair", verifier=v) == 1  # the verifier never stops on its own ...
    assert act("forward", "chair", verifier=v, stop_force=0.8) == 0  # ... unless told to: P 0.9 >= 0.8
    assert act("forward", "bed", verifier=v, stop_force=0.8) == 1
    assert act("stop", "bed", verifier="none") == 0
    with pytest.raises(ValueError, match="stop_check and stop_force apply with a stop verifier"):
        act("stop", "bed", stop_check=0.3)
    with pytest.raises(ValueError, match="stop_force=1.5"):
        act("stop", "bed", verifier=v, stop_force=1.5)
    with pytest.raises(ValueError, match="'bed' is not among the stop verifier's"):
        category_index(StopSpec(categories=("chair",)), "bed")
    pointnav = NavNet(NavSpec(hidden=16, embed=16))
    f = tmp_path / "pointnav.pt"
    save_checkpoint(f, "pointnav", pointnav.spec.to_dict(), pointnav.state_dict(), {})
    with pytest.raises(ValueError, match="applies to objectnav policies"):
        LearnedNavAgent(checkpoint=str(f), device="cpu", verifier=v)


def test_batched_slots_are_verified_each_for_its_own_goal(tmp_path):
    """act_batch: each slot's STOP is checked against its own category, as act() would."""
    from navcore.baselines.agent import LearnedNavAgent

    v, p = _verifier(tmp_path, chair=0.9, bed=0.2), _policy(tmp_path, "stop")
    agents = [LearnedNavAgent(checkpoint=p, device="cpu", verifier=v) for _ in range(3)] + \
        [LearnedNavAgent(checkpoint=p, device="cpu")]
    for a in agents:
        a.reset({"episode_id": 1})
    cats = ["chair", "bed", "chair", "bed"]
    assert LearnedNavAgent.act_batch(agents, [_obs(c) for c in cats]) == [0, 1, 0, 0]


def test_verifier_input_is_resolution_independent():
    spec = StopSpec()
    rng = np.random.default_rng(0)
    depth = torch.from_numpy(np.repeat(np.repeat(rng.uniform(0.5, 8, (96, 128)), 5, 0), 5, 1).astype(np.float32))
    rgb = torch.from_numpy(np.repeat(np.repeat(rng.integers(0, 256, (96, 128, 3), dtype=np.uint8), 5, 0), 5, 1))
    big = stop_input(depth[None], rgb[None], spec)
    small = stop_input(depth[None, ::5, ::5].contiguous(), rgb[None, ::5, ::5].contiguous(), spec)
    assert big.shape == (1, 4, 96, 128)
    assert torch.allclose(big, small, atol=1e-5)
    assert float(big[0, 0].max()) <= 1.0  # depth clipped at max_depth


def test_a_verifier_is_shipped_into_a_card_and_shown(stop_runs, tmp_path):
    """cards verifier: the run's stop.pt beside the policy with its sha256, thresholds, data and the
    held-out runs the thresholds were chosen on; the card's page shows them. A verifier for another
    track's card, or a run whose file is not the one its card names, is refused."""
    import shutil

    from navcore.baselines.agent import MODELS
    from navcore.baselines.card import add_evaluation, card_markdown, ship_verifier

    models = tmp_path / "models"
    (models / "objectnav_bc").mkdir(parents=True)
    shutil.copyfile(MODELS / "objectnav_bc" / "model_card.json", models / "objectnav_bc" / "model_card.json")
    sel = tmp_path / "sel" / "check0.3" / "summary.json"
    sel.parent.mkdir(parents=True)
    sel.write_text(json.dumps({"agent": "objectnav_bc", "agent_args": {"verifier": "x.pt", "stop_check": 0.3},
                               "protocol": "explicit_stop", "split": "val_unseen", "render": None, "root": "r",
                               "tasks": {"objectnav": {"overall": {"episodes": 7, "stop_sr": 0.4286, "spl": 0.2}}}}))
    v = ship_verifier(stop_runs[0], "objectnav_bc", 0.3, None, [sel], models)
    assert (models / "objectnav_bc" / "stop.pt").read_bytes() == (stop_runs[0] / "stop.pt").read_bytes()
    card = json.loads((models / "objectnav_bc" / "model_card.json").read_text())
    assert card["stop_verifier"] == v and v["stop_check"] == 0.3 and v["stop_force"] is None
    assert v["selection"][0]["stop_sr"] == 0.4286 and "/" not in v["data"]["root"]
    page = card_markdown(card)
    assert "## Stop verifier" in page and "| check0.3 | yes | 0.3 | - | 0.429 | 0.200 |" in page
    assert "less than 0.3" in page and "never stops on its own" in page
    rate = {"steps": 10, "process_seconds": 2.0, "steps_per_s_per_process": 5.0, "setting": "s", "machine": "m"}
    card["stop_verifier"]["gpu_eval_rate"] = rate  # measured on the shipped file later ...
    (models / "objectnav_bc" / "model_card.json").write_text(json.dumps(card))
    again = ship_verifier(stop_runs[0], "objectnav_bc", 0.5, None, [sel], models, command="navarena eval X")
    assert again["gpu_eval_rate"] == rate and again["stop_check"] == 0.5  # ... kept when it ships again
    assert "Reproduce: `navarena eval X`" in card_markdown(json.loads((models / "objectnav_bc" / "model_card.json").read_text()))
    # --add: a run joins the main table; a name it already holds is refused
    sel2 = tmp_path / "ev" / "objectnav_bc_tried_objectnav_explicit_stop" / "summary.json"
    sel2.parent.mkdir(parents=True)
    sel2.write_text(sel.read_text())
    add_evaluation("objectnav_bc", [sel2], "more.", "cmd2", models, add=True)
    ev = json.loads((models / "objectnav_bc" / "model_card.json").read_text())["evaluation"]
    assert list(ev["runs"])[-1] == "objectnav_bc_tried_objectnav_explicit_stop" and len(ev["runs"]) > 1
    assert ev["conditions"].endswith(" more.") and ev["command"].endswith("; cmd2")
    with pytest.raises(SystemExit, match="already has objectnav_bc_tried"):
        add_evaluation("objectnav_bc", [sel2], "again.", "cmd3", models, add=True)
    pn = models / "pointnav_bc"
    pn.mkdir()
    shutil.copyfile(MODELS / "pointnav_bc" / "model_card.json", pn / "model_card.json")
    with pytest.raises(SystemExit, match="a pointnav baseline"):
        ship_verifier(stop_runs[0], "pointnav_bc", 0.3, models=models)
    other = tmp_path / "other"
    shutil.copytree(stop_runs[0], other)
    (other / "stop.pt").write_bytes((other / "stop.pt").read_bytes()[:-8] + b"\0" * 8)
    with pytest.raises(SystemExit, match="not the file its card names"):
        ship_verifier(other, "objectnav_bc", 0.3, models=models)
    assert (models / "objectnav_bc" / "stop.pt").read_bytes() == (stop_runs[0] / "stop.pt").read_bytes()  # untouched


def test_the_shipped_objectnav_baseline_runs_its_verifier():
    """The registry name objectnav_bc loads the card's stop verifier (sha256-checked) and its
    threshold; verifier=none runs the policy alone."""
    from navcore.baselines.agent import LearnedNavAgent, shipped_card

    card = shipped_card("objectnav_bc")
    a = LearnedNavAgent(name="objectnav_bc", device="cpu")
    assert a.verifier is not None and a.stop_check == card["stop_verifier"]["stop_check"] and a.stop_force is None
    assert LearnedNavAgent(name="objectnav_bc", device="cpu", verifier="none").verifier is None
    assert LearnedNavAgent(name="objectnav_bc", device="cpu", stop_check=0.6).stop_check == 0.6


@pytest.mark.parametrize("command", ["train", "train_stop"])
def test_training_on_a_missing_root_says_so_in_one_line(command, tmp_path, capsys):
    import importlib

    main = importlib.import_module(f"navarena.{command}").main
    assert main([str(tmp_path / "nowhere"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"navarena {command.replace('_', '-')}: " in err and "nowhere: no such folder" in err
    assert "Traceback" not in err and not (tmp_path / "out").exists()
