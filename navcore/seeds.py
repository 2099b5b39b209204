"""Seeds: every random stream is derived from (config seed, scene id, purpose), so a result never
depends on which worker or shard computed it."""
from __future__ import annotations

import hashlib


def stream_seed(seed: int, scene_id: str, task: str) -> int:
    """The random stream of one (scene, task): independent of which worker runs it."""
    h = hashlib.sha256(f"{seed}:{scene_id}:{task}".encode()).digest()
    return int.from_bytes(h[:8], "little") & (2**63 - 1)
