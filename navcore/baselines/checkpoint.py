"""Policy checkpoints: one torch file holding plain data only (tensors, numbers, strings, lists,
dicts), read with torch.load(weights_only=True), so a file cannot run code when loaded. A
damaged, truncated or unsafe file is refused with an error naming it.

    {"format": "navarena-policy/1", "kind": "pointnav", "spec": "{...}", "state_dict": {...},
     "meta": "{...}"}         # meta: what the training recorded (data, config, seed, curve)

spec and meta are stored as JSON text (sorted keys), so the bytes depend on their values only,
never on which Python objects held them (pickle shares repeated objects by identity).
load_checkpoint returns them as dicts.

The shipped baselines (navcore/models/<name>/) are checked against their published sha256 first.
"""
from __future__ import annotations

import hashlib
import io
import json
import pickle
from pathlib import Path

import torch

from navcore.io.atomic import atomic_path
from navcore.io.release import sha256_file

FORMAT = "navarena-policy/1"


class CheckpointError(ValueError):
    """A checkpoint that cannot be used (damaged, unsafe, of another kind or format)."""


def save_checkpoint(path, kind: str, spec: dict, state_dict: dict, meta: dict | None = None) -> str:
    """Write atomically (navcore.io.atomic); returns the file's sha256. Tensors
    are saved contiguous and on the CPU, so the bytes do not depend on the device trained on."""
    payload = {"format": FORMAT, "kind": kind, "spec": json.dumps(dict(spec), sort_keys=True),
               "state_dict": {k: v.detach().cpu().contiguous().clone() for k, v in state_dict.items()},
               "meta": json.dumps(meta or {}, sort_keys=True, default=str)}
    buf = io.BytesIO()
    torch.save(payload, buf)
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.getvalue())
    return hashlib.sha256(buf.getvalue()).hexdigest()


def load_checkpoint(path, kind: str | None = None, sha256: str | None = None) -> dict:
    """The checkpoint's payload (see the module docstring), its tensors on the CPU. Raises
    FileNotFoundError, or CheckpointError naming the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"policy checkpoint {path} does not exist")
    if sha256 is not None and (got := sha256_file(path)) != sha256:
        raise CheckpointError(f"{path}: sha256 {got[:12]}... differs from the published {sha256[:12]}...; the file "
                              f"is damaged or not the shipped one (reinstall the package)")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # a damaged zip, a pickle of code (refused by weights_only), anything else
        what = "holds objects other than plain data (refused: loading it could run code)" \
            if isinstance(e, pickle.UnpicklingError) else "is damaged or not a torch file"
        raise CheckpointError(f"{path}: {what}: {str(e).splitlines()[0][:200]}") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a NavArena policy checkpoint (format "
                              f"{payload.get('format') if isinstance(payload, dict) else type(payload).__name__!r}, "
                              f"expected {FORMAT!r})")
    for key in ("kind", "spec", "state_dict"):
        if key not in payload:
            raise CheckpointError(f"{path}: the checkpoint has no {key!r}")
    if kind is not None and payload["kind"] != kind:
        raise CheckpointError(f"{path}: a {payload['kind']!r} policy, not {kind!r}")
    try:
        payload["spec"] = json.loads(payload["spec"])
        payload["meta"] = json.loads(payload.get("meta") or "{}")
    except (TypeError, ValueError) as e:
        raise CheckpointError(f"{path}: its spec or meta is not JSON text: {e}") from None
    return payload
