"""Observations on demand: PyTorch datasets over a data root's stored expert trajectories that
render egocentric RGB-D at the expert's poses when asked, so a policy trains from the 22 M-episode
release without a stored frame.

    from navarena.observations import ExpertObservationStream
    stream = ExpertObservationStream("data", split="train", tasks=["pointnav"], batch_size=256, stride=4)
    for batch in torch.utils.data.DataLoader(stream, batch_size=None, num_workers=2):
        batch["rgb"]     # uint8 [B, H, W, 3] (on the renderer's device with device_output=True)
        batch["depth"]   # float32 [B, H, W], metres along the optical axis (0: nothing hit)
        batch["pose"]    # float32 [B, 3]: x, y, yaw in the aligned frame
        batch["velocity"], batch["waypoint"], batch["action_id"]   # the expert's actions, both forms

ExpertObservationStream (IterableDataset) reads one scene at a time and renders a whole batch of
one scene in one call (gsplat on a GPU renders thousands of frames a second; the CPU renderer
otherwise); DataLoader workers split the scenes. ExpertObservations (map-style Dataset) indexes
every step of the chosen scenes for random access; its __getitems__ renders a sampled batch
grouped by scene (the DataLoader calls it with the whole batch of indices). Both are
deterministic for a seed.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import torch

from navcore.io.tool_progress import ToolProgress
from navcore.render.frames import SceneFrames
from navcore.seeds import stream_seed


class ExpertObservationStream(SceneFrames, torch.utils.data.IterableDataset):
    """Batches of rendered expert steps, one scene at a time (see the module docstring).

    Args:
        root: data root. split / tasks / scenes: which episodes (None: all). stride: every n-th
            step of each trajectory (20 Hz stored; 4 -> 5 Hz). episodes_per_scene: at most this
            many per task and scene. width / height / embodiment: the camera (default: the
            embodiment's). renderer: auto | gsplat | cpu. batch_size: frames per render call.
            shuffle: scene order and steps within a scene, reshuffled per epoch (set_epoch).
            device_output: leave rgb / depth on the renderer's device.
    """

    def __init__(self, root, batch_size: int = 64, shuffle: bool = False, **kw):
        super().__init__(root, **kw)
        self.batch_size, self.shuffle, self.epoch = int(batch_size), shuffle, 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __iter__(self):
        info = torch.utils.data.get_worker_info()
        scenes = list(self.scene_ids)
        rng = np.random.default_rng(stream_seed(self.seed, "observations", str(self.epoch)) % 2**32)
        if self.shuffle:
            rng.shuffle(scenes)
        if info is not None:
            scenes = scenes[info.id::info.num_workers]
        for sid in scenes:
            steps = self._steps(sid)
            if self.shuffle:
                steps = steps.iloc[rng.permutation(len(steps))]
            for a in range(0, len(steps), self.batch_size):
                yield self.render(sid, steps.iloc[a:a + self.batch_size])

    def __len__(self) -> int:  # batches (reads the step tables once)
        return sum(math.ceil(len(self._steps(s)) / self.batch_size) for s in self.scene_ids)


class ExpertObservations(SceneFrames, torch.utils.data.Dataset):
    """Every expert step of the chosen scenes, by index (map-style; the index holds all their
    steps in memory, so choose scenes / episodes_per_scene / stride for large releases, or use the
    stream). __getitems__ renders a sampled batch with one render call per scene it touches."""

    def __init__(self, root, quiet: bool = False, **kw):
        super().__init__(root, **kw)
        parts = []
        with ToolProgress("observation index", len(self.scene_ids), quiet, unit="scenes") as bar:  # the pre-pass
            for sid in self.scene_ids:
                parts.append(self._steps(sid))
                bar.advance(1, len(parts[-1]))
        self.index = pd.concat(parts, ignore_index=True)

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, i: int) -> dict:
        return self.__getitems__([i])[0]

    def __getitems__(self, indices) -> list[dict]:
        rows = self.index.iloc[list(indices)]
        out: list[dict | None] = [None] * len(rows)
        pos = np.arange(len(rows))
        for sid, g in rows.groupby("scene_id", sort=True):
            where = pos[(rows["scene_id"] == sid).to_numpy()]
            batch = self.render(sid, g)
            for j, p in enumerate(where):
                out[p] = {k: v[j] for k, v in batch.items()}
        return out
