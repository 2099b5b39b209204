"""PPO fine-tuning (navcore.baselines.ppo, navarena train-rl): GAE's known answers, and a tiny run on
the CPU whose policy any learned agent reads, deterministic for a seed, which resumes where it stopped."""
import json

import numpy as np
import pytest
import torch

from navcore.baselines.ppo import gae

TINY = ["--task", "pointnav", "--slots", "8", "--horizon", "24", "--minibatches", "2", "--epochs", "2", "--lr", "0.002",
        "--width", "32", "--height", "24", "--renderer", "cpu", "--input", "32", "24", "--protocol", "distance",
        "--quiet"]


def test_gae_known_answers():
    """One step, gamma 0.5, lambda 1: the advantage is r + gamma V' - V; an ended episode bootstraps
    nothing; lambda 0 is the one-step TD error at every step."""
    r = torch.tensor([[1.0], [2.0]])
    v = torch.tensor([[0.5], [1.0]])
    last = torch.tensor([4.0])
    adv, ret = gae(r, v, torch.zeros(2, 1), last, 0.5, 1.0)
    d1 = 2.0 + 0.5 * 4.0 - 1.0
    d0 = 1.0 + 0.5 * 1.0 - 0.5
    assert torch.allclose(adv[:, 0], torch.tensor([d0 + 0.5 * d1, d1]))
    assert torch.allclose(ret, adv + v)
    adv, _ = gae(r, v, torch.tensor([[1.0], [0.0]]), last, 0.5, 1.0)  # the first episode ended at step 0
    assert torch.allclose(adv[:, 0], torch.tensor([1.0 - 0.5, d1]))
    adv, _ = gae(r, v, torch.zeros(2, 1), last, 0.5, 0.0)
    assert torch.allclose(adv[:, 0], torch.tensor([d0, d1]))


def test_ppo_runs_writes_a_policy_any_learned_agent_reads_and_resumes(episode_run, tmp_path):
    """Two updates: the card's curve, a model.pt the learned agent loads, the same bytes for the same
    seed, and --resume goes on from the checkpoint with the curve kept."""
    from navarena.train_rl import main
    from navcore.baselines.agent import LearnedNavAgent

    root = episode_run[0]
    args = [str(root), "--horizon", "8", "--updates", "2", "--save-every", "1", *TINY]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    card = json.loads((tmp_path / "a" / "rl_card.json").read_text())
    assert [c["update"] for c in card["curve"]] == [0, 1] and card["recipe"] == "ppo"
    assert {"return", "sr", "policy_loss", "value_loss", "entropy", "frames_per_s"} <= set(card["curve"][0])
    LearnedNavAgent(checkpoint=str(tmp_path / "a" / "model.pt"))  # a policy any learned agent reads
    assert main([*args, "--out", str(tmp_path / "b")]) == 0  # same seed, same policy bytes (CPU)
    assert (tmp_path / "a" / "model.pt").read_bytes() == (tmp_path / "b" / "model.pt").read_bytes()
    assert main([str(root), "--out", str(tmp_path / "a"), "--horizon", "8", "--updates", "3", "--resume", *TINY]) == 0
    again = json.loads((tmp_path / "a" / "rl_card.json").read_text())
    assert [c["update"] for c in again["curve"]] == [0, 1, 2] and again["curve"][:2] == card["curve"]



def test_the_update_replays_the_rollout_as_the_policy_read_it(episode_run, tmp_path):
    """Before any gradient step, replaying a rollout (stored frames, the GRU from the rollout's first
    state, reset where an episode began) gives back, bit for bit, the log-probabilities and values the policy
    had while acting: PPO's first ratio is exactly 1 (the policy reads the frames at the 8 bits they are
    stored in). Episodes end inside the rollout, so the resets are replayed too."""
    from navcore.baselines.model import NavSpec
    from navcore.baselines.ppo import PPOConfig, PPOTrainer

    cfg = PPOConfig(slots=4, horizon=40, minibatches=2, width=32, height=24, renderer="cpu", protocol="explicit_stop",
                    spec=NavSpec(depth_w=32, depth_h=24, hidden=32, embed=32))
    tr = PPOTrainer(episode_run[0], tmp_path / "run", cfg, quiet=True)
    r, finished = tr.rollout(0)
    assert r.frames.dtype == torch.uint8 and r.first[1:].sum() >= 1  # an episode began inside the rollout
    with torch.no_grad():
        logp, value, _ = tr.replay(r, torch.arange(cfg.slots))
    # every slot at once, as while acting: the same operations on the same inputs, the same bits
    assert torch.equal(logp, r.logp) and torch.equal(value, r.value)

@pytest.mark.slow
def test_ppo_from_scratch_raises_its_return(tmp_path):
    """From scratch on the CPU (two generated scenes of 30 k Gaussians, PointNav at 32 x 24, 240 updates of
    16 slots x 32 steps: about 6 minutes on 2 cores): the shaped reward per step of the last 48 updates
    beats the first 48's, and three times as many episodes reach their goal (slow: make test-all)."""
    import subprocess
    import sys

    from navarena.train_rl import main

    root = tmp_path / "data"
    subprocess.run([sys.executable, "-m", "pipeline", f"data_root={root}", "scenes.count=2", "scenes.num_gaussians=30000",
                    "task=[pointnav]", "semantics.enabled=false", "stages=[episodes]", "executor.dashboard=false"],
                   check=True, capture_output=True)
    assert main([str(root), "--out", str(tmp_path / "ppo"), "--task", "pointnav", "--slots", "16", "--horizon", "32",
                 "--updates", "240", "--lr", "0.001", "--entropy-coef", "0.01", "--width", "32", "--height", "24",
                 "--renderer", "cpu", "--input", "32", "24", "--protocol", "distance", "--quiet"]) == 0
    curve = json.loads((tmp_path / "ppo" / "rl_card.json").read_text())["curve"]
    reward = [c["reward_per_step"] for c in curve]
    reached = [c["episodes"] * (c["sr"] or 0) for c in curve]  # episodes that finished at their goal
    assert np.mean(reward[-48:]) > np.mean(reward[:48]) + 0.02, reward
    assert sum(reached[-48:]) > 3 * sum(reached[:48]), reached
