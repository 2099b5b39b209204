"""Protocol codec: frames (msgpack maps {type, payload, seq, timestamp}), arrays and images inside
payloads, and the action forms (see the package docstring)."""
from __future__ import annotations

import io
import time

import msgpack
import numpy as np

FRAME_TYPES = {"observation", "action", "episode_start", "episode_end", "error", "batch_observation",
               "batch_action", "batch_episode_start", "batch_episode_end"}


class ProtocolError(RuntimeError):
    """A frame that breaks the protocol, or a server error frame."""


# ---- values -------------------------------------------------------------------------------------
def encode_array(a: np.ndarray) -> dict:
    a = np.ascontiguousarray(a)
    if a.dtype.kind not in "biuf":
        raise ProtocolError(f"arrays of dtype kind {a.dtype.kind!r} cannot be sent (b, i, u, f only)")
    return {"__ndarray__": True, "data": a.tobytes(), "dtype": a.dtype.str, "shape": list(a.shape)}


def encode_image(img: np.ndarray, fmt: str = "jpeg", quality: int = 90) -> dict:
    """HxWx{1,3,4} uint8 -> image map (jpeg, png or raw)."""
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (1, 3, 4):
        raise ProtocolError(f"images must be HxWx{{1,3,4}} uint8, got {img.dtype} {img.shape}")
    if fmt == "raw":
        return {"__image__": True, "data": img.tobytes(), "format": "raw", "shape": list(img.shape), "dtype": "|u1"}
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(img[..., 0] if img.shape[2] == 1 else img).save(
        buf, format="JPEG" if fmt == "jpeg" else "PNG", **({"quality": quality} if fmt == "jpeg" else {}))
    return {"__image__": True, "data": buf.getvalue(), "format": fmt, "shape": list(img.shape)}


def decode_value(v):
    """Undo encode_array / encode_image anywhere in a nested payload."""
    if isinstance(v, dict):
        if v.get("__ndarray__"):
            return np.frombuffer(v["data"], dtype=np.dtype(v["dtype"])).reshape(v["shape"]).copy()
        if v.get("__image__"):
            shape = tuple(v["shape"])
            if v["format"] == "raw":
                return np.frombuffer(v["data"], dtype=np.dtype(v.get("dtype", "|u1"))).reshape(shape).copy()
            from PIL import Image

            img = np.asarray(Image.open(io.BytesIO(v["data"])))
            return img.reshape(shape)
        return {k: decode_value(x) for k, x in v.items()}
    if isinstance(v, list):
        return [decode_value(x) for x in v]
    return v


def encode_observation(obs: dict, image_format: str = "jpeg") -> dict:
    """An environment observation as a payload: rgb as an image, other arrays as ndarrays."""
    out = {}
    for k, v in obs.items():
        if k in ("rgb", "goal_image") and isinstance(v, np.ndarray):
            out[k] = encode_image(v, image_format)
        elif isinstance(v, np.ndarray):
            out[k] = encode_array(v)
        else:
            out[k] = v
    return out


# ---- frames -------------------------------------------------------------------------------------
def pack(kind: str, payload: dict, seq: int) -> bytes:
    return msgpack.packb({"type": kind, "payload": payload, "seq": int(seq), "timestamp": time.time()},
                         use_bin_type=True)


def unpack(data) -> dict:
    """A frame, checked: msgpack map with type, payload (map), seq (int) and timestamp."""
    try:
        frame = msgpack.unpackb(data, raw=False)
    except Exception as e:  # noqa: BLE001
        raise ProtocolError(f"not a msgpack frame: {type(e).__name__}: {e}") from e
    if not isinstance(frame, dict) or not {"type", "payload", "seq", "timestamp"} <= set(frame):
        raise ProtocolError(f"a frame must be a map with type, payload, seq and timestamp, got {str(frame)[:120]}")
    if frame["type"] not in FRAME_TYPES or not isinstance(frame["payload"], dict) or \
            not isinstance(frame["seq"], int):
        raise ProtocolError(f"malformed frame: type {frame.get('type')!r}, seq {frame.get('seq')!r}")
    if frame["type"] == "error":
        raise ProtocolError(f"server error: {frame['payload'].get('error')}"
                            + (" (fatal)" if frame["payload"].get("fatal") else ""))
    return frame


def parse_action(payload: dict):
    """An action frame's payload -> an environment action."""
    if payload.get("stop"):
        return {"stop": True}
    if "waypoints" in payload:
        return {"waypoints": list(payload["waypoints"])}
    if "v" in payload:
        return {"v": payload["v"], "w": payload.get("w", 0.0), "dt": payload.get("dt", 0.05)}
    if "action_id" in payload:
        return int(payload["action_id"])
    raise ProtocolError(f"action payload has none of stop, waypoints, v/w/dt, action_id: {str(payload)[:120]}")


def action_payload(action) -> dict:
    """An environment action -> an action frame's payload (server side)."""
    if isinstance(action, dict):
        return action
    a = int(action)
    return {"stop": True} if a == 0 else {"action_id": a}
