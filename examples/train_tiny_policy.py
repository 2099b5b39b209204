"""Train a tiny policy for a few steps from the expert's observations (behaviour cloning).

    .venv/bin/python examples/train_tiny_policy.py [DATA_ROOT] [--steps 30]

navarena.observations.ExpertObservations renders egocentric RGB-D at the stored expert poses on
demand (gsplat on a GPU, the CPU renderer otherwise); each item also holds the robot's pose and the
expert's discrete action (`action_id`: 0 stop, 1 forward, 2 / 3 turn); the goal comes from the
episode table (pandas). A small CNN learns to predict the action from depth and the point goal in
the robot frame. A real run trains for hours on a release; this one shows the
loop and that the loss goes down.
"""
import argparse
import math

import torch
from torch import nn


class TinyPolicy(nn.Module):
    def __init__(self):
        super().__init__()
        self.conv = nn.Sequential(nn.Conv2d(1, 8, 5, stride=2), nn.ReLU(), nn.Conv2d(8, 16, 3, stride=2), nn.ReLU(),
                                  nn.AdaptiveAvgPool2d(4), nn.Flatten())
        self.head = nn.Sequential(nn.Linear(16 * 16 + 2, 64), nn.ReLU(), nn.Linear(64, 4))

    def forward(self, depth, goal):
        return self.head(torch.cat([self.conv(depth[:, None]), goal], 1))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("root", nargs="?", default="data")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--batch", type=int, default=32)
    a = ap.parse_args(argv)
    from navarena.observations import ExpertObservations

    torch.manual_seed(0)
    data = ExpertObservations(a.root, split="train", tasks=["pointnav"], stride=10, width=64, height=48,
                              renderer="auto", quiet=True)
    import pandas as pd

    eps = pd.read_parquet(f"{a.root}/05_episodes", filters=[("task", "==", "pointnav")])
    goals = {(s, e): (x, y) for s, e, x, y in eps[["scene_id", "episode_id", "goal_position_x", "goal_position_y"]]
             .itertuples(index=False)}
    loader = torch.utils.data.DataLoader(data, batch_size=a.batch, shuffle=True,
                                         collate_fn=lambda items: collate(items, goals))
    policy = TinyPolicy()
    opt = torch.optim.Adam(policy.parameters(), lr=3e-3)
    losses = []
    batches = iter(loader)
    for step in range(a.steps):
        try:
            b = next(batches)
        except StopIteration:
            batches = iter(loader)
            b = next(batches)
        loss = nn.functional.cross_entropy(policy(b["depth"], b["goal"]), b["action_id"])
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss))
        if step % 10 == 0 or step == a.steps - 1:
            print(f"step {step:3d}  loss {loss.item():.3f}")
    print(f"{len(data)} expert steps; loss {losses[0]:.3f} -> {sum(losses[-5:]) / 5:.3f} (mean of the last 5)")
    return losses


def collate(items, goals):
    """Depth (clipped to 5 m, scaled to [0, 1]), the goal in the robot frame (distance / 10 m and
    bearing), the expert's action id."""
    depth = torch.stack([torch.as_tensor(it["depth"]) for it in items]).float().clamp(0, 5) / 5
    rows = []
    for it in items:
        x, y, yaw = (float(v) for v in it["pose"])
        gx, gy = goals[(it["scene_id"], it["episode_id"])]
        dx, dy = gx - x, gy - y
        rows.append([math.hypot(dx, dy) / 10, math.atan2(dy, dx) - yaw])
    goal = torch.tensor(rows)
    goal[:, 1] = torch.atan2(torch.sin(goal[:, 1]), torch.cos(goal[:, 1]))
    action = torch.tensor([int(it["action_id"]) for it in items])
    return {"depth": depth, "goal": goal, "action_id": action}


if __name__ == "__main__":
    main()
