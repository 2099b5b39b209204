"""The evaluation's progress on the run's console: episodes done / total, steps/s, time left, and
one line per finished episode (and the semantics stage's: views done / total, views/s), read from
the tasks' progress logs
(navcore.io.progress_log) while they run, wherever they run (sync, local workers, batch jobs on a
shared filesystem). The stage-task bar counts (stage, scene) tasks; an evaluation is one task a
scene that can take hours, so it gets this bar of its own."""
from __future__ import annotations

import threading
import time
from pathlib import Path

from navcore.io.progress_log import duration, read_log


class EpisodeWatcher:
    """Polls `folder`/*.jsonl (logs written after `since`, epoch seconds) every `period` seconds into
    a task of a rich Progress (`name`: "episodes"), printing each finished episode on its console
    (log_each). An item counts 1, or its `count` field (the semantics stage logs a batch of views);
    the rate is the items' `rate` field summed per second, in `unit`s (steps, views)."""

    def __init__(self, progress, folder: Path, since: float, period: float = 1.0, log_each: bool = True,
                 name: str = "episodes", count: str | None = None, rate: str = "steps", unit: str = "steps",
                 log_every_s: float = 30.0):
        self.progress, self.folder, self.since, self.period, self.log_each = progress, Path(folder), since, period, log_each
        self.name, self.count, self.rate_key, self.unit = name, count, rate, unit
        self.log_every, self.logged = log_every_s, time.monotonic()
        self.seen: dict[Path, tuple[int, int, int]] = {}  # log -> (its header's total, done so far, item lines read)
        self.steps = 0
        self.task = None
        self.t0 = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="episode-progress", daemon=True)

    def __enter__(self) -> "EpisodeWatcher":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.poll()

    def _loop(self) -> None:
        while not self._stop.wait(self.period):
            self.poll()

    def poll(self) -> None:
        if not self.folder.is_dir():
            return
        for log in sorted(self.folder.glob("*.jsonl")):
            try:
                if log.stat().st_mtime < self.since:
                    continue
            except OSError:
                continue
            total, done, lines = self.seen.get(log, (0, 0, 0))
            header, items = read_log(log, lines)
            if header is None:
                continue
            if log not in self.seen:
                total = int(header.get("total", 0))
                if header.get("hint"):  # what a long task says before it starts: its size, time, the fast path
                    self.progress.console.print(header["hint"])
                if not self.seen:  # steps/s from the first evaluation's start, not the run's
                    self.t0 = time.monotonic()
            done += sum(int(it.get(self.count) or 0) if self.count else 1 for it in items)
            self.seen[log] = (total, done, lines + len(items))
            for it in items:
                self.steps += int(it.get(self.rate_key) or 0)
                if self.log_each:
                    self.progress.console.print(line(header, it))
        if not self.seen:
            return
        total = sum(t for t, _, _ in self.seen.values())
        done = sum(min(n, t) for t, n, _ in self.seen.values())
        rate = self.steps / max(time.monotonic() - self.t0, 1e-9)
        if self.task is None:
            self.task = self.progress.add_task(self.name, total=total, rate=rate, unit=self.unit)
        self.progress.update(self.task, total=total, completed=done, rate=rate)
        now = time.monotonic()
        if not self.progress.console.is_terminal and done < total and now - self.logged >= self.log_every:
            # without a terminal (a log, a batch job) no bar redraws: a plain line now and then
            self.logged = now
            left = f", about {duration((total - done) / rate)} left" if rate > 0 else ""
            self.progress.console.print(f"{self.name}: {done:,}/{total:,} ({rate:,.1f} {self.unit}/s){left}")


def line(header: dict, it: dict) -> str:
    """One finished episode, as the console logs it."""
    how = "[green]success[/]" if it.get("success") else f"[yellow]{it.get('end_reason') or 'failed'}[/]"
    err = f" [red]{it['error']}[/]" if it.get("error") else ""
    spl = it.get("spl")
    return (f"  {header.get('scene', header.get('scene_id', '?'))} {it.get('task')} {it.get('episode_id')}: {how}, "
            f"{it.get('steps')} steps" + (f", SPL {spl:.2f}" if isinstance(spl, (int, float)) else "") + err)


def rate_column():
    """A rich progress column: steps/s and the time left, for the tasks that carry a `rate` field."""
    from rich.progress import ProgressColumn, TimeRemainingColumn
    from rich.text import Text

    left = TimeRemainingColumn()

    class RateColumn(ProgressColumn):
        def render(self, task):
            if "rate" not in task.fields:
                return Text("")
            return Text(f"{task.fields['rate']:,.0f} {task.fields.get('unit', 'steps')}/s, left ") + left.render(task)

    return RateColumn()
