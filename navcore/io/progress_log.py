"""Progress of a long (stage, scene) task, written as it goes and read by the run's console.

A task writes a JSON-lines file: a header line ``{"total": N, ...}`` when it starts (the file is
rewritten), then one line per finished item, flushed at once. The console (pipeline.progress)
polls the files of the tasks of its run and shows items done / total, their rate and the time
left, and logs each item. The file is a log, not an output: it is in no marker's manifest, and a
rerun overwrites it. Works wherever the data root is shared (local workers, batch jobs).
"""
from __future__ import annotations

import json
import os
from pathlib import Path

from navcore.io import jsonio


def duration(s: float) -> str:
    """Seconds as a progress line says them: 45 s, 3.5 min, 2.1 h."""
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} min" if s < 7200 else f"{s / 3600:.1f} h"


class ProgressLog:
    def __init__(self, path: str | Path):
        self.path = Path(path)

    def start(self, total: int, **meta) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with open(self.path, "w") as f:
            f.write(jsonio.dumps({"total": int(total), "pid": os.getpid(), **meta}) + "\n")

    def item(self, **fields) -> None:
        with open(self.path, "a") as f:
            f.write(jsonio.dumps(fields) + "\n")


def read_log(path: str | Path, skip: int = 0) -> tuple[dict | None, list[dict]]:
    """(header, the item lines after the first `skip`) of a log; a line being written is left for later."""
    try:
        lines = Path(path).read_text().split("\n")
    except OSError:
        return None, []
    complete = lines[:-1]  # the last piece has no newline yet (or is empty)
    if not complete:
        return None, []
    try:
        header = json.loads(complete[0])
        items = [json.loads(x) for x in complete[1 + skip:]]
    except json.JSONDecodeError:
        return None, []
    return header, items
