"""Completion markers: data/_markers/{stage}/{scene_id}.json, written last (after all outputs),
holding the config hash, outputs, counts and timing. A (stage, scene) is done when its marker
exists with the current hash."""
from __future__ import annotations

import json
from pathlib import Path

from navcore.io.atomic import write_text_atomic


def read_marker(path: Path) -> dict | None:
    try:
        return json.loads(Path(path).read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None


def is_done(path: Path, config_hash: str) -> bool:
    m = read_marker(path)
    return m is not None and m.get("config_hash") == config_hash


def write_marker(path: Path, payload: dict) -> None:
    write_text_atomic(path, json.dumps(payload, indent=1, sort_keys=True, default=str))
