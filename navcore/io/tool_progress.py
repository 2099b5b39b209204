"""Progress of the long user commands (export-lerobot, render-episodes, the observation index), in
the pipeline's style (rich): items done of the total, frames done and their rate, time elapsed and
left; nothing with quiet. Without a terminal (a log file, a batch job) the bar cannot redraw: a
plain line is printed instead at most every `log_every` seconds, and at the end."""
from __future__ import annotations

import sys
import time

from navcore.io.progress_log import duration


class ToolProgress:
    """with ToolProgress("export-lerobot", total_episodes, quiet) as p: p.advance(frames=n) per item."""

    def __init__(self, what: str, total: int, quiet: bool = False, unit: str = "episodes", log_every: float = 10.0,
                 budget: int | None = None):
        """budget: the frames all items may take at most (an evaluation: the episodes' step budgets); with
        it, the time left is the budget of the items not yet done at the frame rate so far (an episode that
        runs its whole budget is never a surprise), else the items left at the item rate so far."""
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

        self.frames, self.t0 = 0, time.perf_counter()
        self.budget, self.budget_done = budget, 0
        self.what, self.unit, self.total = what, unit, total
        self.plain = not quiet and not sys.stderr.isatty()
        self.log_every, self.logged = log_every, self.t0
        quiet = quiet or self.plain
        self.progress = Progress(TextColumn(f"{what} {unit}"), BarColumn(), MofNCompleteColumn(),
                                 TextColumn("{task.fields[frames]:,} frames, {task.fields[rate]:.1f} frames/s"),
                                 TimeElapsedColumn(), TextColumn("left"),
                                 TextColumn("at most {task.fields[left]}") if budget else TimeRemainingColumn(),
                                 disable=quiet)
        self.task = self.progress.add_task(what, total=total, frames=0, rate=0.0, left="?")

    def __enter__(self) -> "ToolProgress":
        self.progress.start()
        return self

    @property
    def done(self) -> int:
        return int(self.progress.tasks[0].completed)

    def __exit__(self, *exc) -> None:
        if self.plain:
            self.line(final=True)
        self.progress.update(self.task, total=self.done)  # a total given as a bound ends full
        self.progress.stop()

    def budget_left_s(self) -> float | None:
        """Seconds the unfinished items' budget takes at the frame rate so far (None: no budget or no rate yet)."""
        rate = self.frames / max(time.perf_counter() - self.t0, 1e-9)
        return None if not self.budget or not self.frames else max(0, self.budget - self.budget_done) / rate

    def advance(self, items: int = 1, frames: int = 0, budget: int = 0) -> None:
        """items done, the frames they took and (with a budget) the budget they had."""
        self.frames += frames
        self.budget_done += budget
        now = time.perf_counter()
        rate = self.frames / max(now - self.t0, 1e-9)
        left = self.budget_left_s()
        self.progress.update(self.task, advance=items, frames=self.frames, rate=rate,
                             left="?" if left is None else duration(left))
        if self.plain and now - self.logged >= self.log_every:
            self.line()

    def line(self, final: bool = False) -> None:
        """One plain progress line on stderr: done of total, frames and their rate, elapsed, left."""
        now = time.perf_counter()
        self.logged = now
        dt = now - self.t0
        if final or not self.done:
            left = ""
        elif self.budget:
            left = f", at most {duration(self.budget_left_s() or 0)} left (the step budgets of the episodes to run)"
        else:
            left = f", about {duration(dt / self.done * max(0, self.total - self.done))} left"
        print(f"{self.what}: {self.done}/{self.total if not final else self.done} {self.unit}, {self.frames:,} frames "
              f"({self.frames / max(dt, 1e-9):.1f}/s), {duration(dt)} elapsed{left}{' (done)' if final else ''}",
              file=sys.stderr, flush=True)
