"""Progress of the long user commands (export-lerobot, render-episodes, the observation index), in
the pipeline's style (rich): items done of the total, frames done and their rate, time elapsed and
left; nothing with quiet."""
from __future__ import annotations

import time


class ToolProgress:
    """with ToolProgress("export-lerobot", total_episodes, quiet) as p: p.advance(frames=n) per item."""

    def __init__(self, what: str, total: int, quiet: bool = False, unit: str = "episodes"):
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

        self.frames, self.t0 = 0, time.perf_counter()
        self.progress = Progress(TextColumn(f"{what} {unit}"), BarColumn(), MofNCompleteColumn(),
                                 TextColumn("{task.fields[frames]:,} frames, {task.fields[rate]:.1f} frames/s"),
                                 TimeElapsedColumn(), TextColumn("left"), TimeRemainingColumn(), disable=quiet)
        self.task = self.progress.add_task(what, total=total, frames=0, rate=0.0)

    def __enter__(self) -> "ToolProgress":
        self.progress.start()
        return self

    def __exit__(self, *exc) -> None:
        done = self.progress.tasks[0].completed
        self.progress.update(self.task, total=done)  # a total given as a bound ends full
        self.progress.stop()

    def advance(self, items: int = 1, frames: int = 0) -> None:
        self.frames += frames
        rate = self.frames / max(time.perf_counter() - self.t0, 1e-9)
        self.progress.update(self.task, advance=items, frames=self.frames, rate=rate)
